"""Clipped axes: values piled at the ends of the range are found, named and not reported."""

from pathlib import Path

import numpy as np
from numpy.testing import assert_allclose
import pytest

from conftest import T0_NS
from imu_allan.io.csv_io import read_csv
from imu_allan.pipeline.analysis import analyze
from imu_allan.pipeline.clipping import ClipWatch, KEEP_SHARE
from imu_allan.pipeline.hygiene import HygieneStats, WarningLog
from imu_allan.pipeline.session import Session

RATE_HZ = 100.0
N_TRUE = np.array([1e-3] * 3 + [1e-2] * 3)
SD = N_TRUE * np.sqrt(RATE_HZ)       # per-sample sd of the white noise
AXES6 = ('gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z')


def _still(n: int, seed: int) -> tuple:
    rng = np.random.default_rng(seed)
    y = rng.standard_normal((n, 6)) * SD
    y[:, :3] += 0.01                 # a gyro bias: the range is not centred on the mean
    y[:, 5] += 9.80665
    return T0_NS + np.arange(n, dtype=np.int64) * 10_000_000, y


def _run(t, y) -> Session:
    s = Session()
    for k in range(0, t.size, 4096):
        s.add(t[k:k + 4096], y[k:k + 4096])
    s.flush()
    return s


def test_a_gyro_clipped_below_its_noise_peaks_is_named_and_left_out():
    t, y = _still(60_000, seed=1)
    # A range of +-0.3 sd around the bias: most values pinned at the two ends.
    y[:, 0] = np.clip(y[:, 0], 0.01 - 0.3 * SD[0], 0.01 + 0.3 * SD[0])
    s = _run(t, y)
    assert_allclose(s.stats.clipped['gyro_x'], 2 * 0.382, atol=0.02)   # 2 P(z > 0.3)
    assert set(s.stats.clipped) == {'gyro_x'}
    line = next(w for w in s.warnings if 'gyro_x is clipped' in w)
    assert 'wider range' in line and 'left out' in line
    result = analyze(s)
    assert result.fits['gyro_x'] is None      # before: N 0.2 times the truth, no warning
    assert 'clipped' in result.summary_line('gyro_x')
    assert any('gyro_x is clipped' in line for line in
               result.with_trust_comments('x: 1\n').splitlines()[:-1])
    # The other axes as before (their N within 2 %, several of their sd of 0.5 %).
    for j, axis in enumerate(AXES6[1:], start=1):
        assert_allclose(result.fits[axis].optimised['N'].value, N_TRUE[j], rtol=0.02)


def test_occasional_clipping_is_named_and_the_axis_kept_with_the_true_noise():
    t, y = _still(180_000, seed=2)
    y[:, 0] = np.clip(y[:, 0], 0.01 - 3.5 * SD[0], 0.01 + 3.5 * SD[0])   # 5e-4 clipped
    s = _run(t, y)
    assert 0 < s.stats.clipped['gyro_x'] <= KEEP_SHARE
    assert any('gyro_x is clipped' in w and 'analysed as it is' in w for w in s.warnings)
    n = analyze(s).fits['gyro_x'].optimised['N']
    assert n.kind == 'estimate' and n.ci95[0] <= N_TRUE[0] <= n.ci95[1]


def _watch(y: np.ndarray, block: int = 4096) -> ClipWatch:
    watch = ClipWatch(HygieneStats(), WarningLog(), ('u',) * 6)
    for k in range(0, y.shape[0], block):
        watch.take(y[k:k + block])
    return watch


def test_quantised_held_and_frozen_axes_are_not_clipped():
    rng = np.random.default_rng(3)
    counts = np.round(rng.standard_normal((200_000, 6)) * [12, 12, 12, 1.3, 1.3, 0.4])
    held = np.repeat(rng.standard_normal((50_000, 6)), 4, axis=0)
    frozen = np.ones((5000, 6))
    for y in (counts * 0.05, held, frozen):
        assert _watch(y).stats.clipped == {}


def test_the_counts_do_not_depend_on_the_blocks_and_survive_a_checkpoint():
    rng = np.random.default_rng(4)
    y = np.clip(rng.standard_normal((30_000, 6)), -2.5, 2.5)
    a, b = _watch(y, 4096), _watch(y, 77)
    assert a.stats.clipped == b.stats.clipped and len(a.stats.clipped) == 6
    assert np.array_equal(a.value, b.value) and np.array_equal(a.count, b.count)
    meta, arrays = a.state()
    c = ClipWatch(HygieneStats(), WarningLog(), ('u',) * 6)
    c.restore(meta, arrays)
    assert np.array_equal(c.count, a.count) and c.n == a.n


@pytest.mark.parametrize('name', ['adis16405/adis16405_run1.csv.gz',
                                  'adis16405/adis16405_run4.csv.gz',
                                  'mpu6050_irregular/mpu6050_static_11min.csv.gz'])
def test_the_real_records_are_not_clipped(shared_dir: Path, name):
    data = read_csv(shared_dir / 'realdata' / name, columns=list(AXES6))
    watch = _watch(data.samples, 65536)
    assert watch.stats.clipped == {}
    # Their extremes are rare: at most a dozen samples on any axis' extreme value.
    assert watch.count[..., 0].max() <= 12
