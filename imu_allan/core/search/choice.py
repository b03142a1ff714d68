"""
Intervals that include the choice of model: rival minima of the likelihood.

The profile interval of a parameter (:mod:`imu_allan.core.fit.intervals`) is searched
outwards from the estimate and stops at the first crossing of its threshold.  A
correlation time can have a second minimum that fits about as well (the ADIS16405
accelerometers: T_B 0.07 s in one run, 27 s in another, each with a tight interval).
The 95 % confidence set is every value whose profile stays within the threshold, so
the bias-instability time is profiled on a grid over its whole range; every grid
model within the threshold of the best is a rival.  Then:

- B, K and N get intervals that also span their values under the rivals;
- T_B, when its confidence set falls apart into pieces (a rival beyond a gap where the
  profile rises above the threshold), is not identified: its value flips between
  rival models;
- the rivals (their T_B, the rise of the chi-square and their B, K, N) go to the JSON.

With several Gauss-Markov processes in one model the label "bias instability" goes to
the one with the largest B; where the data do not order their levels,
:func:`ambiguous_bias` reports T_B as not identified (see there).  Where a slower
Gauss-Markov process can stand in for the random walk, K is only an upper bound
(:func:`random_walk_or_slow_process`).
"""

from dataclasses import replace
import math

import numpy as np

from imu_allan.core.fit.axis import n_params, profile_threshold
from imu_allan.core.fit.result import AxisFit, Param
from imu_allan.core.fit.solver import fit_fixed_weights, Fix
from imu_allan.core.noise.shapes import GM_PEAK_TAU
from imu_allan.core.rules import GRID_POINTS, PIN_MARGIN, RIVAL_DELTA
from imu_allan.core.search.rivals import _neg2_loglik
from imu_allan.core.search.rules import _label_for, FinalModel, GridPoint, Rival

#: Parameters whose intervals are widened by the rivals, with the term each comes from.
_LEVELS = {'N': ('white', 'filtered_white'), 'B': ('bias_instability',),
           'K': ('random_walk',)}


def _levels(slots, sol, scale: float, i_b: int) -> dict:
    """N, B, T_B and K of one solution (0 where the term is absent or zero)."""
    out = {'N': 0.0, 'B': 0.0, 'K': 0.0, 'T_B': math.nan}
    for k, (s, c, phi) in enumerate(zip(slots, sol.coef, sol.phi)):
        params = s.term.to_params(float(c) * scale, *phi)
        for sym, bases in _LEVELS.items():
            if s.term.name in bases and s.label == s.term.name and sym != 'B':
                out[sym] = float(params[sym])
        if k == i_b:
            out['B'], out['T_B'] = float(params[s.term.symbols[0]]), float(phi[0])
    return out


def _largest_gm(slots, sol, scale: float) -> int | None:
    """Index of the Gauss-Markov slot with the largest B (reported as B, T_B), or None."""
    family = [k for k, s in enumerate(slots)
              if s.term.name in ('bias_instability', 'gauss_markov') and sol.coef[k] > 0]
    if not family:
        return None
    return max(family, key=lambda k: slots[k].term.to_params(
        float(sol.coef[k]) * scale, *sol.phi[k])[slots[k].term.symbols[0]])


def structural_rivals(model: FinalModel) -> list:
    """
    Re-fit the model with each step's runner-up effect in its place; return the rivals.

    A step whose runner-up bought a chi-square drop within :data:`RIVAL_DELTA` of its
    own is re-fitted with the runner-up instead (IRLS at its own weights), and kept as
    a rival when its -2 ln L + BIC (:func:`imu_allan.core.search.rivals._neg2_loglik`)
    is within :data:`RIVAL_DELTA` of the chosen model's.  Returns per rival a
    description, the difference of the criterion and N, B, T_B, K.
    """
    out = []
    scale = model.fitter.data.scale
    slots = model.slots_of(model.labels)
    model.fitter.data.set_sigma(model.sigma)
    mine = _neg2_loglik(model.fitter, model.sol, n_params(slots), model.penalty)
    for st in model.steps:
        other = st.runner_up
        if not other.effect or abs(st.chi2_drop - other.chi2_drop) > RIVAL_DELTA:
            continue
        rest = [lb for lb in model.labels if lb != st.label]
        label = _label_for(other.effect, rest)
        if label is None:
            continue
        labels = rest + [label]
        r_slots = model.slots_of(labels)
        phi0 = [p for lb, p in zip(model.labels, model.sol.phi) if lb != st.label] + [
            tuple(math.sqrt(lo * hi) for lo, hi in r_slots[-1].bounds)]
        sol, _ = model.fitter.irls(r_slots, phi0=phi0)
        value = _neg2_loglik(model.fitter, sol, n_params(r_slots), model.penalty)
        model.fitter.data.set_sigma(model.sigma)
        if value - mine <= RIVAL_DELTA:
            i_b = _largest_gm(r_slots, sol, scale)
            levels = _levels(r_slots, sol, scale, -1 if i_b is None else i_b)
            out.append(Rival(f'{other.effect} instead of {st.effect}', float(value - mine),
                             levels))
    return out


