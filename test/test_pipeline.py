"""Input hygiene and accumulation of the one pipeline Session shared by node and bags."""

import json
import re

import numpy as np
from numpy.testing import assert_allclose, assert_equal
import pytest

from conftest import still_imu, T0_NS
from imu_allan.core.allan import overlapping_avar
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session

RATE_HZ = 100.0


def _feed(session: Session, t, y, block: int = 333) -> Session:
    for k in range(0, t.size, block):
        session.add(t[k:k + block], y[k:k + block])
    session.flush()
    return session


def test_clean_stream_equals_batch_and_warns_nothing():
    t, y = still_imu(60_000)
    s = _feed(Session(), t, y)
    assert s.warnings == []
    assert s.stats.n_used == t.size
    assert_allclose(s.rate_hz, RATE_HZ, rtol=1e-9)
    c = s.curve()
    exact = c.m <= 8192
    ref, _ = overlapping_avar(y, c.m[exact])
    assert_allclose(c.avar[exact], ref, rtol=1e-9)   # streaming equals batch


def test_gap_splits_the_segment_and_is_counted():
    t, y = still_imu(30_000)
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
    t, y = still_imu(5_000)
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
    t, y = still_imu(20_000)
    t = t.copy()
    t[10_000:] = t[10_000] + np.round(np.arange(10_000) * 1e9 / 125.0).astype(np.int64)
    s = _feed(Session(), t, y, block=500)
    assert s.stats.n_rate_changes > 0
    assert any('sample rate changed' in w for w in s.warnings)


def test_bursty_arrival_stamps_are_irregular_not_gaps():
    # Host arrival stamps: bursts of 2 ms steps, then a long wait (MPU-6050 style).
    rng = np.random.default_rng(3)
    t, y = still_imu(30_000)
    jitter = rng.uniform(-8e6, 8e6, t.size).astype(np.int64)
    jitter[::50] += 300_000_000                       # every 0.5 s, one 0.3 s late burst
    t = np.maximum.accumulate(t + jitter) + np.arange(t.size)  # keep them increasing
    s = _feed(Session(), t, y)
    assert s.stats.irregular_stamps
    assert s.stats.n_gaps == 0
    assert any('irregular stamps' in w for w in s.warnings)
    assert_allclose(s.rate_hz, RATE_HZ, rtol=0.02)


def test_a_starved_subscriber_losing_most_messages_keeps_the_clocks_period():
    # A node starved of CPU lost bursts of a 200 Hz stream's messages (sensor stamps):
    # the waits took more time than the received steps, and the window was taken for
    # bursty arrival (irregular, rate 198.09 Hz), so a resume at 200 Hz was refused.
    rng = np.random.default_rng(21)
    t, y = still_imu(60_000, rate_hz=200.0)
    keep = np.ones(t.size, dtype=bool)
    at = 0
    while at < t.size:
        at += int(rng.integers(5, 40))                  # received
        lost = int(rng.integers(20, 80))
        keep[at:at + lost] = False
        at += lost
    assert keep.mean() < 0.4
    s = _feed(Session(), t[keep], y[keep])
    assert not s.stats.irregular_stamps, s.warnings
    assert_allclose(s.rate_hz, 200.0, rtol=1e-9)
    assert_allclose(s.stamp_rate_hz(t[keep][:500]), 200.0, rtol=1e-9)


def test_a_warning_quotes_no_rate_but_the_one_the_analysis_uses():
    # The irregular-stamp warning used to quote the first window's rate (110.457 Hz
    # for the MPU-6050), while the analysis used the whole record's mean (99.317 Hz).
    rng = np.random.default_rng(5)
    t, y = still_imu(30_000)
    jitter = rng.uniform(-8e6, 8e6, t.size).astype(np.int64)
    jitter[::50] += 300_000_000
    jitter[:3_000] //= 4                          # calmer at first: another mean step
    t = np.maximum.accumulate(t + jitter) + np.arange(t.size)
    s = _feed(Session(), t, y)
    assert s.stats.irregular_stamps
    for text in s.warnings:
        for rate in re.findall(r'(\d+(?:\.\d+)?) Hz', text):
            # Quoted to 3 decimals at most: the same within their rounding.
            assert_allclose(float(rate), s.rate_hz, atol=5e-3, err_msg=text)


