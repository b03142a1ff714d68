"""
What a fit reports per parameter: estimates with intervals, or bounds.

Supported terms get their value and 95 % profile-likelihood interval; candidates the data
do not support get a one-sided 95 % upper bound from the chi-square profile of their
level (or "not identified" where the record cannot constrain them).  Then
:func:`bound_by_curve` makes the bounds honest on a short record: an estimate of N, B or
K whose interval reaches 0 is only an upper bound (its interval's upper end), and no
bound of N, B or K lies above the bound the measured curve itself sets
(:mod:`imu_allan.core.fit.caps`, which keeps it so for the bounds later steps make).
"""

import math

import numpy as np
from scipy.optimize import brentq
from scipy.special import ndtr

from imu_allan.core.allan.quantiles import chi2_ppf
from imu_allan.core.fit.caps import cap_bounds
from imu_allan.core.fit.intervals import _profile_interval
from imu_allan.core.fit.result import _unit, CurveCaps, Param
from imu_allan.core.fit.solver import _design, Fitter, Slot, Solution
from imu_allan.core.noise.shapes import GM_PEAK_TAU
from imu_allan.core.noise.terms import base_name, TERMS
from imu_allan.core.rules import PIN_MARGIN

#: Parameters always reported, with the term they belong to.
CORE_PARAMS = {'N': 'white', 'B': 'bias_instability', 'T_B': 'bias_instability',
               'K': 'random_walk'}
#: The paper's model: always part of the fit that yields the reported intervals.
_CORE_TERMS = ('white', 'filtered_white', 'bias_instability', 'random_walk')
Z95_ONE_SIDED = 1.6448536269514722


def _estimates(fitter, slots: list, sol: Solution, supported: set, threshold: float,
               symbols: dict, unit: str, notes: list,
               pinned: list | None = None) -> tuple[dict, dict]:
    """
    Values and 95 % profile intervals of the supported terms (notes appended).

    A nonlinear parameter whose estimate sits at an end of its search range (within
    2 %) is not identified by the taus: a correlation or filter time pinned there is
    the fit reshaping the curve, not a measurement.  It is reported as not identified
    (at the upper end: as a lower bound, the record being too short) and its name is
    appended to ``pinned``.  A time whose interval reaches the lower end is not
    identified either (not pinned: the model stands, the time is unknown).
    """
    optimised: dict[str, Param] = {}
    values: dict[str, dict] = {}
    for i, s in enumerate(slots):
        if s.label not in supported:
            continue
        c_si = sol.coef[i] * fitter.data.scale
        params = s.term.to_params(c_si, *sol.phi[i])
        values[s.label] = params
        for sym, template in zip(s.term.symbols, s.term.units):
            v = params[sym]
            kind, reason = 'estimate', ''
            if sym not in s.term.nonlinear:
                ci = _profile_interval(fitter.data, slots, sol, i, sym, v, threshold)
            else:
                lo_b, hi_b = s.bounds[s.term.nonlinear.index(sym)]
                ci = _profile_interval(fitter.data, slots, sol, i, sym, v, threshold,
                                       (lo_b, hi_b))
                name = symbols[(s.label, sym)]
                if (v <= lo_b * PIN_MARGIN or v >= hi_b / PIN_MARGIN) and pinned is not None:
                    pinned.append(name)
                # At the shortest value of its range, or an interval from there up (any
                # faster process would do: ADIS16405, first 10 minutes, T_B 0.064 s
                # [0.02, 86.7] where the hour's slow process lies beyond 254 s).
                why = ('pinned at the shortest value of its range' if v <= lo_b * PIN_MARGIN
                       else 'its 95 % interval reaches the shortest value of its range'
                       if ci[0] <= lo_b * 1.001 and sym.startswith('T_') else '')
                if why:
                    notes.append(f'{name}: {why}; not identified by these taus')
                    optimised[name] = Param(math.nan, (math.nan, math.nan), 'not_identified',
                                            _unit(template, unit), 'fitted',
                                            f'{why}: not identified')
                    continue
                if ci[1] >= hi_b * 0.999:
                    kind, ci = 'lower_bound', (ci[0], math.inf)
                    reason = 'may exceed the longest tau of the record: lower bound'
                    notes.append(f'{name}: may exceed the longest tau of the record; only a '
                                 'lower bound')
            optimised[symbols[(s.label, sym)]] = Param(
                float(v), (float(ci[0]), float(ci[1])), kind, _unit(template, unit), 'fitted',
                reason)
    return optimised, values


