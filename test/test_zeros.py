"""Zero-filled fields: exact zeros of incomplete packets become lost samples, named."""

import numpy as np
from numpy.testing import assert_allclose

from conftest import T0_NS
from imu_allan.pipeline.fills import filled
from imu_allan.pipeline.hygiene import HygieneStats, WarningLog
from imu_allan.pipeline.session import Session
from imu_allan.pipeline.zeros import ZERO_FILLED, ZeroWatch

RATE_HZ = 100.0
SD = np.array([2e-3] * 3 + [3e-2] * 3)      # per-sample sd of the white noise
#: Gyro biases 3 sds from 0: zeros there are no spikes (10 sds), yet far off the noise.
BIAS = np.array([3 * SD[0], -3 * SD[0], 3 * SD[0], 0.4, 0.6, -9.8])


def _still(n: int, seed: int) -> tuple:
    rng = np.random.default_rng(seed)
    y = BIAS + rng.standard_normal((n, 6)) * SD
    return T0_NS + np.arange(n, dtype=np.int64) * 10_000_000, y


def _zero_rows(y: np.ndarray, share: float, seed: int) -> np.ndarray:
    """Zero the gyro or the accel of ``share`` of the rows (bench/degrade.py zero_rows)."""
    rng = np.random.default_rng(seed)
    out = y.copy()
    rows = np.flatnonzero(rng.random(y.shape[0]) < share)
    gyro = rng.random(rows.size) < 0.5
    out[rows[gyro], :3] = 0.0
    out[rows[~gyro], 3:] = 0.0
    return out


def _run(t, y, block: int = 4096) -> Session:
    s = Session()
    for k in range(0, t.size, block):
        s.add(t[k:k + block], y[k:k + block])
    s.flush()
    return s


def _adev(s: Session, m: int = 10) -> np.ndarray:
    c = s.curve()
    k = int(np.argmin(np.abs(c.tau_s - m / RATE_HZ)))
    return c.adev[k]


def test_zero_filled_messages_are_lost_samples_named_by_axis():
    t, y = _still(60_000, seed=1)
    bad = _zero_rows(y, 0.1, seed=2)
    clean, s = _run(t, y), _run(t, bad)
    # Before: the zeros passed as data, gyro ADEV 1.4x the clean record's, no warning.
    assert_allclose(_adev(s), _adev(clean), rtol=0.03)
    n_rows = int((bad[:, :3] == 0).all(axis=1).sum() + (bad[:, 3:] == 0).all(axis=1).sum())
    # The first run the clock passes on (its rate window) holds too few zeros to judge.
    assert n_rows - 20 <= s.stats.n_zero_rows <= n_rows
    assert set(s.stats.zero_filled) == {'gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y',
                                        'accel_z'}
    line = next(w for w in s.warnings if w.startswith(ZERO_FILLED))
    assert f'{s.stats.n_zero_rows:,} messages' in line
    assert 'gyro_z' in line and 'lost samples' in line
    assert not clean.stats.n_zero_rows and not any(ZERO_FILLED in w for w in clean.warnings)


def test_legitimate_zeros_of_a_quantised_axis_are_kept():
    # An MPU-6050-like gyro: LSB 1.3e-4 rad/s, 0 within the bulk (a third of an sd from
    # the mean), so it reads exactly 0 as often as the levels next to it.
    t, y = _still(30_000, seed=3)
    lsb = 1.3323e-4
    y[:, 1] = np.round((0.5 * SD[1] + np.random.default_rng(4).standard_normal(y.shape[0])
                        * SD[1]) / lsb) * lsb
    assert (y[:, 1] == 0).sum() > 500
    s = _run(t, y)
    assert not s.gate.zeros.filled_axes().any() and s.stats.n_zero_rows == 0
    # A coarse gyro (LSB above its noise) reads 0 most of the time: also data.
    y[:, 2] = np.round(y[:, 2] / (4 * SD[2])) * 4 * SD[2]
    assert not ZeroWatch(HygieneStats(), WarningLog(), 8).filled_axes().any()
    s = _run(t, y)
    assert s.stats.n_zero_rows == 0


