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
from imu_allan.core.rules import THERMAL_BLOCKS, THERMAL_MIN_SPAN_C
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
