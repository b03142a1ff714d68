"""Tests of the streaming accumulator's window passes against the plain formula."""

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from imu_allan.core.allan.window_sums import accumulate, dirty_terms, phase


def _terms(x: np.ndarray, j: np.ndarray, m: int) -> np.ndarray:
    """Squared second differences (X[j] - 2 X[j - m] + X[j - 2m])^2, shape (n_axes, j.size)."""
    d = x[:, j] - 2.0 * x[:, j - m] + x[:, j - 2 * m]
    return d * d


def test_phase_is_the_centred_running_sum():
    rng = np.random.default_rng(51)
    win = rng.normal(3.0, 1.0, (2, 50))
    x = np.empty((2, 51))
    mean = phase(win, x)
    assert_allclose(mean, win.mean(axis=1), rtol=1e-15)
    assert_array_equal(x[:, 0], 0.0)
    assert_allclose(x[:, 1:], np.cumsum(win - mean[:, None], axis=1), atol=1e-12)


@pytest.mark.parametrize('width', [None, 7])
def test_accumulate_adds_the_terms_that_end_in_the_window(width):
    rng = np.random.default_rng(52)
    x = np.cumsum(rng.normal(size=(2, 301)), axis=1)
    ms = np.array([1, 3, 10, 200])
    sums, counts = np.zeros((5, 2)), np.zeros(5, np.int64)
    tile = None if width is None else np.empty((2, width))
    accumulate(x, 40, 300, ms, sums, counts, 1, None, tile)
    assert_array_equal(sums[0], 0.0)
    for k, m in enumerate(ms.tolist()):
        j = np.arange(max(40, 2 * m), 301)
        assert counts[k + 1] == j.size
        assert_allclose(sums[k + 1], _terms(x, j, m).sum(axis=1) if j.size else 0.0,
                        rtol=1e-12)


@pytest.mark.parametrize('share', [0.01, 0.4])
def test_dirty_terms_sum_the_terms_over_missing_samples(share):
    # Few dirty terms are summed, many are the total less the clean ones: both the same.
    rng = np.random.default_rng(53)
    w = 400
    x = np.cumsum(rng.normal(size=(3, w + 1)), axis=1)
    miss = rng.random(w) < share
    ms = np.array([1, 2, 8, 30])
    totals, all_counts = np.zeros((4, 3)), np.zeros(4, np.int64)
    accumulate(x, 1, w, ms, totals, all_counts, 0)
    sums, counts = np.zeros((4, 3)), np.zeros(4, np.int64)
    dirty_terms(x, miss, 1, ms, totals, sums, counts)
    n_miss = np.concatenate(([0], np.cumsum(miss)))
    for k, m in enumerate(ms.tolist()):
        j = np.arange(2 * m, w + 1)
        j = j[n_miss[j] > n_miss[j - 2 * m]]
        assert counts[k] == j.size
        assert_allclose(sums[k], _terms(x, j, m).sum(axis=1), rtol=1e-9, atol=1e-9)
