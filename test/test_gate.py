"""The session's gate on data nobody here has seen: spikes, motion, glitched stamps."""

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan import AXES
from imu_allan.errors import InputError, NotEnoughStillData
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session

RATE_HZ = 100.0
SIGMA = np.array([6e-3] * 3 + [0.04] * 3)   # ADIS16405-like white noise per sample
DAY_NS = 86_400 * 10**9


def _still(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    y = rng.standard_normal((n, 6)) * SIGMA
    y[:, 5] -= 9.81
    t = 10**12 + np.arange(n, dtype=np.int64) * int(1e9 / RATE_HZ)
    return t, y


def _feed(session: Session, t, y, block: int = 777) -> Session:
    for k in range(0, t.size, block):
        session.add(t[k:k + block], y[k:k + block])
    session.flush()
    return session


# -- spikes ---------------------------------------------------------------------------

@pytest.mark.parametrize('burst', [1, 4])
def test_spikes_of_20_sigma_and_more_are_found_and_interpolated(burst):
    t, y = _still(60_000, seed=1)
    clean = y.copy()
    rng = np.random.default_rng(2)
    rows = rng.choice(np.arange(20, t.size - 20, 10), 60, replace=False)
    cols = rng.integers(0, 6, rows.size)
    sizes = rng.uniform(20, 50, rows.size) * rng.choice([-1, 1], rows.size)
    for r, c, a in zip(rows, cols, sizes):
        y[r:r + burst, c] += a * SIGMA[c]
    y[30_001, 1] = 1e154          # a huge finite value is a spike too
    s = _feed(Session(), t, y)
    assert s.stats.n_spikes >= 0.95 * (rows.size * burst + 1)
    assert s.stats.n_spikes <= rows.size * burst + 1
    assert sum(s.stats.spikes.values()) == s.stats.n_spikes
    assert any('spikes' in w for w in s.warnings)
    # Interpolated, not cut: the segment stays whole, the curve matches the clean one.
    assert s.stats.n_used == t.size and s.stats.n_gaps == 0
    ref = _feed(Session(), t, clean)
    # Long taus differ by the random error of the replaced values (few clusters there).
    assert_allclose(s.curve().avar[:20], ref.curve().avar[:20], rtol=0.02)
    assert_allclose(s.curve().avar, ref.curve().avar, rtol=0.15)


def test_clean_noise_has_no_spikes_whatever_the_blocks():
    t, y = _still(50_000, seed=3)
    for block in (50, 777, 50_000):
        assert _feed(Session(), t, y, block).stats.n_spikes == 0


def test_spikes_are_judged_the_same_whatever_the_blocks():
    t, y = _still(30_000, seed=17)
    rng = np.random.default_rng(18)
    rows = rng.choice(np.arange(5, t.size - 5), 40, replace=False)
    y[rows, rng.integers(0, 6, rows.size)] += 30 * SIGMA.max()
    whole = _feed(Session(), t, y, block=t.size)
    assert whole.stats.n_spikes >= 38
    for block in (1, 50, 2_047, 2_053):
        s = _feed(Session(), t, y, block)
        assert s.stats == whole.stats, block
        assert_allclose(s.curve().avar, whole.curve().avar, rtol=1e-12)


def test_a_record_of_mostly_spikes_is_refused():
    t, y = _still(20_000, seed=4)
    rng = np.random.default_rng(5)
    y[rng.random(t.size) < 0.2, 0] += 0.5
    s = _feed(Session(), t, y)
    with pytest.raises(InputError, match='spikes'):
        s.check_usable()


def test_a_quantised_axis_shifted_off_its_grid_keeps_its_noise_scale():
    # An axis quantised at twice its noise (most steps 0), plus a slow correction a
    # driver adds (a warm-up or bias compensation): its 0 steps become tiny, and the
    # median step, the noise scale, fell to them; every real step was then a spike
    # (ADIS16405 run 2 with a warm-up ramp: 11 % of accel_y "spikes", refused).
    t, y = _still(60_000, seed=21)
    lsb = 2.0 * SIGMA
    shift = np.linspace(0.0, 0.3, t.size)[:, None] * lsb
    s = _feed(Session(), t, np.round(y / lsb) * lsb + shift)
    assert s.stats.n_spikes <= 6, s.stats.spikes
    s.check_usable()


def test_a_segment_of_a_whole_number_of_chunks_ends_without_a_traceback():
    # The rows a segment ends with are judged without a next row: 2048 of them (one
    # chunk of the spike filter) left 2047 steps, and the reshape failed (ValueError:
    # ADIS16405 run 5's first hour with five knocks, a traceback).
    from imu_allan.pipeline.hygiene import HygieneStats, WarningLog
    from imu_allan.pipeline.spikes import CHUNK, SpikeFilter
    t, y = _still(CHUNK, seed=22)
    y[1000, 2] += 30 * SIGMA[2]
    spikes = SpikeFilter(SessionConfig(), HygieneStats(), WarningLog())
    assert spikes.take(t, y)[0].size == 0
    t_out, y_out = spikes.flush()
    assert t_out.size == CHUNK and spikes.stats.n_spikes == 1
    assert_allclose(y_out[999:1002, 2], y[999:1002, 2] - [0, 30 * SIGMA[2], 0], atol=0.05)


# -- held values ----------------------------------------------------------------------

#: Quanta of an ADIS16405 (0.05 deg/s, 3.33 mg) [rad/s, m/s^2].
LSB = np.array([0.05 * np.pi / 180] * 3 + [3.33e-3 * 9.80665] * 3)


def _updates(n: int, samples_per_update: float, seed: int) -> np.ndarray:
    """Return (n, 6) quantised sensor updates: the 100 Hz SIGMA averaged over an update."""
    rng = np.random.default_rng(seed)
    y = rng.standard_normal((n, 6)) * SIGMA / np.sqrt(samples_per_update)
    y[:, 5] -= 9.81
    return np.round(y / LSB) * LSB


def _poll(updates: np.ndarray, samples_per_update: float, seed: int) -> np.ndarray:
    """Poll a slower sensor at 100 Hz with jitter, as a logger does: updates held 1-5 times."""
    rng = np.random.default_rng(seed)
    n = int(updates.shape[0] * samples_per_update)
    done_at = np.arange(1, updates.shape[0] + 1) * samples_per_update
    polled = np.arange(n) + rng.uniform(-0.3, 0.3, n)
    return updates[np.clip(np.searchsorted(done_at, polled, side='right') - 1, 0, None)]


@pytest.mark.parametrize('k', [2, 3.6, 4, 5])   # 4: the spike scale's thinning
def test_held_values_are_no_spikes_and_are_reported(k):
    # Before: the median step was 0, the scale one quantum, most updates spikes, and
    # the record refused as 'mostly outliers'.
    y = _poll(_updates(int(60_000 / k), k, seed=11), k, seed=12)
    t = 10**12 + np.arange(y.shape[0], dtype=np.int64) * 10**7
    s = _feed(Session(), t, y)
    assert s.stats.n_spikes == 0
    s.check_usable()
    held = 1 - 1 / k
    assert_allclose(list(s.stats.held.values()), held, atol=0.02)
    assert set(s.stats.held) == set(AXES)
    line = next(w for w in s.warnings if w.startswith('held values'))
    assert f'{100 * held:.0f} %' in line and f'about {100 / k:.2g} Hz' in line
    assert s.stats.n_motion_events == 0 and s.stats.n_used == t.size


def test_quantised_data_is_not_taken_for_held_and_spikes_are_still_found():
    # The accelerometers repeat over a third of their values by quantization alone.
    y = _updates(60_000, 3.0, seed=13)
    t = 10**12 + np.arange(y.shape[0], dtype=np.int64) * 10**7
    s = _feed(Session(), t, y)
    assert s.stats.held == {} and s.stats.n_spikes == 0
    assert np.mean(y[1:, 3] == y[:-1, 3]) > 0.33
    # In held data, a bad update held 3 samples is a burst: still a spike.
    held = _poll(_updates(20_000, 3.0, seed=14), 3.0, seed=15)
    rows = np.arange(1_000, 59_000, 3_001)
    for r in rows:
        held[r:r + 3, 0] += 30 * SIGMA[0]
    s = _feed(Session(), t, held)
    assert s.stats.spikes.get('gyro_x', 0) >= 2 * rows.size


# -- motion ---------------------------------------------------------------------------

def _drive(y: np.ndarray, k: slice, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = y[k].shape[0]
    y[k] += rng.standard_normal((n, 6)) * SIGMA * 5
    y[k, 2] += np.repeat(rng.uniform(-0.3, 0.3, n // 500 + 1), 500)[:n]
    y[k, 3] += np.repeat(rng.uniform(-0.5, 0.5, n // 300 + 1), 300)[:n]


@pytest.mark.parametrize('policy', ['pause', 'restart'])
def test_a_robot_that_moved_first_gives_its_still_part(policy):
    # 2 min of driving, then 8 min parked: the first second is no still reference.
    t, y = _still(60_000, seed=6)
    _drive(y, slice(0, 12_000), seed=7)
    s = _feed(Session(SessionConfig(on_motion=policy)), t, y)
    assert s.stats.n_used / t.size == pytest.approx(0.8, abs=0.05 * 0.8)
    assert s.stats.n_reanchors >= 1
    s.check_usable()


def test_a_slow_bump_of_tens_of_sigma_is_motion():
    # 0.03 rad/s of yaw for 20 s, 50 sigma of a 1 s mean: under the old fixed 0.05 rad/s.
    t, y = _still(60_000, seed=8)
    k = np.arange(2_000)
    y[30_000:32_000, 2] += 0.03 * 0.5 * (1 - np.cos(2 * np.pi * k / k.size))
    s = _feed(Session(), t, y)
    assert s.stats.n_motion_events >= 1
    assert 1_000 <= s.stats.n_motion_dropped <= 3_000 + 600
    still = _feed(Session(), *_still(60_000, seed=8))
    assert still.stats.n_motion_events == 0 and still.stats.n_used == 60_000


@pytest.mark.parametrize('seed', range(8))
def test_a_still_1_hz_record_has_no_motion_and_driving_is_still_found(seed):
    # A 1 s window at 1 Hz held 2 samples: 1 to 658 false episodes in 2 h.
    rng = np.random.default_rng(seed)
    n = 7_200
    y = rng.standard_normal((n, 6)) * SIGMA
    y += np.cumsum(rng.standard_normal((n, 6)), axis=0) * SIGMA * 2e-3
    y[:, 5] -= 9.81
    t = np.arange(n, dtype=np.int64) * 10**9
    s = _feed(Session(), t, y)
    assert s.stats.n_motion_events == 0 and s.stats.n_used == n
    _drive(y, slice(3_000, 3_600), seed=seed)
    s = _feed(Session(), t, y)
    assert s.stats.n_motion_events >= 1
    assert 600 <= s.stats.n_motion_dropped <= 600 + 200


@pytest.mark.parametrize('policy', ['pause', 'restart'])
def test_a_frozen_read_is_never_the_still_reference(policy):
    # 5 of 20 minutes with all six values stuck (ADIS16405 run 5 so degraded was refused:
    # the stretch, quieter than any still data, became the reference, the rest motion).
    t, y = _still(120_000, seed=11)
    y[40_000:70_000] = y[39_999]
    s = _feed(Session(SessionConfig(on_motion=policy)), t, y)
    s.check_usable()
    assert s.stats.n_reanchors == 0 and s.stats.n_motion_events == 0
    assert s.stats.n_used == 120_000 and set(s.stats.frozen_axes) == set(AXES)


def test_too_little_still_data_is_refused_and_shown_live():
    t, y = _still(30_000, seed=9)
    _drive(y, slice(2_000, 30_000), seed=10)
    s = _feed(Session(), t, y)
    assert s.still_problem is not None and 'still' in s.still_problem
    with pytest.raises(NotEnoughStillData, match='not enough still data') as info:
        s.check_usable()
    assert info.value.exit_code == 3 and isinstance(info.value, InputError)


# -- stamps ---------------------------------------------------------------------------

@pytest.mark.parametrize('where', [5_000, 5_776, 5_777])  # inside, and at a block's edge
def test_one_stamp_a_day_ahead_is_an_outlier_not_a_new_clock(where):
    t, y = _still(12_000, seed=11)
    whole = _feed(Session(), t, y)
    t = t.copy()
    t[where] += DAY_NS
    s = _feed(Session(), t, y)
    assert s.stats.n_stamp_outliers == 1
    assert s.stats.n_used == t.size - 1 and s.stats.n_out_of_order == 0
    assert s.stats.n_gaps == 1 and s.stats.n_missing == 1    # the sample it took along
    assert_allclose(s.rate_hz, whole.rate_hz, rtol=1e-9)


def test_a_clock_that_restarts_starts_a_new_segment():
    t, y = _still(12_000, seed=12)
    t = t.copy()
    t[6_000:] -= t[6_000] - 10**9       # the device clock restarts near 1 s
    s = _feed(Session(), t, y)
    assert s.stats.n_clock_restarts == 1 and s.stats.n_out_of_order == 0
    assert s.stats.n_used == t.size and s.stats.n_gaps == 0
    assert any('restarted' in w for w in s.warnings)


def test_a_real_gap_is_a_gap():
    t, y = _still(12_000, seed=13)
    t = t.copy()
    t[6_000:] += 30 * 10**9
    s = _feed(Session(), t, y)
    assert s.stats.n_gaps == 1 and s.stats.n_stamp_outliers == 0
    assert s.stats.n_used == t.size


@pytest.mark.parametrize('glitch', ['ahead', 'restart'])
def test_a_checkpoint_taken_after_a_glitch_does_not_poison_the_resume(tmp_path, glitch):
    t, y = _still(20_000, seed=14)
    t = t.copy()
    if glitch == 'ahead':
        t[9_999] += DAY_NS             # the last stamp before the checkpoint
    first = Session()
    for k in range(0, 10_000, 500):
        first.add(t[k:k + 500], y[k:k + 500])
    first.save_state(tmp_path / 'state.npz')
    resumed = Session.load_state(tmp_path / 'state.npz')
    resumed.break_segment()
    resumed.last_stamp_ns = None       # what the node does after a resume
    rest = t[10_000:]
    if glitch == 'restart':
        rest = rest - rest[0] + 10**9  # the device restarted while the node was down
    _feed(resumed, rest, y[10_000:], block=500)
    lost = 1 if glitch == 'ahead' else 0
    assert resumed.stats.n_used == 20_000 - lost
    assert resumed.stats.n_out_of_order == 0


def test_analyze_refuses_a_moving_record_with_exit_code_3(tmp_path, capsys):
    from imu_allan import AXES
    from imu_allan.cli import main
    from imu_allan.io.csv_io import write_csv

    t, y = _still(30_000, seed=15)
    _drive(y, slice(2_000, 30_000), seed=16)
    write_csv(tmp_path / 'moving.csv', (t - t[0]) / 1e9, y, AXES)
    code = main(['analyze', str(tmp_path / 'moving.csv'), '--out', str(tmp_path / 'out'),
                 '--no-plot'])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 3
    assert err[-1].startswith('imu-allan: error: ') and 'not enough still data' in err[-1]
    assert not (tmp_path / 'out' / 'imu.yaml').exists()
