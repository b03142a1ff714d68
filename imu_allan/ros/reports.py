"""
What the node reports: diagnostic statuses (per axis, input, progress, data) and matrices.

A mixin of :class:`imu_allan.ros.node.ImuAllanNode`, whose state it reads: statuses are
named after the node (``<namespace/name>: <what>``) so two nodes never collide, and go
to /diagnostics at 1 Hz; progress is logged and published on ~/noise_parameters every
``progress_period_s`` until ``min_duration_s``.
"""

import math
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from imu_allan import AXES
from imu_allan.ros.plan_report import progress_report

#: No message for this long is reported as a WARN on /diagnostics.
NO_DATA_WARN_S = 2.0
_LEVELS = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN,
           'error': DiagnosticStatus.ERROR}


class _Reports:
    """Diagnostic statuses of the node, built from its session, counters and last fit."""

    _progress_mark: tuple[float, float]   # (wall time, duration) of the last progress log

    @property
    def hardware_id(self) -> str:
        """hardware_id of the statuses: the parameter, else the messages' frame_id."""
        return self.values['hardware_id'] or self.live.frame_id

    def _status(self, what: str, level, message: str, values: list) -> DiagnosticStatus:
        return DiagnosticStatus(name=f'{self.diag_prefix}: {what}', level=level,
                                message=message, hardware_id=self.hardware_id,
                                values=[KeyValue(key=k, value=v) for k, v in values])

    def _statuses(self, result) -> list:
        out = []
        for axis in AXES:
            level, message, values = result.axis_status(axis)
            out.append(self._status(axis, _LEVELS[level], message, values))
        return out

    def _input_status(self, session) -> DiagnosticStatus:
        """One status with the input-hygiene counters and the warnings, if any."""
        stats = session.stats
        values = [(k, str(v) if not isinstance(v, list) else ','.join(v))
                  for k, v in vars(stats).items()]
        values += [('n_buffer_dropped', str(self.live.n_buffer_dropped)),
                   ('warnings', ' | '.join(session.warnings))]
        message = (' | '.join(session.warnings) if session.warnings
                   else 'input clean: no gaps, bad stamps, bad values or motion')
        return self._status(
            'input', DiagnosticStatus.WARN if session.warnings else DiagnosticStatus.OK,
            message, values)

    def _progress_status(self, log: bool = False) -> DiagnosticStatus:
        """Return the progress status: collection before min_duration_s, then the fits."""
        s = self.session
        target = self.values['min_duration_s']
        values = [('samples', str(s.stats.n_used)), ('rate_hz', f'{s.rate_hz:.4f}'),
                  ('duration_s', f'{s.duration_s:.1f}'), ('fits', str(self.n_fits)),
                  ('warnings', ' | '.join(s.warnings))]
        if s.duration_s >= target:
            text = (f'characterising: {s.duration_s:.0f} s, {s.stats.n_used} samples at '
                    f'{s.rate_hz:.2f} Hz, {self.n_fits} fits published')
            values.append(('percent', '100.00'))
        else:
            pct = 100.0 * s.duration_s / target
            now = time.monotonic()
            wall0, dur0 = self._progress_mark
            if log:
                self._progress_mark = (now, s.duration_s)
            speed = (s.duration_s - dur0) / (now - wall0) if now > wall0 else 0.0
            eta = (target - s.duration_s) / speed if speed > 0 else math.inf
            eta_text = (f'{eta / 60:.1f} min' if math.isfinite(eta)
                        else 'unknown (no data now)')
            text = (f'collecting: {pct:.1f}% of {target:.0f} s, {s.stats.n_used} samples at '
                    f'{s.rate_hz:.2f} Hz, ETA {eta_text}')
            values += [('percent', f'{pct:.2f}'), ('eta_s', f'{eta:.0f}')]
        if self.live.n_buffer_dropped:
            text += f', {self.live.n_buffer_dropped} messages dropped by a full buffer'
        plan_text, plan_kv = progress_report(getattr(self._last_result, 'plans', {}))
        if self.collection_stopped:
            plan_text = ' | stopped collecting: every precision target met (stop_when_pinned)'
        text, values = text + plan_text, values + plan_kv
        level = DiagnosticStatus.WARN if s.warnings else DiagnosticStatus.OK
        return self._status('progress', level, text, values)

    def _data_status(self) -> DiagnosticStatus:
        """WARN while no message arrives on the input topic."""
        topic = self.subscription.topic_name
        since = time.monotonic() - (self.live.last_rx or self._started)
        if since > NO_DATA_WARN_S:
            what = 'no message yet' if self.live.last_rx is None else 'no message'
            return self._status('data', DiagnosticStatus.WARN,
                                f'{what} on {topic} for {since:.0f} s',
                                [('topic', topic), ('received', str(self.n_received))])
        return self._status('data', DiagnosticStatus.OK, f'receiving {topic}',
                            [('topic', topic), ('received', str(self.n_received))])

    def _on_diagnostics(self) -> None:
        # 1 Hz, within the aggregator's 5 s stale timeout; the last fit's per-axis
        # statuses persist between fits.
        array = DiagnosticArray(status=[self._data_status(), self._progress_status()]
                                + self._axis_statuses + [self._input_status(self.session)])
        array.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(array)

    def _progress(self) -> None:
        if self.session.duration_s >= self.values['min_duration_s']:
            # The results hold ~/noise_parameters now: the plan goes to the log (and to
            # the progress status on /diagnostics).
            if getattr(self._last_result, 'plans', None):
                self.get_logger().info(self._progress_status().message)
            return
        status = self._progress_status(log=True)
        self.get_logger().info(status.message)
        array = DiagnosticArray(status=[status, self._input_status(self.session)])
        array.header.stamp = self.get_clock().now().to_msg()
        self.pub_params.publish(array)


def _matrix_msg(matrix: np.ndarray, labels: list) -> Float64MultiArray:
    """Float64MultiArray of a square matrix; the state order is in the dimension labels."""
    n = matrix.shape[0]
    order = ','.join(labels)
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=f'rows:{order}', size=n, stride=n * n),
                      MultiArrayDimension(label=f'cols:{order}', size=n, stride=n)]
    msg.data = [float(x) for x in matrix.ravel()]
    return msg
