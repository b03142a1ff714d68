"""Values a driver interpolated between its sensor's updates: found, named, checkpointed."""

import sys

import numpy as np
from numpy.testing import assert_allclose
import pytest

from conftest import REPO, T0_NS
from imu_allan import AXES
from imu_allan.core.rules import INTERP_MIN
from imu_allan.pipeline.hygiene import HygieneStats, WarningLog
from imu_allan.pipeline.interpolated import INTERPOLATED, InterpWatch
from imu_allan.pipeline.session import Session
sys.path.insert(0, str(REPO / 'bench'))
from degrade import degrade, Record  # noqa: E402, I100, I201

RATE_HZ = 100.0


def _record(seconds: float, seed: int) -> Record:
    """Return a still IMU's white noise at 100 Hz: gyro 1e-3 rad/s, accel 0.02 m/s^2 on 9.81."""
    rng = np.random.default_rng(seed)
    y = rng.standard_normal((int(seconds * RATE_HZ), 6)) * np.array([1e-3] * 3 + [0.02] * 3)
    y[:, 5] += 9.81
    return Record(np.arange(y.shape[0]) / RATE_HZ, y)


def _stamps(rec: Record) -> np.ndarray:
    return T0_NS + np.round(rec.t_s * 1e9).astype(np.int64)


def _watch(rec: Record, sizes=(4096,), value_grid=None) -> InterpWatch:
    """Count a record in blocks of the given sizes (cycled), then judge."""
    watch = InterpWatch(HygieneStats(value_grid=dict(value_grid or {})), WarningLog())
    t, y, k, i = _stamps(rec), rec.samples, 0, 0
    while k < t.size:
        n = sizes[i % len(sizes)]
        watch.take(t[k:k + n], y[k:k + n])
        k, i = k + n, i + 1
    watch.judge(RATE_HZ)
    return watch


@pytest.mark.parametrize('per_update, share', [(2.5, 0.2), (3.2, 0.375), (6.35, 0.685)])
def test_an_interpolated_accelerometer_is_named_with_its_update_rate(per_update, share):
    # realsense-ros linear_interpolation: the accelerometer between its updates on the
    # gyro's stamps.  (k - 2) / k of the triples of k messages per update lie on a line.
    rec = degrade(_record(300.0, seed=1), 'interpolate', per_update)
    watch = _watch(rec)
    assert list(watch.stats.interpolated) == ['accel_x', 'accel_y', 'accel_z']
    found = list(watch.stats.interpolated.values())
    assert_allclose(found[:2], share, atol=0.02)
    # accel_z's 9.81 widens its tolerance (relative to the values): a few more lines.
    assert_allclose(found[2], share, atol=0.05)
    line = watch._warn.lines[0]
    assert line.startswith(INTERPOLATED) and 'linear_interpolation' in line
    said = float(line.split('about every ')[1].split(' samples')[0])
    assert_allclose(said, per_update, rtol=0.05)
    # Streaming equals batch: blocks of a few rows (a node's) count the same triples.
    assert np.array_equal(_watch(rec, sizes=(1, 2, 3, 7)).counts, watch.counts)


def test_own_samples_held_jittered_and_quantised_values_are_not_interpolated():
    rec = _record(300.0, seed=2)
    for case in (rec, degrade(rec, 'hold', 2.0), degrade(rec, 'poll', 1.5),
                 degrade(rec, 'arrival_jitter', 1.0), degrade(rec, 'low_rate', 10.0)):
        watch = _watch(case)
        share = watch.counts[1] / np.maximum(watch.counts[0], 1)    # held: few move
        assert share.max() < INTERP_MIN / 2 and not watch._warn.lines, share
    # A sensor whose LSB is about its noise repeats its steps by chance (the ADIS16405
    # accelerometers: 15 % of their triples); an axis on a value grid is not judged.
    step = 0.02
    grid = rec._replace(samples=np.round(rec.samples / step) * step)
    assert (_watch(grid).counts[1, 3:] / _watch(grid).counts[0, 3:]).min() > INTERP_MIN
    on_grid = _watch(grid, value_grid={a: step for a in AXES[3:]})
    assert not on_grid.stats.interpolated and not on_grid._warn.lines


def test_a_session_names_interpolated_values_and_keeps_them_over_a_checkpoint():
    rec = degrade(_record(120.0, seed=3), 'interpolate', 3.2)
    t, y = _stamps(rec), rec.samples
    s = Session()
    half = t.size // 2
    s.add(t[:half], y[:half])
    meta, arrays = s.gate.state()
    again = Session()
    again.gate.restore(meta, arrays)
    assert np.array_equal(again.gate.interp.counts, s.gate.interp.counts)
    s.add(t[half:], y[half:])
    s.flush()
    assert set(s.stats.interpolated) == {'accel_x', 'accel_y', 'accel_z'}
    assert any(w.startswith(INTERPOLATED) for w in s.warnings)