def test_saturated_and_frozen_axes():
    t, y = still_imu(5_000)
    y[1000:1010, 0] = 8.7266                          # clipped at 500 deg/s
    y[:, 4] = 0.25                                    # dead axis
    s = _feed(Session(SessionConfig(gyro_range_rad_s=8.7266)), t, y)
    assert s.stats.n_saturated == 10
    assert s.stats.saturated_axes == ['gyro_x']
    assert s.stats.frozen_axes == ['accel_y']
    assert any('frozen' in w for w in s.warnings)


def _moving_record():
    t, y = still_imu(40_000)
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


@pytest.mark.parametrize('policy', ['warn', 'pause', 'restart'])
def test_motion_verdicts_do_not_depend_on_the_blocks(policy):
    # Motion windows are cut from the stream: held rows join the next block's first.
    t, y = _moving_record()
    config = SessionConfig(on_motion=policy, settle_s=5.0)
    whole = _feed(Session(config), t, y, block=t.size)
    for seed, max_block in [(4, 7), (5, 250), (6, 9_000)]:
        s = _feed_random_blocks(Session(config), t, y, seed, max_block)
        assert s.stats == whole.stats
        assert s.warnings == whole.warnings
        assert_allclose(s.curve().avar, whole.curve().avar, rtol=1e-12)


def test_a_session_flushed_before_its_rate_is_known_is_empty():
    s = Session()
    s.add(np.array([0, 10_000_000], dtype=np.int64), np.zeros((2, 6)))
    s.flush()                                   # too few samples for a rate: nothing kept
    assert s.acc is None and s.stats.n_used == 0 and s.curve() is None


@pytest.mark.parametrize('cut', [20_000, 20_050])
def test_checkpoint_round_trip_continues_identically(tmp_path, cut):
    # 20_050 stops inside a motion window (100 samples at 100 Hz): the 50 samples held
    # for its check, and a frozen run across the cut, must survive the checkpoint.
    t, y = still_imu(40_000)
    y[cut - 150:cut + 100, 0] = y[cut - 150, 0]  # 250 identical values (limit 200)
    whole = _feed(Session(), t, y)
    first = Session()
    for k in range(0, cut, 500):
        first.add(t[k:min(k + 500, cut)], y[k:min(k + 500, cut)])
    first.save_state(tmp_path / 'state.npz')
    resumed = Session.load_state(tmp_path / 'state.npz')
    assert resumed.stats.n_used == first.stats.n_used
    for k in range(cut, 40_000, 500):
        resumed.add(t[k:k + 500], y[k:k + 500])
    resumed.flush()
    assert resumed.stats == whole.stats and whole.stats.frozen_axes == ['gyro_x']
    assert_allclose(resumed.curve().avar, whole.curve().avar, rtol=1e-12)


def test_checkpoint_refuses_another_rate(tmp_path):
    t, y = still_imu(5_000)
    _feed(Session(), t, y).save_state(tmp_path / 'state.npz')
    with pytest.raises(InputError, match='not resuming'):
        Session.load_state(tmp_path / 'state.npz', SessionConfig(rate_hz=200.0))
    (tmp_path / 'bad.npz').write_bytes(b'not a checkpoint')
    with pytest.raises(InputError, match='cannot read checkpoint'):
        Session.load_state(tmp_path / 'bad.npz')


@pytest.mark.parametrize('damage', [
    'no_stats', 'held_rows', 'meta_list', 'short_reference', 'rate_zero', 'rate_nan',
    'nan_reference', 'negative_count', 'spike_rows', 'clock_field', 'no_accumulator',
    'accumulator_rate', 'far_row', 'step_buf'])
