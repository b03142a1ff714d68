"""
A noise level that changed during the record: named, and N's interval widened to it.

A fit's intervals assume the noise stayed the same over the record.  Where the Allan
variance at a tau ruled by white noise differs between the record's stretches beyond
chance (:func:`imu_allan.core.allan.stretches.level_change`), N is the record's
average of a level that wandered: its value stays, its 95 % interval takes in the
wander (N times exp(+-1.96 s / 2), s the between-stretch standard deviation of ln AVAR
beyond chance), and one top-level warning names the axis, the size of the change and
what to do.  A short record of such a sensor reads its own minutes' level, which this
interval of a long record then covers.
"""

from dataclasses import replace
import math

import numpy as np

from imu_allan import AXES
from imu_allan.core.allan.stretches import (FIRST_STRETCH_ROWS, level_change, LevelChange,
                                            MIN_STRETCHES, Stretches)
from imu_allan.core.fit.result import AxisFit, Param
from imu_allan.core.noise.units import format_quoted, sensor_of
from imu_allan.core.rules import LEVEL_P

#: The start of each warning of this module (consumer files carry them).
NOISE_CHANGED = 'noise level changed'
#: Two-sided 95 % normal quantile.
_Z95 = 1.959964
#: The tested tau's white-noise share may lie this far below the axis' best.
_SHARE_SLACK = 0.02
#: Tested taus hold at most this share of a first stretch (many terms per stretch).
_MAX_M_SHARE = 1.0 / 32
#: Tested taus span at least this many samples, and this many filter time constants.
_MIN_M = 8
_FILTER_SPAN = 20.0


def level_axes(fits: dict, stretches: Stretches | None) -> tuple[dict, tuple]:
    """
    Return the fits with N's interval widened where the noise level changed, and warnings.

    Parameters
    ----------
    fits : dict of str to AxisFit or None
        The fits by axis.
    stretches : Stretches or None
        The record's stretches (:meth:`AllanAccumulator.stretches`).

    Returns
    -------
    tuple of (dict, tuple of str)
        The fits (a new dict) and one warning per axis whose interval was widened.  A
        record of fewer stretches than the test needs gets a note on each fitted axis
        instead (not tested, and the length that would be).

    """
    out: dict = dict(fits)
    if stretches is None or not stretches.rows.size:
        return out, ()
    if stretches.rows.size < MIN_STRETCHES:
        return _untested(out, stretches), ()
    warnings = []
    for j, axis in enumerate(AXES):
        fit: AxisFit | None = fits.get(axis)
        n = None if fit is None else fit.optimised.get('N')
        if fit is None or n is None or n.kind != 'estimate' or not math.isfinite(n.ci95[1]):
            continue
        k = tested_tau(fit, stretches, n.value)
        change = None if k is None else level_change(stretches, k, j)
        if change is None or change.p_value >= LEVEL_P:
            continue
        spread = math.exp(_Z95 * change.sd_log_avar / 2.0)
        lo, hi = min(n.ci95[0], n.value / spread), max(n.ci95[1], n.value * spread)
        if (lo, hi) == tuple(n.ci95):
            continue
        why = (f'the noise level changed during the record (AVAR at {change.tau_s:.3g} s '
               f'{_range(change)} of the pooled value between stretches): the interval '
               'takes in the wander')
        reason = f'{n.reason}; {why}' if n.reason else why
        widened = Param(n.value, (lo, hi), n.kind, n.unit, n.source, reason)
        out[axis] = replace(fit, optimised={**fit.optimised, 'N': widened})
        warnings.append(_warning(axis, n, widened, change, stretches))
    return out, tuple(warnings)


def _rate_hz(stretches: Stretches) -> float:
    """Return the sample rate of the stretches' record [Hz]."""
    return float(stretches.m[0] / stretches.tau_s[0])


def _untested(fits: dict, stretches: Stretches) -> dict:
    """Return the fits with a note that the record is too short for the level test."""
    rate_hz = _rate_hz(stretches)
    minutes = MIN_STRETCHES * FIRST_STRETCH_ROWS / rate_hz / 60.0
    length = f'{minutes:.3g} min' if minutes < 120 else f'{minutes / 60:.3g} h'
    note = (f'noise level over the record: not tested (it holds {stretches.rows.size} of '
            f'the {MIN_STRETCHES} stretches of {FIRST_STRETCH_ROWS} samples the test '
            f'needs; a record of {length} at this rate would be)')
    return {axis: None if fit is None else replace(fit, notes=fit.notes + (note,))
            for axis, fit in fits.items()}


def tested_tau(fit: AxisFit, stretches: Stretches, n_value: float) -> int | None:
    """
    Return the stretch tau index where white noise rules the measured curve, or None.

    The smallest tau whose white share N^2 / (tau AVAR) (at most 1) lies within
    ``_SHARE_SLACK`` of the axis' best; None where no tau is at least half white.  The
    tau spans at least ``_MIN_M`` samples and ``_FILTER_SPAN`` times a fitted filter's
    time constant: the chance spread of the stretches assumes independent samples, and
    a filter of 2.8 samples made its variance 1.4x white noise's at m = 8, 1.1x at 64
    (docs/robustness.md).
    """
    rate_hz = _rate_hz(stretches)
    t_f = fit.optimised.get('T_f')
    m_min = max(_MIN_M, _FILTER_SPAN * t_f.value * rate_hz
                if t_f is not None and math.isfinite(t_f.value) else 0.0)
    idx = np.minimum(np.searchsorted(stretches.tau_s, fit.tau_s), stretches.tau_s.size - 1)
    m = stretches.m[idx]
    ok = ((stretches.tau_s[idx] == fit.tau_s) & (m >= m_min)
          & (m <= FIRST_STRETCH_ROWS * _MAX_M_SHARE) & (fit.avar_meas > 0))
    if not ok.any():
        return None
    share = np.minimum(n_value ** 2 / (fit.tau_s[ok] * fit.avar_meas[ok]), 1.0)
    if share.max() < 0.5:
        return None
    first = int(np.argmax(share >= share.max() - _SHARE_SLACK))
    return int(idx[ok][first])


def _range(change: LevelChange) -> str:
    lo, hi = change.ratio_range
    return f'{100 * lo:.0f}-{100 * hi:.0f} %'


def _warning(axis: str, n: Param, widened: Param, change: LevelChange,
             stretches: Stretches) -> str:
    sensor = sensor_of(axis)
    minutes = float(np.median(stretches.rows)) / _rate_hz(stretches) / 60
    q = [format_quoted('N', sensor, v, digits=3) for v in (n.value, *widened.ci95)]
    p = f'p = {change.p_value:.2g}' if change.p_value > 1e-12 else 'p < 1e-12'
    return (f'{NOISE_CHANGED} on {axis}: its Allan variance at {change.tau_s:.3g} s, where '
            f"white noise rules, was {_range(change)} of the pooled value in the record's "
            f'{change.n_stretches} stretches of {minutes:.3g} min ({p}), beyond chance '
            '(vibration nearby, the sensor warming, its supply); N '
            f"{q[0]} is the record's average, its 95 % interval widened to "
            f'[{q[1]}, {q[2]}]; record where and as the robot runs, and give a filter '
            'the upper end')
