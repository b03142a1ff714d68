"""
Bad arguments and bad output places: one line on stderr, exit 2, before the work.

``--out`` is checked before any input is read (a file, under a file, read-only, too
little space); a write that fails after the analysis (disk full, file too large) is one
line too.  Read-only and size-limited file systems are real tmpfs mounts in a user and
mount namespace (``unshare -rm``); the tests that need one skip where it is refused.
"""

import json
import os
from pathlib import Path
import resource
import shutil
import signal
import subprocess
import sys
import time

import pytest

from imu_allan import AXES
from imu_allan.cli import main
from imu_allan.cli.outdir import OUT_BYTES_PER_INPUT, prepare_out_dir
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.errors import InputError
from imu_allan.io.csv_io import write_csv

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope='module')
def csv_rec(tmp_path_factory) -> Path:
    """Return a CSV of a still Xsens MTi-7, 60 s at 100 Hz."""
    spec = load_params(REPO / 'config' / 'xsens_mti7.yaml')
    t_s, samples = simulate_imu(spec, 100.0, 60.0, seed=7)
    path = tmp_path_factory.mktemp('rec') / 'rec.csv'
    write_csv(path, t_s, samples, AXES)
    return path


def _run(argv: list, prefix: list | None = None, **kwargs) -> tuple:
    """Run ``imu-allan`` in a fresh process; return (exit code, stdout, stderr lines, s)."""
    cmd = (prefix or []) + [sys.executable, '-m', 'imu_allan'] + [str(a) for a in argv]
    start = time.monotonic()
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300,
                         env=dict(os.environ, PYTHONPATH=str(REPO)), **kwargs)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    return res.returncode, res.stdout, lines, time.monotonic() - start


def _one_line(code: int, out: str, err: list, words: str) -> None:
    assert code == 2, (code, out, err)
    assert len(err) == 1 and err[0].startswith('imu-allan: error: '), err
    # Nothing on stdout, or with --format json the one error object.
    assert out == '' or json.loads(out) == {'error': err[0].removeprefix('imu-allan: error: '),
                                            'exit_code': 2}, out
    assert words in err[0], err[0]
    assert 'Traceback' not in err[0]


def _namespace_mount(options: str) -> list | None:
    """Return a command prefix that runs in a fresh tmpfs mounted at /mnt, or None."""
    if shutil.which('unshare') is None:
        return None
    probe = subprocess.run(['unshare', '-rm', 'sh', '-c', f'mount -t tmpfs -o {options} '
                            'tmpfs /mnt && exec "$0" "$@"', 'true'],
                           capture_output=True, timeout=30)
    if probe.returncode != 0:
        return None
    return ['unshare', '-rm', 'sh', '-c', f'mount -t tmpfs -o {options} tmpfs /mnt && '
            'exec "$0" "$@"']


def test_out_that_is_a_file_or_under_one_is_refused_before_the_work(tmp_path, csv_rec):
    (tmp_path / 'afile').write_text('x')
    for out, words in ((tmp_path / 'afile', 'exists and is not a directory'),
                       (tmp_path / 'afile' / 'sub', 'is a file, not a directory')):
        code, stdout, err, seconds = _run(['analyze', csv_rec, '--out', out,
                                           '--format', 'json'])
        _one_line(code, stdout, err, words)
        # Before the analysis: no reading, no fit (the full run takes seconds).
        assert not any('reading' in ln or 'fitting' in ln for ln in err)
    assert (tmp_path / 'afile').read_text() == 'x'


def test_out_on_a_read_only_file_system_is_refused_before_the_work(csv_rec):
    prefix = _namespace_mount('ro')
    if prefix is None:
        pytest.skip('no user and mount namespaces here (unshare -rm)')
    code, stdout, err, _ = _run(['analyze', csv_rec, '--out', '/mnt/out'], prefix)
    _one_line(code, stdout, err, '--out /mnt/out: cannot write there (Read-only file system)')


def test_out_without_space_for_the_outputs_is_refused_before_the_work(csv_rec):
    prefix = _namespace_mount('size=1m')
    if prefix is None:
        pytest.skip('no user and mount namespaces here (unshare -rm)')
    code, stdout, err, _ = _run(['analyze', csv_rec, '--out', '/mnt/out'], prefix)
    _one_line(code, stdout, err, 'MiB free, the outputs need about 2 MiB')


