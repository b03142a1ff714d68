"""
One search of one axis: its state and its phases.

The phases run in the order :func:`imu_allan.core.search.search_axis` calls them: base
model, ramp test, forward search, backward check, final fit (see the package doc).
"""

from dataclasses import replace
import math
from typing import Any

import numpy as np

from imu_allan.core.allan.quantiles import chi2_sf
from imu_allan.core.fit.axis import (check_curve, filter_cut, filter_identified, fit_axis,
                                     n_params, term_slot, thin)
from imu_allan.core.fit.caps import cap_fit
from imu_allan.core.fit.criterion import claim_penalty
from imu_allan.core.fit.judge import shows_quantization
from imu_allan.core.fit.result import AxisFit
from imu_allan.core.fit.solver import fit_fixed_weights, Fitter
from imu_allan.core.fit.trust import judge_fit
from imu_allan.core.noise.terms import base_name, TERMS
from imu_allan.core.rules import (CANNOT_TELL_LR, DELTA_MIN, KEEP_PENALTY, MAX_STEPS,
                                  P_CONSISTENT, PIN_MARGIN, RAMP_LR_MIN)
from imu_allan.core.search.choice import ambiguous_bias
from imu_allan.core.search.evidence import ramp_test
from imu_allan.core.search.rivals import _by_likelihood, _grid_slots, _second_chance
from imu_allan.core.search.rules import (_label_for, _sinusoid_evidence, Candidate, Choice,
                                         FinalModel, RunnerUp, Step)
from imu_allan.errors import InputError


def _short_sinusoid(slot, tau: np.ndarray):
    """
    Keep a sinusoid candidate to at least about 8 periods in the record.

    A line of a few periods is a trend to the curve (it stands in for a random walk or
    a ramp at the longest taus); the periodogram cannot confirm it either.
    """
    if slot.term.name != 'sinusoid':
        return slot
    (lo, hi), = slot.bounds
    return replace(slot, bounds=((max(lo, 2.0 / tau.max()), hi),))


def _noise_terms(slots, coef, phi, scale: float) -> list:
    return [(s.term.name, float(c) * scale, tuple(p)) for s, c, p in zip(slots, coef, phi)]


