"""
The effect search: one model per axis, the base terms plus every effect the data name.

Every analysis (``imu-allan analyze``, the node's periodic fit, ``imu-allan diagnose``)
runs this search, so all of them report the same model, and N, B, K, T_B, Q/R, the
Kalibr file and the Imu covariances all come from it.

1. **Base model.**  White noise, the paper's Gauss-Markov bias instability (B, T_B)
   and random walk (Maia et al., sec. 2).  White noise is taken through the sensor's
   own low-pass filter (term ``filtered_white``: N and a filter time constant of at
   most a few sample periods) when that lowers the GLS chi-square by more than
   :data:`DELTA_MIN` plus ln(k): a real IMU's decimation filter bends the shortest
   taus below the white line, and a model without it spends white noise on a
   fast Gauss-Markov term (T_B a few samples: white noise to the curve).
2. **Forward search.**  While the model does not explain the curve (chi-square
   p-value below :data:`P_CONSISTENT`), every effect not yet in it is fitted at the
   current model's covariance of the curve; the one with the largest drop of the
   GLS chi-square beyond BIC's ln(k) per parameter and the margin :data:`DELTA_MIN`
   is added and the model re-weighted (IRLS), up to :data:`MAX_STEPS` effects.  Rival
   explanations compete on the same statistic: a second Gauss-Markov process (two
   parameters) against flicker noise (one), a sinusoid against both.
3. **Time-domain evidence**, where the curve blurs it (:mod:`imu_allan.core.evidence`):
   a sinusoid must show as a periodogram line of the raw samples near the fitted
   frequency (the line's frequency replaces the curve's); a rate ramp is tested on
   the record itself by a likelihood ratio against more random walk, so a ramp that
   the random walk absorbs on the curve is still found.
4. **Guards.**  Quantization is a candidate only where the curve shows its slope
   (steeper than -0.75 at the shortest taus).  When no effect closes the gap, the
   axis says so (``model_consistent`` false) and N is read from the white region of
   the curve, not from the distorted fit.

Effect names (DESIGN.md diagnose contract): quantization, white, bias_instability
(flicker noise, B), gauss_markov (a further Gauss-Markov process, B and T),
random_walk, rate_ramp, sinusoid; the model's own low-pass is ``filtered_white``.
"""

from dataclasses import replace
import math
from typing import NamedTuple, Sequence

import numpy as np

from imu_allan.core.allan.blas import _single_thread_blas
from imu_allan.core.evidence import periodogram_peak, ramp_test
from imu_allan.core.fit.axis import _check_inputs, _n_params, _slot, _thin, fit_axis
from imu_allan.core.fit.result import AxisFit, Param
from imu_allan.core.fit.solver import _fit_fixed_w, _Fitter
from imu_allan.core.judge import (follows_curve, P_CONSISTENT, shows_quantization,
                                  white_region, white_share)
from imu_allan.core.model import base_name, TERMS
from imu_allan.core.quantiles import chi2_sf
from imu_allan.errors import InputError

#: Effects the search may add, in the order they are tried (ties keep the first).
SEARCH_EFFECTS = ('sinusoid', 'gauss_markov', 'bias_instability', 'quantization',
                  'rate_ramp')
#: The paper's base model (fit labels).
BASE_LABELS = ('white', 'bias_instability', 'random_walk')
#: Fit term behind each effect when it is added ('bias_instability' is flicker noise).
EFFECT_TERM = {'quantization': 'quantization', 'white': 'white',
               'bias_instability': 'flicker', 'gauss_markov': 'gauss_markov',
               'random_walk': 'random_walk', 'rate_ramp': 'rate_ramp',
               'sinusoid': 'sinusoid'}
#: At most this many of a repeatable effect (gauss_markov, sinusoid) are added.
MAX_REPEATS = 2
#: Most effects added per axis.
MAX_STEPS = 4
#: Drop of the GLS chi-square, beyond BIC's ln(k) per parameter, that an effect must buy
#: (keeps clean axes clean: bench/search_power.py).
DELTA_MIN = 10.0
#: A sinusoid's amplitude from the curve and from the periodogram agree within this.
AMPLITUDE_FACTOR = 3.0


class Step(NamedTuple):
    """
    One effect the search added.

    Attributes
    ----------
    effect : str
        Effect name (DESIGN.md), e.g. 'sinusoid'.
    label : str
        Fit term label, e.g. 'sinusoid_2'.
    chi2_drop : float
        Drop of the GLS chi-square the effect bought at the previous model's weights.
    rival : str
        The runner-up explanation and its drop ('' when none qualified).
    evidence : str
        Time-domain evidence (periodogram line, ramp likelihood ratio) or ''.
    fit : AxisFit or None
        The model after this step (kept for the diagnosis' before/after view).

    """

    effect: str
    label: str
    chi2_drop: float
    rival: str
    evidence: str
    fit: AxisFit | None = None


