"""
The Allan variance of an axis model: the sum over the terms of the registry.

The closed forms live in :mod:`imu_allan.core.noise.shapes`, the terms in
:mod:`imu_allan.core.noise.terms` (:data:`TERMS`); both are re-exported here, so
``imu_allan.core.noise.model`` stays the one import for "the model".
"""

import numpy as np

from imu_allan.core.noise.shapes import _as_tau
from imu_allan.core.noise.terms import TERMS, terms_of
from imu_allan.core.noise.values import AxisNoise


def avar_terms(tau_s, noise: AxisNoise) -> dict[str, np.ndarray]:
    """
    Allan variance of every term present in an axis model.

    Names are the labels of :func:`imu_allan.core.noise.terms.terms_of`: the term's
    name ('white', 'flicker', 'bias_instability' for the Gauss-Markov floor with T_B,
    'gauss_markov' for a further one ...), numbered ('gauss_markov_1',
    'gauss_markov_2', ...) when a term occurs several times.

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
    for label, name, params in terms_of(noise):
        term = TERMS[name]
        nonlinear = [params[s] for s in term.nonlinear]
        coef = term.to_coef(params[term.symbols[0]], *nonlinear)
        out[label] = coef * term.shape(tau, *nonlinear)
    return out


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


_ROLE_TEXT = {'white': 'R (adds to S_N)', 'b_gm': 'state b_gm (S_B, T_B)',
              'b_rw': 'state b_rw (adds to S_K)', '': 'not in Q or R'}


def term_table() -> str:
    """
    Return the registry as a markdown table (docs/architecture.md shows it; tested).

    Returns
    -------
    str
        One row per entry of :data:`TERMS`: name, what it is, parameters with their
        unit templates, parameter-file keys, effect (and search order), Kalman role.

    """
    rows = ['| term | what | parameters | in parameter files | effect | Kalman |',
            '| --- | --- | --- | --- | --- | --- |']
    for name, t in TERMS.items():
        params = ', '.join(f'{s} [{u}]' for s, u in zip(t.symbols, t.units))
        keys = ', '.join(k.name for k in t.keys if k.name) or '-'
        listed = t.list_key or (name if t.read is None else '')
        files = f'list `{listed}`: {keys}' if listed else keys
        effect = 'no' if not t.effect else (
            'yes' if t.search_rank is None else f'yes, searched ({t.search_rank + 1})')
        rows.append(f'| `{name}` | {t.title} | {params} | {files} | {effect} | '
                    f'{_ROLE_TEXT[t.kalman]} |')
    return '\n'.join(rows) + '\n'
