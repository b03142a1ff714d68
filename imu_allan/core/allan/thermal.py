"""
The bias's thermal coefficient from streamed Allan sums, and the compensated curve.

A bias that follows the temperature, ``y = n + c T`` (n the sensor's noise, c the
thermal coefficient [unit/degC]), is found without a second pass over the samples: the
accumulator that already holds the Allan variance of every axis y_i is given a second
one with the columns ``T`` and ``y_i + s T`` (:func:`thermal_columns`, s = 1
unit/degC), and the polarisation identity gives the Allan covariance at every tau::

    ACOV(y_i, T) = (AVAR(y_i + s T) - AVAR(y_i) - s^2 AVAR(T)) / (2 s)

(the overlapping estimator, NIST SP 1065 eq. 14, is a quadratic form of the samples,
so the identity holds for the estimates term by term; same taus, same term counts).
Then, for any coefficient c and exactly::

    AVAR(y_i - c T) = AVAR(y_i) - 2 c ACOV(y_i, T) + c^2 AVAR(T)

which is the curve of the compensated axis (:func:`compensated_avar`).

The coefficient c itself is regressed on the record's block means
(:mod:`imu_allan.core.search.thermal`).
"""

import numpy as np


#: The scale s [unit/degC] of the polarisation columns ``y + s T``.
SCALE = 1.0


def thermal_columns(samples: np.ndarray, temp_c: np.ndarray) -> np.ndarray:
    """
    Return the columns the thermal accumulator sums: T, then y_i + s T.

    Parameters
    ----------
    samples : np.ndarray
        Shape (n, a), the axes' samples [unit].
    temp_c : np.ndarray
        Shape (n,), the temperature at each sample [degC].

    Returns
    -------
    np.ndarray
        Shape (n, a + 1), float64: column 0 is T [degC], column 1 + i is y_i + s T.

    """
    y = np.asarray(samples, dtype=np.float64)
    t = np.asarray(temp_c, dtype=np.float64).reshape(-1, 1)
    return np.concatenate((t, y + SCALE * t), axis=1)


def allan_covariance(avar_y: np.ndarray, avar_thermal: np.ndarray) -> tuple:
    """
    Split the thermal accumulator's variances into AVAR(T) and ACOV(y_i, T).

    Parameters
    ----------
    avar_y : np.ndarray
        Shape (k, a), AVAR(y_i) of the main accumulator [unit^2].
    avar_thermal : np.ndarray
        Shape (k, a + 1), the thermal accumulator's variances at the same taus: column 0
        AVAR(T) [degC^2], then AVAR(y_i + s T).

    Returns
    -------
    avar_t : np.ndarray
        Shape (k,), AVAR(T) [degC^2].
    acov : np.ndarray
        Shape (k, a), ACOV(y_i, T) [unit degC] (polarisation, module docstring).

    """
    avar_t = avar_thermal[:, 0]
    acov = (avar_thermal[:, 1:] - avar_y - SCALE ** 2 * avar_t[:, None]) / (2.0 * SCALE)
    return avar_t, acov


def compensated_avar(avar_y: np.ndarray, avar_t: np.ndarray, acov: np.ndarray,
                     c: np.ndarray) -> np.ndarray:
    """
    Return AVAR(y_i - c_i T) at every tau (exact for the estimates, module docstring).

    Parameters
    ----------
    avar_y : np.ndarray
        Shape (k, a), AVAR(y_i) [unit^2].
    avar_t : np.ndarray
        Shape (k,), AVAR(T) [degC^2].
    acov : np.ndarray
        Shape (k, a), ACOV(y_i, T) [unit degC].
    c : np.ndarray
        Shape (a,), coefficients [unit/degC]; NaN leaves an axis as it is.

    Returns
    -------
    np.ndarray
        Shape (k, a) [unit^2]; never below 1e-6 of AVAR(y_i) (rounding, not noise).

    """
    c = np.nan_to_num(np.asarray(c, dtype=np.float64), nan=0.0)[None, :]
    out = avar_y - 2.0 * c * acov + c ** 2 * avar_t[:, None]
    return np.maximum(out, 1e-6 * avar_y)
