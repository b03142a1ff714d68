"""
imu_allan_node: live six-axis IMU noise characterisation beside a stationary robot.

Thin by design, so that 1 kHz input costs little CPU: the subscription is raw (no
deserialisation) and its callback only appends the serialized message to a buffer (and,
with ``publish_imu_with_covariance``, relays it at once with the current covariances
written into its bytes, :mod:`imu_allan.ros.relay`); a timer decodes the buffer in one
vectorised step (:func:`~imu_allan.io.imu_cdr.decode_imu_cdr`) and feeds the pipeline
:class:`~imu_allan.pipeline.Session` that the offline mode uses too; both live in the
ROS-free :class:`~imu_allan.ros.live.LiveInput`.  The fit (seconds
of CPU) runs on a worker thread on a snapshot of the Allan curve, so the executor keeps
taking messages while it runs.  Other timers report progress, publish /diagnostics at
1 Hz and checkpoint; all run on the steady clock, so a node with ``use_sim_time`` and no
/clock (a bag played without ``--clock``) still processes, checkpoints and reports (and
says once that no /clock arrives).  The statuses come from a
:class:`~imu_allan.ros.reports.NodeReports` and the services from a
:class:`~imu_allan.ros.services.NodeServices`, plain objects the node owns.  ``main``
spins the node with rclpy's EventsExecutor (cheaper per message than the
SingleThreadedExecutor, which it falls back to when unavailable; see
bench/bench_node.py).
"""

from dataclasses import replace
import os
from pathlib import Path
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image, Imu, Temperature
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger

from imu_allan.core.allan.raw import RawKeeper
from imu_allan.errors import InputError
from imu_allan.io.imu_cdr import imu_frame_id
from imu_allan.io.report import result_json, write_outputs
from imu_allan.pipeline.analysis import analyze
from imu_allan.pipeline.session import Session
from imu_allan.ros.declare import as_declared_types, descriptor
from imu_allan.ros.live import LiveInput, SessionView
from imu_allan.ros.params import as_declared_type, BY_NAME, default_output_dir, PARAMS, RENAMED
from imu_allan.ros.pictures import CurvePictures
from imu_allan.ros.plan_report import node_targets, plan_due, targets_label, targets_met
from imu_allan.ros.relay import CovarianceRelay, load_covariance_file
from imu_allan.ros.reports import matrix_msg, NodeReports
from imu_allan.ros.services import NodeServices
from imu_allan.ros.spin import create_executor, spin_until_shutdown, until_shutdown

#: Period of the /diagnostics statuses (the aggregator marks a status stale after 5 s).
DIAGNOSTICS_PERIOD_S = 1.0
#: With use_sim_time, a /clock message is expected within this time of the start [s].
CLOCK_WAIT_S = 3.0
#: The warning when none came.
NO_CLOCK = ('use_sim_time is true but no /clock arrives: play the bag with --clock (the '
            "node's processing, checkpoints and progress run on the steady clock meanwhile; "
            'published stamps stay at 0)')


def _result_qos() -> QoSProfile:
    # Late subscribers get the last result.
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      history=HistoryPolicy.KEEP_LAST)


