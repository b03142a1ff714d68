"""
What the measured curve allows: no bound of N, B or K lies above the record's own curve.

Every noise term but a sensor's filter only adds to the Allan variance, so B and K are
bounded by the whole curve, and N by the curve past the filter
(:class:`imu_allan.core.fit.result.CurveCaps`).
:func:`curve_caps` reads the bounds off every point past the sensor's filter once, where
the fit is made; :func:`cap_fit` caps the upper bounds each later step makes (a rival
model, the trust fallback, a drift test) at them.  numpy only: the pipeline imports it
where scipy is not loaded.
"""

from dataclasses import replace
import math

import numpy as np

from imu_allan.core.allan.edf import curve_k_bound, curve_n_bound, floor_b_bound
from imu_allan.core.fit.result import AxisFit, CurveCaps, Param


def curve_caps(tau: np.ndarray, avar: np.ndarray, edf: np.ndarray,
               white_from_s: float = math.nan) -> CurveCaps:
    """
    Return what the measured curve allows of N, B and K (:class:`CurveCaps`).

    Parameters
    ----------
    tau : numpy.ndarray
        (k,) averaging times past the sensor's filter, every point of the curve [s].
    avar : numpy.ndarray
        (k,) measured AVAR at them [unit^2].
    edf : numpy.ndarray
        (k,) their equivalent degrees of freedom.
    white_from_s : float
        The first tau where the curve showed the filter's bend end [s]: N is capped by
        the points from there (NaN, ``AxisFit.filter_end_s`` where the end was not seen:
        no N cap).

    Returns
    -------
    CurveCaps
        No cap (inf) without points.

    """
    if not np.size(tau):
        return CurveCaps()
    white = tau >= white_from_s * (1.0 - 1e-9)
    return CurveCaps(floor_b_bound(avar, edf), curve_k_bound(tau, avar, edf),
                     curve_n_bound(tau[white], avar[white], edf[white]) if white.any()
                     else math.inf)


#: What each cap of :class:`CurveCaps` is, for the note of a capped bound.
_CAP_WHAT = {'N': 'what the curve itself allows past the filter (white noise under its 95 % '
                  'upper band at every tau)',
             'K': 'what the curve itself allows (a random walk under its 95 % upper band '
                  'at every tau)',
             'B': "what the curve's floor allows (its 95 % upper band / 0.664)"}


def cap_bounds(optimised: dict, caps: CurveCaps, notes: list) -> dict:
    """
    Cap every upper bound of N, B and K at what the measured curve allows.

    A bound from a profile, from a rival model or from a drift test is an interval's
    upper end; on a short record it can lie far above the curve (the profile of a term
    the data do not see runs up to hundreds of times the floor).  No term exceeds the
    whole curve, so such a bound is replaced by the curve's (:class:`CurveCaps`).

    Parameters
    ----------
    optimised : dict of str to Param
        The reported parameters, by symbol.
    caps : CurveCaps
        The curve's bounds.
    notes : list of str
        Appended with one line per bound capped.

    Returns
    -------
    dict of str to Param
        ``optimised`` with the capped bounds (a new dict).

    """
    out = dict(optimised)
    for sym in ('N', 'B', 'K'):
        p, cap = out.get(sym), getattr(caps, sym)
        if (p is None or p.kind != 'upper_bound' or not (math.isfinite(cap) and cap > 0)
                or p.value <= cap):
            continue
        what = _CAP_WHAT[sym]
        out[sym] = Param(cap, (0.0, cap), 'upper_bound', p.unit, 'curve',
                         f'the bound lay above {what}: capped there')
        notes.append(f'{sym}: the bound {p.value:.3g} lay above {what}, {cap:.3g}: '
                     'capped there')
    return out


def cap_fit(fit: AxisFit) -> AxisFit:
    """
    Return ``fit`` with every upper bound capped at its curve (:func:`cap_bounds`).

    Each step that makes a bound after the fit (a rival model, the trust fallback, a
    drift test) ends with it, so no reported bound lies above the record's own curve.

    Parameters
    ----------
    fit : AxisFit
        A fit with its :attr:`AxisFit.caps`.

    Returns
    -------
    AxisFit
        ``fit`` itself when nothing lay above.

    """
    notes: list[str] = []
    optimised = cap_bounds(fit.optimised, fit.caps, notes)
    if not notes:
        return fit
    return replace(fit, optimised=optimised, notes=fit.notes + tuple(notes))
