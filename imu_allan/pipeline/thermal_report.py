"""
The thermal part of an analysis: each axis' coefficient and its compensated fit.

When the session was given a temperature (:mod:`imu_allan.pipeline.thermal`),
:func:`thermal_axes` regresses each axis' bias on it
(:func:`imu_allan.core.search.thermal.thermal_regression`, with the axis'
uncompensated noise model), and where the coefficient c is significant it searches
the compensated curve AVAR(y - c T) (:func:`imu_allan.core.allan.thermal.compensated_avar`)
as every curve is searched.  The uncompensated fit stays what every output reports:
the drift as a filter without thermal compensation sees it.  The compensated one is
what a filter that subtracts c (T - T0) should use; where the two disagree (a reported
N, B or K outside the compensated interval) a top-level warning names the axis, the
cause and what to do.  Without a temperature nothing here runs.
"""

from dataclasses import dataclass
import math
from typing import Callable, TYPE_CHECKING

import numpy as np

from imu_allan import AXES, AXIS_UNITS
from imu_allan.core.allan.curve import AllanCurve
from imu_allan.core.allan.noise_id import alpha_from_slope
from imu_allan.core.allan.thermal import allan_covariance, compensated_avar
from imu_allan.core.fit.result import AxisFit, json_floats
from imu_allan.core.noise.units import format_quoted, sensor_of
from imu_allan.core.outputs.reported import report_axis

if TYPE_CHECKING:
    from imu_allan.core.search.thermal import ThermalCoefficient

#: The start of each warning of this module (consumer files carry them).
THERMAL_DRIFT = 'thermal drift'


@dataclass(frozen=True)
class AxisThermal:
    """
    One axis' thermal coefficient and the fit of its compensated curve.

    Attributes
    ----------
    coefficient : ThermalCoefficient
        c [unit/degC] with its 95 % interval.
    unit : str
        Its unit ('rad/s/degC', 'm/s^2/degC').
    fit : AxisFit or None
        The compensated curve's fit (None where c is not significant).
    adev : np.ndarray or None
        Shape (k,), the compensated curve's ADEV at the analysis' taus [unit].

    """

    coefficient: 'ThermalCoefficient'
    unit: str
    fit: AxisFit | None = None
    adev: np.ndarray | None = None

    def to_json(self, axis: str) -> dict:
        """Return the ``thermal`` entry of an axis in result.json (docs/outputs.md)."""
        out: dict = {'coefficient': {**self.coefficient.to_json(), 'unit': self.unit}}
        if self.fit is not None and self.adev is not None:
            out['compensated'] = {**self.fit.to_json(),
                                  'reported': report_axis(self.fit, axis).to_json(),
                                  'adev': json_floats(self.adev)}
        return out