# Long because __init__ declares every parameter, topic, service and timer in one place
# (the ROS convention); the work is in LiveInput, NodeReports and NodeServices.
class ImuAllanNode(Node):
    """
    Subscribe to sensor_msgs/Imu, characterise its noise, publish the results.

    Parameters
    ----------
    **kwargs
        Passed to :class:`rclpy.node.Node` (e.g. ``parameter_overrides``).

    Raises
    ------
    InputError
        If a parameter value is invalid (the message names it and its range).

    """

    def __init__(self, **kwargs):
        super().__init__('imu_allan', **kwargs)
        for was, now in RENAMED.items():
            if was in self._parameter_overrides:
                value = self._parameter_overrides.pop(was).value
                self._parameter_overrides.setdefault(now, Parameter(now, value=value))
                self.get_logger().warning(f'the parameter {was} is now {now}: rename it')
        # Overrides from -p name:=value and parameter files: 600 for a double becomes 600.0
        # (rclpy keeps them in _parameter_overrides and refuses an int for a double).
        for name, override in list(self._parameter_overrides.items()):
            value = as_declared_type(name, override.value)
            if value is not override.value:
                self._parameter_overrides[name] = Parameter(name, value=value)
        for p in PARAMS:
            try:
                self.declare_parameter(p.name, p.default, descriptor(p))
            except ParameterException as exc:
                self.destroy_node()
                raise InputError(f'invalid parameter {p.name}: {exc}') from None
        self.values = {p.name: self.get_parameter(p.name).value for p in PARAMS}
        for name, value in self.values.items():
            why = BY_NAME[name].check(value)
            if why:
                self.destroy_node()
                raise InputError(f'invalid parameter: {why}')
        # `ros2 param set ... min_duration_s 600` sends an integer: converted before rclpy
        # checks the type, as the start-up overrides above.
        self.add_pre_set_parameters_callback(as_declared_types)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        # Statuses, files and checkpoints are named after the node, so two nodes (two
        # IMUs, two namespaces) never collide.
        self.diag_prefix = self.get_fully_qualified_name().lstrip('/')
        self.output_dir = (Path(os.path.expanduser(self.values['output_dir']))
                           if self.values['output_dir']
                           else default_output_dir(self.diag_prefix))
        try:
            initial = (load_covariance_file(self.values['initial_covariance_file'])
                       if self.values['initial_covariance_file'] else None)
        except InputError:
            self.destroy_node()
            raise
        self.relay = CovarianceRelay(initial)
        self._frame_bytes = ('', b'')     # frame_id and its CDR bytes, for the relay
        self.live = LiveInput(self.values, self.output_dir, self.get_logger())
        self._last_result = None
        self._fit_thread: threading.Thread | None = None
        # When the last plan was made (plans run every plan_period_s: they cost CPU).
        self._plan_mark = time.monotonic()

        qos = QoSProfile(
            depth=self.values['qos_depth'], history=HistoryPolicy.KEEP_LAST,
            durability=DurabilityPolicy.VOLATILE,
            reliability=(ReliabilityPolicy.BEST_EFFORT
                         if self.values['qos_reliability'] == 'best_effort'
                         else ReliabilityPolicy.RELIABLE))
        self.subscription = self.create_subscription(
            Imu, 'imu', self._on_imu, qos, raw=True,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        if self.values['temperature_topic']:
            self.create_subscription(Temperature, self.values['temperature_topic'],
                                     self.live.append_temperature, qos, raw=True)
        self.pub_params = self.create_publisher(DiagnosticArray, '~/noise_parameters',
                                                _result_qos())
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.pub_q = self.create_publisher(Float64MultiArray, '~/kalman/process_noise',
                                           _result_qos())
        self.pub_r = self.create_publisher(Float64MultiArray, '~/kalman/measurement_noise',
                                           _result_qos())
        self.pub_kalibr = self.create_publisher(String, '~/kalibr_imu_yaml', _result_qos())
        self.pub_diagnosis = self.create_publisher(String, '~/diagnosis', _result_qos())
        self.pub_result = self.create_publisher(String, '~/result', _result_qos())
        self.pictures = CurvePictures(
            self.create_publisher(Image, '~/adev_image', _result_qos()), self.get_logger())
        self.pub_imu = None
        if self.values['publish_imu_with_covariance']:
            self.pub_imu = self.create_publisher(Imu, '~/imu_with_covariance', qos)
        topic = self.subscription.topic_name
        self.reports = NodeReports(self.diag_prefix, self.values, self.live, topic)
        self.service_handlers = NodeServices(
            self.live, self.get_logger(), topic, save=self.save, forget=self._forget,
            publish_diagnosis=lambda text: self.pub_diagnosis.publish(String(data=text)))
        self.create_service(Trigger, '~/reset', self.service_handlers.on_reset)
        self.create_service(Trigger, '~/save', self.service_handlers.on_save)
        self.create_service(Trigger, '~/diagnose', self.service_handlers.on_diagnose)
        # The node's own work runs on the steady clock: under use_sim_time the ROS clock
        # stands still until /clock arrives, and with it every timer made on it.
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._make_timers()
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._on_diagnostics, clock=self._steady)
        self._clock_check = self.create_timer(CLOCK_WAIT_S, self._check_sim_clock,
                                              clock=self._steady)
        self.get_logger().info(
            f'listening on {self.subscription.topic_name} '
            f'({self.values["qos_reliability"]}, depth {self.values["qos_depth"]}); '
            f'results after {self.values["min_duration_s"]:.0f} s of stationary data; '
            f'files in {self.output_dir}')

    def _make_timers(self) -> None:
        self._period_timers = {
            key: self.create_timer(max(self.values[f'{key}_period_s'], 1.0), callback,
                                   clock=self._steady)
            for key, callback in (('process', self._on_process_timer),
                                  ('publish', self._publish),
                                  ('progress', self._on_progress_timer),
                                  ('adev_image', self._on_image_timer),
                                  ('checkpoint', self._checkpoint))}
        for key in self._period_timers:
            self._set_period(key, self.values[f'{key}_period_s'])

    def _check_sim_clock(self) -> None:
        """Warn once when use_sim_time is set and no /clock came (the ROS time is 0)."""
        self._clock_check.cancel()
        if (self.get_parameter('use_sim_time').value
                and self.get_clock().now().nanoseconds == 0):
            self.get_logger().warning(NO_CLOCK)

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

    @property
    def session(self) -> Session:
        """Return the pipeline session the node accumulates into (a new one after ~/reset)."""
        return self.live.session

    @property
    def n_received(self) -> int:
        """Return the number of messages received since start."""
        return self.live.n_received

    @property
    def n_fits(self) -> int:
        """Return the number of fits published since start."""
        return self.reports.n_fits

    def diagnose(self, view=None, raw: RawKeeper | None = None) -> str:
        """Diagnose the data so far and publish it (:meth:`NodeServices.diagnose`)."""
        return self.service_handlers.diagnose(view, raw)

    def _forget(self) -> None:
        self._last_result = None
        self.reports.clear()
        self._plan_mark = time.monotonic()

    @property
    def collection_stopped(self) -> bool:
        """Whether stop_when_met stopped the collection (cleared by ~/reset)."""
        return self.reports.collection_stopped

    def _stamped(self, statuses: list) -> DiagnosticArray:
        array = DiagnosticArray(status=statuses)
        array.header.stamp = self.get_clock().now().to_msg()
        return array

    def _on_diagnostics(self) -> None:
        # 1 Hz, within the aggregator's 5 s stale timeout.
        self.pub_diag.publish(self._stamped(self.reports.diagnostics()))

    def _on_progress_timer(self) -> None:
        statuses = self.reports.progress()
        if statuses:
            self.get_logger().info(statuses[0].message)
            self.pub_params.publish(self._stamped(statuses))

    def destroy_node(self) -> None:
        """Destroy the node once no picture is being drawn (it would publish after)."""
        if hasattr(self, 'pictures'):       # none when a parameter was refused at start
            self.pictures.close()
        super().destroy_node()

    def _on_image_timer(self) -> None:
        if self.pictures.wanted():
            self.pictures.draw(self.live.view(), self._last_result,
                               self.subscription.topic_name, self.get_clock().now().to_msg())

    def _on_imu(self, raw: bytes) -> None:
        # The only per-message Python work: count, append and (if asked) relay the
        # message at once with the current covariances (a byte patch).
        if not self.collection_stopped:
            self.live.append(raw)
        else:                       # received (the data status stays OK), not collected
            self.live.n_received += 1
            self.live.last_rx = time.monotonic()
        if self.pub_imu is not None and self._analysed(raw):
            patched = self.relay.patch(raw)
            if patched is None:  # an unusual layout: through a Python message
                patched = deserialize_message(raw, Imu)
                patched.angular_velocity_covariance = self.relay.fields[0]
                patched.linear_acceleration_covariance = self.relay.fields[1]
            self.pub_imu.publish(patched)

    def _analysed(self, raw: bytes) -> bool:
        """Whether a message is of the IMU analysed (another on the topic is not it)."""
        frame = self.live.frame_id
        if not frame:
            return True
        if self._frame_bytes[0] != frame:
            name = frame.encode() + b'\0'
            self._frame_bytes = (frame, len(name).to_bytes(4, 'little') + name)
        # The little-endian CDR length and name, one slice; anything else decoded.
        key = self._frame_bytes[1]
        return raw[12:12 + len(key)] == key or imu_frame_id(raw) in (frame, None)

    def _on_process_timer(self) -> None:
        if self.live.due():
            self.live.process()

    @property
    def last_result(self):
        """Return the latest published AnalysisResult, or None."""
        return self._last_result

    @property
    def fitting(self) -> bool:
        """Return True while a background fit runs."""
        return self._fit_thread is not None and self._fit_thread.is_alive()

    def _publish(self) -> None:
        if self.fitting or self.collection_stopped:
            return
        # The rows received so far count before "is it early?" (the processing timer may
        # not have run since they came).
        self.live.process()
        early = self.session.duration_s < self.values['min_duration_s']
        if self.session.unit_problem is not None or (early and not self._plan_due()):
            return
        view, raw = self.live.snapshot()
        # Before min_duration_s only the plan: "how long?" is answered from the start.
        work = self._plan_early if early else self._fit_and_publish
        self._fit_thread = threading.Thread(target=until_shutdown, name='imu_allan_fit',
                                            args=(self.context, work, view, raw), daemon=True)
        self._fit_thread.start()

    def publish_now(self):
        """
        Fit the data so far and publish every result topic (synchronously).

        Returns
        -------
        AnalysisResult or None
            The result published, or None while no Allan deviation is computable.

        """
        self.live.process()
        if self.session.unit_problem is not None:
            return None
        return self._fit_and_publish(*self.live.snapshot())

    def _fit_and_publish(self, view: SessionView, raw: RawKeeper | None = None):
        if view.curve(bounds=False) is None:
            return None
        # The raw copy feeds the effect search's periodogram and ramp evidence, so the
        # node publishes the model analyze and diagnose give for the same data.
        result, planned = self._analyze(view, raw)
        if result is None:
            return None
        self._last_result = result
        self.relay.update(result.imu_covariances())
        self.pub_params.publish(self._stamped(self.reports.fitted(result, view)))
        if planned:
            self._stop_if_met(result, view.duration_s)
        self.pub_q.publish(matrix_msg(*result.process_noise()))
        self.pub_r.publish(matrix_msg(*result.measurement_noise()))
        self.pub_kalibr.publish(String(data=result.kalibr_yaml()))
        self.pub_result.publish(String(data=result_json(result)))
        self.get_logger().info('published: ' + '; '.join(result.summary_lines()))
        return result

    def _plan_due(self) -> bool:
        return plan_due(self.values, time.monotonic() - self._plan_mark,
                        bool(self.reports.plans))

    def _plan_early(self, view: SessionView, raw: RawKeeper | None) -> None:
        """Plan before min_duration_s (fit, nothing published) and log the plan."""
        if view.curve(bounds=False) is not None and self._analyze(view, raw)[1]:
            self.get_logger().info('plan: ' + self.reports.progress_status().message)

    def _analyze(self, view: SessionView, raw: RawKeeper | None) -> tuple:
        """
        Analyse a snapshot; plan the record length when plan_period_s has passed.

        The plan costs several fits' CPU, so it runs at most every plan_period_s (the
        first sooner: plan_report.plan_due); between plans the last one rides along with
        each result.  Returns the result (or None) and whether it was planned now.
        """
        plan = self._plan_due()
        result = analyze(view, source=self.subscription.topic_name, raw=raw,
                         topic=self.subscription.topic_name,
                         covering_tau_max_s=self.values['covering_tau_max_s'], plan=plan,
                         plan_targets=node_targets(self.values))
        if result is not None and plan:
            self._plan_mark = time.monotonic()
            self.reports.plans = result.plans
        elif result is not None and self.reports.plans:
            result = replace(result, plans=self.reports.plans)
        return result, plan and result is not None

    def _stop_if_met(self, result, duration_s: float) -> None:
        """With stop_when_met: stop collecting once every target is met, and say so."""
        fitted = sum(f is not None for f in result.fits.values())
        if (not self.values['stop_when_met'] or self.collection_stopped
                or duration_s < self.values['min_duration_s']
                or not targets_met(result.plans, fitted)):
            return
        self.reports.collection_stopped = True
        self.get_logger().info(
            f'{targets_label(self.values)} met on every axis after {duration_s:.0f} s: '
            'stopped collecting (stop_when_met); the results stay published, '
            '~/reset starts over')

    def _checkpoint(self) -> None:
        try:
            self.live.checkpoint()
        except OSError as exc:
            self.get_logger().error(f'checkpoint failed: {exc}')

    def save(self) -> list:
        """
        Write the result JSON, Kalibr file, Q/R and ADEV plot to output_dir.

        Returns
        -------
        list of Path
            The files written (the checkpoint too).

        Raises
        ------
        InputError
            If there is not enough data for any Allan deviation yet, or the data show a
            unit mistake.

        """
        if self._fit_thread is not None:
            self._fit_thread.join()
        if self.session.unit_problem is not None:
            raise InputError(self.session.unit_problem)
        self.live.checkpoint(flush=True)
        view, raw = self.live.snapshot()
        # The same model as the periodic fit: raw copy, topic and plan included.
        result = self._analyze(view, raw)[0] if view.curve(bounds=False) is not None else None
        if result is None:
            raise InputError('not enough data for any Allan deviation yet')
        self._last_result = result
        self.relay.update(result.imu_covariances())
        imu_topic = self.pub_imu.topic_name if self.pub_imu is not None else None
        return write_outputs(result, self.output_dir, imu_topic=imu_topic) + [
            self.live.checkpoint_path]


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
        executor = create_executor()
        executor.add_node(node)
        spin_until_shutdown(executor)
    except InputError as exc:
        print(f'imu_allan_node: error: {exc}', file=sys.stderr)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            print('imu_allan_node: saving the results (after the fit that runs, if one'
                  ' does)...', file=sys.stderr, flush=True)
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
