"""
The diagnosis of one axis, a curve and a session: search, simulate, compare.

Part of :mod:`imu_allan.core.diagnose` (see its docstring for the method).
"""

from dataclasses import replace
from typing import NamedTuple, Sequence

import numpy as np

from imu_allan import AXES, AXIS_UNITS
from imu_allan.core.allan.curve import AllanCurve
from imu_allan.core.allan.edf import edf_overlapping
from imu_allan.core.allan.raw import raw_evidence, RawKeeper
from imu_allan.core.diagnose.gap import find_bands, gap, gap_z, ln_adev_stderr
from imu_allan.core.diagnose.replicas import N_REPLICAS, simulate_fit_avar
from imu_allan.core.diagnose.result import AxisDiagnosis, DiagnoseResult, Finding, summary_line
from imu_allan.core.fit.result import AxisFit
from imu_allan.core.noise.terms import (BASE_ALIASES, EFFECT_ALIASES, effect_name, effect_names,
                                        TERMS)
from imu_allan.core.search import search_axis
from imu_allan.core.search.rules import SEARCH_EFFECTS
from imu_allan.errors import InputError


#: Effect names the diagnosis can report: the registry's effects (term names).
EFFECTS = effect_names()

#: The paper's model (term names): white noise, the Gauss-Markov bias instability
#: (B, T_B), random walk.
DEFAULT_BASE = ('white', 'bias_instability', 'random_walk')


class _State(NamedTuple):
    labels: tuple
    fit: AxisFit
    adev_sim: np.ndarray
    gap: float


def base_terms(base_model: Sequence[str]) -> tuple:
    """
    Return the term names of a base model, old names mapped (:data:`BASE_ALIASES`).

    Parameters
    ----------
    base_model : sequence of str
        Term names; 'gauss_markov' (the old name of the paper's floor) is read as
        'bias_instability' for one release.

    Returns
    -------
    tuple of str
        Registry names, each once.

    Raises
    ------
    InputError
        An unknown name, or an empty model.

    """
    names = tuple(BASE_ALIASES.get(b, b) for b in base_model)
    for name in names:
        if name not in TERMS:
            raise InputError(f'unknown term {name!r} in the base model; known: '
                             f'{", ".join(TERMS)}')
    if not names:
        raise InputError('the base model needs at least one term')
    return tuple(dict.fromkeys(names))


def _default_effects(base_model: Sequence[str]) -> tuple:
    """Return the search's own effects, plus white or random walk where the base lacks them."""
    return SEARCH_EFFECTS + tuple(e for e in ('white', 'random_walk') if e not in base_model)


def _fit_symbol(fit: AxisFit, label: str, sym: str):
    for key in (f'{label}.{sym}', sym):
        if key in fit.optimised:
            return fit.optimised[key]
    return None


def _effect_params(fit: AxisFit, effect: str, label: str, unit: str):
    params, ci, units = {}, {}, {}
    term = TERMS[effect]
    for sym, template in zip(term.symbols, term.units):
        p = _fit_symbol(fit, label, sym)
        if p is None:
            return None
        params[sym] = float(p.value)
        ci[sym] = (float(p.ci95[0]), float(p.ci95[1]))
        units[sym] = unit + template[1:] if template.startswith('u') else template
    return params, ci, units


def _visible_range(tau: np.ndarray, avar_term: np.ndarray, avar_rest: np.ndarray,
                   s_ln: np.ndarray) -> tuple:
    """Taus where a term moves ln ADEV by more than s(tau): 0.5 ln(1 + x) > s."""
    lift = 0.5 * np.log1p(avar_term / np.maximum(avar_rest, 1e-300))
    vis = np.flatnonzero(lift > s_ln)
    if vis.size == 0:
        k = int(np.argmax(lift / s_ln))
        return (float(tau[k]), float(tau[k]))
    return (float(tau[vis[0]]), float(tau[vis[-1]]))


