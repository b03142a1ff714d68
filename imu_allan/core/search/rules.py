"""
What the effect search may add, and when.

Its constants (the effects, their fit terms, the amplitude agreement), its result types
and the rules an effect must pass: a label it can still take, periodogram evidence of a
sinusoid.  The margin an effect must buy is the selection rule's
(:data:`imu_allan.core.fit.criterion.DELTA_MIN`).
"""

from typing import NamedTuple, Sequence

from imu_allan.core.fit.result import AxisFit
from imu_allan.core.noise.terms import base_name, search_effects, TERMS
from imu_allan.core.search.evidence import periodogram_peak

#: Effects the search may add, in the order they are tried (ties keep the first): the
#: registry's terms with a ``search_rank``.  An effect's name is its term's name.
SEARCH_EFFECTS = search_effects()
#: The paper's base model (term names).
BASE_LABELS = ('white', 'bias_instability', 'random_walk')
#: Most effects added per axis.
MAX_STEPS = 4
#: A sinusoid's amplitude from the curve and from the periodogram agree within this.
AMPLITUDE_FACTOR = 3.0


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