def test_free_space_needed_scales_with_the_inputs(tmp_path):
    free = shutil.disk_usage(tmp_path).free
    too_many = free // OUT_BYTES_PER_INPUT + 1
    with pytest.raises(InputError, match='MiB free, the outputs need about'):
        prepare_out_dir(tmp_path / 'new', n_inputs=too_many)
    assert not (tmp_path / 'new').exists()            # created for the check, removed
    assert prepare_out_dir(tmp_path / 'new' / 'deeper') is True


def _small_files_only():
    # Files larger than 16 kB fail to grow with EFBIG, as on a full disk (ENOSPC): the
    # write fails in the middle of the outputs, after the analysis.
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (16384, 16384))


def test_a_write_that_fails_after_the_analysis_is_one_line(tmp_path, csv_rec):
    code, stdout, err, _ = _run(['analyze', csv_rec, '--out', tmp_path / 'o', '--no-plot',
                                 '--jobs', '1', '--format', 'json'],
                                preexec_fn=_small_files_only)
    _one_line(code, stdout, err[-1:], f'cannot write the outputs to {tmp_path / "o"}: '
                                      'File too large')
    assert stdout, 'no JSON error object'
    assert not any('Traceback' in ln for ln in err)


def test_a_full_disk_while_writing_a_simulated_bag_is_one_line(tmp_path):
    code, stdout, err, _ = _run(['simulate', '--params', REPO / 'config' / 'xsens_mti7.yaml',
                                 '--rate', '100', '--duration', '60', '--seed', '1',
                                 '--out', tmp_path / 's.mcap'], preexec_fn=_small_files_only)
    _one_line(code, stdout, err, 'cannot write (File too large)')


@pytest.mark.parametrize('options, words', [
    ('size=1m', 'database or disk is full'), ('ro', 'unable to open database file')])
def test_a_full_or_read_only_disk_while_writing_a_sqlite3_bag_is_one_line(
        tmp_path, csv_rec, options, words):
    # sqlite3 reports a full disk as its own OperationalError: one line, no traceback.
    prefix = _namespace_mount(options)
    if prefix is None:
        pytest.skip('no user and mount namespaces here (unshare -rm)')
    for argv in (['simulate', '--params', REPO / 'config' / 'xsens_mti7.yaml', '--rate',
                  '100', '--duration', '60', '--seed', '1', '--out', '/mnt/s.db3'],
                 ['csv-to-bag', csv_rec, '/mnt/c.db3']):
        code, stdout, err, _ = _run(argv, prefix)
        _one_line(code, stdout, err, f'{argv[-1]}: cannot write ({words}')


@pytest.mark.parametrize('argv, words', [
    (['analyze', '{csv}', '--rate', 'nan'], '--rate must be a finite number'),
    (['analyze', '{csv}', '--rate', '-5'], '--rate must be a finite number'),
    (['analyze', '{csv}', '--jobs', '-1'], '--jobs must be >= 0'),
    (['diagnose', '{csv}', '--out', '{tmp}/afile'], 'exists and is not a directory'),
    (['diagnose', '{csv}', '--rate', 'inf'], '--rate must be a finite number'),
    (['simulate', '--params', '{repo}/config/xsens_mti7.yaml', '--rate', '100',
      '--duration', '1', '--seed', '-1', '--out', '{tmp}/s.csv'], '--seed must be >= 0'),
    (['simulate', '--params', '{repo}/config/xsens_mti7.yaml', '--rate', '1e12',
      '--duration', '1e9', '--out', '{tmp}/s.csv'], 'fit in memory'),
    (['simulate', '--params', '{repo}/config/xsens_mti7.yaml', '--rate', '100',
      '--duration', '1', '--out', '{tmp}/afile/s.mcap'], 'cannot write'),
    (['csv-to-bag', '{csv}', '{tmp}/afile/x.mcap'], 'cannot write'),
    (['demo', '--speed', '0'], '--speed must be a positive number'),
    (['demo', '--out', '{tmp}/afile'], 'exists and is not a directory'),
])
def test_bad_arguments_of_every_command_are_one_line(tmp_path, csv_rec, capsys, argv, words):
    (tmp_path / 'afile').write_text('x')
    argv = [a.format(csv=csv_rec, tmp=tmp_path, repo=REPO) for a in argv]
    code = main(argv)
    out, err = capsys.readouterr()
    _one_line(code, out, [ln for ln in err.splitlines() if ln.strip()], words)