def _unsupported(fitter, slots_all: list, slots: list, sol: Solution, supported: set,
                 candidates: tuple, requested: bool, symbols: dict, unit: str,
                 optimised: dict, notes: list) -> None:
    """
    Report the candidates the data do not support: a 95 % upper bound, or not identified.

    Only core terms (and every term when the caller chose the candidates) get a bound;
    ``optimised`` and ``notes`` are filled in place.
    """
    for s in slots_all:
        if s.label in supported:
            continue
        if s.term.name not in _CORE_TERMS and not requested:
            notes.append(f'{s.label}: not supported by the data (left out)')
            continue
        others = [i for i, x in enumerate(slots) if x.label != s.label]
        rest = Solution(sol.coef[others], tuple(sol.phi[i] for i in others), sol.j)
        if s.label not in [x.label for x in slots]:    # a requested extra term
            others, rest = list(range(len(slots))), sol
        bound = _upper_bound(fitter, [slots[i] for i in others], rest, s)
        lin_sym = s.term.symbols[0]
        name = symbols[(s.label, lin_sym)]
        if math.isfinite(bound) and bound > 0:
            optimised[name] = Param(bound, (0.0, bound), 'upper_bound',
                                    _unit(s.term.units[0], unit), 'fitted',
                                    'not supported by the data: 95 % upper bound')
            notes.append(f'{name}: not supported by the data (too small or the record too '
                         'short); 95 % upper bound')
        else:
            # A degenerate bound (0 or inf): the record cannot constrain the term at all.
            optimised[name] = Param(math.nan, (math.nan, math.nan), 'not_identified',
                                    _unit(s.term.units[0], unit), 'fitted',
                                    'the record cannot constrain it')
            notes.append(f'{name}: the record cannot constrain it (too short); no bound')
        for sym, template in zip(s.term.symbols[1:], s.term.units[1:]):
            optimised[symbols[(s.label, sym)]] = Param(
                math.nan, (math.nan, math.nan), 'not_identified', _unit(template, unit),
                'fitted', f'{name} not supported')
    for sym, base in CORE_PARAMS.items():
        if sym not in optimised:
            units = dict(zip(TERMS[base].symbols, TERMS[base].units))
            optimised[sym] = Param(math.nan, (math.nan, math.nan), 'not_identified',
                                   _unit(units.get(sym, 'u'), unit))
            if base not in [base_name(x) for x in candidates]:
                notes.append(f'{sym}: not modelled (term {base} not among the candidates)')


def _upper_bound(fitter: Fitter, slots: list, sol: Solution, extra: Slot) -> float:
    """
    One-sided 95 % upper bound of an unsupported term's level (its first symbol).

    The selected model plus the term is fitted by unconstrained GLS at the selected
    model's weights, so the term's coefficient is a fixed linear combination
    c_hat = g^T avar of the Allan estimates.  The bound is the coefficient c0 at which
    P(c_hat <= observed | c0) = 5 %, with the covariance evaluated *under* c0 (a bound
    computed with the covariance of a model without the term would be far too tight):
    c_hat = c0 X + e, X ~ chi2_nu / nu for the term's own part (nu = 2 c0^2 / its
    variance, Satterthwaite) and e Gaussian with the rest of the variance.  A term with
    a nonlinear parameter (Gauss-Markov T) takes the largest bound over a grid of it
    within the observed tau range.
    """
    tau = fitter.data.tau
    grid: list = [()]
    if extra.bounds:
        lo, hi = extra.bounds[0]
        if extra.term.name in ('gauss_markov', 'bias_instability'):
            lo, hi = tau.min() / GM_PEAK_TAU, tau.max() / GM_PEAK_TAU
        grid = [(float(g),) for g in np.geomspace(lo, hi, 6)]
    base = _design(slots, tau, sol.phi)
    best = 0.0
    for nl in grid:
        a = np.column_stack([base, extra.term.shape(tau, *nl)])
        aw = fitter.data.whiten(a)
        g = np.linalg.pinv(aw)[-1] @ fitter.data.inv      # c_hat = g @ y (scaled units)
        c_obs = float(g @ fitter.data.y)
        terms = [s.term for s in slots] + [extra.term]
        blocks, active = fitter.cov.blocks(terms, list(sol.phi) + [nl])
        quad = np.einsum('i,abij,j->ab', g, blocks, g)
        coef = np.append(sol.coef, 0.0)[active]
        x = len(terms) - 1
        v0 = float(coef @ quad @ coef)
        if x in active:
            ix = active.index(x)
            v1 = float(coef @ quad[:, ix])
            v2 = float(quad[ix, ix])
        else:
            v1 = v2 = 0.0
        c_ub = _one_sided_bound(c_obs, v0, v1, v2)
        if not math.isfinite(c_ub):
            return math.inf
        value = extra.term.to_params(c_ub * fitter.data.scale, *nl)[extra.term.symbols[0]]
        best = max(best, value)
    return float(best)


