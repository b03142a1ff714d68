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
from scipy.stats import chi2

from imu_allan.core.evidence import periodogram_peak, ramp_test
from imu_allan.core.fit.axis import _check_inputs, _n_params, _slot, _thin, fit_axis
from imu_allan.core.fit.result import AxisFit, Param
from imu_allan.core.fit.solver import _design, _fit_fixed_w, _Fitter
from imu_allan.core.model import base_name, TERMS
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
#: A model whose chi-square p-value is at least this explains the curve: no search.
P_CONSISTENT = 1e-3
#: ... or one inside the curve's 95 % band (or within 5 %) at this share of the taus.
FOLLOW_SHARE = 0.85
#: Drop of the GLS chi-square, beyond BIC's ln(k) per parameter, that an effect must buy
#: (keeps clean axes clean: bench/search_power.py).
DELTA_MIN = 10.0
#: A sinusoid's amplitude from the curve and from the periodogram agree within this.
AMPLITUDE_FACTOR = 3.0
#: The shortest taus must fall at least this steeply (ADEV slope) for quantization.
QUANTIZATION_SLOPE = -0.75


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


def follows_curve(avar: np.ndarray, edf: np.ndarray, model: np.ndarray, chi2_value: float,
                  dof: int) -> bool:
    """
    Whether a model explains a measured curve.

    Either its GLS chi-square is acceptable (p >= :data:`P_CONSISTENT`), or the model
    lies inside the 95 % chi-square band of the measured ADEV, or within 5 % of it, at
    :data:`FOLLOW_SHARE` of the taus.  The second reading matters on long real
    records: with a million samples the shortest taus are known to 0.3 %, and a
    chi-square with the exact covariance rejects every model of a real sensor.

    Parameters
    ----------
    avar, edf, model : np.ndarray
        Shape (k,), measured AVAR [unit^2], its EDF, the model's AVAR [unit^2].
    chi2_value : float
        GLS chi-square of the model.
    dof : int
        Its degrees of freedom.

    Returns
    -------
    bool
        True when the model explains the curve.

    """
    if dof > 0 and chi2.sf(chi2_value, dof) >= P_CONSISTENT:
        return True
    e = np.maximum(edf, 1e-3)
    lo, hi = avar * e / chi2.ppf(0.975, e), avar * e / chi2.ppf(0.025, e)
    inside = ((model >= lo) & (model <= hi)) | (np.abs(np.sqrt(model / avar) - 1.0) <= 0.05)
    return bool(np.mean(inside) >= FOLLOW_SHARE)


def shows_quantization(tau: np.ndarray, avar: np.ndarray) -> bool:
    """
    Whether the shortest taus fall as steeply as quantization noise makes them.

    Quantization (white phase) gives an ADEV slope of -1; white noise -1/2, and a
    low-pass filter makes the shortest taus flatter still.  The term is a candidate
    only where the first ADEV slope is below :data:`QUANTIZATION_SLOPE`.
    """
    if tau.size < 2:
        return False
    slope = 0.5 * math.log(avar[1] / avar[0]) / math.log(tau[1] / tau[0])
    return slope < QUANTIZATION_SLOPE


