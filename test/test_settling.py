"""
Where a record's output settled after power-on (imu_allan.core.allan.settling).

Seeded records of 30 min at 10 Hz: white, Gauss-Markov and random-walk noise, with and
without a transient at the start (an exponential, a ramp to a level, two time
constants).
"""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan.core.allan.settling import find_settling, nnls_few
from imu_allan.core.noise.simulate import simulate_axis
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.rules import SETTLE_LEFT, SETTLE_SCORE

RATE_HZ = 10.0
N_ROWS = 18_000          # 30 min
#: Per axis: white 2e-3, bias instability 2e-4 (Gauss-Markov 100 s on three axes,
#: flicker on the others), random walk 2e-6 [unit, s].
NOISE = [AxisNoise(N=2e-3, B=2e-4, T_B=100.0 if j % 2 else None, K=2e-6) for j in range(6)]


def _clean(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.stack([simulate_axis(NOISE[j], RATE_HZ, N_ROWS, rng) for j in range(6)], axis=1)


def _t_s() -> np.ndarray:
    return np.arange(N_ROWS) / RATE_HZ


@pytest.mark.parametrize('seed', range(4))
def test_a_clean_record_is_not_cut(seed):
    found = find_settling(_clean(seed), RATE_HZ)
    assert found.cut_rows == 0 and found.transients == ()


def test_an_exponential_is_cut_where_what_is_left_is_one_wander():
    y = _clean(10)
    y[:, 1] += 0.02 * np.exp(-_t_s() / 120.0)
    found = find_settling(y, RATE_HZ)
    assert found.axes == (1,)
    first = found.transients[0]
    assert_allclose(first.amplitude, 0.02, rtol=0.3)
    assert_allclose(first.tau_s, 120.0, rtol=0.4)
    assert first.score > SETTLE_SCORE
    # Cut where a exp(-t / tau) is down to SETTLE_LEFT wanders: within 25 % of the time
    # the true transient takes to get there.
    true_s = 120.0 * math.log(0.02 / (SETTLE_LEFT * first.wander))
    assert_allclose(found.cut_s, true_s, rtol=0.25)
    assert not found.capped


@pytest.mark.parametrize('shape', ['ramp', 'two'])
def test_a_ramp_to_a_level_and_two_time_constants_are_cut_after_they_end(shape):
    y = _clean(11)
    t = _t_s()
    if shape == 'ramp':       # 0.02 falling linearly to the level over 8 min
        bump = 0.02 * np.clip(1 - t / 480.0, 0, None)
        end_s = 480.0
    else:                     # 0.02 over 30 s plus 0.01 over 180 s
        bump = 0.02 * np.exp(-t / 30.0) + 0.01 * np.exp(-t / 180.0)
        end_s = 180.0 * math.log(0.01 / 4e-4)
    y[:, 4] += bump
    found = find_settling(y, RATE_HZ)
    assert found.axes == (4,)
    # A ramp's cut is late: the two time constants that fit it best have a slow tail.
    assert end_s * 0.7 < found.cut_s < end_s * 2.5, found
    # What is left after the cut is within a few wanders of the level (one, for the
    # shape the fit assumes).
    wander = min(t.wander for t in found.transients)
    assert np.abs(bump[found.cut_rows:]).max() < 3 * wander


def test_the_cut_is_capped_and_says_it_was_still_settling():
    y = _clean(12)
    y[:, 3] += 0.05 * np.exp(-_t_s() / 300.0)
    free = find_settling(y, RATE_HZ)
    capped = find_settling(y, RATE_HZ, max_cut_rows=3000)
    assert free.cut_rows > 3000 and not free.capped
    assert capped.cut_rows == 3000 and capped.capped
    assert capped.needed_rows == free.needed_rows
    assert_allclose(capped.left_at_cut(3), 0.05 * math.exp(-300.0 / 300.0), rtol=0.4)


def test_a_frozen_axis_and_a_short_stretch_are_not_judged():
    y = _clean(13)
    y[:, 2] = 0.25
    assert find_settling(y, RATE_HZ).transients == ()
    assert find_settling(y[:20], RATE_HZ).cut_rows == 0


def test_the_small_nnls_equals_scipys():
    # numpy only (the main process of an analysis imports no scipy.optimize), exact.
    from scipy.optimize import nnls

    rng = np.random.default_rng(5)
    for _ in range(300):
        a = rng.normal(size=(int(rng.integers(3, 12)), 3))
        b = rng.normal(size=a.shape[0])
        assert_allclose(nnls_few(a, b), nnls(a, b)[0], atol=1e-10)