def _term_avar(tau: np.ndarray, fit: AxisFit, effect: str, params: dict) -> np.ndarray:
    term = TERMS[effect]
    nonlinear = [params[s] for s in term.nonlinear]
    coef = term.to_coef(params[term.symbols[0]], *nonlinear)
    return coef * term.shape(tau, *nonlinear)


def diagnose_axis(tau_s, avar, edf, rate_hz: float, n_samples: int, *,
                  raw=None, raw_rate_hz: float | None = None,
                  base_model: Sequence[str] = DEFAULT_BASE, axis: str = 'axis',
                  unit: str = 'unit', rng: np.random.Generator | None = None,
                  n_replicas: int = N_REPLICAS,
                  effects: Sequence[str] | None = None) -> AxisDiagnosis:
    """
    Diagnose one axis: fit, simulate, compare, name and add what is missing, repeat.

    Parameters
    ----------
    tau_s, avar, edf : array_like
        Shape (k,), the measured overlapping Allan curve: averaging times [s], AVAR
        [unit^2] and equivalent degrees of freedom.
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Samples behind the curve.
    raw : array_like, optional
        Shape (n,), raw (or block-averaged) samples of the axis for the periodogram
        check of a sinusoid; without them the sinusoid is named from the curve alone.
    raw_rate_hz : float, optional
        Rate of ``raw`` [Hz]; default ``rate_hz``.
    base_model : sequence of str
        Term names of the base model (default white, bias_instability, random_walk:
        the paper's model; see :func:`base_terms` for the old names).
    axis : str
        Axis name for the summary.
    unit : str
        Unit of the samples.
    rng : np.random.Generator, optional
        Random source of the simulation; default ``np.random.default_rng(0)``.
    n_replicas : int
        Simulated replicas per model.
    effects : sequence of str
        Effects that may be added, term names (the old bias_instability is read as
        flicker; default the search's own list,
        :data:`imu_allan.core.search.SEARCH_EFFECTS`, plus white noise or random walk
        where the base lacks them: with the default base the diagnosis ends at the model
        every analysis reports).

    Returns
    -------
    AxisDiagnosis
        The diagnosis.

    Raises
    ------
    InputError
        Unknown effect names, or a curve the fit cannot use.

    """
    rng = np.random.default_rng(0) if rng is None else rng
    base_labels = base_terms(base_model)
    if effects is not None:
        effects = tuple(effect_name(e) for e in effects)
        for name in effects:
            if name not in EFFECTS:
                raise InputError(f'unknown effect {name!r}; known: {", ".join(EFFECTS)} '
                                 f'(old names: {", ".join(EFFECT_ALIASES)})')
    tau_all = np.asarray(tau_s, dtype=np.float64)
    avar_all = np.asarray(avar, dtype=np.float64)
    edf_all = np.asarray(edf, dtype=np.float64)
    # The same search as every analysis (one model); here each step is also simulated.
    # Effects are added in core/search/run.py, _Run.forward (screen, then choose: a
    # sinusoid must also pass the periodogram check, core/search/rules.py).
    search = search_axis(tau_all, avar_all, edf_all, rate_hz, n_samples, raw=raw,
                         raw_rate_hz=raw_rate_hz, unit=unit, base_labels=base_labels,
                         effects=tuple(e for e in (_default_effects(base_labels) if effects
                                                   is None else effects)
                                       if e not in base_labels),
                         keep_steps=True)
    fit0 = search.base
    # The comparison grid: the fit's taus (thinned to two per octave).
    idx = np.array([int(np.argmin(np.abs(tau_all - t))) for t in fit0.tau_s])
    tau, a_meas = tau_all[idx], avar_all[idx]
    adev = np.sqrt(a_meas)
    m = np.maximum(np.round(tau * rate_hz), 1).astype(np.int64)
    # The EDF of the curve rests on a noise type identified from the data, which is
    # erratic where few clusters remain (a flicker-PM guess at the last tau gives it
    # 20 times the EDF it has).  None of the model's terms beyond quantization has more
    # EDF than white FM, so the EDF is capped at the white-FM value (NIST SP 1065 /
    # Greenhall), which only widens s(tau).
    e_meas = np.minimum(edf_all[idx], edf_overlapping(0, m, int(n_samples)))
    s_ln = ln_adev_stderr(e_meas)

    def state_of(labels, fit) -> _State:
        sim = np.sqrt(simulate_fit_avar(fit, rate_hz, int(n_samples), m, rng, n_replicas))
        return _State(tuple(labels), fit, sim, gap(adev, sim, s_ln))

    first = state_of(fit0.terms, fit0)
    state = first
    gaps = [first.gap]
    findings: list[Finding] = []
    notes = [n for n in search.fit.notes if 'not confirm' in n or 'same periodogram' in n
             or 'rate_ramp' in n or 'cannot tell' in n or n.startswith('not trusted')]
    for step in search.steps:
        z = gap_z(adev, state.adev_sim, s_ln)
        bands = find_bands(tau, z)
        got = _effect_params(step.fit, step.effect, step.label, unit)
        if got is None:
            continue
        params, ci, units = got
        new = state_of(step.fit.terms, step.fit)
        term_avar = _term_avar(tau, step.fit, step.effect, params)
        rest = np.maximum(new.adev_sim ** 2 - term_avar, 1e-300)
        tau_range = _visible_range(tau, term_avar, rest, s_ln)
        in_band = [b for b in bands if b.tau_range_s[1] >= tau_range[0]
                   and b.tau_range_s[0] <= tau_range[1]]
        shape = max(in_band, key=lambda b: b.peak_z).shape if in_band else 'level'
        note = step.evidence + (f'; rival: {step.rival}' if step.rival else '')
        findings.append(Finding(step.effect, params, ci, units, tau_range, shape, state.gap,
                                new.gap, float(step.chi2_drop), note))
        state = new
        gaps.append(new.gap)
    bands_before = find_bands(tau, gap_z(adev, first.adev_sim, s_ln))
    bands_after = find_bands(tau, gap_z(adev, state.adev_sim, s_ln))
    if search.fit.model_consistent is False and not findings:
        desc = '; '.join(f'{b.shape} {b.sign} at {b.tau_range_s[0]:.3g}-'
                         f'{b.tau_range_s[1]:.3g} s' for b in bands_before)
        notes.append('the base model disagrees with the data' + (f' ({desc})' if desc else '')
                     + ' but no listed effect is supported')
    diag = AxisDiagnosis(
        axis=axis, unit=unit, base_terms=fit0.terms, terms=state.labels,
        missing=tuple(findings), gap_before=first.gap, gap_after=state.gap,
        gaps=tuple(gaps), tau_s=tau, adev=adev, s_ln=s_ln, adev_before=first.adev_sim,
        adev_after=state.adev_sim, bands_before=bands_before, bands_after=bands_after,
        chi2_before=float(first.fit.chi2), chi2_after=float(search.fit.chi2),
        dof=int(search.fit.dof), fit_before=first.fit, fit_after=search.fit,
        notes=tuple(notes))
    return replace(diag, summary=summary_line(diag))


