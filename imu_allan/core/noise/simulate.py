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

The generators of the terms and their discretisation are in
:mod:`imu_allan.core.noise.generators`; which generator a term uses is its registry
entry's ``simulate`` (:mod:`imu_allan.core.noise.terms`).
"""

import math
from typing import NamedTuple

import numpy as np

from imu_allan import AXES
from imu_allan.core.noise.generators import _check_grid
from imu_allan.core.noise.terms import TERMS, terms_of
from imu_allan.core.noise.values import AxisNoise, NoiseSpec
from imu_allan.errors import InputError


def simulate_axis(noise: AxisNoise, rate_hz: float, n_samples: int,
                  rng: np.random.Generator) -> np.ndarray:
    """
    Simulate one axis as the sum of every term present in ``noise``.

    Each term instance is simulated by its registry entry's ``simulate``
    (:func:`imu_allan.core.noise.terms.terms_of`); B is the Gauss-Markov term
    bias_instability when T_B is set (the paper's model), otherwise flicker noise.
    Random numbers are drawn in the registry's order (white, Gauss-Markov terms,
    flicker, random walk, quantization, sinusoids), and only for terms that are present.

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
    _check_grid(rate_hz, n_samples)
    n = int(n_samples)
    y = np.full(n, float(noise.bias))
    for _, name, params in terms_of(noise):
        y += TERMS[name].samples(params, rate_hz, n, rng)
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
    from scipy.signal import lfilter    # on first use: reading models stays light

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
