"""The slow-drift test (core/search/drift.py) and its report (pipeline/drift_report.py)."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from imu_allan.core.fit.result import AxisFit, CurveCaps, Param
from imu_allan.core.noise.units import format_quoted
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.rules import DRIFT_ALPHA
from imu_allan.core.search.drift import drift_test, smooth_basis
from imu_allan.core.search.thermal import model_terms
from imu_allan.pipeline.analysis import AnalysisResult
from imu_allan.pipeline.drift_report import drift_axes, SLOW_DRIFT

RATE_HZ = 10.0
N_WHITE = 7e-4


def _record(rng, hours: float, walk: float) -> tuple:
    """Return (t_s (n,), y (n,) white + random walk [rad/s])."""
    n = int(hours * 3600 * RATE_HZ)
    dt = 1.0 / RATE_HZ
    y = (rng.standard_normal(n) * N_WHITE / math.sqrt(dt)
         + np.cumsum(rng.standard_normal(n) * walk * math.sqrt(dt)))
    return np.arange(n) * dt, y


def _terms(walk: float) -> list:
    return model_terms(AxisNoise(N=N_WHITE, K=walk))


def test_smooth_basis_is_orthonormal_cosines():
    x = smooth_basis(100, 4)
    np.testing.assert_allclose(x.T @ x, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(x[:, 0], 0.1, atol=1e-12)     # the constant: a ramp


def test_a_true_random_walk_is_not_named():
    rng = np.random.default_rng(3)
    for _ in range(3):
        _t, y = _record(rng, 2.0, 1.5e-5)
        check = drift_test(y, RATE_HZ, _terms(1.5e-5))
        assert check is not None and not check.named
        assert check.p_value >= DRIFT_ALPHA
        # The level it fits is the true one (the random walk dominates the blocks).
        assert check.k_full == pytest.approx(1.5e-5, rel=0.3)


@pytest.mark.parametrize('kind', ['cycle', 'warming'])
def test_a_smooth_drift_is_named(kind):
    rng = np.random.default_rng(5)
    t_s, y = _record(rng, 2.0, 1e-7)
    if kind == 'cycle':     # a 40-minute air-conditioning cycle
        y = y + 5e-4 * np.sin(2 * math.pi * t_s / 2400.0)
    else:                   # an exponential warming over the record
        y = y + 1e-3 * (1.0 - np.exp(-4.0 * t_s / t_s[-1]))
    check = drift_test(y, RATE_HZ, _terms(1e-5))
    assert check is not None and check.named
    assert check.p_value < DRIFT_ALPHA
    # Outside the smooth part, far less random walk than the whole record reads.
    assert check.k_rest < 0.5 * check.k_full


def test_the_test_is_deterministic_and_needs_blocks():
    rng = np.random.default_rng(7)
    _t, y = _record(rng, 0.5, 1.5e-5)
    a = drift_test(y, RATE_HZ, _terms(1.5e-5))
    assert a == drift_test(y, RATE_HZ, _terms(1.5e-5))
    assert drift_test(y[:150], RATE_HZ, _terms(1.5e-5)) is None
    bad = y.copy()
    bad[10] = np.nan
    assert drift_test(bad, RATE_HZ, _terms(1.5e-5)) is None
    assert drift_test(np.ones(y.size), RATE_HZ, _terms(1.5e-5)) is None


def _axis_fit(optimised: dict, model: AxisNoise | None = None,
              caps: CurveCaps = CurveCaps()) -> AxisFit:
    """Return an AxisFit with these parameters (what drift_axes reads of it)."""
    return AxisFit(nominal={}, optimised=optimised, terms=(), notes=(), caps=caps,
                   model=AxisNoise(N=N_WHITE, K=1e-5) if model is None else model)


def _fit(kind: str = 'estimate', caps: CurveCaps = CurveCaps()) -> AxisFit:
    k = (Param(1.2e-5, (8e-6, 1.6e-5), 'estimate', 'rad/s*s^0.5') if kind == 'estimate'
         else Param(1.6e-5, (0.0, 1.6e-5), 'upper_bound', 'rad/s*s^0.5'))
    return _axis_fit({'N': Param(N_WHITE, (6.9e-4, 7.1e-4), 'estimate', 'rad/s/sqrt(Hz)'),
                      'K': k}, caps=caps)


def test_a_named_drift_bounds_k_and_warns():
    rng = np.random.default_rng(5)
    t_s, y = _record(rng, 2.0, 1e-7)
    drifted = y + 1e-3 * (1.0 - np.exp(-4.0 * t_s / t_s[-1]))
    samples = np.zeros((y.size, 6))
    samples[:, 0], samples[:, 1] = drifted, _record(rng, 2.0, 1.5e-5)[1]
    fits = {'gyro_x': _fit(), 'gyro_y': _axis_fit({'K': _fit().optimised['K']},
                                                  AxisNoise(N=N_WHITE, K=1.5e-5)),
            'gyro_z': _fit('bound')}
    out, warnings = drift_axes(fits, samples, RATE_HZ, {})
    k = out['gyro_x'].optimised['K']
    assert k.kind == 'upper_bound' and k.value == 1.6e-5 and k.ci95 == (0.0, 1.6e-5)
    assert 'slow drift' in k.reason
    assert out['gyro_x'].optimised['N'] is fits['gyro_x'].optimised['N']
    assert out['gyro_y'] is fits['gyro_y'] and out['gyro_z'] is fits['gyro_z']
    assert len(warnings) == 1 and warnings[0].startswith(f'{SLOW_DRIFT} on gyro_x')
    assert 'temperature' in warnings[0] and 'upper bound' in warnings[0]
    # The fits passed in are not changed; without a raw copy nothing is tested.
    assert fits['gyro_x'].optimised['K'].kind == 'estimate'
    assert drift_axes(fits, None, None, {}) == (fits, ())


def test_a_drift_bound_above_the_curve_is_capped_there_and_the_warning_says_so():
    # The drift's bound is the estimate's upper end, which can lie above what the
    # record's own curve allows: it is capped there, and the warning quotes the cap.
    rng = np.random.default_rng(5)
    t_s, y = _record(rng, 2.0, 1e-7)
    samples = np.zeros((y.size, 6))
    samples[:, 0] = y + 1e-3 * (1.0 - np.exp(-4.0 * t_s / t_s[-1]))
    out, warnings = drift_axes({'gyro_x': _fit(caps=CurveCaps(K=1.1e-5))}, samples,
                               RATE_HZ, {})
    k = out['gyro_x'].optimised['K']
    assert k[:3] == (1.1e-5, (0.0, 1.1e-5), 'upper_bound') and k.source == 'curve'
    assert 'capped' in k.reason and any('capped' in n for n in out['gyro_x'].notes)
    quoted = {v: format_quoted('K', 'gyro', v, digits=3) for v in (1.1e-5, 1.6e-5)}
    assert f'upper bound, {quoted[1.1e-5]}, not' in warnings[0]
    assert quoted[1.6e-5] not in warnings[0]


def test_an_axis_the_temperature_explains_is_left_to_the_thermal_part():
    rng = np.random.default_rng(5)
    t_s, y = _record(rng, 2.0, 1e-7)
    samples = np.zeros((y.size, 6))
    samples[:, 0] = y + 1e-3 * (1.0 - np.exp(-4.0 * t_s / t_s[-1]))
    fits = {'gyro_x': _fit()}
    hot = SimpleNamespace(coefficient=SimpleNamespace(significant=True))
    assert drift_axes(fits, samples, RATE_HZ, {'gyro_x': hot}) == (fits, ())
    # Its warning reaches every consumer file's header (as the thermal one does).
    line = f'{SLOW_DRIFT} on gyro_x: ...'
    text = AnalysisResult.with_trust_comments(SimpleNamespace(fits={}, warnings=(line,)),
                                              'x: 1\n')
    assert text == f'# WARNING {line}\nx: 1\n'
