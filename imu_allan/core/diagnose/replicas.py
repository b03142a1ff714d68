"""
The model's own curve: simulated replicas of a fitted model (paper eqs. 14-23).

Part of :mod:`imu_allan.core.diagnose`.
"""

from dataclasses import dataclass, replace
import math

import numpy as np
from scipy.signal import lfilter

from imu_allan.core.allan import overlapping_avar
from imu_allan.core.fit import AxisFit
from imu_allan.core.noise.params import AxisNoise
from imu_allan.core.noise.simulate import (flicker_noise, quantization_noise, rate_ramp,
                                           simulate_state_space, sinusoid)


#: Default number of simulated replicas.
N_REPLICAS = 8


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
    x = lfilter([1.0], [1.0, -a], np.concatenate(([x0], w[0, :-1])))
    return (t * (1.0 - a) * x + w[1]) / h


def simulate_model_avar(model: _Model, rate_hz: float, n_samples: int, m: np.ndarray,
                        rng: np.random.Generator, n_replicas: int = N_REPLICAS) -> np.ndarray:
    """
    Simulate a model and return its replica-mean overlapping AVAR at cluster sizes ``m``.

    The white, Gauss-Markov and random-walk part runs through the paper's state-space
    model (:func:`imu_allan.core.noise.simulate.simulate_state_space`, eqs. 14-23); flicker,
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
