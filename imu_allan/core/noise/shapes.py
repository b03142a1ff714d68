"""
Closed-form Allan variance of the IMU noise terms, and what the fit's covariance needs.

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
(pi 0.4365^2 T) (:attr:`imu_allan.core.noise.values.GaussMarkov.psd`), so its ADEV
peak is 0.664 B, the same floor as flicker noise of level B.

Besides the closed forms: each term's generalised covariance of the phase (the running
sum of the rate times dt, ``_gcov_*``), the reach and tail of its second-difference
covariance and its phase PSD, which the registry entries of
:mod:`imu_allan.core.noise.terms` carry for the fit's covariance of the curve.
"""

import math
from typing import Callable

import numpy as np

from imu_allan.core.noise.values import GM_PEAK_FACTOR

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


def gcov_gauss_markov(u_s: np.ndarray, T: float) -> np.ndarray:
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
