"""
The warnings that name each consumer value a record is too short to determine.

A value is undetermined on an axis whose parameter is not an estimate (an upper bound,
or not identified): the consumer files then carry a bound, and stdout, result.json and
every consumer file's header carry the warning, with the record length that would
determine it (from the plan).
"""

import math

from imu_allan import AXES
from imu_allan.core.plan.result import hours, more_total

#: What consumers call N, K and B of a sensor (Kalibr keys; B is the Kalman b_gm state).
CONSUMER_NAMES = {('gyro', 'N'): 'gyroscope_noise_density (N)',
                  ('gyro', 'K'): 'gyroscope_random_walk (K)',
                  ('gyro', 'B'): 'the gyroscope bias instability B (kalman_qr.yaml b_gm)',
                  ('accel', 'N'): 'accelerometer_noise_density (N)',
                  ('accel', 'K'): 'accelerometer_random_walk (K)',
                  ('accel', 'B'): 'the accelerometer bias instability B (kalman_qr.yaml b_gm)'}
#: The start of each warning of :func:`short_record_warnings` (consumer files carry them).
SHORT_RECORD = 'record too short'


def short_record_warnings(fits: dict, plans: dict, duration_s: float) -> list:
    """
    Name each consumer value the record cannot determine, and the length that would.

    A value is undetermined on an axis whose parameter is not an estimate (an upper
    bound, or not identified): the consumer files then carry a bound.  The length is
    the plan's record length to the parameter's target (an upper bound's plan is a
    lower limit).

    Parameters
    ----------
    fits : dict of str to AxisFit or None
        The fits by axis.
    plans : dict of str to imu_allan.core.plan.AxisPlan
        The plans by axis (empty when not planned).
    duration_s : float
        Length of the record [s].

    Returns
    -------
    list of str
        One line per sensor and parameter (N, K, B) with an undetermined axis.

    """
    out = []
    for (sensor, sym), name in CONSUMER_NAMES.items():
        axes = [a for a in AXES if a.startswith(sensor) and fits.get(a) is not None]
        params = {a: fits[a].optimised.get(sym) for a in axes}
        open_axes = [a for a, p in params.items() if p is None or p.kind != 'estimate']
        if not open_axes:
            continue
        bounds = [p.value for a, p in params.items() if a in open_axes and p is not None
                  and p.kind == 'upper_bound' and math.isfinite(p.value)]
        what = (f'only a 95 % upper bound (up to {max(bounds):.3g} {params[open_axes[0]].unit}'
                ', what the files carry)' if bounds else 'not identified')
        estimated = [a for a in axes if a not in open_axes]
        line = (f'{SHORT_RECORD} ({hours(duration_s)}) to determine {name}: '
                f'{what} on {", ".join(open_axes)}'
                + (f' ({", ".join(estimated)} estimated)' if estimated else ''))
        planned = [plans[a].param(sym) for a in open_axes if a in plans]
        planned = [q for q in planned if q is not None]
        if planned and len(planned) == len(open_axes):
            worst = max(planned, key=lambda q: q.time_s if not math.isnan(q.time_s)
                        else math.inf)
            at_least = any(q.kind in ('at_least', 'open') for q in planned)
            if math.isinf(worst.target):
                line += '; the plan sets it no target (its profile does not need it)'
            elif worst.kind == 'open' or math.isnan(worst.time_s):
                line += '; a longer record (this one cannot say how long) would'
            else:
                at_least = at_least or worst.lower_limit(duration_s)
                line += (f'; {more_total(worst.time_s, duration_s, at_least)} would (the '
                         f'time the plan gives to +-{100 * worst.target:.0f} %)')
        else:
            line += ('; a longer record would (plan it: imu-allan plan, or analyze without '
                     '--no-plan)')
        out.append(line)
    return out