def _bias_slot(slots, sol, t_b: float) -> int | None:
    """Index of the Gauss-Markov slot whose time is the reported T_B (None without)."""
    family = [k for k, s in enumerate(slots)
              if s.term.name in ('bias_instability', 'gauss_markov')]
    if not family:
        return None
    return min(family, key=lambda k: abs(math.log(sol.phi[k][0] / t_b)))


def rival_models(fitter, slots, sol, dof: int, i: int) -> list:
    """
    Profile T_B over its whole range; return the grid models within the threshold.

    Parameters
    ----------
    fitter : imu_allan.core.fit.solver.Fitter
        The search's fitter at the final model's weights.
    slots : list of Slot
        The final model's slots.
    sol : Solution
        Its solution.
    dof : int
        Its degrees of freedom.
    i : int
        Index of the slot whose time is T_B.

    Returns
    -------
    list of GridPoint
        Per grid point: the rise of the chi-square over the best, whether it lies
        within the 95 % threshold, and N, B, T_B, K there.

    """
    lo, hi = slots[i].bounds[0]
    threshold = profile_threshold(sol.j, dof)
    out = []
    best = sol.j
    for t_b in np.geomspace(lo * 1.05, hi / 1.05, GRID_POINTS):
        symbol = slots[i].term.nonlinear[0]
        grid = fit_fixed_weights(fitter.data, slots, sol.phi, Fix(i, symbol, float(t_b)),
                                 local=True)
        best = min(best, grid.j)
        out.append((grid.j, _levels(slots, grid, fitter.data.scale, i)))
    return [GridPoint(j - best, j - best <= threshold, lv) for j, lv in out]


def with_rivals(fit: AxisFit, model: FinalModel) -> AxisFit:
    """
    Widen the intervals of ``fit`` by its rival models (see the module doc).

    Rivals are the grid models of T_B within the threshold beyond the fit's own T_B
    interval, and the rival structures of :func:`structural_rivals`.  N, B and K
    intervals span their values under every rival; T_B is not identified when its
    confidence set falls apart, or when a rival structure puts it outside its interval.
    """
    slots, sol = model.slots_of(model.labels), model.sol
    model.fitter.data.set_sigma(model.sigma)
    t_b = fit.optimised.get('T_B')
    rivals, flips = [], []
    if t_b is not None and t_b.kind == 'estimate':
        i = _bias_slot(slots, sol, t_b.value)
        if i is not None:
            dof = model.fitter.data.tau.size - n_params(slots)
            grid = rival_models(model.fitter, slots, sol, dof, i)
            own = np.array([t_b.ci95[0] <= g.levels['T_B'] <= t_b.ci95[1] for g in grid])
            inside = np.array([g.inside for g in grid]) | own
            pieces = int(np.sum(np.diff(inside.astype(int)) == 1)) + int(inside[0])
            for g, o in zip(grid, own):
                if g.inside and not o and g.levels['B'] > 0:
                    rivals.append(Rival(f'T_B {g.levels["T_B"]:.3g} s', float(g.rise),
                                        g.levels))
                    if pieces > 1:
                        flips.append(rivals[-1].model)
    for r in structural_rivals(model):
        rivals.append(r)
        if (t_b is not None and t_b.kind == 'estimate' and math.isfinite(r.levels['T_B'])
                and not t_b.ci95[0] <= r.levels['T_B'] <= t_b.ci95[1]):
            flips.append(r.model)
    if not rivals:
        return fit
    optimised = dict(fit.optimised)
    notes = list(fit.notes)
    for sym in ('N', 'B', 'K'):
        p = optimised.get(sym)
        if p is None or p.kind != 'estimate':
            continue
        values = [r.levels[sym] for r in rivals]
        lo, hi = min([p.ci95[0]] + values), max([p.ci95[1]] + values)
        if (lo, hi) != p.ci95:
            optimised[sym] = p._replace(ci95=(float(lo), float(hi)),
                                        reason='interval widened to span models that fit as well')
    if flips and t_b is not None:
        optimised['T_B'] = Param(math.nan, (math.nan, math.nan), 'not_identified', t_b.unit,
                                 'fitted', 'other models that fit as well give it other values')
        notes.append(f'T_B: differs between models that fit about as well ('
                     f'{t_b.value:.3g} s; {", ".join(flips)}): not identified')
    elif t_b is not None and t_b.kind == 'estimate':
        ts = [r.levels['T_B'] for r in rivals if math.isfinite(r.levels['T_B'])]
        optimised['T_B'] = t_b._replace(ci95=(float(min([t_b.ci95[0]] + ts)),
                                              float(max([t_b.ci95[1]] + ts))))
    notes.append('intervals of N, B, K span the models that fit about as well: '
                 + ', '.join(r.model for r in rivals))
    listed = tuple({'model': r.model, 'criterion_rise': r.criterion_rise, **r.levels}
                   for r in rivals)
    return replace(fit, optimised=optimised, notes=tuple(notes), rivals=listed)


