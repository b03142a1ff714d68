"""
Batch Allan curves: overlapping, non-overlapping (octave) and Hadamard variance.

All estimators take rate samples ``y`` (gyro rad/s, accel m/s^2, or fractional
frequency) at a constant sample period ``1 / rate_hz``.  Formulas follow
NIST SP 1065 (Riley, Handbook of Frequency Stability Analysis, 2008).
"""

from typing import NamedTuple

import numpy as np


class AllanCurve(NamedTuple):
    """
    An Allan (or Hadamard) curve for one or more axes.

    Attributes
    ----------
    tau_s : np.ndarray
        Shape (k,), averaging times [s].
    m : np.ndarray
        Shape (k,), cluster sizes [samples], ``tau_s = m / rate_hz``.
    avar : np.ndarray
        Shape (k, n_axes), variance estimate [unit^2].
    n_terms : np.ndarray
        Shape (k,), number of squared differences summed at each tau.
    edf : np.ndarray
        Shape (k, n_axes), equivalent degrees of freedom of each estimate.
    alpha : np.ndarray
        Shape (k, n_axes), power-law exponent of the frequency PSD (S_y ~ f^alpha)
        used for the EDF: 2 white PM, 1 flicker PM, 0 white FM (white rate noise),
        -1 flicker FM (bias instability), -2 random-walk FM (rate random walk).
    adev_lo, adev_hi : np.ndarray
        Shape (k, n_axes), lower and upper deviation bounds at ``confidence`` [unit].
    confidence : float
        Two-sided confidence level of the bounds, e.g. 0.683 or 0.95.
    method : str
        'overlapping', 'nonoverlapping' or 'hadamard'.
    rate_hz : float
        Sample rate [Hz].

    """

    tau_s: np.ndarray
    m: np.ndarray
    avar: np.ndarray
    n_terms: np.ndarray
    edf: np.ndarray
    alpha: np.ndarray
    adev_lo: np.ndarray
    adev_hi: np.ndarray
    confidence: float
    method: str
    rate_hz: float

    @property
    def adev(self) -> np.ndarray:
        """Deviation, shape (k, n_axes) [unit]."""
        return np.sqrt(self.avar)


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
    y = np.asarray(y, dtype=np.float64)
    one_d = y.ndim == 1
    y2 = y[:, None] if one_d else y
    m = np.asarray(m, dtype=np.int64)
    n = y2.shape[0]
    if m.size and (m.min() < 1 or 2 * m.max() > n):
        raise ValueError(f'cluster sizes must lie in 1..{n // 2} for {n} samples')
    # Axis-major contiguous phase; the mean is a free reference (AVAR ignores it).
    x = np.zeros((y2.shape[1], n + 1))
    np.cumsum((y2 - y2.mean(axis=0)).T, axis=1, out=x[:, 1:])
    avar = np.empty((m.size, y2.shape[1]))
    n_terms = n + 1 - 2 * m
    for j, mj in enumerate(m):
        d = x[:, 2 * mj:] - 2.0 * x[:, mj:-mj] + x[:, :n + 1 - 2 * mj]
        avar[j] = np.einsum('ij,ij->i', d, d) / (2.0 * mj * mj * n_terms[j])
    return (avar[:, 0] if one_d else avar), n_terms
