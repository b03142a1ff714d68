"""
Diagnosis: where the fitted model and the measurement disagree, and what is missing.

The seed paper (Maia, Silva, De Lima, Meneses; its figures 2-5 and table 3) validates
a noise model by simulating its discrete state-space form (eqs. 14-23) and comparing
the simulated Allan deviation with the measured one.  This module closes that loop
for one axis at a time:

1. fit the base model (default: white noise, the paper's Gauss-Markov bias
   instability, random walk) with :func:`imu_allan.core.fit.fit_axis`;
2. simulate the fitted model (``n_replicas`` replicas: the state-space model of
   :func:`imu_allan.core.simulate.simulate_state_space` plus the generators of the terms it
   has no state for) and take the replica-mean Allan variance as the model's curve;
3. measure the **gap** (defined once, used everywhere)::

       z(tau) = (ln ADEV_meas(tau) - ln ADEV_model(tau)) / s(tau),
       gap = sqrt(mean over tau of z^2),

   where s(tau) = sqrt(psi_1(edf / 2)) / 2 is the standard deviation of ln ADEV of
   an estimate with ``edf`` equivalent degrees of freedom (AVAR ~ avar chi2_edf / edf,
   and Var ln(chi2_nu) = psi_1(nu / 2), the trigamma function; Johnson, Kotz &
   Balakrishnan, Continuous Univariate Distributions vol. 1, ch. 18).  About 1 means
   consistent; the replica mean adds its own spread, a factor sqrt(1 + 1/n_replicas)
   on a consistent gap.  The taus are those of the base fit (at most two per octave,
   leading taus bent by the sensor's low-pass filter left out, as in the fit);
4. find the tau bands where |z| > 2 (beyond 95 % confidence) and their shape
   ('level', 'slope', 'bump', 'oscillation');
5. try every effect not yet in the model (:data:`EFFECTS`), refit with it, and keep
   the one that lowers the penalised criterion most: the GLS chi-square of the fit
   plus ``ln(k)`` per parameter (BIC, k the number of fitted taus) plus a margin
   :data:`DELTA_MIN` that keeps clean data free of invented effects (calibrated with
   bench/diagnose_cases.py).  A sinusoid must also show as a peak in a periodogram of
   the raw samples near the fitted frequency (when raw samples are given);
6. re-simulate, report the gap before and after the step, and repeat until the model
   is consistent (gap <= :data:`GAP_OK` and the fit's chi-square acceptable) or
   nothing more is supported.

Effect names (DESIGN.md diagnose contract) and the fit terms behind them:
quantization (Q), white (N), bias_instability (flicker noise, B), gauss_markov (a
further first-order Gauss-Markov process, B and T), random_walk (K), rate_ramp (R),
sinusoid (A, f0_hz).  B follows the paper's convention (eq. 8, see noise_params).
"""

from dataclasses import dataclass, field, replace
import math
from typing import NamedTuple, Sequence

import numpy as np
from scipy.signal import lfilter
from scipy.special import polygamma

from imu_allan import AXES, AXIS_UNITS
from imu_allan.core.allan import AllanCurve, edf_overlapping, overlapping_avar
from imu_allan.core.evidence import RawKeeper
from imu_allan.core.fit import AxisFit, json_floats, json_num
from imu_allan.core.noise_params import AxisNoise
from imu_allan.core.search import EFFECT_TERM as _EFFECT_TERM, search_axis, SEARCH_EFFECTS
from imu_allan.core.simulate import (flicker_noise, quantization_noise, rate_ramp,
                                     simulate_state_space, sinusoid)
from imu_allan.errors import InputError

#: Effect names the diagnosis can report (DESIGN.md), in the order they are tried.
EFFECTS = ('quantization', 'white', 'bias_instability', 'gauss_markov', 'random_walk',
           'rate_ramp', 'sinusoid')
