"""
imu_allan_node: live six-axis IMU noise characterisation beside a stationary robot.

Thin by design: the subscription callback only appends the serialized message to a
buffer; a timer decodes the buffer in one vectorised step and feeds the pipeline
:class:`~imu_allan.pipeline.Session` that the offline mode uses too; other timers fit,
publish, report progress and checkpoint.
"""

from collections import deque
import math
import os
from pathlib import Path
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String
from std_srvs.srv import Trigger

from imu_allan import AXES
from imu_allan.analysis import analyze
from imu_allan.bag_reader import decode_imu_cdr
from imu_allan.errors import InputError
from imu_allan.node_params import BY_NAME, PARAMS, session_config
from imu_allan.pipeline import Session
from imu_allan.report import write_outputs

CHECKPOINT = 'checkpoint.npz'
#: Parameters that shape the session: fixed while it runs (change them and ~/reset).
_SESSION_PARAMS = {'rate_hz', 'qos_depth', 'qos_reliability', 'max_buffer_messages',
                   'output_dir', 'resume', 'publish_imu_with_covariance'}


def _descriptor(p) -> ParameterDescriptor:
    d = ParameterDescriptor(description=f'{p.description} [{p.unit}]' if p.unit
                            else p.description,
                            read_only=p.name in _SESSION_PARAMS)
    if p.value_type is float and p.limits:
        d.floating_point_range = [FloatingPointRange(from_value=float(p.limits[0]),
                                                     to_value=float(p.limits[1]), step=0.0)]
    elif p.value_type is int and p.limits:
        d.integer_range = [IntegerRange(from_value=int(p.limits[0]),
                                        to_value=int(p.limits[1]), step=1)]
    elif p.value_type is str and p.limits:
        d.additional_constraints = 'one of: ' + ', '.join(p.limits)
    return d


def _result_qos() -> QoSProfile:
    # Late subscribers get the last result.
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      history=HistoryPolicy.KEEP_LAST)


