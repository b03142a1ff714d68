"""
Precision now, and when: the record length at which each parameter meets its target.

For each axis the fitted model is carried to records of growing length (a grid of
four-fold steps from the present length to :data:`HORIZON_S`, plus 1, 3 and 10 h), the
expected relative 95 % half-width of every parameter is computed there
(:class:`imu_allan.core.plan.precision.CurveModel`) and the length at which it falls
to its target is interpolated in log-log (the widths fall about as L^-1/2 once a term
is resolved).  The widths are read against the fit: inflated by its dispersion, from
its present interval on (:mod:`imu_allan.core.plan.reading`).  A parameter the fit
reports as an upper bound is planned at its bound: a smaller true value takes longer,
so the time is "at least".  The grid is shared by the six axes, whose curves share
their taus and so the quadrature of Sigma.
"""

import math
from typing import Collection, Mapping, Sequence

import numpy as np

from imu_allan.core.fit.covariance import CurveCovariance
from imu_allan.core.noise.terms import TERMS
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.plan.precision import (_avar, _jacobian, Component, CurveModel,
                                           expected_widths, fit_taus)
from imu_allan.core.plan.reading import as_read, crossing, inflation, present_width
from imu_allan.core.plan.result import AxisPlan, ParamPlan, Separation
from imu_allan.core.plan.separation import (LAMBDA_SEPARATED, mismatch, ORDERING, ordering,
                                            rivals, scaled, SLOW_PROCESS)
from imu_allan.core.plan.targets import DEFAULT_PROFILE, PROFILES
from imu_allan.core.search.choice import SLOWER_PROCESS_RIVAL

#: Default targets: relative 95 % half-widths (+-10 % for N and B, +-25 % otherwise),
#: those of the 'full' profile.
DEFAULT_TARGETS = {k: v for k, v in PROFILES[DEFAULT_PROFILE].items() if k != '*'}
#: Target of every other parameter (the extra terms), unless the targets give '*'.
DEFAULT_OTHER_TARGET = PROFILES[DEFAULT_PROFILE]['*']
#: Longest record the planner looks at [s] (1000 h).
HORIZON_S = 3.6e6
#: Record lengths at which the expected widths are always reported [h].
REPORT_HOURS = (1.0, 3.0, 10.0)
#: Symbols of the core terms and their term (for the bounds of unsupported terms).
_CORE = {'N': 'white', 'B': 'bias_instability', 'K': 'random_walk'}
#: The core parameters in the order a plan lists them (the extra terms follow).
_CORE_ORDER = ('N', 'B', 'T_B', 'K')


def target_of(name: str, targets: Mapping[str, float] | None) -> float:
    """Target relative half-width of one parameter (``targets`` override the defaults)."""
    merged = dict(DEFAULT_TARGETS, **(targets or {}))
    other = merged.get('*', DEFAULT_OTHER_TARGET)
    return float(merged.get(name, merged.get(name.split('.')[-1], other)))


def planning_model(components: Sequence, optimised: Mapping | None = None) -> tuple:
    """
    Components to plan with, and the models of the parameters planned at an upper bound.

    Parameters
    ----------
    components : sequence of (label, coef, phi)
        The fitted model (``AxisFit.components``).
    optimised : mapping of str to Param, optional
        The fit's reported parameters; a core parameter reported as an upper bound is
        planned at that bound (its term added or raised to it) in a model of its own,
        so that the bound does not blur the other parameters' plans.

    Returns
    -------
    comps : list of Component
        The point estimates (terms with a positive coefficient).
    bounds : dict of str to list of Component
        Per parameter planned at a bound, the model with that term at its bound.

    """
    comps = [Component(str(lb), float(c), tuple(float(v) for v in p))
             for lb, c, p in components if c > 0]
    bounds: dict = {}
    for sym, base in _CORE.items():
        p = (optimised or {}).get(sym)
        if p is None or p.kind != 'upper_bound' or not p.value > 0:
            continue
        labels = [c.label for c in comps]
        raised = list(comps)
        if base == 'bias_instability':
            if base not in labels:
                continue        # no T_B to plan B with
            i = labels.index(base)
            coef = TERMS[base].to_coef(p.value, *comps[i].phi)
            raised[i] = Component(base, max(coef, comps[i].coef), comps[i].phi)
            bounds['B'] = bounds['T_B'] = raised
            continue
        coef = TERMS[base].to_coef(p.value)
        if base in labels:
            i = labels.index(base)
            raised[i] = Component(base, max(coef, comps[i].coef), ())
        else:
            raised.append(Component(base, coef, ()))
        bounds[sym] = raised
    return comps, bounds