#: The paper's model: white noise, Gauss-Markov bias instability, random walk.
DEFAULT_BASE = ('white', 'gauss_markov', 'random_walk')
#: Fit term behind each name of the base model: 'gauss_markov' is the paper's
#: bias-instability Gauss-Markov term (B, T_B).
_BASE_TERM = dict(_EFFECT_TERM, gauss_markov='bias_instability')
#: Reported symbols of each effect (DESIGN.md) and the fit's symbols behind them.
_EFFECT_SYMBOLS = {'quantization': (('Q', 'Q'),), 'white': (('N', 'N'),),
                   'bias_instability': (('B', 'B'),),
                   'gauss_markov': (('B', 'B'), ('T', 'T')), 'random_walk': (('K', 'K'),),
                   'rate_ramp': (('R', 'R'),), 'sinusoid': (('A', 'A'), ('f0_hz', 'f0_hz'))}
#: Unit templates of the reported symbols ('u' = the sample unit).
_UNITS = {'Q': 'u*s', 'N': 'u*s^0.5', 'B': 'u', 'T': 's', 'K': 'u/s^0.5', 'R': 'u/s',
          'A': 'u', 'f0_hz': 'Hz'}
#: A gap at or below this (with an acceptable chi-square) is consistent: no search.
GAP_OK = 1.5
#: chi-square p-value below which the fit itself says the model misses something.
P_INCONSISTENT = 1e-3
#: |z| above this marks a tau as disagreeing (two-sided 95 %).
Z_BAND = 2.0
#: Default number of simulated replicas.
N_REPLICAS = 8


class Band(NamedTuple):
    """
    A range of averaging times where measurement and model disagree beyond 95 %.

    Attributes
    ----------
    tau_range_s : tuple of float
        (first, last) averaging time of the band [s].
    shape : str
        'level' (an offset of one sign), 'slope' (a tilt), 'bump' (a hump or dip inside
        the band) or 'oscillation' (the sign alternates).
    sign : str
        'above' when the measurement lies mostly above the model, else 'below'.
    peak_z : float
        Largest |z| in the band [-].

    """

    tau_range_s: tuple
    shape: str
    sign: str
    peak_z: float

    def to_json(self) -> dict:
        """Return the band as a JSON-ready dict."""
        return {'tau_range_s': [float(v) for v in self.tau_range_s], 'shape': self.shape,
                'sign': self.sign, 'peak_z': float(self.peak_z)}


class Finding(NamedTuple):
    """
    One missing effect that the diagnosis named and added.

    Attributes
    ----------
    effect : str
        One of :data:`EFFECTS`.
    params : dict of str to float
        The effect's parameters in SI (DESIGN.md symbols), e.g. {'A': .., 'f0_hz': ..}.
    ci95 : dict of str to tuple
        95 % interval of each parameter (the fit's profile interval; for a frequency
        checked against the periodogram, the peak +- one frequency bin).
    units : dict of str to str
        Unit of each parameter.
    tau_range_s : tuple of float
        Averaging times where the effect changes ln ADEV by more than s(tau) [s].
    shape : str
        Shape of the disagreement the effect explains (see :class:`Band`).
    gap_before : float
        Gap before the step [-].
    gap_after : float
        Gap after the step [-].
    delta_chi2 : float
        Drop of the GLS chi-square bought by the effect [-].
    note : str
        E.g. the periodogram check of a sinusoid.

    """

    effect: str
    params: dict
    ci95: dict
    units: dict
    tau_range_s: tuple
    shape: str
    gap_before: float
    gap_after: float
    delta_chi2: float
    note: str = ''

    def to_json(self) -> dict:
        """Return the DESIGN.md entry {effect, params, tau_range_s} plus details."""
        return {'effect': self.effect, 'params': {k: json_num(v) for k, v in self.params.items()},
                'ci95': {k: [json_num(v[0]), json_num(v[1])] for k, v in self.ci95.items()},
                'units': dict(self.units),
                'tau_range_s': [float(v) for v in self.tau_range_s], 'shape': self.shape,
                'gap_before': json_num(self.gap_before), 'gap_after': json_num(self.gap_after),
                'delta_chi2': json_num(self.delta_chi2), 'note': self.note}


