"""
Closed-form Allan variance of the IMU noise terms, and the term registry of the fit.

Each term's Allan variance is linear in one variance-like coefficient ``c`` (the
*linear coefficient*) times a shape function of tau that may depend on a nonlinear
parameter (a correlation time, a frequency).  IEEE Std 952-1997 annex C, with the
first-order Gauss-Markov form of the paper (Maia, Silva, De Lima, Meneses, eqs. 8 and
26-27, sign of the exponent corrected, see :func:`avar_gauss_markov`):

===================  =================  ==============================================
term                 coefficient c      AVAR(tau)
===================  =================  ==============================================
quantization         Q^2  [unit^2 s^2]  3 Q^2 / tau^2
white                N^2 = S_N          N^2 / tau
flicker (B, no T_B)  B^2  [unit^2]      2 ln2 B^2 / pi          (ADEV 0.664 B)
Gauss-Markov         q^2 = S_B          (q T)^2 / tau (1 - T / (2 tau) (3 - 4 e^(-tau/T)
                                        + e^(-2 tau/T)))        (peak 0.4365 q sqrt(T)
                                        at tau = 1.89 T)
random walk          K^2 = S_K          K^2 tau / 3
rate ramp            R^2  [unit^2/s^2]  R^2 tau^2 / 2
sinusoid             A^2  [unit^2]      A^2 (sin^2(pi f0 tau) / (pi f0 tau))^2
===================  =================  ==============================================

B convention (paper eq. 8, the one used everywhere in imu_allan): the Gauss-Markov
term with level B and correlation time T has driving PSD S_B = 2 B^2 ln2 /
(pi 0.4365^2 T) (:attr:`imu_allan.core.noise.params.GaussMarkov.psd`), so its ADEV peak
is 0.664 B, the same floor as flicker noise of level B.

The registry :data:`TERMS` also carries each term's generalised covariance of the
phase (the running sum of the rate times dt), which the fit uses to compute the
covariance between Allan estimates at different tau; see :class:`Term`.
"""

from dataclasses import dataclass
import math
import re
from typing import Callable

import numpy as np

from imu_allan.core import native
from imu_allan.core.noise.params import AxisNoise, GaussMarkov, GM_PEAK_FACTOR, Sinusoid

#: 2 ln2 / pi: flicker AVAR floor per unit B^2 (IEEE Std 952 C.1).
FLICKER_AVAR = 2.0 * math.log(2.0) / math.pi
#: tau of the Gauss-Markov ADEV peak in units of T (IEEE Std 952 C.1): 1.89.
GM_PEAK_TAU = 1.8926
#: Paper eq. 8 factor: S_B = GM_PSD_FACTOR B^2 / T.
GM_PSD_FACTOR = 2.0 * math.log(2.0) / (math.pi * GM_PEAK_FACTOR ** 2)


def _as_tau(tau_s) -> np.ndarray:
    """Return tau as a float array (any shape) [s]."""
    return np.asarray(tau_s, dtype=np.float64)


def avar_quantization(tau_s, Q: float) -> np.ndarray:
    """
    Quantization noise: AVAR = 3 Q^2 / tau^2 (IEEE Std 952 C.1).

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s].
    Q : float
        Quantization coefficient [unit*s].

    Returns
    -------
    np.ndarray
        Shape (k,), Allan variance [unit^2].

    """
    tau = _as_tau(tau_s)
    return 3.0 * Q ** 2 / tau ** 2


def avar_white(tau_s, N: float) -> np.ndarray:
    """
    White rate noise (angle / velocity random walk): AVAR = N^2 / tau (IEEE Std 952 C.1).

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s].
    N : float
        Noise density [unit*s^0.5].

    Returns
    -------
    np.ndarray
        Shape (k,), Allan variance [unit^2].

    """
    return N ** 2 / _as_tau(tau_s)


def avar_flicker(tau_s, B: float) -> np.ndarray:
    """
    Flicker (bias instability) noise: AVAR = 2 ln2 B^2 / pi (IEEE Std 952 C.1).

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s].
    B : float
        Bias instability [unit]; the ADEV floor is 0.664 B.

    Returns
    -------
    np.ndarray
        Shape (k,), Allan variance [unit^2], constant in tau.

    """
    return np.full(_as_tau(tau_s).shape, FLICKER_AVAR * B ** 2)


