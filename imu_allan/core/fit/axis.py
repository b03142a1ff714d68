"""
Fit one axis: candidate terms, selection, intervals, bounds (the per-axis driver).

Part of :mod:`imu_allan.core.fit` (see its docstring for the method).
"""

from dataclasses import replace
from itertools import combinations
import math
from typing import NamedTuple, Sequence

import numpy as np

from imu_allan.core.allan.curve import AllanCurve
from imu_allan.core.allan.quantiles import chi2_ppf, chi2_sf, f_ppf
from imu_allan.core.fit.caps import curve_caps
from imu_allan.core.fit.criterion import criterion
from imu_allan.core.fit.nominal import nominal_fit
from imu_allan.core.fit.params import _CORE_TERMS, _estimates, _unsupported, bound_by_curve
from imu_allan.core.fit.result import AxisFit
from imu_allan.core.fit.solver import _design, fit_fixed_weights, Fitter, Slot, Solution
from imu_allan.core.noise.terms import base_name, noise_from_terms, TERMS
from imu_allan.core.rules import FILTER_MIN_TAU_SHARE, KEEP_PENALTY, P_CONSISTENT
from imu_allan.errors import InputError

#: Candidate terms when ``terms`` is not given; the fit keeps those the data support.
DEFAULT_TERMS = ('quantization', 'white', 'bias_instability', 'random_walk')
Z95 = 1.959963984540054


def term_slot(label: str, tau: np.ndarray, rate_hz: float) -> Slot:
    """
    Return a term label's slot: its registry entry and the search range over these taus.

    Parameters
    ----------
    label : str
        Term label, possibly numbered ('gauss_markov_2').
    tau : numpy.ndarray
        (k,) averaging times of the fit [s].
    rate_hz : float
        Sample rate [Hz].

    Returns
    -------
    Slot

    """
    term = TERMS[base_name(label)]
    if not term.nonlinear:
        return Slot(label, term, ())
    if term.bounds is None:
        raise InputError(f'no search range for the nonlinear parameters of term {label}')
    # The registry entry's search range (e.g. a Gauss-Markov bump inside the record).
    return Slot(label, term, tuple(term.bounds(tau, rate_hz)))


def n_params(slots: Sequence[Slot]) -> int:
    """Return the parameters of a model: one level plus the nonlinear ones per slot."""
    return sum(1 + len(s.bounds) for s in slots)


def _symbols(slots: Sequence[Slot]) -> dict:
    """Map every (label, symbol) pair of the candidate slots to its reported name."""
    out, used = {}, set()
    for s in slots:
        base = base_name(s.label)
        for sym in s.term.symbols:
            plain = TERMS[base].plain and s.label == base
            name = sym if plain and sym not in used else f'{s.label}.{sym}'
            used.add(name)
            out[(s.label, sym)] = name
    return out


