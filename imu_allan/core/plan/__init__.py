"""
"Have I recorded long enough?": the precision of each parameter now, and when.

From a fitted model (or a datasheet's numbers) the planner predicts the relative 95 %
half-width of every parameter for a record of any length of the same sensor, from the
exact covariance of the Allan curve under the model (Fisher information of the GLS fit,
:mod:`imu_allan.core.plan.precision`), the record length at which each reaches its
target (:mod:`imu_allan.core.plan.planner`), and how long a record must be to tell a
ramp from a random walk, or one Gauss-Markov process from two
(:mod:`imu_allan.core.plan.separation`).  Validation: bench/plan_validate.py and
docs/planning.md.
"""

import importlib
from typing import TYPE_CHECKING

from imu_allan.core.plan.result import (AxisPlan, hours, more_total, ParamPlan, percent,
                                        Separation)
from imu_allan.core.plan.targets import parse_targets, profile_targets, PROFILES

if TYPE_CHECKING:
    from imu_allan.core.plan.planner import (DEFAULT_TARGETS, HORIZON_S, noise_components,
                                             plan_axes, plan_fits, planning_model,
                                             REPORT_HOURS, target_of)

#: The planner (scipy, the fit's covariance) is imported on first use: the command line
#: and the node read targets and report plans without it.
_LAZY = ('DEFAULT_TARGETS', 'HORIZON_S', 'noise_components', 'plan_axes', 'plan_fits',
         'planning_model', 'REPORT_HOURS', 'target_of')


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f'{__name__}.planner'), name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')


__all__ = ['AxisPlan', 'DEFAULT_TARGETS', 'HORIZON_S', 'hours', 'more_total',
           'noise_components', 'ParamPlan', 'parse_targets', 'percent', 'plan_axes',
           'plan_fits', 'planning_model', 'PROFILES', 'profile_targets', 'REPORT_HOURS',
           'Separation', 'target_of']
