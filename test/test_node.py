"""
The live node with real rclpy (no mocks of ROS): topics, QoS, hygiene, services, resume.

In-process tests run the node and a peer node (publisher of simulated Imu messages with
synthetic header stamps, subscriber of the results) on one EventsExecutor in a thread;
the player keeps at most ``WINDOW`` messages in flight so that the best-effort queue
never overflows, which makes the runs deterministic.  Process tests start the installed
``imu_allan_node`` console script and kill or interrupt it.  Every run uses its own
ROS_DOMAIN_ID so that parallel runs do not hear each other.
"""

import json
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import threading
import time

os.environ['ROS_DOMAIN_ID'] = str(random.Random().randint(1, 100))

import numpy as np  # noqa: E402
from numpy.testing import assert_allclose  # noqa: E402
import pytest  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import (DurabilityPolicy, QoSProfile, ReliabilityPolicy)  # noqa: E402
import yaml  # noqa: E402

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402, I100
from sensor_msgs.msg import Imu  # noqa: E402
from std_msgs.msg import Float64MultiArray, String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from conftest import T0_NS  # noqa: E402
from imu_allan import AXES  # noqa: E402, I100
from imu_allan.core.noise.params import parse_params  # noqa: E402
from imu_allan.core.noise.simulate import simulate_imu  # noqa: E402
from imu_allan.core.outputs.kalman import UNKNOWN_VARIANCE  # noqa: E402
from imu_allan.errors import InputError  # noqa: E402
from imu_allan.io.bag_writer import serialize_imu  # noqa: E402
from imu_allan.pipeline.analysis import analyze  # noqa: E402
from imu_allan.pipeline.hygiene import SessionConfig  # noqa: E402
from imu_allan.pipeline.session import Session  # noqa: E402
from imu_allan.pipeline.spikes import CHUNK, CONTEXT  # noqa: E402
from imu_allan.ros.node import ImuAllanNode, NO_CLOCK  # noqa: E402
from imu_allan.ros.spin import create_executor  # noqa: E402

WINDOW = 1000
NODE = '/imu_allan'
#: A fast-moving model: T_B under a second, so 200 s at 200 Hz pin N, B and T_B.
SPEC = parse_params({'name': 'test IMU', 'axes': {
    'gyro': {'N': 2e-3, 'B': 1.5e-3, 'T_B': 0.5, 'K': 1e-5},
    'accel': {'N': 4e-3, 'B': 3e-3, 'T_B': 1.0, 'K': 2e-5},
    'accel_z': {'bias': 9.80665}}})
RESULT_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _record(rate_hz: float, duration_s: float, seed: int = 1, t0_ns: int = T0_NS):
    """Simulate a still IMU: stamps (n,) [ns] and samples (n, 6)."""
    t_s, y = simulate_imu(SPEC, rate_hz, duration_s, seed=seed)
    return t0_ns + np.round(t_s * 1e9).astype(np.int64), y


@pytest.fixture(scope='module')
def context():
    ctx = Context()
    rclpy.init(args=[], context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


class Rig:
    """The node under test plus a peer node that publishes Imu and records results."""

    def __init__(self, context, out_dir: Path, **params):
        values = {'output_dir': str(out_dir), 'min_duration_s': 1.0,
                  'publish_period_s': 3600.0, 'process_period_s': 0.05,
                  'progress_period_s': 3600.0, 'checkpoint_period_s': 0.0, **params}
        self.node = ImuAllanNode(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in values.items()])
        self.peer = rclpy.create_node('imu_allan_test_peer', context=context)
        self.got = {}
        self._lock = threading.Lock()
        for topic, kind in (('noise_parameters', DiagnosticArray),
                            ('kalman/process_noise', Float64MultiArray),
                            ('kalman/measurement_noise', Float64MultiArray),
                            ('kalibr_imu_yaml', String)):
            self.subscribe(f'{NODE}/{topic}', kind)
        # Both spin on SingleThreadedExecutors in threads: rclpy's EventsExecutor (what
        # main() uses) received nothing when spun outside the main thread here, and
        # deadlocked on a same-process publish, so main() is covered by the process
        # tests at the end of this module.
        self.executor = create_executor('single', context=context)
        self.executor.add_node(self.node)
        self.peer_executor = create_executor('single', context=context)
        self.peer_executor.add_node(self.peer)
        self._threads = [threading.Thread(target=e.spin, daemon=True)
                         for e in (self.executor, self.peer_executor)]
        for th in self._threads:
            th.start()
        self.sent = 0

    def subscribe(self, topic: str, kind, node=None):
        """Record every message of a result topic in self.got[topic]."""
        def record(msg):
            with self._lock:
                self.got.setdefault(topic, []).append(msg)
        return (node or self.peer).create_subscription(kind, topic, record, RESULT_QOS)

    def publisher(self, reliable: bool = False):
        """Imu publisher: best effort (sensor data) or reliable."""
        qos = QoSProfile(depth=1000, reliability=(ReliabilityPolicy.RELIABLE if reliable
                                                  else ReliabilityPolicy.BEST_EFFORT))
        pub = self.peer.create_publisher(Imu, 'imu', qos)
        wait(lambda: pub.get_subscription_count() > 0, 10, 'discovery of the node')
        return pub

    def feed(self, stamps, samples, pub=None, expect_all: bool = True) -> None:
        """Publish one message per row, at most WINDOW in flight; wait for all."""
        pub = pub or self.publisher()
        payloads = serialize_imu(np.asarray(stamps, np.int64), samples)
        start = self.node.n_received
        for k, row in enumerate(payloads):
            if k % 100 == 0:
                wait(lambda: self.node.n_received - start >= k - WINDOW, 30, 'the node')
            pub.publish(row.tobytes())
        self.sent += len(payloads)
        if expect_all:
            wait(lambda: self.node.n_received - start >= len(payloads), 30,
                 'every message received')

    def deliver(self, stamps, samples) -> None:
        """
        Hand one serialized Imu message per row to the node's subscription callback.

        The bytes DDS would deliver, without the transport (which :meth:`feed` tests):
        hours of messages in seconds, for the tests of what the node does with them.
        """
        for row in serialize_imu(np.asarray(stamps, np.int64), samples):
            self.node._on_imu(row.tobytes())
        self.sent += len(stamps)

    def last(self, topic: str):
        """Return the last message recorded on a result topic (None if none)."""
        with self._lock:
            msgs = self.got.get(f'{NODE}/{topic}', [])
            return msgs[-1] if msgs else None

    def publish(self):
        """Fit now; wait for the four result topics."""
        with self._lock:
            self.got.clear()
        result = self.node.publish_now()
        assert result is not None
        wait(lambda: all(self.last(t) is not None for t in (
            'noise_parameters', 'kalman/process_noise', 'kalman/measurement_noise',
            'kalibr_imu_yaml')), 10, 'the result topics')
        return result

    def close(self) -> None:
        self.executor.shutdown()
        self.peer_executor.shutdown()
        for th in self._threads:
            th.join(5)
        self.node.destroy_node()
        self.peer.destroy_node()