#: Taylor coefficients of h(x) / x^3 (highest power first), see :func:`_gm_shape`.
_GM_SERIES = np.array([(-1) ** n * (2.0 - 2.0 ** (n - 1)) / math.factorial(n)
                       for n in range(12, 2, -1)])


def _gm_shape(x: np.ndarray) -> np.ndarray:
    """
    Return h(x) / x^2 with h(x) = x - (3 - 4 e^-x + e^-2x) / 2, x = tau / T.

    AVAR_GM = q^2 T h(x) / x^2 (same formula as :func:`avar_gauss_markov`).  For small
    x the bracket cancels to x^3 / 3, so a Taylor series is used below x = 0.05:
    h(x) = sum_{n>=3} (-1)^n (2 - 2^(n-1)) x^n / n!.
    """
    x = np.asarray(x, dtype=np.float64)
    if native.LIB is not None:
        return native.gm_shape(x, _GM_SERIES)
    small = x < 0.05
    if small.all():  # long T: the series alone (a fit calls this very often)
        return _gm_series(x)
    xl = np.where(small, 1.0, x)
    e = np.exp(-xl)
    out = (xl - 1.5 + 2.0 * e - 0.5 * e * e) / (xl * xl)
    if small.any():
        out[small] = _gm_series(x[small])
    return out


def _gm_series(x: np.ndarray) -> np.ndarray:
    """Return h(x) / x^2 from its Taylor series (Horner, in place), x small."""
    acc = np.full(x.shape, _GM_SERIES[0])
    for c in _GM_SERIES[1:]:
        acc *= x
        acc += c
    return acc * x


def avar_gauss_markov(tau_s, q: float, T: float) -> np.ndarray:
    """
    First-order Gauss-Markov noise in the driving-PSD form (IEEE Std 952 C.1).

    AVAR = (q T)^2 / tau (1 - T / (2 tau) (3 - 4 exp(-tau/T) + exp(-2 tau/T))), for
    the PSD q^2 / (w^2 + 1/T^2).  The exponents are negative: the paper's eq. 26/27
    prints exp(+tau/T_B), a typo (compare eq. 6.66 of the Japanese text).  Limits:
    q^2 tau / 3 (random walk) for tau << T, q^2 T^2 / tau (white) for tau >> T; peak
    ADEV 0.4365 q sqrt(T) at tau = 1.89 T.

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s].
    q : float
        Driving noise density, q^2 = S_B [unit^2/s].
    T : float
        Correlation time [s].

    Returns
    -------
    np.ndarray
        Shape (k,), Allan variance [unit^2].

    """
    tau = _as_tau(tau_s)
    return q ** 2 * T * _gm_shape(tau / T)


def avar_random_walk(tau_s, K: float) -> np.ndarray:
    """
    Rate random walk: AVAR = K^2 tau / 3 (IEEE Std 952 C.1).

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s].
    K : float
        Random-walk density [unit/s^0.5].

    Returns
    -------
    np.ndarray
        Shape (k,), Allan variance [unit^2].

    """
    return K ** 2 * _as_tau(tau_s) / 3.0


def avar_rate_ramp(tau_s, R: float) -> np.ndarray:
    """
    Rate ramp: AVAR = R^2 tau^2 / 2 (IEEE Std 952 C.1).

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s].
    R : float
        Ramp slope [unit/s].

    Returns
    -------
    np.ndarray
        Shape (k,), Allan variance [unit^2].

    """
    return R ** 2 * _as_tau(tau_s) ** 2 / 2.0


def avar_sinusoid(tau_s, A: float, f0_hz: float) -> np.ndarray:
    """
    Sinusoid A sin(2 pi f0 t): AVAR = A^2 (sin^2(pi f0 tau) / (pi f0 tau))^2.

    IEEE Std 952 C.1; the ADEV peaks at 0.7246 A near tau = 0.371 / f0.

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s].
    A : float
        Amplitude [unit].
    f0_hz : float
        Frequency [Hz].

    Returns
    -------
    np.ndarray
        Shape (k,), Allan variance [unit^2].

    """
    u = math.pi * f0_hz * _as_tau(tau_s)
    return A ** 2 * (np.sin(u) ** 2 / u) ** 2


def _gcov_quantization(u_s: np.ndarray, T: float = 0.0) -> np.ndarray:
    # White phase (angle) noise of variance Q^2: a Kronecker delta at lag 0.
    return np.where(u_s == 0.0, 1.0, 0.0)


