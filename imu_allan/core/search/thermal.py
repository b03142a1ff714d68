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

and K maximises the restricted (REML) likelihood of the residual.  The 95 % interval
is the profile-likelihood one: 2 (l(c_hat) - max_K l(c, K)) <= chi2(1) at 95 %, since K
and c trade against each other on a slow temperature (the Wald interval at the best K
covered 85-90 % on simulated random-walk records).  The noise model is the axis'
uncompensated fit: a thermal drift it took for noise (a Gauss-Markov process, more
random walk) only widens the interval (the random walk is re-fitted with c;
deterministic terms carry no covariance).  The record's own block means, not the Allan
curve: the Allan covariance at one tau reads the noise over that tau's band, where the
coefficient's error is the noise at the temperature's own slow frequencies (its
interval covered 83 % on simulated random-walk records).  Coverage, power and size:
``bench/thermal_power.py``, docs/thermal.md.
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


class _BlockModel:
    """
    Differences of block means against the noise model, K^2 free, in its eigenbasis.

    Sigma(K) = S0 + K^2 S1 (S0 the fixed terms' covariance, S1 the random walk's per
    unit K^2, :func:`imu_allan.core.search.evidence._stencil_cov`).  With the
    generalised eigenvectors V of (S0, S1) (V' S1 V = I, V' S0 V = diag(lambda)),
    Sigma(K)^-1 = V diag(1 / (lambda + K^2)) V' and ln det Sigma(K) = sum ln(lambda +
    K^2) + const: one eigendecomposition, then every K costs O(n).
    """

    def __init__(self, d: np.ndarray, terms: list, lag_s: float):
        from scipy.linalg import eigh

        fixed = [tm for tm in terms if tm[0] != 'random_walk']
        self.k2 = sum(tm[1] for tm in terms if tm[0] == 'random_walk')
        self.unit = math.sqrt(max(float(np.mean(d * d)), 1e-300))
        base = _stencil_cov(fixed, lag_s, d.size)
        unit_rw = _stencil_cov([('random_walk', 1.0, ())], lag_s, d.size)
        # Scaled so that K^2 = 1 adds a random walk of the data's own size.
        self.rw_scale = float(np.trace(unit_rw)) / d.size / self.unit ** 2
        s1 = unit_rw / np.trace(unit_rw) * d.size
        s0 = base / self.unit ** 2
        s1 = s1 + 1e-12 * np.eye(d.size)
        self.lam, self.vec = eigh(s0, s1)
        self.lam = np.maximum(self.lam, 0.0) + 1e-12 * max(float(self.lam.max()), 1.0)
        self.z = self.vec.T @ (d / self.unit)

    def rotate(self, x: np.ndarray) -> np.ndarray:
        """Return V' x / unit-free regressors (x in the units of the differences' own)."""
        return self.vec.T @ x

    def weights(self, log_k2: float) -> np.ndarray:
        """Return 1 / (lambda + K^2) in the eigenbasis (K^2 = exp(log_k2), scaled)."""
        return 1.0 / (self.lam + math.exp(log_k2))

    def best(self, loglik) -> float:
        """Return the log K^2 (scaled) that maximises ``loglik``: 1e-6 to 1e6 of a start."""
        from scipy.optimize import minimize_scalar

        k0 = self.k2 * self.rw_scale if self.k2 > 0 else 1.0
        res = minimize_scalar(lambda v: -loglik(v), method='bounded',
                              bounds=(math.log(k0) - 14.0, math.log(k0) + 14.0),
                              options={'xatol': 1e-3})
        return float(res.x)


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
    model = _BlockModel(np.diff(mean_y), terms, per / float(rate_hz))
    x = model.rotate(np.diff(mean_t))

    def solve(log_k2: float) -> tuple[float, float, float]:
        """Return (restricted log-likelihood, c, Var c) at K^2 = exp(log_k2)."""
        w = model.weights(log_k2)
        info = float(np.sum(x * x * w))
        if not info > 0:
            return -math.inf, math.nan, math.nan
        c = float(np.sum(x * model.z * w)) / info
        r = model.z - c * x
        # REML: the restricted likelihood (less c's own degree of freedom) does not
        # take the share of the noise that c explains away from K^2.
        return (-0.5 * (float(np.sum(r * r * w)) - float(np.sum(np.log(w)))
                        + math.log(info)), c * model.unit, model.unit ** 2 / info)

    log_k2 = model.best(lambda v: solve(v)[0])
    _ll, c, var = solve(log_k2)
    if not (math.isfinite(c) and math.isfinite(var)):
        return _not_determined(span, 'the regression is singular')
    lo, hi = _profile_interval(model, x, c / model.unit, math.sqrt(var) / model.unit)
    lo, hi = lo * model.unit, hi * model.unit
    return ThermalCoefficient(c, (lo, hi), bool(lo > 0 or hi < 0), span)


def _profile_interval(model: _BlockModel, x: np.ndarray, c: float, se: float) -> tuple:
    """
    Return the 95 % profile-likelihood interval of c (scaled), K^2 re-fitted at each c.

    2 (l(c_hat) - l_p(c)) <= chi2(1) at 95 % (3.841): the random walk's level and c
    trade against each other on a slow temperature, which the Wald interval at one K
    ignores (it covered 85-90 % on simulated random-walk records).
    """
    from scipy.optimize import brentq

    def profile(cv: float) -> float:
        r = model.z - cv * x

        def ll(v: float) -> float:
            w = model.weights(v)
            return -0.5 * (float(np.sum(r * r * w)) - float(np.sum(np.log(w))))
        return ll(model.best(ll))

    top = profile(c)
    limit = 0.5 * 3.841459

    def gap(cv: float) -> float:
        return top - profile(cv) - limit

    ends = []
    for sign in (-1.0, 1.0):
        step = 2.0 * se
        while gap(c + sign * step) < 0 and step < 1e6 * se:
            step *= 2.0
        ends.append(brentq(gap, c, c + sign * step, xtol=1e-3 * se)
                    if gap(c + sign * step) >= 0 else c + sign * step)
    return ends[0], ends[1]
