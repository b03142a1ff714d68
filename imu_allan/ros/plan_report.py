"""
What the node says about its plan: per axis, what meets its target, and when the rest will.

No rclpy here (the node turns the key/value pairs into KeyValue messages): the plans
come with the analysis (:func:`imu_allan.pipeline.analysis.analyze` with ``plan``,
:mod:`imu_allan.core.plan`).  The node calls :func:`plan_values` where it builds the
~/noise_parameters statuses, :func:`progress_report` where it reports progress, and
:func:`targets_met` after each fit when ``stop_when_met`` is set.
"""

import math

from imu_allan.core.plan.result import AxisPlan, hours


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
        '' without plans; else e.g. ' | gyro_x met: N; B, T_B in 2.1 h more | ...',
        or ' | every target met' when all axes meet them; the axes whose model does not
        hold are named at the end.
    values : list of (str, str)
        ``<axis>_met`` (the parameters that meet their target), ``<axis>_remaining_s`` per axis and
        ``plan_remaining_s`` (the longest).

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
    remaining = [p.remaining_s() for p in plans.values()]
    longest = math.nan if any(math.isnan(r) for r in remaining) else max(remaining)
    values.append(('plan_remaining_s', _num(longest)))
    caveats = [axis for axis, plan in plans.items() if plan.caveat]
    tail = (f' | model does not hold on {", ".join(caveats)}: times may be short'
            if caveats else '')
    if not parts:
        return ' | every target met' + tail, values
    when = f'in {hours(longest)} more' if not math.isnan(longest) else 'later (bounds only)'
    return f' | every target met {when} | ' + ' | '.join(parts) + tail, values


def targets_met(plans: dict, n_axes_fitted: int) -> bool:
    """
    Whether every fitted axis has a plan and meets every target now.

    Not while the model of an axis does not hold (its plan's caveat): its widths assume
    a model that a longer record will likely change.
    """
    return bool(plans) and len(plans) >= n_axes_fitted and all(
        p.all_met() and not p.caveat for p in plans.values())