def _gcov_white(u_s: np.ndarray, T: float = 0.0) -> np.ndarray:
    # Brownian phase: E (X(t+u) - X(t))^2 = S_N |u|.
    return -0.5 * np.abs(u_s)


def _gcov_flicker(u_s: np.ndarray, T: float = 0.0) -> np.ndarray:
    # Flicker FM: phase spectrum ~ f^-3, generalised covariance u^2 ln|u| / (2 pi),
    # scaled so that the Allan variance is 2 ln2 B^2 / pi.
    a = np.abs(u_s)
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(a > 0.0, a * a * np.log(np.where(a > 0.0, a, 1.0)), 0.0) / (
            2.0 * math.pi)


def _gcov_gauss_markov(u_s: np.ndarray, T: float) -> np.ndarray:
    # Integrated Ornstein-Uhlenbeck rate (autocovariance S_B T / 2 e^(-|u|/T)):
    # -(T^2/2) (|u| + T e^(-|u|/T)), written as -(T^3/2) (e^-x - 1 + x), x = |u|/T, since
    # constants vanish under the stencils; the series avoids cancellation for x << 1.
    x = np.abs(np.atleast_1d(np.asarray(u_s, dtype=np.float64)))
    x *= 1.0 / T
    h = np.expm1(-x)
    h += x
    small = x < 1e-3
    if small.any():
        xs = x[small]
        h[small] = xs * xs * (0.5 - xs * (1.0 / 6.0 - xs / 24.0))
    h *= -0.5 * T ** 3
    return h.reshape(np.shape(u_s))


def _tail_gauss_markov(d: np.ndarray, m1: np.ndarray, m2: np.ndarray, dt: float,
                       T: float) -> np.ndarray:
    # Beyond the outermost stencil kink (d >= 0 lags further) only the exponential part
    # of the generalised covariance survives; its stencil sum factorises exactly into
    # -(T^3/2) e^(-d dt/T) (1 - e^(-m1 dt/T))^2 (1 - e^(-m2 dt/T))^2, free of the
    # cancellation a direct 9-term sum suffers when m dt << T.
    x = dt / T
    return -0.5 * T ** 3 * np.exp(-d * x) * np.expm1(-m1 * x) ** 2 * np.expm1(-m2 * x) ** 2


def _reach_gauss_markov(m1: np.ndarray, m2: np.ndarray, dt: float, T: float) -> np.ndarray:
    # e^-60: the exponential tail is negligible 60 T beyond the kinks.
    return np.full(np.shape(m1), 60.0 * T / dt)


def _reach_flicker(m1: np.ndarray, m2: np.ndarray, dt: float) -> np.ndarray:
    # gamma ~ lag^-2 beyond the kinks: 64 (m1 + m2) lags keep all but ~1e-5 of the sum.
    return 64.0 * (np.asarray(m1, dtype=np.float64) + m2)


def _w2(f_hz: float) -> float:
    return (2.0 * math.pi * f_hz) ** 2


# Two-sided PSDs of the phase X (running sum of the rate times dt) per unit coefficient,
# from the rate autocovariances c delta (white), c T/2 e^(-|u|/T) (Gauss-Markov), the
# integrated white c delta (random walk), flicker h_-1 / f with h_-1 = B^2 / pi one-sided,
# and white phase of variance c per sample (quantization).
_PSD_PHASE: dict[str, Callable[..., float]] = {
    'quantization': lambda f, dt: dt,
    'white': lambda f, dt: 1.0 / _w2(f),
    'flicker': lambda f, dt: 1.0 / (2.0 * math.pi * abs(f) * _w2(f)),
    'gauss_markov': lambda f, dt, T: 1.0 / ((_w2(f) + 1.0 / T ** 2) * _w2(f)),
    'random_walk': lambda f, dt: 1.0 / _w2(f) ** 2,
}


def _gcov_random_walk(u_s: np.ndarray, T: float = 0.0) -> np.ndarray:
    # Integrated Brownian rate: |u|^3 / 12 (AVAR K^2 tau / 3).
    a = np.abs(u_s)
    return a * a * a / 12.0


