"""
Unit mistakes named from physics, and ``--units`` that converts before the analysis.

A seeded simulated still Xsens MTi-7 (gravity on z) is written in each wrong unit: gyro
in deg/s, accelerometer in g and mg, a CSV t column in ms, bag stamps one nanosecond
apart.  ``imu-allan analyze`` must name the likely mistake in the top-level warnings of
result.json and on stderr, and with the unit declared give the numbers of the SI record.
"""

import json
import math
from pathlib import Path

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan import AXES
from imu_allan.cli import main
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.unit_check import (G0_M_S2, GYRO_BIAS_MAX, GYRO_WHITE_MAX,
                                             parse_units, stamps_ns, unit_warnings)
from imu_allan.core.outputs.short_record import SHORT_RECORD
from imu_allan.errors import InputError
from imu_allan.io.bag_writer import write_imu_bag
from imu_allan.io.csv_io import write_csv
from imu_allan.pipeline.resolution import COARSE_GRID

REPO = Path(__file__).resolve().parents[1]
RATE_HZ = 100.0
DEG = math.pi / 180.0


@pytest.fixture(scope='module')
def still():
    """Return (t_s (n,), samples (n, 6) in SI) of a still Xsens MTi-7, 60 s at 100 Hz."""
    spec = load_params(REPO / 'config' / 'xsens_mti7.yaml')
    return simulate_imu(spec, RATE_HZ, 60.0, seed=21)


def _analyze(tmp_path, path: Path, capsys, *extra) -> tuple:
    """Run analyze; return (result.json, stderr lines)."""
    out = tmp_path / ('out_' + path.stem)
    code = main(['analyze', str(path), '--out', str(out), '--no-plot', '--jobs', '1',
                 '--format', 'json', *extra])
    _, err = capsys.readouterr()
    assert code == 0, err
    return json.loads((out / 'result.json').read_text()), err.splitlines()


def _unit_warnings(doc: dict) -> list:
    """Return the warnings of a result JSON but a short record's (60 s) and a grid's."""
    return [w for w in doc['warnings'] if not w.startswith((SHORT_RECORD, COARSE_GRID))]


def _csv(tmp_path, name: str, t_s, samples) -> Path:
    path = tmp_path / name
    write_csv(path, t_s, samples, AXES)
    return path


def _named(doc: dict, err: list, words: str) -> None:
    hits = [w for w in doc['warnings'] if words in w]
    assert len(hits) == 1, doc['warnings']
    assert any(words in line and line.startswith('imu-allan: warning: ') for line in err), err


def test_an_si_record_raises_no_unit_warning(tmp_path, still, capsys):
    doc, _ = _analyze(tmp_path, _csv(tmp_path, 'si.csv', *still), capsys)
    assert _unit_warnings(doc) == []


def _refused(tmp_path, path: Path, capsys, *extra) -> str:
    """Run analyze on a record with a unit mistake: exit 2, one line, no file; the line."""
    out = tmp_path / ('out_' + path.stem)
    code = main(['analyze', str(path), '--out', str(out), '--no-plot', '--jobs', '1',
                 '--format', 'json', *extra])
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 2 and len(err) == 1, captured
    # --format json: stdout holds the one error object, the same line as stderr's.
    doc = json.loads(captured.out)
    assert doc['exit_code'] == 2 and err[0] == f'imu-allan: error: {doc["error"]}', captured
    assert err[0].startswith(f'imu-allan: error: {path}: unit mistake: '), err
    assert not out.exists()
    return err[0]


def test_each_wrong_unit_is_refused_by_name_and_declaring_it_gives_the_si_numbers(
        tmp_path, still, capsys):
    t_s, y = still
    si, _ = _analyze(tmp_path, _csv(tmp_path, 'si.csv', t_s, y), capsys)
    wrong = y.copy()
    wrong[:, :3] /= DEG                      # gyro in deg/s
    wrong[:, 3:] /= G0_M_S2                  # accelerometer in g
    err = _refused(tmp_path, _csv(tmp_path, 'deg_g.csv', t_s, wrong), capsys)
    assert 'the accelerometer looks like g (declare --units accel=g)' in err
    # The MTi-7 in deg/s reads 4.8e-3 "rad/s/sqrt(Hz)": under GYRO_WHITE_REFUSE (a real
    # u-blox gyro is that noisy), so only a warning, once the record is analysed.
    assert 'rerun with --units accel=g (or' in err
    assert 'confirm the values as they are with --units accel=m/s^2)' in err
    doc, lines = _analyze(tmp_path, _csv(tmp_path, 'deg.csv', t_s,
                                         wrong * np.repeat([1.0, G0_M_S2], 3)), capsys)
    _named(doc, lines, 'the gyro does not look like rad/s')
    path = _csv(tmp_path, 'deg_g_ms.csv', t_s * 1e3, wrong)      # and t in ms
    err = _refused(tmp_path, path, capsys)
    # At 0.1 Hz the noise is not judged; the times and the gravity are.
    assert 'the times look like ms read as seconds (the rate would be 100 Hz' in err
    assert 'rerun with --units time=ms,accel=g ' in err
    fixed, _ = _analyze(tmp_path, path, capsys, '--units', 'gyro=deg/s,accel=g,time=ms')
    assert _unit_warnings(fixed) == []
    assert fixed['sample_rate_hz'] == pytest.approx(RATE_HZ, rel=1e-9)
    for axis in AXES:
        # Only float rounding differs (a unit converted there and back).
        assert_allclose(fixed['axes'][axis]['adev'], si['axes'][axis]['adev'], rtol=1e-9)
        assert_allclose(fixed['axes'][axis]['params']['N']['value'],
                        si['axes'][axis]['params']['N']['value'], rtol=1e-6)


