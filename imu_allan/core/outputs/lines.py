"""
The human lines of a report: one per axis, in the units people quote.

The summary, the node's statuses and its log read them; the numbers are the
:class:`~imu_allan.core.outputs.reported.AxisReport`'s, only formatted here.
"""

import math

from imu_allan.core.noise.units import format_quoted, quoted, sensor_of

#: The parameters of an axis line, in order.
CORE = ('N', 'B', 'K', 'T_B')


def axis_line(axis: str, fit, report) -> str:
    """
    One human line: N, B, K, T_B with their 95 % intervals in the units people quote.

    An estimate reads ``value unit [lo, hi]``, an upper bound ``< bound``, a lower
    bound ``> bound (fit value)`` (the bound: its interval's lower end); gyro N also in
    a datasheet's deg/s/sqrt(Hz); the lowest ADEV (a datasheet's in-run bias stability)
    only where the curve measures it (:class:`imu_allan.core.outputs.reported.Floor`).

    Parameters
    ----------
    axis : str
        Axis name.
    fit : imu_allan.core.fit.AxisFit or None
        The axis' fit (None: no usable noise).
    report : imu_allan.core.outputs.reported.AxisReport
        What every output reports for it.

    Returns
    -------
    str
        The line.

    """
    if fit is None:
        return f'{axis}: no usable noise (frozen or constant axis)'
    sensor = sensor_of(axis)
    parts = []
    for sym in CORE:
        p = report.params.get(sym)
        if p is None or p.kind == 'not_identified' or not math.isfinite(p.value):
            parts.append(f'{sym} n/a')
            continue
        text = _quoted(sym, sensor, p.value)
        if p.kind == 'lower_bound' and math.isfinite(p.ci95[0]):
            # The 95 % statement is the interval's lower end (the fit's value is only
            # the likeliest of the times beyond it).
            text = f'{_quoted(sym, sensor, p.ci95[0])} (fit {text})'
        if p.kind == 'estimate':
            lo, hi = (quoted(sym, sensor, v)[0] for v in p.ci95)
            text += f' [{lo:.3g}, {hi:.3g}]'
        mark = {'upper_bound': '< ', 'lower_bound': '> '}.get(p.kind, '')
        if sym == 'N' and sensor == 'gyro':
            text += f' ({math.degrees(p.value):.3g} deg/s/sqrt(Hz))'
        parts.append(f'{sym} {mark}{text}')
    floor = report.floor
    if floor is not None:
        lo, hi = (quoted('B', sensor, v)[0] for v in floor.ci95)
        parts.append(f'ADEV floor {_quoted("B", sensor, floor.adev)} [{lo:.3g}, {hi:.3g}] '
                     f'at {floor.tau_s:.3g} s')
    line = f'{axis}: ' + '; '.join(parts)
    return line + (' (NOT TRUSTED: conservative values)' if fit.trust else '')


def _quoted(sym: str, sensor: str, value_si: float) -> str:
    """Format a value in the unit people quote, 3 significant digits: 2.44 deg/sqrt(h)."""
    return format_quoted(sym, sensor, value_si, digits=3)