def test_the_outputs_check_leaves_no_empty_directory_after_a_failed_input(tmp_path):
    bad = tmp_path / 'bad.csv'
    bad.write_text('t,x\n0,1\n')
    code = main(['analyze', str(bad), '--out', str(tmp_path / 'o')])
    assert code == 2 and not (tmp_path / 'o').exists()


@pytest.mark.parametrize('argv, words', [
    (['analyze', '{tmp}/missing.csv'], 'no such file'),
    (['analyze', '{bad}', '{bad}', '--out', '{tmp}/o'], 'none of the 2 inputs'),
    (['analyze', '{csv}', '--jobs', 'x'], "invalid int value: 'x'"),
    (['adev', '{tmp}/missing.csv'], 'no such file'),
    (['diagnose', '{csv}', '--rate', 'inf'], '--rate must be a finite number'),
    (['plan', '--N', '1e-3'], 'needs the sample rate'),
    (['plan', '--N', '1e-3', '--rate', '100', '--B', '1 parsec'], 'unit'),
    (['fleet', '{csv}'], 'required: --store'),
])
@pytest.mark.parametrize('spelling', [['--format', 'json'], ['--format=json']])
def test_a_failure_with_format_json_is_one_json_error_object(tmp_path, csv_rec, capsys,
                                                             argv, words, spelling):
    bad = tmp_path / 'bad.csv'
    bad.write_text('t,gyro_x\n')
    argv = [a.format(csv=csv_rec, tmp=tmp_path, bad=bad) for a in argv] + spelling
    code = main(argv)
    out, err = capsys.readouterr()
    doc = json.loads(out)           # all of stdout: exactly one document
    assert doc == {'error': doc['error'], 'exit_code': code} and code == 2, (doc, code)
    assert words in doc['error'] and doc['error'] in err.splitlines()[-1], (doc, err)
    assert 'Traceback' not in err


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _fork_server_started(pgid: int) -> bool:
    """Tell whether a fork server runs in the process group (it preloads its modules)."""
    for proc in Path('/proc').iterdir():
        try:
            if proc.name.isdigit() and os.getpgid(int(proc.name)) == pgid and \
                    b'forkserver' in (proc / 'cmdline').read_bytes():
                return True
        except OSError:
            continue
    return False


def _terminal_sigint() -> None:
    """Give the child a terminal's SIGINT: a shell's background job inherits it ignored."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture(scope='module')
def long_csv(tmp_path_factory) -> Path:
    """Return a CSV of a still Xsens MTi-7, 30 min at 100 Hz (its fit takes seconds)."""
    spec = load_params(REPO / 'config' / 'xsens_mti7.yaml')
    t_s, samples = simulate_imu(spec, 100.0, 1800.0, seed=11)
    path = tmp_path_factory.mktemp('long') / 'long.csv'
    write_csv(path, t_s, samples, AXES)
    return path


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='/proc, process groups')
@pytest.mark.parametrize('when', ['fork server starting', 'fitting'])
def test_ctrl_c_is_one_line_and_exit_130_promptly(tmp_path, long_csv, when):
    # A terminal's Ctrl-C: SIGINT to the whole process group (fork server and workers).
    err_path = tmp_path / 'err.txt'
    with open(err_path, 'w') as err_file:
        proc = subprocess.Popen(
            [sys.executable, '-m', 'imu_allan', 'analyze', str(long_csv), '--out',
             str(tmp_path / 'o'), '--jobs', '2', '--format', 'json'],
            stdout=subprocess.PIPE, stderr=err_file, process_group=0,
            env=dict(os.environ, PYTHONPATH=str(REPO)), preexec_fn=_terminal_sigint)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if when == 'fitting' and 'fitting the noise model' in err_path.read_text():
                break
            if when != 'fitting' and _fork_server_started(proc.pid):
                break
            time.sleep(0.02)
        assert proc.poll() is None, err_path.read_text()
        sent = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
        took_s = time.monotonic() - sent
        while _group_alive(proc.pid) and time.monotonic() - sent < 30:
            time.sleep(0.05)
        gone_s = time.monotonic() - sent
    finally:
        if _group_alive(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
    err = err_path.read_text()
    assert proc.returncode == 130, err
    assert 'Traceback' not in err and err.splitlines()[-1] == 'imu-allan: interrupted', err
    assert err.count('interrupted') == 1, err
    assert json.loads(out) == {'error': 'interrupted', 'exit_code': 130}
    # Promptly: the fit's workers are ended, not waited for (seconds each), and so is
    # the fork server (its preloading takes seconds).
    assert took_s < 5.0 and gone_s < 8.0, (took_s, gone_s)
