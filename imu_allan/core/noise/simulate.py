"""
Simulate IMU rate samples from a stochastic error model.

Two generators are provided:

* :func:`simulate_axis` sums independent generators, one per term of an
  :class:`~imu_allan.core.noise.params.AxisNoise` (white, Gauss-Markov, flicker, random
  walk, quantization, rate ramp, sinusoids, constant bias).  Each generator's Allan
  variance matches the closed form of its term (IEEE Std 952 annex C); the tests check
  every one against ``imu_allan.core.allan.overlapping_avar``.
* :func:`simulate_state_space` runs the discrete state-space model of the paper
  (Maia, Silva, De Lima, Meneses, eqs. 14-23, after Farrell): states
  [Gauss-Markov bias, random-walk bias], measurement = states + white noise.  It is the
  model a Kalman filter sees, and it is vectorised over Monte-Carlo replicas.

:func:`simulate_imu` draws a six-axis record from a
:class:`~imu_allan.core.noise.params.NoiseSpec`.  Everything is reproducible from a seed:
each axis gets its own child generator (``numpy.random.SeedSequence.spawn``), so
changing one axis' model leaves the other axes' samples unchanged.

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
from typing import NamedTuple

import numpy as np
import scipy.fft
from scipy.signal import lfilter

from imu_allan import AXES
from imu_allan.core.noise.params import AxisNoise, GaussMarkov, NoiseSpec
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


def simulate_axis(noise: AxisNoise, rate_hz: float, n_samples: int,
                  rng: np.random.Generator) -> np.ndarray:
    """
    Simulate one axis as the sum of every term present in ``noise``.

    B is a Gauss-Markov term with T_B when T_B is set (the paper's model), otherwise
    flicker noise; see the module docstring for each generator.  Random numbers are
    drawn in a fixed order (white, Gauss-Markov terms, flicker, random walk,
    quantization, sinusoids), and only for terms that are present.

    Parameters
    ----------
    noise : AxisNoise
        Error model of the axis, SI units.
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Number of samples.
    rng : np.random.Generator
        Random source, e.g. ``np.random.default_rng(seed)``.

    Returns
    -------
    np.ndarray
        Shape (n_samples,), rate samples [unit] (rad/s or m/s^2), including the
        constant bias.

    """
    dt = _check_grid(rate_hz, n_samples)
    n = int(n_samples)
    y = np.full(n, float(noise.bias))
    if noise.N > 0:
        y += white_noise(noise.N, rate_hz, n, rng)
    for gm in noise.all_gauss_markov():
        if gm.B > 0:
            y += gauss_markov_noise(gm, rate_hz, n, rng)
    if noise.has_flicker:
        y += flicker_noise(noise.B, rate_hz, n, rng)
    if noise.K > 0:
        y += random_walk_noise(noise.K, rate_hz, n, rng)
    if noise.Q > 0:
        y += quantization_noise(noise.Q, rate_hz, n, rng)
    if noise.R or noise.sinusoids:
        t_s = np.arange(n) * dt
        if noise.R:
            y += rate_ramp(noise.R, t_s)
        for s in noise.sinusoids:
            if s.A:
                y += sinusoid(s.A, s.f0_hz, t_s, rng)
    return y


def state_space_matrices(
        noise: AxisNoise, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """
    Discrete state-space model of one axis (paper eqs. 14-23, exact discretisation).

    States x = [b_GM, b_RW]: x_{k+1} = Phi x_k + w_k, w_k ~ N(0, Qd);
    y_k = H x_k + v_k, v_k ~ N(0, R).  With S_N = N^2, S_K = K^2 and S_B from paper
    eq. 8 (``GaussMarkov.psd``):
    Phi = diag(exp(-dt/T_B), 1),
    Qd = diag(S_B T_B / 2 (1 - exp(-2 dt / T_B)), S_K dt), H = [1, 1], R = S_N / dt.
    Note the decaying exponential: the paper's eq. 26/27 prints exp(+tau/T_B), which is
    a typo.  Each further Gauss-Markov term in ``noise.gauss_markov`` adds a state
    between b_GM and b_RW.  Without any Gauss-Markov term the b_GM state is kept with
    Phi = 1 and zero process noise (it stays 0), so the shape is always the paper's.
    Flicker, quantization, ramp, sinusoids and the constant bias are not part of this
    model.

    Parameters
    ----------
    noise : AxisNoise
        Error model, SI units; B > 0 needs T_B (flicker noise has no finite state).
    dt : float
        Sample period [s].

    Returns
    -------
    Phi : np.ndarray
        Shape (n_x, n_x), state transition [-].
    Qd : np.ndarray
        Shape (n_x, n_x), process noise covariance [unit^2].
    H : np.ndarray
        Shape (1, n_x), measurement matrix [-].
    R : np.ndarray
        Shape (1, 1), measurement noise variance [unit^2].

    """
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f'sample period must be positive, got {dt!r}')
    if noise.has_flicker:
        raise InputError('the state-space model needs T_B for B (flicker noise has no '
                         'finite-dimensional state)')
    gms = noise.all_gauss_markov()
    phis, qs = [], []
    for gm in gms:
        phis.append(math.exp(-dt / gm.T))
        qs.append(gm.psd * gm.T / 2.0 * -math.expm1(-2.0 * dt / gm.T))
    if not gms:
        phis.append(1.0)
        qs.append(0.0)
    phis.append(1.0)
    qs.append(noise.K ** 2 * dt)
    Phi = np.diag(phis)
    Qd = np.diag(qs)
    H = np.ones((1, len(phis)))
    R = np.array([[noise.N ** 2 / dt]])
    return Phi, Qd, H, R


class StateSpaceRun(NamedTuple):
    """
    Output of :func:`simulate_state_space`.

    Attributes
    ----------
    y : np.ndarray
        Shape (n_samples, n_replicas), measurements y_k [unit].
    x : np.ndarray
        Shape (n_samples, n_replicas, n_x), states x_k [unit] in the order of
        :func:`state_space_matrices` (b_GM ..., b_RW).

    """

    y: np.ndarray
    x: np.ndarray


def simulate_state_space(noise: AxisNoise, rate_hz: float, n_samples: int,
                         rng: np.random.Generator, n_replicas: int = 1) -> StateSpaceRun:
    """
    Run the paper's discrete state-space model (eqs. 14-23) for one axis.

    The Gauss-Markov states start from their stationary distribution N(0, S_B T_B / 2),
    the random-walk state from 0.  The diagonal recursions run with
    ``scipy.signal.lfilter`` along time, vectorised over replicas.

    Parameters
    ----------
    noise : AxisNoise
        Error model, SI units (see :func:`state_space_matrices`).
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Number of samples per replica.
    rng : np.random.Generator
        Random source.
    n_replicas : int
        Number of independent replicas.

    Returns
    -------
    StateSpaceRun
        y (n_samples, n_replicas) [unit] and x (n_samples, n_replicas, n_x) [unit].

    """
    dt = _check_grid(rate_hz, n_samples)
    if int(n_replicas) != n_replicas or n_replicas < 1:
        raise InputError(f'number of replicas must be a positive integer, got {n_replicas!r}')
    Phi, Qd, H, R = state_space_matrices(noise, dt)
    n, r, n_x = int(n_samples), int(n_replicas), Phi.shape[0]
    phi = np.diag(Phi)
    q_std = np.sqrt(np.diag(Qd))
    # Stationary std of each state: sqrt(q / (1 - phi^2)) for |phi| < 1, 0 at start else.
    x0_std = np.where(phi < 1.0, q_std / np.sqrt(np.maximum(1.0 - phi ** 2, 1e-300)), 0.0)
    x = np.empty((n, r, n_x))
    if n:
        for j in range(n_x):  # a handful of states: the loop is over states, not time
            e = rng.standard_normal((n, r))
            e[0] *= x0_std[j]
            e[1:] *= q_std[j]
            x[:, :, j] = lfilter([1.0], [1.0, -phi[j]], e, axis=0)
    y = x @ H[0] + rng.standard_normal((n, r)) * math.sqrt(R[0, 0])
    return StateSpaceRun(y=y, x=x)


def simulate_imu(spec: NoiseSpec, rate_hz: float, duration_s: float,
                 seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """
    Simulate a six-axis IMU record with :func:`simulate_axis`.

    Parameters
    ----------
    spec : NoiseSpec
        Error model of every axis, SI units.
    rate_hz : float
        Sample rate [Hz].
    duration_s : float
        Record length [s]; n = round(duration_s * rate_hz) samples.
    seed : int or None
        Seed of ``np.random.default_rng``; each axis uses its own spawned child
        generator, so one axis' model does not change another axis' samples.

    Returns
    -------
    t_s : np.ndarray
        Shape (n,), sample times k / rate_hz [s].
    samples : np.ndarray
        Shape (n, 6), rate samples in AXES order [rad/s, m/s^2].

    """
    _check_grid(rate_hz, 0)
    if not (isinstance(duration_s, (int, float, np.floating, np.integer))
            and math.isfinite(duration_s) and duration_s > 0):
        raise InputError(f'duration must be a positive number of seconds, got {duration_s!r}')
    n = int(round(duration_s * rate_hz))
    children = np.random.SeedSequence(seed).spawn(len(AXES))
    samples = np.empty((n, len(AXES)))
    for j, axis in enumerate(AXES):
        noise = spec.axes.get(axis, AxisNoise())
        samples[:, j] = simulate_axis(noise, rate_hz, n, np.random.default_rng(children[j]))
    return np.arange(n) / float(rate_hz), samples