class ImuAllanNode(Node):
    """Subscribe to sensor_msgs/Imu, characterise its noise, publish the results."""

    def __init__(self, **kwargs):
        super().__init__('imu_allan', **kwargs)
        for p in PARAMS:
            self.declare_parameter(p.name, p.default, _descriptor(p))
        self.values = {p.name: self.get_parameter(p.name).value for p in PARAMS}
        for name, value in self.values.items():
            why = BY_NAME[name].check(value)
            if why:
                raise InputError(f'invalid parameter: {why}')
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.output_dir = Path(os.path.expanduser(self.values['output_dir']))
        self._lock = threading.Lock()
        self._buffer: deque = deque()
        self.n_received = 0
        self._n_buffer_dropped = 0
        self._last_result = None
        self._start_wall = time.monotonic()
        self.session = self._new_session(resume=self.values['resume'])

        qos = QoSProfile(
            depth=self.values['qos_depth'], history=HistoryPolicy.KEEP_LAST,
            durability=DurabilityPolicy.VOLATILE,
            reliability=(ReliabilityPolicy.BEST_EFFORT
                         if self.values['qos_reliability'] == 'best_effort'
                         else ReliabilityPolicy.RELIABLE))
        self._input_group = MutuallyExclusiveCallbackGroup()
        self._work_group = MutuallyExclusiveCallbackGroup()
        self.subscription = self.create_subscription(
            Imu, 'imu', self._on_imu, qos, raw=True, callback_group=self._input_group,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self.pub_params = self.create_publisher(DiagnosticArray, '~/noise_parameters',
                                                _result_qos())
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.pub_q = self.create_publisher(Float64MultiArray, '~/kalman/process_noise',
                                           _result_qos())
        self.pub_r = self.create_publisher(Float64MultiArray, '~/kalman/measurement_noise',
                                           _result_qos())
        self.pub_kalibr = self.create_publisher(String, '~/kalibr_imu_yaml', _result_qos())
        self.pub_imu = None
        if self.values['publish_imu_with_covariance']:
            self.pub_imu = self.create_publisher(Imu, '~/imu_with_covariance', qos)
        self.create_service(Trigger, '~/reset', self._on_reset, callback_group=self._work_group)
        self.create_service(Trigger, '~/save', self._on_save, callback_group=self._work_group)
        self._make_timers()
        self.get_logger().info(
            f'listening on {self.subscription.topic_name} '
            f'({self.values["qos_reliability"]}, depth {self.values["qos_depth"]}); '
            f'results after {self.values["min_duration_s"]:.0f} s of stationary data; '
            f'files in {self.output_dir}')

    # ------------------------------------------------------------- set-up
    def _make_timers(self) -> None:
        self._period_timers = {
            key: self.create_timer(max(self.values[f'{key}_period_s'], 1.0), callback,
                                   callback_group=self._work_group)
            for key, callback in (('process', self._process), ('publish', self._publish),
                                  ('progress', self._progress),
                                  ('checkpoint', self._checkpoint))}
        for key in self._period_timers:
            self._set_period(key, self.values[f'{key}_period_s'])

    def _set_period(self, key: str, period_s: float) -> None:
        timer = self._period_timers[key]
        if period_s <= 0:   # checkpoint_period_s = 0 disables checkpoints
            timer.cancel()
            return
        timer.timer_period_ns = int(period_s * 1e9)
        if timer.is_canceled():
            timer.reset()

    def _on_set_parameters(self, params) -> SetParametersResult:
        for p in params:
            spec = BY_NAME.get(p.name)
            why = spec.check(p.value) if spec else None
            if why:
                return SetParametersResult(successful=False, reason=why)
        for p in params:
            if p.name in BY_NAME:
                self.values[p.name] = p.value
                key = p.name.removesuffix('_period_s')
                if key in getattr(self, '_period_timers', {}):
                    self._set_period(key, p.value)
        # Input-check settings apply to the next session (~/reset).
        return SetParametersResult(successful=True)

    def _warn(self, text: str) -> None:
        self.get_logger().warning(text)

    def _new_session(self, resume: bool) -> Session:
        config = session_config(self.values)
        path = self.output_dir / CHECKPOINT
        if resume and path.exists():
            try:
                session = Session.load_state(path, config, on_warning=self._warn)
                self.get_logger().info(
                    f'resumed from {path}: {session.stats.n_used} samples, '
                    f'{session.duration_s / 3600:.2f} h at {session.rate_hz:.2f} Hz')
                return session
            except InputError as exc:
                kept = path.with_name(f'checkpoint.{time.strftime("%Y%m%d-%H%M%S")}.npz')
                os.replace(path, kept)
                self.get_logger().warning(f'not resuming: {exc}; old state kept as {kept}')
        elif resume:
            self.get_logger().info(f'resume requested but {path} does not exist: starting fresh')
        return Session(config, on_warning=self._warn)

    # ----------------------------------------------------------- callbacks
    def _on_imu(self, raw: bytes) -> None:
        self.n_received += 1
        if len(self._buffer) >= self.values['max_buffer_messages']:
            self._buffer.popleft()
            self._n_buffer_dropped += 1
        self._buffer.append(raw)

    def _process(self) -> None:
        n = len(self._buffer)
        if n == 0:
            return
        raws = [self._buffer.popleft() for _ in range(n)]
        try:
            stamp_ns, samples = decode_imu_cdr(raws)
        except InputError as exc:
            self.get_logger().error(f'undecodable Imu messages dropped: {exc}')
            return
        with self._lock:
            self.session.add(stamp_ns, samples)
        if self.pub_imu is not None and self._last_result is not None:
            cov = self._last_result.imu_covariances()
            for raw in raws:
                msg = deserialize_message(raw, Imu)
                msg.angular_velocity_covariance = cov['angular_velocity_covariance']
                msg.linear_acceleration_covariance = cov['linear_acceleration_covariance']
                self.pub_imu.publish(msg)

    @property
    def last_result(self):
        """Return the latest published AnalysisResult, or None."""
        return self._last_result

    def _publish(self) -> None:
        if self.session.duration_s >= self.values['min_duration_s']:
            self.publish_now()

    def publish_now(self) -> None:
        """Fit the data so far and publish every result topic."""
        self._process()
        with self._lock:
            result = analyze(self.session, source=self.subscription.topic_name)
        if result is None:
            return
        self._last_result = result
        statuses = self._statuses(result)
        stamp = self.get_clock().now().to_msg()
        array = DiagnosticArray(status=statuses)
        array.header.stamp = stamp
        self.pub_params.publish(array)
        self.pub_diag.publish(array)
        self.pub_q.publish(_matrix_msg(*result.process_noise()))
        self.pub_r.publish(_matrix_msg(*result.measurement_noise()))
        self.pub_kalibr.publish(String(data=result.kalibr_yaml()))
        self.get_logger().info('published: ' + '; '.join(result.summary_lines()))

    def _statuses(self, result) -> list:
        out = []
        for axis in AXES:
            status = DiagnosticStatus(name=f'imu_allan: {axis}',
                                      hardware_id=self.values['hardware_id'])
            level, message, values = result.axis_status(axis)
            status.level = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN,
                            'error': DiagnosticStatus.ERROR}[level]
            status.message = message
            status.values = [KeyValue(key=k, value=v) for k, v in values]
            out.append(status)
        return out

    def _progress(self) -> None:
        s = self.session
        target = self.values['min_duration_s']
        pct = min(100.0, 100.0 * s.duration_s / target)
        if s.duration_s >= target:
            return
        elapsed = time.monotonic() - self._start_wall
        speed = s.duration_s / elapsed if elapsed > 0 else 0.0
        eta = (target - s.duration_s) / speed if speed > 0 else math.inf
        eta_text = f'{eta / 60:.1f} min' if math.isfinite(eta) else 'unknown (no data yet)'
        text = (f'collecting: {pct:.1f}% of {target:.0f} s, {s.stats.n_used} samples at '
                f'{s.rate_hz:.2f} Hz, ETA {eta_text}')
        if self._n_buffer_dropped:
            text += f', {self._n_buffer_dropped} messages dropped by a full buffer'
        self.get_logger().info(text)
        values = [('percent', f'{pct:.2f}'), ('samples', str(s.stats.n_used)),
                  ('rate_hz', f'{s.rate_hz:.4f}'), ('duration_s', f'{s.duration_s:.1f}'),
                  ('eta_s', f'{eta:.0f}'), ('warnings', ' | '.join(s.warnings))]
        status = DiagnosticStatus(
            name='imu_allan: progress', hardware_id=self.values['hardware_id'],
            level=DiagnosticStatus.WARN if s.warnings else DiagnosticStatus.OK,
            message=text, values=[KeyValue(key=k, value=v) for k, v in values])
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(array)
        self.pub_params.publish(array)

    def _checkpoint(self) -> None:
        with self._lock:
            try:
                self.session.save_state(self.output_dir / CHECKPOINT)
            except OSError as exc:
                self.get_logger().error(f'checkpoint failed: {exc}')

    def _on_reset(self, request, response):
        with self._lock:
            self.session = self._new_session(resume=False)
            self._last_result = None
        response.success = True
        response.message = 'accumulator reset: a new characterisation starts now'
        self.get_logger().info(response.message)
        return response

    def _on_save(self, request, response):
        try:
            paths = self.save()
        except (InputError, OSError) as exc:
            response.success, response.message = False, str(exc)
        else:
            response.success = True
            response.message = 'wrote ' + ', '.join(str(p) for p in paths)
        return response

    def save(self) -> list:
        """Write the result JSON, Kalibr file, Q/R and ADEV plot to output_dir."""
        self._process()
        with self._lock:
            self.session.flush()
            result = analyze(self.session, source=self.subscription.topic_name)
            if result is None:
                raise InputError('not enough data for any Allan deviation yet')
            self.session.save_state(self.output_dir / CHECKPOINT)
        return write_outputs(result, self.output_dir)