def test_a_damaged_checkpoint_is_one_clear_error(tmp_path, damage):
    # Every part checks its own state when it is restored: never a ZeroDivisionError,
    # KeyError or a motion scan reading past an array's end.
    t, y = still_imu(5_050)
    _feed(Session(), t, y).save_state(tmp_path / 'state.npz')
    with np.load(tmp_path / 'state.npz') as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays['session_meta']))
    motion = meta['gate']['motion']
    if damage == 'no_stats':
        del meta['stats']
    elif damage == 'held_rows':
        arrays['held_stamp_ns'] = np.arange(3, dtype=np.int64)
        arrays['held_samples'] = np.zeros((3, 2))
    elif damage == 'short_reference':     # the motion scan would read past its end
        assert motion['ref_mean'] is not None
        motion['ref_mean'] = motion['ref_mean'][:3]
    elif damage == 'rate_zero':
        meta['clock']['rate_hz'] = 0
    elif damage == 'rate_nan':
        meta['clock']['rate_hz'] = float('nan')
    elif damage == 'nan_reference':
        motion['ref_std'][2] = float('nan')
    elif damage == 'negative_count':
        meta['stats']['n_used'] = -5
    elif damage == 'spike_rows':
        arrays['spike_held_samples'] = np.zeros((2, 6))
    elif damage == 'clock_field':
        meta['clock']['newest_stamp_ns'] = 'tomorrow'
    elif damage == 'no_accumulator':
        arrays = {k: v for k, v in arrays.items() if not k.startswith('acc__')}
    elif damage == 'accumulator_rate':
        meta['clock']['rate_hz'] = 2 * meta['clock']['rate_hz']
    elif damage == 'far_row':
        meta['clock']['far'] = [5, [1.0, 2.0]]
    elif damage == 'step_buf':
        meta['clock']['step_buf'] = [0, -3]
    arrays['session_meta'] = np.array(json.dumps([] if damage == 'meta_list' else meta))
    np.savez(tmp_path / 'damaged.npz', **arrays)
    with pytest.raises(InputError, match='is damaged') as info:
        Session.load_state(tmp_path / 'damaged.npz')
    assert '\n' not in str(info.value)


@pytest.mark.parametrize('content', [b'', b'PK\x03\x04 truncated', b'not a checkpoint'])
def test_an_unreadable_checkpoint_is_one_clear_error(tmp_path, content):
    (tmp_path / 'bad.npz').write_bytes(content)
    with pytest.raises(InputError, match='cannot read checkpoint'):
        Session.load_state(tmp_path / 'bad.npz')


def test_a_checkpoint_of_another_format_version_is_refused(tmp_path):
    t, y = still_imu(5_000)
    _feed(Session(), t, y).save_state(tmp_path / 'state.npz')
    with np.load(tmp_path / 'state.npz') as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays['session_meta']))
    meta['version'] = 3
    arrays['session_meta'] = np.array(json.dumps(meta))
    np.savez(tmp_path / 'old.npz', **arrays)
    with pytest.raises(InputError, match='format version 3'):
        Session.load_state(tmp_path / 'old.npz')


def test_a_checkpoint_with_the_retired_accumulator_thread_setting_resumes(tmp_path):
    # Checkpoints of the version that had the accumulator's thread hold its setting.
    t, y = still_imu(10_000)
    first = Session()
    for k in range(0, 5_000, 500):
        first.add(t[k:k + 500], y[k:k + 500])
    first.save_state(tmp_path / 'state.npz')
    with np.load(tmp_path / 'state.npz') as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays['session_meta']))
    meta['config']['background_accumulator'] = False
    arrays['session_meta'] = np.array(json.dumps(meta))
    np.savez(tmp_path / 'old.npz', **arrays)
    resumed = Session.load_state(tmp_path / 'old.npz')
    whole = _feed(Session(), t, y, block=500)
    assert_allclose(_feed(resumed, t[5_000:], y[5_000:], block=500).curve().avar,
                    whole.curve().avar, rtol=1e-12)


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


