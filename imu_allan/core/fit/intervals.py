"""
Profile-likelihood intervals of one fitted parameter at fixed weights.

The interval is the set of values whose re-optimised chi-square stays within a
threshold of the minimum (profile likelihood, Venzon & Moolgavkar, Applied Statistics
37, 1988), searched from the estimate outwards.
"""

import math
from typing import Sequence

from imu_allan.core.fit.solver import _Data, fit_fixed_weights, Fix, Slot, Solution

#: First trial of a profile interval: 2 % from the estimate (then a quadratic guess).
_FIRST_STEP = 0.02
#: A profile still below its threshold 1e7 x away from the estimate is unbounded there.
_MAX_REACH = math.log(1e7)


def _profile_interval(data: _Data, slots: Sequence[Slot], sol: Solution, slot: int,
                      symbol: str, value: float, threshold: float,
                      hard: tuple = (0.0, math.inf)) -> tuple[float, float]:
    """
    95 % profile interval of one parameter at fixed weights: {v : J(v) - J_min <= thr}.

    J(v) is the GLS chi-square minimised over every other parameter with this one held
    at v (non-negative coefficients, nonlinear parameters searched again), so the
    interval follows the curvature and the bounds of the real problem, not a quadratic
    approximation.  ``threshold`` is F(0.95; 1, dof) times the dispersion
    max(1, J_min / dof) (see :func:`fit_axis`).  ``hard`` are the limits of the
    parameter (a search range for nonlinear ones); a side that reaches one returns it.
    """
    target = sol.j + threshold

    last = {'phi': sol.phi}

    def excess(v):
        fit = fit_fixed_weights(data, slots, last['phi'], Fix(slot, symbol, v), local=True)
        last['phi'] = fit.phi
        return fit.j - target

    def crossing(a: float, fa: float, b: float, fb: float) -> float:
        # Illinois regula falsi in log(v) (or v when the bracket touches 0), from the
        # bracket values already known: robust where the profile, found by local
        # searches, is not exactly monotone; it stops at 0.2 % of v, or where J is
        # within 1 % of the threshold of its target (the end then moves by < 0.5 %
        # of the half-width).
        logs = a > 0 and b > 0
        xa, xb = (math.log(a), math.log(b)) if logs else (a, b)
        side = 0
        for _ in range(12):
            xc = xb - fb * (xb - xa) / (fb - fa) if fb != fa else 0.5 * (xa + xb)
            fc = excess(math.exp(xc) if logs else xc)
            if abs(fc) < 0.01 * threshold:
                return math.exp(xc) if logs else xc
            if fc > 0:
                xb, fb = xc, fc
                if side == 1:
                    fa *= 0.5
                side = 1
            else:
                xa, fa = xc, fc
                if side == -1:
                    fb *= 0.5
                side = -1
            if abs(xb - xa) < (2e-3 if logs else 2e-3 * max(abs(xa), abs(xb))):
                break
        x = 0.5 * (xa + xb)
        return math.exp(x) if logs else x

    ends = []
    for direction in (-1.0, 1.0):
        last['phi'] = sol.phi
        inner, f_inner = value, -threshold
        limit = hard[0] if direction < 0 else hard[1]
        end = limit
        reach = _FIRST_STEP  # distance |log(v / value)| of the next trial
        while reach < _MAX_REACH:
            outer = value * math.exp(direction * reach)
            if (direction < 0 and outer <= limit) or (direction > 0 and outer >= limit):
                if math.isfinite(limit):
                    f_limit = excess(limit) if limit > 0 else excess(0.0)
                    if f_limit > 0:
                        end = crossing(inner, f_inner, limit, f_limit)
                break
            f_outer = excess(outer)
            if f_outer > 0:
                end = crossing(inner, f_inner, outer, f_outer)
                break
            inner, f_inner = outer, f_outer
            # The profile is about quadratic in log(v) near its minimum: aim just beyond
            # the predicted crossing, at most 4x further out.
            rise = f_outer + threshold
            aim = reach * math.sqrt(threshold / rise) if rise > 0 else math.inf
            reach = min(max(1.1 * aim, 1.2 * reach), 4.0 * reach)
        ends.append(float(end))
    return ends[0], ends[1]