def ambiguous_bias(fit: AxisFit) -> AxisFit:
    """
    Report T_B as not identified where the data do not say which process is B's.

    With several Gauss-Markov processes the label bias instability (B, T_B) goes to
    the one with the largest B (:func:`imu_allan.core.fit.axis._dominant_bias_instability`).
    When the 95 % interval of another process's B reaches the labelled one's, the
    data do not exclude that the other is the larger: the label, and with it T_B,
    could go to either (the ADIS16405 accelerometers: T_B 0.07 s in one run, 27 s in
    another, both "estimates").  Without the joint covariance of the two levels,
    overlapping intervals are the test of their difference at the least favourable
    correlation, -1 (the two processes trade level on the curve, so their estimates
    anti-correlate; half-widths then add).  Then
    T_B is not identified, B keeps the largest level with an interval that spans the
    candidates' intervals (B is the level of whichever is the bias instability), and
    each candidate goes to the rivals with its B and T (criterion rise 0: the same
    model, labelled otherwise).  Processes whose levels are ordered keep the label.
    """
    opt = fit.optimised
    b, t_b = opt.get('B'), opt.get('T_B')
    if b is None or t_b is None or b.kind != 'estimate' or 'bias_instability' not in fit.terms:
        return fit
    tied = []
    for label in fit.terms:
        other, time = opt.get(f'{label}.B'), opt.get(f'{label}.T')
        if (not label.startswith('gauss_markov') or other is None or time is None
                or other.kind != 'estimate'):
            continue
        if other.ci95[1] >= b.ci95[0]:
            tied.append((label, other, time))
    if not tied:
        return fit
    lo = min([b.ci95[0]] + [o.ci95[0] for _, o, _ in tied])
    hi = max([b.ci95[1]] + [o.ci95[1] for _, o, _ in tied])
    optimised = dict(opt)
    optimised['B'] = b._replace(ci95=(float(lo), float(hi)),
                                reason='two processes of about this level: interval spans both')
    optimised['T_B'] = Param(math.nan, (math.nan, math.nan), 'not_identified', t_b.unit,
                             'fitted', 'which process is the bias instability is not clear')
    levels = {sym: opt[sym].value if opt[sym].kind == 'estimate' else math.nan
              for sym in ('N', 'K')}
    listed = tuple({'model': f'bias instability = {label} (T {time.value:.3g} s)',
                    'criterion_rise': 0.0, 'N': levels['N'], 'B': other.value,
                    'T_B': time.value, 'K': levels['K']} for label, other, time in tied)
    names = ', '.join(f'{label} (B {o.value:.3g}, T {t.value:.3g} s)' for label, o, t in tied)
    own = f', T_B {t_b.value:.3g} s' if math.isfinite(t_b.value) else ''
    note = (f'B, T_B: the bias instability (B {b.value:.3g}{own}) and {names} have levels '
            'the data do not order: T_B not identified, the B interval spans them')
    return replace(fit, optimised=optimised, notes=fit.notes + (note,),
                   rivals=fit.rivals + listed)


def _final_solution(model: FinalModel) -> tuple:
    """Return the search's final slots and solution at its final weights."""
    model.fitter.data.set_sigma(model.sigma)
    slots = model.slots_of(model.labels)
    sol = model.sol
    if len(sol.phi) != len(slots):
        # final() dropped steps after the last IRLS: fit the kept labels at these weights.
        sol = fit_fixed_weights(model.fitter.data, slots,
                                [model.phi_of[lb] for lb in model.labels], local=True)
    return slots, sol


#: The rivals' name of the model of :func:`random_walk_or_slow_process`.
SLOWER_PROCESS_RIVAL = 'a slower gauss_markov instead of random_walk'