def test_an_accelerometer_in_mg_is_refused_by_name(tmp_path, still, capsys):
    t_s, y = still
    mg = y.copy()
    mg[:, 3:] /= G0_M_S2 * 1e-3
    err = _refused(tmp_path, _csv(tmp_path, 'mg.csv', t_s, mg), capsys)
    assert 'the accelerometer looks like mg (declare --units accel=mg)' in err
    assert 'gyro' not in err
    fixed, _ = _analyze(tmp_path, _csv(tmp_path, 'mg2.csv', t_s, mg), capsys, '--units', 'mg')
    assert _unit_warnings(fixed) == []


def test_declaring_the_si_unit_confirms_values_the_check_doubts(tmp_path, still, capsys):
    # An accelerometer whose output is scaled by 1/g (or has gravity removed) is what
    # the user says it is once declared: no refusal, no warning.
    t_s, y = still
    odd = y.copy()
    odd[:, 3:] /= G0_M_S2
    doc, _ = _analyze(tmp_path, _csv(tmp_path, 'odd.csv', t_s, odd), capsys,
                      '--units', 'accel=m/s^2')
    assert _unit_warnings(doc) == []
    assert_allclose(doc['axes']['accel_z']['adev'][0] * G0_M_S2,
                    _analyze(tmp_path, _csv(tmp_path, 'si.csv', t_s, y), capsys)[0]
                    ['axes']['accel_z']['adev'][0], rtol=1e-9)


def test_raw_counts_are_named_and_their_scale_declared(tmp_path, still, capsys):
    t_s, y = still
    gyro_lsb, accel_lsb = 0.05 * DEG, 3.33e-3 * G0_M_S2      # ADIS16405 counts
    counts = np.round(y / np.repeat([gyro_lsb, accel_lsb], 3))
    path = _csv(tmp_path, 'counts.csv', t_s, counts)
    err = _refused(tmp_path, path, capsys)
    assert err.count('its values are whole numbers, raw counts?') == 2, err
    assert 'rerun with --units accel=<value of one count>,gyro=<value of one count>' in err
    doc, _ = _analyze(tmp_path, path, capsys, '--units', 'gyro=0.05deg/s,accel=3.33mg')
    assert _unit_warnings(doc) == []
    # Counts at about one sd per LSB: the grid is named, in SI (pipeline/resolution.py).
    assert any(w.startswith(f'{COARSE_GRID} on gyro_x, gyro_y, gyro_z: the values lie on a '
                            'grid of 0.000873 rad/s') for w in doc['warnings']), doc['warnings']
    # The same curve as the counts converted to SI beforehand.
    scaled = counts * np.repeat([gyro_lsb, accel_lsb], 3)
    si, _ = _analyze(tmp_path, _csv(tmp_path, 'si.csv', t_s, scaled), capsys)
    for axis in AXES:
        assert_allclose(doc['axes'][axis]['adev'], si['axes'][axis]['adev'], rtol=1e-9)


def test_integer_times_since_1970_read_as_seconds_are_named(tmp_path, still, capsys):
    # ms, us or ns since 1970 in t, read as seconds, overflowed int64 nanoseconds (a
    # ValueError traceback); one line names the unit, and declaring it is the fix.
    t_s, y = still
    for unit, per_s in (('ms', 1e3), ('us', 1e6), ('ns', 1e9)):
        path = _csv(tmp_path, f'epoch_{unit}.csv', (1.7e9 + t_s) * per_s, y)
        err = _refused(tmp_path, path, capsys)
        assert (f'the times look like {unit} read as seconds; rerun with --units '
                f'time={unit}') in err, err
    doc, _ = _analyze(tmp_path, path, capsys, '--units', 'time=ns')
    assert_allclose(doc['sample_rate_hz'], RATE_HZ, rtol=1e-4)
    assert_allclose(stamps_ns(np.array([1.5, -2.0]), 1e-3), [1_500_000, -2_000_000])


