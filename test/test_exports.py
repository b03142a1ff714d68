"""Tests of imu_allan.core.outputs.exports: robot_localization, driver and VINS outputs."""

import math

from numpy.testing import assert_allclose
import pytest
import yaml

from imu_allan import AXES
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.outputs.covering import cover_axes, default_horizon
from imu_allan.core.outputs.exports import (driver_noise, driver_yaml, IMU0_CONFIG,
                                            robot_localization_yaml)
from imu_allan.core.outputs.vio import vins_yaml
from imu_allan.errors import InputError

RATE_HZ = 200.0
N = {'gyro_x': 1.0e-4, 'gyro_y': 1.5e-4, 'gyro_z': 1.2e-4,
     'accel_x': 6.0e-4, 'accel_y': 8.0e-4, 'accel_z': 7.0e-4}
K = {'gyro_x': 2e-6, 'gyro_y': 3e-6, 'gyro_z': 2.5e-6,
     'accel_x': 1e-5, 'accel_y': 1.2e-5, 'accel_z': 9e-6}


def _sources(**override):
    out = {a: AxisNoise(N=N[a], B=1e-5, T_B=50.0, K=K[a]) for a in AXES}
    out.update(override)
    return out


def test_ekf_fragment_has_the_keys_robot_localization_reads():
    text = robot_localization_yaml(_sources(), RATE_HZ, '/robot/imu_allan/imu_with_covariance')
    doc = yaml.safe_load(text)
    params = doc['ekf_filter_node']['ros__parameters']
    assert params['imu0'] == '/robot/imu_allan/imu_with_covariance'
    config = params['imu0_config']
    assert len(config) == 15 and all(isinstance(v, bool) for v in config)
    assert tuple(config) == IMU0_CONFIG
    assert config[9:15] == [True] * 6 and not any(config[:9])  # rates and accelerations
    assert params['imu0_remove_gravitational_acceleration'] is True
    assert params['imu0_differential'] is False
    assert params['imu0_queue_size'] >= 10
    for key in ('imu0_twist_rejection_threshold',
                'imu0_linear_acceleration_rejection_threshold'):
        assert params[key] > 0
    assert 'imu0_angular_velocity_rejection_threshold' not in params   # ROS 1 name
    # The comment states what the Allan values set, with the worst-axis stdev.
    assert f'{1.5e-4 * math.sqrt(RATE_HZ):.3e} rad/s' in text
    assert 'process_noise_covariance' in text
    with pytest.raises(InputError):
        robot_localization_yaml(_sources(), RATE_HZ, '')


def test_driver_scalars_are_n_sqrt_rate_and_the_worst_axis():
    d = driver_noise(_sources(), RATE_HZ)
    for a in AXES:
        assert_allclose(d.stdev[a], N[a] * math.sqrt(RATE_HZ), rtol=1e-12)
        assert_allclose(d.variance[a], N[a] ** 2 * RATE_HZ, rtol=1e-12)
    assert_allclose(d.worst['angular_velocity_stdev'], 1.5e-4 * math.sqrt(RATE_HZ), rtol=1e-12)
    assert_allclose(d.worst['linear_acceleration_variance'], 8e-4 ** 2 * RATE_HZ, rtol=1e-12)
    doc = yaml.safe_load(driver_yaml(_sources(), RATE_HZ))
    assert doc['rate_hz'] == RATE_HZ
    assert_allclose(doc['worst']['linear_acceleration_stdev'], 8e-4 * math.sqrt(RATE_HZ),
                    rtol=1e-6)
    assert_allclose(doc['per_axis']['gyro_z']['variance'], 1.2e-4 ** 2 * RATE_HZ, rtol=1e-6)


