"""
The model's own curve: simulated replicas of a fitted model (paper eqs. 14-23).

The terms of the paper's state-space model (registry flag ``state_space``: white
noise, the Gauss-Markov and random-walk states) run through
:func:`imu_allan.core.noise.simulate.simulate_state_space`, the way the seed paper
validates its model; every other fitted term (the sensor's filter, flicker,
quantization, ramp, sinusoids) is added by its registry entry's ``simulate``.  Part of
:mod:`imu_allan.core.diagnose`.
"""

import numpy as np

from imu_allan.core.allan.kernels import overlapping_avar
from imu_allan.core.fit.result import AxisFit
from imu_allan.core.noise.simulate import simulate_state_space
from imu_allan.core.noise.terms import base_name, noise_from_terms, TERMS

#: Default number of simulated replicas.
N_REPLICAS = 8


def fit_instances(fit: AxisFit) -> list:
    """
    Return the fitted terms as (label, term name, parameters), from the fit's components.

    Parameters
    ----------
    fit : AxisFit
        A fit; its ``components`` are (label, coefficient in SI, nonlinear parameters).

    Returns
    -------
    list of (str, str, dict)
        Each positive term's label, registry name and ``to_params`` dict (SI).

    """
    out = []
    for label, coef, phi in fit.components:
        term = TERMS[base_name(label)]
        out.append((label, term.name, term.to_params(coef, *phi)))
    return out


def simulate_fit_avar(fit: AxisFit, rate_hz: float, n_samples: int, m: np.ndarray,
                      rng: np.random.Generator, n_replicas: int = N_REPLICAS) -> np.ndarray:
    """
    Simulate a fitted model and return its replica-mean overlapping AVAR at sizes ``m``.

    Replicas are simulated two at a time to bound memory.

    Parameters
    ----------
    fit : AxisFit
        The fitted model (its ``components``).
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
    found = fit_instances(fit)
    states = noise_from_terms({lb: p for lb, name, p in found if TERMS[name].state_space})
    order = list(TERMS)
    rest = sorted(((name, p) for _, name, p in found if not TERMS[name].state_space),
                  key=lambda item: order.index(item[0]))
    n = int(n_samples)
    total = np.zeros(m.size)
    done = 0
    while done < n_replicas:
        r = min(2, n_replicas - done)
        y = simulate_state_space(states, rate_hz, n, rng, r).y
        for j in range(r):
            for name, params in rest:
                y[:, j] += TERMS[name].samples(params, rate_hz, n, rng)
        avar, _ = overlapping_avar(y, m)
        total += avar.sum(axis=1)
        done += r
    return total / n_replicas