def test_a_deg_s_gyro_is_refused_before_the_motion_check_on_real_data(shared_dir, tmp_path,
                                                                      capsys):
    # The ADIS16405 run 1 (rad/s), first 20 min, its gyro converted to deg/s: before,
    # motion lines and exit 3 ('the IMU moved most of the time').
    from imu_allan.io.csv_io import read_csv
    data = read_csv(shared_dir / 'realdata' / 'adis16405' / 'adis16405_run1.csv.gz',
                    columns=list(AXES))
    t_s, y = data.t_s[:120_000], data.samples[:120_000].copy()
    y[:, :3] /= DEG
    err = _refused(tmp_path, _csv(tmp_path, 'adis_deg.csv', t_s, y), capsys)
    assert 'rerun with --units gyro=deg/s' in err and 'motion' not in err


def test_a_moving_robot_is_not_taken_for_a_unit_mistake(shared_dir):
    # Its gyro turns in the first 2 s (variance 27-83x that of its steps): the motion
    # check judges it, not the unit check.
    from imu_allan.core.noise.unit_check import first_look, FIRST_LOOK_ROWS
    from imu_allan.io.inputs import open_input
    for name, rate_hz in (('test1.bag', 30.0), ('test2.bag', 50.0)):
        with open_input(shared_dir / 'realdata' / 'ros1_moving_robot' / name) as source:
            y = next(iter(source.blocks()))[1][:FIRST_LOOK_ROWS]
        assert first_look(rate_hz, y) == [], name


def test_bag_stamps_one_nanosecond_apart_are_named(tmp_path, still, capsys):
    _, y = still
    stamps = 1_700_000_000 * 10 ** 9 + np.arange(y.shape[0], dtype=np.int64)   # a counter
    path = tmp_path / 'counter.mcap'
    write_imu_bag(path, stamps, y)
    # 1 ns apart, the record lasts microseconds: refused, and the error names the unit.
    code = main(['analyze', str(path), '--out', str(tmp_path / 'o'), '--no-plot',
                 '--jobs', '1', '--format', 'json'])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 3 and len(err) == 1, err
    assert 'not enough still data' in err[0] and 'the stamps are 1 ns apart' in err[0], err


@pytest.mark.parametrize('text, expect', [
    ('', ('rad/s', 'm/s^2', None, ())),
    ('gyro=deg/s', ('deg/s', 'm/s^2', None, ('gyro',))),
    ('deg/s, mg, ms', ('deg/s', 'mg', 'ms', ('gyro', 'accel', 'time'))),
    ('accel=g,time=us', ('rad/s', 'g', 'us', ('accel', 'time'))),
    ('accel=m/s^2', ('rad/s', 'm/s^2', None, ('accel',))),
    ('gyro=0.05deg/s,accel=3.33*mg', ('0.05deg/s', '3.33*mg', None, ('gyro', 'accel'))),
])
def test_units_are_parsed(text, expect):
    assert tuple(parse_units(text)) == expect


def test_a_count_scale_gives_its_factor():
    units = parse_units('gyro=0.05deg/s,accel=3.33e-3g')
    assert_allclose(units.sample_scale(), np.repeat([0.05 * DEG, 3.33e-3 * G0_M_S2], 3),
                    rtol=1e-15)


@pytest.mark.parametrize('text, words', [
    ('gyro=rpm', "cannot read 'gyro=rpm'"),
    ('furlongs', "cannot read 'furlongs'"),
    ('g,mg', 'accel given twice'),
    ('gyro=0deg/s', "cannot read 'gyro=0deg/s'"),
    ('time=2ms', "cannot read 'time=2ms'"),
])
def test_bad_units_are_one_line(text, words):
    with pytest.raises(InputError, match=words):
        parse_units(text)


def test_a_bad_units_option_fails_before_the_work(tmp_path, capsys):
    code = main(['analyze', str(tmp_path / 'missing.csv'), '--units', 'gyro=rpm',
                 '--out', str(tmp_path / 'o')])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and '--units: cannot read' in err[0]
    assert not (tmp_path / 'o').exists()


