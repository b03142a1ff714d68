"""
How a plan reads its expected widths: the fit's dispersion, the present interval, a target.

:mod:`imu_allan.core.plan.precision` gives the widths a correct model would show on
average; the plan reads them against the fit it starts from: inflated by the fit's
dispersion (:func:`inflation`, :func:`inflated`), from the present interval on
(:func:`as_read`, :func:`present_width`), and :func:`crossing` finds the record length
at which they meet a target.  Used by :mod:`imu_allan.core.plan.planner`.
"""

import math

import numpy as np

from imu_allan.core.fit.axis import profile_threshold
from imu_allan.core.plan.precision import interval_threshold, relative_width


def inflation(chi2: float, dof: int) -> float:
    """
    Factor on the expected intervals' z for a fit whose curve is more dispersed than its model.

    The fit widens its profile intervals where its model explains the curve worse than
    Sigma allows (J / dof > 1: a real sensor's curve, an effect the model lacks):
    :func:`imu_allan.core.fit.axis.profile_threshold`.  The expected widths assume the
    dispersion a correct model shows on average (:func:`interval_threshold`); a longer
    record of the same sensor keeps the excess, so its widths are sinh(f z sd),
    f = sqrt(threshold of the fit / threshold expected), at least 1.

    Parameters
    ----------
    chi2 : float
        The fit's GLS chi-square J_min [-].
    dof : int
        Its degrees of freedom.

    Returns
    -------
    float
        f >= 1 [-]; 1 without degrees of freedom or a finite chi-square.

    """
    if dof <= 0 or not math.isfinite(chi2):
        return 1.0
    return math.sqrt(max(1.0, profile_threshold(chi2, dof) / interval_threshold(dof)))


def inflated(widths: np.ndarray, factor: float) -> np.ndarray:
    """Multiply the log-scale z of expected relative half-widths by ``factor``."""
    return np.sinh(factor * np.arcsinh(widths))


def as_read(widths: np.ndarray, lengths_s: np.ndarray, factor: float, duration_s: float,
            now: float) -> np.ndarray:
    """
    Read expected widths as the plan does: the fit's dispersion, the present excess.

    The widths are inflated by the fit's dispersion (:func:`inflated`), which a longer
    record keeps.  The present interval differs from that expected width by the
    profile's departure from its quadratic approximation and by the scatter of one
    record's fit; both are of the order of the standard deviation relative to one, so
    the excess on the log scale, asinh(now) / asinh(expected now) - 1, is carried
    forward shrinking as sd, (duration / L)^(1/2).  The plan then starts at the
    present width and joins the expected widths as the record grows.  (Carrying the
    whole present ratio forward, as the plan once did, put 70 rather than 79 of 82
    simulated plans within 1.5x of the record length needed: docs/planning.md.)

    Parameters
    ----------
    widths : np.ndarray
        Shape (n,), expected relative half-widths at ``lengths_s`` [-].
    lengths_s : np.ndarray
        Shape (n,), record lengths [s], the first the present one.
    factor : float
        :func:`inflation` of the fit [-].
    duration_s : float
        Length of the present record [s] (0 or less: no record, no present width).
    now : float
        The present relative half-width [-] (not finite: no excess carried).

    Returns
    -------
    np.ndarray
        Shape (n,), the widths as read [-].

    """
    out = inflated(np.asarray(widths, float), factor)
    if not (duration_s > 0 and out.size and math.isfinite(now) and now > 0
            and math.isfinite(out[0]) and out[0] > 0):
        return out
    excess = math.asinh(now) / math.asinh(float(out[0])) - 1.0
    return np.sinh(np.arcsinh(out) * (1.0 + excess * np.sqrt(duration_s / lengths_s)))


def present_width(p) -> float:
    """Relative half-width of a reported parameter: inf unless an estimate, NaN if absent."""
    if p is None:
        return math.nan
    return relative_width(p.value, p.ci95) if p.kind == 'estimate' else math.inf


def crossing(lengths: np.ndarray, widths: np.ndarray, target: float) -> float:
    """First length where the width falls to ``target`` (log-log interpolation)."""
    ok = widths <= target
    if not ok.any():
        return math.inf
    j = int(np.argmax(ok))
    if j == 0:
        return float(lengths[0])
    w0, w1 = widths[j - 1], widths[j]
    if not math.isfinite(w0):
        return float(lengths[j])
    f = math.log(w0 / target) / math.log(w0 / w1)
    return float(math.exp(math.log(lengths[j - 1]) + f * math.log(lengths[j] / lengths[j - 1])))