def test_an_axis_without_white_noise_is_unknown_not_trusted():
    # gyro_y without N: null in the driver file and left out of the worst axis.
    d = driver_noise(_sources(gyro_y=AxisNoise()), RATE_HZ)
    assert d.stdev['gyro_y'] is None and d.variance['gyro_y'] is None
    assert_allclose(d.worst['angular_velocity_stdev'], 1.2e-4 * math.sqrt(RATE_HZ), rtol=1e-12)
    doc = yaml.safe_load(driver_yaml(_sources(gyro_y=AxisNoise()), RATE_HZ))
    assert doc['per_axis']['gyro_y']['stdev'] is None


def _vins(text: str) -> dict:
    """Return the VINS keys (OpenCV YAML: PyYAML reads it after the header line)."""
    head, _, body = text.partition('\n')
    assert head == '%YAML:1.0'
    return yaml.safe_load(body)


def test_vins_block_holds_the_worst_covering_values_per_step():
    # Without covers given, the file makes them over the default horizon (one rule for
    # every random-walk consumer); the worst axis, per step.
    covers = cover_axes(_sources(), default_horizon(RATE_HZ))
    doc = _vins(vins_yaml(_sources(), RATE_HZ))
    for key, axes, sym, scale in (('acc_n', AXES[3:], 'N_cover', math.sqrt(2 * RATE_HZ)),
                                  ('gyr_n', AXES[:3], 'N_cover', math.sqrt(2 * RATE_HZ)),
                                  ('acc_w', AXES[3:], 'K_cover', math.sqrt(RATE_HZ)),
                                  ('gyr_w', AXES[:3], 'K_cover', math.sqrt(RATE_HZ))):
        want = max(getattr(covers[a], sym) for a in axes) * scale
        assert_allclose(doc[key], want, rtol=1e-6)
    # Never below the worst reported values.
    assert doc['acc_n'] >= 8e-4 * math.sqrt(2 * RATE_HZ)
    assert doc['gyr_w'] >= 3e-6 * math.sqrt(RATE_HZ)
    # A model without a random walk on any gyro axis: the pair's walk is what covers
    # the model (next to nothing for white noise alone), never 0.
    no_k = {a: AxisNoise(N=N[a]) for a in ('gyro_x', 'gyro_y', 'gyro_z')}
    doc = _vins(vins_yaml(_sources(**no_k), RATE_HZ))
    assert 0 < doc['gyr_w'] < 3e-6 * math.sqrt(RATE_HZ)
    assert all(v > 0 for v in doc.values())
    # No noise at all on the gyros (no term, no curve): the keys are left out, never 0.
    text = vins_yaml(_sources(**{a: AxisNoise() for a in AXES[:3]}), RATE_HZ)
    doc = _vins(text)
    assert 'gyr_w' not in doc and '# gyr_w: not available' in text
    assert all(v > 0 for v in doc.values())


def test_the_curve_bound_of_k_holds_the_truth_at_95_percent():
    """The last resort of a consumer file: K from the curve alone, a 95 % bound."""
    import numpy as np
    from imu_allan.core.allan import allan_curve
    from imu_allan.core.fit.result import AxisFit
    from imu_allan.core.noise.simulate import simulate_axis
    from imu_allan.core.outputs.exports import sensor_value
    truth = AxisNoise(N=1e-3, K=1e-4)
    held = 0
    for seed in range(10):
        y = simulate_axis(truth, 100.0, 360_000, np.random.default_rng(seed))
        c = allan_curve(y, 100.0, 'octave', confidence=0.95)
        fit = AxisFit(terms=('white',), nominal={}, optimised={}, model=None, notes=(),
                      tau_s=c.tau_s, avar_meas=c.avar[:, 0], edf=c.edf[:, 0])
        got = sensor_value({a: fit for a in ('x', 'y', 'z')}, ('x', 'y', 'z'), 'K')
        assert got.kind == 'curve_bound'
        raw_min = math.sqrt(np.min(3.0 * c.avar[:, 0] / c.tau_s))
        assert got.value >= raw_min
        held += got.value >= truth.K
    assert held >= 9