def white_region(tau: np.ndarray, avar: np.ndarray, edf: np.ndarray,
                 share: np.ndarray) -> tuple[float, tuple[float, float]] | None:
    """
    Read N from the taus where white noise dominates the curve.

    Parameters
    ----------
    tau, avar, edf : np.ndarray
        Shape (k,), the curve [s], [unit^2], [-].
    share : np.ndarray
        Shape (k,), the white term's share of the fitted model's AVAR [-].

    Returns
    -------
    (N, (lo, hi)) or None
        Median of sqrt(avar tau) over the taus where the share is at least 0.8 (the
        white region), with the 95 % range of those points' chi-square intervals
        (NIST SP 1065 sec. 5.3), widened to cover their spread; None without such taus.

    """
    sel = np.flatnonzero(share >= 0.8)
    if sel.size == 0:
        return None
    level = np.sqrt(avar[sel] * tau[sel])
    n_value = float(np.median(level))
    e = np.maximum(edf[sel], 1.0)
    lo = level * np.sqrt(e / chi2.ppf(0.975, e))
    hi = level * np.sqrt(e / chi2.ppf(0.025, e))
    return n_value, (float(min(np.median(lo), level.min())),
                     float(max(np.median(hi), level.max())))


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
            tuple(math.sqrt(lo * hi) for lo, hi in slots[-1].bounds)])
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
    tau0, avar0, edf0 = _check_inputs(tau_s, avar, edf, rate_hz, n_samples)
    keep = _thin(tau0)
    tau, y, e = tau0[keep], avar0[keep], edf0[keep]
    if tau.size < 3:
        raise InputError(f'the fit needs at least 3 averaging times, got {tau.size}')
    k = tau.size
    dt = 1.0 / float(rate_hz)
    m = np.maximum(np.round(tau * rate_hz), 1).astype(np.int64)
    n_terms = np.maximum(int(n_samples) + 1 - 2 * m, 1)
    fitter = _Fitter(tau, y, e, m, n_terms, dt, int(n_samples), 'overlapping')
    penalty = math.log(k)
    raw_y = None if raw is None else np.asarray(raw, dtype=np.float64)
    raw_rate = float(raw_rate_hz or rate_hz)

    # A sinusoid, once named, keeps its frequency within 20 % (the re-weighted fits
    # must not move it to another feature of the curve).
    narrowed: dict[str, tuple] = {}

    def slots_of(labels):
        return [replace(s, bounds=narrowed[s.label]) if s.label in narrowed else
                _short_sinusoid(s, tau) for s in (_slot(lb, tau, rate_hz) for lb in labels)]

    def irls(labels, phi0=None, local=False):
        # IRLS leaves the plug-in Sigma of its solution as the weights; the candidates
        # are scored at those weights, so the model's own J is taken there too.
        slots = slots_of(labels)
        sol, sigma = fitter.irls(slots, phi0=phi0, local=local)
        return _fit_fixed_w(fitter.data, slots, sol.phi, local=True), sigma

    labels = list(base_labels)
    sol, sigma = irls(labels)
    base_j = sol.j
    dof = k - _n_params(slots_of(labels))
    # The filter only where the base model leaves something to explain.
    if 'white' in labels and dof > 2 and chi2.sf(sol.j, dof) < P_CONSISTENT:
        alt = ['filtered_white' if lb == 'white' else lb for lb in labels]
        trial = _fit_fixed_w(fitter.data, slots_of(alt))
        i_f = alt.index('filtered_white')
        # A filter time at the bottom of its range is no filter: plain white noise.
        shows = trial.phi[i_f][0] > 1.05 * slots_of(alt)[i_f].bounds[0][0]
        if base_j - trial.j > penalty + DELTA_MIN and trial.coef[i_f] > 0 and shows:
            labels = alt
            sol, sigma = irls(labels, phi0=trial.phi)
    base_fit = fit_axis(tau0, avar0, edf0, rate_hz, n_samples, terms=labels, unit=unit)
    steps: list[Step] = []
    notes: list[str] = []
    lines_hz: list[float] = []

    # A ramp is looked for in the record itself first: on the curve a random walk can
    # absorb it (its +1/2 slope bends towards the ramp's +1 only at the last taus).
    if 'rate_ramp' in effects and raw_y is not None and 'rate_ramp' not in labels:
        check = ramp_test(raw_y, raw_rate, _noise_terms(slots_of(labels), sol.coef, sol.phi,
                                                        fitter.data.scale))
        if check is not None and check.significant:
            slots = slots_of(labels + ['rate_ramp'])
            new = _fit_fixed_w(fitter.data, slots, list(sol.phi) + [()])
            if new.coef[-1] > 0:
                steps.append(Step('rate_ramp', 'rate_ramp', float(sol.j - new.j), '',
                                  f'ramp {check.slope:.3g} {unit}/s in the record: likelihood '
                                  f'ratio {check.lr:.1f} against more random walk'))
                labels.append('rate_ramp')
                sol, sigma = irls(labels, phi0=new.phi, local=True)
        elif check is not None:
            notes.append(f'rate_ramp: not supported by the record (likelihood ratio '
                         f'{check.lr:.1f} against more random walk)')

    while len(steps) < MAX_STEPS:
        # The search goes on while the chi-square rejects the model (the margins keep
        # it from inventing effects); 'follows the curve' only grades the final model.
        dof = k - _n_params(slots_of(labels))
        if dof <= 0 or chi2.sf(sol.j, dof) >= P_CONSISTENT:
            break
        ranked = []
        for effect in effects:
            label = _label_for(effect, labels)
            if label is None or effect == 'rate_ramp' and raw_y is not None:
                continue
            if effect == 'quantization' and not shows_quantization(tau, y):
                continue
            cand = labels + [label]
            slots = slots_of(cand)
            if _n_params(slots) >= k:
                continue
            phi0 = list(sol.phi) + [tuple(math.sqrt(lo * hi) for lo, hi in slots[-1].bounds)]
            # Interchangeable Gauss-Markov terms keep their order (shortest T first), so
            # a further one may need to take the other's place: grid them all.
            family = effect == 'gauss_markov' and any(
                x.term.name in ('gauss_markov', 'bias_instability') for x in slots[:-1])
            new = _fit_fixed_w(fitter.data, slots, phi0,
                               grid_slots=None if family else [len(labels)])
            if new.coef[-1] <= 0:
                continue
            n_par = 1 + len(slots[-1].bounds)
            drop = float(sol.j - new.j)
            score = drop - n_par * penalty - DELTA_MIN
            if score > 0:
                ranked.append((score, drop, effect, label, new))
        ranked = _by_likelihood(fitter, slots_of, labels, ranked, penalty)
        chosen = None
        for i, (score, drop, effect, label, new) in enumerate(ranked):
            evidence = ''
            if effect == 'sinusoid' and raw_y is not None:
                idx = len(labels)
                f0 = new.phi[idx][0]
                amp = math.sqrt(new.coef[idx] * fitter.data.scale)
                ok, f_line, evidence = _sinusoid_evidence(raw_y, raw_rate, f0, amp, lines_hz)
                if not ok:
                    notes.append(evidence)
                    continue
                lines_hz.append(f_line)
                phi = list(new.phi)
                phi[idx] = (f_line,)
                new = new._replace(phi=tuple(phi))
            rival = next((f'{r[2]} (chi2 drop {r[1]:.1f})' for r in ranked[i + 1:]
                          if r[2] != effect), '')
            chosen = (drop, effect, label, new, rival, evidence)
            break
        if chosen is None:
            # Second chance: at the current weights a model that overshoots the long
            # taus gives them little weight, so no effect buys its margin there.  Each
            # noise effect is re-fitted with its own weights and compared by likelihood.
            chosen = _second_chance(fitter, slots_of, labels, sol, sigma, effects, penalty)
            fitter.data.set_sigma(sigma)
        if chosen is None:
            break
        drop, effect, label, new, rival, evidence = chosen
        if effect == 'sinusoid':
            f_line = new.phi[len(labels)][0]
            narrowed[label] = ((f_line / 1.2, f_line * 1.2),)
        labels.append(label)
        sol, sigma = irls(labels, phi0=new.phi, local=True)
        steps.append(Step(effect, label, drop, rival, evidence))

    # Backward check at the final weights: an effect whose removal no longer costs
    # its margin (the others took over its role once re-weighted) is not named.
    for st in list(steps):
        rest = [lb for lb in labels if lb != st.label]
        slots = slots_of(rest)
        without = _fit_fixed_w(fitter.data, slots,
                               [p for lb, p in zip(labels, sol.phi) if lb != st.label],
                               local=True)
        n_par = 1 + len(_slot(st.label, tau, rate_hz).bounds)
        if without.j - sol.j < n_par * penalty + DELTA_MIN:
            steps.remove(st)
            labels = rest
            notes.append(f'{st.effect}: lowered the chi-square at first, but the re-weighted '
                         'model does as well without it (left out)')
            sol, sigma = irls(labels, phi0=without.phi, local=True)
    phi_of = dict(zip(labels, sol.phi))
    fit = base_fit
    if steps:
        fit = fit_axis(tau0, avar0, edf0, rate_hz, n_samples, terms=labels, unit=unit,
                       select=False, phi0=phi_of, sigma0=sigma)
        # A step the final fit holds at zero is not named (the model has no such term).
        unheld = [st for st in steps if st.label not in fit.terms]
        steps = [st for st in steps if st not in unheld]
        notes += [f'{st.effect}: the final fit holds it at zero (left out)' for st in unheld]
        # Where the final model explains the curve, its profile intervals are plain
        # likelihood-ratio intervals: an effect whose level may be zero is not named.
        if fit.dof > 0 and chi2.sf(fit.chi2, fit.dof) >= P_CONSISTENT:
            dropped = [st for st in steps if not _level_above_zero(fit, st.label)]
            if dropped:
                steps = [st for st in steps if st not in dropped]
                labels = [lb for lb in labels if lb not in {st.label for st in dropped}]
                notes += [f'{st.effect}: its level may be zero at 95 % (left out)'
                          for st in dropped]
                fit = base_fit if not steps else fit_axis(
                    tau0, avar0, edf0, rate_hz, n_samples, terms=labels, unit=unit,
                    select=False, phi0=phi_of)
    if keep_steps and steps:
        done = []
        for i, s in enumerate(steps):
            f = fit if i == len(steps) - 1 else fit_axis(
                tau0, avar0, edf0, rate_hz, n_samples,
                terms=list(labels[:len(labels) - len(steps) + i + 1]), unit=unit,
                select=False, phi0=phi_of)
            done.append(s._replace(fit=f))
        steps = done
    fit = _finish(fit, steps, notes, unit)
    return Search(fit, base_fit, tuple(steps))


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


def white_share(fit: AxisFit) -> np.ndarray | None:
    """Share of the white term in the fitted AVAR at each of the fit's taus."""
    for label, c_si, phi in fit.components:
        if label in ('white', 'filtered_white'):
            slot = _slot(label, fit.tau_s, 1.0 / max(fit.tau_s.min(), 1e-9))
            part = c_si * _design([slot], fit.tau_s, [phi])[:, 0]
            return part / np.maximum(fit.avar_fit, 1e-300)
    return None