def length_grid(duration_s: float) -> np.ndarray:
    """
    Record lengths to evaluate [s]: now, then 1, 3, 10, 30 ... 1000 h.

    Without a record (``duration_s`` 0) the grid starts at 1, 5 and 15 min.  The widths
    fall about as L^-1/2 between the points once a term is resolved, so a log-log
    interpolation over these steps is close; :func:`plan_axes` stops early once every
    target is met beyond 10 h.
    """
    long_h = (1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)
    first = [duration_s] if duration_s > 0 else [60.0, 300.0, 900.0]
    later = [h * 3600.0 for h in long_h if h * 3600.0 > first[-1] * 1.05]
    return np.array(first + later)


def plan_axes(models: Mapping[str, tuple], rate_hz: float, duration_s: float,
              targets: Mapping[str, float] | None = None,
              present: Mapping[str, Mapping] | None = None,
              lengths_s: Sequence[float] | None = None,
              slow_process: Collection[str] = (),
              inflations: Mapping[str, float] | None = None) -> dict:
    """
    Plan every axis: width now, time to target, widths at 1, 3 and 10 h, separations.

    Parameters
    ----------
    models : mapping of str to (list of Component, dict)
        Per axis, :func:`planning_model`'s output.
    rate_hz : float
        Sample rate [Hz].
    duration_s : float
        Length of the record behind the models [s] (0 or less: a datasheet, no record).
    targets : mapping of str to float, optional
        Target relative 95 % half-widths by parameter name (or symbol).
    present : mapping of str to mapping, optional
        Per axis, the fit's reported parameters (Param): their intervals give the
        present widths; without them the model's expected widths at ``duration_s``.
    lengths_s : sequence of float, optional
        Record lengths to evaluate instead of :func:`length_grid`.
    slow_process : collection of str
        Axes whose fit found a slower Gauss-Markov process standing in for the random
        walk (:func:`imu_allan.core.search.choice.random_walk_or_slow_process`): their
        plans say how long until a record tells the two apart.
    inflations : mapping of str to float, optional
        Per axis, the factor on the expected widths' z for the fit's dispersion
        (:func:`~imu_allan.core.plan.reading.inflation`; 1 when absent).

    Returns
    -------
    dict of str to AxisPlan

    """
    start = duration_s if duration_s > 0 else 60.0
    grid = np.asarray(lengths_s if lengths_s is not None else length_grid(start), float)
    # Per axis the point-estimate model and one model per parameter planned at a bound.
    cms: dict = {}
    for axis, (comps, bounds) in models.items():
        variants = {'': comps}
        variants.update({name: b for name, b in bounds.items() if b})
        cms[axis] = {k: CurveModel(v, rate_hz) for k, v in variants.items() if v}
    widths: dict = {(a, k): [] for a, v in cms.items() for k in v}
    # An axis whose T_B is not identified yet is followed over the whole grid.  The
    # slower process the fit found instead of a random walk turns over inside the
    # present record (its longest tau).
    slow_peak_s = float(fit_taus(rate_hz, max(int(round(start * rate_hz)), 8))[1].max())
    open_t_b = {a for a in cms if getattr((present or {}).get(a, {}).get('T_B'), 'kind', '')
                == 'not_identified'}
    lams: dict = {a: [] for a in cms}
    # Each axis stops once its targets are met beyond 10 h (per axis, so that a plan
    # does not depend on which other axes are planned with it).
    done: dict = {}
    for i, length in enumerate(grid):
        for axis in cms:
            if (axis not in done and axis not in open_t_b
                    and length > max(REPORT_HOURS) * 3600.0 and _all_met(
                        {k[1]: v for k, v in widths.items() if k[0] == axis}, lams[axis],
                        targets, grid[:i], (inflations or {}).get(axis, 1.0), duration_s,
                        (present or {}).get(axis, {}))):
                done[axis] = i
        if len(done) == len(cms):
            break
        n = max(int(round(length * rate_hz)), 8)
        m, tau = fit_taus(rate_hz, n)
        cov = CurveCovariance(m, np.maximum(n + 1 - 2 * m, 1), 1.0 / rate_hz, n)
        for axis, variants in cms.items():
            if axis in done:
                continue
            for key, cm in variants.items():
                avar = _avar(cm.comps, cm.theta, tau)
                scale = float(np.max(avar))
                sigma = cov.sigma([c.term for c in cm.comps],
                                  np.array([c.coef / scale for c in cm.comps]),
                                  [c.phi for c in cm.comps])
                jac = _jacobian(cm.comps, cm.theta, tau) / scale
                widths[(axis, key)].append(dict(zip(cm.names, expected_widths(jac, sigma))))
                if key == '':
                    peak = slow_peak_s if axis in slow_process else None
                    lams[axis].append({q: mismatch(avar / scale, sigma, scaled(r, scale), tau,
                                                   peak if q == SLOW_PROCESS else None)
                                       for q, r in rivals(cm.comps, float(tau.max()), peak)})
    out = {}
    for axis, variants in cms.items():
        columns, values = {}, {}
        for key, cm in variants.items():
            for j, name in enumerate(cm.names):
                if (key == '' and name not in variants) or key == name:
                    columns[name] = np.array([row[name] for row in widths[(axis, key)]])
                    values[name] = [v for c in cm.comps for v in c.values()][j]
        n_done = len(next(iter(widths[(axis, k)] for k in variants)))
        out[axis] = _axis_plan(columns, values, set(variants) - {''}, grid[:n_done],
                               lams[axis], duration_s, targets, (present or {}).get(axis),
                               (inflations or {}).get(axis, 1.0))
    return out


