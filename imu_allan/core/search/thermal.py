"""
The bias's thermal coefficient, regressed in the time domain against the noise model.

The record's block means of an axis y and of the temperature T (kept beside the
accumulator, :class:`imu_allan.pipeline.thermal.ThermalFeed`) give differences of
neighbouring block means d_y and d_T.  With ``y = n + c T``, ``d_y = c d_T + d_n``, and
d_n is Gaussian with the covariance Sigma(K) that the axis' noise model fixes (the
generalised covariances of its terms, as the ramp test of
:mod:`imu_allan.core.search.evidence` uses), the random walk's share K^2 left free.
For each K, c is the GLS estimate (Aitken)::

    c(K) = d_T' Sigma^-1 d_y / d_T' Sigma^-1 d_T,   Var c = 1 / d_T' Sigma^-1 d_T

and K maximises the Gaussian likelihood of the residual.  The 95 % interval is
c +- 1.96 sqrt(Var c) at that K.  The noise model is the axis' uncompensated fit: a
thermal drift it took for noise (a Gauss-Markov process, more random walk) only
widens the interval (the random walk is re-fitted with c; deterministic terms carry no
covariance).  A record's own block means, not the Allan curve: the Allan covariance at
one tau reads the noise's spectrum over that tau's band, where the coefficient's error
is the noise at the temperature's own (slow) frequencies; its t interval covered 83 %
on simulated random-walk records; this estimator's coverage is in docs/thermal.md.
"""

import math
from typing import NamedTuple

import numpy as np

from imu_allan.core.noise.terms import TERMS, terms_of
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.rules import (DRIFT_BASIS, DRIFT_FALSE_ALARM, THERMAL_BLOCKS,
                                  THERMAL_MIN_SPAN_C)
from imu_allan.core.search.evidence import _stencil_cov


class ThermalCoefficient(NamedTuple):
    """
    The bias's thermal coefficient of one axis.

    Attributes
    ----------
    value : float
        c [unit/degC]: the bias changes by c per degC; NaN when not determined.
    ci95 : tuple of float
        Its 95 % interval [unit/degC] (NaN, NaN when not determined).
    significant : bool
        True when the interval excludes 0: the bias follows the temperature.
    span_c : float
        Range of the temperature's block means over the record [degC].
    reason : str
        Why c is not determined ('' when it is).

    """

    value: float
    ci95: tuple
    significant: bool
    span_c: float
    reason: str = ''

    def to_json(self) -> dict:
        """Return the JSON of docs/outputs.md (None for NaN)."""
        def num(x):
            return float(x) if math.isfinite(x) else None
        return {'value': num(self.value), 'ci95': [num(self.ci95[0]), num(self.ci95[1])],
                'significant': self.significant, 'span_c': num(self.span_c),
                'reason': self.reason}


def model_terms(noise: AxisNoise) -> list:
    """
    Return the stochastic terms of a model as (name, coefficient, nonlinear parameters).

    Parameters
    ----------
    noise : AxisNoise
        The axis model, SI units.

    Returns
    -------
    list of (str, float, tuple)
        One entry per term instance that has a generalised covariance.

    """
    out = []
    for _label, name, params in terms_of(noise):
        term = TERMS[name]
        if term.gcov is None:
            continue
        nonlinear = tuple(params[s] for s in term.nonlinear)
        out.append((name, float(term.to_coef(params[term.symbols[0]], *nonlinear)),
                    nonlinear))
    return out


def _not_determined(span_c: float, reason: str) -> ThermalCoefficient:
    return ThermalCoefficient(math.nan, (math.nan, math.nan), False, span_c, reason)


