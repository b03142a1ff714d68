"""
What the node reports: diagnostic statuses (per axis, input, progress, data) and matrices.

:class:`NodeReports` is a plain object the node owns: it reads the node's input
(:class:`~imu_allan.ros.live.LiveInput`) and parameter values, keeps the count of fits and
the last fit's per-axis statuses, and builds the statuses; the node stamps and publishes
them.  Statuses are named after the node (``<namespace/name>: <what>``) so two nodes
never collide, and go to /diagnostics at 1 Hz; progress is logged and published on
~/noise_parameters every ``progress_period_s`` until ``min_duration_s``.
"""

import math
import time

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
import numpy as np
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from imu_allan import AXES
from imu_allan.ros.live import LiveInput
from imu_allan.ros.plan_report import (eta_text, plan_values, progress_report, targets_label,
                                       toward_targets)

#: No message for this long is reported as a WARN on /diagnostics.
NO_DATA_WARN_S = 2.0
_LEVELS = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN,
           'error': DiagnosticStatus.ERROR}


class NodeReports:
    """
    Diagnostic statuses of one node, built from its input, parameters and last fit.

    Parameters
    ----------
    prefix : str
        The node's fully qualified name without the leading slash (status names).
    values : dict
        The node's parameter values (read at every use: changes apply at once).
    live : LiveInput
        The node's input side.
    topic : str
        The Imu topic the node listens to.

    """

    def __init__(self, prefix: str, values: dict, live: LiveInput, topic: str):
        self.prefix, self.values, self.live, self.topic = prefix, values, live, topic
        self.started = time.monotonic()
        self.n_fits = 0
        #: The last fit's per-axis statuses; they persist between fits.
        self.axis_statuses: list[DiagnosticStatus] = []
        # (wall time, duration) of the last progress log: the ETA's speed.
        self._progress_mark = (self.started, 0.0)
        #: The last plan per axis (:mod:`imu_allan.core.plan`), set by the node.
        self.plans: dict = {}
        #: Set when stop_when_met stopped the collection (cleared by ~/reset).
        self.collection_stopped = False

    @property
    def hardware_id(self) -> str:
        """hardware_id of the statuses: the parameter, else the messages' frame_id."""
        return self.values['hardware_id'] or self.live.frame_id

    def status(self, what: str, level, message: str, values: list) -> DiagnosticStatus:
        """Return one status named ``<prefix>: <what>`` with (key, value) string pairs."""
        return DiagnosticStatus(name=f'{self.prefix}: {what}', level=level,
                                message=message, hardware_id=self.hardware_id,
                                values=[KeyValue(key=k, value=v) for k, v in values])

    def fitted(self, result, view) -> list[DiagnosticStatus]:
        """Count a published fit; return its per-axis statuses plus the input status."""
        self.n_fits += 1
        self.axis_statuses = []
        for axis in AXES:
            level, message, values = result.axis_status(axis)
            values = list(values) + plan_values(result.plans.get(axis))
            self.axis_statuses.append(self.status(axis, _LEVELS[level], message, values))
        return self.axis_statuses + [self.input_status(view)]

    def clear(self) -> None:
        """Forget the last fit's statuses and plans (after ~/reset)."""
        self.axis_statuses = []
        self.plans = {}
        self.collection_stopped = False

    def input_status(self, session) -> DiagnosticStatus:
        """One status with the input-hygiene counters and the warnings, if any."""
        stats = session.stats
        values = [(k, str(v) if not isinstance(v, list) else ','.join(v))
                  for k, v in vars(stats).items()]
        values += [('n_buffer_dropped', str(self.live.n_buffer_dropped)),
                   ('n_undecodable', str(self.live.n_undecodable)),
                   ('warnings', ' | '.join(session.warnings))]
        problems = list(session.warnings)
        if self.live.n_undecodable:
            problems.append(f'{self.live.n_undecodable} messages were not decodable Imu '
                            'messages and were dropped')
        message = (' | '.join(problems) if problems
                   else 'input clean: no gaps, bad stamps, bad values or motion')
        return self.status('input', DiagnosticStatus.WARN if problems else DiagnosticStatus.OK,
                           message, values)

    def progress_status(self, log: bool = False) -> DiagnosticStatus:
        """Return the progress status: collection before min_duration_s, then the fits."""
        s = self.live.session
        target = self.values['min_duration_s']
        values = [('samples', str(s.stats.n_used)), ('rate_hz', f'{s.rate_hz:.4f}'),
                  ('duration_s', f'{s.duration_s:.1f}'), ('fits', str(self.n_fits)),
                  ('warnings', ' | '.join(s.warnings))]
        now = time.monotonic()
        wall0, dur0 = self._progress_mark
        if log:
            self._progress_mark = (now, s.duration_s)
        speed = (s.duration_s - dur0) / (now - wall0) if now > wall0 else 0.0
        if self.plans and not self.collection_stopped:
            # Progress and ETA toward the profile's targets, as the last plan says.
            head, pct, eta = toward_targets(self.values, self.plans, s.duration_s, speed)
            text = (f'collecting: {s.duration_s:.0f} s, {s.stats.n_used} samples at '
                    f'{s.rate_hz:.2f} Hz; {head}')
            values += [('percent', f'{pct:.2f}'), ('eta_s', f'{eta:.0f}')]
        elif s.duration_s >= target:
            text = (f'characterising: {s.duration_s:.0f} s, {s.stats.n_used} samples at '
                    f'{s.rate_hz:.2f} Hz, {self.n_fits} fits published')
            values.append(('percent', '100.00'))
        else:
            pct = 100.0 * s.duration_s / target
            eta = (target - s.duration_s) / speed if speed > 0 else math.inf
            text = (f'collecting: {pct:.1f}% of min_duration_s {target:.0f} s (no plan yet), '
                    f'{s.stats.n_used} samples at {s.rate_hz:.2f} Hz, ETA {eta_text(eta)}')
            values += [('percent', f'{pct:.2f}'), ('eta_s', f'{eta:.0f}')]
        if s.settling is not None:
            held_s, window_s = s.settling
            text += (f', waiting for the output to settle after power-on ({held_s / 60:.1f} '
                     f'of {window_s / 60:.0f} min held)')
            values.append(('warmup_held_s', f'{held_s:.1f}'))
        if self.live.n_buffer_dropped:
            text += f', {self.live.n_buffer_dropped} messages dropped by a full buffer'
        plan_text, plan_kv = progress_report(self.plans)
        if self.collection_stopped:
            plan_text = (f' | stopped collecting: {targets_label(self.values)} met on every '
                         'axis (stop_when_met)')
        text, values = text + plan_text, values + plan_kv
        level = DiagnosticStatus.WARN if s.warnings else DiagnosticStatus.OK
        if s.unit_problem is not None:      # nothing is published until ~/reset
            text, level = f'not collecting: {s.unit_problem}', DiagnosticStatus.ERROR
        return self.status('progress', level, text, values)

    def data_status(self) -> DiagnosticStatus:
        """WARN while no message arrives on the input topic."""
        since = time.monotonic() - (self.live.last_rx or self.started)
        values = [('topic', self.topic), ('received', str(self.live.n_received))]
        if since > NO_DATA_WARN_S:
            what = 'no message yet' if self.live.last_rx is None else 'no message'
            return self.status('data', DiagnosticStatus.WARN,
                               f'{what} on {self.topic} for {since:.0f} s', values)
        return self.status('data', DiagnosticStatus.OK, f'receiving {self.topic}', values)

    def diagnostics(self) -> list[DiagnosticStatus]:
        """Return the /diagnostics statuses: data, progress, the last fit's axes, input."""
        session = self.live.session
        return ([self.data_status(), self.progress_status()] + self.axis_statuses
                + [self.input_status(session)])

    def progress(self) -> list[DiagnosticStatus]:
        """
        Progress and input statuses while collecting (empty once min_duration_s is met).

        Later the fits' statuses own ~/noise_parameters (its last message is what a late
        subscriber gets); the progress, with the plan's ETA, stays on /diagnostics.
        """
        session = self.live.session
        if session.duration_s >= self.values['min_duration_s']:
            return []
        return [self.progress_status(log=True), self.input_status(session)]


def matrix_msg(matrix: np.ndarray, labels: list) -> Float64MultiArray:
    """Float64MultiArray of a square matrix; the state order is in the dimension labels."""
    n = matrix.shape[0]
    order = ','.join(labels)
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=f'rows:{order}', size=n, stride=n * n),
                      MultiArrayDimension(label=f'cols:{order}', size=n, stride=n)]
    msg.data = [float(x) for x in matrix.ravel()]
    return msg