def _one_sided_bound(c_obs: float, v0: float, v1: float, v2: float) -> float:
    """Smallest c0 with P(c0 X + e <= c_obs) <= 5 % (see :func:`_upper_bound`)."""
    v0 = max(v0, 0.0)
    if v2 <= 0.0:
        return max(c_obs, 0.0) + Z95_ONE_SIDED * math.sqrt(v0)
    nu = 2.0 / v2
    u = (np.arange(256) + 0.5) / 256.0
    x = chi2_ppf(u, nu) / nu

    def prob(c0: float) -> float:
        s_e = math.sqrt(max(v0 + 2.0 * c0 * v1, 1e-300))
        return float(np.mean(ndtr((c_obs - c0 * x) / s_e)))

    scale = max(abs(c_obs), math.sqrt(v0), 1e-300)
    lo, hi = 0.0, scale
    if prob(lo) <= 0.05:
        return 0.0
    while prob(hi) > 0.05:
        lo, hi = hi, hi * 4.0
        if hi > 1e8 * scale:
            return math.inf
    return float(brentq(lambda c: prob(c) - 0.05, lo, hi, xtol=1e-6 * hi))


def bound_by_curve(optimised: dict, caps: CurveCaps, notes: list) -> dict:
    """
    Turn estimates that may be 0 into bounds, and cap the bounds at the curve's own.

    - An estimate of N, B or K whose 95 % interval reaches 0 does not show its term: it
      is reported as the upper bound at the interval's upper end (B's T_B is then not
      identified).
    - No bound exceeds what the whole curve allows
      (:func:`imu_allan.core.fit.caps.cap_bounds`).

    Parameters
    ----------
    optimised : dict of str to Param
        The reported parameters, by symbol.
    caps : CurveCaps
        What the curve allows (:func:`imu_allan.core.fit.caps.curve_caps`).
    notes : list of str
        Appended with one line per change.

    Returns
    -------
    dict of str to Param
        ``optimised`` with the changed parameters (a new dict).

    """
    out = dict(optimised)
    for sym in ('N', 'B', 'K'):
        p = out.get(sym)
        if p is None or p.kind != 'estimate' or not p.ci95[0] <= 0.0:
            continue
        hi = float(p.ci95[1])
        if math.isfinite(hi) and hi > 0:
            out[sym] = Param(hi, (0.0, hi), 'upper_bound', p.unit, p.source,
                             'its 95 % interval reaches 0: upper bound')
        else:
            out[sym] = Param(math.nan, (math.nan, math.nan), 'not_identified', p.unit,
                             p.source, 'its 95 % interval reaches 0')
        notes.append(f'{sym}: its 95 % interval reaches 0 (the record does not show the '
                     'term); only an upper bound')
        if sym == 'B' and out.get('T_B') is not None and out['T_B'].kind != 'not_identified':
            out['T_B'] = Param(math.nan, (math.nan, math.nan), 'not_identified',
                               out['T_B'].unit, 'fitted', 'B is only an upper bound')
    return cap_bounds(out, caps, notes)