@dataclass(frozen=True)
class AxisDiagnosis:
    """
    Diagnosis of one axis.

    Attributes
    ----------
    axis : str
        Axis name.
    unit : str
        Unit of the samples.
    base_terms : tuple of str
        Fit terms of the base model.
    terms : tuple of str
        Fit terms of the final model.
    missing : tuple of Finding
        Effects added, in order.
    gap_before, gap_after : float
        Gap of the base model and of the final model [-].
    gaps : tuple of float
        Gap after each step, starting with the base model's.
    tau_s : np.ndarray
        Shape (k,), averaging times of the comparison [s].
    adev : np.ndarray
        Shape (k,), measured Allan deviation [unit].
    s_ln : np.ndarray
        Shape (k,), standard error of ln ADEV, s(tau) [-].
    adev_before, adev_after : np.ndarray
        Shape (k,), simulated (replica-mean) ADEV of the base and the final model.
    bands_before, bands_after : tuple of Band
        Disagreement bands of the base and the final model.
    chi2_before, chi2_after : float
        GLS chi-square of the base and the final fit; ``dof`` the final fit's dof.
    dof : int
        Degrees of freedom of the final fit.
    fit_before, fit_after : AxisFit
        The base and the final fit.
    summary : str
        One line, e.g. 'gyro_z: missing sinusoid at 0.011 Hz (period 90 s, amplitude
        2.1e-4 rad/s); gap 7.9 -> 1.1'.
    notes : tuple of str
        Further remarks (rejected candidates, an unexplained disagreement).

    """

    axis: str
    unit: str
    base_terms: tuple
    terms: tuple
    missing: tuple
    gap_before: float
    gap_after: float
    gaps: tuple
    tau_s: np.ndarray
    adev: np.ndarray
    s_ln: np.ndarray
    adev_before: np.ndarray
    adev_after: np.ndarray
    bands_before: tuple
    bands_after: tuple
    chi2_before: float
    chi2_after: float
    dof: int
    fit_before: AxisFit = field(repr=False, default=None)
    fit_after: AxisFit = field(repr=False, default=None)
    summary: str = ''
    notes: tuple = ()

    @property
    def consistent(self) -> bool:
        """Whether the final model is consistent: its gap is at most GAP_OK."""
        return self.gap_after <= GAP_OK

    def to_json(self) -> dict:
        """Return the DESIGN.md axis entry (missing, gap_before, gap_after) plus details."""
        return {'missing': [f.to_json() for f in self.missing],
                'gap_before': json_num(self.gap_before), 'gap_after': json_num(self.gap_after),
                'gaps': [json_num(g) for g in self.gaps], 'consistent': bool(self.consistent),
                'base_terms': list(self.base_terms), 'terms': list(self.terms),
                'chi2_before': json_num(self.chi2_before), 'chi2_after': json_num(self.chi2_after),
                'dof': int(self.dof),
                'bands_before': [b.to_json() for b in self.bands_before],
                'bands_after': [b.to_json() for b in self.bands_after],
                'tau_s': json_floats(self.tau_s), 'adev': json_floats(self.adev),
                's_ln': json_floats(self.s_ln), 'adev_sim_before': json_floats(self.adev_before),
                'adev_sim_after': json_floats(self.adev_after),
                'params_after': self.fit_after.to_json()['params'] if self.fit_after else {},
                'summary': self.summary, 'notes': list(self.notes)}