def diagnose_curve(curve: AllanCurve, n_samples: int, *, raw=None,
                   raw_rate_hz: float | None = None,
                   base_model: Sequence[str] = DEFAULT_BASE, seed: int = 0,
                   n_replicas: int = N_REPLICAS, axes: Sequence[str] = AXES,
                   duration_s: float | None = None, source: str = '',
                   warnings: Sequence[str] = ()) -> DiagnoseResult:
    """
    Diagnose every axis of a six-axis Allan curve.

    Parameters
    ----------
    curve : AllanCurve
        Overlapping curve with one column per name in ``axes``.
    n_samples : int
        Samples behind the curve.
    raw : array_like, optional
        Shape (n, len(axes)), raw or block-averaged samples (periodogram check).
    raw_rate_hz : float, optional
        Rate of ``raw`` [Hz]; default the curve's rate.
    base_model : sequence of str
        Base-model effect names (see :func:`diagnose_axis`).
    seed : int
        Seed of the simulation (each axis gets its own spawned generator).
    n_replicas : int
        Simulated replicas per model.
    axes : sequence of str
        Names of the curve's columns (default the six contract axes).
    duration_s : float, optional
        Record duration [s]; default n_samples / rate.
    source : str
        What was diagnosed.
    warnings : sequence of str
        Input warnings to carry along.

    Returns
    -------
    DiagnoseResult
        The diagnosis of every axis (None where an axis cannot be fitted).

    """
    if curve.method != 'overlapping':
        raise InputError(f'diagnose needs an overlapping Allan curve, got {curve.method}')
    avar = np.asarray(curve.avar).reshape(curve.tau_s.size, -1)
    edf = np.asarray(curve.edf).reshape(curve.tau_s.size, -1)
    if avar.shape[1] != len(axes):
        raise InputError(f'the curve has {avar.shape[1]} columns but {len(axes)} axis names')
    raw_arr = None if raw is None else np.asarray(raw, dtype=np.float64).reshape(-1, len(axes))
    children = np.random.SeedSequence(seed).spawn(len(axes))
    out: dict[str, AxisDiagnosis | None] = {}
    for j, axis in enumerate(axes):
        ok = np.isfinite(avar[:, j]) & (avar[:, j] > 0)
        if np.count_nonzero(ok) < 3:
            out[axis] = None
            continue
        try:
            out[axis] = diagnose_axis(
                curve.tau_s[ok], avar[ok, j], edf[ok, j], curve.rate_hz, n_samples,
                raw=None if raw_arr is None else raw_arr[:, j], raw_rate_hz=raw_rate_hz,
                base_model=base_model, axis=axis, unit=AXIS_UNITS.get(axis, 'unit'),
                rng=np.random.default_rng(children[j]), n_replicas=n_replicas)
        except InputError as exc:
            if 'unknown' in str(exc) or 'base model' in str(exc):
                raise
            out[axis] = None
    return DiagnoseResult(
        axes=out, rate_hz=float(curve.rate_hz), n_samples=int(n_samples),
        duration_s=float(duration_s if duration_s is not None else n_samples / curve.rate_hz),
        base_model=base_terms(base_model), n_replicas=int(n_replicas),
        raw_checked=raw is not None, source=source, warnings=tuple(warnings))


