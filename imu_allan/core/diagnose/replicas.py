"""
The model's own curve: simulated replicas of a fitted model.

Each fitted term (the fit's ``components``) is simulated by its registry entry's
``simulate`` (:mod:`imu_allan.core.noise.terms`): white noise, the sensor's filter,
the Gauss-Markov terms (exact discretisation, paper eqs. 18-23), flicker, random walk,
quantization, ramp and sinusoids.  Part of :mod:`imu_allan.core.diagnose`.
"""

import numpy as np

from imu_allan.core.allan import overlapping_avar
from imu_allan.core.fit import AxisFit
from imu_allan.core.noise.generators import filtered_white_noise  # noqa: F401
from imu_allan.core.noise.terms import base_name, TERMS

#: Default number of simulated replicas.
N_REPLICAS = 8


def fit_instances(fit: AxisFit) -> list:
    """
    Return the fitted terms as (term name, parameters) pairs, from the fit's components.

    Parameters
    ----------
    fit : AxisFit
        A fit; its ``components`` are (label, coefficient in SI, nonlinear parameters).

    Returns
    -------
    list of (str, dict)
        The registry name of each positive term and its ``to_params`` dict (SI).

    """
    out = []
    for label, coef, phi in fit.components:
        term = TERMS[base_name(label)]
        out.append((term.name, term.to_params(coef, *phi)))
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
    instances = fit_instances(fit)
    total = np.zeros(m.size)
    done = 0
    while done < n_replicas:
        r = min(2, n_replicas - done)
        y = np.zeros((int(n_samples), r))
        for j in range(r):
            for name, params in instances:
                y[:, j] += TERMS[name].simulate(params, rate_hz, int(n_samples), rng)
        avar, _ = overlapping_avar(y, m)
        total += avar.sum(axis=1)
        done += r
    return total / n_replicas