@dataclass(frozen=True)
class DiagnoseResult:
    """
    Diagnosis of every axis of a record.

    Attributes
    ----------
    axes : dict of str to AxisDiagnosis or None
        Per axis; None where the axis cannot be fitted (frozen, too short).
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Samples behind the curve.
    duration_s : float
        Duration [s].
    base_model : tuple of str
        Base-model effect names.
    n_replicas : int
        Simulated replicas per model.
    raw_checked : bool
        True when raw samples were available for the periodogram check.
    source : str
        What was diagnosed.
    warnings : tuple of str
        Input warnings.

    """

    axes: dict
    rate_hz: float
    n_samples: int
    duration_s: float
    base_model: tuple
    n_replicas: int
    raw_checked: bool
    source: str = ''
    warnings: tuple = ()

    def summary_lines(self) -> list:
        """Return one line per axis (see :class:`AxisDiagnosis`)."""
        return [d.summary if d is not None else f'{a}: not diagnosed (no usable curve)'
                for a, d in self.axes.items()]

    def table_markdown(self) -> str:
        """Return the gap table (the paper's table 3: RMS error before and after)."""
        rows = ['| axis | base model gap | final gap | missing effects | gap per step |',
                '| --- | --- | --- | --- | --- |']
        for a, d in self.axes.items():
            if d is None:
                rows.append(f'| {a} | - | - | (not diagnosed) | - |')
                continue
            names = ', '.join(f.effect for f in d.missing) or 'none'
            steps = ' -> '.join(f'{g:.2f}' for g in d.gaps)
            rows.append(f'| {a} | {d.gap_before:.2f} | {d.gap_after:.2f} | {names} | '
                        f'{steps} |')
        return '\n'.join(rows) + '\n'

    def to_json(self) -> dict:
        """Return the diagnose JSON of DESIGN.md."""
        return {'source': self.source, 'sample_rate_hz': float(self.rate_hz),
                'n_samples': int(self.n_samples), 'duration_s': float(self.duration_s),
                'base_model': list(self.base_model), 'n_replicas': int(self.n_replicas),
                'raw_checked': bool(self.raw_checked),
                'gap_definition': 'RMS over tau of (ln ADEV_meas - ln ADEV_sim) / s(tau), '
                                  's = sqrt(trigamma(edf / 2)) / 2',
                'axes': {a: (d.to_json() if d is not None else None)
                         for a, d in self.axes.items()},
                'summary': self.summary_lines(), 'warnings': list(self.warnings)}


# ------------------------------------------------------------------------------ the gap


def ln_adev_stderr(edf) -> np.ndarray:
    """
    Return the standard error s(tau) of ln ADEV for ``edf`` degrees of freedom.

    AVAR_hat ~ AVAR chi2_nu / nu, so Var ln AVAR_hat = psi_1(nu / 2) (trigamma) and
    ln ADEV = ln AVAR / 2 has s = sqrt(psi_1(nu / 2)) / 2 (about 1 / sqrt(2 nu) for
    large nu).

    Parameters
    ----------
    edf : array_like
        Equivalent degrees of freedom, > 0.

    Returns
    -------
    np.ndarray
        s, same shape [-].

    """
    nu = np.maximum(np.asarray(edf, dtype=np.float64), 1e-3)
    return 0.5 * np.sqrt(polygamma(1, 0.5 * nu))


def gap_z(adev_meas, adev_model, s_ln) -> np.ndarray:
    """
    Return the normalised log residuals z = (ln ADEV_meas - ln ADEV_model) / s.

    Parameters
    ----------
    adev_meas, adev_model : array_like
        Shape (k,), measured and model Allan deviation [unit], > 0.
    s_ln : array_like
        Shape (k,), standard error of ln ADEV (:func:`ln_adev_stderr`).

    Returns
    -------
    np.ndarray
        Shape (k,), z [-].

    """
    return (np.log(adev_meas) - np.log(adev_model)) / np.asarray(s_ln, dtype=np.float64)


def gap(adev_meas, adev_model, s_ln) -> float:
    """
    Return the gap: RMS over tau of :func:`gap_z` (about 1 when model and data agree).

    Parameters
    ----------
    adev_meas, adev_model : array_like
        Shape (k,), measured and model Allan deviation [unit].
    s_ln : array_like
        Shape (k,), standard error of ln ADEV.

    Returns
    -------
    float
        The gap [-].

    """
    z = gap_z(adev_meas, adev_model, s_ln)
    return float(np.sqrt(np.mean(z * z)))


