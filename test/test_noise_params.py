"""Tests of imu_allan.core.noise.units and the parameter files of imu_allan.core.noise.params."""

import math
from pathlib import Path

from numpy.testing import assert_allclose
import pytest
import yaml

from imu_allan import AXES
from imu_allan.core.noise.params import dump_params, load_params, parse_params, save_params
from imu_allan.core.noise.units import format_quoted, parse_unit, quoted, to_si
from imu_allan.core.noise.values import AxisNoise, GaussMarkov, NoiseSpec, Sinusoid
from imu_allan.errors import InputError

CONFIG = Path(__file__).resolve().parents[1] / 'config'
DEG = math.pi / 180.0
G = 9.80665


# --- units -----------------------------------------------------------------------------

@pytest.mark.parametrize('text, key, sensor, si', [
    # Golden values: datasheet figures in SI.
    ('0.007 deg/s/sqrt(Hz)', 'N', 'gyro', 1.2217e-4),
    ('10 deg/h', 'B', 'gyro', 4.8481e-5),
    ('60 ug/sqrt(Hz)', 'N', 'accel', 5.884e-4),
    # 1 deg/sqrt(h) = (pi/180) / 60 rad/s^0.5 (IEEE Std 952 angle random walk unit).
    ('1 deg/sqrt(h)', 'N', 'gyro', DEG / 60.0),
    ('1 deg/rt-hr', 'N', 'gyro', DEG / 60.0),
    ('1 °/√h', 'N', 'gyro', DEG / 60.0),
    ('1 deg/h/rtHz', 'N', 'gyro', DEG / 3600.0),
    ('1 rad/s/sqrt(Hz)', 'N', 'gyro', 1.0),
    ('1 rad/sqrt(s)', 'N', 'gyro', 1.0),
    ('1 deg/h/sqrt(h)', 'K', 'gyro', DEG / 3600.0 ** 1.5),
    ('1 deg/h^1.5', 'K', 'gyro', DEG / 3600.0 ** 1.5),
    ('1 deg/s/sqrt(s)', 'K', 'gyro', DEG),
    ('2 rad/s^1.5', 'K', 'gyro', 2.0),
    ('1 arcsec', 'Q', 'gyro', DEG / 3600.0),
    ('1 deg/h/h', 'R', 'gyro', DEG / 3600.0 ** 2),
    ('1 deg/h^2', 'R', 'gyro', DEG / 3600.0 ** 2),
    ('1 deg/s', 'A', 'gyro', DEG),
    ('1 µg/√Hz', 'N', 'accel', 1e-6 * G),
    ('1 μg/sqrt(Hz)', 'N', 'accel', 1e-6 * G),
    ('1 mg/sqrt(Hz)', 'N', 'accel', 1e-3 * G),
    ('1 m/s/sqrt(h)', 'N', 'accel', 1.0 / 60.0),
    ('1 m/s^1.5', 'N', 'accel', 1.0),
    ('30 ug', 'B', 'accel', 30e-6 * G),
    ('1 g', 'bias', 'accel', G),
    ('1 ug/sqrt(s)', 'K', 'accel', 1e-6 * G),
    ('1 m/s/h/sqrt(h)', 'K', 'accel', 1.0 / 3600.0 ** 1.5),
    ('1 m/s/h^(3/2)', 'K', 'accel', 1.0 / 3600.0 ** 1.5),
    ('1 m/s^2/sqrt(s)', 'K', 'accel', 1.0),
    ('2 min', 'T_B', 'gyro', 120.0),
    ('1.5 h', 'T', 'accel', 5400.0),
    ('0.25 Hz', 'f0_hz', 'gyro', 0.25),
    ('11 mHz', 'f0_hz', 'gyro', 0.011),
    ('1e-4', 'N', 'gyro', 1e-4),   # YAML 1.1 reads 1e-4 as text: a bare number is SI
    (3.5e-3, 'N', 'accel', 3.5e-3),
])
def test_to_si(text, key, sensor, si):
    assert_allclose(to_si(text, key, sensor), si, rtol=1e-4)


@pytest.mark.parametrize('text, key, sensor, needle', [
    ('10 deg/h', 'K', 'gyro', 'K of a gyro'),
    ('1 ug/sqrt(Hz)', 'N', 'gyro_x', 'N of a gyro'),
    ('1 deg/s', 'B', 'accel', 'B of an accel'),
    ('5 m/s^2', 'T_B', 'accel', 'T_B'),
    ('abc', 'N', 'gyro', 'expected a number'),
    ('1 furlong', 'N', 'gyro', "unknown unit 'furlong'"),
    ('1 MHz', 'f0_hz', 'gyro', "unknown unit 'MHz'"),
    ('1 deg/(s', 'B', 'gyro', 'ends unexpectedly'),
    (True, 'N', 'gyro', 'expected a number'),
])
def test_to_si_errors(text, key, sensor, needle):
    with pytest.raises(InputError, match=needle.replace('(', r'\(')):
        to_si(text, key, sensor)


