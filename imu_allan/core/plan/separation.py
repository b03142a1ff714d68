"""
How long a record must be to tell two explanations of the long-tau curve apart.

The rivals are a rate ramp against a random walk (both raise the curve at long tau),
one Gauss-Markov process against two, and, where the fit could not tell them apart
(:func:`imu_allan.core.search.choice.random_walk_or_slow_process`), a random walk
against a slower Gauss-Markov process that turns over inside the record; and where the
fit could not tell which of two tied Gauss-Markov processes is the bias instability,
how long until their levels are ordered (:func:`ordering`).  For a record
of a given length the curve the fitted model predicts is compared with the best rival
curve (the rival model fitted to it by GLS at the model's own Sigma); the mismatch
delta^T Sigma^-1 delta is the non-centrality lambda of the likelihood-ratio statistic
that would reject the rival.
The record separates the two when lambda >= 10.5, where a 5 % test on one degree of
freedom has 90 % power ((1.96 + 1.28)^2; Cohen, Statistical power analysis, 1988).
"""

import math
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares

from imu_allan.core.noise.shapes import GM_PEAK_TAU
from imu_allan.core.noise.terms import base_name, TERMS
from imu_allan.core.plan.precision import _avar, _log_params, Component, Z95

#: Non-centrality at which a 5 % test on one degree of freedom has 90 % power.
LAMBDA_SEPARATED = 10.5


#: Question of the random walk against a slower process (see :func:`rivals`).
SLOW_PROCESS = 'random walk or slower process'
#: Question of which Gauss-Markov process is the bias instability (:func:`ordering`).
ORDERING = 'which process is the bias instability'


def rivals(comps: Sequence[Component], tau_max_s: float,
           slow_peak_s: float | None = None) -> list:
    """
    Rival models of a fitted one: (question, rival components) pairs.

    A random walk is rivalled by a ramp (and a ramp by a random walk) matching it at
    ``tau_max_s``; two Gauss-Markov processes by one (the one with the larger B).  With
    ``slow_peak_s`` (the fit found the random walk replaceable by a slower process that
    turns over inside its record, whose longest tau that is), the random walk is
    rivalled by a Gauss-Markov process peaking there and matching it at that tau: a
    longer record tells whether the curve keeps rising.
    """
    out = []
    bases = [base_name(c.label) for c in comps]
    rest = [c for c, b in zip(comps, bases) if b not in ('random_walk', 'rate_ramp')]
    if 'random_walk' in bases and 'rate_ramp' not in bases:
        k2 = comps[bases.index('random_walk')].coef
        out.append(('ramp or random walk',
                    rest + [Component('rate_ramp', k2 * 2.0 / (3.0 * tau_max_s), ())]))
    elif 'rate_ramp' in bases and 'random_walk' not in bases:
        r2 = comps[bases.index('rate_ramp')].coef
        out.append(('ramp or random walk',
                    rest + [Component('random_walk', r2 * 1.5 * tau_max_s, ())]))
    gm = [i for i, b in enumerate(bases) if b in ('bias_instability', 'gauss_markov')]
    if len(gm) == 2:
        level = {i: comps[i].values()[0] for i in gm}
        drop = min(gm, key=lambda i: level[i])
        keep = max(gm, key=lambda i: level[i])
        one = [c if i != keep else Component('bias_instability', c.coef, c.phi)
               for i, c in enumerate(comps) if i != drop]
        out.append(('one or two Gauss-Markov', one))
    if slow_peak_s is not None and 'random_walk' in bases:
        gm_term = TERMS['gauss_markov']
        t = slow_peak_s / GM_PEAK_TAU
        rw = comps[bases.index('random_walk')]
        used = bases.count('gauss_markov')
        label = f'gauss_markov_{used + 1}' if used else 'gauss_markov'
        at = np.array([slow_peak_s])
        coef = rw.coef * float(rw.term.shape(at)[0] / gm_term.shape(at, t)[0])
        out.append((SLOW_PROCESS, [c for c, b in zip(comps, bases) if b != 'random_walk']
                    + [Component(label, coef, (t,))]))
    return out