@dataclass(frozen=True)
class Term:
    """
    One noise term as the fit sees it: AVAR = c * shape(tau, nonlinear...).

    Attributes
    ----------
    name : str
        Base name (DESIGN.md effect names), e.g. 'white', 'gauss_markov'.
    symbols : tuple of str
        Symbols of the reported parameters, the linear one first (e.g. ('B', 'T')).
    nonlinear : tuple of str
        Names of the nonlinear parameters of ``shape`` (e.g. ('T',)), a suffix of
        ``symbols`` ('' entries are not allowed).
    shape : callable
        ``shape(tau_s (k,), *nonlinear) -> (k,)``: AVAR per unit coefficient.
    gcov : callable or None
        Generalised covariance of the phase per unit coefficient,
        ``gcov(u_s, *nonlinear)`` [s^2 per unit coefficient], such that
        Cov(sum a_i X(t_i), sum b_j X(s_j)) = c sum a_i b_j gcov(t_i - s_j) for
        stencils a, b that annihilate linear functions.  None for deterministic terms
        (ramp, sinusoid), whose spread the fit neglects.
    to_params : callable
        ``to_params(c, *nonlinear) -> dict`` of the reported parameters (SI).
    to_coef : callable
        Inverse of ``to_params`` for the linear parameter:
        ``to_coef(value, *nonlinear) -> c``.
    units : tuple of str
        Unit of each symbol with 'u' for the sample unit (rad/s or m/s^2).
    discrete : bool
        True when ``gcov`` is a Kronecker delta (lags are integers, no integration).
    reach : callable or None
        ``reach(m1, m2, dt, *nonlinear) -> lags``: how far beyond the outermost
        stencil kink the second-difference covariance of two cluster sizes is non-zero;
        None for polynomial covariances, which vanish there exactly.
    tail : callable or None
        ``tail(d, m1, m2, dt, *nonlinear)``: that covariance d >= 0 lags beyond the
        outermost kink in closed form (None: evaluate ``gcov`` directly).
    psd_phase : callable or None
        ``psd_phase(f_hz, dt, *nonlinear)``: two-sided PSD of the phase per unit
        coefficient [s^3 per unit coefficient], S_y(f) / (2 pi f)^2; used for the
        spread a sinusoid adds by beating with the noise.  None for deterministic terms.

    """

    name: str
    symbols: tuple[str, ...]
    nonlinear: tuple[str, ...]
    shape: Callable[..., np.ndarray]
    gcov: Callable[..., np.ndarray] | None
    to_params: Callable[..., dict]
    to_coef: Callable[..., float]
    units: tuple[str, ...]
    discrete: bool = False
    reach: Callable[..., np.ndarray] | None = None
    tail: Callable[..., np.ndarray] | None = None
    psd_phase: Callable[..., float] | None = None


def _gm_b(c: float, T: float) -> float:
    """Level B [unit] of a Gauss-Markov term with driving PSD c and time T (eq. 8)."""
    return math.sqrt(max(c, 0.0) * T / GM_PSD_FACTOR)


