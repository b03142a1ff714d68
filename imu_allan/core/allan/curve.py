"""
The Allan curve of one or more axes with EDF, bounds and noise types.

Part of :mod:`imu_allan.core.allan`.
"""

import math
from typing import NamedTuple, Sequence

import numpy as np

from imu_allan.core.allan.edf import confidence_bounds, edf_for_method
from imu_allan.core.allan.kernels import _curve_core
from imu_allan.core.allan.noise_id import _fill_unknown
from imu_allan.core.allan.taus import _as_2d, _check_method, cluster_sizes, max_cluster_size
from imu_allan.errors import InputError


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


def allan_curve(y: np.ndarray, rate_hz: float,
                taus: str | Sequence[float] | np.ndarray = 'octave',
                method: str = 'overlapping', confidence: float = 0.683,
                alpha: int | np.ndarray | None = None) -> AllanCurve:
    """
    Allan (or Hadamard) curve with noise-aware confidence bounds for every axis.

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit] at a constant rate.
    rate_hz : float
        Sample rate [Hz].
    taus : str or sequence of float
        'octave', 'dense', 'all' (:func:`tau_grid`) or tau values [s]
        (:func:`cluster_sizes`).
    method : str
        'overlapping' (NIST SP 1065 eq. 14), 'nonoverlapping' (eq. 12, the octave
        procedure of the Japanese text) or 'hadamard' (overlapping, eq. 20).
    confidence : float
        Two-sided confidence level of the bounds, e.g. 0.683 or 0.95.
    alpha : int or np.ndarray, optional
        Noise exponent for the EDF, broadcast to (k, n_axes); None identifies it per
        tau and axis from the data (:func:`identify_alpha`).

    Returns
    -------
    AllanCurve
        Arrays of shape (k, n_axes) (n_axes = 1 for 1-D input).

    Raises
    ------
    InputError
        Non-finite samples, a record too short for any tau, a bad rate, tau or method.

    """
    _check_method(method)
    if not (isinstance(rate_hz, (int, float, np.floating)) and math.isfinite(rate_hz)
            and rate_hz > 0):
        raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
    if not 0.0 < confidence < 1.0:
        raise InputError(f'confidence must lie strictly between 0 and 1, got {confidence}')
    y2, _ = _as_2d(y)
    n, n_axes = y2.shape
    m_max = max_cluster_size(n, method)
    if m_max < 1:
        need = 3 if method == 'hadamard' else 2
        raise InputError(f'{n} samples are too few for any tau of the {method} variance '
                         f'(need at least {need})')
    m = cluster_sizes(taus, n, float(rate_hz), method)
    avar, n_terms, alpha_arr = _curve_core(y2, m, method, identify=alpha is None)
    tau_s = m / float(rate_hz)
    if alpha is None:
        alpha_arr = _fill_unknown(alpha_arr, tau_s, avar, method)
    else:
        alpha_arr = np.broadcast_to(np.asarray(alpha, dtype=np.int64),
                                    (m.size, n_axes)).copy()
    edf = edf_for_method(alpha_arr, m[:, None], n, method)
    lo, hi = confidence_bounds(avar, edf, confidence)
    return AllanCurve(tau_s=tau_s, m=m, avar=avar, n_terms=n_terms, edf=edf,
                      alpha=alpha_arr, adev_lo=lo, adev_hi=hi,
                      confidence=float(confidence), method=method, rate_hz=float(rate_hz))
