"""The Allan sums of a record's stretches (core/allan/stretches.py)."""

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from imu_allan.core.allan import overlapping_avar
from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.core.allan.stretches import (FIRST_STRETCH_ROWS, level_change, MAX_STRETCHES,
                                            StretchSums)
from imu_allan.errors import InputError

RATE_HZ = 100.0


def _acc(y: np.ndarray, blocks=None, missing=None) -> AllanAccumulator:
    acc = AllanAccumulator(y.shape[1], RATE_HZ)
    if blocks is None:
        acc.add(y, missing)
    else:
        for s, e in zip(blocks[:-1], blocks[1:]):
            acc.add(y[s:e], None if missing is None else missing[s:e])
    return acc


def _white(n: int, n_axes: int, seed: int, scale_after=None) -> np.ndarray:
    """White noise of sd 1; from row ``scale_after[0]`` on, sd ``scale_after[1]``."""
    y = np.random.default_rng(seed).standard_normal((n, n_axes))
    if scale_after is not None:
        y[scale_after[0]:] *= scale_after[1]
    return y


def test_the_stretches_add_up_to_the_pooled_sums_and_each_reads_its_own_piece():
    n = 5 * FIRST_STRETCH_ROWS + 1000
    y = _white(n, 2, seed=1)
    acc = _acc(y)
    st = acc.stretches()
    assert_array_equal(st.rows, [FIRST_STRETCH_ROWS] * 5 + [1000])
    curve = acc.curve()
    k0 = st.m.size
    # Pooled: the stretches' terms are the curve's terms (no term counted twice or lost).
    assert_array_equal(st.n_terms.sum(axis=0), curve.n_terms[:k0])
    pooled = np.nansum(st.avar * st.n_terms[:, :, None], axis=0) / st.n_terms.sum(axis=0)[:, None]
    assert_allclose(pooled, curve.avar[:k0], rtol=1e-10)
    # Each full stretch is the overlapping AVAR of its rows, but for the 2m terms that
    # reach back into the previous stretch (under 0.1 % of the terms at m = 8).
    k = int(np.searchsorted(st.m, 8))
    for i in range(5):
        piece = y[i * FIRST_STRETCH_ROWS:(i + 1) * FIRST_STRETCH_ROWS, 0]
        assert_allclose(st.avar[i, k, 0], overlapping_avar(piece, np.array([8]))[0][0],
                        rtol=2e-3)


def test_the_stretches_do_not_depend_on_the_blocks_or_a_checkpoint(tmp_path):
    y = _white(3 * FIRST_STRETCH_ROWS + 777, 3, seed=2)
    whole = _acc(y).stretches()
    cuts = np.sort(np.random.default_rng(3).choice(y.shape[0], 40, replace=False))
    blocks = np.concatenate(([0], cuts, [y.shape[0]]))
    by_blocks = _acc(y, blocks).stretches()
    assert_array_equal(by_blocks.rows, whole.rows)
    assert_allclose(by_blocks.avar, whole.avar, rtol=1e-12)
    first = _acc(y[:50_000])
    first.save(tmp_path / 'acc.npz')
    resumed = AllanAccumulator.load(tmp_path / 'acc.npz')
    resumed.add(y[50_000:])
    assert_array_equal(resumed.stretches().n_terms, whole.n_terms)
    assert_allclose(resumed.stretches().avar, whole.avar, rtol=1e-12)


def test_a_state_without_stretches_loads_and_a_damaged_one_is_refused():
    acc = _acc(_white(40_000, 2, seed=4))
    meta, arrays = acc.to_state()
    old = {k: v for k, v in arrays.items() if not k.startswith('stretch_')}
    # The stretches before such a checkpoint are unknown; those after it are kept.
    assert_array_equal(AllanAccumulator.from_state(meta, old).stretches().rows,
                       [40_000 - FIRST_STRETCH_ROWS])
    bad = dict(arrays, stretch_rows=-arrays['stretch_rows'])
    with pytest.raises(InputError, match='stretch_rows'):
        AllanAccumulator.from_state(meta, bad)