def random_walk_or_slow_process(fit: AxisFit, model: FinalModel) -> AxisFit:
    """
    Report K as an upper bound where a slower Gauss-Markov process does as well.

    Below its correlation time a Gauss-Markov process rises on the Allan curve as a
    random walk does (AVAR ~ tau), so within a record a slow process can stand in for
    the random walk: a K estimate then says only that the curve rises, not that it
    keeps rising.  The final model with the random walk replaced by one more
    Gauss-Markov process (grid-searched) is fitted at the final model's weights.  It
    is a different model only if every process of it turns over within the fitted
    taus (ADEV peak at 1.89 T, paper eq. 8, below the longest tau): a process peaking
    beyond is the random walk under another name, and K keeps its estimate (a clean
    white + Gauss-Markov + random-walk record).  A time at an end of its range is no
    rival either (the fit's own rule: not identified, the curve reshaped).  When its
    chi-square is within the profile threshold of the final model's minimum
    (:func:`imu_allan.core.fit.axis.profile_threshold`, the same rise that bounds every
    95 % interval), K = 0 is in the confidence set of that wider family: K is
    reported as an upper bound at its interval's upper end, and the
    alternative model goes to the rivals (the ADIS16405 gyros: K from 6e-6 to 2.2e-5
    over six runs, the replaced models fitting as well on every axis).  B's interval
    spans the alternative's B; T_B is not identified when the alternative gives the
    label to a process whose time lies outside T_B's interval.
    """
    k, b, t_b = (fit.optimised.get(sym) for sym in ('K', 'B', 'T_B'))
    if (k is None or k.kind != 'estimate' or 'random_walk' not in model.labels
            or 'gauss_markov' not in model.effects):
        return fit
    label = _label_for('gauss_markov', model.labels)
    if label is None:
        return fit
    slots, sol = _final_solution(model)
    kept = [i for i, lb in enumerate(model.labels) if lb != 'random_walk']
    alt = [slots[i] for i in kept] + model.slots_of([label])
    if n_params(alt) >= model.k:
        return fit
    phi0 = [sol.phi[i] for i in kept] + [tuple(math.sqrt(lo * hi) for lo, hi in alt[-1].bounds)]
    # Only the new process is gridded; the others start where they are (the polish
    # moves them).
    new = fit_fixed_weights(model.fitter.data, alt, phi0, grid_slots=[len(alt) - 1])
    family = [i for i, s in enumerate(alt) if s.term.name in ('bias_instability', 'gauss_markov')]
    rise = float(new.j - sol.j)
    slowest = max(new.phi[i][0] for i in family)
    pinned = any(not alt[i].bounds[0][0] * PIN_MARGIN < new.phi[i][0]
                 < alt[i].bounds[0][1] / PIN_MARGIN
                 for i in family)
    if (np.any(new.coef[family] <= 0) or pinned or GM_PEAK_TAU * slowest > model.tau.max()
            or rise > profile_threshold(sol.j, model.k - n_params(slots))):
        return fit
    i_b = _largest_gm(alt, new, model.fitter.data.scale)
    levels = _levels(alt, new, model.fitter.data.scale, -1 if i_b is None else i_b)
    optimised = dict(fit.optimised)
    optimised['K'] = Param(k.ci95[1], (0.0, k.ci95[1]), 'upper_bound', k.unit, 'fitted',
                           'a slower Gauss-Markov process fits as well: 95 % upper bound')
    notes = [f'K: a slower Gauss-Markov process (T {slowest:.3g} s) instead of the '
             f'random walk fits as well (chi-square {rise:+.1f}): 95 % upper bound']
    if b is not None and b.kind == 'estimate':
        optimised['B'] = b._replace(ci95=(min(b.ci95[0], levels['B']),
                                          max(b.ci95[1], levels['B'])))
    if t_b is not None and t_b.kind in ('estimate', 'lower_bound') and not (
            t_b.ci95[0] <= levels['T_B'] <= t_b.ci95[1]):
        optimised['T_B'] = Param(math.nan, (math.nan, math.nan), 'not_identified', t_b.unit,
                                 'fitted', 'a slower process instead of the random walk '
                                 'gives another value')
        notes.append(f'T_B: {t_b.value:.3g} s with the random walk, {levels["T_B"]:.3g} s '
                     'with the slower process instead: not identified')
    listed = ({'model': SLOWER_PROCESS_RIVAL,
               'criterion_rise': rise, **levels},)
    return replace(fit, optimised=optimised, notes=fit.notes + tuple(notes),
                   rivals=fit.rivals + listed)
