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
