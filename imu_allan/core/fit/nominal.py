"""
The nominal method: the IEEE Std 952 annex C read-off of N, B, K and T_B.

Part of :mod:`imu_allan.core.fit` (see its docstring for the method).
"""

import math

import numpy as np

from imu_allan.core.allan.quantiles import chi2_ppf
from imu_allan.core.fit.result import _unit, Param
from imu_allan.core.noise.shapes import FLICKER_AVAR, GM_PEAK_TAU


def _chi2_factors(edf: float) -> tuple[float, float]:
    """Multipliers (lo, hi) of an ADEV estimate for a 95 % chi-square interval."""
    edf = max(float(edf), 1e-3)
    return (math.sqrt(edf / chi2_ppf(0.975, edf)), math.sqrt(edf / chi2_ppf(0.025, edf)))


def nominal_fit(tau_s: np.ndarray, avar: np.ndarray, edf: np.ndarray,
                unit: str = 'unit') -> dict:
    """
    IEEE Std 952 read-off of N, B, K and T_B (the nominal method).

    N from the -1/2 slope line at tau = 1 s, K from the +1/2 slope line at tau = 3 s,
    each through the point whose forward log-log slope is closest to the target;
    B = min ADEV / 0.664, T_B = tau at the minimum / 1.89.  A slope more than 0.25 away
    from its target makes the value an upper bound (the line then only bounds the
    term from above).  Intervals: chi-square bounds of the read point (its EDF); for
    T_B the range of tau whose interval overlaps the minimum's, / 1.89.

    Parameters
    ----------
    tau_s : np.ndarray
        Shape (k,), averaging times [s], increasing.
    avar : np.ndarray
        Shape (k,), Allan variance [unit^2].
    edf : np.ndarray
        Shape (k,), equivalent degrees of freedom of each estimate.
    unit : str
        Unit of the samples, e.g. 'rad/s'.

    Returns
    -------
    dict of str to Param
        N, B, K, T_B.

    """
    tau = np.asarray(tau_s, dtype=np.float64)
    adev = np.sqrt(np.asarray(avar, dtype=np.float64))
    edf = np.asarray(edf, dtype=np.float64)
    out = {}
    if tau.size < 2:
        nan = Param(math.nan, (math.nan, math.nan), 'not_identified', '')
        return {k: nan._replace(unit=_unit(u, unit)) for k, u in
                (('N', 'u*s^0.5'), ('B', 'u'), ('K', 'u/s^0.5'), ('T_B', 's'))}
    slope = np.diff(np.log(adev)) / np.diff(np.log(tau))
    for sym, target, tau_read, u in (('N', -0.5, 1.0, 'u*s^0.5'), ('K', 0.5, 3.0, 'u/s^0.5')):
        i = int(np.argmin(np.abs(slope - target)))
        # The line through (tau_i, adev_i) with slope target, read at tau_read.
        value = adev[i] * (tau_read / tau[i]) ** target
        lo, hi = _chi2_factors(edf[i])
        kind = 'estimate' if abs(slope[i] - target) <= 0.25 else 'upper_bound'
        ci = (value * lo, value * hi) if kind == 'estimate' else (0.0, value * hi)
        out[sym] = Param(float(value), ci, kind, _unit(u, unit))
    i = int(np.argmin(adev))
    lo, hi = _chi2_factors(edf[i])
    out['B'] = Param(float(adev[i] / FLICKER_AVAR ** 0.5),
                     (adev[i] * lo / FLICKER_AVAR ** 0.5, adev[i] * hi / FLICKER_AVAR ** 0.5),
                     'estimate', _unit('u', unit))
    # Taus whose interval reaches down to the minimum's upper bound: where the minimum
    # could as well be.
    lo_all = adev * np.array([_chi2_factors(e)[0] for e in edf])
    near = np.flatnonzero(lo_all <= adev[i] * hi)
    t_lo = tau[near].min() / GM_PEAK_TAU
    t_hi = tau[near].max() / GM_PEAK_TAU
    out['T_B'] = Param(float(tau[i] / GM_PEAK_TAU), (float(t_lo), float(t_hi)),
                       'estimate', 's')
    return {k: out[k] for k in ('N', 'B', 'K', 'T_B')}
