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
3. **Time-domain evidence**, where the curve blurs it (:mod:`imu_allan.core.search.evidence`):
   a sinusoid must show as a periodogram line of the raw samples near the fitted
   frequency (the line's frequency replaces the curve's); a rate ramp is tested on
   the record itself by a likelihood ratio against more random walk, so a ramp that
   the random walk absorbs on the curve is still found.
4. **Guards.**  Quantization is a candidate only where the curve shows its slope
   (steeper than -0.75 at the shortest taus).  When no effect closes the gap, the
   axis says so (``model_consistent`` false) and N is read from the white region of
   the curve, not from the distorted fit.

Effect names are term names (:mod:`imu_allan.core.noise.terms`): quantization, white,
flicker (B), gauss_markov (a further Gauss-Markov process, B and T), random_walk,
rate_ramp, sinusoid; the old effect name bias_instability is read as flicker for one
release.  The model's own low-pass is the term ``filtered_white``.

Every threshold named here (:data:`DELTA_MIN`, :data:`P_CONSISTENT`, :data:`MAX_STEPS`
...) lives in :mod:`imu_allan.core.rules`, with its reason.
"""

from typing import Sequence

from imu_allan.core.noise.terms import effect_name, effect_names, TERMS
from imu_allan.core.search.choice import random_walk_or_slow_process, with_rivals
from imu_allan.core.search.rules import BASE_LABELS, Search, SEARCH_EFFECTS, Step
from imu_allan.core.search.run import _finish, _Run
from imu_allan.errors import InputError

__all__ = ['BASE_LABELS', 'Search', 'search_axis', 'SEARCH_EFFECTS', 'Step']


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
        Effects the search may add (term names with ``effect`` in the registry; the old
        name bias_instability is read as flicker).
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
    effects = tuple(effect_name(e) for e in effects)
    for e in effects:
        if e not in TERMS or not TERMS[e].effect:
            raise InputError(f'unknown effect {e!r}; known: {", ".join(effect_names())}')
    return _search(tau_s, avar, edf, rate_hz, n_samples, raw, raw_rate_hz, unit, effects,
                   base_labels, keep_steps)


def _search(tau_s, avar, edf, rate_hz, n_samples, raw, raw_rate_hz, unit, effects,
            base_labels, keep_steps) -> Search:
    """Body of :func:`search_axis` (same arguments)."""
    run = _Run(tau_s, avar, edf, rate_hz, n_samples, raw, raw_rate_hz, unit, tuple(effects))
    run.base(base_labels)
    run.ramp_first()
    run.forward()
    run.backward()
    run.undecided()
    fit = run.final()
    final = run.final_model()
    fit = random_walk_or_slow_process(with_rivals(fit, final), final)
    steps = run.step_fits(fit) if keep_steps else run.steps
    return Search(_finish(fit, steps, run.notes, unit, tuple(run.problems)), run.base_fit,
                  tuple(steps))
