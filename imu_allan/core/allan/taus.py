"""
Cluster sizes and tau grids of the Allan estimators (octave, dense, all).

Part of :mod:`imu_allan.core.allan`.
"""

import math
from typing import Sequence

import numpy as np

from imu_allan.errors import InputError


#: Estimators of :func:`allan_curve`.
METHODS = ('overlapping', 'nonoverlapping', 'hadamard')

#: Named tau sets of :func:`tau_grid`.
TAU_KINDS = ('octave', 'dense', 'all')

#: Log-spaced points per decade of the 'dense' tau set.
DENSE_PER_DECADE = 10

# Order of the phase difference (d in Greenhall's notation) of each method.
_DIFF_ORDER = {'overlapping': 2, 'nonoverlapping': 2, 'hadamard': 3}


def _check_method(method: str) -> str:
    if method not in METHODS:
        raise InputError(f'unknown method {method!r}; expected one of {", ".join(METHODS)}')
    return method


def max_cluster_size(n_samples: int, method: str = 'overlapping') -> int:
    """
    Largest cluster size with at least one difference term.

    Parameters
    ----------
    n_samples : int
        Number of rate samples M.
    method : str
        'overlapping' or 'nonoverlapping' (M // 2: two clusters), or 'hadamard'
        (M // 3: three clusters).

    Returns
    -------
    int
        Largest m [samples]; 0 when the record is too short for any tau.

    """
    return int(n_samples) // (3 if _check_method(method) == 'hadamard' else 2)


def tau_grid(n_samples: int, kind: str, method: str = 'overlapping') -> np.ndarray:
    """
    Cluster sizes of a named tau set.

    Parameters
    ----------
    n_samples : int
        Number of rate samples M.
    kind : str
        'octave' (m = 1, 2, 4, ... as in the octave procedure of the Japanese text),
        'dense' (log-spaced, ``DENSE_PER_DECADE`` = 10 per decade, rounded to integers
        and deduplicated: 7 sizes below m = 10, 9 or 10 in every later decade; the
        streaming accumulator's exact taus use the same grid) or 'all' (every integer m;
        costs O(M) per tau, so O(M^2) in all).
    method : str
        'overlapping', 'nonoverlapping' or 'hadamard': sets the largest m
        (:func:`max_cluster_size`).

    Returns
    -------
    np.ndarray
        Shape (k,), int64 cluster sizes [samples], increasing; empty when the record is
        too short for any tau.

    """
    m_max = max_cluster_size(n_samples, method)
    if kind == 'octave':
        if m_max < 1:
            return np.zeros(0, dtype=np.int64)
        return 2 ** np.arange(int(math.log2(m_max)) + 1, dtype=np.int64)
    if kind == 'dense':
        if m_max < 1:
            return np.zeros(0, dtype=np.int64)
        n_pts = int(math.floor(DENSE_PER_DECADE * math.log10(m_max) + 1e-9)) + 1
        m = np.round(10.0 ** (np.arange(n_pts) / DENSE_PER_DECADE)).astype(np.int64)
        return np.unique(m[m <= m_max])
    if kind == 'all':
        return np.arange(1, m_max + 1, dtype=np.int64)
    raise InputError(f'unknown tau set {kind!r}; expected octave, dense, all or a list of '
                     'tau values in seconds')


def cluster_sizes(taus: str | Sequence[float] | np.ndarray, n_samples: int,
                  rate_hz: float, method: str = 'overlapping') -> np.ndarray:
    """
    Cluster sizes for a named tau set or for explicit tau values.

    Parameters
    ----------
    taus : str or sequence of float
        A kind of :func:`tau_grid`, or tau values [s]; these are rounded to the nearest
        cluster size ``round(tau_s * rate_hz)``, sorted and deduplicated.
    n_samples : int
        Number of rate samples M.
    rate_hz : float
        Sample rate [Hz].
    method : str
        'overlapping', 'nonoverlapping' or 'hadamard'.

    Returns
    -------
    np.ndarray
        Shape (k,), int64 cluster sizes [samples], increasing.

    Raises
    ------
    InputError
        A tau that rounds outside 1 .. :func:`max_cluster_size`, or an unknown kind.

    """
    if isinstance(taus, str):
        return tau_grid(n_samples, taus, method)
    tau_s = np.atleast_1d(np.asarray(taus, dtype=np.float64))
    if tau_s.ndim != 1 or tau_s.size == 0:
        raise InputError('tau values must be a non-empty list of numbers [s]')
    m_max = max_cluster_size(n_samples, method)
    m_float = np.round(tau_s * rate_hz)
    bad = ~np.isfinite(m_float) | (m_float < 1) | (m_float > m_max)
    if bad.any():
        t = tau_s[bad][0]
        raise InputError(
            f'tau {t:g} s is outside the range {1.0 / rate_hz:g} .. {m_max / rate_hz:g} s '
            f'that {n_samples} samples at {rate_hz:g} Hz allow for the {method} variance')
    return np.unique(m_float.astype(np.int64))


def terms_count(m: np.ndarray, n_samples: int, method: str = 'overlapping') -> np.ndarray:
    """
    Count the squared differences summed at each cluster size.

    Parameters
    ----------
    m : np.ndarray
        Shape (k,), cluster sizes [samples].
    n_samples : int
        Number of rate samples M.
    method : str
        'overlapping' (M + 1 - 2m), 'nonoverlapping' (M // m - 1) or 'hadamard'
        (M + 1 - 3m), NIST SP 1065 eqs. 12, 14, 20.

    Returns
    -------
    np.ndarray
        Shape (k,), int64 counts.

    """
    m = np.asarray(m, dtype=np.int64)
    if _check_method(method) == 'nonoverlapping':
        return n_samples // m - 1
    return n_samples + 1 - _DIFF_ORDER[method] * m


def _as_2d(y: np.ndarray) -> tuple[np.ndarray, bool]:
    y = np.asarray(y, dtype=np.float64)
    if y.ndim == 1:
        return y[:, None], True
    if y.ndim != 2:
        raise InputError(f'samples must be 1-D or 2-D, got shape {y.shape}')
    return y, False


def _check_m(m: np.ndarray, n: int, method: str) -> np.ndarray:
    m = np.asarray(m, dtype=np.int64).reshape(-1)
    m_max = max_cluster_size(n, method)
    if m.size and (m.min() < 1 or m.max() > m_max):
        raise ValueError(f'cluster sizes must lie in 1..{m_max} for {n} samples ({method})')
    return m


def dense_m_grid(max_m: int, per_decade: int) -> np.ndarray:
    """
    Log-spaced cluster sizes, ``per_decade`` per decade, rounded and deduplicated.

    Parameters
    ----------
    max_m : int
        Largest cluster size [samples].
    per_decade : int
        Grid points per decade of tau.

    Returns
    -------
    np.ndarray
        Shape (k,), int64 cluster sizes 1 .. max_m [samples], ascending.

    """
    n = int(np.floor(per_decade * np.log10(max_m) + 1e-9)) + 1
    m = np.round(10.0 ** (np.arange(n) / per_decade)).astype(np.int64)
    return np.unique(m[m <= max_m])
