"""Stamp clocks coarser than the sample period: recognised, stamps rebuilt, N kept."""

import numpy as np
from numpy.testing import assert_allclose
import pytest

from conftest import T0_NS
from imu_allan.pipeline.analysis import analyze
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session
from imu_allan.pipeline.ticks import coarse_tick, TickClock

#: White noise of the simulated gyro and accelerometer [rad/s/sqrt(Hz), m/s^2/sqrt(Hz)].
N_TRUE = np.array([1e-3] * 3 + [1e-2] * 3)


def _coarse(rate_hz: float, tick_s: float, seconds: float, seed: int,
            jitter_s: float = 0.0) -> tuple:
    """Return (stamps [ns], samples): white noise sampled at rate_hz, stamped in ticks."""
    rng = np.random.default_rng(seed)
    n = int(rate_hz * seconds)
    # A phase within the tick, so no sample sits on a tick's edge by construction.
    true_s = 0.37 * tick_s + np.arange(n) / rate_hz + rng.normal(0, jitter_s, n)
    stamp_ns = T0_NS + np.round(np.floor(true_s / tick_s) * tick_s * 1e9).astype(np.int64)
    y = rng.standard_normal((n, 6)) * N_TRUE * np.sqrt(rate_hz)
    y[:, 5] += 9.80665
    return stamp_ns, y


def _session(t, y, config=SessionConfig(), block: int = 4096) -> Session:
    s = Session(config)
    for k in range(0, t.size, block):
        s.add(t[k:k + block], y[k:k + block])
    s.flush()
    return s


@pytest.mark.parametrize('rate_hz, tick_s, seconds', [
    (4000.0, 1e-3, 30.0),    # four samples per tick
    (2500.0, 1e-3, 30.0),    # 2.5 per tick: groups of three and two
    (800.0, 1e-3, 100.0),    # 0.8 per tick: steps of 1, 1, 1, 2 ms
    (200.0, 1e-2, 300.0),    # two per 10 ms tick
])
def test_coarse_stamps_keep_every_sample_and_the_true_noise(rate_hz, tick_s, seconds):
    t, y = _coarse(rate_hz, tick_s, seconds, seed=int(rate_hz))
    s = _session(t, y)
    assert s.stats.n_duplicate == 0 and s.stats.n_gaps == 0
    assert s.stats.n_used == t.size
    assert_allclose(s.stats.coarse_tick_s, tick_s, rtol=1e-6)
    # The count over the record: within a tick over its span.
    assert abs(s.rate_hz - rate_hz) <= rate_hz * 2 * tick_s / seconds
    warning = next(w for w in s.warnings if 'coarse stamps' in w)
    assert f'{rate_hz * tick_s:.3g} samples per tick' in warning
    assert not any('irregular' in w or 'repeated stamp' in w for w in s.warnings)
    result = analyze(s)
    for j, axis in enumerate(('gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z')):
        n = result.fits[axis].optimised['N']
        assert n.kind == 'estimate'
        assert n.ci95[0] <= N_TRUE[j] <= n.ci95[1], (axis, n)


def test_the_tick_and_period_are_found_and_resent_messages_are_no_ticks():
    t, y = _coarse(4000.0, 1e-3, 5.0, seed=1)
    assert coarse_tick(t[:4096], y[:4096]) == pytest.approx((1e6, 2.5e5), rel=1e-3)
    # Every message sent twice (same stamp, same values): re-sent, not a coarse clock.
    t2, y2 = _coarse(100.0, 1e-3, 20.0, seed=2)
    assert coarse_tick(np.repeat(t2, 2), np.repeat(y2, 2, axis=0)) is None
    # A regular clock that lost 5 % of its messages at random: not a coarse clock.
    keep = np.random.default_rng(3).random(t2.size) > 0.05
    assert coarse_tick(t2[keep][:1000], y2[keep][:1000]) is None


@pytest.mark.parametrize('jitter_s', [0.0, 1e-4, 2e-4])
def test_one_sample_per_tick_with_jitter_is_not_coarse(jitter_s):
    # A 1 kHz IMU stamped in 1 ms ticks, its read times jittered: a repeated stamp is a
    # late one, and the stamp clock's rules (drop it, fill its gap) apply as before.
    t, y = _coarse(1000.0, 1e-3, 30.0, seed=5, jitter_s=jitter_s)
    s = _session(t, y)
    assert s.stats.coarse_tick_s == 0.0
    assert not any('coarse' in w for w in s.warnings)
    assert_allclose(s.rate_hz, 1000.0, rtol=1e-4)


def test_regular_and_irregular_stamps_pass_as_they_are_from_the_first_rows():
    rng = np.random.default_rng(3)
    regular = T0_NS + np.arange(500, dtype=np.int64) * 10_000_000
    bursty = T0_NS + np.cumsum(rng.exponential(1e7, 500)).astype(np.int64)
    y = rng.standard_normal((500, 6))
    for t in (regular, bursty):
        ticks = TickClock(SessionConfig(), Session().stats, Session().log)
        assert ticks.take(t[:31], y[:31]) == []          # held: too few to judge
        out = ticks.take(t[31:40], y[31:40])
        assert ticks.mode == 'plain'
        assert np.array_equal(np.concatenate([o[0] for o in out]), t[:40])


