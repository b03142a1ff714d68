"""Dropped messages: short gaps filled and marked, long ones split (pipeline/fills.py)."""

import re

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.values import AxisNoise, NoiseSpec
from imu_allan.core.search import search_axis
from imu_allan.pipeline.fills import fill_rows, filled
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session

RATE_HZ = 100.0
T0_NS = 1_700_000_000_000_000_000
TRUTH = AxisNoise(N=1e-3, B=6e-4, T_B=10.0, K=2e-5)


def _stamps(n: int) -> np.ndarray:
    return T0_NS + np.round(np.arange(n) * 1e9 / RATE_HZ).astype(np.int64)


def _still(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    y = rng.normal(0.0, [1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2], (n, 6))
    y[:, 5] += 9.80665
    return _stamps(n), y


def _feed(session: Session, t, y, seed: int | None = None, block: int = 5_000) -> Session:
    """Feed in blocks of ``block`` rows, or of random sizes up to it with a seed."""
    rng = None if seed is None else np.random.default_rng(seed)
    k = 0
    while k < t.size:
        n = block if rng is None else int(rng.integers(1, block))
        session.add(t[k:k + n], y[k:k + n])
        k += n
    session.flush()
    return session


def _lose(n: int, share: float, burst: int, seed: int, long_s: float = 30.0) -> np.ndarray:
    """Keep-mask: ``share`` of the samples lost in bursts of 1..burst, one long gap."""
    rng = np.random.default_rng(seed)
    keep = np.ones(n, bool)
    if burst == 1:
        keep &= rng.random(n) >= share
    else:
        # Bursts of 1..burst on a grid of burst + 1, so that no two of them merge.
        slots = rng.choice(n // (burst + 1), int(share * n / ((burst + 1) / 2)), replace=False)
        for s, k in zip(slots * (burst + 1), rng.integers(1, burst + 1, slots.size)):
            keep[s:s + k] = False
    keep[[0, -1]] = True
    keep[n // 2:n // 2 + int(long_s * RATE_HZ)] = False
    return keep


def test_fills_are_marked_and_nothing_else_is():
    rng = np.random.default_rng(1)
    left, right = rng.normal(size=(3, 6)), rng.normal(size=(3, 6))
    right[1, :5] = left[1, :5]                      # five held axes: still a fill
    right[2] = left[2]                              # all six held: a repeat, not marked
    rows = fill_rows(left, right, np.array([1, 2, 3]))
    assert rows.shape == (6, 6)
    # Linear interpolation to 4e-9 of the values (the mark is in the low bits).
    assert_allclose(rows[2], left[1] + 2 * (right[1] - left[1]) / 3, rtol=4e-9)
    # Held values untouched, but for one that carries the second tag.
    assert_array_equal(rows[1:3, 1:5], left[[1, 1], 1:5])
    assert_allclose(rows[1:3, 0], left[[1, 1], 0], rtol=4e-9)
    assert_array_equal(rows[3:], left[[2, 2, 2]])
    assert_array_equal(filled(rows), [True, True, True, False, False, False])
    # Samples from float32 (as Imu messages carry them) or from text never look filled.
    assert filled(rng.normal(size=(100_000, 6)).astype(np.float32).astype(float)) is None
    assert filled(np.round(rng.normal(size=(100_000, 6)), 6)) is None
    # Nor float64 arithmetic: one value in about 17 M ends in the tag by chance, and a
    # row needs two (one tag alone marked about 2 rows of a 3 h, 400 Hz record).
    y = rng.normal(size=(2_000_000, 6))
    one = ((y[:1000].view(np.uint64) & np.uint64(0xFFFFFF)) | np.uint64(0xA5C3E1))
    y[:1000, 0] = one[:, 0].view(np.float64)
    assert filled(y) is None


def test_a_short_gap_is_filled_counted_and_does_not_split():
    t, y = _still(30_000, seed=2)
    keep = np.ones(t.size, bool)
    keep[[5_000, 9_000, 9_001, 9_002]] = False      # one lost message, then three
    keep[20_000:20_100] = False                     # and 1 s: a long gap
    s = _feed(Session(), t[keep], y[keep])
    st = s.stats
    assert (st.n_gaps, st.n_short_gaps, st.n_missing, st.n_filled) == (3, 2, 104, 4)
    assert st.n_used == keep.sum() and s.acc.n_missing == 4
    assert s.acc.n_segments == 2                    # split at the long gap only
    assert s.warnings[0] == ('0.3 % of samples missing (104 in 3 gaps): 2 short gaps of up '
                             'to 8 samples filled (no Allan term at short taus uses a filled '
                             'sample), 1 long gap split the record')
    # With max_fill_samples=0 every gap splits, as before.
    old = _feed(Session(SessionConfig(max_fill_samples=0)), t[keep], y[keep])
    assert old.acc.n_segments == 4 and old.stats.n_short_gaps == 0


def test_short_gaps_give_the_same_result_for_any_blocks_and_a_resume(tmp_path):
    t, y = _still(12_000, seed=3)
    keep = _lose(t.size, 0.03, 4, seed=4, long_s=2.0)
    t, y = t[keep], y[keep]
    whole = _feed(Session(), t, y, block=t.size)
    assert whole.acc.n_segments == 2 and whole.stats.n_short_gaps > 100
    for seed, block in [(5, 3), (6, 900)]:
        s = _feed(Session(), t, y, seed=seed, block=block)
        assert s.stats == whole.stats and s.warnings == whole.warnings
        assert_array_equal(s.curve().avar, whole.curve().avar)
    # A checkpoint just before a short gap: the resumed session fills it.
    cut = int(np.flatnonzero(np.diff(t) == 3 * 10_000_000)[5]) + 1
    first = _feed(Session(), t[:cut], y[:cut], seed=7, block=700)
    first.save_state(tmp_path / 'state.npz')
    resumed = _feed(Session.load_state(tmp_path / 'state.npz'), t[cut:], y[cut:], seed=8,
                    block=700)
    assert resumed.stats == whole.stats
    assert_allclose(resumed.curve().avar, whole.curve().avar, rtol=1e-12)


@pytest.fixture(scope='module')
def simulated():
    """One hour at 100 Hz: gyro_x of TRUTH, white noise elsewhere; its clean fit."""
    _, y = simulate_imu(NoiseSpec(name='t', axes={'gyro_x': TRUTH}), RATE_HZ, 3600.0, seed=3)
    y[:, 1:] = np.random.default_rng(9).normal(0.0, 1e-3, (y.shape[0], 5))
    t = _stamps(y.shape[0])
    return t, y, _fit(_feed(Session(), t, y, block=100_000))


def _fit(session: Session):
    c = session.curve(confidence=0.95)
    return search_axis(c.tau_s, c.avar[:, 0], c.edf[:, 0], RATE_HZ, session.stats.n_used,
                       unit='rad/s').fit


@pytest.mark.parametrize('share,burst', [(0.005, 1), (0.02, 1), (0.10, 1), (0.02, 8)])
def test_dropped_messages_keep_the_clean_records_intervals(simulated, share, burst):
    # The case: messages lost at random (or in bursts of up to 8) and one 30 s
    # hiccup.  The record stays two segments, the warning says how much was missing,
    # and N, B and K keep the clean record's verdicts, their intervals overlapping.
    t, y, clean = simulated
    keep = _lose(t.size, share, burst, seed=5)
    s = _feed(Session(), t[keep], y[keep], block=100_000)
    assert s.acc.n_segments == 2
    lost = 1.0 - keep.mean()
    found = re.match(r'([\d.]+) % of samples missing .* 1 long gap split the record$',
                     s.warnings[0])
    assert found and float(found[1]) == pytest.approx(100 * lost, abs=0.05)
    fit = _fit(s)
    for name in ('N', 'B', 'K'):
        p, q = fit.optimised[name], clean.optimised[name]
        # The same verdict as the clean record: an estimate (K's interval may reach 0
        # after an hour: then both are 95 % bounds, and of about the same height).
        assert p.kind == q.kind and p.kind in ('estimate', 'upper_bound'), (name, p, q)
        assert p.ci95[0] <= q.ci95[1] and q.ci95[0] <= p.ci95[1], (name, p, q)
        if p.kind == 'upper_bound':
            assert p.value == pytest.approx(q.value, rel=0.5), (name, p, q)
    assert fit.optimised['N'].value == pytest.approx(clean.optimised['N'].value, rel=0.01)
