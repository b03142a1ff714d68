"""Input hygiene and accumulation of the one pipeline Session shared by node and bags."""

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan.allan import overlapping_avar
from imu_allan.errors import InputError
from imu_allan.pipeline import Session, SessionConfig

RATE_HZ = 100.0
T0_NS = 1_700_000_000_000_000_000


def _record(n: int, seed: int = 0, rate_hz: float = RATE_HZ):
    """Still IMU: white noise, gravity on accel_z; stamps (n,) [ns], samples (n, 6)."""
    rng = np.random.default_rng(seed)
    y = rng.normal(0.0, [1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2], (n, 6))
    y[:, 5] += 9.80665
    t = T0_NS + np.round(np.arange(n) * 1e9 / rate_hz).astype(np.int64)
    return t, y


def _feed(session: Session, t, y, block: int = 333) -> Session:
    for k in range(0, t.size, block):
        session.add(t[k:k + block], y[k:k + block])
    session.flush()
    return session


def test_clean_stream_equals_batch_and_warns_nothing():
    t, y = _record(60_000)
    s = _feed(Session(), t, y)
    assert s.warnings == []
    assert s.stats.n_used == t.size
    assert_allclose(s.rate_hz, RATE_HZ, rtol=1e-9)
    c = s.curve()
    exact = c.m <= 8192
    ref, _ = overlapping_avar(y, c.m[exact])
    assert_allclose(c.avar[exact], ref, rtol=1e-9)   # streaming equals batch


def test_gap_splits_the_segment_and_is_counted():
    t, y = _record(30_000)
    keep = np.ones(t.size, dtype=bool)
    keep[10_000:10_250] = False                       # 2.5 s of lost messages
    s = _feed(Session(), t[keep], y[keep])
    assert s.stats.n_gaps == 1 and s.stats.n_missing == 250
    assert any('gap of 2.510 s' in w for w in s.warnings)
    # No difference term spans the gap: the sums pool the two segments exactly.
    c = s.curve()
    m = c.m[:3]
    parts = [y[:10_000], y[10_250:]]
    sums = [overlapping_avar(p, m) for p in parts]
    pooled = sum(a * 2 * m[:, None] ** 2 * n[:, None] for a, n in sums) / (
        2 * m[:, None] ** 2 * sum(n for _, n in sums)[:, None])
    assert_allclose(c.avar[:3], pooled, rtol=1e-9)


def test_nan_rows_duplicates_and_out_of_order_are_dropped_and_counted():
    t, y = _record(5_000)
    y[100, 2] = np.nan
    y[200, 4] = np.inf
    t2 = np.insert(t, 300, t[299])                    # a re-sent message
    y2 = np.insert(y, 300, y[299], axis=0)
    t2[400], t2[401] = t2[401], t2[400]                # swapped pair
    s = _feed(Session(), t2, y2)
    assert s.stats.n_nonfinite == 2
    assert s.stats.n_duplicate == 1
    assert s.stats.n_out_of_order == 1
    assert s.stats.n_used == t2.size - 4
    text = ' '.join(s.warnings)
    assert 'NaN/Inf' in text and 'repeated stamp' in text and 'out-of-order' in text


def test_rate_change_is_reported():
    t, y = _record(20_000)
    t = t.copy()
    t[10_000:] = t[10_000] + np.round(np.arange(10_000) * 1e9 / 125.0).astype(np.int64)
    s = _feed(Session(), t, y, block=500)
    assert s.stats.n_rate_changes > 0
    assert any('sample rate changed' in w for w in s.warnings)


def test_bursty_arrival_stamps_are_irregular_not_gaps():
    # Host arrival stamps: bursts of 2 ms steps, then a long wait (MPU-6050 style).
    rng = np.random.default_rng(3)
    t, y = _record(30_000)
    jitter = rng.uniform(-8e6, 8e6, t.size).astype(np.int64)
    jitter[::50] += 300_000_000                       # every 0.5 s, one 0.3 s late burst
    t = np.maximum.accumulate(t + jitter) + np.arange(t.size)  # keep them increasing
    s = _feed(Session(), t, y)
    assert s.stats.irregular_stamps
    assert s.stats.n_gaps == 0
    assert any('irregular stamps' in w for w in s.warnings)
    assert_allclose(s.rate_hz, RATE_HZ, rtol=0.02)


