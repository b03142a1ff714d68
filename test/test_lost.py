"""Messages lost on irregular (host) stamps: found from the spread of the counts, named."""

import math

import numpy as np
from numpy.testing import assert_allclose

from conftest import T0_NS
from imu_allan.core.rules import LOST_FANO
from imu_allan.pipeline.hygiene import HygieneStats, WarningLog
from imu_allan.pipeline.lost import LostWatch
from imu_allan.pipeline.session import Session

RATE_HZ = 100.0


def _host_stamps(duration_s: float, seed: int) -> np.ndarray:
    """Stamps [ns] of a 100 Hz sensor whose buffer a host reads every 20-60 ms (bursts)."""
    rng = np.random.default_rng(seed)
    sampled = np.arange(int(duration_s * RATE_HZ)) / RATE_HZ
    reads = np.cumsum(rng.uniform(0.02, 0.06, int(duration_s / 0.02)))
    read = np.searchsorted(reads, sampled)          # the read that delivers each sample
    place = np.arange(read.size) - np.searchsorted(read, read)    # its place in the burst
    t = reads[np.minimum(read, reads.size - 1)] + 0.002 * place
    return T0_NS + np.round(np.maximum.accumulate(t) * 1e9).astype(np.int64)


def _watch(stamp_ns: np.ndarray, block: int = 997) -> LostWatch:
    stats = HygieneStats(irregular_stamps=True)
    watch = LostWatch(stats, WarningLog())
    for k in range(0, stamp_ns.size, block):
        watch.take(stamp_ns[k:k + block])
    return watch


def test_messages_lost_at_random_are_told_from_a_host_reading_in_bursts():
    t = _host_stamps(600.0, seed=1)
    assert np.median(np.diff(t)) < 0.5 * np.mean(np.diff(t))   # bursts: no step shows a loss
    clean = _watch(t)
    assert clean.fano < LOST_FANO / 2 and not clean._warn.lines
    keep = np.random.default_rng(2).random(t.size) >= 0.1
    lost = _watch(t[keep])
    # Binomial thinning: the counts' variance over their mean grows by the share lost.
    assert_allclose(lost.fano, 0.1, atol=0.05)
    line = lost._warn.lines[0]
    assert line.startswith('messages lost') and 'irregular stamps' in line
    # The verdict does not depend on the blocks.
    assert_allclose(_watch(t[keep], block=64).fano, lost.fano, rtol=1e-12)


def test_regular_stamps_and_breaks_are_not_counted_as_losses():
    t = _host_stamps(600.0, seed=3)
    stats = HygieneStats()          # regular stamps: the stamp clock counts their gaps
    watch = LostWatch(stats, WarningLog())
    keep = np.random.default_rng(4).random(t.size) >= 0.2
    watch.take(t[keep])
    assert watch.fano > LOST_FANO and not watch._warn.lines
    # A segment break leaves its window out; a clock restart starts the windows again.
    w = LostWatch(HygieneStats(irregular_stamps=True), WarningLog())
    w.take(t[:30_000])
    n = w.sums[0]
    w.end_segment()
    w.take(t[30_000:31_000] - 10**12)
    assert w.sums[0] == n and w.origin_ns == t[30_000] - 10**12


def test_a_session_on_host_stamps_names_the_loss():
    t = _host_stamps(600.0, seed=5)
    keep = np.random.default_rng(6).random(t.size) >= 0.1
    y = np.random.default_rng(7).standard_normal((t.size, 6)) * 1e-3 + [0, 0, 0, 0, 0, 9.8]
    s = Session()
    for k in range(0, int(keep.sum()), 4096):
        s.add(t[keep][k:k + 4096], y[keep][k:k + 4096])
    s.flush()
    assert s.stats.irregular_stamps
    # The mean rate of what arrived: low by the share lost (N reads high by its root).
    assert_allclose(s.rate_hz, RATE_HZ * keep.mean(), rtol=0.01)
    line = next(w for w in s.warnings if w.startswith('messages lost'))
    assert 'N reads high' in line
    share = float(line.split('about ')[1].split(' %')[0]) / 100
    assert 0.05 <= share <= 0.2 and math.isfinite(share)


def test_the_counts_survive_a_checkpoint():
    t = _host_stamps(300.0, seed=8)
    whole = _watch(t)
    half = _watch(t[:14_000])
    again = LostWatch(HygieneStats(irregular_stamps=True), WarningLog())
    again.restore({k: v.copy() for k, v in half.state().items()})
    again.take(t[14_000:])
    assert_allclose(again.fano, whole.fano, rtol=1e-12)
    assert again.sums[0] == whole.sums[0] > 20
