"""
Values on a coarse grid: name the axes whose rounding changes N.

A sensor's LSB, or a logger that writes few digits (``%.3f`` in a CSV, a scaled integer),
puts the values on a grid; rounding to it adds white noise of q^2 / 12 per sample
(:mod:`imu_allan.core.noise.rounding`).  The sample gate measures each axis' grid, the
median step between its few distinct values (``HygieneStats.value_grid``,
:mod:`imu_allan.pipeline.zeros`);
here it is set against the fitted white noise.  Where rounding raises N by
:data:`~imu_allan.core.rules.ROUNDING_N_RAISE` or more a top-level warning names the
axes, the step and the share; the reported N includes it, as a filter fed this stream
sees it.  From :data:`~imu_allan.core.rules.ROUNDING_RATIO_MAX` sds of one sample on,
the white noise is not resolved and the warning says N cannot be measured.
"""

from imu_allan import AXES, AXIS_UNITS
from imu_allan.core.noise.rounding import rounding_effect
from imu_allan.core.rules import ROUNDING_N_RAISE, ROUNDING_RATIO_MAX

#: The start of each warning of this module (consumer files carry them).
COARSE_GRID = 'coarse resolution'
_SENSOR = {'gyro': 'gyroscope', 'accel': 'accelerometer'}


def resolution_warnings(value_grid: dict, fits: dict, rate_hz: float) -> tuple:
    """
    Return one warning per sensor whose axes' grid raises N, or leaves it unresolved.

    Parameters
    ----------
    value_grid : dict of str to float
        Per axis, the grid step of its values [unit].
    fits : dict of str to AxisFit or None
        The fits by axis (N's value is the recorded white noise).
    rate_hz : float
        The sample rate [Hz].

    Returns
    -------
    tuple of str

    """
    found: dict = {'gyro': [], 'accel': []}
    for axis in AXES:
        fit, step = fits.get(axis), value_grid.get(axis)
        n = None if fit is None else fit.optimised.get('N')
        if step is None or n is None or n.kind != 'estimate' or not rate_hz > 0:
            continue
        effect = rounding_effect(float(step), float(n.value), float(rate_hz))
        if effect.n_raise >= ROUNDING_N_RAISE or effect.ratio >= ROUNDING_RATIO_MAX:
            found[axis.split('_')[0]].append((axis, effect))
    return tuple(_warning(kind, items) for kind, items in found.items() if items)


def _warning(kind: str, items: list) -> str:
    axes = ', '.join(a for a, _ in items)
    steps = sorted({f'{e.quantum:.3g}' for _, e in items})
    ratios = [e.ratio for _, e in items]
    where = (f'{COARSE_GRID} on {axes}: the values lie on a grid of {" / ".join(steps)} '
             f'{AXIS_UNITS[items[0][0]]} ({_span(ratios, "")} times the noise of one sample)')
    if max(ratios) >= ROUNDING_RATIO_MAX:
        return (f'{where}: the white noise is not resolved, so N (and the {_SENSOR[kind]} '
                'white noise of every file) cannot be measured from this record, it reads '
                'high or low; log the values at full resolution (more digits, not a scaled '
                'integer) or use a finer sensor range')
    raises = [100.0 * e.n_raise for _, e in items]
    return (f'{where}: rounding raises N by {_span(raises, " %")} (the reported N includes '
            'it, as a filter fed this stream sees it); if a logger rounded the values '
            '(the digits of a CSV, a scaled integer), log them at full resolution')


def _span(values: list, unit: str) -> str:
    lo, hi = min(values), max(values)
    return f'{lo:.2g}{unit}' if f'{lo:.2g}' == f'{hi:.2g}' else f'{lo:.2g}-{hi:.2g}{unit}'
