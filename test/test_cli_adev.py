"""``imu-allan adev``: JSON and table output, rate handling and bad input."""

import json
import subprocess
import sys

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan import AXES
from imu_allan.cli import main
from imu_allan.core.allan import allan_curve
from imu_allan.io.csv_io import write_csv

KEYS = {'column', 'method', 'confidence', 'tau_s', 'adev', 'adev_lo', 'adev_hi', 'n'}


@pytest.fixture
def record(tmp_path):
    rng = np.random.default_rng(4)
    n = 4000
    y = rng.standard_normal((n, 6)) * 1e-3 + [0, 0, 0, 0, 0, 9.80665]
    path = tmp_path / 'imu.csv.gz'
    write_csv(path, np.arange(n) / 200.0, y, AXES)
    return path, y


def run_cli(capsys, *argv):
    code = main(['adev', *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_json_one_column_matches_allan_curve(record, capsys):
    path, y = record
    code, out, err = run_cli(capsys, path, '--column', 'accel_z', '--format', 'json',
                             '--method', 'hadamard', '--confidence', '0.95')
    assert code == 0 and err == ''
    doc = json.loads(out)
    assert KEYS <= set(doc)
    assert doc['column'] == 'accel_z' and doc['method'] == 'hadamard'
    c = allan_curve(y[:, 5], 200.0, 'octave', 'hadamard', 0.95)
    assert_allclose(doc['tau_s'], c.tau_s, rtol=1e-9)
    assert_allclose(doc['adev'], c.adev[:, 0], rtol=1e-12)
    assert_allclose(doc['adev_lo'], c.adev_lo[:, 0], rtol=1e-12)
    assert_allclose(doc['adev_hi'], c.adev_hi[:, 0], rtol=1e-12)
    assert doc['n'] == [int(v) for v in c.n_terms]


def test_json_all_axes_is_a_list(record, capsys):
    path, _ = record
    code, out, _ = run_cli(capsys, path, '--format', 'json', '--taus', 'dense')
    assert code == 0
    docs = json.loads(out)
    assert [d['column'] for d in docs] == list(AXES)
    assert all(len(d['tau_s']) == len(d['adev']) == len(d['n']) for d in docs)


def test_explicit_taus_and_table(record, capsys):
    path, _ = record
    code, out, _ = run_cli(capsys, path, '--column', 'gyro_x', '--column', 'gyro_y',
                           '--taus', '0.1,1,0.1004,2.5')
    assert code == 0
    assert 'gyro_x [rad/s]' in out and 'gyro_y [rad/s]' in out
    rows = [ln.split() for ln in out.splitlines() if ln.strip()[:1].isdigit()]
    assert [float(r[0]) for r in rows[:3]] == [0.1, 1.0, 2.5]
    code, out, _ = run_cli(capsys, path, '--column', 'gyro_x', '--format', 'json',
                           '--method', 'nonoverlapping', '--taus', '0.005,0.01')
    assert json.loads(out)['n'] == [3999, 1999]


def test_headerless_file_needs_rate(tmp_path, capsys):
    path = tmp_path / 'freq.txt'
    path.write_text('# comment\n' + '\n'.join(f'{v:.6f}' for v in np.sin(np.arange(300))))
    code, out, err = run_cli(capsys, path, '--rate', '2', '--format', 'json')
    assert code == 0 and json.loads(out)['column'] == 'value'
    code, out, err = run_cli(capsys, path)
    assert code == 2 and out == '' and '--rate' in err


def test_irregular_stamps_warn_on_stderr(shared_dir, capsys):
    path = shared_dir / 'realdata/mpu6050_irregular/mpu6050_static_11min.csv.gz'
    code, out, err = run_cli(capsys, path, '--column', 'gyro_z', '--format', 'json')
    assert code == 0
    assert 'irregular time stamps' in err and err.count('\n') == 1
    assert json.loads(out)['column'] == 'gyro_z'


BAD = {
    'empty.csv': '',
    'nan.csv': 't,gyro_x\n0,1\n0.01,nan\n0.02,1\n',
    'text.csv': 't,gyro_x\n0,1\n0.01,oops\n',
    'short.csv': 't,gyro_x\n0,1\n0.01,2\n0.02,3\n',
}


@pytest.mark.parametrize('name, extra', [
    ('empty.csv', []), ('nan.csv', []), ('text.csv', []),
    ('short.csv', ['--method', 'hadamard', '--taus', '0.02']),
    ('short.csv', ['--taus', 'decade']), ('short.csv', ['--confidence', '1.2']),
    ('missing.csv', []), ('short.csv', ['--column', 'accel_q']),
])
def test_bad_input_exit_2_one_line(tmp_path, capsys, name, extra):
    for fname, text in BAD.items():
        (tmp_path / fname).write_text(text)
    argv = [tmp_path / name] + (['--column', 'gyro_x'] if '--column' not in extra else [])
    code, out, err = run_cli(capsys, *argv, *extra)
    assert code == 2
    assert out == ''
    assert err.startswith('imu-allan: error: ') and err.count('\n') == 1
    assert 'Traceback' not in err


def test_subprocess_python_m(record, tmp_path):
    path, _ = record
    ok = subprocess.run([sys.executable, '-m', 'imu_allan', 'adev', str(path), '--column',
                         'gyro_x', '--format', 'json'], capture_output=True, text=True,
                        timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)['column'] == 'gyro_x'
    bad = tmp_path / 'bad.csv'
    bad.write_text('t,gyro_x\n0,1\n0.01,x\n')
    res = subprocess.run([sys.executable, '-m', 'imu_allan', 'adev', str(bad)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and res.stdout == ''
    assert res.stderr.count('\n') == 1 and 'row 3' in res.stderr


def test_adev_imports_no_fitting_machinery(record):
    # Its bounds take scipy.special's chi-square quantiles; scipy.stats, the fit's
    # optimizer and the simulator's signal filters stay unloaded.
    path, _ = record
    code = ('import sys\nfrom imu_allan.cli import main\n'
            f'assert main(["adev", {str(path)!r}, "--format", "json"]) == 0\n'
            'print(sorted(m for m in sys.modules if m in '
            '("scipy.stats", "scipy.optimize", "scipy.signal")))\n')
    res = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().splitlines()[-1] == '[]'
