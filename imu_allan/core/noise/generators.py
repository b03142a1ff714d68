"""
The generators of the noise terms: one function per term, samples of one axis.

Each registry entry of :mod:`imu_allan.core.noise.terms` simulates its term with one
of these; each generator's Allan variance matches the closed form of its term (IEEE Std
952 annex C); the tests check every one against ``imu_allan.core.allan.overlapping_avar``.
scipy is imported on first use, so reading parameter files stays light.

Discretisation (exact, paper eqs. 18-23 with the exact forms; sample period dt)
----------------------------------------------------------------------------------
* white: v_k ~ N(0, S_N / dt) with S_N = N^2, i.e. std N sqrt(rate_hz).
* Gauss-Markov (driving PSD S_B, paper eq. 8, correlation time T):
  x_{k+1} = exp(-dt/T) x_k + w_k, var w_k = S_B T / 2 (1 - exp(-2 dt / T));
  x_0 ~ N(0, S_B T / 2) (stationary start, so no warm-up transient).
* random walk: x_{k+1} = x_k + w_k, var w_k = S_K dt with S_K = K^2; x_0 = 0.
* flicker (1/f, used for B when T_B is not set): Kasdin's fractional integration
  (N. J. Kasdin, Proc. IEEE 83(5), 1995): x = h * w with h_0 = 1,
  h_k = h_{k-1} (k - 1/2) / k (alpha = 1), computed by FFT convolution in
  O(n log n).  Scaling: the filter's one-sided PSD is
  S_y(f) = 2 sigma_w^2 dt / (2 sin(pi f dt)) ~= sigma_w^2 / (pi f) for f << rate.
  Flicker FM with S_y = h_-1 / f has AVAR = 2 ln2 h_-1 (NIST SP 1065 table 5) and
  the IEEE Std 952 floor 2 ln2 B^2 / pi needs h_-1 = B^2 / pi, so sigma_w = B,
  independent of the sample rate.  Check: the replica-mean AVAR of the simulation
  equals 2 ln2 B^2 / pi (ADEV 0.664 B) within 4.5 standard errors from m = 16 to n / 8
  (test_simulate.py); at m = 1 and 2 the discrete filter's extra high-frequency power
  lifts the ADEV by 20 % and 7 %.
* quantization: white *phase* (angle) noise theta_k ~ N(0, Q^2) differenced,
  y_k = (theta_{k+1} - theta_k) / dt.  Its overlapping AVAR is exactly
  <(theta_{k+2m} - 2 theta_{k+m} + theta_k)^2> / (2 tau^2) = 3 Q^2 / tau^2
  (IEEE Std 952 C.1) at every tau = m dt.  This is the statistical model of the
  quantizer, not a rounding of the signal: rounding would couple the term to the
  other terms' values and is left out on purpose.
* rate ramp R t, sinusoid A sin(2 pi f0 t + phi) with phi uniform in [0, 2 pi).

Time runs from t_0 = 0 with t_k = k dt.

Point sampling: the Gauss-Markov, random-walk and flicker terms are the processes'
values at t_k (as in the paper's state-space model), not averages over each sample
interval.  At the shortest taus their AVAR therefore exceeds the continuous closed
form, e.g. by the factor 1 + 1 / (2 m^2) for the random walk (1.5 at tau = dt, 1.125
at 2 dt, below 1 % from m = 8); white, quantization, ramp and sinusoid terms match at
every m.  These terms are far below the white noise at such short taus in practice.
"""

import functools
import math

import numpy as np

from imu_allan.core.noise.values import GaussMarkov
from imu_allan.errors import InputError