# -- stamp clock: gaps, rate changes, resume, block sizes ------------------------------

def _bursty(t, seed: int = 3):
    """Turn clock stamps into host arrival stamps: jitter, and a late burst every 50."""
    rng = np.random.default_rng(seed)
    period = int(np.median(np.diff(t)))
    jitter = rng.uniform(-0.8 * period, 0.8 * period, t.size).astype(np.int64)
    jitter[::50] += 30 * period
    return np.maximum.accumulate(t + jitter) + np.arange(t.size)


def test_stamp_rate_ignores_lost_messages_and_averages_bursts():
    # What a resume checks its first samples with: 300 lost messages among 50 must not
    # read as another rate, and bursty host stamps give their mean rate, not the
    # short steps inside a burst.
    t, _ = still_imu(400, rate_hz=200.0)
    s = Session()
    assert_allclose(s.stamp_rate_hz(np.r_[t[:10], t[310:350]]), 200.0, rtol=1e-9)
    assert_allclose(s.stamp_rate_hz(t[::-1][:50]), 200.0, rtol=1e-9)
    bursty = _bursty(t)
    assert_allclose(s.stamp_rate_hz(bursty), 399 * 1e9 / (bursty[-1] - bursty[0]), rtol=1e-9)
    assert s.stamp_rate_hz(t[:1]) == 0.0


def _feed_random_blocks(session: Session, t, y, seed: int, max_block: int) -> Session:
    rng = np.random.default_rng(seed)
    k = 0
    while k < t.size:
        n = int(rng.integers(1, max_block))
        session.add(t[k:k + n], y[k:k + n])
        k += n
    session.flush()
    return session


@pytest.mark.parametrize('lost_from', [100, 10_000])    # inside the rate window, or later
@pytest.mark.parametrize('block', [1, 333, 20_000])
def test_short_gap_in_regular_stamps_is_counted_not_taken_for_jitter(lost_from, block):
    t, y = still_imu(20_000, rate_hz=200.0)
    keep = np.ones(t.size, dtype=bool)
    keep[lost_from:lost_from + 100] = False             # 0.5 s of lost messages
    s = _feed(Session(), t[keep], y[keep], block=block)
    assert not s.stats.irregular_stamps
    assert s.stats.jitter_rel == 0.0
    assert (s.stats.n_gaps, s.stats.n_missing) == (1, 100)
    assert s.warnings == ['gap of 0.505 s (~100 samples) in the stamps: the segment is split '
                          'there, no term spans it']
    assert s.acc.n_segments == 2 and s.stats.n_used == keep.sum()
    assert s.rate_hz == 200.0                          # the gap is not part of the period


def test_short_gap_in_jittery_regular_stamps_is_counted():
    # Stamps off by up to 10 % of a period: still a clock, so a 0.5 s gap is a gap.
    rng = np.random.default_rng(5)
    t, y = still_imu(40_000, rate_hz=200.0)
    t = t + rng.uniform(-500_000, 500_000, t.size).astype(np.int64)
    keep = np.ones(t.size, dtype=bool)
    keep[20_000:20_100] = False
    s = _feed(Session(), t[keep], y[keep], block=5_000)
    assert not s.stats.irregular_stamps
    assert s.stats.jitter_rel == pytest.approx(0.1 * np.sqrt(2 / 3), rel=0.05)
    assert s.stats.n_gaps == 1 and s.stats.n_missing == 100
    assert_allclose(s.rate_hz, 200.0, rtol=1e-3)        # from the first 200 stamps


def test_bursty_stamps_stay_irregular_with_a_gap_of_a_few_seconds():
    t, y = still_imu(30_000)
    t = _bursty(t)
    t[20_000:] += 3_000_000_000                          # 3 s > irregular_gap_s
    s = _feed(Session(), t, y, block=30_000)
    assert s.stats.irregular_stamps and s.stats.jitter_rel > 1.0
    assert s.stats.n_gaps == 1
    # The mean rate leaves the gap out: it would otherwise read ~91 Hz.
    assert_allclose(s.rate_hz, RATE_HZ, rtol=0.02)