class Search(NamedTuple):
    """
    Result of :func:`search_axis`.

    Attributes
    ----------
    fit : AxisFit
        The final model (base terms plus every accepted effect); its ``effects`` and
        ``model_consistent`` say what the search found.
    base : AxisFit
        The base model's fit (the diagnosis' 'before').
    steps : tuple of Step
        The accepted effects in order.

    """

    fit: AxisFit
    base: AxisFit
    steps: tuple


def _label_for(effect: str, labels: Sequence[str]) -> str | None:
    """Fit label of an effect to add, or None when it cannot be added again."""
    term = EFFECT_TERM[effect]
    if effect == 'white' and 'filtered_white' in labels:
        return None
    if effect in ('gauss_markov', 'sinusoid'):
        used = [lb for lb in labels if lb == term or lb.startswith(term + '_')]
        if len(used) >= MAX_REPEATS:
            return None
        return term if term not in labels else f'{term}_{len(used) + 1}'
    return None if term in labels else term


def _sinusoid_evidence(raw, raw_rate_hz: float, f0: float, amp: float,
                       lines_hz: Sequence[float]) -> tuple[bool, float, str]:
    """Check a curve-fitted sinusoid against the periodogram (see the module doc)."""
    peak = periodogram_peak(raw, raw_rate_hz, f0 / 2.0, f0 * 2.0)
    if peak is None:
        return True, f0, f'frequency {f0:.3g} Hz beyond the raw samples; not checked'
    if not peak.significant or not (
            1.0 / AMPLITUDE_FACTOR <= peak.band_amplitude / amp <= AMPLITUDE_FACTOR):
        return False, f0, (f'sinusoid at {f0:.3g} Hz (A {amp:.2g}) fits the curve but the '
                           f'periodogram does not confirm it (line {peak.ratio:.0f} x '
                           f'background, needs {peak.threshold:.0f}; amplitude '
                           f'{peak.band_amplitude:.2g}); not added')
    for f_line in lines_hz:
        if abs(f_line - peak.f0_hz) <= max(3.0 * peak.bin_hz, 0.05 * peak.f0_hz):
            return False, f0, (f'a further sinusoid near {peak.f0_hz:.3g} Hz would model '
                               'the same periodogram line again; not added')
    return True, peak.f0_hz, (f'periodogram line at {peak.f0_hz:.4g} Hz ({peak.ratio:.0f} x '
                              f'background; curve fit {f0:.3g} Hz), amplitude '
                              f'{peak.band_amplitude:.3g} (curve fit {amp:.3g})')


#: Rival effects re-fitted (IRLS) and compared by their full likelihood at each step.
N_RIVALS = 3


def _by_likelihood(fitter, slots_of, labels: list, ranked: list, penalty: float) -> list:
    """
    Order the qualifying effects by penalised Gaussian likelihood, best first.

    The first screen scores every effect at the current model's weights.  Rivals can
    trade roles there (a second Gauss-Markov process against flicker noise, a
    Gauss-Markov process of very long T against a random walk), and each changes the
    covariance of the curve in its own way, so the best :data:`N_RIVALS` are re-fitted
    to convergence and compared by -2 ln L = J + ln det Sigma (GLS chi-square at the
    model's own covariance plus its log-determinant) + ln(k) per parameter (BIC).
    """
    ranked = sorted(ranked, key=lambda r: -r[0])
    if len(ranked) < 2:
        return ranked
    scored = []
    for r in ranked[:N_RIVALS]:
        slots = slots_of(labels + [r[3]])
        sol, _ = fitter.irls(slots, phi0=r[4].phi, local=True)
        logdet = 2.0 * float(np.sum(np.log(np.abs(np.diag(fitter.data.chol)))))
        scored.append((sol.j + logdet + _n_params(slots) * penalty, r))
    scored.sort(key=lambda x: x[0])
    return [r for _, r in scored] + ranked[N_RIVALS:]


def _neg2_loglik(fitter, sol, n_params: int, penalty: float) -> float:
    """-2 ln L + BIC penalty of a solution at the fitter's current Sigma."""
    logdet = 2.0 * float(np.sum(np.log(np.abs(np.diag(fitter.data.chol)))))
    return sol.j + logdet + n_params * penalty