def diagnose_session(session, raw: RawKeeper | None = None, *,
                     base_model: Sequence[str] = DEFAULT_BASE, seed: int = 0,
                     n_replicas: int = N_REPLICAS, source: str = '') -> DiagnoseResult | None:
    """
    Diagnose the current data of a pipeline session (the node's ~/diagnose service).

    Parameters
    ----------
    session : imu_allan.pipeline.Session
        Any object with ``curve(confidence)``, ``stats.n_used``, ``duration_s`` and
        ``warnings`` (duck-typed: the core does not import the pipeline).
    raw : RawKeeper, optional
        Bounded copy of the samples fed to the session (the periodogram check of a
        sinusoid); without it a sinusoid is named from the Allan curve only.
    base_model : sequence of str
        Base-model effect names.
    seed : int
        Seed of the simulation.
    n_replicas : int
        Simulated replicas per model.
    source : str
        What was diagnosed.

    Returns
    -------
    DiagnoseResult or None
        None while the session has no Allan curve with at least 3 taus yet.

    """
    curve = session.curve(confidence=0.95)
    if curve is None or curve.tau_s.size < 3:
        return None
    # A duck-typed session may leave out rate_hz when the copy knows its own rate.
    raw_samples, raw_rate = raw_evidence(raw, getattr(session, 'rate_hz', None))
    return diagnose_curve(curve, int(session.stats.n_used), raw=raw_samples,
                          raw_rate_hz=raw_rate, base_model=base_model, seed=seed,
                          n_replicas=n_replicas, duration_s=float(session.duration_s),
                          source=source, warnings=tuple(session.warnings))