@pytest.mark.parametrize('block', [1, 500, 7_000, 20_000])
def test_rate_change_inside_a_block_is_reported_once(block):
    t, y = still_imu(20_000, rate_hz=200.0)
    t = t.copy()
    # 220 Hz from sample 7_000 on: one block of 20_000 spans both rates.
    t[7_000:] = t[7_000] + np.round(np.arange(13_000) * 1e9 / 220.0).astype(np.int64)
    s = _feed(Session(), t, y, block=block)
    assert s.stats.n_rate_changes == 1
    assert len(s.warnings) == 1
    found = re.fullmatch(r'sample rate changed: ([\d.]+) Hz against the nominal 200.00 Hz '
                         r'\(gaps are located with the nominal rate\)', s.warnings[0])
    assert found and float(found[1]) == pytest.approx(220.0, rel=0.01)
    assert s.stats.n_gaps == 0 and not s.stats.irregular_stamps
    assert s.rate_hz == 200.0


def test_rate_back_and_forth_counts_each_episode():
    t, y = still_imu(30_000, rate_hz=200.0)
    period = np.full(t.size - 1, 5_000_000)
    period[10_000:15_000] = 4_000_000                    # 250 Hz for 5_000 samples
    t = t[0] + np.concatenate(([0], np.cumsum(period)))
    s = _feed(Session(), t, y, block=30_000)
    assert s.stats.n_rate_changes == 1
    period[20_000:25_000] = 6_000_000                    # then 166.7 Hz
    t = t[0] + np.concatenate(([0], np.cumsum(period)))
    s = _feed(Session(), t, y, block=30_000)
    assert s.stats.n_rate_changes == 2


def _messy(kind: str):
    """Return a record with a gap, NaN rows, a re-sent message, and a 5 % faster rate."""
    t, y = still_imu(50_000, seed=7, rate_hz=200.0)
    t = t.copy()
    t[30_000:] = t[30_000] + np.round(np.arange(20_000) * 1e9 / 210.0).astype(np.int64)
    if kind == 'irregular':
        t = _bursty(t, seed=8)
    keep = np.ones(t.size, dtype=bool)
    keep[12_345:12_445] = False                          # 0.5 s gap
    y[20_000:20_003, 1] = np.nan
    t, y = t[keep], y[keep]
    return np.insert(t, 4_000, t[3_999]), np.insert(y, 4_000, y[3_999], axis=0)


def _clock_lines(warnings):
    return [w for w in warnings if 'NaN/Inf' not in w and 'repeated stamp' not in w]


@pytest.mark.parametrize('kind', ['regular', 'irregular'])
def test_any_block_sizes_give_identical_results(kind):
    t, y = _messy(kind)
    whole = _feed(Session(), t, y, block=t.size)
    assert whole.stats.irregular_stamps == (kind == 'irregular')
    # Under 2 s, the 0.5 s gap and the step over the NaN rows are gaps of regular stamps.
    assert whole.stats.n_gaps == (2 if kind == 'regular' else 0)
    assert whole.stats.n_duplicate == 1 and whole.acc.n_segments == 3 - (kind == 'irregular')
    for seed, max_block in [(1, 3), (2, 60), (3, 4_000)]:
        s = _feed_random_blocks(Session(), t, y, seed, max_block)
        assert s.stats == whole.stats
        # The NaN and repeated-stamp lines quote per-block counts; all others must match.
        assert _clock_lines(s.warnings) == _clock_lines(whole.warnings)
        assert s.rate_hz == whole.rate_hz
        assert_allclose(s.curve().avar, whole.curve().avar, rtol=1e-12)