def _second_chance(fitter, slots_of, labels: list, sol, sigma, effects, penalty: float):
    """
    Re-fit each noise effect with its own weights; return the best step or None.

    Used when the screen at the current weights found nothing but the chi-square still
    rejects the model.  Sinusoids and ramps need their time-domain evidence and are
    not tried here.  A step is taken when its penalised -2 ln L (:func:`_by_likelihood`)
    beats the current model's by :data:`DELTA_MIN`.
    """
    fitter.data.set_sigma(sigma)
    current = _neg2_loglik(fitter, sol, _n_params(slots_of(labels)), penalty)
    best = None
    for effect in effects:
        label = _label_for(effect, labels)
        if label is None or effect in ('sinusoid', 'rate_ramp'):
            continue
        if effect == 'quantization' and not shows_quantization(fitter.data.tau, fitter.data.y):
            continue
        slots = slots_of(labels + [label])
        if _n_params(slots) >= fitter.data.tau.size:
            continue
        new, _ = fitter.irls(slots, phi0=list(sol.phi) + [
            tuple(math.sqrt(lo * hi) for lo, hi in slots[-1].bounds)],
            grid_slots=_grid_slots(effect, slots))
        if new.coef[-1] <= 0:
            continue
        value = _neg2_loglik(fitter, new, _n_params(slots), penalty)
        if current - value > DELTA_MIN and (best is None or value < best[0]):
            best = (value, (float(current - value), effect, label, new, '',
                            'chosen by likelihood with its own weights'))
    return None if best is None else best[1]


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


def _grid_slots(effect: str, slots) -> list | None:
    """Slots whose parameters a fit with an added effect (the last slot) grids anew."""
    # Interchangeable Gauss-Markov terms keep their order (shortest T first), so a
    # further one may need to take the other's place: grid them all.
    family = effect == 'gauss_markov' and any(
        x.term.name in ('gauss_markov', 'bias_instability') for x in slots[:-1])
    return None if family else [len(slots) - 1]


def _noise_terms(slots, coef, phi, scale: float) -> list:
    return [(s.term.name, float(c) * scale, tuple(p)) for s, c, p in zip(slots, coef, phi)]


def search_axis(tau_s, avar, edf, rate_hz: float, n_samples: int, *, raw=None,
                raw_rate_hz: float | None = None, unit: str = 'unit',
                effects: Sequence[str] = SEARCH_EFFECTS,
                base_labels: Sequence[str] = BASE_LABELS,
                keep_steps: bool = False) -> Search:
    """
    Fit the base model of one axis and add every effect the data name.

    Parameters
    ----------
    tau_s, avar, edf : array_like
        Shape (k,), the overlapping Allan curve: averaging times [s], AVAR [unit^2],
        equivalent degrees of freedom.
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Samples behind the curve.
    raw : array_like, optional
        Shape (n,), raw or block-averaged samples of the axis (periodogram and ramp
        evidence); without them sinusoids and ramps are named from the curve alone.
    raw_rate_hz : float, optional
        Rate of ``raw`` [Hz]; default ``rate_hz``.
    unit : str
        Unit of the samples.
    effects : sequence of str
        Effects the search may add (names of :data:`SEARCH_EFFECTS`).
    base_labels : sequence of str
        Fit labels of the base model.
    keep_steps : bool
        Fit and keep the full model after every step (the diagnosis shows them).

    Returns
    -------
    Search
        The final fit, the base fit and the accepted steps.

    Raises
    ------
    InputError
        Unknown effects, or a curve the fit cannot use.

    """
    for e in effects:
        if e not in EFFECT_TERM:
            raise InputError(f'unknown effect {e!r}; known: {", ".join(EFFECT_TERM)}')
    # Tiny matrices: OpenBLAS threads only add overhead (see fit_axis).
    with _single_thread_blas():
        return _search(tau_s, avar, edf, rate_hz, n_samples, raw, raw_rate_hz, unit,
                       effects, base_labels, keep_steps)