def _all_met(widths: dict, lams: list, targets, lengths_s: np.ndarray, factor: float,
             duration_s: float, present: Mapping) -> bool:
    """
    Whether at the last length evaluated every target is met, every rival rejected.

    ``widths`` maps each variant ('' the point model) to its rows at ``lengths_s``; the
    point model's widths are read as the plan reads them
    (:func:`~imu_allan.core.plan.reading.as_read`).
    """
    for key, rows in widths.items():
        if not rows:
            return False
        for name in rows[-1]:
            col = np.array([row[name] for row in rows])
            if key == '':
                col = as_read(col, lengths_s, factor, duration_s,
                              present_width(present.get(name)))
            if col[-1] > target_of(name, targets):
                return False
    return all(v >= LAMBDA_SEPARATED for v in (lams[-1].values() if lams else ()))


def _axis_plan(columns: dict, values: dict, bounded: set, grid: np.ndarray, lams: list,
               duration_s: float, targets, present, factor: float) -> AxisPlan:
    """One axis' plan from the expected widths of its parameters on the length grid."""
    order_lam = ordering(columns, values, present)
    if order_lam is not None:
        lams = [{**row, ORDERING: lam} for row, lam in zip(lams, order_lam)]
    seps = []
    for q in sorted({q for row in lams for q in row}):
        lam = np.array([row.get(q, 0.0) for row in lams])
        when = crossing(grid, 1.0 / np.maximum(lam, 1e-300), 1.0 / LAMBDA_SEPARATED)
        lam_now = (float(np.interp(math.log(duration_s), np.log(grid), lam))
                   if duration_s > 0 else math.nan)
        # The fit has the last word on the present record: it found the levels tied.
        separated = bool(duration_s > 0 and lam_now >= LAMBDA_SEPARATED and q != ORDERING)
        seps.append(Separation(q, lam_now, float(when), separated))
    # A parameter the fit could not pin down for want of a separation waits for it.
    open_times = {s.question: s.time_s for s in seps if not s.separated}
    waits = {name: [open_times[q] for q in qs if q in open_times]
             for name, qs in _WAITS.items()}
    params = []
    for name, col in columns.items():
        target = target_of(name, targets)
        p = (present or {}).get(name)
        now = present_width(p) if duration_s > 0 else math.nan
        if name not in bounded:
            col = as_read(col, grid, factor, duration_s, now)
        if duration_s > 0 and p is None:
            now = float(np.interp(math.log(duration_s), np.log(grid), col))
        if math.isinf(target):
            kind = 'met'             # no target: nothing to wait for
        elif name in bounded:
            kind = 'at_least'
        elif duration_s > 0 and now <= target:
            kind = 'met'
        else:
            kind = 'predicted'
        when = crossing(grid, col, target)
        if kind == 'met':
            when = duration_s
        elif kind == 'at_least' and duration_s > 0 and when <= duration_s:
            # At its bound the term would be resolved by now: it is smaller, by how
            # much the record cannot say yet.
            when = math.nan
        elif duration_s > 0:
            when = max(when, duration_s)
        if kind != 'met' and p is not None and p.kind != 'estimate' and waits.get(name):
            when = max(waits[name]) if math.isnan(when) else max(when, *waits[name])
        if math.isinf(when) and kind != 'at_least':
            kind = 'beyond'
        at = {h: float(col[int(np.argmin(np.abs(grid - h * 3600.0)))])
              for h in REPORT_HOURS if np.isclose(grid, h * 3600.0).any()}
        params.append(ParamPlan(name, float(values[name]), float(now), target, float(when), kind,
                                at))
    params.sort(key=_listed)
    return AxisPlan(float(duration_s), tuple(params), tuple(seps))


