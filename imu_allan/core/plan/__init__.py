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

from typing import Mapping

from imu_allan.core.noise.model import TERMS
from imu_allan.core.noise.params import AxisNoise
from imu_allan.core.plan.planner import (DEFAULT_TARGETS, HORIZON_S, plan_axes, planning_model,
                                         REPORT_HOURS, target_of)
from imu_allan.core.plan.result import AxisPlan, hours, ParamPlan, percent, Separation


def noise_components(noise: AxisNoise) -> list:
    """
    The (label, coef, phi) components of an axis model (a datasheet or parameter file).

    Parameters
    ----------
    noise : AxisNoise
        The model, SI.

    Returns
    -------
    list of (str, float, tuple)
        As ``AxisFit.components``.

    """
    out = []
    if noise.Q:
        out.append(('quantization', noise.Q ** 2, ()))
    if noise.N:
        out.append(('white', noise.N ** 2, ()))
    if noise.B and noise.T_B:
        out.append(('bias_instability', TERMS['bias_instability'].to_coef(noise.B, noise.T_B),
                    (noise.T_B,)))
    elif noise.B:
        out.append(('flicker', noise.B ** 2, ()))
    for i, gm in enumerate(g for g in noise.gauss_markov if g.B):
        label = 'gauss_markov' if i == 0 else f'gauss_markov_{i + 1}'
        out.append((label, TERMS['gauss_markov'].to_coef(gm.B, gm.T), (gm.T,)))
    if noise.K:
        out.append(('random_walk', noise.K ** 2, ()))
    if noise.R:
        out.append(('rate_ramp', noise.R ** 2, ()))
    for i, s in enumerate(s for s in noise.sinusoids if s.A):
        out.append(('sinusoid' if i == 0 else f'sinusoid_{i + 1}', s.A ** 2, (s.f0_hz,)))
    return out


def plan_fits(fits: Mapping, rate_hz: float, duration_s: float,
              targets: Mapping[str, float] | None = None) -> dict:
    """
    Plan the axes of an analysis: per axis with a fit, its :class:`AxisPlan`.

    Parameters
    ----------
    fits : mapping of str to AxisFit or None
        The fits per axis.
    rate_hz : float
        Sample rate [Hz].
    duration_s : float
        Length of the analysed record [s].
    targets : mapping of str to float, optional
        Target relative half-widths by parameter (defaults :data:`DEFAULT_TARGETS`).

    Returns
    -------
    dict of str to AxisPlan

    """
    models = {a: planning_model(f.components, f.optimised) for a, f in fits.items()
              if f is not None and f.components}
    present = {a: fits[a].optimised for a in models}
    return plan_axes(models, rate_hz, duration_s, targets, present)


__all__ = ['AxisPlan', 'DEFAULT_TARGETS', 'HORIZON_S', 'hours', 'noise_components',
           'ParamPlan', 'percent', 'plan_axes', 'plan_fits', 'planning_model', 'REPORT_HOURS',
           'Separation', 'target_of']
