"""
The variance kernels: Allan and Hadamard variances per cluster size.

Overlapping Allan (NIST SP 1065 eq. 14), non-overlapping (eq. 12) and overlapping
Hadamard (eq. 20) variances, normalised from the difference sums of :mod:`.sums`.
Part of :mod:`imu_allan.core.allan`.
"""

import os

import numpy as np

from imu_allan.core.allan.noise_id import _fill_unknown
from imu_allan.core.allan.sums import (_axis_work, _columns, _is_octave, _map_threads,
                                       _MAX_THREADS, _means, _workers)
from imu_allan.core.allan.taus import _as_2d, _check_m, _check_method, terms_count


def _normalise(sums: np.ndarray, m: np.ndarray, n_terms: np.ndarray,
               method: str) -> np.ndarray:
    # AVAR = sum / (2 m^2 n_terms), HVAR = sum / (6 m^2 n_terms) in units of y^2
    # (NIST SP 1065 eqs. 12, 14, 20 with x = tau0 X and tau = m tau0).
    scale = 6.0 if method == 'hadamard' else 2.0
    mf = m.astype(np.float64)
    return sums / (scale * mf * mf * n_terms.astype(np.float64))[:, None]


def _curve_core(y2: np.ndarray, m: np.ndarray, method: str,
                identify: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Variance and identified alpha per tau and axis (threads over the axes).

    Returns var (k, n_axes) [unit^2], n_terms (k,), alpha (k, n_axes) with
    ``_ALPHA_UNKNOWN`` where the record has too few clusters for a data-based test.
    """
    n, n_axes = y2.shape
    if method == 'overlapping' and _is_octave(m) and m.size > 2:
        cols, means = _columns(y2)
    else:
        # The running-sum path reads y2 itself: no axis-major copy.
        cols, means = None, _means(y2)
    workers = _workers(n_axes)
    # Cores left over by the axes share each axis' taus.
    tau_threads = max(1, min(os.cpu_count() or 1, _MAX_THREADS) // workers)
    results = _map_threads(
        lambda a: _axis_work(y2, None if cols is None else cols[a], a, float(means[a]),
                             m, method, identify, tau_threads),
        n_axes, workers)
    n_terms = terms_count(m, n, method)
    sums = np.stack([r[0] for r in results], axis=1).reshape(m.size, n_axes)
    var = _normalise(sums, m, n_terms, method)
    alpha = (np.stack([r[1] for r in results], axis=1).reshape(m.size, n_axes)
             if identify else np.zeros((m.size, n_axes), dtype=np.int64))
    return var, n_terms, alpha


def _variance(y: np.ndarray, m: np.ndarray, method: str) -> tuple[np.ndarray, np.ndarray]:
    y2, one_d = _as_2d(y)
    m = _check_m(m, y2.shape[0], method)
    var, n_terms, _ = _curve_core(y2, m, method, identify=False)
    return (var[:, 0] if one_d else var), n_terms


def overlapping_avar(y: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Overlapping Allan variance at cluster sizes ``m`` (NIST SP 1065 eq. 14).

    AVAR(m tau0) = sum_i (X[i+2m] - 2 X[i+m] + X[i])^2 / (2 m^2 (M + 1 - 2m)), with
    X the running sum of the M samples (the phase divided by tau0).  A per-axis
    reference (the mean) is subtracted first, so a 9.81 m/s^2 offset costs no digits.

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit].
    m : np.ndarray
        Shape (k,), cluster sizes [samples], each in 1 .. M // 2.

    Returns
    -------
    avar : np.ndarray
        Shape (k, n_axes) (or (k,) for 1-D input), Allan variance [unit^2].
    n_terms : np.ndarray
        Shape (k,), number of second differences summed, M + 1 - 2m.

    """
    return _variance(y, m, 'overlapping')


def nonoverlapping_avar(y: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Non-overlapping Allan variance at cluster sizes ``m`` (NIST SP 1065 eq. 12).

    AVAR(m tau0) = sum_k (ybar[k+1] - ybar[k])^2 / (2 (K - 1)) over the K = M // m
    plain (non-overlapping) cluster averages ybar: the octave procedure of the
    Japanese text when m = 1, 2, 4, ...

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit].
    m : np.ndarray
        Shape (k,), cluster sizes [samples], each in 1 .. M // 2.

    Returns
    -------
    avar : np.ndarray
        Shape (k, n_axes) (or (k,) for 1-D input), Allan variance [unit^2].
    n_terms : np.ndarray
        Shape (k,), number of differences summed, M // m - 1.

    """
    return _variance(y, m, 'nonoverlapping')


def hadamard_var(y: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Overlapping Hadamard variance at cluster sizes ``m`` (NIST SP 1065 eq. 20).

    HVAR(m tau0) = sum_i (X[i+3m] - 3 X[i+2m] + 3 X[i+m] - X[i])^2 / (6 m^2 (M + 1 - 3m)):
    a third difference of the phase, so a linear frequency drift (a ramp in y)
    cancels exactly.

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit].
    m : np.ndarray
        Shape (k,), cluster sizes [samples], each in 1 .. M // 3.

    Returns
    -------
    hvar : np.ndarray
        Shape (k, n_axes) (or (k,) for 1-D input), Hadamard variance [unit^2].
    n_terms : np.ndarray
        Shape (k,), number of third differences summed, M + 1 - 3m.

    """
    return _variance(y, m, 'hadamard')


def identify_alpha(y: np.ndarray, m: np.ndarray, method: str = 'overlapping') -> np.ndarray:
    """
    Integer noise exponent alpha per cluster size and axis, as Stable32 does.

    Lag-1 autocorrelation (Riley & Greenhall 2004) of the linearly detrended
    non-overlapping cluster averages when there are at least 30 of them; else the
    B1 ratio (and R(n) for phase noise) with at least 4; else the local slope.

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit].
    m : np.ndarray
        Shape (k,), cluster sizes [samples].
    method : str
        'overlapping', 'nonoverlapping' or 'hadamard' (sets the alpha range).

    Returns
    -------
    np.ndarray
        Shape (k, n_axes) (or (k,) for 1-D input), int64 alpha.

    """
    y2, one_d = _as_2d(y)
    _check_method(method)
    m = _check_m(m, y2.shape[0], method)
    var, _, alpha = _curve_core(y2, m, method, identify=True)
    alpha = _fill_unknown(alpha, m.astype(np.float64), var, method)
    return alpha[:, 0] if one_d else alpha