def test_jittered_regular_stamps_give_identical_stats_for_any_blocks():
    # Ordinary windows are judged together; the jitter sums must still come out the
    # same, to the last bit, however the record is cut.
    t, y = still_imu(30_000, seed=11, rate_hz=200.0)
    rng = np.random.default_rng(12)
    t = t + rng.integers(-50_000, 50_000, t.size)         # +-1 % of the 5 ms period
    whole = _feed(Session(), t, y, block=t.size)
    assert not whole.stats.irregular_stamps and whole.stats.jitter_rel > 0
    for seed, max_block in [(1, 7), (2, 150), (3, 5_000)]:
        s = _feed_random_blocks(Session(), t, y, seed, max_block)
        assert s.stats == whole.stats
        assert_allclose(s.curve().avar, whole.curve().avar, rtol=1e-12)


def _resume(tmp_path, t, y, cut: int, lost: int = 0, node_style: bool = False) -> Session:
    """Feed t[:cut], checkpoint, load, drop ``lost`` samples, feed the rest."""
    first = _feed_random_blocks(Session(), t[:cut], y[:cut], 4, 700)
    first.save_state(tmp_path / 'state.npz')
    resumed = Session.load_state(tmp_path / 'state.npz')
    if node_style:
        # What the node does after a resume: no Allan term or step spans the lost tail.
        resumed.break_segment()
        resumed.last_stamp_ns = None
    return _feed_random_blocks(resumed, t[cut + lost:], y[cut + lost:], 5, 700)


@pytest.mark.parametrize('kind', ['regular', 'irregular', 'irregular_after_resume'])
def test_resume_gives_the_rate_of_an_uninterrupted_session(tmp_path, kind):
    t, y = still_imu(40_000, seed=9, rate_hz=200.0)
    if kind == 'irregular':
        t = _bursty(t)
    elif kind == 'irregular_after_resume':
        # The reported case: regular stamps, then host stamps after the restart.
        t = np.concatenate((t[:20_000], _bursty(t[20_000:])))
    whole = _feed_random_blocks(Session(), t, y, 6, 700)
    assert whole.stats.irregular_stamps == (kind != 'regular')
    resumed = _resume(tmp_path, t, y, 20_000)
    assert resumed.stats.irregular_stamps == whole.stats.irregular_stamps
    assert resumed.stats.n_gaps == whole.stats.n_gaps
    assert_allclose(resumed.rate_hz, whole.rate_hz, rtol=1e-12)
    assert resumed.stats.jitter_rel == pytest.approx(whole.stats.jitter_rel, rel=1e-12)
    # Samples lost between checkpoint and restart do not drag the rate down either.
    lossy = _resume(tmp_path, t, y, 20_000, lost=5_000, node_style=True)
    assert_allclose(lossy.rate_hz, 200.0, rtol=0.02)


def test_axes_searched_in_worker_processes_give_the_same_result():
    # imu-allan analyze searches one input's axes in two processes; the node in its own.
    from imu_allan.pipeline.analysis import analyze

    t, y = still_imu(20_000, seed=21, rate_hz=100.0)
    s = _feed(Session(), t, y, block=5_000)
    one, two = analyze(s, workers=1), analyze(s, workers=2)
    for axis in one.fits:
        a, b = one.fits[axis].optimised, two.fits[axis].optimised
        assert a.keys() == b.keys() and one.fits[axis].terms == two.fits[axis].terms
        for sym in a:   # exactly equal, NaN for NaN
            assert_equal((a[sym].value, a[sym].ci95, a[sym].kind),
                         (b[sym].value, b[sym].ci95, b[sym].kind), err_msg=f'{axis} {sym}')