def thermal_regression(y, temp_c, rate_hz: float, terms: list,
                       n_blocks: int = THERMAL_BLOCKS) -> ThermalCoefficient:
    """
    Estimate one axis' thermal coefficient with its 95 % interval (module docstring).

    Parameters
    ----------
    y : array_like
        Shape (n,), the axis' samples (raw or block-averaged) [unit].
    temp_c : array_like
        Shape (n,), the temperature at each of them [degC].
    rate_hz : float
        Their rate [Hz].
    terms : list of (str, float, tuple)
        The axis' noise terms (:func:`model_terms`).
    n_blocks : int
        Blocks the record is cut into.

    Returns
    -------
    ThermalCoefficient
        Not determined when the record is too short (fewer than 16 blocks) or the
        temperature's block means span less than
        :data:`imu_allan.core.rules.THERMAL_MIN_SPAN_C`.

    """
    from scipy.linalg import cho_factor, cho_solve
    from scipy.optimize import minimize_scalar

    y = np.asarray(y, dtype=np.float64)
    t = np.asarray(temp_c, dtype=np.float64)
    n_blocks = min(int(n_blocks), y.size // 2)
    if n_blocks < 16:
        return _not_determined(math.nan, 'the record is too short (fewer than 16 blocks)')
    per = y.size // n_blocks
    mean_y = y[:per * n_blocks].reshape(n_blocks, per).mean(axis=1)
    mean_t = t[:per * n_blocks].reshape(n_blocks, per).mean(axis=1)
    span = float(mean_t.max() - mean_t.min())
    if not span >= THERMAL_MIN_SPAN_C:
        return _not_determined(span, f'the temperature did not change (its block means '
                               f'span {span:.3g} degC)')
    lag_s = per / float(rate_hz)
    d, x = np.diff(mean_y), np.diff(mean_t)
    fixed = [tm for tm in terms if tm[0] != 'random_walk']
    c_rw = sum(tm[1] for tm in terms if tm[0] == 'random_walk')
    base = _stencil_cov(fixed, lag_s, d.size)
    unit_rw = _stencil_cov([('random_walk', 1.0, ())], lag_s, d.size)
    scale = max(float(np.mean(d * d)), 1e-300)
    eye = np.eye(d.size)

    def solve(log_k2: float) -> tuple[float, float, float]:
        """Return (log-likelihood, c, Var c) at K^2 = exp(log_k2)."""
        cov = (base + math.exp(log_k2) * unit_rw) / scale
        try:
            cf = cho_factor(cov + 1e-12 * eye * np.trace(cov) / d.size)
        except np.linalg.LinAlgError:
            return -math.inf, math.nan, math.nan
        w = cho_solve(cf, x)
        info = float(w @ x)
        if not info > 0:
            return -math.inf, math.nan, math.nan
        z = d / math.sqrt(scale)
        c = float(w @ z) / info
        r = z - c * x
        logdet = 2.0 * float(np.sum(np.log(np.diag(cf[0]))))
        # REML: the restricted likelihood (less c's own degree of freedom) does not
        # take the share of the noise that c explains away from K^2.
        return (-0.5 * (float(r @ cho_solve(cf, r)) + logdet + math.log(info)),
                c * math.sqrt(scale), scale / info)

    # K^2 from 1e-6 to 1e6 times its fitted value (or the data's own scale without one).
    k0 = c_rw if c_rw > 0 else scale * lag_s
    res = minimize_scalar(lambda v: -solve(v)[0], method='bounded',
                          bounds=(math.log(k0) - 14.0, math.log(k0) + 14.0),
                          options={'xatol': 1e-3})
    _ll, c, var = solve(float(res.x))
    if not (math.isfinite(c) and math.isfinite(var)):
        return _not_determined(span, 'the regression is singular')
    half = 1.959964 * math.sqrt(var)
    lo, hi = c - half, c + half
    return ThermalCoefficient(c, (lo, hi), bool(lo > 0 or hi < 0), span)


class DriftCheck(NamedTuple):
    """
    Result of :func:`drift_test`.

    Attributes
    ----------
    lr : float
        2 (restricted log-likelihood with the slow drift - without it), each maximised
        over the random walk's level [-].
    amplitude : float
        Range of the fitted slow drift over the record [unit].
    significant : bool
        lr beyond the chi-square quantile of :data:`imu_allan.core.rules.DRIFT_FALSE_ALARM`.

    """

    lr: float
    amplitude: float
    significant: bool


def drift_test(y, rate_hz: float, terms: list, n_blocks: int = THERMAL_BLOCKS,
               n_basis: int = DRIFT_BASIS) -> DriftCheck | None:
    """
    Test a slow deterministic drift against the noise model, in the time domain.

    The ramp test of :mod:`imu_allan.core.search.evidence` for any slow drift (a
    temperature's): the record's block means carry, under the alternative, a smooth
    function of time, the first ``n_basis`` cosines of the record (DCT-II, half-cycles
    1 .. n_basis: a warm-up, a day's cycle, a 40-minute air-conditioning cycle in a
    3 h record), and the differences of neighbouring block means are Gaussian with the
    covariance Sigma(K) of the noise model, K^2 free.  Both restricted likelihoods
    (REML: the drift's own degrees of freedom do not shrink K) are maximised over K;
    a random walk spreads its power over every frequency, as K fixes it, a drift puts
    it at the slow ones beyond what K explains.  Twice their difference is compared
    with the chi-square(n_basis) quantile at :data:`imu_allan.core.rules.DRIFT_FALSE_ALARM`.

    Parameters
    ----------
    y : array_like
        Shape (n,), samples (raw or block-averaged) [unit].
    rate_hz : float
        Their rate [Hz].
    terms : list of (str, float, tuple)
        The fitted noise terms (:func:`model_terms`).
    n_blocks : int
        Blocks the record is cut into.
    n_basis : int
        Cosines of the slow drift.

    Returns
    -------
    DriftCheck or None
        None when the record is too short (fewer than 4 blocks per cosine).

    """
    from scipy.linalg import cho_factor, cho_solve
    from scipy.optimize import minimize_scalar

    from imu_allan.core.allan.quantiles import chi2_ppf

    y = np.asarray(y, dtype=np.float64)
    n_blocks = min(int(n_blocks), y.size // 2)
    if n_blocks < 4 * n_basis:
        return None
    per = y.size // n_blocks
    means = y[:per * n_blocks].reshape(n_blocks, per).mean(axis=1)
    lag_s = per / float(rate_hz)
    d = np.diff(means)
    k = np.arange(1, n_basis + 1)
    basis = np.cos(np.pi * np.outer(np.arange(n_blocks) + 0.5, k) / n_blocks)
    x = np.diff(basis, axis=0)
    fixed = [tm for tm in terms if tm[0] != 'random_walk']
    c_rw = sum(tm[1] for tm in terms if tm[0] == 'random_walk')
    base = _stencil_cov(fixed, lag_s, d.size)
    unit_rw = _stencil_cov([('random_walk', 1.0, ())], lag_s, d.size)
    scale = max(float(np.mean(d * d)), 1e-300)
    z = d / math.sqrt(scale)
    eye = np.eye(d.size)

    def loglik(log_k2: float, drift: bool) -> tuple[float, np.ndarray]:
        cov = (base + math.exp(log_k2) * unit_rw) / scale
        try:
            cf = cho_factor(cov + 1e-12 * eye * np.trace(cov) / d.size)
        except np.linalg.LinAlgError:
            return -math.inf, np.zeros(n_basis)
        logdet = 2.0 * float(np.sum(np.log(np.diag(cf[0]))))
        beta = np.zeros(n_basis)
        extra = 0.0
        if drift:
            w = cho_solve(cf, x)
            info = x.T @ w
            beta = np.linalg.solve(info, w.T @ z)
            extra = float(np.linalg.slogdet(info)[1])
        r = z - x @ beta
        return -0.5 * (float(r @ cho_solve(cf, r)) + logdet + extra), beta

    k0 = c_rw if c_rw > 0 else scale * lag_s
    best = {}
    for drift in (False, True):
        res = minimize_scalar(lambda v: -loglik(v, drift)[0], method='bounded',
                              bounds=(math.log(k0) - 14.0, math.log(k0) + 14.0),
                              options={'xatol': 1e-3})
        best[drift] = (-float(res.fun), float(res.x))
    lr = 2.0 * (best[True][0] - best[False][0])
    beta = loglik(best[True][1], True)[1] * math.sqrt(scale)
    shape = basis @ beta
    limit = float(chi2_ppf(1.0 - DRIFT_FALSE_ALARM, n_basis))
    return DriftCheck(float(lr), float(shape.max() - shape.min()), bool(lr >= limit))