def _matrix_msg(matrix: np.ndarray, labels: list) -> Float64MultiArray:
    """Float64MultiArray of a square matrix; the state order is in the dimension labels."""
    n = matrix.shape[0]
    order = ','.join(labels)
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=f'rows:{order}', size=n, stride=n * n),
                      MultiArrayDimension(label=f'cols:{order}', size=n, stride=n)]
    msg.data = [float(x) for x in matrix.ravel()]
    return msg


def main(args=None) -> int:
    """Run the node until shutdown; write the result files on the way out."""
    try:
        rclpy.init(args=args)
    except Exception as exc:  # noqa: B902 - rcl raises several types for bad ROS args
        print(f'imu_allan_node: error: {exc}', file=sys.stderr)
        return 2
    node = None
    code = 0
    try:
        node = ImuAllanNode()
        executor = MultiThreadedExecutor(num_threads=2)
        executor.add_node(node)
        executor.spin()
    except InputError as exc:
        print(f'imu_allan_node: error: {exc}', file=sys.stderr)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            try:
                paths = node.save()
                print('imu_allan_node: wrote ' + ', '.join(str(p) for p in paths),
                      file=sys.stderr)
            except (InputError, OSError) as exc:
                print(f'imu_allan_node: nothing written on shutdown: {exc}', file=sys.stderr)
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
