"""
Result types of the planner: one parameter's precision plan, one axis' plan.

Part of :mod:`imu_allan.core.plan`.
"""

import math
from typing import NamedTuple

from imu_allan.core.fit.result import json_num
from imu_allan.core.noise.words import spoken
from imu_allan.core.rules import LOWER_LIMIT_RATIO

#: Kinds of a parameter's plan.
PLAN_KINDS = ('met', 'predicted', 'at_least', 'beyond', 'open')


def hours(t_s: float) -> str:
    """Return a record length for people: '40 s', '42 min', '3.1 h', '> 1000 h', '?'."""
    if math.isnan(t_s):
        return '?'
    if math.isinf(t_s):
        return '> 1000 h'
    if t_s < 60.0:
        return f'{t_s:.0f} s'
    if t_s < 3600.0:
        return f'{t_s / 60.0:.0f} min'
    return f'{t_s / 3600.0:.2g} h' if t_s < 36000.0 else f'{t_s / 3600.0:.0f} h'


def more_total(total_s: float, duration_s: float, at_least: bool = False) -> str:
    """
    Return a time to a target as people read it: '3.2 h more (5.0 h total)'.

    The one format of every time the planner shows (plan lines, tables, node progress).

    Parameters
    ----------
    total_s : float
        Record length at which the target is met [s] (inf: beyond the horizon).
    duration_s : float
        Length of the present record [s] (0 or less: none yet, the total alone).
    at_least : bool
        Whether the time is a lower limit ('at least ...').

    """
    if math.isnan(total_s):
        return 'unknown yet'
    if math.isinf(total_s):
        return 'more than 1000 h'
    lower = 'at least ' if at_least else ''
    if duration_s <= 0:             # no record yet (a datasheet): the total is all
        return f'{lower}{hours(total_s)} total'
    more = max(total_s - duration_s, 0.0)
    return f'{lower}{hours(more)} more ({hours(total_s)} total)'


def percent(w: float, tight: bool = False) -> str:
    """
    Return a relative half-width as '+-12 %' ('n/a' when not identified).

    With ``tight`` (a target) an infinite width reads 'none' (no target).
    """
    if math.isnan(w):
        return '-'
    if math.isinf(w) and w > 0 and tight:
        return 'none'
    if math.isinf(w) or w > 10.0:
        return 'n/a'
    return f'+-{100.0 * w:.0f} %' if w >= 0.1 else f'+-{100.0 * w:.2g} %'


class ParamPlan(NamedTuple):
    """
    The precision of one parameter, now and to come.

    Attributes
    ----------
    name : str
        Reported name (N, B, T_B, K, gauss_markov.T ...).
    value : float
        The value planned with [SI]; for an upper bound, the bound.
    width_now : float
        Present relative 95 % half-width (hi - lo) / (2 value) [-]; inf for a bound or
        an unidentified parameter, NaN without a record.
    target : float
        Target relative half-width [-].
    time_s : float
        Record length at which the width reaches the target [s]; inf beyond 1000 h.
    kind : str
        'met' (target met now), 'predicted', 'at_least' (planned at an upper
        bound: a smaller true value takes longer), 'beyond' (not within 1000 h) or
        'open' (the fit reports it, but its model has no term to plan it with: K the
        record cannot constrain, T_B of a bias instability only bounded).
    widths_at : dict of float to float
        Expected relative half-width at record lengths of 1, 3 and 10 h [-].

    """

    name: str
    value: float
    width_now: float
    target: float
    time_s: float
    kind: str
    widths_at: dict

    def lower_limit(self, duration_s: float) -> bool:
        """
        Whether the time to target is a lower limit.

        Planned at an upper bound ('at_least'), or extrapolated from a record shorter
        than 1 / :data:`~imu_allan.core.rules.LOWER_LIMIT_RATIO` of it: the model has not
        seen the taus that decide it (a datasheet's plan, ``duration_s`` 0, is not).
        """
        return self.kind == 'at_least' or (
            self.kind == 'predicted' and duration_s > 0
            and self.time_s > LOWER_LIMIT_RATIO * duration_s)

    def to_json(self, duration_s: float = 0.0) -> dict:
        """Return the JSON entry (None for NaN/inf)."""
        return {'value': json_num(self.value), 'width_now': json_num(self.width_now),
                'target': json_num(self.target), 'time_s': json_num(self.time_s),
                'kind': self.kind, 'lower_limit': self.lower_limit(duration_s),
                'widths_at_h': {f'{h:g}': json_num(w) for h, w in self.widths_at.items()}}