def _check_grid(rate_hz: float, n_samples: int) -> float:
    """Validate the sample grid; return the sample period dt [s]."""
    if not (isinstance(rate_hz, (int, float, np.floating, np.integer))
            and math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
    if int(n_samples) != n_samples or n_samples < 0:
        raise InputError(f'number of samples must be a non-negative integer, got {n_samples!r}')
    return 1.0 / float(rate_hz)


def white_noise(N: float, rate_hz: float, n_samples: int,
                rng: np.random.Generator) -> np.ndarray:
    """
    White rate noise (angle / velocity random walk).

    Parameters
    ----------
    N : float
        Noise density [unit*s^0.5]; AVAR = N^2 / tau (IEEE Std 952 C.1).
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Number of samples.
    rng : np.random.Generator
        Random source.

    Returns
    -------
    np.ndarray
        Shape (n_samples,), samples [unit] with std N sqrt(rate_hz).

    """
    _check_grid(rate_hz, n_samples)
    return N * math.sqrt(rate_hz) * rng.standard_normal(int(n_samples))


def gauss_markov_noise(gm: GaussMarkov, rate_hz: float, n_samples: int,
                       rng: np.random.Generator, n_replicas: int | None = None) -> np.ndarray:
    """
    First-order Gauss-Markov process, exact discretisation, stationary start.

    Parameters
    ----------
    gm : GaussMarkov
        Level B [unit] (driving PSD ``gm.psd`` by paper eq. 8) and correlation time T [s].
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Number of samples.
    rng : np.random.Generator
        Random source.
    n_replicas : int or None
        None for one series; otherwise that many independent series.

    Returns
    -------
    np.ndarray
        Shape (n_samples,) or (n_samples, n_replicas), the process [unit].  Its
        variance is S_B T / 2 at every sample, its lag-1 correlation exp(-dt/T).

    """
    dt = _check_grid(rate_hz, n_samples)
    if not (gm.T > 0 and math.isfinite(gm.T)):
        raise InputError(f'Gauss-Markov correlation time must be positive, got {gm.T!r}')
    shape = (int(n_samples),) if n_replicas is None else (int(n_samples), int(n_replicas))
    if n_samples == 0:
        return np.zeros(shape)
    phi = math.exp(-dt / gm.T)
    # -expm1 keeps the digits of 1 - exp(-2 dt/T) when dt << T.
    w_std = math.sqrt(gm.psd * gm.T / 2.0 * -math.expm1(-2.0 * dt / gm.T))
    e = rng.standard_normal(shape)
    e[0] *= gm.sigma          # x_0 drawn from the stationary distribution
    e[1:] *= w_std            # w_{k-1} drives x_k
    from scipy.signal import lfilter

    return lfilter([1.0], [1.0, -phi], e, axis=0)


def random_walk_noise(K: float, rate_hz: float, n_samples: int,
                      rng: np.random.Generator) -> np.ndarray:
    """
    Rate random walk starting at 0.

    Parameters
    ----------
    K : float
        Random-walk density [unit/s^0.5]; AVAR = K^2 tau / 3 (IEEE Std 952 C.1).
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Number of samples.
    rng : np.random.Generator
        Random source.

    Returns
    -------
    np.ndarray
        Shape (n_samples,), samples [unit]; increments have variance K^2 dt.

    """
    dt = _check_grid(rate_hz, n_samples)
    out = np.zeros(int(n_samples))
    if n_samples > 1:
        np.cumsum(rng.standard_normal(int(n_samples) - 1) * (K * math.sqrt(dt)), out=out[1:])
    return out


def flicker_noise(B: float, rate_hz: float, n_samples: int,
                  rng: np.random.Generator) -> np.ndarray:
    """
    Flicker (1/f) rate noise by Kasdin's fractional integration (alpha = 1).

    Parameters
    ----------
    B : float
        Bias instability [unit]; the ADEV floor is sqrt(2 ln2 / pi) B = 0.664 B
        (IEEE Std 952 C.1).  The driving white noise has std B (module docstring).
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Number of samples.
    rng : np.random.Generator
        Random source.

    Returns
    -------
    np.ndarray
        Shape (n_samples,), samples [unit].

    """
    _check_grid(rate_hz, n_samples)
    n = int(n_samples)
    if n == 0:
        return np.zeros(0)
    import scipy.fft

    n_fft, h_spectrum = _kasdin_spectrum(n)
    w = rng.standard_normal(n) * B
    return scipy.fft.irfft(h_spectrum * scipy.fft.rfft(w, n_fft), n_fft)[:n]


@functools.lru_cache(maxsize=1)
def _kasdin_spectrum(n: int) -> tuple[int, np.ndarray]:
    """
    FFT length and spectrum of Kasdin's alpha = 1 filter for n samples.

    Cached: the six axes of one record share it.  The impulse response of
    (1 - z^-1)^(-1/2) is h_0 = 1, h_k = h_{k-1} (k - 1 + alpha/2) / k (Kasdin 1995).

    Parameters
    ----------
    n : int
        Number of samples.

    Returns
    -------
    n_fft : int
        FFT length >= 2 n - 1, so the FFT product is a linear (not circular) convolution.
    spectrum : np.ndarray
        Shape (n_fft // 2 + 1,), complex rfft of h zero-padded to n_fft (read-only).

    """
    import scipy.fft

    k = np.arange(1, n, dtype=np.float64)
    h = np.empty(n)
    h[0] = 1.0
    np.cumprod((k - 0.5) / k, out=h[1:])
    n_fft = scipy.fft.next_fast_len(2 * n - 1, real=True)
    spectrum = scipy.fft.rfft(h, n_fft)
    spectrum.flags.writeable = False
    return n_fft, spectrum


def quantization_noise(Q: float, rate_hz: float, n_samples: int,
                       rng: np.random.Generator) -> np.ndarray:
    """
    Quantization noise as differenced white phase noise.

    Parameters
    ----------
    Q : float
        Quantization coefficient [unit*s]; AVAR = 3 Q^2 / tau^2 (IEEE Std 952 C.1).
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Number of samples.
    rng : np.random.Generator
        Random source.

    Returns
    -------
    np.ndarray
        Shape (n_samples,), samples (theta_{k+1} - theta_k) rate_hz [unit], with
        theta ~ N(0, Q^2) white [unit*s].

    """
    _check_grid(rate_hz, n_samples)
    theta = rng.standard_normal(int(n_samples) + 1) * Q
    return np.diff(theta) * float(rate_hz)


def rate_ramp(R: float, t_s: np.ndarray) -> np.ndarray:
    """
    Deterministic rate ramp R t; AVAR = R^2 tau^2 / 2 (IEEE Std 952 C.1).

    Parameters
    ----------
    R : float
        Ramp slope [unit/s].
    t_s : np.ndarray
        Shape (n,), sample times [s].

    Returns
    -------
    np.ndarray
        Shape (n,), samples [unit].

    """
    return R * np.asarray(t_s, dtype=np.float64)


def sinusoid(A: float, f0_hz: float, t_s: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """
    Sinusoid A sin(2 pi f0 t + phi) with a uniformly random phase.

    AVAR = A^2 (sin^2(pi f0 tau) / (pi f0 tau))^2 averaged over the phase
    (IEEE Std 952 C.1).

    Parameters
    ----------
    A : float
        Amplitude [unit].
    f0_hz : float
        Frequency [Hz].
    t_s : np.ndarray
        Shape (n,), sample times [s].
    rng : np.random.Generator
        Random source (draws the phase).

    Returns
    -------
    np.ndarray
        Shape (n,), samples [unit].

    """
    phase = rng.uniform(0.0, 2.0 * math.pi)
    return A * np.sin(2.0 * math.pi * f0_hz * np.asarray(t_s, dtype=np.float64) + phase)


def filtered_white_noise(n_density: float, filter_s: float, rate_hz: float, n_samples: int,
                         rng: np.random.Generator) -> np.ndarray:
    """
    White noise of density N seen through a first-order filter, sampled by averaging.

    The filtered rate x is an Ornstein-Uhlenbeck process of time constant T and driving
    noise q^2 = N^2 / T^2 (DC gain 1); each output sample is its mean over the sample
    period h, as the ``filtered_white`` term of :data:`imu_allan.core.noise.model.TERMS`
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
    from scipy.signal import lfilter

    x = lfilter([1.0], [1.0, -a], np.concatenate(([x0], w[0, :-1])))
    return (t * (1.0 - a) * x + w[1]) / h
