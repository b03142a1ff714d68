"""The one atomic file write: a failed writer leaves the old file and no debris."""

import pytest

from imu_allan.atomic import write_atomic


def test_write_replaces_the_file(tmp_path):
    path = tmp_path / 'state.txt'
    write_atomic(path, lambda f: f.write('one'), mode='w')
    write_atomic(path, lambda f: f.write('two'), mode='w')
    assert path.read_text() == 'two'
    assert [p.name for p in tmp_path.iterdir()] == ['state.txt']


def test_a_failed_write_keeps_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / 'state.bin'
    write_atomic(path, lambda f: f.write(b'good'))

    def broken(f):
        f.write(b'half')
        raise RuntimeError('disk full')
    with pytest.raises(RuntimeError, match='disk full'):
        write_atomic(path, broken)
    assert path.read_bytes() == b'good'
    assert [p.name for p in tmp_path.iterdir()] == ['state.bin']


def test_a_new_file_gets_the_mode_open_gives_and_an_old_one_keeps_its_own(tmp_path):
    """Reports must be readable by their consumers: not mkstemp's 0600."""
    import os
    import stat
    plain = tmp_path / 'plain.txt'
    plain.write_text('x')
    path = write_atomic(tmp_path / 'imu.yaml', lambda f: f.write('a: 1\n'), mode='w')
    assert stat.S_IMODE(path.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode)
    os.chmod(path, 0o640)
    write_atomic(path, lambda f: f.write('a: 2\n'), mode='w')
    assert stat.S_IMODE(path.stat().st_mode) == 0o640 and path.read_text() == 'a: 2\n'