def test_window_statistics_and_raw_means_equal_numpy():
    # The checks' three-pass window statistics against mean/std, at noise scale on a
    # 9.81 offset and at motion scale; the raw copy's strided means are bit-identical.
    from imu_allan.core.allan.raw import _means
    from imu_allan.pipeline.motion import _window_stats
    rng = np.random.default_rng(8)
    for scale, offset in ((1e-3, 9.81), (3.0, 0.0)):
        blocks = rng.standard_normal((40, 400, 6)) * scale + offset
        means, stds = _window_stats(blocks)
        assert_allclose(means, blocks.mean(axis=1), rtol=1e-14, atol=1e-14 * scale)
        assert_allclose(stds, blocks.std(axis=1), rtol=1e-12)
    y = rng.standard_normal((4096, 6)) * 1e-3 + 9.81
    for factor in (1, 2, 8, 32):
        assert_equal(_means(y, factor), y.reshape(-1, factor, 6).mean(axis=1))


def test_the_pipeline_modules_import_without_a_cycle():
    # Every import between pipeline modules, lazy ones inside functions included: the
    # Session's parts do not import the Session (the old session_state -> session loop).
    import ast
    from pathlib import Path

    import imu_allan.pipeline as pipeline
    folder = Path(pipeline.__file__).parent
    graph = {}
    for path in folder.glob('*.py'):
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                names.add(node.module)
                names.update(f'{node.module}.{a.name}' for a in node.names)
            elif isinstance(node, ast.Import):
                names.update(a.name for a in node.names)
        graph[path.stem] = {n.split('.')[2] for n in names
                            if n.startswith('imu_allan.pipeline.') and n.count('.') >= 2}
        graph[path.stem] &= {p.stem for p in folder.glob('*.py')}
    assert 'session' not in set().union(*(graph[m] for m in graph if m != 'session'
                                          and m != 'analysis'))
    done, visiting = set(), []

    def visit(module):
        assert module not in visiting, ' -> '.join(visiting + [module])
        if module in done:
            return
        visiting.append(module)
        for other in sorted(graph[module]):
            visit(other)
        visiting.pop()
        done.add(module)

    for module in sorted(graph):
        visit(module)
    assert not (folder / 'parts.py').exists()


def test_a_held_record_keeps_the_noise_of_its_updates():
    # A sensor updating at 33.3 Hz read at 100 Hz: each update held 3 samples.  The
    # held curve is low by (k^2 - 1) / (2 k m) well above the update period; the fit
    # corrects it and starts where the correction is small: its intervals widen (the
    # shortest taus are not used) and hold the values of the updates themselves.
    from imu_allan.core.noise.values import AxisNoise
    from imu_allan.core.noise.simulate import simulate_axis
    from imu_allan.pipeline.analysis import analyze

    rng = np.random.default_rng(31)
    k, n = 3, 30_000
    gyro = AxisNoise(N=7e-4, B=5e-4, T_B=20.0, K=3e-5)
    updates = np.stack([simulate_axis(gyro, RATE_HZ / k, n, rng) for _ in range(6)], axis=1)
    t = T0_NS + np.arange(n * k, dtype=np.int64) * 10**7
    clean = analyze(_feed(Session(), t[::k], updates, block=5_000), workers=1)
    held = _feed(Session(), t, np.repeat(updates, k, axis=0), block=5_000)
    assert_allclose(list(held.stats.held.values()), 1 - 1 / k, atol=0.01)
    result = analyze(held, workers=1)
    assert any(w.startswith('held values') for w in result.warnings)
    for axis in ('gyro_x', 'gyro_y', 'gyro_z'):
        for sym in ('N', 'B'):
            ref, got = clean.fits[axis].optimised[sym], result.fits[axis].optimised[sym]
            assert got.kind == ref.kind == 'estimate', (axis, sym)
            assert got.ci95[0] <= ref.value <= got.ci95[1], (axis, sym)
            # Within the clean interval widened by the held one: no bias beyond it.
            assert abs(got.value / ref.value - 1) <= (got.ci95[1] - got.ci95[0]) / ref.value
        n_ref, n_got = clean.fits[axis].optimised['N'].ci95, result.fits[axis].optimised['N'].ci95
        assert n_got[1] - n_got[0] > n_ref[1] - n_ref[0]
