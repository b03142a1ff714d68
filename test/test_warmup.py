"""
The warm-up hold of a session (imu_allan.pipeline.warmup): seeded records at 10 Hz.

A transient at the start (and after a restart of the sensor) is left out, said and
counted; a clean record gives the numbers it gave without the hold; the cut does not
depend on the blocks, survives a checkpoint, and the node's input side makes it too.
"""

import logging
import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from conftest import T0_NS
from imu_allan import AXES
from imu_allan.core.noise.simulate import simulate_axis
from imu_allan.core.noise.values import AxisNoise
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import HygieneStats, SessionConfig
from imu_allan.pipeline.session import Session
from imu_allan.pipeline.warmup import STILL_SETTLING

RATE_HZ = 10.0
PERIOD_NS = 100_000_000
#: White 2e-3, bias instability 2e-4 (Gauss-Markov, 100-600 s), random walk 2e-6.
NOISE = [AxisNoise(N=2e-3, B=2e-4, T_B=100.0 * (1 + j), K=2e-6) for j in range(6)]
#: The transient: +0.02 on gyro_x and accel_y, time constant 150 s.
AMPLITUDE, TAU_S = 0.02, 150.0


def _record(n: int, seed: int = 0, transient: bool = True, t0_ns: int = T0_NS) -> tuple:
    """Return stamps (n,) [ns] and samples (n, 6), gravity on accel_z."""
    rng = np.random.default_rng(seed)
    y = np.stack([simulate_axis(NOISE[j], RATE_HZ, n, rng) for j in range(6)], axis=1)
    y[:, 5] += 9.80665
    if transient:
        bump = AMPLITUDE * np.exp(-np.arange(n) / RATE_HZ / TAU_S)
        y[:, 0] += bump
        y[:, 4] += bump
    return t0_ns + np.arange(n, dtype=np.int64) * PERIOD_NS, y


def _session(t, y, block: int = 5000, **config) -> Session:
    session = Session(SessionConfig(**config))
    for k in range(0, t.size, block):
        session.add(t[k:k + block], y[k:k + block])
    session.flush()
    return session


N_LONG = 45_000      # 75 min


@pytest.fixture(scope='module')
def warm():
    t, y = _record(N_LONG)
    return t, y, _session(t, y)


def test_a_transient_at_the_start_is_left_out_and_said(warm):
    t, y, session = warm
    s = session.stats
    assert s.warmup_axes == ['gyro_x', 'accel_y']
    # Left out where 0.02 exp(-t / 150 s) is down to the wander (a few 1e-4): 9-14 min.
    assert 540 < s.warmup_s < 840, s.warmup_s
    assert s.n_warmup == round(s.warmup_s * RATE_HZ)
    assert s.n_used == N_LONG - s.n_warmup
    assert session.duration_s == pytest.approx((N_LONG - s.n_warmup) / RATE_HZ)
    [line] = [w for w in session.warnings if 'power-on' in w]
    assert 'at the start of the record' in line and 'gyro_x +1.1' in line, line
    # 0.02 m/s^2 is 2.04 mg; the fitted amplitudes are within 5 %.
    assert 'accel_y +1.9' in line or 'accel_y +2' in line, line
    assert f'first {s.warmup_s / 60:.1f} min of the record' in line
    assert 'before recording' in line and STILL_SETTLING not in line


def test_what_is_kept_follows_the_clean_record_and_the_whole_does_not(warm):
    # Against the same noise without the transient: the curve of what was kept stays
    # inside the clean curve's 95 % bounds at every tau; the whole record's does not.
    t, y, cut = warm
    t_c, y_c = _record(N_LONG, transient=False)
    clean = _session(t_c, y_c).curve()
    kept = cut.curve()
    whole = _session(t, y, warmup_window_s=0).curve()
    assert clean is not None and kept is not None and whole is not None
    k = min(clean.tau_s.size, kept.tau_s.size)
    for j in (0, 4):
        assert (kept.adev[:k, j] <= clean.adev_hi[:k, j]).all(), AXES[j]
        assert (kept.adev[:k, j] >= clean.adev_lo[:k, j]).all(), AXES[j]
        assert (whole.adev[:, j] > clean.adev_hi[:, j]).any(), AXES[j]