def test_quoted_units_and_round_trip():
    assert quoted('N', 'gyro', DEG / 60.0) == pytest.approx((1.0, 'deg/sqrt(h)'))
    assert quoted('B', 'gyro_z', 4.8481368e-5) == pytest.approx((10.0, 'deg/h'))
    assert quoted('N', 'accel', 5.88399e-4) == pytest.approx((60.0, 'ug/sqrt(Hz)'))
    assert quoted('K', 'accel', G * 1e-6) == pytest.approx((1.0, 'ug/sqrt(s)'))
    for sensor in ('gyro', 'accel'):
        for key in ('N', 'B', 'K', 'Q', 'R', 'A', 'bias', 'T_B', 'T', 'f0_hz'):
            value, unit = quoted(key, sensor, 1.2345e-4)
            assert_allclose(to_si(f'{value!r} {unit}', key, sensor), 1.2345e-4, rtol=1e-12)
    assert format_quoted('N', 'gyro', 1.2217305e-4) == '0.42 deg/sqrt(h)'


def test_parse_unit_dimensions():
    factor, dim = parse_unit('deg/h/h')
    assert_allclose(factor, DEG / 3600.0 ** 2)
    assert dim == (1, 0, -2)
    assert parse_unit('') == (1.0, (0, 0, 0))


# --- parameter files -------------------------------------------------------------------

EXAMPLE = """\
name: Example IMU
axes:
  gyro:   {N: 1.2e-4, B: 5.0e-5, T_B: 80.0, K: 2.0e-6}
  accel:  {N: 6.0e-4, B: 3.0e-4, T_B: 60.0, K: 1.0e-5}
  accel_z: {bias: 9.80665}
  gyro_z: {sinusoid: [{A: 1e-4, f0_hz: 0.011}], gauss_markov: [{B: 1e-4, T: 5.0}],
           Q: 1e-6, R: 1e-7, N: 0.007 deg/s/sqrt(Hz)}
"""


def test_parse_example_groups_and_overrides():
    spec = parse_params(yaml.safe_load(EXAMPLE))
    assert spec.name == 'Example IMU' and tuple(spec.axes) == AXES
    assert spec.axes['gyro_x'] == AxisNoise(N=1.2e-4, B=5e-5, T_B=80.0, K=2e-6)
    assert spec.axes['gyro_y'] == spec.axes['gyro_x']
    gz = spec.axes['gyro_z']
    assert_allclose(gz.N, 1.2217e-4, rtol=1e-4)     # per-axis key overrides the group
    assert (gz.B, gz.T_B, gz.K, gz.Q, gz.R) == (5e-5, 80.0, 2e-6, 1e-6, 1e-7)
    assert gz.gauss_markov == (GaussMarkov(B=1e-4, T=5.0),)
    assert gz.sinusoids == (Sinusoid(A=1e-4, f0_hz=0.011),)
    assert spec.axes['accel_z'].bias == 9.80665 and spec.axes['accel_z'].T_B == 60.0
    assert spec.axes['accel_x'].bias == 0.0


def test_absent_axes_and_flicker():
    spec = parse_params({'axes': {'gyro_x': {'N': 1e-4, 'B': 1e-5}}})
    assert spec.name == ''
    assert spec.axes['gyro_x'].has_flicker
    for axis in AXES[1:]:
        assert spec.axes[axis] == AxisNoise()


@pytest.mark.parametrize('mapping, needles', [
    ({'name': 'x'}, ['p.yaml', 'missing key axes']),
    ({'axes': {}, 'rate': 100}, ['p.yaml', 'rate', 'unknown key']),
    ({'axes': {'gyro_w': {}}}, ['axes.gyro_w', 'unknown axis']),
    ({'axes': {'gyro': {'N': 1e-4, 'BI': 1e-5}}}, ['axes.gyro.BI', 'unknown key']),
    ({'axes': {'accel_y': {'N': -1e-4}}}, ['axes.accel_y.N', '>= 0']),
    ({'axes': {'gyro': {'K': float('nan')}}}, ['axes.gyro.K', 'finite']),
    ({'axes': {'gyro': {'K': float('inf')}}}, ['axes.gyro.K', 'finite']),
    ({'axes': {'gyro': {'B': 1e-5, 'T_B': 0}}}, ['axes.gyro.T_B', '> 0']),
    ({'axes': {'gyro': {'B': 1e-5, 'T_B': '-3 s'}}}, ['axes.gyro.T_B', '> 0']),
    ({'axes': {'gyro_z': {'sinusoid': [{'A': 1e-4, 'f0_hz': 0}]}}},
     ['axes.gyro_z.sinusoid[0].f0_hz', '> 0']),
    ({'axes': {'gyro_z': {'sinusoid': [{'A': 1e-4}]}}},
     ['axes.gyro_z.sinusoid[0]', 'missing key f0_hz']),
    ({'axes': {'gyro_z': {'gauss_markov': [{'B': 1e-4, 'T': 5, 'q': 1}]}}},
     ['axes.gyro_z.gauss_markov[0].q', 'unknown key']),
    ({'axes': {'gyro': {'K': '10 deg/h'}}}, ['axes.gyro.K', "'deg/h'", 'deg/h/sqrt(h)']),
    ({'axes': {'gyro_x': {'N': '60 ug/sqrt(Hz)'}}}, ['axes.gyro_x.N', 'N of a gyro']),
    ({'axes': {'accel': {'B': 'ten ug'}}}, ['axes.accel.B', 'expected a number']),
    ({'axes': {'accel': {'B': [1, 2]}}}, ['axes.accel.B', 'expected a number']),
    ({'axes': {'accel': 5}}, ['axes.accel', 'expected a mapping']),
    ({'axes': {'accel': {'N': True}}}, ['axes.accel.N', 'expected a number']),
])
def test_parse_errors_name_file_axis_and_key(mapping, needles):
    with pytest.raises(InputError) as info:
        parse_params(mapping, source='p.yaml')
    text = str(info.value)
    assert '\n' not in text and text.startswith('p.yaml: ')
    for needle in needles:
        assert needle in text, text


