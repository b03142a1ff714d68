"""
Judging a fitted model against its own curve (used by the effect search).

- :func:`follows_curve`: does the model explain the measured curve?
- :func:`shows_quantization`: does the curve show quantization's slope at all?
- :func:`white_region` and :func:`white_share`: the curve's own white-noise level, read
  where white noise carries the model (N when no effect closes the gap).
"""

import math

import numpy as np

from imu_allan.core.allan.quantiles import chi2_ppf, chi2_sf
from imu_allan.core.fit.axis import term_slot
from imu_allan.core.fit.result import AxisFit
from imu_allan.core.fit.solver import _design
from imu_allan.core.rules import FOLLOW_SHARE, P_CONSISTENT, QUANTIZATION_SLOPE


def follows_curve(avar: np.ndarray, edf: np.ndarray, model: np.ndarray, chi2_value: float,
                  dof: int) -> bool:
    """
    Whether a model explains a measured curve.

    Either its GLS chi-square is acceptable (p >= :data:`P_CONSISTENT`), or the model
    lies inside the 95 % chi-square band of the measured ADEV, or within 5 % of it, at
    :data:`FOLLOW_SHARE` of the taus.  The second reading matters on long real
    records: with a million samples the shortest taus are known to 0.3 %, and a
    chi-square with the exact covariance rejects every model of a real sensor.

    Parameters
    ----------
    avar, edf, model : np.ndarray
        Shape (k,), measured AVAR [unit^2], its EDF, the model's AVAR [unit^2].
    chi2_value : float
        GLS chi-square of the model.
    dof : int
        Its degrees of freedom.

    Returns
    -------
    bool
        True when the model explains the curve.

    """
    if dof > 0 and chi2_sf(chi2_value, dof) >= P_CONSISTENT:
        return True
    e = np.maximum(edf, 1e-3)
    lo, hi = avar * e / chi2_ppf(0.975, e), avar * e / chi2_ppf(0.025, e)
    inside = ((model >= lo) & (model <= hi)) | (np.abs(np.sqrt(model / avar) - 1.0) <= 0.05)
    return bool(np.mean(inside) >= FOLLOW_SHARE)


def shows_quantization(tau: np.ndarray, avar: np.ndarray) -> bool:
    """
    Whether the shortest taus fall as steeply as quantization noise makes them.

    Quantization (white phase) gives an ADEV slope of -1; white noise -1/2, and a
    low-pass filter makes the shortest taus flatter still.  The term is a candidate
    only where the first ADEV slope is below :data:`QUANTIZATION_SLOPE`.
    """
    if tau.size < 2:
        return False
    slope = 0.5 * math.log(avar[1] / avar[0]) / math.log(tau[1] / tau[0])
    return slope < QUANTIZATION_SLOPE


def white_region(tau: np.ndarray, avar: np.ndarray, edf: np.ndarray,
                 share: np.ndarray) -> tuple[float, tuple[float, float]] | None:
    """
    Read N from the taus where white noise dominates the curve.

    Parameters
    ----------
    tau, avar, edf : np.ndarray
        Shape (k,), the curve [s], [unit^2], [-].
    share : np.ndarray
        Shape (k,), the white term's share of the fitted model's AVAR [-].

    Returns
    -------
    (N, (lo, hi)) or None
        Median of sqrt(avar tau) over the taus where the share is at least 0.8 (the
        white region), with the 95 % range of those points' chi-square intervals
        (NIST SP 1065 sec. 5.3), widened to cover their spread; None without such taus.

    """
    sel = np.flatnonzero(share >= 0.8)
    if sel.size == 0:
        return None
    level = np.sqrt(avar[sel] * tau[sel])
    n_value = float(np.median(level))
    e = np.maximum(edf[sel], 1.0)
    lo = level * np.sqrt(e / chi2_ppf(0.975, e))
    hi = level * np.sqrt(e / chi2_ppf(0.025, e))
    return n_value, (float(min(np.median(lo), level.min())),
                     float(max(np.median(hi), level.max())))


def white_share(fit: AxisFit) -> np.ndarray | None:
    """Share of the white term in the fitted AVAR at each of the fit's taus."""
    for label, c_si, phi in fit.components:
        if label in ('white', 'filtered_white'):
            slot = term_slot(label, fit.tau_s, 1.0 / max(fit.tau_s.min(), 1e-9))
            part = c_si * _design([slot], fit.tau_s, [phi])[:, 0]
            return part / np.maximum(fit.avar_fit, 1e-300)
    return None
