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
                                             parse_units, unit_warnings)
from imu_allan.errors import InputError
from imu_allan.io.bag_writer import write_imu_bag
from imu_allan.io.csv_io import write_csv

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
    assert doc['warnings'] == []


def test_each_wrong_unit_is_named_and_declaring_it_gives_the_si_numbers(tmp_path, still,
                                                                        capsys):
    t_s, y = still
    si, _ = _analyze(tmp_path, _csv(tmp_path, 'si.csv', t_s, y), capsys)
    wrong = y.copy()
    wrong[:, :3] /= DEG                      # gyro in deg/s
    wrong[:, 3:] /= G0_M_S2                  # accelerometer in g
    doc, err = _analyze(tmp_path, _csv(tmp_path, 'deg_g.csv', t_s, wrong), capsys)
    _named(doc, err, 'the gyro does not look like rad/s')
    _named(doc, err, 'the accelerometer looks like g (declare --units accel=g)')
    path = _csv(tmp_path, 'deg_g_ms.csv', t_s * 1e3, wrong)      # and t in ms
    # At the 0.1 Hz the stamps then claim, the record is refused or warned; either way
    # the unit mistake is named.
    code = main(['analyze', str(path), '--out', str(tmp_path / 'ms'), '--no-plot', '--jobs',
                 '1', '--format', 'json'])
    err = capsys.readouterr().err
    assert code in (0, 3), err
    assert 'the times look like ms read as seconds (the rate would be 100 Hz' in err, err
    fixed, _ = _analyze(tmp_path, path, capsys, '--units', 'gyro=deg/s,accel=g,time=ms')
    assert fixed['warnings'] == []
    assert fixed['sample_rate_hz'] == pytest.approx(RATE_HZ, rel=1e-9)
    for axis in AXES:
        # Only float rounding differs (a unit converted there and back).
        assert_allclose(fixed['axes'][axis]['adev'], si['axes'][axis]['adev'], rtol=1e-9)
        assert_allclose(fixed['axes'][axis]['params']['N']['value'],
                        si['axes'][axis]['params']['N']['value'], rtol=1e-6)


def test_an_accelerometer_in_mg_is_named(tmp_path, still, capsys):
    t_s, y = still
    mg = y.copy()
    mg[:, 3:] /= G0_M_S2 * 1e-3
    doc, err = _analyze(tmp_path, _csv(tmp_path, 'mg.csv', t_s, mg), capsys)
    _named(doc, err, 'the accelerometer looks like mg (declare --units accel=mg)')
    assert len(doc['warnings']) == 1
    fixed, _ = _analyze(tmp_path, _csv(tmp_path, 'mg2.csv', t_s, mg), capsys, '--units', 'mg')
    assert fixed['warnings'] == []


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
    ('', ('rad/s', 'm/s^2', None)),
    ('gyro=deg/s', ('deg/s', 'm/s^2', None)),
    ('deg/s, mg, ms', ('deg/s', 'mg', 'ms')),
    ('accel=g,time=us', ('rad/s', 'g', 'us')),
])
def test_units_are_parsed(text, expect):
    assert tuple(parse_units(text)) == expect


@pytest.mark.parametrize('text, words', [
    ('gyro=rpm', "cannot read 'gyro=rpm'"),
    ('furlongs', "cannot read 'furlongs'"),
    ('g,mg', 'accel given twice'),
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