def test_rows_become_fills_between_their_neighbours_and_long_runs_split():
    t, y = _still(3000, seed=5)
    y[100:120, :3] = 0.0      # a long run (20 > max_fill_samples 8): dropped, a break
    y[200:300:10, :3] = 0.0   # single rows: fills
    watch = ZeroWatch(HygieneStats(), WarningLog(), 8)
    runs = list(watch.take(t, y))
    assert [r[2] for r in runs] == [False, True]
    assert runs[0][0].size == 100 and runs[1][0][0] == t[120]
    fills = filled(runs[1][1])
    assert fills is not None and fills.sum() == 10
    row = 200 - 120
    assert_allclose(runs[1][1][row], (y[199] + y[201]) / 2, rtol=1e-8)
    # Cut into single rows, the verdict and the fills are the same once judged.
    one = ZeroWatch(HygieneStats(), WarningLog(), 8)
    for k in range(150):
        list(one.take(t[k:k + 1], y[k:k + 1]))
    assert one.filled_axes()[:3].all()
    again = [r for k in range(150, 300) for r in one.take(t[k:k + 1], y[k:k + 1])]
    assert sum(int(filled(r[1]) is not None) for r in again) == 10


def test_zeroed_vectors_of_axes_that_read_zero_now_and_then_are_found():
    # ADIS16405-like gyros: 0 within the bulk, read on about 4 % of the samples each;
    # all three at once as often as the product of their shares (the six real runs:
    # 31-41 rows against 28-37 by chance in 1 M).
    t, y = _still(60_000, seed=8)
    lsb = 0.4 * SD[0]
    y[:, :3] = np.round((y[:, :3] - BIAS[:3]) / lsb) * lsb
    assert 0.02 < (y[:, :3] == 0).mean() < 0.2
    clean = _run(t, y)
    assert not clean.gate.zeros.filled_axes().any()
    assert not clean.gate.zeros.filled_sensors().any() and clean.stats.n_zero_rows == 0
    bad = y.copy()
    rows = np.flatnonzero(np.random.default_rng(9).random(y.shape[0]) < 0.02)
    bad[rows, :3] = 0.0
    s = _run(t, bad)
    assert not s.gate.zeros.filled_axes()[:3].any()      # no axis alone shows them
    assert s.gate.zeros.filled_sensors().tolist() == [True, False]
    # Until ten all-zero rows are in (about 500 rows here) they pass as data.
    assert rows.size - 40 <= s.stats.n_zero_rows <= rows.size + 5
    assert_allclose(_adev(s)[:3], _adev(clean)[:3], rtol=0.03)


def test_a_checkpoint_keeps_the_verdict_and_the_left_neighbour(tmp_path):
    t, y = _still(20_000, seed=10)
    bad = _zero_rows(y, 0.05, seed=11)
    whole = _run(t, bad, block=500)
    first = Session()
    for k in range(0, 10_000, 500):
        first.add(t[k:k + 500], bad[k:k + 500])
    first.save_state(tmp_path / 'state.npz')
    resumed = Session.load_state(tmp_path / 'state.npz')
    for k in range(10_000, 20_000, 500):
        resumed.add(t[k:k + 500], bad[k:k + 500])
    resumed.flush()
    assert resumed.stats == whole.stats and whole.stats.n_zero_rows > 900
    assert_allclose(resumed.curve().avar, whole.curve().avar, rtol=1e-12)