def test_the_limits_sit_between_si_and_the_wrong_units():
    # A still IMU with gravity near z: plausible in SI, named in g and mg.
    rng = np.random.default_rng(2)
    for norm in rng.uniform(9.6, 10.0, 20):
        means = np.r_[rng.uniform(-0.05, 0.05, 3), 0.0, 0.0, norm]
        assert unit_warnings(100.0, means, np.full(3, 9e-4)) == []
        for unit, scale in (('g', G0_M_S2), ('mg', G0_M_S2 * 1e-3)):
            text = unit_warnings(100.0, np.r_[means[:3], means[3:] / scale], None)
            assert len(text) == 1 and f'looks like {unit} ' in text[0]
    # The noisiest MEMS gyro on common datasheets (ADXRS620, 0.05 deg/s/sqrt(Hz)) is
    # plausible in rad/s and named in deg/s; so is a bias of 20 deg/s (MPU-6050 range).
    noisy = 0.05 * DEG
    assert noisy < GYRO_WHITE_MAX < noisy / DEG
    assert 20 * DEG < GYRO_BIAS_MAX < 20.0
    assert unit_warnings(100.0, None, np.full(3, noisy)) == []
    assert unit_warnings(100.0, None, np.full(3, noisy / DEG))[0].startswith(
        'the gyro does not look like rad/s')
    assert 'still bias 20 rad/s' in unit_warnings(
        100.0, np.r_[20.0, 0, 0, 0, 0, G0_M_S2], None)[0]
    no_gravity = unit_warnings(100.0, np.zeros(6), None)
    assert len(no_gravity) == 1 and 'gravity was removed' in no_gravity[0]
    assert 'us stored as ns? (the rate would be 50 Hz' in unit_warnings(5e4, None, None)[0]
    assert 'ms stored as ns? (the rate would be 100 Hz' in unit_warnings(1e8, None, None)[0]
    assert 'the rate would be 1000 Hz; declare --units time=us)' in unit_warnings(
        0.001, None, None)[0]
    assert unit_warnings(1.0, None, None) == unit_warnings(1e4, None, None) == []
    # A 1 Hz IMU whose jittered stamps give a rate a little below 1 Hz is one.
    assert unit_warnings(0.99999, None, None) == unit_warnings(1.00001e4, None, None) == []
    assert 'the rate would be 980 Hz' in unit_warnings(0.98, None, None)[0]


def test_a_short_record_names_what_it_cannot_determine_in_every_output(tmp_path, still,
                                                                       capsys):
    # Issue 35: a record too short for K wrote K into imu.yaml with 'warnings' empty.
    out = tmp_path / 'out'
    code = main(['analyze', str(_csv(tmp_path, 'si.csv', *still)), '--out', str(out),
                 '--no-plot', '--jobs', '1', '--format', 'json'])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    doc = json.loads(captured.out)
    short = [w for w in doc['warnings'] if w.startswith(SHORT_RECORD)]
    k_accel = [w for w in short if 'accelerometer_random_walk (K)' in w]
    assert len(k_accel) == 1 and 'would' in k_accel[0], doc['warnings']
    for fit in (doc['axes'][a] for a in AXES if a.startswith('accel')):
        assert fit['params']['K']['kind'] != 'estimate'
    for w in short:
        assert f'imu-allan: warning: si.csv: {w}' in captured.err
    for name in ('imu.yaml', 'vins_imu.yaml', 'kalibr_imu_chain.yaml', 'ekf_imu.yaml',
                 'imu_driver_noise.yaml', 'kalman_qr.yaml', 'imu_covariance.yaml',
                 'noise_model.yaml'):
        text = (out / name).read_text()
        assert f'# WARNING {k_accel[0]}' in text, name


@pytest.mark.parametrize('accel_sd', [0.3, 8.0])
def test_coarse_raw_counts_with_a_constant_axis_are_named_before_the_motion_check(accel_sd):
    # An MPU-6050 at +-16 g (2048 counts per g) whose gyro and accel_x hold one count
    # through the first samples: before, accel_x counted as no counts, the check saw
    # no unit that explains 2048 "m/s^2", and the motion check called each one-count
    # step motion (exit 0 with motion warnings, or 'the IMU moved most of the time').
    from imu_allan.errors import UnitMistake
    from imu_allan.pipeline.session import Session
    rng = np.random.default_rng(9)
    n = 20_000
    t = 10**18 + np.arange(n, dtype=np.int64) * 10_000_000
    y = np.round(np.hstack([rng.normal(0, 0.3, (n, 3)),
                            rng.normal([20, -30, 2048], [0.1, accel_sd, accel_sd], (n, 3))]))
    session = Session()
    with pytest.raises(UnitMistake) as err:
        for k in range(0, n, 4096):
            session.add(t[k:k + 4096], y[k:k + 4096])
    text = str(err.value)
    assert 'raw counts?' in text and 'the LSB of the range set' in text
    assert 'rerun with --units accel=<value of one count>,gyro=<value of one count>' in text
    assert session.stats.n_motion_events == 0