def thermal_axes(session, curve: AllanCurve, fits: dict, raw: tuple,
                 map_axes: Callable, workers: int) -> tuple[dict, tuple]:
    """
    Return each axis' :class:`AxisThermal` and the top-level warnings, or ({}, []).

    Parameters
    ----------
    session : imu_allan.pipeline.session.Session
        The analysed session; nothing is done unless it holds thermal sums.
    curve : AllanCurve
        The session's curve (the uncompensated one every output reports).
    fits : dict of str to AxisFit or None
        The uncompensated fits by axis.
    raw : tuple
        (samples (n, 6) or None, their rate [Hz] or None): the raw copy the search's
        evidence reads (the compensated search reads it less c T, T from the thermal
        block means by record share).
    map_axes : callable
        ``map_axes(jobs, workers, meanwhile) -> (fits, _)``: the analysis' search jobs
        on its worker pool.
    workers : int
        Processes for them.

    """
    # A session, or a snapshot of one (the node's SessionView) with its copies.
    thermal = getattr(getattr(session, 'feed', None), 'thermal', None)
    if thermal is None or thermal.acc is None:
        return {}, ()
    # scipy (the search package): imported only when a temperature was given.
    from imu_allan.core.search.thermal import model_terms, thermal_regression

    if thermal.off_reason:
        return {}, (f'{THERMAL_DRIFT}: {thermal.off_reason}',)
    thermal.flush()     # the rows after the last reading: the last value held
    tcurve = thermal.acc.curve(bounds=False)
    if (not np.array_equal(tcurve.m, curve.m)
            or thermal.acc.n_samples != session.feed.acc.n_samples):
        return {}, (f'{THERMAL_DRIFT}: the thermal sums do not match the curve: not used',)
    avar_t, acov = allan_covariance(curve.avar, tcurve.avar)
    means, means_rate = thermal.block_means()
    out: dict = {}
    c = np.full(len(AXES), np.nan)
    for j, axis in enumerate(AXES):
        fit = fits.get(axis)
        unit = f'{AXIS_UNITS[axis]}/degC'
        if fit is None:
            continue
        coef = thermal_regression(means[:, j], means[:, -1], means_rate,
                                  model_terms(fit.model))
        out[axis] = AxisThermal(coef, unit)
        if coef.significant:
            c[j] = coef.value
    if not np.isfinite(c).any():
        return out, ()
    comp = compensated_avar(curve.avar, avar_t, acov, c)
    acc = session.feed.acc
    alpha = alpha_from_slope(curve.tau_s, comp, n_clusters=(acc.n_samples // curve.m)[:, None])
    edf = acc.curve(curve.confidence, alpha=alpha, bounds=False).edf
    raw_comp, (samples, raw_rate) = None, raw
    if samples is not None and means.shape[0] >= 2:
        share = (np.arange(samples.shape[0]) + 0.5) / samples.shape[0]
        temp = np.interp(share, (np.arange(means.shape[0]) + 0.5) / means.shape[0],
                         means[:, -1])
        raw_comp = samples - np.nan_to_num(c)[None, :] * temp[:, None]
    axes = [a for j, a in enumerate(AXES) if np.isfinite(c[j])]
    jobs = []
    for axis in axes:
        j = AXES.index(axis)
        jobs.append((curve.tau_s, comp[:, j], edf[:, j], curve.rate_hz,
                     int(session.stats.n_used), None if raw_comp is None else raw_comp[:, j],
                     raw_rate, AXIS_UNITS[axis]))
    found = map_axes(jobs, workers, lambda: None)[0]
    return out, tuple(_with_fits(out, axes, found, comp, fits))


def _with_fits(out: dict, axes: list, found: list, comp: np.ndarray, fits: dict) -> list:
    """Put the compensated fits into ``out``; return the warnings of the axes that differ."""
    warnings = []
    for axis, fit in zip(axes, found):
        j = AXES.index(axis)
        entry = out[axis]
        out[axis] = AxisThermal(entry.coefficient, entry.unit, fit, np.sqrt(comp[:, j]))
        if fit is None:
            continue
        moved = _moved(fits[axis], fit)
        if moved:
            warnings.append(_warning(axis, entry, fit, moved))
    return warnings


def _moved(plain: AxisFit, comp: AxisFit) -> list:
    """
    Return the symbols of N, B, K the drift moved (outside the compensated interval).

    Also where the compensated value is only an upper bound and the reported one an
    estimate: the drift made an estimate of what the noise alone cannot determine.
    """
    out = []
    a, b = report_axis(plain).params, report_axis(comp).params
    for sym in ('N', 'B', 'K'):
        p, q = a.get(sym), b.get(sym)
        if (p is None or q is None or not math.isfinite(p.value)
                or q.kind not in ('estimate', 'upper_bound')):
            continue
        lo, hi = (0.0 if q.kind == 'upper_bound' else q.ci95[0]), q.ci95[1]
        made = q.kind == 'upper_bound' and p.kind == 'estimate'
        if made or not lo <= p.value <= hi * (1 + 1e-9):
            out.append(sym)
    return out


def _warning(axis: str, entry: AxisThermal, fit: AxisFit, moved: list) -> str:
    c = entry.coefficient
    return (f'{THERMAL_DRIFT} on {axis}: its bias follows the temperature '
            f'(c = {c.value:.3g} {entry.unit}, 95 % [{c.ci95[0]:.3g}, {c.ci95[1]:.3g}], '
            f'over {c.span_c:.3g} degC); the reported {", ".join(moved)} include that drift, as '
            'a filter without thermal compensation sees it; a filter that subtracts '
            f'c (T - T0) should use the compensated values: {_values(axis, fit)} '
            f'(result.json axes.{axis}.thermal)')


def thermal_lines(thermal: dict) -> list:
    """Return the summary lines of the thermal part ([] without a temperature)."""
    if not thermal:
        return []
    lines = ['', 'thermal coefficient c of the bias (95 %); the values above are without '
             'thermal compensation (what a filter without it should use); a filter that '
             'subtracts c (T - T0) should use the compensated values:']
    for axis, entry in thermal.items():
        c = entry.coefficient
        if not math.isfinite(c.value):
            lines.append(f'  {axis}: c not determined ({c.reason})')
            continue
        line = (f'  {axis}: c {c.value:.3g} {entry.unit} [{c.ci95[0]:.3g}, {c.ci95[1]:.3g}]'
                f' over {c.span_c:.3g} degC')
        if entry.fit is None:
            line += ' (its interval holds 0: nothing to compensate)'
        else:
            line += ': compensated ' + _values(axis, entry.fit)
        lines.append(line)
    return lines


def _values(axis: str, fit: AxisFit) -> str:
    """Return N, B, K of a fit as reported, in customary units."""
    params = report_axis(fit).params
    return ', '.join(
        f'{s} {"< " if params[s].kind == "upper_bound" else ""}'
        + format_quoted(s, sensor_of(axis), params[s].value, digits=3)
        for s in ('N', 'B', 'K') if s in params
        and params[s].kind in ('estimate', 'upper_bound'))