def test_fills_and_block_means_of_a_quantised_axis_are_not_zero_fills():
    # An ADIS16405-like accel_x: 0 is a level of a grid of 1.6 sd, read on a quarter of
    # the samples.  Messages lost (gaps the clock fills half way between two levels),
    # and block means (each level spread over float values, 0 too), are no pile at 0.
    t, y = _still(60_000, seed=12)
    lsb = 1.6 * SD[3]
    y[:, 3] = np.round((y[:, 3] - BIAS[3] - 0.5 * lsb) / lsb) * lsb
    assert (y[:, 3] == 0).mean() > 0.2
    keep = np.random.default_rng(13).random(t.size) >= 0.02
    s = _run(t[keep], y[keep])
    assert s.stats.n_short_gaps > 500 and s.stats.n_zero_rows == 0
    means = y[:, 3].reshape(-1, 10).mean(axis=1)
    # The zero level as the ADIS16405's block means gave it: 761 exact zeros, 20 values
    # of about 1e-18 (sums of levels in another order).
    level = np.flatnonzero(np.abs(means) < 1e-12)
    means[level] = 0.0
    means[level[::30]] = 1e-18 * np.sign(np.arange(level[::30].size) % 2 - 0.5)
    watch = ZeroWatch(HygieneStats(), WarningLog(), 8)
    tm, ym = t[::10], np.repeat(means[:, None], 6, axis=1) + BIAS * [1, 1, 1, 0, 1, 1]
    list(watch.take(tm, ym))
    assert not watch.filled_axes().any()


def test_zeros_of_a_grid_that_a_drift_left_for_a_while_are_a_level():
    # An ADIS16405-like accel_x (0 a level of a grid of 1.6 sd) whose bias a warm-up
    # moved off the grid for its first 20,000 rows: the values nearest to 0 are then
    # single readings of the drift, 0 of the settled part no rarer than its neighbours.
    t, y = _still(60_000, seed=14)
    lsb = 1.6 * SD[3]
    y[:, 3] = np.round((y[:, 3] - BIAS[3] - 0.3 * lsb) / lsb) * lsb
    y[:20_000, 3] += 2e-2 * np.linspace(1.0, 0.0, 20_000) ** 2
    assert (y[20_000:, 3] == 0).mean() > 0.2
    s = _run(t, y, block=97)
    assert s.stats.n_zero_rows == 0 and not any(ZERO_FILLED in w for w in s.warnings)
    # Fills on a grid whose levels lie 3 sds off 0 remain fills: no level explains them.
    y[:, 0] = np.round(y[:, 0] / (0.4 * SD[0])) * 0.4 * SD[0]
    rows = np.flatnonzero(np.random.default_rng(15).random(t.size) < 0.05)
    y[rows, 0] = 0.0
    s = _run(t, y, block=97)
    assert s.gate.zeros.filled_axes().tolist() == [True] + [False] * 5
    # (with the grid's own zeros, 0.2 % of the rows: 3 sds off the mean, one LSB wide)
    zeros = int((y[:, 0] == 0).sum())
    assert zeros - 40 <= s.stats.zero_filled['gyro_x'] <= zeros
    # Cut into other blocks, the summary of frequent values is the same.
    other = _run(t, y, block=1000)
    for a, b in zip(s.gate.zeros.heavy, other.gate.zeros.heavy):
        np.testing.assert_array_equal(a.keys, b.keys)
        np.testing.assert_array_equal(a.counts, b.counts)


def test_a_frozen_read_of_zeros_is_one_reading_not_a_pile():
    # 300 s of one row repeated whose gyro_z and accel_x read 0 (ADIS16405 run 5 so
    # degraded: 30,000 zeros made a pile, and the axes' own zeros were then taken for
    # zero-filled fields); held values likewise count once per update.
    t, y = _still(60_000, seed=16)
    y[:, 2] = np.round((y[:, 2] - BIAS[2]) / (0.4 * SD[2])) * 0.4 * SD[2]    # reads 0 too
    y[20_000:50_000] = y[19_999]
    y[20_000:50_000, [2, 3]] = 0.0
    s = _run(t, y, block=333)
    assert s.stats.n_zero_rows == 0 and not any(ZERO_FILLED in w for w in s.warnings)
    # The same zeros in 3,000 separate messages are fills (10 % of rows as before).
    bad = _zero_rows(_still(60_000, seed=16)[1], 0.1, seed=17)
    assert _run(t, bad, block=333).stats.n_zero_rows > 5_000