def check_curve(tau, avar, edf, rate_hz, n_samples):
    """
    Return the usable points of a curve, sorted by tau.

    Parameters
    ----------
    tau, avar, edf : array_like
        (k,) averaging times [s], Allan variances [unit^2] and their EDF [-].
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Samples behind the curve.

    Returns
    -------
    tau, avar, edf : numpy.ndarray
        (k',) the finite points with positive variance and EDF, tau ascending.

    Raises
    ------
    InputError
        For arrays of different shapes, a bad rate or fewer than 4 samples.

    """
    tau = np.atleast_1d(np.asarray(tau, dtype=np.float64))
    avar = np.atleast_1d(np.asarray(avar, dtype=np.float64))
    edf = np.atleast_1d(np.asarray(edf, dtype=np.float64))
    if not (tau.shape == avar.shape == edf.shape and tau.ndim == 1):
        raise InputError('tau, avar and edf must be 1-D arrays of the same length, got '
                         f'{tau.shape}, {avar.shape}, {edf.shape}')
    if not (isinstance(rate_hz, (int, float, np.integer, np.floating))
            and math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
    if int(n_samples) != n_samples or n_samples < 4:
        raise InputError(f'number of samples must be an integer >= 4, got {n_samples!r}')
    ok = np.isfinite(tau) & np.isfinite(avar) & np.isfinite(edf) & (avar > 0) & (edf > 0)
    order = np.argsort(tau[ok])
    return tau[ok][order], avar[ok][order], edf[ok][order]


def thin(tau: np.ndarray, per_octave: float = 2.0) -> np.ndarray:
    """Return the indices that keep at most ``per_octave`` points per octave of tau."""
    keep, last = [], -np.inf
    for i, t in enumerate(np.log2(tau)):
        if t - last >= 1.0 / per_octave - 1e-9:
            keep.append(i)
            last = t
    return np.array(keep, dtype=np.int64)


class FilterCut(NamedTuple):
    """
    Where a sensor's filter stops bending a curve (:func:`filter_cut`).

    Attributes
    ----------
    first : int
        Index of the first tau past the bend [taus].
    ended : bool
        Whether the curve falls as steeply as white noise there (the bend seen to end),
        not only at the cut's limit.

    """

    first: int
    ended: bool


def filter_cut(tau: np.ndarray, avar: np.ndarray, rate_hz: float,
               edf: np.ndarray | None = None) -> FilterCut:
    """
    Return where to start fitting: past the leading taus bent by the sensor's filter.

    Real IMUs low-pass filter (anti-aliasing, decimation) before they output samples, so
    at the first few cluster sizes neighbouring samples are correlated and the curve is
    flatter than the white-noise slope of -1/2 (no noise term of the model does that:
    quantization is steeper).  Those points carry the largest EDF, so left in they
    would pull N below the density that matters at longer tau and recruit a fast
    Gauss-Markov term to bridge the bend.  Leading points whose ADEV slope to the next
    point is above -0.48 are dropped, at most those below 64 sample periods; a white
    record keeps them all (its slope noise there is ~0.003).  A term rising within the
    bend does not end it (a filter may act past the taus it visibly flattens).  A
    filter flattens the first step most: where the bend is not seen to end and that
    step is not flatter than white noise by twice its own noise (a short or slow
    record whose curve rises gently: the ADIS16405 as 1 Hz block means, slope
    -0.47 +- 0.024, flatter further out) nothing is left out.

    Parameters
    ----------
    tau : np.ndarray
        Shape (k,), averaging times [s], shortest first.
    avar : np.ndarray
        Shape (k,), Allan variance [unit^2].
    rate_hz : float
        Sample rate [Hz].
    edf : np.ndarray, optional
        Shape (k,), equivalent degrees of freedom of each point [-]: the first step's
        noise (without, the step is taken as exact).

    Returns
    -------
    FilterCut

    """
    first = 0
    slope = 0.5 * np.diff(np.log(avar)) / np.diff(np.log(tau))
    while (first < slope.size and tau[first] * rate_hz < 64.0 and slope[first] > -0.48
           and tau.size - first > 3):
        first += 1
    ended = bool(first < slope.size and slope[first] <= -0.48)
    if first and not ended and edf is not None:
        # Var ln AVAR = 2 / EDF per point (NIST SP 1065 sec. 5.3), their covariance
        # left out: an upper bound of the step's noise, so a doubt keeps the taus.
        noise = 0.5 * math.sqrt(2.0 / edf[0] + 2.0 / edf[1]) / math.log(tau[1] / tau[0])
        if slope[0] <= -0.5 + 2.0 * noise:
            return FilterCut(0, True)
    return FilterCut(first, ended)


def filter_identified(t_f_s: float, tau0_s: float, bounds: tuple) -> bool:
    """
    Whether the curve identifies a filter time constant T_f.

    The filter bends the Allan curve only at taus of the order of T_f: one far below
    the shortest fitted tau leaves no trace the fit can measure (a T_f of a 25th of
    the sample period, fitted to reshape the curve elsewhere, is a distortion, not a
    filter).  T_f must reach :data:`FILTER_MIN_TAU_SHARE` of the shortest fitted tau
    and stay clear of its search range's ends.
    """
    lo, hi = bounds
    return (t_f_s >= FILTER_MIN_TAU_SHARE * tau0_s and t_f_s > 1.05 * lo
            and t_f_s < hi / 1.05)


def fit_axis(curve_tau_s, avar, edf, rate_hz: float, n_samples: int, *,
             terms: Sequence[str] | None = None, unit: str = 'unit',
             method: str = 'overlapping', select: bool = True,
             phi0: dict | None = None, sigma0: np.ndarray | None = None) -> AxisFit:
    """
    Fit the noise model of one axis to its Allan curve (nominal and optimised).

    Parameters
    ----------
    curve_tau_s : array_like
        Shape (k,), averaging times [s], multiples of 1 / rate_hz.
    avar : array_like
        Shape (k,), overlapping Allan variance [unit^2].
    edf : array_like
        Shape (k,), equivalent degrees of freedom of each estimate (the nominal
        intervals and the first weights; the optimised fit then uses the model's own
        covariance).
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Number of samples the curve was computed from.
    terms : sequence of str, optional
        Candidate terms (names of :data:`imu_allan.core.noise.model.TERMS`, numbered for repeats:
        'gauss_markov', 'gauss_markov_2', 'sinusoid' ...).  Default
        :data:`DEFAULT_TERMS`.  The fit keeps the subset the data support.
    unit : str
        Unit of the samples ('rad/s', 'm/s^2'), used in the parameter units.
    method : str
        Estimator of the curve: 'overlapping' (exact covariance) or 'nonoverlapping'
        (overlapping correlations, variances from ``edf``).
    select : bool
        True: keep the subset of ``terms`` the data support (AIC over every subset).
        False: ``terms`` were already selected (:mod:`imu_allan.core.search`); fit them
        all, and report a term whose coefficient comes out zero as a bound; of several
        Gauss-Markov terms, the one with the largest B is then reported as B and T_B
        (with ``select`` True the fastest is, see :func:`_dominant_bias_instability`).
    phi0 : dict of str to tuple, optional
        Starting nonlinear parameters per term label (the search's values); a
        sinusoid's frequency then stays within 20 % of its start (a line the
        periodogram confirmed).
    sigma0 : np.ndarray, optional
        Shape (k, k), covariance of the thinned curve to start the re-weighting from
        (the search's last one, in the fit's scaled units), instead of the paper's
        diagonal weights.

    Returns
    -------
    AxisFit
        Nominal and optimised parameters with 95 % intervals, the selected model and
        notes.

    Raises
    ------
    InputError
        Mismatched arrays, a bad rate, an unknown term, or fewer than 3 usable taus.

    """
    return _fit_axis(curve_tau_s, avar, edf, rate_hz, n_samples, terms, unit, method,
                     select, phi0, sigma0)


def _fit_axis(curve_tau_s, avar, edf, rate_hz, n_samples, terms, unit, method,
              select=True, phi0=None, sigma0=None) -> AxisFit:
    """Body of :func:`fit_axis` (same arguments)."""
    tau, avar, edf = check_curve(curve_tau_s, avar, edf, rate_hz, n_samples)
    if method not in ('overlapping', 'nonoverlapping'):
        raise InputError(f'the fit needs an Allan curve (overlapping or nonoverlapping), '
                         f'got method {method!r}')
    candidates = tuple(DEFAULT_TERMS if terms is None else terms)
    for label in candidates:
        try:
            base_name(label)
        except KeyError:
            raise InputError(f'unknown noise term {label!r}; known: '
                             f'{", ".join(sorted(TERMS))}') from None
    if len(set(candidates)) != len(candidates):
        raise InputError('each term may appear once; number repeats, e.g. gauss_markov_2')
    nominal = nominal_fit(tau, avar, edf, unit)
    # The curve's own bounds of B and K read every point, not only the thinned ones
    # the fit weighs: a bound may lie above no point of the curve (the joint band).
    whole = (tau, avar, edf)
    keep = thin(tau)
    tau, avar, edf = tau[keep], avar[keep], edf[keep]
    notes: list[str] = []
    # With the filtered_white term the filter is part of the model, not cut away.
    cut = filter_cut(tau, avar, rate_hz, edf)
    filter_end_s = float(tau[cut.first]) if cut.ended else math.nan
    first = 0 if 'filtered_white' in candidates else cut.first
    if first:
        notes.append(f'tau < {tau[first]:.3g} s left out: flatter than white noise there '
                     "(the sensor's low-pass filter)")
        tau, avar, edf = tau[first:], avar[first:], edf[first:]
    if tau.size < 3:
        raise InputError(f'the fit needs at least 3 averaging times, got {tau.size}')
    dt = 1.0 / float(rate_hz)
    m = np.maximum(np.round(tau * rate_hz), 1).astype(np.int64)
    n_terms = np.maximum(int(n_samples) + 1 - 2 * m, 1)
    fitter = Fitter(tau, avar, edf, m, n_terms, dt, int(n_samples), method)
    slots_all = [term_slot(lbl, tau, rate_hz) for lbl in candidates]
    start = None
    if phi0:
        start = [tuple(phi0.get(s.label, [math.sqrt(lo * hi) for lo, hi in s.bounds]))
                 for s in slots_all]
        slots_all = [replace(s, bounds=((p[0] / 1.2, p[0] * 1.2),))
                     if s.term.name == 'sinusoid' and s.label in phi0 else s
                     for s, p in zip(slots_all, start)]
    symbols = _symbols(slots_all)

    full_sol, full_sigma, phi_full, supported = _select_terms(fitter, slots_all, start,
                                                              sigma0, select)
    # Values and intervals come from the supported terms plus the paper's core terms
    # (white, bias instability, random walk) even where the data do not support them:
    # a weak random walk dropped from the fit would push B and T_B up and make their
    # intervals too narrow.  Other unsupported candidates (quantization, say) are left
    # out, since keeping them only blurs N.  The selection decides what is reported as
    # an estimate and what as an upper bound.
    slots = [s for s in slots_all if s.label in supported or s.term.name in _CORE_TERMS]
    if len(slots) == len(slots_all):
        sol, sigma = full_sol, full_sigma
        fitter.data.set_sigma(sigma)
    else:
        sol, sigma = fitter.irls(slots, phi0=[phi_full[s.label] for s in slots],
                                 sigma0=full_sigma)
    # J at exactly these weights (from the search's model: a polish, not a new search).
    sol = fit_fixed_weights(fitter.data, slots, sol.phi, local=start is not None)
    relabelled = (_dominant_bias_instability(slots, sol, fitter.data.scale) if not select
                  else slots)
    swap = {a.label: b.label for a, b in zip(slots, relabelled) if a.label != b.label}
    supported = {swap.get(lb, lb) for lb in supported}
    slots = relabelled
    chi2_value = float(sol.j)
    dof = int(tau.size - n_params(slots))
    threshold = profile_threshold(chi2_value, dof)

    pinned: list[str] = []
    optimised, values = _estimates(fitter, slots, sol, supported, threshold, symbols, unit,
                                   notes, pinned)

    _unsupported(fitter, slots_all, slots, sol, supported, candidates, terms is not None,
                 symbols, unit, optimised, notes)
    past = whole[0] >= tau[0]
    caps = curve_caps(whole[0][past], whole[1][past], whole[2][past], filter_end_s)
    optimised = bound_by_curve(optimised, caps, notes)
    if dof > 0 and chi2_sf(chi2_value, dof) < P_CONSISTENT:
        notes.append(f'the model does not explain the curve (chi2 {chi2_value:.1f} for '
                     f'{dof} dof): a missing effect? (imu-allan diagnose)')
    order = ['N', 'B', 'T_B', 'K']
    rest = sorted(k for k in optimised if k not in order)
    optimised = {k: optimised[k] for k in order + rest}
    # The model keeps the core terms reported as bounds at their point estimates: it is
    # the curve the data support best, e.g. for simulation and diagnosis.
    for i, s in enumerate(slots):
        if s.label not in values and s.term.name in _CORE_TERMS:
            values[s.label] = s.term.to_params(sol.coef[i] * fitter.data.scale, *sol.phi[i])
    avar_fit = _design(slots, tau, sol.phi) @ sol.coef * fitter.data.scale
    components = tuple((s.label, float(c * fitter.data.scale), tuple(p))
                       for s, c, p in zip(slots, sol.coef, sol.phi) if c > 0)
    return AxisFit(nominal=nominal, optimised=optimised, model=noise_from_terms(values),
                   terms=tuple(s.label for s in slots if s.label in supported),
                   notes=tuple(notes), chi2=chi2_value, dof=dof, tau_s=tau,
                   avar_fit=avar_fit, avar_sd=np.sqrt(np.diag(sigma)) * fitter.data.scale,
                   avar_meas=avar, edf=edf, components=components, pinned=tuple(pinned),
                   caps=caps, filter_end_s=filter_end_s)


def _select_terms(fitter, slots_all: list, start, sigma0, select: bool) -> tuple:
    """
    Fit the full candidate model, then every subset at its weights; keep the best.

    The criterion keeps a base term at 2 per parameter (AIC: :mod:`.criterion`).

    Returns the full model's solution and covariance, its nonlinear parameters by label
    and the set of labels the data support (all positive terms when not ``select``).
    """
    tau = fitter.data.tau
    if sigma0 is not None and np.shape(sigma0) != (tau.size, tau.size):
        sigma0 = None
    full_sol, full_sigma = fitter.irls(slots_all, phi0=start, sigma0=sigma0,
                                       local=start is not None)
    fitter.data.set_sigma(full_sigma)
    phi_full = dict(zip([s.label for s in slots_all], full_sol.phi))
    best = None
    if not select:
        kept = tuple(i for i, c in enumerate(full_sol.coef) if c > 0)
        best = (0.0, kept) if kept else None
    for r in range(1, len(slots_all) + 1 if select else 1):
        for subset in combinations(range(len(slots_all)), r):
            slots = [slots_all[i] for i in subset]
            if n_params(slots) >= tau.size:
                continue
            sol = fit_fixed_weights(fitter.data, slots, [phi_full[s.label] for s in slots])
            if np.any(sol.coef <= 0):
                continue  # a zero term: the same fit as a smaller subset
            ic = criterion(sol.j, n_params(slots), KEEP_PENALTY)
            if best is None or ic < best[0]:
                best = (ic, subset)
    if best is None:
        raise InputError('no noise term fits this curve (all coefficients zero)')
    return full_sol, full_sigma, phi_full, {slots_all[i].label for i in best[1]}


def profile_threshold(chi2_value: float, dof: int) -> float:
    """Rise of the GLS chi-square that bounds a 95 % profile interval."""
    # Sigma is the model's own covariance of the curve (checked against Monte Carlo in
    # test_fit.py), so the scale is known and the threshold is the chi-square quantile
    # (likelihood-ratio interval, Bates & Watts 1988).  Where the model fits worse than
    # that covariance allows (J / dof > 1: an effect the model lacks, or a Sigma too
    # small because it was evaluated at an estimate whose long-tau points run low), the
    # observed dispersion scales the threshold up, with the F quantile for a dispersion
    # that is itself estimated.
    dispersion = chi2_value / dof if dof > 0 else 0.0
    if dispersion > 1.0:
        return f_ppf(0.95, 1, dof) * dispersion
    else:
        return chi2_ppf(0.95, 1)


def _dominant_bias_instability(slots: list, sol: Solution, scale: float) -> list:
    """
    Give the label 'bias_instability' (B, T_B) to the Gauss-Markov term with the largest B.

    Interchangeable Gauss-Markov terms are fitted in order of their correlation time (the
    solver keeps the first label the fastest, so profiles cannot swap their roles).  The
    paper's B is the floor of the curve, so the term reported as B and T_B is the one
    with the highest ADEV peak (0.664 B, paper eq. 8); the others are reported as further
    Gauss-Markov processes.  Only labels move: positions, order and values stay.
    """
    family = [i for i, s in enumerate(slots)
              if s.term.name in ('bias_instability', 'gauss_markov')]
    bias = [i for i in family if slots[i].term.name == 'bias_instability']
    if len(family) < 2 or not bias:
        return slots
    level = {i: slots[i].term.to_params(sol.coef[i] * scale, *sol.phi[i])['B'] for i in family}
    top = max(family, key=lambda i: level[i])
    if top == bias[0]:
        return slots
    out = list(slots)
    a, b = bias[0], top
    out[a] = replace(slots[a], label=slots[b].label, term=slots[b].term)
    out[b] = replace(slots[b], label=slots[a].label, term=slots[a].term)
    return out


def fit_curve(curve: AllanCurve, axis_index: int, n_samples: int | None = None, *,
              terms: Sequence[str] | None = None, unit: str | None = None) -> AxisFit:
    """
    Fit one axis of an :class:`~imu_allan.core.allan.AllanCurve` (batch or streaming).

    Parameters
    ----------
    curve : AllanCurve
        The curve; ``curve.method`` must be 'overlapping' or 'nonoverlapping'.
    axis_index : int
        Column of ``curve.avar`` to fit.
    n_samples : int, optional
        Number of samples behind the curve; default from the shortest tau's term count
        (n_terms + 2 m - 1 for the overlapping estimator, (n_terms + 1) m otherwise).
    terms : sequence of str, optional
        Candidate terms, see :func:`fit_axis`.
    unit : str, optional
        Unit of the samples; default from ``imu_allan.AXIS_UNITS`` when the curve has
        the six contract axes, else 'unit'.

    Returns
    -------
    AxisFit
        See :func:`fit_axis`.

    """
    from imu_allan import AXES, AXIS_UNITS

    avar = np.asarray(curve.avar)
    if avar.ndim == 1:
        avar = avar[:, None]
    edf = np.asarray(curve.edf)
    if edf.ndim == 1:
        edf = edf[:, None]
    if not 0 <= axis_index < avar.shape[1]:
        raise InputError(f'axis index {axis_index} outside 0..{avar.shape[1] - 1}')
    if curve.method not in ('overlapping', 'nonoverlapping'):
        raise InputError(f'the fit needs an Allan curve (overlapping or nonoverlapping), '
                         f'got a {curve.method} curve')
    if n_samples is None:
        m0, n0 = int(np.asarray(curve.m)[0]), int(np.asarray(curve.n_terms)[0])
        n_samples = n0 + 2 * m0 - 1 if curve.method == 'overlapping' else (n0 + 1) * m0
    if unit is None:
        unit = AXIS_UNITS[AXES[axis_index]] if avar.shape[1] == len(AXES) else 'unit'
    return fit_axis(curve.tau_s, avar[:, axis_index], edf[:, axis_index], curve.rate_hz,
                    n_samples, terms=terms, unit=unit, method=curve.method)
