"""
A random walk that is a slow drift: named, and reported as a bound.

Without a temperature (or where the thermal regression found no coefficient), a slow
deterministic drift of the bias (a warming, an air-conditioning cycle) raises the Allan
curve at its longest taus as a random walk does, and the fit reports K as an estimate.
For every axis whose K is an estimate, :func:`drift_axes` asks
:func:`imu_allan.core.search.drift.drift_test` whether the record's random walk sits in
its smooth part only (read from the raw copy the search's evidence reads).  Where it
does, K becomes a 95 % upper bound (its estimate's upper end: a random walk of the
record is no larger) and one top-level warning names the axis, the drift and what to do.
"""

from dataclasses import replace
import math

from imu_allan import AXES
from imu_allan.core.fit.caps import cap_fit
from imu_allan.core.fit.result import AxisFit, Param
from imu_allan.core.noise.units import format_quoted, sensor_of
from imu_allan.core.rules import DRIFT_SIMS

#: The start of each warning of this module (consumer files carry them).
SLOW_DRIFT = 'slow drift'


def drift_axes(fits: dict, samples, raw_rate: float | None, thermal: dict) -> tuple:
    """
    Return the fits with K bounded where a drift was named, and the warnings.

    Parameters
    ----------
    fits : dict of str to AxisFit or None
        The fits by axis.
    samples : np.ndarray or None
        Shape (n, 6), the raw copy [SI] (None: nothing is tested).
    raw_rate : float or None
        Its rate [Hz].
    thermal : dict of str to imu_allan.pipeline.thermal_report.AxisThermal
        The thermal part: an axis whose coefficient is significant is left to it.

    Returns
    -------
    tuple of (dict, tuple of str)
        The fits (a new dict) and one warning per axis named.

    """
    out, warnings = dict(fits), []
    if samples is None or not raw_rate:
        return out, ()
    tested = [a for a in AXES if _k_estimate(fits.get(a))
              and not (a in thermal and thermal[a].coefficient.significant)]
    if not tested:
        return out, ()
    # scipy (the search package): imported only where a K estimate is tested.
    from imu_allan.core.search.drift import drift_test
    from imu_allan.core.search.thermal import model_terms

    for axis in tested:
        fit = fits[axis]
        check = drift_test(samples[:, AXES.index(axis)], float(raw_rate),
                           model_terms(fit.model))
        if check is None or not check.named:
            continue
        k = fit.optimised['K']
        why = (f'a slow drift, not a random walk ({_p(check.p_value)}): the estimate '
               f'{k.value:.3g} [{k.ci95[0]:.3g}, {k.ci95[1]:.3g}] is its upper end')
        bound = Param(float(k.ci95[1]), (0.0, float(k.ci95[1])), 'upper_bound', k.unit,
                      k.source, why)
        out[axis] = cap_fit(replace(fit, optimised={**fit.optimised, 'K': bound}))
        warnings.append(_warning(axis, k, out[axis].optimised['K'].value, check.p_value))
    return out, tuple(warnings)


def _k_estimate(fit: AxisFit | None) -> bool:
    """Return True where the fit reports K as an estimate."""
    p = None if fit is None else fit.optimised.get('K')
    return p is not None and p.kind == 'estimate' and math.isfinite(p.ci95[1])


def _warning(axis: str, k: Param, bound: float, p_value: float) -> str:
    sensor = sensor_of(axis)
    return (f'{SLOW_DRIFT} on {axis}: its bias drifts slowly (a warming, a temperature '
            f'cycle) where the curve reads a random walk; the random walk of the record lies '
            f'in its slowest part only ({_p(p_value)}, core/search/drift.py), so K is '
            f'reported as a 95 % upper bound, '
            f'{format_quoted("K", sensor, bound, digits=3)}, not the estimate '
            f'{format_quoted("K", sensor, k.value, digits=3)}; record the temperature '
            'and pass it (a temperature CSV column or topic: docs/thermal.md) so the drift '
            'is regressed out, or record longer')


def _p(p_value: float) -> str:
    """Return 'p = 0.004', or 'p < 0.0025' below the bootstrap's resolution."""
    return f'p = {p_value:.2g}' if p_value > 0 else f'p < {1.0 / DRIFT_SIMS:.2g}'
