"""
What the node says about its plan: per axis, what meets its target, and when the rest will.

No rclpy here (the node turns the key/value pairs into KeyValue messages): the plans
come with the analysis (:func:`imu_allan.pipeline.analysis.analyze` with ``plan``,
:mod:`imu_allan.core.plan`).  The node calls :func:`plan_values` where it builds the
~/noise_parameters statuses, :func:`progress_report` where it reports progress, and
:func:`targets_met` after each fit when ``stop_when_met`` is set.
"""

import math

from imu_allan.core.plan.result import AxisPlan, more_total
from imu_allan.core.plan.targets import profile_targets, targeted

#: The node's first plan comes after this long, or one plan_period_s if shorter [s]: a
#: user asks "how long?" in the first minutes, and a minute of data already bounds the
#: answer from below (the plan says 'at least' while it extrapolates).
FIRST_PLAN_S = 60.0


def plan_due(values: dict, since_s: float, planned: bool) -> bool:
    """
    Whether the node should plan now.

    Parameters
    ----------
    values : dict
        The node's parameter values (plan_period_s).
    since_s : float
        Wall time since the last plan, or since the start or ~/reset [s].
    planned : bool
        Whether a plan was made since the start or ~/reset.

    """
    period = values['plan_period_s']
    if period <= 0:
        return False
    return since_s >= (period if planned else min(period, FIRST_PLAN_S))


def node_targets(values: dict) -> dict:
    """Return the node's targets: plan_profile, with plan_targets over it."""
    return profile_targets(values['plan_profile'], values['plan_targets'])


def targets_label(values: dict) -> str:
    """Return e.g. 'vio targets (N, K)' for the progress line and the stop message."""
    return f'{values["plan_profile"]} targets ({", ".join(targeted(node_targets(values)))})'


def remaining(plans: dict) -> tuple[float, float, bool]:
    """
    Return the record time still needed, the record at that time, and 'at least'.

    Returns
    -------
    more_s : float
        The longest further recording over the axes that have a time [s] (NaN when
        none has: bounds only).
    total_s : float
        The record length then [s].
    at_least : bool
        Whether that time is a lower limit (an axis' plan extrapolates, has a bound or
        has no time yet).

    """
    more = [p.remaining_s() for p in plans.values()]
    known = [r for r in more if not math.isnan(r)]
    more_s = max(known) if known else math.nan
    duration_s = max(p.duration_s for p in plans.values())
    at_least = len(known) < len(more) or any(p.lower_limit() for p in plans.values())
    return more_s, duration_s + more_s, at_least


def toward_targets(values: dict, plans: dict, duration_s: float,
                   speed: float) -> tuple[str, float, float]:
    """
    Return the node's progress toward its profile's targets, as the last plan says.

    Parameters
    ----------
    values : dict
        The node's parameter values (plan_profile, plan_targets).
    plans : dict of str to AxisPlan
        The last plans (not empty).
    duration_s : float
        The record's length now [s] (the plans may be older).
    speed : float
        Record seconds per wall second lately [-] (0: no data now).

    Returns
    -------
    text : str
        e.g. 'vio targets (N, K): at least 9 min more (16 min total), ETA 2.1 min'.
    percent : float
        The share of the record needed that is recorded [%] (0 while unknown).
    eta_s : float
        Wall time until then [s] (inf while unknown).

    """
    more_s, total_s, at_least = remaining(plans)
    met, known = more_s == 0, not math.isnan(more_s)
    more_s = max(total_s - duration_s, 0.0) if known else math.nan
    pct = 100.0 if met else 100.0 * min(duration_s / total_s, 1.0) if known else 0.0
    eta = 0.0 if met else more_s / speed if speed > 0 and known else math.inf
    when = ('met' if met else 'not yet known (bounds only)' if not known
            else f'{more_total(total_s, duration_s, at_least)}, ETA {eta_text(eta)}')
    return f'{targets_label(values)}: {when}', pct, eta