# Long because it is the search's state plus its phases, one short method each.
class _Run:
    """
    One search: the curve, its fitter and the model as it grows, phase by phase.

    The phases are methods, in the order :func:`search_axis` calls them: the base model
    (with or without the sensor's filter), the ramp test on the record, the forward
    search, the backward check and the final fit with intervals.  The class is longer
    than a function should be because it is the search's state plus those phases; each
    method is short.
    """

    def __init__(self, tau_s, avar, edf, rate_hz, n_samples, raw, raw_rate_hz, unit,
                 effects):
        self.curve = check_curve(tau_s, avar, edf, rate_hz, n_samples)
        tau0, avar0, edf0 = self.curve
        keep = thin(tau0)
        self.tau, self.y, e = tau0[keep], avar0[keep], edf0[keep]
        if self.tau.size < 3:
            raise InputError(f'the fit needs at least 3 averaging times, got {self.tau.size}')
        self.rate_hz, self.n_samples, self.unit = rate_hz, int(n_samples), unit
        self.effects = effects
        self.edf_thin = e
        # The one rule for the sensor's filter on every axis: the leading taus it bends
        # are left out (as fit_axis does for plain white noise) unless the filter is
        # modelled with an identifiable time constant (see :meth:`base`).
        self.cut = filter_cut(self.tau, self.y, rate_hz, e)
        self.use_taus(0)
        self.raw = None if raw is None else np.asarray(raw, dtype=np.float64)
        self.raw_rate = float(raw_rate_hz or rate_hz)
        # A sinusoid, once named, keeps its frequency within 20 % (the re-weighted fits
        # must not move it to another feature of the curve).
        self.narrowed: dict[str, tuple] = {}
        self.lines_hz: list[float] = []
        self.steps: list[Step] = []
        self.notes: list[str] = []
        self.problems: list[str] = []
        self.labels: list[str] = []
        self.base_labels: list[str] = []
        # The current model: set by every fit (:meth:`irls`), first by :meth:`base`.
        self.sol: Any = None
        self.sigma: Any = None
        self.base_fit: AxisFit       # the base model's full fit, set by :meth:`base`
        self.phi_of: dict = {}

    def use_taus(self, first: int) -> None:
        """Fit the thinned curve from its ``first`` tau on (a new fitter)."""
        tau, y, e = self.tau[first:], self.y[first:], self.edf_thin[first:]
        self.tau, self.y, self.edf_thin = tau, y, e
        m = np.maximum(np.round(tau * self.rate_hz), 1).astype(np.int64)
        n_terms = np.maximum(self.n_samples + 1 - 2 * m, 1)
        self.fitter = Fitter(tau, y, e, m, n_terms, 1.0 / float(self.rate_hz),
                             self.n_samples, 'overlapping')
        self.k = tau.size
        self.penalty = claim_penalty(self.k)

    def slots_of(self, labels):
        """Return the slots of the labels, with narrowed sinusoid frequencies."""
        return [replace(s, bounds=self.narrowed[s.label]) if s.label in self.narrowed else
                _short_sinusoid(s, self.tau)
                for s in (term_slot(lb, self.tau, self.rate_hz) for lb in labels)]

    def irls(self, labels, phi0=None, local=False) -> None:
        """Fit ``labels`` by IRLS and make it the current model."""
        # IRLS leaves the plug-in Sigma of its solution as the weights; the candidates
        # are scored at those weights, so the model's own J is taken there too.
        slots = self.slots_of(labels)
        sol, self.sigma = self.fitter.irls(slots, phi0=phi0, local=local)
        self.sol = fit_fixed_weights(self.fitter.data, slots, sol.phi, local=True)
        self.labels = list(labels)

    def rejected(self) -> bool:
        """Whether the chi-square rejects the current model."""
        dof = self.k - n_params(self.slots_of(self.labels))
        return dof > 0 and chi2_sf(self.sol.j, dof) < P_CONSISTENT

    def pinned(self) -> set:
        """
        Return the labels of the current model's terms with a time at an end of its range.

        A term the model holds at zero has no time to pin.
        """
        slots = self.slots_of(self.labels)
        return {slot.label for slot, c, phi in zip(slots, self.sol.coef, self.sol.phi)
                if c > 0 and any(v <= lo * PIN_MARGIN or v >= hi / PIN_MARGIN
                                 for (lo, hi), v in zip(slot.bounds, phi))}

    def base(self, base_labels) -> None:
        """
        Fit the paper's model, through the sensor's filter where the curve identifies it.

        One rule on every axis: the filter is modelled (``filtered_white``) only where
        it buys its margin on the whole curve, its time constant is identifiable
        (:func:`filter_identified`) and no other time of the model is pinned at an end
        of its range by it; otherwise the leading taus it bends are left out
        (:func:`imu_allan.core.fit.axis.filter_cut`) and white noise is fitted to
        the rest, as :func:`fit_axis` does.
        """
        self.irls(list(base_labels))
        labels = self.labels
        pinned_white = self.pinned()
        modelled = False
        if 'white' in labels and self.rejected() and (
                self.k - n_params(self.slots_of(labels)) > 2):
            alt = ['filtered_white' if lb == 'white' else lb for lb in labels]
            trial = fit_fixed_weights(self.fitter.data, self.slots_of(alt))
            i_f = alt.index('filtered_white')
            bounds = self.slots_of(alt)[i_f].bounds[0]
            # The trial is scored at the white model's weights; the filter time is
            # judged after the re-weighting (it moves there).
            if (self.sol.j - trial.j > self.penalty + DELTA_MIN and trial.coef[i_f] > 0
                    and trial.phi[i_f][0] > 1.05 * bounds[0]):
                self.irls(alt, phi0=trial.phi)
                i_f = self.labels.index('filtered_white')
                # A time pinned with white noise alone (a slow process the record
                # cannot resolve) is not the filter's doing.
                modelled = (filter_identified(self.sol.phi[i_f][0], self.tau[0], bounds)
                            and self.pinned() <= pinned_white)
                if not modelled:
                    self.notes.append(
                        f'filtered_white: T_f {self.sol.phi[i_f][0]:.3g} s is not '
                        f'identified by taus from {self.tau[0]:.3g} s (left out)')
        if not modelled and (self.cut.first or 'filtered_white' in self.labels):
            if self.cut.first:
                self.use_taus(self.cut.first)
                if not self.cut.ended:
                    # The cut stopped at its limit with the curve still flatter than
                    # white noise: filter and floor cannot be told apart.
                    self.problems.append(f"the sensor's filter bends the curve beyond "
                                         f'{self.tau[0]:.3g} s')
            self.irls(list(base_labels))
        self.base_labels = list(self.labels)
        tau0, avar0, edf0 = self.curve
        self.base_fit = fit_axis(tau0, avar0, edf0, self.rate_hz, self.n_samples,
                                 terms=self.labels, unit=self.unit)

    def ramp_first(self) -> None:
        """Test a rate ramp on the record itself, before the curve search."""
        # On the curve a random walk can absorb a ramp (its +1/2 slope bends towards the
        # ramp's +1 only at the last taus); in the record it cannot.
        if 'rate_ramp' not in self.effects or self.raw is None:
            return
        sol, scale = self.sol, self.fitter.data.scale
        check = ramp_test(self.raw, self.raw_rate,
                          _noise_terms(self.slots_of(self.labels), sol.coef, sol.phi, scale))
        if check is None:
            return
        if not check.significant:
            if check.lr >= CANNOT_TELL_LR:
                self.notes.append(cannot_tell('rate_ramp', 'a rate ramp or more random walk',
                                              check.lr, RAMP_LR_MIN, self.duration_s()))
            else:
                self.notes.append(f'rate_ramp: not supported by the record (likelihood '
                                  f'ratio {check.lr:.1f} against more random walk)')
            return
        slots = self.slots_of(self.labels + ['rate_ramp'])
        new = fit_fixed_weights(self.fitter.data, slots, list(sol.phi) + [()])
        if new.coef[-1] > 0:
            self.steps.append(Step(
                'rate_ramp', 'rate_ramp', float(sol.j - new.j), RunnerUp(),
                f'ramp {check.slope:.3g} {self.unit}/s in the record: likelihood ratio '
                f'{check.lr:.1f} against more random walk'))
            self.irls(self.labels + ['rate_ramp'], phi0=new.phi, local=True)

    def screen(self) -> list:
        """Score every effect not yet in the model at the current weights."""
        ranked = []
        for effect in self.effects:
            label = _label_for(effect, self.labels)
            if label is None or effect == 'rate_ramp' and self.raw is not None:
                continue
            if effect == 'quantization' and not shows_quantization(self.tau, self.y):
                continue
            slots = self.slots_of(self.labels + [label])
            if n_params(slots) >= self.k:
                continue
            phi0 = list(self.sol.phi) + [tuple(math.sqrt(lo * hi)
                                               for lo, hi in slots[-1].bounds)]
            new = fit_fixed_weights(self.fitter.data, slots, phi0,
                                    grid_slots=_grid_slots(effect, slots))
            if new.coef[-1] <= 0:
                continue
            drop = float(self.sol.j - new.j)
            score = drop - (1 + len(slots[-1].bounds)) * self.penalty - DELTA_MIN
            if score > 0:
                ranked.append(Candidate(score, drop, effect, label, new))
        return _by_likelihood(self.fitter, self.slots_of, self.labels, ranked, self.penalty)

    def choose(self, ranked: list) -> Choice | None:
        """Return the best ranked effect whose time-domain evidence holds, or None."""
        for i, cand in enumerate(ranked):
            effect, new, evidence = cand.effect, cand.solution, ''
            if effect == 'sinusoid' and self.raw is not None:
                idx = len(self.labels)
                amp = math.sqrt(new.coef[idx] * self.fitter.data.scale)
                ok, f_line, evidence = _sinusoid_evidence(self.raw, self.raw_rate,
                                                          new.phi[idx][0], amp, self.lines_hz)
                if not ok:
                    self.notes.append(evidence)
                    continue
                self.lines_hz.append(f_line)
                phi = list(new.phi)
                phi[idx] = (f_line,)
                new = new._replace(phi=tuple(phi))
            runner_up = next((RunnerUp(r.effect, r.chi2_drop) for r in ranked[i + 1:]
                              if r.effect != effect), RunnerUp())
            return Choice(cand.chi2_drop, effect, cand.label, new, runner_up, evidence)
        return None

    def forward(self) -> None:
        """Add effects while the chi-square rejects the model (the margins keep it honest)."""
        while len(self.steps) < MAX_STEPS and self.rejected():
            chosen = self.choose(self.screen())
            if chosen is None:
                # Second chance: at the current weights a model that overshoots the long
                # taus gives them little weight, so no effect buys its margin there.
                chosen = _second_chance(self.fitter, self.slots_of, self.labels, self.sol,
                                        self.sigma, self.effects, self.penalty)
                self.fitter.data.set_sigma(self.sigma)
            if chosen is None:
                return
            if chosen.effect == 'sinusoid':
                f_line = chosen.solution.phi[len(self.labels)][0]
                self.narrowed[chosen.label] = ((f_line / 1.2, f_line * 1.2),)
            self.irls(self.labels + [chosen.label], phi0=chosen.solution.phi, local=True)
            self.steps.append(Step(chosen.effect, chosen.label, chosen.chi2_drop,
                                   chosen.runner_up, chosen.evidence))

    def duration_s(self) -> float:
        """Length of the record [s]."""
        return self.n_samples / float(self.rate_hz)

    def undecided(self) -> None:
        """
        Say where the record cannot tell a further Gauss-Markov process from none.

        The final model plus one more Gauss-Markov process is fitted at the current
        weights; a chi-square drop worth its parameters by AIC (2 per parameter) but
        short of the search's margin (BIC plus :data:`DELTA_MIN`) is "cannot tell",
        with the record length whose expected drop would reach the margin (the drop,
        a Fisher information, grows with the number of samples).
        """
        if 'gauss_markov' not in self.effects:
            return
        label = _label_for('gauss_markov', self.labels)
        slots = self.slots_of(self.labels + [label]) if label else []
        if not label or n_params(slots) >= self.k:
            return
        self.fitter.data.set_sigma(self.sigma)
        phi0 = list(self.sol.phi) + [tuple(math.sqrt(lo * hi) for lo, hi in slots[-1].bounds)]
        new = fit_fixed_weights(self.fitter.data, slots, phi0, grid_slots=_grid_slots(
            'gauss_markov', slots))
        drop = float(self.sol.j - new.j)
        need = 2 * self.penalty + DELTA_MIN
        if new.coef[-1] > 0 and KEEP_PENALTY * 2 < drop < need:
            self.notes.append(cannot_tell('gauss_markov', 'one more Gauss-Markov process '
                                          'or none', drop, need, self.duration_s(),
                                          'chi2 drop'))

    def drop_steps(self, dropped: list, why: str) -> None:
        """Remove steps (and their terms) from the model's record."""
        gone = {st.label for st in dropped}
        self.steps = [st for st in self.steps if st.label not in gone]
        kept = [k for k, lb in enumerate(self.labels) if lb not in gone]
        if len(kept) < len(self.labels) and self.sol is not None:
            # The solution follows its labels (the rival checks read both): the rest
            # re-solved at the same weights from their values.
            self.sol = fit_fixed_weights(
                self.fitter.data, self.slots_of([self.labels[k] for k in kept]),
                [self.sol.phi[k] for k in kept], local=True)
        self.labels = [self.labels[k] for k in kept]
        self.notes += [f'{st.effect}: {why} (left out)' for st in dropped]

    def backward(self) -> None:
        """Drop an effect whose removal no longer costs its margin at the final weights."""
        for st in list(self.steps):
            rest = [lb for lb in self.labels if lb != st.label]
            without = fit_fixed_weights(
                self.fitter.data, self.slots_of(rest),
                [p for lb, p in zip(self.labels, self.sol.phi) if lb != st.label], local=True)
            n_par = 1 + len(term_slot(st.label, self.tau, self.rate_hz).bounds)
            if without.j - self.sol.j < n_par * self.penalty + DELTA_MIN:
                # Re-fitted first: the record then drops a label the solution no longer has.
                self.irls(rest, phi0=without.phi, local=True)
                self.drop_steps([st], 'lowered the chi-square at first, but the re-weighted '
                                'model does as well without it')

    def full_fit(self, labels, sigma0=None) -> AxisFit:
        """Return the fit with intervals and bounds of these terms, from the search's values."""
        tau0, avar0, edf0 = self.curve
        return fit_axis(tau0, avar0, edf0, self.rate_hz, self.n_samples, terms=list(labels),
                        unit=self.unit, select=False, phi0=self.phi_of, sigma0=sigma0)

    def final_model(self) -> FinalModel:
        """Return the final state the rival checks read (:mod:`imu_allan.core.search.choice`)."""
        return FinalModel(fitter=self.fitter, sigma=self.sigma, labels=tuple(self.labels),
                          slots_of=self.slots_of, sol=self.sol, phi_of=dict(self.phi_of),
                          penalty=self.penalty, steps=tuple(self.steps),
                          effects=tuple(self.effects), k=self.k, tau=self.tau)

    def final(self) -> AxisFit:
        """Return the final model's full fit; effects it does not hold are not named."""
        self.phi_of = dict(zip(self.labels, self.sol.phi))
        if not self.steps:
            return self.base_fit
        fit = self.full_fit(self.labels, self.sigma)
        unheld = [st for st in self.steps if st.label not in fit.terms]
        if unheld:
            # The model has no such term: its record goes (the fit already left it out).
            self.drop_steps(unheld, 'the final fit holds it at zero')
        # Where the final model explains the curve, its profile intervals are plain
        # likelihood-ratio intervals: an effect whose level may be zero is not named.
        if fit.dof > 0 and chi2_sf(fit.chi2, fit.dof) >= P_CONSISTENT:
            dropped = [st for st in self.steps if not _level_above_zero(fit, st.label)]
            if dropped:
                self.drop_steps(dropped, 'its level may be zero at 95 %')
                fit = self.base_fit if not self.steps else self.full_fit(self.labels)
        return fit

    def step_fits(self, fit: AxisFit) -> list:
        """Return each step with the full fit of the model up to it (the diagnosis' view)."""
        out = []
        for i, st in enumerate(self.steps):
            labels = self.base_labels + [s.label for s in self.steps[:i + 1]]
            f = fit if i == len(self.steps) - 1 else self.full_fit(labels)
            out.append(st._replace(fit=f))
        return out