def _search(tau_s, avar, edf, rate_hz, n_samples, raw, raw_rate_hz, unit, effects,
            base_labels, keep_steps) -> Search:
    """Body of :func:`search_axis` (same arguments)."""
    run = _Run(tau_s, avar, edf, rate_hz, n_samples, raw, raw_rate_hz, unit, tuple(effects))
    run.base(base_labels)
    run.ramp_first()
    run.forward()
    run.backward()
    fit = run.final()
    steps = run.step_fits(fit) if keep_steps else run.steps
    return Search(_finish(fit, steps, run.notes, unit), run.base_fit, tuple(steps))


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
        self.curve = _check_inputs(tau_s, avar, edf, rate_hz, n_samples)
        tau0, avar0, edf0 = self.curve
        keep = _thin(tau0)
        self.tau, self.y, e = tau0[keep], avar0[keep], edf0[keep]
        if self.tau.size < 3:
            raise InputError(f'the fit needs at least 3 averaging times, got {self.tau.size}')
        self.rate_hz, self.n_samples, self.unit = rate_hz, int(n_samples), unit
        self.effects = effects
        m = np.maximum(np.round(self.tau * rate_hz), 1).astype(np.int64)
        n_terms = np.maximum(self.n_samples + 1 - 2 * m, 1)
        self.fitter = _Fitter(self.tau, self.y, e, m, n_terms, 1.0 / float(rate_hz),
                              self.n_samples, 'overlapping')
        self.k = self.tau.size
        self.penalty = math.log(self.k)
        self.raw = None if raw is None else np.asarray(raw, dtype=np.float64)
        self.raw_rate = float(raw_rate_hz or rate_hz)
        # A sinusoid, once named, keeps its frequency within 20 % (the re-weighted fits
        # must not move it to another feature of the curve).
        self.narrowed: dict[str, tuple] = {}
        self.lines_hz: list[float] = []
        self.steps: list[Step] = []
        self.notes: list[str] = []
        self.labels: list[str] = []
        self.base_labels: list[str] = []

    def slots_of(self, labels):
        """Return the slots of the labels, with narrowed sinusoid frequencies."""
        return [replace(s, bounds=self.narrowed[s.label]) if s.label in self.narrowed else
                _short_sinusoid(s, self.tau)
                for s in (_slot(lb, self.tau, self.rate_hz) for lb in labels)]

    def irls(self, labels, phi0=None, local=False) -> None:
        """Fit ``labels`` by IRLS and make it the current model."""
        # IRLS leaves the plug-in Sigma of its solution as the weights; the candidates
        # are scored at those weights, so the model's own J is taken there too.
        slots = self.slots_of(labels)
        sol, self.sigma = self.fitter.irls(slots, phi0=phi0, local=local)
        self.sol = _fit_fixed_w(self.fitter.data, slots, sol.phi, local=True)
        self.labels = list(labels)

    def rejected(self) -> bool:
        """Whether the chi-square rejects the current model."""
        dof = self.k - _n_params(self.slots_of(self.labels))
        return dof > 0 and chi2_sf(self.sol.j, dof) < P_CONSISTENT

    def base(self, base_labels) -> None:
        """Fit the paper's model, through the sensor's filter where the curve shows one."""
        self.irls(list(base_labels))
        labels = self.labels
        if 'white' in labels and self.rejected() and (
                self.k - _n_params(self.slots_of(labels)) > 2):
            alt = ['filtered_white' if lb == 'white' else lb for lb in labels]
            trial = _fit_fixed_w(self.fitter.data, self.slots_of(alt))
            i_f = alt.index('filtered_white')
            # A filter time at the bottom of its range is no filter: plain white noise.
            shows = trial.phi[i_f][0] > 1.05 * self.slots_of(alt)[i_f].bounds[0][0]
            if (self.sol.j - trial.j > self.penalty + DELTA_MIN and trial.coef[i_f] > 0
                    and shows):
                self.irls(alt, phi0=trial.phi)
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
            self.notes.append(f'rate_ramp: not supported by the record (likelihood ratio '
                              f'{check.lr:.1f} against more random walk)')
            return
        slots = self.slots_of(self.labels + ['rate_ramp'])
        new = _fit_fixed_w(self.fitter.data, slots, list(sol.phi) + [()])
        if new.coef[-1] > 0:
            self.steps.append(Step(
                'rate_ramp', 'rate_ramp', float(sol.j - new.j), '',
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
            if _n_params(slots) >= self.k:
                continue
            phi0 = list(self.sol.phi) + [tuple(math.sqrt(lo * hi)
                                               for lo, hi in slots[-1].bounds)]
            new = _fit_fixed_w(self.fitter.data, slots, phi0,
                               grid_slots=_grid_slots(effect, slots))
            if new.coef[-1] <= 0:
                continue
            drop = float(self.sol.j - new.j)
            score = drop - (1 + len(slots[-1].bounds)) * self.penalty - DELTA_MIN
            if score > 0:
                ranked.append((score, drop, effect, label, new))
        return _by_likelihood(self.fitter, self.slots_of, self.labels, ranked, self.penalty)

    def choose(self, ranked: list):
        """Return the best ranked effect whose time-domain evidence holds, or None."""
        for i, (_, drop, effect, label, new) in enumerate(ranked):
            evidence = ''
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
            rival = next((f'{r[2]} (chi2 drop {r[1]:.1f})' for r in ranked[i + 1:]
                          if r[2] != effect), '')
            return drop, effect, label, new, rival, evidence
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
            drop, effect, label, new, rival, evidence = chosen
            if effect == 'sinusoid':
                f_line = new.phi[len(self.labels)][0]
                self.narrowed[label] = ((f_line / 1.2, f_line * 1.2),)
            self.irls(self.labels + [label], phi0=new.phi, local=True)
            self.steps.append(Step(effect, label, drop, rival, evidence))

    def drop_steps(self, dropped: list, why: str) -> None:
        """Remove steps (and their terms) from the model's record."""
        gone = {st.label for st in dropped}
        self.steps = [st for st in self.steps if st.label not in gone]
        self.labels = [lb for lb in self.labels if lb not in gone]
        self.notes += [f'{st.effect}: {why} (left out)' for st in dropped]

    def backward(self) -> None:
        """Drop an effect whose removal no longer costs its margin at the final weights."""
        for st in list(self.steps):
            rest = [lb for lb in self.labels if lb != st.label]
            without = _fit_fixed_w(
                self.fitter.data, self.slots_of(rest),
                [p for lb, p in zip(self.labels, self.sol.phi) if lb != st.label], local=True)
            n_par = 1 + len(_slot(st.label, self.tau, self.rate_hz).bounds)
            if without.j - self.sol.j < n_par * self.penalty + DELTA_MIN:
                self.drop_steps([st], 'lowered the chi-square at first, but the re-weighted '
                                'model does as well without it')
                self.irls(rest, phi0=without.phi, local=True)

    def full_fit(self, labels, sigma0=None) -> AxisFit:
        """Return the fit with intervals and bounds of these terms, from the search's values."""
        tau0, avar0, edf0 = self.curve
        return fit_axis(tau0, avar0, edf0, self.rate_hz, self.n_samples, terms=list(labels),
                        unit=self.unit, select=False, phi0=self.phi_of, sigma0=sigma0)

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


def _level_above_zero(fit: AxisFit, label: str) -> bool:
    """Whether the fit holds the term with a 95 % interval of its level above zero."""
    if label not in fit.terms:
        return False
    name = TERMS[base_name(label)].symbols[0]
    p = fit.optimised.get(f'{label}.{name}', fit.optimised.get(name))
    return p is not None and p.kind == 'estimate' and p.ci95[0] > 0


def _finish(fit: AxisFit, steps: list, notes: list, unit: str) -> AxisFit:
    """Attach the effects, judge consistency, and fall back to the white region for N."""
    consistent = follows_curve(fit.avar_meas, fit.edf, fit.avar_fit, fit.chi2, fit.dof)
    optimised = dict(fit.optimised)
    notes = list(fit.notes) + notes
    flicker = optimised.get('flicker.B')
    if optimised['B'].kind != 'estimate' and flicker is not None and flicker.kind == 'estimate':
        # The floor is flicker noise, not a Gauss-Markov process: B is its level and
        # T_B stays undefined (the Kalman model then uses kalman.flicker_time_s).
        optimised['B'] = flicker
        notes.append('B is flicker noise (no Gauss-Markov floor): no T_B')
    effects = tuple({'effect': s.effect, 'term': s.label, 'chi2_drop': s.chi2_drop,
                     'rival': s.rival, 'evidence': s.evidence} for s in steps)
    if not consistent:
        notes.append('no listed effect closes the gap between the model and the curve '
                     f'(chi2 {fit.chi2:.1f} for {fit.dof} dof)')
        share = white_share(fit)
        got = None if share is None else white_region(fit.tau_s, fit.avar_meas, fit.edf,
                                                      share)
        n_fit = optimised.get('N')
        if got is not None and n_fit is not None and n_fit.kind == 'estimate' and (
                abs(n_fit.value / got[0] - 1.0) > 0.05):
            optimised['N'] = Param(got[0], got[1], 'estimate', n_fit.unit)
            notes.append(f'N read from the white region of the curve ({got[0]:.4g}; the '
                         f'distorted fit gave {n_fit.value:.4g})')
    return replace(fit, optimised=optimised, notes=tuple(notes), effects=effects,
                   model_consistent=consistent)