def mismatch(true_avar: np.ndarray, sigma: np.ndarray, rival: Sequence[Component],
             tau: np.ndarray, max_peak_s: float | None = None) -> float:
    """
    Smallest delta^T Sigma^-1 delta between a curve and a rival model's curves.

    Parameters
    ----------
    true_avar : np.ndarray
        Shape (k,), the model's AVAR at ``tau`` [unit^2, scaled like ``sigma``].
    sigma : np.ndarray
        Shape (k, k), its covariance [same units squared].
    rival : sequence of Component
        The rival model, its starting point (coefficients in the same scale).
    tau : np.ndarray
        Shape (k,), averaging times [s].
    max_peak_s : float, optional
        Latest ADEV peak of the rival's Gauss-Markov processes [s] (default four times
        the longest tau: the rival's bumps sit about inside the record, as in the fit).

    Returns
    -------
    float
        The non-centrality lambda [-].

    """
    chol = np.linalg.cholesky(sigma + 1e-12 * np.trace(sigma) / tau.size * np.eye(tau.size))
    theta0 = _log_params(rival)
    lo = np.full(theta0.size, -np.inf)
    hi = np.full(theta0.size, np.inf)
    i = 0
    for c in rival:
        if c.term.nonlinear and base_name(c.label) in ('bias_instability', 'gauss_markov'):
            # The rival's bump must sit inside the record, as in the fit.
            lo[i + 1] = math.log(2.0 * tau.min())
            peak = 4.0 * tau.max() if max_peak_s is None else max_peak_s
            hi[i + 1] = math.log(peak / GM_PEAK_TAU)
            theta0[i + 1] = float(np.clip(theta0[i + 1], lo[i + 1] + 1e-9, hi[i + 1] - 1e-9))
        i += len(c.term.symbols)

    def resid(theta):
        return np.linalg.solve(chol, _avar(rival, theta, tau) - true_avar)

    sol = least_squares(resid, theta0, bounds=(lo, hi), x_scale=1.0, max_nfev=200)
    return float(2.0 * sol.cost)


def scaled(comps: Sequence[Component], scale: float) -> list:
    """Return the components with their coefficients divided by ``scale``."""
    return [Component(c.label, c.coef / scale, c.phi) for c in comps]


def ordering(columns: dict, values: dict, present) -> np.ndarray | None:
    """
    Return the non-centrality per length of the test that orders B against a tied B.

    Where the fit reports T_B as not identified because another Gauss-Markov process's
    B interval reaches B's (:func:`imu_allan.core.search.choice.ambiguous_bias`), T_B is
    known once the two levels are ordered.  Their 95 % intervals are ln B +- asinh(w)
    (w the relative half-width); they part when |ln(B / B_other)| exceeds the sum of
    the two, the test at correlation -1 the fit uses.  As a non-centrality on the scale
    of the other questions, lambda = (Z95 ln(B / B_other) / (asinh(w) + asinh(w_other)))^2
    (3.84 where the intervals touch); the least over the tied processes.  None when
    no process is tied.
    """
    b, t_b = (present or {}).get('B'), (present or {}).get('T_B')
    if b is None or t_b is None or t_b.kind != 'not_identified' or 'B' not in columns:
        return None
    lams = []
    for name, col in columns.items():
        other = present.get(name)
        if (not name.endswith('.B') or other is None or other.kind != 'estimate'
                or other.ci95[1] < b.ci95[0]):
            continue
        gap = Z95 * abs(math.log(values['B'] / values[name]))
        lams.append((gap / (np.arcsinh(columns['B']) + np.arcsinh(col))) ** 2)
    return np.min(lams, axis=0) if lams else None


__all__ = ['LAMBDA_SEPARATED', 'mismatch', 'ordering', 'ORDERING', 'rivals', 'scaled',
           'SLOW_PROCESS', 'TERMS']