class Separation(NamedTuple):
    """
    Whether (and when) the record tells two explanations apart.

    Attributes
    ----------
    question : str
        'ramp or random walk' or 'one or two Gauss-Markov'.
    lambda_now : float
        Present non-centrality of the test against the rival [-].
    time_s : float
        Record length at which it reaches 10.5 (90 % power at 5 %) [s].
    separated : bool
        Whether the present record separates them.

    """

    question: str
    lambda_now: float
    time_s: float
    separated: bool

    def to_json(self) -> dict:
        """Return the JSON entry."""
        return {'lambda_now': json_num(self.lambda_now), 'time_s': json_num(self.time_s),
                'separated': self.separated}


class AxisPlan(NamedTuple):
    """
    The plan of one axis.

    Attributes
    ----------
    duration_s : float
        Length of the record the model came from [s] (0: a datasheet).
    params : tuple of ParamPlan
    separations : tuple of Separation
    caveat : str
        Why the times may be too short ('' when the model behind them is trusted): the
        fitted model does not explain its curve, or the fit is not trusted.  The times
        assume the model holds; a record that needs more terms takes longer.

    """

    duration_s: float
    params: tuple
    separations: tuple
    caveat: str = ''

    def remaining_s(self) -> float:
        """
        Further recording until every target is met [s].

        inf when a target is beyond 1000 h; NaN when only an upper bound is known of a
        parameter the record should already have resolved at that bound.  With a
        parameter planned at a bound the time is a lower limit.
        """
        times = [p.time_s for p in self.params if p.kind != 'met']
        if not times:
            return 0.0
        if any(math.isnan(t) for t in times):
            return math.nan
        return max(max(times) - self.duration_s, 0.0)

    def lower_limit(self) -> bool:
        """Whether the time to every target is a lower limit (a parameter's is)."""
        return any(p.kind != 'met' and p.lower_limit(self.duration_s) for p in self.params)

    def all_met(self) -> bool:
        """Whether every parameter meets its target now."""
        return all(p.kind == 'met' for p in self.params)

    def param(self, name: str) -> ParamPlan | None:
        """Return the plan of one parameter, None when absent."""
        return next((p for p in self.params if p.name == name), None)

    def to_json(self) -> dict:
        """Return the JSON entry of the axis."""
        return {'duration_s': self.duration_s,
                'params': {p.name: p.to_json(self.duration_s) for p in self.params},
                'separations': {s.question: s.to_json() for s in self.separations},
                'remaining_s': json_num(self.remaining_s()),
                'lower_limit': self.lower_limit(), 'caveat': self.caveat}

    def progress_line(self) -> str:
        """One line: which parameters meet their target, and the time to each of the rest."""
        # A parameter without a target (not in the profile) is not listed.
        met = [spoken(p.name) for p in self.params
               if p.kind == 'met' and not math.isinf(p.target)]
        rest = []
        for p in self.params:
            if p.kind == 'met':
                continue
            if p.kind == 'at_least' and math.isnan(p.time_s):
                rest.append(f'{spoken(p.name)} only bounded yet')
                continue
            if p.kind == 'open':
                rest.append(f'{spoken(p.name)} not constrained yet')
                continue
            when = more_total(p.time_s, self.duration_s, p.lower_limit(self.duration_s))
            rest.append(f'{spoken(p.name)} {when}')
        text = f'met: {", ".join(met) or "none"}'
        text += '; ' + ', '.join(rest) if rest else ''
        return text + (' (model does not hold: times may be short)' if self.caveat else '')

    def table_lines(self) -> list:
        """Human table: parameter, width now, target, record length, widths at 1/3/10 h."""
        lines = [f'  {"param":<24} {"now":>10} {"target":>8} {"record to target":>33} '
                 f'{"at 1 h":>10} {"at 3 h":>10} {"at 10 h":>10}']
        for p in self.params:
            need = more_total(p.time_s, self.duration_s, p.lower_limit(self.duration_s))
            if p.kind == 'met':
                need = 'no target' if math.isinf(p.target) else 'met now'
            elif p.kind == 'at_least' and math.isnan(p.time_s):
                need = 'bound only'
            elif p.kind == 'open':
                need = 'open'
            cells = [percent(p.widths_at.get(h, math.nan)) for h in (1.0, 3.0, 10.0)]
            lines.append(f'  {spoken(p.name):<24} {percent(p.width_now):>10} '
                         f'{percent(p.target, tight=True):>8} {need:>33} ' + ' '.join(
                             f'{c:>10}' for c in cells))
        for s in self.separations:
            state = ('separated now' if s.separated
                     else 'not separated yet, although a record of this length should'
                     if 0 < s.time_s <= self.duration_s
                     else 'needs ' + more_total(s.time_s, self.duration_s))
            lines.append(f'  {s.question}: {state}')
        if self.caveat:
            lines.append(f'  caveat: {self.caveat}')
        return lines