def test_the_stretches_stay_bounded_by_merging_pairs():
    sums = StretchSums(k0=3, n_axes=1)
    rows_total = 0
    for i in range(MAX_STRETCHES + 5):
        sums.add(np.full((3, 1), float(i)), np.full(3, 10, dtype=np.int64), FIRST_STRETCH_ROWS)
        rows_total += FIRST_STRETCH_ROWS
    # 64 full stretches merged into 32 of twice the length, then 5 more chunks: 3 stretches.
    assert sums.n == MAX_STRETCHES // 2 + 3
    assert sums.rows_target == 2 * FIRST_STRETCH_ROWS
    assert sums.rows[:sums.n].sum() == rows_total
    assert sums.sums[:sums.n].sum() == pytest.approx(3 * sum(range(MAX_STRETCHES + 5)))
    assert_array_equal(sums.counts[0], [20, 20, 20])


def test_filled_samples_leave_their_terms_out_of_the_stretches():
    n = 2 * FIRST_STRETCH_ROWS
    y = _white(n, 1, seed=5)
    missing = np.zeros(n, dtype=bool)
    missing[1000:1010] = True
    y[missing] = 0.0
    acc = _acc(y, missing=missing)
    st, curve = acc.stretches(), acc.curve()
    assert_array_equal(st.n_terms.sum(axis=0), curve.n_terms[:st.m.size])
    assert st.n_terms[0, 0] == FIRST_STRETCH_ROWS + 1 - 2 - 11     # M + 1 - 2m, 11 dirty


@pytest.mark.parametrize('hours', [0.5, 1.0, 3.0])
def test_a_steady_white_noise_is_not_called_a_change(hours):
    # 40 seeds x 3 axes per length: Cochran's Q at a white tau (m = 8) is calibrated, so
    # p < 1e-3 is rare (0 of 360 at 1 h in a longer run); p < 0.1 about 10 %.
    n = int(hours * 3600 * RATE_HZ)
    p = []
    for seed in range(40):
        st = _acc(_white(n, 3, seed=100 + seed)).stretches()
        k = int(np.searchsorted(st.m, 8))
        p += [c.p_value for j in range(3) if (c := level_change(st, k, j)) is not None]
    p = np.array(p)
    assert p.size == 120
    assert (p < 1e-3).sum() <= 1
    assert 0.03 <= (p < 0.1).mean() <= 0.2


@pytest.mark.parametrize('hours,step,power', [(0.5, 1.05, 0.5), (1.0, 1.05, 0.9),
                                              (1.0, 1.10, 1.0), (3.0, 1.03, 0.9)])
def test_a_noise_level_that_steps_is_found_and_its_size_estimated(hours, step, power):
    # The white noise's sd steps by ``step`` halfway: power against size (found at
    # p < 1e-3 in at least ``power`` of 10 seeds), and the spread estimate of ln AVAR is
    # near the step's own: sd of two equal halves at +-ln(step^2)/2 is ln(step).
    n = int(hours * 3600 * RATE_HZ)
    found, sd = 0, []
    for seed in range(10):
        st = _acc(_white(n, 1, seed=200 + seed, scale_after=(n // 2, step))).stretches()
        c = level_change(st, int(np.searchsorted(st.m, 8)), 0)
        found += c.p_value < 1e-3
        sd.append(c.sd_log_avar)
    assert found >= power * 10
    if power == 1.0:
        assert_allclose(np.median(sd), np.log(step), rtol=0.3)


def test_a_record_of_few_stretches_is_not_tested():
    st = _acc(_white(3 * FIRST_STRETCH_ROWS, 1, seed=6)).stretches()
    assert level_change(st, int(np.searchsorted(st.m, 8)), 0) is None