def test_a_set_rate_overrides_the_count():
    t, y = _coarse(4000.0, 1e-3, 10.0, seed=7)
    s = _session(t, y, SessionConfig(rate_hz=4000.0))
    assert s.rate_hz == 4000.0 and s.stats.n_used == t.size
    assert 'at the rate set' in next(w for w in s.warnings if 'coarse stamps' in w)
    # A wrong rate is honoured too (the user said so); the stamps follow it.
    s = _session(t, y, SessionConfig(rate_hz=3990.0))
    assert s.rate_hz == 3990.0


def test_a_gap_in_coarse_stamps_is_a_gap_and_blocks_do_not_matter():
    t, y = _coarse(4000.0, 1e-3, 20.0, seed=9)
    cut = np.r_[np.arange(30_000), np.arange(30_400, t.size)]     # 100 ms lost
    t, y = t[cut], y[cut]
    a, b = _session(t, y, block=4096), _session(t, y, block=333)
    for s in (a, b):
        assert s.stats.n_used == t.size
        assert s.stats.n_gaps == 1
        assert abs(s.stats.n_missing - 400) <= 8       # within a tick's samples
    assert_allclose(a.curve().avar, b.curve().avar, rtol=1e-9)


def test_a_coarse_session_resumes_from_its_checkpoint(tmp_path):
    t, y = _coarse(4000.0, 1e-3, 20.0, seed=11)
    whole = _session(t, y)
    first = Session()
    for k in range(0, 40_000, 4096):
        first.add(t[k:min(k + 4096, 40_000)], y[k:min(k + 4096, 40_000)])
    first.save_state(tmp_path / 'cp.npz')
    resumed = Session.load_state(tmp_path / 'cp.npz')
    assert resumed.ticks.mode == 'coarse'
    for k in range(40_000, t.size, 4096):
        resumed.add(t[k:k + 4096], y[k:k + 4096])
    resumed.flush()
    assert resumed.stats.n_used == whole.stats.n_used == t.size
    assert resumed.stats.n_duplicate == 0
    assert_allclose(resumed.curve().avar[:10], whole.curve().avar[:10], rtol=1e-3)


def test_a_resumed_coarse_session_judges_incoming_stamps_by_their_count():
    # The node checks the rate of the first stamps after a resume against the
    # checkpoint: coarse raw stamps give the tick's rate step by step, the count's here.
    t, y = _coarse(4000.0, 1e-3, 2.0, seed=12)
    s = _session(t[:4000], y[:4000])
    assert s.ticks.mode == 'coarse'
    assert_allclose(s.stamp_rate_hz(t[4000:4400]), 4000.0, rtol=0.01)
    assert_allclose(Session().stamp_rate_hz(t[4000:4400]), 1000.0, rtol=0.01)


def test_stamps_that_are_all_one_value_are_named():
    rng = np.random.default_rng(13)
    t = np.zeros(5000, dtype=np.int64)
    s = _session(t, rng.standard_normal((5000, 6)))
    assert any('stamps are all 0 ns: they carry no time' in w for w in s.warnings)
    assert s.stats.n_duplicate == 4999


@pytest.mark.parametrize('seed', range(6))
def test_a_short_first_block_then_a_long_one_gives_no_false_gaps(seed):
    # The first judgement times the period over about 20 ticks; a long block after it
    # is followed piece by piece as the count's span grows (before: up to 574 samples
    # taken for lost in 20 s).
    t, y = _coarse(4000.0 + 7.3 * seed, 1e-3, 20.0, seed=seed)
    s = Session()
    s.add(t[:85], y[:85])
    s.add(t[85:], y[85:])
    s.flush()
    assert s.stats.n_gaps == 0 and s.stats.n_lost_in_ticks == 0
    assert s.stats.n_used == t.size


@pytest.mark.parametrize('block', [4096, 333])
def test_a_glitched_stamp_and_a_restart_in_coarse_stamps(block):
    t, y = _coarse(4000.0, 1e-3, 20.0, seed=3)
    glitch = t.copy()
    glitch[30_001] += 86_400 * 10**9            # one stamp a day ahead: a lone outlier
    s = _session(glitch, y, block=block)
    assert s.stats.n_stamp_outliers == 1 and s.stats.n_used == t.size - 1
    assert s.stats.n_missing == 1 and s.stats.n_clock_restarts == 0
    restart = t.copy()
    restart[40_000:] -= 10**12                  # the clock restarts 1000 s back
    s = _session(restart, y, block=block)
    assert s.stats.n_clock_restarts == 1 and s.stats.n_used == t.size
    assert s.stats.n_duplicate == 0 and s.stats.n_out_of_order == 0


def test_a_session_flushed_before_any_row_or_twice_is_empty():
    s = Session()
    s.flush()                       # the node's ~/save before any message
    assert s.stats.n_used == 0 and s.ticks.mode == 'detect'
    t, y = _coarse(100.0, 1e-3, 1.0, seed=14)
    s.add(t[:10], y[:10])
    s.flush()
    s.flush()
    assert s.ticks.mode == 'plain'