#: Parameters the fit leaves unidentified (or bounded) until a question is answered.
_WAITS = {'T_B': (ORDERING, SLOW_PROCESS), 'K': (SLOW_PROCESS,)}


def noise_components(noise: AxisNoise) -> list:
    """
    Return the (label, coef, phi) components of an axis model (datasheet, parameter file).

    Parameters
    ----------
    noise : AxisNoise
        The model, SI.

    Returns
    -------
    list of (str, float, tuple)
        As ``AxisFit.components``.

    """
    # Every registry term by its own read-out (Term.instances), so a term added to the
    # registry is planned too; labels as the fit numbers repeats (gauss_markov_2).
    out: list[tuple[str, float, tuple]] = []
    for name, term in TERMS.items():
        found = [v for v in term.instances(noise) if v[0]]
        for i, values in enumerate(found):
            phi = tuple(values[len(term.symbols) - len(term.nonlinear):])
            out.append((name if i == 0 else f'{name}_{i + 1}', term.to_coef(values[0], *phi),
                        phi))
    return out


def plan_fits(fits: Mapping, rate_hz: float, duration_s: float,
              targets: Mapping[str, float] | None = None) -> dict:
    """
    Plan the axes of an analysis: per axis with a fit, its :class:`AxisPlan`.

    Parameters
    ----------
    fits : mapping of str to AxisFit or None
        The fits per axis.
    rate_hz : float
        Sample rate [Hz].
    duration_s : float
        Length of the analysed record [s].
    targets : mapping of str to float, optional
        Target relative half-widths by parameter (defaults :data:`DEFAULT_TARGETS`).

    Returns
    -------
    dict of str to AxisPlan

    """
    models = {a: planning_model(f.components, f.optimised) for a, f in fits.items()
              if f is not None and f.components}
    present = {a: fits[a].optimised for a in models}
    slow = {a for a in models if any(r.get('model') == SLOWER_PROCESS_RIVAL
                                     for r in fits[a].rivals)}
    factors = {a: inflation(fits[a].chi2, fits[a].dof) for a in models}
    plans = plan_axes(models, rate_hz, duration_s, targets, present, slow_process=slow,
                      inflations=factors)
    out = {}
    for axis, plan in plans.items():
        params = plan.params + _unplanned(plan, fits[axis].optimised, targets)
        out[axis] = plan._replace(params=tuple(sorted(params, key=_listed)),
                                  caveat=plan_caveat(fits[axis]))
    return out


def _listed(p: ParamPlan) -> tuple:
    """Sort key of a plan's parameters: N, B, T_B, K, then the extra terms by name."""
    core = _CORE_ORDER.index(p.name) if p.name in _CORE_ORDER else len(_CORE_ORDER)
    return core, p.name


def _unplanned(plan: AxisPlan, optimised: Mapping, targets) -> tuple:
    """
    Return the core parameters the fit reports but its model cannot plan, still to come.

    A B only bounded by a curve without a bias-instability term, its T_B, or a K the
    record cannot constrain have no term to extrapolate; left out, the plan would read
    "every target met" while they are unknown.  A bound is 'at_least' with no time (its
    time is unknown), the rest 'open'.
    """
    out = []
    for name in _CORE_ORDER:
        q = optimised.get(name)
        if q is None or plan.param(name) is not None or q.kind == 'estimate':
            continue
        kind = 'at_least' if q.kind == 'upper_bound' else 'open'
        target = target_of(name, targets)
        if math.isinf(target):          # no target: nothing to wait for
            kind = 'met'
        out.append(ParamPlan(name, float(q.value), math.inf, target,
                             plan.duration_s if kind == 'met' else math.nan, kind, {}))
    return tuple(out)


def plan_caveat(fit) -> str:
    """
    Say why a fit's plan may promise too short a record ('' when its model holds).

    The planner extrapolates the fitted model: where that model does not explain its
    own curve (an effect it lacks) or the fit is not trusted (conservative values
    replaced it), a longer record will likely need more terms, whose parameters widen
    the intervals, and the predicted times are then lower limits at best.

    Parameters
    ----------
    fit : AxisFit
        The fit the plan came from.

    Returns
    -------
    str
        The caveat, or ''.

    """
    if fit.trust:
        return 'the fit is not trusted (' + '; '.join(fit.trust) + '): the times assume ' \
            'its model, which does not hold'
    if fit.model_consistent is False:
        return (f'the model does not explain the curve (chi2 {fit.chi2:.0f} for {fit.dof} '
                'dof): the times assume it does, and a record that needs more terms takes '
                'longer')
    return ''