def test_saturated_and_frozen_axes():
    t, y = _record(5_000)
    y[1000:1010, 0] = 8.7266                          # clipped at 500 deg/s
    y[:, 4] = 0.25                                    # dead axis
    s = _feed(Session(SessionConfig(gyro_range_rad_s=8.7266)), t, y)
    assert s.stats.n_saturated == 10
    assert s.stats.saturated_axes == ['gyro_x']
    assert s.stats.frozen_axes == ['accel_y']
    assert any('frozen' in w for w in s.warnings)


def _moving_record():
    t, y = _record(40_000)
    y[15_000:16_000, 2] += 0.5                        # a 10 s turn at 0.5 rad/s
    return t, y


@pytest.mark.parametrize('policy', ['warn', 'pause', 'restart'])
def test_motion_policies(policy):
    t, y = _moving_record()
    s = _feed(Session(SessionConfig(on_motion=policy, settle_s=5.0)), t, y)
    assert s.stats.n_motion_events == 1
    assert any('motion detected on gyro_z' in w for w in s.warnings)
    if policy == 'warn':
        assert s.stats.n_used == t.size
    elif policy == 'pause':
        # The 10 s of motion plus 5 s of settling are left out; nothing else is.
        assert s.stats.n_motion_dropped == pytest.approx(1_500, abs=200)
        assert s.stats.n_used == t.size - s.stats.n_motion_dropped
        assert s.acc.n_segments == 2
    else:
        assert s.stats.n_restarts == 1
        assert s.stats.n_used == pytest.approx(40_000 - 16_500, abs=200)


def test_checkpoint_round_trip_continues_identically(tmp_path):
    t, y = _record(40_000)
    whole = _feed(Session(), t, y)
    first = Session()
    for k in range(0, 20_000, 500):
        first.add(t[k:k + 500], y[k:k + 500])
    first.save_state(tmp_path / 'state.npz')
    resumed = Session.load_state(tmp_path / 'state.npz')
    assert resumed.stats.n_used == first.stats.n_used
    for k in range(20_000, 40_000, 500):
        resumed.add(t[k:k + 500], y[k:k + 500])
    resumed.flush()
    assert_allclose(resumed.curve().avar, whole.curve().avar, rtol=1e-12)


def test_checkpoint_refuses_another_rate(tmp_path):
    t, y = _record(5_000)
    _feed(Session(), t, y).save_state(tmp_path / 'state.npz')
    with pytest.raises(InputError, match='not resuming'):
        Session.load_state(tmp_path / 'state.npz', SessionConfig(rate_hz=200.0))
    (tmp_path / 'bad.npz').write_bytes(b'not a checkpoint')
    with pytest.raises(InputError, match='cannot read checkpoint'):
        Session.load_state(tmp_path / 'bad.npz')


@pytest.mark.parametrize('stamps, samples, match', [
    (np.zeros(3, dtype=np.int64), np.zeros((3, 5)), r'samples \(n, 6\)'),
    (np.array(['a', 'b']), np.zeros((2, 6)), 'integer nanoseconds'),
    (np.zeros(2, dtype=np.int64), [['x'] * 6] * 2, 'must be numbers'),
])
def test_wrong_types_are_one_line_errors(stamps, samples, match):
    with pytest.raises(InputError, match=match):
        Session().add(stamps, samples)


def test_bad_config_is_refused():
    with pytest.raises(InputError, match='on_motion'):
        SessionConfig(on_motion='panic')
    with pytest.raises(InputError, match='gap_factor'):
        SessionConfig(gap_factor=float('nan'))