def test_negative_ramp_and_bias_are_allowed():
    spec = parse_params({'axes': {'accel_z': {'bias': -9.80665, 'R': '-2 ug/h'}}})
    assert spec.axes['accel_z'].bias == -9.80665
    assert_allclose(spec.axes['accel_z'].R, -2e-6 * G / 3600.0)


def test_load_params_errors(tmp_path):
    with pytest.raises(InputError, match='cannot read params file'):
        load_params(tmp_path / 'absent.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('axes: {gyro: [1, 2\n')
    with pytest.raises(InputError, match=r'bad.yaml: invalid YAML \(line'):
        load_params(bad)
    empty = tmp_path / 'empty.yaml'
    empty.write_text('# nothing\n')
    with pytest.raises(InputError, match='empty'):
        load_params(empty)
    neg = tmp_path / 'neg.yaml'
    neg.write_text('axes:\n  accel: {N: -60 ug/sqrt(Hz)}\n')
    with pytest.raises(InputError, match='neg.yaml: axes.accel.N: must be >= 0'):
        load_params(neg)


def test_dump_parse_round_trip_is_exact(tmp_path):
    spec = parse_params(yaml.safe_load(EXAMPLE))
    dumped = dump_params(spec)
    assert dumped['axes']['gyro']['T_B'] == 80.0       # common terms use the group
    assert 'N' in dumped['axes']['gyro_z']              # differing terms stay per axis
    assert parse_params(dumped) == spec
    path = tmp_path / 'fit.yaml'
    save_params(spec, path, header='fitted by a test\n\nsecond paragraph')
    assert path.read_text().startswith('# fitted by a test\n#\n')
    assert load_params(path) == spec


def test_dump_with_units_round_trips_to_six_significant_digits():
    spec = NoiseSpec('u', {a: AxisNoise(N=1.234567e-4, B=3.3e-5, T_B=42.0, K=7.5e-7,
                                        bias=(9.80665 if a == 'accel_z' else 0.0))
                           for a in AXES})
    text = yaml.safe_dump(dump_params(spec, with_units=True), allow_unicode=True)
    assert 'deg/sqrt(h)' in text and 'ug/sqrt(Hz)' in text
    back = parse_params(yaml.safe_load(text))
    for axis in AXES:
        a, b = spec.axes[axis], back.axes[axis]
        assert_allclose([b.N, b.B, b.T_B, b.K, b.bias], [a.N, a.B, a.T_B, a.K, a.bias],
                        rtol=5e-6)  # 6 significant digits


@pytest.mark.parametrize('name', ['xsens_mti7.yaml', 'ublox_c102_f9r.yaml',
                                  'xsens_mti7_readoff.yaml', 'ublox_c102_f9r_readoff.yaml'])
def test_shipped_params_files_load(name):
    spec = load_params(CONFIG / name)
    assert ('table 1' if 'readoff' in name else 'table 2') in spec.name
    assert spec.axes['accel_z'].bias == 9.80665
    for axis, noise in spec.axes.items():
        assert noise.N > 0 and noise.B > 0 and noise.T_B > 0 and noise.K > 0, axis
    if name == 'xsens_mti7.yaml':
        # Maia et al., table 2 (X axis, copied to every axis); test_paper.py checks all.
        assert_allclose(spec.axes['gyro_x'].N, 8.4e-5, rtol=1e-12)
        assert_allclose(spec.axes['gyro_y'].B, 6.7e-5, rtol=1e-12)
        assert_allclose(spec.axes['accel_z'].N, 9.6e-4, rtol=1e-12)