#: Every term the fit knows, by base name.  Adding a term is adding an entry here.
TERMS: dict[str, Term] = {
    'quantization': Term(
        'quantization', ('Q',), (), lambda tau: 3.0 / _as_tau(tau) ** 2,
        _gcov_quantization, lambda c: {'Q': math.sqrt(max(c, 0.0))},
        lambda v: v * v, ('u*s',), discrete=True, psd_phase=_PSD_PHASE['quantization']),
    'white': Term(
        'white', ('N',), (), lambda tau: 1.0 / _as_tau(tau), _gcov_white,
        lambda c: {'N': math.sqrt(max(c, 0.0))}, lambda v: v * v, ('u*s^0.5',),
        psd_phase=_PSD_PHASE['white']),
    'flicker': Term(
        'flicker', ('B',), (), lambda tau: np.full(_as_tau(tau).shape, FLICKER_AVAR),
        _gcov_flicker, lambda c: {'B': math.sqrt(max(c, 0.0))}, lambda v: v * v, ('u',),
        reach=_reach_flicker, psd_phase=_PSD_PHASE['flicker']),
    'gauss_markov': Term(
        'gauss_markov', ('B', 'T'), ('T',), lambda tau, T: T * _gm_shape(_as_tau(tau) / T),
        _gcov_gauss_markov, lambda c, T: {'B': _gm_b(c, T), 'T': T},
        lambda v, T: GM_PSD_FACTOR * v * v / T, ('u', 's'), reach=_reach_gauss_markov,
        tail=_tail_gauss_markov, psd_phase=_PSD_PHASE['gauss_markov']),
    'random_walk': Term(
        'random_walk', ('K',), (), lambda tau: _as_tau(tau) / 3.0, _gcov_random_walk,
        lambda c: {'K': math.sqrt(max(c, 0.0))}, lambda v: v * v, ('u/s^0.5',),
        psd_phase=_PSD_PHASE['random_walk']),
    'rate_ramp': Term(
        'rate_ramp', ('R',), (), lambda tau: _as_tau(tau) ** 2 / 2.0, None,
        lambda c: {'R': math.sqrt(max(c, 0.0))}, lambda v: v * v, ('u/s',)),
    'sinusoid': Term(
        'sinusoid', ('A', 'f0_hz'), ('f0_hz',),
        lambda tau, f0: (np.sin(math.pi * f0 * _as_tau(tau)) ** 2
                         / (math.pi * f0 * _as_tau(tau))) ** 2,
        None, lambda c, f0: {'A': math.sqrt(max(c, 0.0)), 'f0_hz': f0},
        lambda v, f0: v * v, ('u', 'Hz')),
}
#: White noise seen through the sensor's own low-pass filter (anti-aliasing, decimation):
#: first-order filtered white noise is a Gauss-Markov process of time constant T_f, so
#: its AVAR is the Gauss-Markov shape scaled to N^2, N^2 / tau (1 - T_f / (2 tau) (3 -
#: 4 exp(-tau/T_f) + exp(-2 tau/T_f))), white noise of density N for tau >> T_f.
#: T_f is a nuisance parameter of at most a few sample periods; N is the density the
#: filter passes at long tau, what a Kalman filter running at the output rate sees.
TERMS['filtered_white'] = Term(
    'filtered_white', ('N', 'T_f'), ('T_f',), lambda tau, T: _gm_shape(_as_tau(tau) / T) / T,
    lambda u, T: _gcov_gauss_markov(u, T) / (T * T),
    lambda c, T: {'N': math.sqrt(max(c, 0.0)), 'T_f': T}, lambda v, T: v * v,
    ('u*s^0.5', 's'), reach=_reach_gauss_markov,
    tail=lambda d, m1, m2, dt, T: _tail_gauss_markov(d, m1, m2, dt, T) / (T * T),
    psd_phase=lambda f, dt, T: _PSD_PHASE['gauss_markov'](f, dt, T) / (T * T))
#: 'bias_instability' is the paper's Gauss-Markov term with T_B (symbols B, T_B).
TERMS['bias_instability'] = Term(
    'bias_instability', ('B', 'T_B'), ('T_B',), TERMS['gauss_markov'].shape,
    _gcov_gauss_markov, lambda c, T: {'B': _gm_b(c, T), 'T_B': T},
    TERMS['gauss_markov'].to_coef, ('u', 's'), reach=_reach_gauss_markov,
    tail=_tail_gauss_markov, psd_phase=_PSD_PHASE['gauss_markov'])

_SUFFIX = re.compile(r'^(?P<base>[a-z_]+?)(?:_(?P<num>\d+))?$')


def base_name(term_name: str) -> str:
    """
    Return the registry name of a possibly numbered term ('gauss_markov_2' -> 'gauss_markov').

    Parameters
    ----------
    term_name : str
        A term name, optionally with a ``_<number>`` suffix.

    Returns
    -------
    str
        The key of :data:`TERMS`; KeyError when unknown.

    """
    if term_name in TERMS:
        return term_name
    match = _SUFFIX.match(term_name)
    if match and match.group('base') in TERMS:
        return match.group('base')
    raise KeyError(term_name)


