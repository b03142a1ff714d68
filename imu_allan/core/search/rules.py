"""
What the effect search may add, and when.

Its constants (the effects, their fit terms, the amplitude agreement), its result types
and the rules an effect must pass: a label it can still take, periodogram evidence of a
sinusoid.  The margin an effect must buy is the selection rule's
(:data:`imu_allan.core.rules.DELTA_MIN`); every threshold is in
:mod:`imu_allan.core.rules`.
"""

import math
from typing import Any, Callable, NamedTuple, Sequence

import numpy as np

from imu_allan.core.fit.result import AxisFit
from imu_allan.core.noise.terms import base_name, search_effects, TERMS
from imu_allan.core.rules import AMPLITUDE_FACTOR
from imu_allan.core.search.evidence import periodogram_peak

#: Effects the search may add, in the order they are tried (ties keep the first): the
#: registry's terms with a ``search_rank``.  An effect's name is its term's name.
SEARCH_EFFECTS = search_effects()
#: The paper's base model (term names).
BASE_LABELS = ('white', 'bias_instability', 'random_walk')


class Candidate(NamedTuple):
    """
    One effect scored against the current model (the forward search's screen).

    Attributes
    ----------
    score : float
        Chi-square drop beyond the effect's margin (BIC per parameter plus
        :data:`imu_allan.core.rules.DELTA_MIN`) [-].
    chi2_drop : float
        Drop of the GLS chi-square at the current model's weights [-].
    effect : str
        Effect name, e.g. 'sinusoid'.
    label : str
        Fit term label it would take, e.g. 'sinusoid_2'.
    solution : object
        The fit of the model with it (a solver solution: coef, phi, j).

    """

    score: float
    chi2_drop: float
    effect: str
    label: str
    solution: Any


class RunnerUp(NamedTuple):
    """
    The best other explanation of a step's gap.

    Attributes
    ----------
    effect : str
        Effect name ('' when none qualified).
    chi2_drop : float
        The drop it bought at the same weights [-] (NaN when none).

    """

    effect: str = ''
    chi2_drop: float = math.nan

    def __str__(self) -> str:
        """Return 'effect (chi2 drop D)', or '' when none."""
        return f'{self.effect} (chi2 drop {self.chi2_drop:.1f})' if self.effect else ''


class Choice(NamedTuple):
    """
    The effect a step of the forward search takes.

    Attributes
    ----------
    chi2_drop : float
        Drop of the GLS chi-square it bought [-].
    effect : str
        Effect name.
    label : str
        Fit term label.
    solution : object
        The fit of the model with it (starting values of the re-weighted fit).
    runner_up : RunnerUp
        The best other explanation.
    evidence : str
        Time-domain evidence or how it was chosen ('' when none).

    """

    chi2_drop: float
    effect: str
    label: str
    solution: Any
    runner_up: RunnerUp
    evidence: str


class Step(NamedTuple):
    """
    One effect the search added.

    Attributes
    ----------
    effect : str
        Effect name (docs/contracts.md), e.g. 'sinusoid'.
    label : str
        Fit term label, e.g. 'sinusoid_2'.
    chi2_drop : float
        Drop of the GLS chi-square the effect bought at the previous model's weights.
    runner_up : RunnerUp
        The runner-up explanation and its drop (empty when none qualified).
    evidence : str
        Time-domain evidence (periodogram line, ramp likelihood ratio) or ''.
    fit : AxisFit or None
        The model after this step (kept for the diagnosis' before/after view).

    """

    effect: str
    label: str
    chi2_drop: float
    runner_up: RunnerUp
    evidence: str
    fit: AxisFit | None = None

    @property
    def rival(self) -> str:
        """Return the runner-up as the JSON and the notes show it ('' when none)."""
        return str(self.runner_up)


class FinalModel(NamedTuple):
    """
    The search's final model, as the rival checks read it (:mod:`imu_allan.core.search.choice`).

    Attributes
    ----------
    fitter : object
        The search's fitter (its curve and covariance); its weights are reset to
        ``sigma`` by whoever re-fits with it.
    sigma : np.ndarray
        Shape (k, k), the final model's covariance of the curve (the fit's weights).
    labels : tuple of str
        Fit labels of the final model.
    slots_of : callable
        Labels to fit slots (the search's narrowed sinusoid ranges included).
    sol : object
        The final model's solution (coef, phi, j) at ``sigma``.
    phi_of : dict of str to tuple
        Nonlinear parameters per label.
    penalty : float
        BIC's penalty per parameter for these taus.
    steps : tuple of Step
        The accepted effects.
    effects : tuple of str
        The effects the search could add.
    k : int
        Number of fitted taus.
    tau : np.ndarray
        Shape (k,), the fitted taus [s].

    """

    fitter: Any
    sigma: np.ndarray
    labels: tuple
    slots_of: Callable[..., list]
    sol: Any
    phi_of: dict
    penalty: float
    steps: tuple
    effects: tuple
    k: int
    tau: np.ndarray


class Rival(NamedTuple):
    """
    A model that fits about as well as the chosen one.

    Attributes
    ----------
    model : str
        What differs from the chosen model.
    criterion_rise : float
        Its chi-square (or -2 ln L + BIC) above the chosen model's [-].
    levels : dict of str to float
        Its N, B, T_B and K [SI].

    """

    model: str
    criterion_rise: float
    levels: dict


class GridPoint(NamedTuple):
    """
    One point of T_B's profile over its whole range.

    Attributes
    ----------
    rise : float
        Chi-square above the best grid point [-].
    inside : bool
        Within the 95 % profile threshold.
    levels : dict of str to float
        N, B, T_B and K there [SI].

    """

    rise: float
    inside: bool
    levels: dict


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
    term = TERMS[effect]
    bases = [base_name(lb) for lb in labels]
    if any(b in term.exclusive for b in bases):
        return None
    used = bases.count(effect)
    if used >= term.repeats:     # the registry says how many of it a model may hold
        return None
    return effect if effect not in labels else f'{effect}_{used + 1}'


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
