"""A noise level that changed during the record (pipeline/level_report.py)."""

import numpy as np
import pytest

from conftest import STILL_SIGMA, T0_NS
from imu_allan import AXES
from imu_allan.core.noise.generators import filtered_white_noise
from imu_allan.pipeline.analysis import analyze
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.level_report import NOISE_CHANGED
from imu_allan.pipeline.session import Session

RATE_HZ = 100.0
N_ROWS = int(3600 * RATE_HZ)
#: gyro_x's white noise steps up by this factor halfway through the hour.
STEP = 1.12


def _analysed(samples: np.ndarray):
    stamp_ns = T0_NS + np.round(np.arange(samples.shape[0]) * 1e9 / RATE_HZ).astype(np.int64)
    session = Session(SessionConfig())
    session.add(stamp_ns, samples)
    session.flush()
    return analyze(session)


def _still(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y = rng.normal(0.0, STILL_SIGMA, (N_ROWS, 6))
    y[:, 5] += 9.80665
    return y


@pytest.fixture(scope='module')
def stepped():
    """Return the hour whose gyro_x noise steps halfway, analysed whole and by halves."""
    y = _still(seed=11)
    y[N_ROWS // 2:, 0] *= STEP
    return _analysed(y), _analysed(y[:N_ROWS // 2]), _analysed(y[N_ROWS // 2:])


def _n(result, axis: str):
    return result.fits[axis].optimised['N']


def test_a_noise_level_that_stepped_is_named_and_its_interval_takes_in_both_halves(stepped):
    whole, first, second = stepped
    named = [w for w in whole.warnings if w.startswith(NOISE_CHANGED)]
    assert len(named) == 1 and 'on gyro_x' in named[0], whole.warnings
    n = _n(whole, 'gyro_x')
    assert n.kind == 'estimate' and 'noise level changed' in n.reason
    # Degraded within clean: each half's own interval overlaps the whole's (before the
    # widening the whole's 1.1 % half-width missed both halves, 6 % apart).
    for half in (first, second):
        lo, hi = _n(half, 'gyro_x').ci95
        assert lo <= n.ci95[1] and n.ci95[0] <= hi, (half, n)
    # The wander's 95 % range: ln AVAR of two equal halves has sd ln(STEP^2) / 2, so
    # N exp(+-1.96 ln(STEP) / 2) spans STEP^1.96; up to STEP^2.5 with the estimate's noise.
    assert STEP ** 1.5 < n.ci95[1] / n.ci95[0] < STEP ** 2.5


def test_the_steady_axes_keep_their_statistical_intervals(stepped):
    whole = stepped[0]
    for axis in AXES[1:]:
        n = _n(whole, axis)
        assert 'noise level' not in n.reason
        assert n.ci95[1] / n.ci95[0] < 1.04, (axis, n)


def test_the_consumer_files_carry_the_change(stepped):
    text = stepped[0].kalibr_yaml()
    assert f'# WARNING {NOISE_CHANGED} on gyro_x' in text
    assert stepped[0].to_json()['axes']['gyro_x']['params']['N']['reason']


@pytest.mark.parametrize('filter_s', [0.02, 0.05])
def test_a_steady_filtered_sensor_is_not_called_a_change(filter_s):
    # A low-pass filter correlates neighbouring samples: the chance spread of the
    # stretches is larger than white noise's at a few filter times (1.4x at 3 T_f),
    # so the tested tau spans 20 T_f and more.
    rng = np.random.default_rng(12)
    y = _still(seed=13)
    for j in range(6):
        y[:, j] = filtered_white_noise(STILL_SIGMA[j] / RATE_HZ ** 0.5, filter_s, RATE_HZ,
                                       N_ROWS, rng) + (9.80665 if j == 5 else 0.0)
    result = _analysed(y)
    assert not [w for w in result.warnings if w.startswith(NOISE_CHANGED)], result.warnings


def test_a_record_too_short_for_the_test_says_so(stepped):
    short = _analysed(_still(seed=5)[:int(600 * RATE_HZ)])      # 10 min: 1.8 stretches
    for axis in AXES:
        notes = [n for n in short.fits[axis].notes if n.startswith('noise level over')]
        assert len(notes) == 1 and 'not tested' in notes[0], short.fits[axis].notes
        assert '21.8 min' in notes[0]
    whole = stepped[0]
    assert not any(n.startswith('noise level over') for axis in AXES
                   for n in whole.fits[axis].notes)
