"""Values on a coarse grid (core/noise/rounding.py, pipeline/resolution.py)."""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan import AXES
from imu_allan.core.fit.result import AxisFit, Param
from imu_allan.core.noise.rounding import rounding_effect
from imu_allan.core.noise.values import AxisNoise
from imu_allan.pipeline.resolution import COARSE_GRID, resolution_warnings

RATE_HZ = 100.0


@pytest.mark.parametrize('step_sd', [0.25, 0.5, 1.0, 1.5])
def test_rounding_adds_a_twelfth_of_the_step_squared_while_the_noise_resolves_it(step_sd):
    # Widrow and Kollar: for an sd of at least about half a step the rounding error is
    # uniform and white, so the variance of one sample grows by q^2 / 12.
    rng = np.random.default_rng(3)
    x = rng.standard_normal(1_000_000) + 0.37     # an offset off the grid
    rounded = np.round(x / step_sd) * step_sd
    n_rounded = float(np.std(np.diff(rounded)) / math.sqrt(2.0 * RATE_HZ))
    effect = rounding_effect(step_sd, n_rounded, RATE_HZ)
    # N of the values before rounding: sd 1 per sample.
    assert_allclose(1.0 + effect.n_raise, n_rounded * math.sqrt(RATE_HZ), rtol=0.01)
    assert_allclose(effect.ratio, step_sd / (n_rounded * math.sqrt(RATE_HZ)), rtol=1e-12)


def test_a_grid_the_noise_does_not_resolve_reads_no_share():
    assert rounding_effect(1.0, 0.02, RATE_HZ).n_raise == math.inf      # sd 0.2 steps
    assert rounding_effect(1.0, 0.0, RATE_HZ).ratio == math.inf


def _fits(n_value: float) -> dict:
    n = Param(n_value, (0.99 * n_value, 1.01 * n_value), 'estimate', 'u')
    return {a: AxisFit(nominal={}, optimised={'N': n}, model=AxisNoise(N=n_value), terms=(),
                       notes=()) for a in ('gyro_x', 'gyro_y', 'accel_x')}


def test_a_grid_is_named_per_sensor_from_a_one_percent_raise_on():
    n = 1e-3 / math.sqrt(RATE_HZ)                 # sd 1e-3 per sample
    fine = {'gyro_x': 4e-4, 'gyro_y': 4e-4, 'accel_x': 1e-9}
    assert resolution_warnings(fine, _fits(n), RATE_HZ) == ()           # 0.7 % raise
    coarse = {'gyro_x': 1e-3, 'gyro_y': 1e-3, 'accel_x': 1e-9}
    (line,) = resolution_warnings(coarse, _fits(n), RATE_HZ)
    assert line.startswith(f'{COARSE_GRID} on gyro_x, gyro_y: the values lie on a grid of '
                           '0.001 rad/s (1 times the noise of one sample): rounding raises N '
                           'by 4.4 %')
    (line,) = resolution_warnings({'accel_x': 3e-3}, _fits(n), RATE_HZ)
    assert 'on accel_x' in line and 'not resolved' in line and 'm/s^2' in line
    # Nothing is said of an axis whose N is not an estimate, or without a rate.
    assert resolution_warnings(coarse, {'gyro_x': None}, RATE_HZ) == ()
    assert resolution_warnings(coarse, _fits(n), 0.0) == ()


def test_the_gate_measures_the_grid_of_an_axis_with_two_levels():
    # A gyro rounded to 8 sds reads two levels only (ADIS16405 run 3's gyros so rounded:
    # N 0.43x its clean value, and no word of the grid when two levels were too few).
    from conftest import still_imu
    from imu_allan.pipeline.session import Session
    t, y = still_imu(30_000, seed=6, rate_hz=RATE_HZ)
    sd = np.std(np.diff(y, axis=0), axis=0) / math.sqrt(2.0)
    steps = np.array([8.0, 8.0, 2.0, 1.6, 1.6, 1.6]) * sd
    y = np.round((y - y.mean(axis=0) + 0.3 * steps) / steps) * steps
    assert np.unique(y[:, 0]).size == 2
    s = Session()
    s.add(t, y)
    s.flush()
    got = np.array([s.stats.value_grid[a] for a in AXES])
    assert_allclose(got, steps, rtol=1e-9)
    n = float(sd[0]) / math.sqrt(RATE_HZ)
    line = resolution_warnings(s.stats.value_grid, _fits(n), RATE_HZ)[0]
    assert line.startswith(f'{COARSE_GRID} on gyro_x, gyro_y') and 'not resolved' in line