def avar_terms(tau_s, noise: AxisNoise) -> dict[str, np.ndarray]:
    """
    Allan variance of every term present in an axis model.

    Names: 'quantization', 'white', 'bias_instability' (flicker when T_B is unset,
    otherwise the Gauss-Markov term with T_B), 'gauss_markov' (the further Gauss-Markov
    terms; 'gauss_markov_1', 'gauss_markov_2', ... when there are several),
    'random_walk', 'rate_ramp', 'sinusoid' (numbered the same way).

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s], > 0.
    noise : AxisNoise
        The axis model, SI units.

    Returns
    -------
    dict of str to np.ndarray
        Each present term's AVAR, shape (k,) [unit^2]; absent terms are left out.

    """
    tau = _as_tau(tau_s)
    out: dict[str, np.ndarray] = {}
    if noise.Q:
        out['quantization'] = avar_quantization(tau, noise.Q)
    if noise.N:
        out['white'] = avar_white(tau, noise.N)
    if noise.B:
        if noise.T_B:
            out['bias_instability'] = avar_gauss_markov(
                tau, GaussMarkov(noise.B, noise.T_B).q, noise.T_B)
        else:
            out['bias_instability'] = avar_flicker(tau, noise.B)
    out.update(_numbered('gauss_markov', [
        avar_gauss_markov(tau, gm.q, gm.T) for gm in noise.gauss_markov if gm.B]))
    if noise.K:
        out['random_walk'] = avar_random_walk(tau, noise.K)
    if noise.R:
        out['rate_ramp'] = avar_rate_ramp(tau, noise.R)
    out.update(_numbered('sinusoid', [
        avar_sinusoid(tau, s.A, s.f0_hz) for s in noise.sinusoids if s.A]))
    return out


def _numbered(name: str, curves: list[np.ndarray]) -> dict[str, np.ndarray]:
    """Name one curve ``name`` and several ``name_1``, ``name_2``, ..."""
    if len(curves) == 1:
        return {name: curves[0]}
    return {f'{name}_{i + 1}': c for i, c in enumerate(curves)}


def avar_model(tau_s, noise: AxisNoise) -> np.ndarray:
    """
    Allan variance of an axis model: the sum of :func:`avar_terms`.

    The terms are independent, so their Allan variances add (IEEE Std 952 C.1).

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s], > 0.
    noise : AxisNoise
        The axis model, SI units.

    Returns
    -------
    np.ndarray
        Shape (k,), Allan variance [unit^2].

    """
    tau = _as_tau(tau_s)
    total = np.zeros(tau.shape)
    for curve in avar_terms(tau, noise).values():
        total = total + curve
    return total


def adev_model(tau_s, noise: AxisNoise) -> np.ndarray:
    """
    Allan deviation of an axis model, sqrt(:func:`avar_model`).

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s], > 0.
    noise : AxisNoise
        The axis model, SI units.

    Returns
    -------
    np.ndarray
        Shape (k,), Allan deviation [unit].

    """
    return np.sqrt(avar_model(tau_s, noise))


def noise_from_terms(values: dict[str, dict[str, float]]) -> AxisNoise:
    """
    Build an AxisNoise from per-term parameter dicts (as reported by the fit).

    Parameters
    ----------
    values : dict of str to dict
        Term name (possibly numbered) -> {symbol: value} in SI, e.g.
        {'white': {'N': 1e-4}, 'bias_instability': {'B': 5e-5, 'T_B': 80.0}}.

    Returns
    -------
    AxisNoise
        The model; terms missing from ``values`` are absent.

    """
    kw: dict = {'gauss_markov': [], 'sinusoids': []}
    # T_B is read only when the Gauss-Markov level is positive.
    flicker_b, bias = 0.0, (0.0, 0.0)
    for name, p in values.items():
        base = base_name(name)
        if base == 'quantization':
            kw['Q'] = p['Q']
        elif base in ('white', 'filtered_white'):
            kw['N'] = p['N']
        elif base == 'flicker':
            flicker_b = p['B']
        elif base == 'bias_instability':
            bias = (p['B'], p['T_B'])
        elif base == 'gauss_markov':
            kw['gauss_markov'].append(GaussMarkov(p['B'], p['T']))
        elif base == 'random_walk':
            kw['K'] = p['K']
        elif base == 'rate_ramp':
            kw['R'] = p['R']
        elif base == 'sinusoid':
            kw['sinusoids'].append(Sinusoid(p['A'], p['f0_hz']))
    # AxisNoise has one B: a Gauss-Markov floor (B, T_B), or flicker (B, no T_B).  With
    # both, flicker takes B and the Gauss-Markov process joins the further ones.
    if bias[0] > 0 and flicker_b > 0:
        kw['gauss_markov'].insert(0, GaussMarkov(*bias))
        kw['B'] = flicker_b
    elif bias[0] > 0:
        kw['B'], kw['T_B'] = bias
    elif flicker_b > 0:
        kw['B'] = flicker_b
    kw['gauss_markov'] = tuple(kw['gauss_markov'])
    kw['sinusoids'] = tuple(kw['sinusoids'])
    return AxisNoise(**kw)