@pytest.fixture
def rig(context, tmp_path):
    rigs = []

    def make(**params):
        r = Rig(context, tmp_path / f'out{len(rigs)}', **params)
        rigs.append(r)
        return r
    yield make
    for r in rigs:
        r.close()


def wait(predicate, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out waiting for {what}')
        time.sleep(0.005)


def statuses(array: DiagnosticArray) -> dict:
    """Name -> (level, message, {key: value}) of a DiagnosticArray."""
    return {s.name: (int.from_bytes(s.level, 'little') if isinstance(s.level, bytes)
                     else int(s.level), s.message, {kv.key: kv.value for kv in s.values})
            for s in array.status}


def input_status(r: Rig) -> tuple:
    r.publish()
    return statuses(r.last('noise_parameters'))['imu_allan: input']


# ------------------------------------------------------------------ results
def test_published_parameters_match_the_truth_and_the_offline_mode(rig):
    r = rig()
    t, y = _record(200.0, 200.0)
    r.feed(t, y)
    assert r.node.n_received == t.size           # best-effort, paced: nothing lost
    result = r.publish()
    st = statuses(r.last('noise_parameters'))
    assert set(st) == {f'imu_allan: {a}' for a in AXES} | {'imu_allan: input'}
    # Same numbers as the offline mode on the same samples (one pipeline).
    offline = Session(SessionConfig())
    for k in range(0, t.size, 997):
        offline.add(t[k:k + 997], y[k:k + 997])
    offline.flush()                             # the end of the recording: every row
    ref = analyze(offline)
    misses = []
    for axis in AXES:
        level, message, kv = st[f'imu_allan: {axis}']
        assert int(kv['samples']) == t.size and abs(float(kv['rate_hz']) - 200.0) < 1e-6
        for sym in ('N', 'B', 'T_B', 'K'):
            value, lo, hi = (float(kv[sym]), float(kv[f'{sym}_ci95_lo']),
                             float(kv[f'{sym}_ci95_hi']))
            assert kv[f'{sym}_unit']
            assert value == pytest.approx(ref.fits[axis].optimised[sym].value, rel=1e-4)
            truth = getattr(SPEC.axes[axis], sym)
            if kv[f'{sym}_kind'] == 'estimate':
                inside = lo <= truth <= hi
            else:
                inside = truth <= hi                 # an upper bound must bound it
            if not inside:
                misses.append(f'{axis} {sym}: {truth:.3g} not in [{lo:.3g}, {hi:.3g}]')
        # N is pinned by 40 000 samples: a tight interval around the truth.
        n_true = SPEC.axes[axis].N
        assert abs(float(kv['N']) / n_true - 1) < 0.03, (axis, kv['N'])
    # 24 intervals at 95 %: about one miss is expected; more means a biased fit.
    assert len(misses) <= 2, misses
    assert result.n_samples == t.size


def test_kalman_matrices_and_kalibr_yaml_are_labelled(rig):
    r = rig()
    r.feed(*_record(200.0, 30.0))
    r.publish()
    q, rr = r.last('kalman/process_noise'), r.last('kalman/measurement_noise')
    assert [d.size for d in q.layout.dim] == [12, 12] and len(q.data) == 144
    assert [d.size for d in rr.layout.dim] == [6, 6] and len(rr.data) == 36
    rows = q.layout.dim[0].label
    assert rows.startswith('rows:') and q.layout.dim[1].label.startswith('cols:')
    labels = rows[5:].split(',')
    assert len(labels) == 12 and any('gyro_x' in lb for lb in labels)
    assert rr.layout.dim[0].label == 'rows:' + ','.join(AXES) or \
        len(rr.layout.dim[0].label[5:].split(',')) == 6
    qm = np.array(q.data).reshape(12, 12)
    assert np.allclose(qm, qm.T) and np.all(np.diag(qm) >= 0)
    rm = np.array(rr.data).reshape(6, 6)
    assert np.allclose(np.sqrt(np.diag(rm)[:3] / 200.0), 2e-3, rtol=0.05)   # Rd = N^2/dt
    text = r.last('kalibr_imu_yaml').data
    for key in ('accelerometer_noise_density', 'accelerometer_random_walk',
                'gyroscope_noise_density', 'gyroscope_random_walk', 'update_rate'):
        assert key in text
    assert 'rostopic: /imu\n' in text      # the topic the node subscribes to


def test_late_subscriber_gets_the_last_result(rig, context):
    r = rig()
    r.feed(*_record(200.0, 20.0))
    r.publish()
    late = rclpy.create_node('late_subscriber', context=context)
    try:
        r.got.pop(f'{NODE}/kalibr_imu_yaml', None)
        got = []
        late.create_subscription(String, f'{NODE}/kalibr_imu_yaml', got.append, RESULT_QOS)
        executor = create_executor('single', context=context)
        executor.add_node(late)
        deadline = time.monotonic() + 10
        while not got and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        executor.shutdown()
        assert got and 'gyroscope_noise_density' in got[0].data
    finally:
        late.destroy_node()


def test_reliable_publisher_matches_the_best_effort_subscription(rig):
    r = rig()
    pub = r.publisher(reliable=True)
    t, y = _record(200.0, 5.0)
    r.feed(t, y, pub=pub)
    assert r.node.n_received == t.size


def test_reliable_subscription_hears_no_best_effort_publisher(rig):
    r = rig(qos_reliability='reliable')
    pub = r.peer.create_publisher(Imu, 'imu', QoSProfile(
        depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
    time.sleep(1.0)                      # discovered, but the QoS are incompatible
    assert pub.get_subscription_count() == 0
    for row in serialize_imu(*_record(200.0, 1.0)):
        pub.publish(row.tobytes())
    time.sleep(0.5)
    assert r.node.n_received == 0


def test_progress_before_min_duration(rig):
    r = rig(min_duration_s=1000.0, progress_period_s=0.1)
    r.feed(*_record(200.0, 10.0))
    wait(lambda: r.last('noise_parameters') is not None and 'imu_allan: progress' in
         statuses(r.last('noise_parameters')), 10, 'a progress report')
    wait(lambda: float(statuses(r.last('noise_parameters'))['imu_allan: progress'][2]
                       ['percent']) > 0.9, 10, 'the progress of the fed data')
    level, message, kv = statuses(r.last('noise_parameters'))['imu_allan: progress']
    assert message.startswith('collecting: 1.0% of min_duration_s 1000 s (no plan yet), '
                              '2000 samples at 200.00 Hz')
    assert {'percent', 'samples', 'rate_hz', 'eta_s'} <= set(kv)


class _SpyLogger:
    """A logger that keeps the warnings it is given and passes everything on."""

    def __init__(self, logger, warned: list):
        self._logger, self.warned = logger, warned

    def warning(self, text, *args, **kwargs):
        self.warned.append(text)
        return self._logger.warning(text, *args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._logger, name)


def test_sim_time_without_a_clock_still_processes_checkpoints_and_reports(rig, monkeypatch):
    # use_sim_time and no /clock (a bag played without --clock): the ROS clock stands
    # at 0, and timers on it never fire.  Before: nothing processed, no checkpoint (a
    # kill -9 lost everything), no progress, no word.
    r = rig(use_sim_time=True, checkpoint_period_s=0.2, progress_period_s=0.1,
            min_duration_s=1000.0)
    warned: list = []
    spy = _SpyLogger(r.node.get_logger(), warned)
    monkeypatch.setattr(r.node, 'get_logger', lambda: spy)
    r.feed(*_record(200.0, 5.0))
    wait(lambda: r.node.session.stats.n_used > 0, 10, 'the timer to process')
    wait(lambda: r.node.live.checkpoint_path.exists(), 10, 'a checkpoint')
    wait(lambda: r.last('noise_parameters') is not None and 'imu_allan: progress' in
         statuses(r.last('noise_parameters')), 10, 'a progress report')
    wait(lambda: warned, 10, 'the warning that no /clock arrives')
    assert warned == [NO_CLOCK] and 'play the bag with --clock' in NO_CLOCK
    assert r.node.get_clock().now().nanoseconds == 0


def test_a_shutdown_during_a_background_fit_ends_it_without_a_traceback(
        tmp_path, monkeypatch):
    # SIGTERM while the node fits: rclpy's handler shuts the context down, and the fit
    # thread's publish raised RCLError (publisher's context is invalid) with a traceback
    # in 3 of 4 runs of the node process.  Its result is kept for save().
    ctx = Context()
    rclpy.init(args=[], context=ctx)
    r = Rig(ctx, tmp_path / 'out', min_duration_s=1.0)
    raised: list = []
    monkeypatch.setattr(threading, 'excepthook', lambda a: raised.append(a.exc_value)
                        if a.thread.name == 'imu_allan_fit' else None)
    try:
        r.feed(*_record(400.0, 4.0))
        r.node._publish()
        thread = r.node._fit_thread
        assert thread is not None and thread.is_alive()
        rclpy.shutdown(context=ctx)
        thread.join(60)
        assert not raised and r.node.last_result is not None
        assert r.node.save()
    finally:
        try:
            r.close()
        finally:
            rclpy.try_shutdown(context=ctx)


def test_results_are_published_by_the_timer_once_long_enough(rig):
    r = rig(min_duration_s=5.0, publish_period_s=0.2)
    r.feed(*_record(200.0, 6.0))
    wait(lambda: r.last('kalibr_imu_yaml') is not None, 30, 'the timer fit')
    assert r.node.n_fits >= 1


def test_imu_with_covariance_is_republished_after_a_fit(rig):
    r = rig(publish_imu_with_covariance=True)
    t, y = _record(200.0, 25.0)
    r.feed(t[:4000], y[:4000])
    r.publish()
    got = []
    r.peer.create_subscription(Imu, f'{NODE}/imu_with_covariance', got.append, QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT))
    time.sleep(0.5)
    r.feed(t[4000:], y[4000:])
    wait(lambda: len(got) > 0, 10, '~/imu_with_covariance')
    cov = np.array(got[-1].angular_velocity_covariance).reshape(3, 3)
    assert np.allclose(np.sqrt(np.diag(cov) / 200.0), 2e-3, rtol=0.05)   # N^2 * rate
    assert got[-1].header.stamp.sec * 10 ** 9 + got[-1].header.stamp.nanosec in set(t[4000:])


#: A robot_localization stand-in: its own process, its QoS (best effort, keep last 10);
#: it writes "stamp_ns receive_time_s variance_gyro_x frame_id" per message.
_RL_SUBSCRIBER = """
import sys, time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
topic, out, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
rclpy.init()
node = rclpy.create_node('rl_stand_in')
got = []
node.create_subscription(Imu, topic, lambda m: got.append(
    (m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec, time.monotonic(),
     m.angular_velocity_covariance[0], m.header.frame_id)),
    QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
print('ready', flush=True)
deadline = time.monotonic() + 60
while len(got) < n and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
with open(out, 'w') as f:
    f.writelines(f'{k} {t!r} {float(v)!r} {fr}\\n' for k, t, v, fr in got)
"""


def test_imu_with_covariance_relays_every_message_at_once(rig, tmp_path):
    # A subscriber with robot_localization's QoS (best effort, keep last 10), in its own
    # process, gets every message at 200 Hz, from the first one on, within 50 ms; before
    # any fit the covariances say "unknown" with a large variance, not the 1e-9 floor.
    r = rig(publish_imu_with_covariance=True)
    t, y = _record(200.0, 3.0)
    out = tmp_path / 'received.txt'
    sub = subprocess.Popen([sys.executable, '-c', _RL_SUBSCRIBER,
                            f'{NODE}/imu_with_covariance', str(out), str(t.size)],
                           stdout=subprocess.PIPE, text=True)
    try:
        assert sub.stdout.readline().strip() == 'ready'
        wait(lambda: r.node.pub_imu.get_subscription_count() > 0, 20, 'the subscriber')
        time.sleep(1.0)     # the graph shows the reader before DDS has matched it
        pub = r.publisher()
        sent = {}
        start = time.monotonic()
        for k, row in enumerate(serialize_imu(t, y)):
            while time.monotonic() < start + k / 200.0:
                time.sleep(0.0005)
            sent[int(t[k])] = time.monotonic()
            pub.publish(row.tobytes())
        assert sub.wait(60) == 0
    finally:
        sub.kill()
    rows = [line.split() for line in out.read_text().splitlines()]
    got = {int(k): (float(ts), float(v), fr) for k, ts, v, fr in rows}
    assert sorted(got) == sorted(sent), f'{len(sent) - len(got)} of {len(sent)} missing'
    latency = np.array([got[k][0] - sent[k] for k in sent])
    assert latency.max() <= 0.05, f'latency up to {latency.max() * 1e3:.1f} ms'
    assert got[int(t[0])][1] == UNKNOWN_VARIANCE
    assert got[int(t[0])][2] == 'imu_link'


def test_imu_with_covariance_starts_from_an_initial_covariance_file(rig, context, tmp_path):
    gyro, accel = np.diag([1e-6, 2e-6, 3e-6]).ravel(), np.diag([4e-4, 5e-4, 6e-4]).ravel()
    path = tmp_path / 'result.json'
    path.write_text(json.dumps({'imu_covariance': {
        'angular_velocity_covariance': gyro.tolist(),
        'linear_acceleration_covariance': accel.tolist()}}))
    r = rig(publish_imu_with_covariance=True, initial_covariance_file=str(path))
    got = []
    r.peer.create_subscription(Imu, f'{NODE}/imu_with_covariance', got.append, QoSProfile(
        depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
    wait(lambda: r.node.pub_imu.get_subscription_count() > 0, 10, 'discovery of the relay')
    r.feed(*_record(200.0, 0.1))
    wait(lambda: len(got) == 20, 10, 'the relayed messages')
    assert_allclose(got[0].angular_velocity_covariance, gyro)
    assert_allclose(got[0].linear_acceleration_covariance, accel)
    assert r.node.relay.source == 'file'
    path.write_text('{"imu_covariance": {"angular_velocity_covariance": [1, 2]}}')
    with pytest.raises(InputError, match='initial_covariance_file'):
        ImuAllanNode(context=context, parameter_overrides=[
            Parameter('output_dir', value=str(tmp_path)),
            Parameter('initial_covariance_file', value=str(path))])


def test_diagnostics_at_1_hz_named_after_the_node(rig):
    r = rig()
    arrays = []
    r.peer.create_subscription(DiagnosticArray, '/diagnostics', arrays.append, 100)

    def level(name):
        return statuses(arrays[-1])[name][0] if arrays and name in statuses(arrays[-1]) \
            else None
    # No data yet: a WARN, not an OK.
    wait(lambda: level('imu_allan: data') == 1, 10, 'a WARN without data')
    assert 'no message yet on /imu' in statuses(arrays[-1])['imu_allan: data'][1]
    r.feed(*_record(200.0, 20.0))
    r.publish()
    n0 = len(arrays)
    time.sleep(2.6)
    assert len(arrays) - n0 >= 2                 # about 1 Hz
    last = statuses(arrays[-1])
    names = {f'imu_allan: {a}' for a in AXES} | {
        'imu_allan: data', 'imu_allan: progress', 'imu_allan: input'}
    assert names <= set(last)                    # per-axis statuses persist after the fit
    assert last['imu_allan: progress'][1].startswith('characterising:')
    assert {s.hardware_id for s in arrays[-1].status} == {'imu_link'}   # the frame_id


def test_two_nodes_in_two_namespaces_keep_apart(context, tmp_path, monkeypatch):
    # Two IMUs on one robot: default output directories, topics and diagnostic names
    # follow each node's namespace, so nothing collides.
    monkeypatch.setenv('HOME', str(tmp_path))
    nodes = [ImuAllanNode(context=context, namespace=ns, parameter_overrides=[
        Parameter('min_duration_s', value=1.0), Parameter('checkpoint_period_s', value=0.0),
        Parameter('process_period_s', value=0.05)]) for ns in ('/left', '/right')]
    peer = rclpy.create_node('imu_allan_two_peer', context=context)
    executor = create_executor('single', context=context)
    for n in nodes + [peer]:
        executor.add_node(n)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    try:
        dirs = [n.output_dir for n in nodes]
        assert dirs == [tmp_path / '.ros' / 'imu_allan' / ns / 'imu_allan'
                        for ns in ('left', 'right')]
        assert [n.subscription.topic_name for n in nodes] == ['/left/imu', '/right/imu']
        names = [n.reports.data_status().name for n in nodes]
        assert names == ['left/imu_allan: data', 'right/imu_allan: data']
        for n, seconds in zip(nodes, (10.0, 15.0)):
            pub = peer.create_publisher(Imu, n.subscription.topic_name, QoSProfile(
                depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT))
            wait(lambda: pub.get_subscription_count() > 0, 10, 'discovery')
            t, y = _record(200.0, seconds)
            for k, row in enumerate(serialize_imu(t, y)):
                if k % 100 == 0:
                    wait(lambda: n.n_received >= k - WINDOW, 30, 'the node')
                pub.publish(row.tobytes())
            wait(lambda: n.n_received >= t.size, 30, 'every message received')
        for n, expected in zip(nodes, (2000, 3000)):
            n.save()
            result = json.loads((n.output_dir / 'result.json').read_text())
            assert result['n_samples'] == expected
    finally:
        executor.shutdown()
        thread.join(5)
        for n in nodes + [peer]:
            n.destroy_node()


# ------------------------------------------------------------------ hygiene
def test_gap_is_reported(rig):
    r = rig()
    t, y = _record(200.0, 20.0)
    keep = np.ones(t.size, bool)
    keep[2000:2100] = False                                  # 0.5 s of lost messages
    r.feed(t[keep], y[keep])
    level, message, kv = input_status(r)
    assert level == 1 and kv['n_gaps'] == '1' and 'gap of 0.505 s' in message
    assert kv['irregular_stamps'] == 'False'


def test_duplicate_and_out_of_order_stamps_are_dropped(rig):
    r = rig()
    t, y = _record(200.0, 20.0)
    idx = np.arange(t.size)
    idx = np.insert(idx, 1500, [1499] * 10)                  # ten re-sent messages
    idx[3000], idx[3001] = idx[3001], idx[3000]               # one swapped pair
    r.feed(t[idx], y[idx])
    level, message, kv = input_status(r)
    assert kv['n_duplicate'] == '10' and kv['n_out_of_order'] == '1'
    assert 'repeated stamp' in message and 'out-of-order' in message


def test_rate_change_is_reported(rig):
    r = rig()
    t, y = _record(200.0, 20.0)
    t2 = t[-1] + np.round(np.arange(1, 2001) * 1e9 / 220.0).astype(np.int64)  # 220 Hz
    # One feed: the change is found inside a block too, wherever the timer cuts.
    r.feed(np.concatenate((t, t2)), np.concatenate((y, y[:2000])))
    level, message, kv = input_status(r)
    assert int(kv['n_rate_changes']) >= 1 and 'sample rate changed' in message


def test_nan_values_are_dropped(rig):
    r = rig()
    t, y = _record(200.0, 20.0)
    y[1000:1005, 2] = np.nan
    y[2000, 4] = np.inf
    r.feed(t, y)
    level, message, kv = input_status(r)
    assert kv['n_nonfinite'] == '6' and 'NaN/Inf' in message


def test_saturated_axis_is_dropped(rig):
    r = rig(gyro_range_rad_s=0.5)
    t, y = _record(200.0, 20.0)
    y[1000:1010, 1] = 0.5
    r.feed(t, y)
    level, message, kv = input_status(r)
    assert kv['n_saturated'] == '10' and 'gyro_y' in kv['saturated_axes']
    assert 'saturated' in message


def test_frozen_axis_is_reported(rig):
    r = rig()
    t, y = _record(200.0, 20.0)
    y[1000:1500, 3] = y[1000, 3]
    r.feed(t, y)
    level, message, kv = input_status(r)
    assert kv['frozen_axes'] == 'accel_x' and 'accel_x is frozen' in message


def _bumped(duration_s: float = 40.0):
    t, y = _record(200.0, duration_s)
    y[3000:3400, :3] += 0.5             # 2 s turning at 0.5 rad/s, from 15 s
    return t, y


@pytest.mark.parametrize('policy, what', [('warn', 'samples kept'),
                                          ('pause', 'accumulation paused'),
                                          ('restart', 'restarting from scratch')])
def test_motion_is_reported_and_handled_per_on_motion(rig, policy, what):
    r = rig(on_motion=policy, settle_s=2.0)
    t, y = _bumped()
    r.feed(t, y)
    level, message, kv = input_status(r)
    assert int(kv['n_motion_events']) == 1 and what in message
    used, dropped = int(kv['n_used']), int(kv['n_motion_dropped'])
    if policy == 'warn':
        assert dropped == 0 and used == t.size
    elif policy == 'pause':
        # The moving windows plus settle_s are dropped; the rest is used.
        assert 400 <= dropped <= 400 + 200 * 4 and used == t.size - dropped
    else:
        assert kv['n_restarts'] == '1' and used < t.size - 3000 - 400
    st = statuses(r.last('noise_parameters'))
    assert st['imu_allan: gyro_x'][0] == 1          # not trusted: motion seen


# --------------------------------------------------------------- parameters
@pytest.mark.parametrize('name, value, why', [
    ('min_duration_s', 0.5, 'out of range'),
    ('on_motion', 'jump', 'must be one of warn, pause, restart'),
    ('qos_depth', 2.5, 'expecting type'),
    ('qos_reliability', 'sometimes', 'must be one of best_effort, reliable'),
])
def test_invalid_parameter_values_are_refused_at_start(context, tmp_path, name, value, why):
    with pytest.raises(InputError, match=why) as exc:
        ImuAllanNode(context=context, parameter_overrides=[
            Parameter('output_dir', value=str(tmp_path)), Parameter(name, value=value)])
    assert name in str(exc.value)


def test_invalid_parameter_changes_are_refused_with_a_reason(rig):
    r = rig()
    res = r.node.set_parameters([Parameter('publish_period_s', value=-1.0),
                                 Parameter('on_motion', value='jump'),
                                 Parameter('resume', value=True),
                                 Parameter('publish_period_s', value=5.0)])
    assert not res[0].successful and 'out of range' in res[0].reason
    assert not res[1].successful and 'warn, pause, restart' in res[1].reason
    assert not res[2].successful and 'read-only' in res[2].reason
    assert res[3].successful and r.node.values['publish_period_s'] == 5.0
    # An integer for a double (what `ros2 param set node min_duration_s 600` sends) is
    # taken as that number; rclpy alone refuses it for its type.
    (res,) = r.node.set_parameters([Parameter('publish_period_s', value=7)])
    assert res.successful, res.reason
    value = r.node.get_parameter('publish_period_s').value
    assert value == 7.0 and isinstance(value, float) and r.node.values['publish_period_s'] == 7.0
    (res,) = r.node.set_parameters([Parameter('publish_period_s', value='7')])
    assert not res.successful


# ----------------------------------------------------------------- services
def _call(r: Rig, name: str) -> Trigger.Response:
    client = r.peer.create_client(Trigger, f'{NODE}/{name}')
    assert client.wait_for_service(timeout_sec=10)
    future = client.call_async(Trigger.Request())
    wait(future.done, 30, f'~/{name}')
    r.peer.destroy_client(client)
    return future.result()


def test_save_and_reset_services(rig, tmp_path):
    r = rig()
    res = _call(r, 'save')
    assert not res.success and 'not enough data' in res.message
    r.feed(*_record(200.0, 20.0))
    res = _call(r, 'save')
    assert res.success, res.message
    out = Path(r.node.output_dir)
    for name in ('result.json', 'imu.yaml', 'kalman_qr.yaml', 'summary.txt',
                 'checkpoint.npz'):
        assert (out / name).is_file() and str(out / name) in res.message
    assert json.loads((out / 'result.json').read_text())['n_samples'] == 4000
    ekf = yaml.safe_load((out / 'ekf_imu.yaml').read_text())
    assert ekf['ekf_filter_node']['ros__parameters']['imu0'] == '/imu'   # relay off
    res = _call(r, 'reset')
    assert res.success and 'reset' in res.message
    assert r.node.session.stats.n_used == 0 and r.node.last_result is None


def test_resume_is_confirmed_across_a_gap_in_the_first_samples(context, tmp_path):
    # A reader that has just started often misses messages: a gap among the samples
    # that check the rate must not pass for another rate and set the checkpoint aside.
    t, y = _record(200.0, 20.0)
    first = Rig(context, tmp_path)
    try:
        first.feed(t[:2000], y[:2000])
        assert _call(first, 'save').success
    finally:
        first.close()
    second = Rig(context, tmp_path, resume=True)
    try:
        keep = np.r_[2000:2010, 2300:4000]  # 1.45 s lost after the first 10 samples
        second.feed(t[keep], y[keep])
        # A fresh session (the checkpoint refused) would count only the new samples.
        wait(lambda: second.node.session.stats.n_received == 2000 + keep.size, 20,
             'the checkpoint plus the new samples')
        assert not list(tmp_path.glob('checkpoint.npz.*'))  # nothing set aside
    finally:
        second.close()


def _good_checkpoint(path: Path, n: int = 4000) -> int:
    """Write a checkpoint of n still samples at 200 Hz with the pipeline; return n_used."""
    t, y = _record(200.0, n / 200.0, seed=3)
    session = Session(SessionConfig())
    session.add(t, y)
    path.parent.mkdir(parents=True, exist_ok=True)
    session.save_state(path)
    return session.stats.n_used


def _rewrite_meta(path: Path, **changes) -> None:
    """Rewrite fields of a checkpoint's session metadata (a file that loads but lies)."""
    with np.load(path) as z:
        arrays = dict(z)
    meta = json.loads(str(arrays['session_meta']))
    for key, value in changes.items():
        target = meta
        *parents, leaf = key.split('__')
        for k in parents:
            target = target[k]
        target[leaf] = value
    arrays['session_meta'] = np.array(json.dumps(meta))
    with open(path, 'wb') as f:
        np.savez(f, **arrays)


@pytest.mark.parametrize('damage', ['empty', 'truncated', 'garbage', 'rate_zero',
                                    'negative_count', 'string_stamp', 'directory'])
def test_a_damaged_checkpoint_is_set_aside_and_the_node_starts_fresh(
        context, tmp_path, capfd, damage):
    ck = tmp_path / 'checkpoint.npz'
    _good_checkpoint(ck)
    good = ck.read_bytes()
    if damage == 'empty':
        ck.write_bytes(b'')
    elif damage == 'truncated':
        ck.write_bytes(good[:len(good) // 2])
    elif damage == 'garbage':
        ck.write_bytes(np.random.default_rng(4).bytes(5000))
    elif damage == 'rate_zero':
        _rewrite_meta(ck, clock__rate_hz=0.0)
    elif damage == 'negative_count':
        _rewrite_meta(ck, stats__n_used=-5)
    elif damage == 'string_stamp':
        _rewrite_meta(ck, clock__first_stamp_ns='yesterday')
    else:
        ck.unlink()
        ck.mkdir()
    damaged = None if ck.is_dir() else ck.read_bytes()
    r = Rig(context, tmp_path, resume=True)
    try:
        aside = list(tmp_path.glob('checkpoint.npz.bad-*'))
        assert len(aside) == 1 and not ck.exists()
        if damaged is not None:
            assert aside[0].read_bytes() == damaged            # kept as it was
        assert r.node.session.stats.n_received == 0           # a fresh session
        t, y = _record(200.0, 5.0, t0_ns=T0_NS + 3600 * 10 ** 9)
        r.feed(t, y)
        wait(lambda: r.node.session.stats.n_used == t.size, 20, 'the new samples')
    finally:
        r.close()
    err = capfd.readouterr().err
    assert 'not resuming: the checkpoint cannot be used (' in err and 'starting fresh' in err, err
    assert 'Traceback' not in err


_SAVE_LOOP = """
import sys
import numpy as np
from imu_allan.pipeline.session import Session, SessionConfig
path, seed = sys.argv[1], int(sys.argv[2])
rng = np.random.default_rng(seed)
session = Session(SessionConfig())
t0, k = 1_700_000_000 * 10 ** 9, 0
while True:          # add a second of samples, save, again: until SIGKILL
    t = t0 + (k + np.arange(200, dtype=np.int64)) * 5_000_000
    y = 1e-3 * rng.standard_normal((200, 6))
    y[:, 5] += 9.81
    session.add(t, y)
    k += 200
    if k >= 1000:
        session.save_state(path)
        print(k, flush=True)
"""


def test_a_sigkill_during_a_save_never_leaves_a_checkpoint_that_stops_the_next_start(
        context, tmp_path):
    ck = tmp_path / 'checkpoint.npz'
    rng = np.random.default_rng(11)
    left_temporaries = 0
    # At least 5 kills, and more (up to 20) until one has landed inside a save: how
    # often one does depends on how long a save takes beside the adds around it.
    for round_ in range(20):
        if round_ >= 5 and left_temporaries:
            break
        proc = subprocess.Popen([sys.executable, '-c', _SAVE_LOOP, str(ck), str(round_)],
                                stdout=subprocess.PIPE, text=True)
        assert proc.stdout.readline().strip()       # the first checkpoint is written
        time.sleep(float(rng.uniform(0.05, 0.5)))   # then killed at a random moment
        proc.kill()
        proc.wait(10)
        assert proc.returncode == -signal.SIGKILL
        left_temporaries += bool(list(tmp_path.glob('.checkpoint.npz.*.tmp')))
        on_disk = Session.load_state(ck)             # whole: the last completed save
        r = Rig(context, tmp_path, resume=True)
        try:
            session = r.node.session
            session.break_segment()
            on_disk.break_segment()
            assert session.stats.n_used == on_disk.stats.n_used >= 1000
            assert not list(tmp_path.glob('checkpoint.npz.bad-*'))
            assert not list(tmp_path.glob('.checkpoint.npz.*.tmp'))   # cleaned at start
        finally:
            r.close()
    # The kills did land inside saves (a temporary file left behind) at least once.
    assert left_temporaries >= 1


def test_reset_deletes_the_checkpoint_so_a_resume_starts_from_nothing(context, tmp_path):
    ck = tmp_path / 'checkpoint.npz'
    first = Rig(context, tmp_path)
    try:
        first.feed(*_record(200.0, 10.0))
        assert _call(first, 'save').success and ck.exists()
        assert _call(first, 'reset').success
        assert not ck.exists()
    finally:
        first.close()
    second = Rig(context, tmp_path, resume=True)
    try:
        assert second.node.session.stats.n_received == 0
        assert not list(tmp_path.glob('checkpoint.npz.*'))
    finally:
        second.close()


def test_an_undecodable_payload_drops_only_itself(rig):
    r = rig()
    t, y = _record(200.0, 10.0)
    rows = [row.tobytes() for row in serialize_imu(t, y)]
    bad = {500: rows[500][:40], 1200: b'\x00\x01\x00\x00' + b'\xff' * 60,
           1900: rows[1900][:-120]}
    pub = r.publisher()
    start = r.node.n_received
    for k, row in enumerate(rows):
        if k % 100 == 0:
            wait(lambda: r.node.n_received - start >= k - WINDOW, 30, 'the node')
        if k in bad:
            pub.publish(bad[k])
        pub.publish(row)
    wait(lambda: r.node.n_received - start == len(rows) + len(bad), 30, 'every message')
    r.node.live.process()
    # Every good message of the batches the bad ones came in still counts.
    assert r.node.live.n_undecodable == len(bad)
    assert r.node.session.stats.n_received == len(rows)
    level, message, values = input_status(r)
    assert values['n_undecodable'] == str(len(bad))
    assert f'{len(bad)} messages were not decodable' in message


def test_diagnose_service_runs_in_the_background_and_publishes_the_summary(rig):
    r = rig()
    sub = r.subscribe(f'{NODE}/diagnosis', String)
    res = _call(r, 'diagnose')
    assert not res.success and 'not enough data' in res.message
    r.feed(*_record(200.0, 20.0))
    res = _call(r, 'diagnose')
    assert res.success and 'background' in res.message, res.message
    wait(lambda: r.last('diagnosis') is not None, 60, '~/diagnosis')
    lines = r.last('diagnosis').data.splitlines()
    assert [ln.split(':')[0] for ln in lines] == list(AXES)
    assert all('gap' in ln for ln in lines)
    r.peer.destroy_subscription(sub)


def test_the_node_keeps_raw_samples_for_the_diagnosis_periodogram(rig):
    t, y = _record(200.0, 20.0)
    r = rig()
    r.feed(t, y)
    r.node.live.process()
    view, raw = r.node.live.snapshot()
    # All 4000 samples fit in the default 1048576 rows: kept as they came.  The session
    # itself holds back at most the spike filter's chunk and context and one window.
    assert raw.kept_rate_hz == 200.0
    assert 0 <= t.size - view.stats.n_used <= CHUNK + CONTEXT + 200
    assert_allclose(raw.samples, y, rtol=0, atol=0)
    small = rig(diagnose_raw_samples=1000)
    small.feed(t, y)
    small.node.live.process()
    raw = small.node.live.snapshot()[1]
    # Full three times, so pairs were averaged three times: the means of eight samples.
    assert raw.kept_rate_hz == 25.0 and raw.samples.shape == (500, 6)
    assert_allclose(raw.samples, y.reshape(-1, 8, 6).mean(axis=1), rtol=1e-12)
    assert _call(small, 'reset').success
    assert small.node.live.snapshot()[1] is None          # a new session, a new copy
    none = rig(diagnose_raw_samples=0)
    none.feed(t[:1000], y[:1000])
    none.node.live.process()
    assert none.node.live.snapshot()[1] is None


# ------------------------------------------- the client (imu-allan node) and pictures
def _client(*args: str, timeout_s: float = 20.0) -> subprocess.CompletedProcess:
    """Run ``imu-allan node ...`` in another process, in this test's ROS_DOMAIN_ID."""
    return subprocess.run([sys.executable, '-m', 'imu_allan', 'node', *args,
                           '--timeout', str(timeout_s)],
                          capture_output=True, text=True, timeout=300)


def test_the_client_reads_status_and_result_and_calls_save_and_reset(rig, tmp_path):
    r = rig()
    t, y = _record(200.0, 30.0)
    r.feed(t, y)
    result = r.publish()
    status = _client('status')
    assert status.returncode == 0, status.stderr
    lines = status.stdout.splitlines()
    # One line per status, in the node's own words.
    assert {ln.split(':')[0] for ln in lines} == set(AXES) | {'input'}, lines
    for axis in AXES:
        st = statuses(r.last('noise_parameters'))[f'imu_allan: {axis}']
        assert f'{axis}: {st[1]}' in lines
    # ~/result carries result.json: the same document save writes.
    out = tmp_path / 'from_topic.json'
    got = _client('result', '--out', str(out))
    assert got.returncode == 0, got.stderr
    doc = json.loads(out.read_text())
    assert doc == json.loads(json.dumps(result.to_json()))
    saved = _client('save', '--format', 'json')
    assert saved.returncode == 0, saved.stderr
    answer = json.loads(saved.stdout)
    assert answer['success'] and 'result.json' in answer['message']
    written = json.loads((Path(r.node.output_dir) / 'result.json').read_text())
    assert written['n_samples'] == doc['n_samples'] == t.size
    reset = _client('reset')
    assert reset.returncode == 0 and 'reset' in reset.stdout, reset.stderr
    assert r.node.session.stats.n_used == 0 and r.node.last_result is None


def test_the_client_watches_until_ctrl_c_and_names_a_missing_node(rig):
    r = rig()
    r.feed(*_record(200.0, 5.0))
    r.publish()                 # the latched results: what a watcher hears first
    # A terminal's SIGINT (a shell's background job would inherit it ignored).
    proc = subprocess.Popen([sys.executable, '-m', 'imu_allan', 'node', 'watch'],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines: list = []
    reader = threading.Thread(target=lambda: lines.append(proc.stdout.readline()),
                              daemon=True)
    reader.start()
    reader.join(120)
    proc.send_signal(signal.SIGINT)
    proc.wait(30)
    err = proc.stderr.read()
    assert lines and lines[0].startswith(('gyro_x: ', 'input: ')), (lines, err)
    assert proc.returncode == 130 and 'interrupted' in err and 'Traceback' not in err
    gone = _client('status', '--node', '/no_such_node', timeout_s=1.0)
    assert gone.returncode == 2 and 'Traceback' not in gone.stderr
    assert gone.stderr.strip().splitlines() == [
        'imu-allan: error: no node /no_such_node answered /no_such_node/noise_parameters '
        'within 1 s: is it running (and in this ROS_DOMAIN_ID)? give its name with --node']


def test_the_curve_is_drawn_on_adev_image_while_someone_subscribes(rig):
    from sensor_msgs.msg import Image

    r = rig(adev_image_period_s=0.2, warmup_window_s=0.0)   # a curve from the start
    r.feed(*_record(200.0, 20.0))
    time.sleep(0.5)
    assert r.last('adev_image') is None          # nobody subscribed: nothing drawn
    r.subscribe(f'{NODE}/adev_image', Image)
    wait(lambda: r.last('adev_image') is not None, 60, 'a picture before the first fit')
    before = r.last('adev_image')
    assert (before.width, before.height, before.encoding) == (1040, 416, 'rgb8')
    pixels = np.frombuffer(bytes(before.data), np.uint8).reshape(416, 1040, 3)
    # The curve's colours are there, not a blank page.
    assert (np.ptp(pixels.astype(int), axis=2) > 100).sum() > 500
    r.publish()
    # A picture started before the fit may still arrive; one after it has the models.
    wait(lambda: not np.array_equal(np.frombuffer(bytes(r.last('adev_image').data),
                                                  np.uint8), pixels.ravel()),
         60, 'a picture with the models drawn over the curve')


def test_a_node_destroyed_while_it_draws_publishes_nothing_after(context, tmp_path,
                                                                 monkeypatch):
    # The picture thread published through a destroyed node: a traceback in the thread
    # (InvalidHandle) at every shutdown that came while it drew.
    from sensor_msgs.msg import Image

    errors = []
    monkeypatch.setattr(threading, 'excepthook', errors.append)
    r = Rig(context, tmp_path / 'out', adev_image_period_s=0.2, warmup_window_s=0.0)
    r.feed(*_record(200.0, 20.0))
    r.subscribe(f'{NODE}/adev_image', Image)
    drawing = r.node.pictures
    wait(lambda: drawing._thread is not None and drawing._thread.is_alive(), 60,
         'a picture being drawn')
    r.close()
    drawing._thread.join()
    assert not errors, [str(e.exc_value) for e in errors]


# ------------------------------------------------------ the executable itself
def _start(out: Path, *params: str, env: dict | None = None) -> subprocess.Popen:
    exe = Path(sys.executable).parent / 'imu_allan_node'
    cmd = [str(exe) if exe.exists() else sys.executable]
    if not exe.exists():
        cmd += ['-m', 'imu_allan.ros.node']
    cmd += ['--ros-args', '-p', f'output_dir:={out}', '-p', 'process_period_s:=0.05',
            '-p', 'checkpoint_period_s:=0.3', '-p', 'min_duration_s:=1.0',
            '-p', 'progress_period_s:=1.0']
    for p in params:
        cmd += ['-p', p]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)


class Player:
    """Publisher of a simulated record to a node in another process, in real order."""

    def __init__(self, context):
        self.node = rclpy.create_node('imu_allan_test_player', context=context)
        self.pub = self.node.create_publisher(
            Imu, 'imu', QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE))

    def endpoints(self) -> set:
        """Return the gids of the subscriptions to /imu in the graph."""
        return {bytes(i.endpoint_gid) for i in self.node.get_subscriptions_info_by_topic('/imu')}

    def play(self, stamps, samples, known: set, per_second: float = 5000.0) -> None:
        """Wait for a subscription not in ``known`` (a new process), then publish."""
        wait(lambda: self.endpoints() - known, 20, 'the node process')
        time.sleep(2.0)     # the graph shows the reader before DDS has matched it
        payloads = serialize_imu(stamps, samples)
        t0 = time.monotonic()
        for k in range(0, len(payloads), 100):
            for row in payloads[k:k + 100]:
                self.pub.publish(row.tobytes())
            time.sleep(max(0.0, t0 + (k + 100) / per_second - time.monotonic()))

    def close(self):
        self.node.destroy_node()


def _checkpoint_used(path: Path) -> int:
    # What a resume restores: the used samples plus those held for the motion check.
    session = Session.load_state(path)
    session.break_segment()
    return session.stats.n_used


def test_checkpoint_and_resume_across_a_killed_process(context, tmp_path):
    out = tmp_path / 'out'
    player = Player(context)
    try:
        t, y = _record(200.0, 60.0)
        proc = _start(out)
        player.play(t[:6000], y[:6000], set())
        ck = out / 'checkpoint.npz'
        wait(lambda: ck.exists() and _checkpoint_used(ck) >= 5000, 20, 'a checkpoint')
        proc.kill()                                           # SIGKILL: no goodbye
        proc.communicate(timeout=10)
        saved = _checkpoint_used(ck)
        assert proc.returncode == -signal.SIGKILL and not (out / 'result.json').exists()

        known = player.endpoints()
        proc = _start(out, 'resume:=true')
        player.play(t[6000:], y[6000:], known)
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err[-3000:]
        assert f'resumed from {ck}: {saved} samples' in err
        assert 'resume confirmed: incoming rate 200.000 Hz' in err, err
        assert 'Traceback' not in err and 'wrote ' in err
        result = json.loads((out / 'result.json').read_text())
        # Everything in the checkpoint counts, plus the new samples that arrived (the
        # best-effort reader of a freshly started process misses some of the first).
        new = t.size - 6000
        assert saved + 0.25 * new <= result['n_samples'] <= saved + new, result['hygiene']
        assert 'split from the new samples' in err       # no term spans the lost tail

        known = player.endpoints()
        proc = _start(out, 'resume:=true')                   # now at 100 Hz: refused
        t2 = t[-1] + 10_000_000 * np.arange(1, 301)
        player.play(t2, y[:300], known)
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert 'not resuming: the checkpoint was taken at 200.000 Hz but the data now ' \
            'arrive at 100.000 Hz' in err, err[-3000:]
        assert list(out.glob('checkpoint.npz.other-rate-*'))  # old state kept aside
    finally:
        player.close()


def test_node_runs_and_characterises_without_the_bag_libraries(context, tmp_path):
    # A robot with only the ROS runtime: rosbags, mcap, lz4 and zstandard refuse to
    # import in the node's process (stub packages first on its path).
    stubs = tmp_path / 'stubs'
    for name in ('rosbags', 'mcap', 'lz4', 'zstandard'):
        (stubs / name).mkdir(parents=True)
        (stubs / name / '__init__.py').write_text(
            f'raise ImportError("{name} is not installed on this robot")\n')
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(stubs)] + [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p]))
    out = tmp_path / 'out'
    player = Player(context)
    try:
        t, y = _record(200.0, 20.0)
        proc = _start(out, env=env)
        player.play(t, y, set())
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 0 and 'Traceback' not in err, err[-3000:]
        assert 'not installed on this robot' not in err
        result = json.loads((out / 'result.json').read_text())
        assert result['n_samples'] >= 0.5 * t.size
        for axis in AXES:
            n = result['axes'][axis]['params']['N']['value']
            assert n == pytest.approx(SPEC.axes[axis].N, rel=0.1), axis
    finally:
        player.close()


def test_executable_refuses_a_bad_parameter_without_traceback(tmp_path):
    proc = _start(tmp_path, 'on_motion:=jump')
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2
    assert 'imu_allan_node: error: invalid parameter: on_motion must be one of' in err
    assert 'Traceback' not in err


def test_executable_without_data_shuts_down_cleanly_on_sigint(tmp_path):
    proc = _start(tmp_path)
    deadline = time.monotonic() + 30
    line = ''
    while 'listening on' not in line and time.monotonic() < deadline:
        line = proc.stderr.readline()
    time.sleep(0.5)                  # past the constructor: the executor is spinning
    proc.send_signal(signal.SIGINT)
    proc.wait(30)
    err = proc.stderr.read()         # not communicate(): readline() buffered the pipe
    assert proc.returncode == 0 and 'Traceback' not in err
    # At once, before the save that may take seconds, then why nothing was written.
    saving = err.index('saving the results')
    assert saving < err.index('nothing written on shutdown: not enough data'), err


@pytest.mark.parametrize('glitch', ['stamp_a_day_ahead', 'device_clock_restarted'])
def test_a_glitched_stamp_or_a_restarted_clock_poisons_nothing_across_a_resume(
        context, tmp_path, glitch):
    # Before the resume: a stamp a day ahead is one dropped outlier, not a new clock,
    # and is not saved as the newest stamp. After it: data from a device whose clock
    # restarted (stamps an hour earlier) start a new segment and are used.
    t, y = _record(200.0, 10.0)
    if glitch == 'stamp_a_day_ahead':
        t = t.copy()
        t[1000] += 86_400 * 10 ** 9
    first = Rig(context, tmp_path)
    try:
        first.feed(t, y)
        assert _call(first, 'save').success
        used = first.node.session.stats.n_used
        assert used >= t.size - 1
        assert first.node.session.stats.n_stamp_outliers == (glitch == 'stamp_a_day_ahead')
    finally:
        first.close()
    if glitch == 'stamp_a_day_ahead':
        t2, y2 = _record(200.0, 10.0, seed=2, t0_ns=int(t[-1]) + 5_000_000)
    else:
        t2, y2 = _record(200.0, 10.0, seed=2, t0_ns=T0_NS - 3600 * 10 ** 9)
    second = Rig(context, tmp_path, resume=True)
    try:
        assert second.node.session.stats.n_used == used        # resumed, not refused
        second.feed(t2, y2)
        wait(lambda: (second.node.live.process() or True)
             and second.node.session.stats.n_used >= used + t2.size - 1, 30,
             'the new samples after the resume')
        # The day-ahead stamp was not kept as the newest: the data go on, no restart.
        assert second.node.session.stats.n_clock_restarts == (
            glitch == 'device_clock_restarted')
    finally:
        second.close()