def eta_text(eta_s: float) -> str:
    """Return a wall-clock ETA for people ('unknown (no data now)' without a speed)."""
    if not math.isfinite(eta_s):
        return 'unknown (no data now)'
    return f'{eta_s / 60:.1f} min' if eta_s < 3600.0 else f'{eta_s / 3600:.1f} h'


def _num(x: float) -> str:
    return f'{x:.6g}' if math.isfinite(x) else ('inf' if x > 0 else 'nan')


def plan_values(plan: AxisPlan | None) -> list:
    """
    Key/value pairs of one axis' plan for its diagnostic status.

    Per parameter P: ``P_width_now`` and ``P_target`` (relative 95 % half-widths),
    ``P_time_to_target_s`` (record length at which the target is met) and ``P_plan``
    (met, predicted, at_least, beyond or open); then ``plan_remaining_s``, ``plan`` (one
    line) and, where the model behind the plan does not hold, ``plan_caveat``.  Empty
    without a plan.
    """
    if plan is None:
        return []
    out = []
    for p in plan.params:
        out += [(f'{p.name}_width_now', _num(p.width_now)), (f'{p.name}_target', _num(p.target)),
                (f'{p.name}_time_to_target_s', _num(p.time_s)), (f'{p.name}_plan', p.kind)]
    for s in plan.separations:
        key = s.question.replace(' ', '_')
        out.append((f'{key}_time_s', _num(s.time_s)))
    out += [('plan_remaining_s', _num(plan.remaining_s())), ('plan', plan.progress_line())]
    return out + ([('plan_caveat', plan.caveat)] if plan.caveat else [])


def progress_report(plans: dict) -> tuple[str, list]:
    """
    Return the plan part of a progress report: one text and key/value pairs.

    Parameters
    ----------
    plans : dict of str to AxisPlan
        The last analysis' plans (may be empty).

    Returns
    -------
    text : str
        '' without plans; else e.g. ' | every target met in at least 2.1 h more (2.3 h
        total) | gyro_x met: N; K at least 2.1 h more (2.3 h total) | ...',
        or ' | every target met' when all axes meet them; the axes whose model does not
        hold are named at the end.
    values : list of (str, str)
        ``<axis>_met`` (the parameters that meet their target), ``<axis>_remaining_s``
        per axis, ``plan_remaining_s`` (the longest) and ``plan_lower_limit`` (whether
        that time is a lower limit).

    """
    if not plans:
        return '', []
    values = []
    parts = []
    for axis, plan in plans.items():
        met = [p.name for p in plan.params if p.kind == 'met']
        values += [(f'{axis}_met', ','.join(met)),
                   (f'{axis}_remaining_s', _num(plan.remaining_s()))]
        if not plan.all_met():
            parts.append(f'{axis} {plan.progress_line()}')
    longest = remaining(plans)[0]
    values.append(('plan_remaining_s', _num(longest)))
    caveats = [axis for axis, plan in plans.items() if plan.caveat]
    tail = (f' | model does not hold on {", ".join(caveats)}: times may be short'
            if caveats else '')
    if not parts:
        return ' | every target met' + tail, values
    more_s, total_s, at_least = remaining(plans)
    when = (f'in {more_total(total_s, total_s - more_s, at_least)}'
            if not math.isnan(more_s) else 'later: bounds only yet')
    values.append(('plan_lower_limit', str(at_least).lower()))
    return f' | every target met {when} | ' + ' | '.join(parts) + tail, values


def targets_met(plans: dict, n_axes_fitted: int) -> bool:
    """
    Whether every fitted axis has a plan and meets every target now.

    Not while the model of an axis does not hold (its plan's caveat): its widths assume
    a model that a longer record will likely change.
    """
    return bool(plans) and len(plans) >= n_axes_fitted and all(
        p.all_met() and not p.caveat for p in plans.values())