def find_bands(tau_s, z, threshold: float = Z_BAND) -> tuple:
    """
    Find the contiguous tau ranges where |z| > threshold, and the disagreement's shape.

    A single agreeing tau between two disagreeing ones does not split a band.  Shape:
    'oscillation' when z changes sign at least twice over the band's extent, 'bump'
    when the interior peak exceeds both ends by more than 2 (in z), 'slope' when a
    straight line in log tau changes by more than 2 across the band, else 'level'.

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s], increasing.
    z : array_like
        Shape (k,), normalised residuals (:func:`gap_z`).
    threshold : float
        |z| that marks disagreement.

    Returns
    -------
    tuple of Band
        The bands, in tau order.

    """
    tau = np.asarray(tau_s, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    bad = np.abs(z) > threshold
    for i in range(1, bad.size - 1):  # bridge single agreeing taus
        if not bad[i] and bad[i - 1] and bad[i + 1]:
            bad[i] = True
    bands = []
    i = 0
    while i < bad.size:
        if not bad[i]:
            i += 1
            continue
        j = i
        while j + 1 < bad.size and bad[j + 1]:
            j += 1
        lo, hi = max(i - 1, 0), min(j + 1, z.size - 1)
        seg = z[lo:hi + 1]
        core = z[i:j + 1]
        signs = np.sign(seg[np.abs(seg) > 1.0])
        changes = int(np.count_nonzero(np.diff(signs) != 0)) if signs.size > 1 else 0
        sign = 'above' if core.sum() >= 0 else 'below'
        x = np.log(tau[i:j + 1])
        a = np.abs(core)
        if changes >= 2:
            shape = 'oscillation'
        elif core.size >= 3 and a[1:-1].max() > max(a[0], a[-1]) + 2.0:
            shape = 'bump'
        elif core.size >= 2 and abs(np.polyfit(x, core, 1)[0] * (x[-1] - x[0])) > 2.0:
            shape = 'slope'
        else:
            shape = 'level'
        bands.append(Band((float(tau[i]), float(tau[j])), shape, sign, float(a.max())))
        i = j + 1
    return tuple(bands)


# -------------------------------------------------------------------- model & simulation

@dataclass(frozen=True)
class _Model:
    """A fitted model as the simulator sees it: state-space part plus the rest."""

    noise: AxisNoise
    flicker_b: float = 0.0
    filter_s: float = 0.0


def _model_from_fit(fit: AxisFit) -> _Model:
    """Fitted model; flicker and the sensor's filter are kept apart (AxisNoise has neither)."""
    noise = replace(fit.model, bias=0.0)
    filter_s = next((float(phi[0]) for label, _, phi in fit.components
                     if label == 'filtered_white'), 0.0)
    flicker = 0.0
    if noise.B > 0 and not noise.T_B:   # B without T_B is flicker (model.noise_from_terms)
        flicker, noise = noise.B, replace(noise, B=0.0, T_B=None)
    return _Model(noise, float(flicker), filter_s)


def filtered_white_noise(n_density: float, filter_s: float, rate_hz: float, n_samples: int,
                         rng: np.random.Generator) -> np.ndarray:
    """
    White noise of density N seen through a first-order filter, sampled by averaging.

    The filtered rate x is an Ornstein-Uhlenbeck process of time constant T and driving
    noise q^2 = N^2 / T^2 (DC gain 1); each output sample is its mean over the sample
    period h, as the ``filtered_white`` term of :data:`imu_allan.core.model.TERMS`
    assumes.  Exact discretisation: with a = exp(-h/T), x' = a x + w1 and the integral
    I = T (1 - a) x + w2, where Var w1 = q^2 T (1 - a^2) / 2, Var w2 = q^2 T^2 (h -
    2 T (1 - a) + T (1 - a^2) / 2) and Cov(w1, w2) = q^2 T^2 (1 - a)^2 / 2.

    Parameters
    ----------
    n_density : float
        N [unit*s^0.5].
    filter_s : float
        T [s].
    rate_hz : float
        Output rate [Hz].
    n_samples : int
        Output samples.
    rng : np.random.Generator
        Random source.

    Returns
    -------
    np.ndarray
        Shape (n_samples,), samples [unit].

    """
    h, t = 1.0 / rate_hz, float(filter_s)
    a = math.exp(-h / t)
    q2 = n_density ** 2 / (t * t)
    v1 = q2 * t * (1.0 - a * a) / 2.0
    v2 = q2 * t * t * (h - 2.0 * t * (1.0 - a) + t * (1.0 - a * a) / 2.0)
    c12 = q2 * t * t * (1.0 - a) ** 2 / 2.0
    chol = np.linalg.cholesky(np.array([[v1, c12], [c12, v2]]) + 1e-300 * np.eye(2))
    w = chol @ rng.standard_normal((2, n_samples))
    x0 = rng.standard_normal() * math.sqrt(q2 * t / 2.0)
    # x_k at the start of each sample period: x_0 stationary, x_{k+1} = a x_k + w1_k.
    x = lfilter([1.0], [1.0, -a], np.concatenate(([x0], w[0, :-1])))
    return (t * (1.0 - a) * x + w[1]) / h


def simulate_model_avar(model: _Model, rate_hz: float, n_samples: int, m: np.ndarray,
                        rng: np.random.Generator, n_replicas: int = N_REPLICAS) -> np.ndarray:
    """
    Simulate a model and return its replica-mean overlapping AVAR at cluster sizes ``m``.

    The white, Gauss-Markov and random-walk part runs through the paper's state-space
    model (:func:`imu_allan.core.simulate.simulate_state_space`, eqs. 14-23); flicker,
    quantization, ramp and sinusoids are added with their generators.  Replicas are
    simulated two at a time to bound memory.

    Parameters
    ----------
    model : _Model
        The model.
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Samples per replica (the measured record's length).
    m : np.ndarray
        Shape (k,), cluster sizes [samples].
    rng : np.random.Generator
        Random source.
    n_replicas : int
        Number of replicas.

    Returns
    -------
    np.ndarray
        Shape (k,), mean AVAR over the replicas [unit^2].

    """
    noise = model.noise
    white = 0.0
    if model.filter_s > 0:
        white, noise = noise.N, replace(noise, N=0.0)
    total = np.zeros(m.size)
    done = 0
    t_s = None
    while done < n_replicas:
        r = min(2, n_replicas - done)
        y = simulate_state_space(noise, rate_hz, n_samples, rng, r).y
        for j in range(r):
            if white > 0:
                y[:, j] += filtered_white_noise(white, model.filter_s, rate_hz, n_samples, rng)
            if model.flicker_b > 0:
                y[:, j] += flicker_noise(model.flicker_b, rate_hz, n_samples, rng)
            if noise.Q > 0:
                y[:, j] += quantization_noise(noise.Q, rate_hz, n_samples, rng)
            if noise.R or noise.sinusoids:
                if t_s is None:
                    t_s = np.arange(n_samples) / float(rate_hz)
                if noise.R:
                    y[:, j] += rate_ramp(noise.R, t_s)
                for s in noise.sinusoids:
                    if s.A:
                        y[:, j] += sinusoid(s.A, s.f0_hz, t_s, rng)
        avar, _ = overlapping_avar(y, m)
        total += avar.sum(axis=1)
        done += r
    return total / n_replicas


# ----------------------------------------------------------------------------- the loop

class _State(NamedTuple):
    labels: tuple
    fit: AxisFit
    model: _Model
    adev_sim: np.ndarray
    gap: float


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
    for out_sym, fit_sym in _EFFECT_SYMBOLS[effect]:
        p = _fit_symbol(fit, label, fit_sym)
        if p is None:
            return None
        params[out_sym] = float(p.value)
        ci[out_sym] = (float(p.ci95[0]), float(p.ci95[1]))
        template = _UNITS[out_sym]
        units[out_sym] = template if template in ('s', 'Hz') else unit + template[1:]
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
    from imu_allan.core.model import TERMS
    term = TERMS[_EFFECT_TERM[effect]]
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
        Effect names of the base model (default white, gauss_markov, random_walk:
        the paper's model; 'gauss_markov' there is the bias-instability term B, T_B).
    axis : str
        Axis name for the summary.
    unit : str
        Unit of the samples.
    rng : np.random.Generator, optional
        Random source of the simulation; default ``np.random.default_rng(0)``.
    n_replicas : int
        Simulated replicas per model.
    effects : sequence of str
        Effects that may be added (default the search's own list,
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
    for name in tuple(base_model) + tuple(effects or ()):
        if name not in _BASE_TERM:
            raise InputError(f'unknown effect {name!r}; known: {", ".join(EFFECTS)}')
    if not base_model:
        raise InputError('the base model needs at least one term')
    base_labels = tuple(dict.fromkeys(_BASE_TERM[b] for b in base_model))
    tau_all = np.asarray(tau_s, dtype=np.float64)
    avar_all = np.asarray(avar, dtype=np.float64)
    edf_all = np.asarray(edf, dtype=np.float64)
    # The same search as every analysis (one model); here each step is also simulated.
    search = search_axis(tau_all, avar_all, edf_all, rate_hz, n_samples, raw=raw,
                         raw_rate_hz=raw_rate_hz, unit=unit, base_labels=base_labels,
                         effects=tuple(e for e in (_default_effects(base_model) if effects
                                                   is None else effects)
                                       if e not in base_model),
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
        model = _model_from_fit(fit)
        sim = np.sqrt(simulate_model_avar(model, rate_hz, int(n_samples), m, rng, n_replicas))
        return _State(tuple(labels), fit, model, sim, gap(adev, sim, s_ln))

    first = state_of(fit0.terms, fit0)
    state = first
    gaps = [first.gap]
    findings: list[Finding] = []
    notes = [n for n in search.fit.notes if 'not confirm' in n or 'same periodogram' in n
             or 'rate_ramp' in n]
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


def _finding_text(f: Finding) -> str:
    p, u = f.params, f.units
    if f.effect == 'sinusoid':
        return (f'sinusoid at {p["f0_hz"]:.2g} Hz (period {1.0 / p["f0_hz"]:.3g} s, '
                f'amplitude {p["A"]:.2g} {u["A"]})')
    if f.effect == 'gauss_markov':
        return (f'a further Gauss-Markov process (B {p["B"]:.2g} {u["B"]}, '
                f'T {p["T"]:.3g} s)')
    if f.effect == 'bias_instability':
        return f'flicker bias instability (B {p["B"]:.2g} {u["B"]})'
    if f.effect == 'quantization':
        return f'quantization (Q {p["Q"]:.2g} {u["Q"]})'
    if f.effect == 'white':
        return f'white noise (N {p["N"]:.2g} {u["N"]})'
    if f.effect == 'random_walk':
        return f'rate random walk (K {p["K"]:.2g} {u["K"]})'
    return f'rate ramp (R {p["R"]:.2g} {u["R"]})'


def summary_line(d: AxisDiagnosis) -> str:
    """
    Return the axis' line, e.g. 'gyro_z: missing sinusoid at 0.011 Hz (...); gap 7.9 -> 1.1'.

    Parameters
    ----------
    d : AxisDiagnosis
        The diagnosis.

    Returns
    -------
    str
        The line.

    """
    gaps = f'gap {d.gap_before:.2g} -> {d.gap_after:.2g}'
    if d.missing:
        what = ' + '.join(_finding_text(f) for f in d.missing)
        tail = '' if d.consistent else ' (still inconsistent)'
        return f'{d.axis}: missing {what}; {gaps}{tail}'
    if d.consistent:
        return f'{d.axis}: nothing missing, the base model is consistent; gap {d.gap_before:.2g}'
    bands = ', '.join(f'{b.shape} {b.sign} at {b.tau_range_s[0]:.3g}-{b.tau_range_s[1]:.3g} s'
                      for b in d.bands_before)
    return (f'{d.axis}: base model inconsistent (gap {d.gap_before:.2g}'
            + (f'; {bands}' if bands else '') + ') but no listed effect is supported')


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
    out = {}
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
            if 'unknown effect' in str(exc) or 'base model' in str(exc):
                raise
            out[axis] = None
    return DiagnoseResult(
        axes=out, rate_hz=float(curve.rate_hz), n_samples=int(n_samples),
        duration_s=float(duration_s if duration_s is not None else n_samples / curve.rate_hz),
        base_model=tuple(base_model), n_replicas=int(n_replicas),
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
    raw_samples = raw_rate = None
    if raw is not None and raw.samples.shape[0] >= 16 and (raw.rate_hz or session.rate_hz):
        raw_samples = raw.samples
        raw_rate = (raw.rate_hz or float(session.rate_hz)) / raw.factor
    return diagnose_curve(curve, int(session.stats.n_used), raw=raw_samples,
                          raw_rate_hz=raw_rate, base_model=base_model, seed=seed,
                          n_replicas=n_replicas, duration_s=float(session.duration_s),
                          source=source, warnings=tuple(session.warnings))