def cannot_tell(effect: str, what: str, value: float, need: float, duration_s: float,
                statistic: str = 'likelihood ratio') -> str:
    """
    Note that the record cannot separate two explanations, and the length that would.

    The statistic (a likelihood ratio or a chi-square drop, i.e. the Fisher information
    of the effect at the fitted value) grows in proportion to the number of samples, so
    a record ``need / value`` times longer would reach the threshold on average.
    """
    hours = duration_s * need / max(value, 1e-9) / 3600.0
    return (f'{effect}: cannot tell from this record whether {what} ({statistic} '
            f'{value:.1f}, needs {need:.1f}); a record of about {hours:.2g} h would tell '
            'them apart')


def _level_above_zero(fit: AxisFit, label: str) -> bool:
    """Whether the fit holds the term with a 95 % interval of its level above zero."""
    if label not in fit.terms:
        return False
    name = TERMS[base_name(label)].symbols[0]
    p = fit.optimised.get(f'{label}.{name}', fit.optimised.get(name))
    return p is not None and p.kind == 'estimate' and p.ci95[0] > 0


def _finish(fit: AxisFit, steps: list, notes: list, unit: str,
            problems: tuple = ()) -> AxisFit:
    """Attach the effects, judge the fit, fall back to the curve where it fails, cap bounds."""
    optimised = dict(fit.optimised)
    notes = list(dict.fromkeys(list(fit.notes) + notes))    # each once, in order
    flicker = optimised.get('flicker.B')
    if optimised['B'].kind != 'estimate' and flicker is not None and flicker.kind == 'estimate':
        # The floor is flicker noise, not a Gauss-Markov process: B is its level and
        # T_B stays undefined (the Kalman model then lists B as left out).
        optimised['B'] = flicker
        notes = [n for n in notes if not n.startswith('B is flicker noise')]
        notes.append('B is flicker noise (no Gauss-Markov floor): no T_B')
    effects = tuple({'effect': s.effect, 'term': s.label, 'chi2_drop': s.chi2_drop,
                     'rival': s.rival, 'evidence': s.evidence} for s in steps)
    fit = replace(fit, optimised=optimised, notes=tuple(notes), effects=effects)
    return cap_fit(judge_fit(ambiguous_bias(fit), problems))