def test_a_clean_record_gives_the_numbers_it_gave_without_the_hold():
    t, y = _record(N_LONG, seed=1, transient=False)
    held, free = _session(t, y), _session(t, y, warmup_window_s=0)
    assert held.stats.n_warmup == 0 and held.stats.warmup_axes == []
    assert held.stats.n_used == free.stats.n_used == N_LONG
    assert not [w for w in held.warnings if 'power-on' in w]
    assert_allclose(held.curve().avar, free.curve().avar, rtol=1e-12)


def test_the_cut_does_not_depend_on_the_blocks(warm):
    t, y, whole = warm
    for block in (777, 18_000, N_LONG):
        other = _session(t, y, block=block)
        assert other.stats.n_warmup == whole.stats.n_warmup, block
        assert_allclose(other.curve().avar, whole.curve().avar, rtol=1e-12)


def test_a_checkpoint_in_the_window_keeps_the_rows_held(warm, tmp_path):
    t, y, whole = warm
    session = Session(SessionConfig())
    session.add(t[:9000], y[:9000])        # 15 of the 30 min window
    held_s, window_s = session.settling       # the spike filter and motion gate hold some
    assert 800 < held_s <= 900 and window_s == 1800
    assert session.curve() is None         # all of it held
    path = tmp_path / 'checkpoint.npz'
    session.save_state(path)
    resumed = Session.load_state(path)
    assert resumed.warmup.held_rows == session.warmup.held_rows
    resumed.add(t[9000:], y[9000:])
    resumed.flush()
    assert resumed.stats.n_warmup == whole.stats.n_warmup
    assert_allclose(resumed.curve().avar, whole.curve().avar, rtol=1e-12)


def test_a_damaged_hold_is_one_line_and_old_counters_read():
    session = Session(SessionConfig())
    with pytest.raises(InputError, match='warm-up hold'):
        session.warmup.restore({'holding': True}, {})
    old = {k: v for k, v in vars(HygieneStats()).items()
           if k not in ('n_warmup', 'warmup_s', 'warmup_axes')}
    assert HygieneStats.restore(old).warmup_s == 0.0


@pytest.mark.parametrize('how', ['clock restart', 'gap'])
def test_a_sensor_restart_opens_a_new_window(how):
    t1, y1 = _record(24_000, seed=2, transient=False)          # 40 min settled
    jump = -3600 * 10 ** 9 if how == 'clock restart' else 120 * 10 ** 9
    t2, y2 = _record(24_000, seed=3, t0_ns=int(t1[-1]) + jump)
    session = _session(np.concatenate((t1, t2)), np.concatenate((y1, y2)))
    s = session.stats
    assert s.warmup_axes == ['gyro_x', 'accel_y'] and 540 < s.warmup_s < 840
    [line] = [w for w in session.warnings if 'power-on' in w]
    at = '40.0' if how == 'clock restart' else '42.0'       # 2 min without stamps
    assert f'after the sensor restarted at {at} min into the record' in line, line


def test_a_short_record_is_judged_at_its_end_and_keeps_a_quarter():
    t, y = _record(6000, seed=4)                          # 10 min
    session = _session(t, y)
    assert session.stats.n_warmup == 4500
    [line] = [w for w in session.warnings if 'power-on' in w]
    assert STILL_SETTLING in line and 'accel_y' in line and '(B, K)' in line, line


