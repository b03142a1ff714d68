"""The covering white + random-walk pair, and the consistency it gives a random-walk filter."""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan.core.noise.generators import white_noise
from imu_allan.core.noise.model import avar_model
from imu_allan.core.noise.simulate import simulate_axis
from imu_allan.core.noise.values import AxisNoise, GaussMarkov, Sinusoid
from imu_allan.core.outputs.consistency import random_walk_filter
from imu_allan.core.outputs.covering import cover_axis, horizon_taus, N_MARGIN
from imu_allan.errors import InputError

RATE_HZ = 100.0
HORIZON_S = (1.0 / RATE_HZ, 100.0)
#: ADIS16405-like gyro: white, Gauss-Markov bias instability, random walk.
GYRO = AxisNoise(N=7.5e-4, B=1.7e-4, T_B=40.0, K=1.4e-5)


def _pair_avar(tau, n, k):
    return n ** 2 / tau + k ** 2 * tau / 3.0


def test_a_white_and_random_walk_model_is_its_own_cover_plus_the_n_margin():
    # The model covers itself exactly; N then gets the run-to-run margin.
    c = cover_axis(AxisNoise(N=2e-4, K=3e-6), HORIZON_S)
    assert_allclose([c.N_cover, c.K_cover], [N_MARGIN * 2e-4, 3e-6], rtol=1e-6)
    assert_allclose([c.factor_N, c.factor_K], [N_MARGIN, 1.0], rtol=1e-6)
    assert 1.0 < c.worst_ratio <= N_MARGIN ** 2 * (1 + 1e-9)


@pytest.mark.parametrize('model', [
    GYRO,
    AxisNoise(N=4.4e-3, B=4.1e-3, K=1.2e-4),                        # flicker
    AxisNoise(N=1e-4, B=5e-5, T_B=3.0, K=1e-6, Q=2e-6,
              gauss_markov=(GaussMarkov(8e-5, 300.0),),
              sinusoids=(Sinusoid(1e-3, 0.05),)),                    # lines, Q, 2 GMs
])
def test_the_cover_bounds_the_whole_model_over_the_horizon_and_no_more(model):
    c = cover_axis(model, HORIZON_S)
    # Between and beyond the programme's own taus: 10x denser grid.
    tau = np.geomspace(*HORIZON_S, 2000)
    ratio = _pair_avar(tau, c.N_cover, c.K_cover) / avar_model(tau, model)
    assert ratio.min() >= 1.0 - 1e-3
    assert c.worst_ratio >= 1.0
    # The factors are derived, not guessed: at least 1, and K grows for bias instability.
    assert c.factor_N >= 1.0 - 1e-9 and c.factor_K > 1.0
    assert c.horizon_s == pytest.approx(HORIZON_S)
    # A longer horizon must cover more of the random walk's range, never less.
    longer = cover_axis(model, (HORIZON_S[0], 1000.0))
    tau_l = np.geomspace(HORIZON_S[0], 1000.0, 500)
    assert np.all(_pair_avar(tau_l, longer.N_cover, longer.K_cover)
                  >= (1 - 1e-3) * avar_model(tau_l, model))


def test_a_bad_horizon_is_one_clear_error():
    with pytest.raises(InputError, match='horizon'):
        horizon_taus((10.0, 1.0))
    with pytest.raises(InputError, match='horizon'):
        cover_axis(GYRO, (0.0, 100.0))


def _record(hours: float, seed: int):
    n = int(hours * 3600 * RATE_HZ)
    rng = np.random.default_rng(seed)
    bias = simulate_axis(AxisNoise(B=GYRO.B, T_B=GYRO.T_B, K=GYRO.K), RATE_HZ, n, rng)
    return bias + white_noise(GYRO.N, RATE_HZ, n, rng), bias


def test_fitted_pair_is_over_confident_the_covering_pair_consistent():
    # A held-out static record of the full model, filtered by the consumers' model (white
    # + bias random walk).  NIS of block means of h seconds scores the predicted angle
    # over the next h seconds (see core/outputs/consistency.py).
    y, _ = _record(2.0, seed=7)
    c = cover_axis(GYRO, HORIZON_S)
    for h in (10.0, 30.0):
        fitted = random_walk_filter(y, RATE_HZ, GYRO.N, GYRO.K, block_s=h, burn_in_s=600)
        cover = random_walk_filter(y, RATE_HZ, c.N_cover, c.K_cover, block_s=h, burn_in_s=600)
        folk = random_walk_filter(y, RATE_HZ, 10 * GYRO.N, 10 * GYRO.K, block_s=h,
                                  burn_in_s=600)
        assert fitted.verdict == 'over-confident', (h, fitted)
        assert fitted.mean_nis > 1.2
        assert cover.mean_nis <= cover.bounds[1], (h, cover)
        assert cover.mean_nis > 0.6, (h, cover)        # not wildly conservative
        assert folk.mean_nis < 0.05, (h, folk)          # 10x is 100x in variance
        assert folk.verdict == 'conservative'


def test_nees_with_the_true_bias_falls_with_the_covering_pair():
    y, bias = _record(1.0, seed=8)
    c = cover_axis(GYRO, HORIZON_S)
    fitted = random_walk_filter(y, RATE_HZ, GYRO.N, GYRO.K, block_s=10.0, truth=bias,
                                burn_in_s=600)
    cover = random_walk_filter(y, RATE_HZ, c.N_cover, c.K_cover, block_s=10.0, truth=bias,
                               burn_in_s=600)
    assert fitted.verdict == 'over-confident' and fitted.mean_nees > 1.5
    assert cover.mean_nees < fitted.mean_nees / 1.5
    assert math.isfinite(cover.mean_nis)
