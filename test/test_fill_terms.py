"""Tests of the terms over filled samples: left out at short taus, repaired beyond."""

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from conftest import white_rw_offset
from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.core.allan.fill_terms import gap_excess


def _skip_avar(y: np.ndarray, miss: np.ndarray, m: int) -> tuple[np.ndarray, int]:
    """Batch overlapping AVAR over the terms whose 2m samples hold no missing one."""
    x = np.zeros((y.shape[0] + 1, y.shape[1]))
    np.cumsum(y - y.mean(axis=0), axis=0, out=x[1:])
    c = np.concatenate(([0], np.cumsum(miss)))
    i = np.arange(y.shape[0] + 1 - 2 * m)
    i = i[c[i + 2 * m] == c[i]]
    d = x[i + 2 * m] - 2.0 * x[i + m] + x[i]
    return (d * d).sum(axis=0) / (2.0 * m * m * i.size), i.size


def test_missing_samples_leave_their_terms_out_at_short_taus(tmp_path):
    # 2 % of the samples lost at random and filled: where at least half of a tau's
    # terms are free of them, the curve is the batch estimator over those terms alone;
    # beyond, every term counts, by the share of real samples.
    y = white_rw_offset(150_000, 6, seed=21)
    rng = np.random.default_rng(22)
    miss = rng.random(y.shape[0]) < 0.02
    miss[[0, -1]] = False
    i = np.arange(y.shape[0])
    for a in range(6):                              # filled by linear interpolation
        y[miss, a] = np.interp(i[miss], i[~miss], y[~miss, a])
    whole = AllanAccumulator(6, 100.0, exact_max_m=512)
    whole.add(y, missing=miss)
    c = whole.curve()
    assert whole.n_missing == miss.sum()
    short = c.m[c.m <= 16]
    for k, m in enumerate(short.tolist()):
        ref, n = _skip_avar(y, miss, m)
        assert c.n_terms[k] == n and n >= 0.5 * (y.shape[0] + 1 - 2 * m)
        assert_allclose(c.avar[k], ref, rtol=1e-9)
    real = 1.0 - miss.mean()
    far = (c.m > 64) & (c.m <= 512)
    assert_allclose(c.n_terms[far], np.round((y.shape[0] + 1 - 2 * c.m[far]) * real),
                    atol=1)
    # Any blocks, and a save and load midstream, give the same sums.
    many = AllanAccumulator(6, 100.0, exact_max_m=512)
    start = 0
    while start < 70_000:
        k = int(rng.integers(1, 3000))
        many.add(y[start:start + k], missing=miss[start:start + k])
        start += k
    many.save(tmp_path / 'acc.npz')
    back = AllanAccumulator.load(tmp_path / 'acc.npz')
    back.add(y[start:], missing=miss[start:])
    b = back.curve()
    assert back.n_missing == whole.n_missing
    assert_array_equal(b.n_terms, c.n_terms)
    assert_allclose(b.avar, c.avar, rtol=1e-12)


@pytest.mark.parametrize('share,burst', [(0.10, 1), (0.05, 8)])
def test_filled_taus_take_off_the_fills_white_noise_excess(share, burst):
    # Interpolated fills read white noise about share * (1 + g / 2) high where the
    # filled terms are used; the excess is taken off, so the curve stays the clean
    # record's (the same samples with nothing lost) to 1.5 %, averaged over six axes.
    rng = np.random.default_rng(31)
    n = 300_000
    y = rng.normal(0.0, 1.0, (n, 6)) + np.cumsum(rng.normal(0.0, 2e-3, (n, 6)), axis=0)
    miss = np.zeros(n, bool)
    starts = np.flatnonzero(rng.random(n) < share / burst)
    for k in range(burst):
        miss[np.minimum(starts + k, n - 1)] = True
    miss[[0, -1]] = False
    filled = y.copy()
    i = np.arange(n)
    for a in range(6):
        filled[miss, a] = np.interp(i[miss], i[~miss], y[~miss, a])
    clean, lossy = (AllanAccumulator(6, 100.0, exact_max_m=1024) for _ in range(2))
    clean.add(y)
    lossy.add(filled, missing=miss)
    a, b = clean.curve(), lossy.curve()
    assert_array_equal(a.m, b.m)
    ratio = (b.avar / a.avar).mean(axis=1)
    mid = (a.m >= 3) & (a.m <= 256)
    assert_allclose(ratio[mid], 1.0, atol=0.015)


def test_gap_excess_sums_g_plus_half_g_squared_however_blocks_cut_gaps():
    # K = sum over gaps of g + g^2 / 2, whatever blocks the gaps straddle.
    rng = np.random.default_rng(41)
    miss = rng.random(5000) < 0.3
    edges = np.flatnonzero(np.diff(np.concatenate(([0], miss.astype(int), [0]))))
    gaps = edges[1::2] - edges[::2]
    expected = float(np.sum(gaps + gaps ** 2 / 2.0))
    cuts = np.sort(rng.choice(np.arange(1, miss.size), 40, replace=False))
    total, run = 0.0, 0
    for block in np.split(miss, cuts):
        excess, run = gap_excess(block, run)
        total += excess
    assert_allclose(total, expected, rtol=1e-12)
    assert run == (gaps[-1] if miss[-1] else 0)
    assert gap_excess(np.zeros(4, bool), 3) == (0.0, 0)