def test_the_node_input_makes_the_cut_analyze_makes(warm, tmp_path):
    from imu_allan.io.bag_writer import serialize_imu
    from imu_allan.ros.live import LiveInput
    from imu_allan.ros.params import PARAMS
    t, y, offline = warm
    values = {p.name: p.default for p in PARAMS}
    live = LiveInput(values, tmp_path, logging.getLogger('warmup'))
    rows = serialize_imu(t, y)
    for k in range(0, t.size, 3000):
        for raw in rows[k:k + 3000]:
            live.append(raw.tobytes())
        live.process()
        if k == 9000:
            assert live.session.settling is not None     # the window is filling
    assert live.checkpoint(flush=True)
    s = live.session.stats
    assert (s.n_warmup, s.warmup_axes) == (offline.stats.n_warmup, offline.stats.warmup_axes)
    assert_allclose(live.session.curve().avar, offline.curve().avar, rtol=1e-9)


def test_adis_run_6_with_a_ten_minute_transient(shared_dir):
    # The case: +0.1 deg/s and +20 mg decaying with 200 s on the first hour of
    # ADIS16405 run 6.  The accelerometers' transient is found and left out, and what
    # is kept follows the clean hour's curve on accel_x.
    from imu_allan.io.csv_io import read_csv
    d = read_csv(shared_dir / 'realdata' / 'adis16405' / 'adis16405_run6.csv.gz')
    n = 360_000
    t = T0_NS + np.round(d.t_s[:n] * 1e9).astype(np.int64)
    y = d.samples[:n].copy()
    shape = np.exp(-d.t_s[:n] / 200.0)[:, None]
    clean = _session(t, y, block=100_000)
    y[:, :3] += math.radians(0.1) * shape
    y[:, 3:] += 0.02 * 9.80665 * shape
    warm = _session(t, y, block=100_000)
    s = warm.stats
    assert {'accel_x', 'accel_y', 'accel_z'} <= set(s.warmup_axes)
    assert 600 < s.warmup_s < 1500, s.warmup_s
    # The motion gate's still reference lags the settling output: the episodes it saw
    # there are the warm-up's, and no warning calls the IMU moving.
    assert s.n_motion_events == s.n_motion_dropped == s.n_reanchors == 0
    assert not [w for w in warm.warnings if 'not stationary' in w or 'reference' in w]
    [line] = [w for w in warm.warnings if 'power-on' in w]
    assert 'motion episodes seen then were the output settling' in line, line
    assert clean.stats.n_warmup == 0
    a, b = warm.curve(), clean.curve()
    k = min(a.tau_s.size, b.tau_s.size)
    # From 10 s on (the shortest taus' bounds are tighter than a different sample set).
    long = a.tau_s[:k] >= 10.0
    assert (a.adev[:k, 3][long] <= b.adev_hi[:k, 3][long]).all()


def test_a_transient_longer_than_the_window_takes_whole_windows(tmp_path):
    # 5 min windows, a transient of 0.2 over 60 s: it needs about 6 min, so the first
    # window is left out whole and what its fit still needs is cut from the second; a
    # checkpoint between them keeps that.  The motion gate's reference lags the
    # transient at first: with on_motion=warn its rows stay, and its episodes are the
    # warm-up's.
    t, y = _record(12_000, seed=5, transient=False)
    y[:, 3] += 0.2 * np.exp(-np.arange(t.size) / RATE_HZ / 60.0)
    config = SessionConfig(warmup_window_s=300.0, on_motion='warn')
    session = Session(config)
    k = 0
    while not session.stats.n_warmup:        # until the first window is left out
        session.add(t[k:k + 500], y[k:k + 500])
        k += 500
    assert session.stats.warmup_s > 250 and session.settling is not None
    path = tmp_path / 'checkpoint.npz'
    session.save_state(path)
    resumed = Session.load_state(path, config)
    resumed.add(t[k:], y[k:])
    resumed.flush()
    whole = _session(t, y, warmup_window_s=300.0, on_motion='warn')
    s = resumed.stats
    assert s.n_warmup == whole.stats.n_warmup and 330 < s.warmup_s < 450, s.warmup_s
    assert s.n_motion_events == 0 and s.warmup_axes == ['accel_x']
    [line] = [w for w in resumed.warnings if 'power-on' in w]
    assert f'the first {s.warmup_s / 60:.1f} min of the record' in line, line
    assert 'accel_x +2' in line and STILL_SETTLING not in line, line
