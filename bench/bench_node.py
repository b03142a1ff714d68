"""
Benchmark of the live node (imu_allan.ros.node) with real rclpy topics.

Three measurements, each in fresh processes (a benchmark, not a test):

1. ``realtime``: a publisher *in another process* sends sensor_msgs/Imu at ``--rate``
   (1 kHz) with best-effort sensor-data QoS for ``--seconds``; the node runs in a
   second process with the chosen executor(s).  Reported: messages published and
   received (drops), the node process' CPU time over wall time (all its threads,
   DDS included) in % of one core, measured after a 2 s warm-up, and its RSS.
   With ``--fit-every S`` the node also fits and publishes every S seconds, and the
   CPU of those fits is reported apart (they run on a worker thread).
2. ``flood``: the same two processes, the publisher at ``--flood-rate`` (20 000 msg/s,
   20x real time) for ``--flood-seconds``: the throughput the node sustains and its
   RSS over time.  A 24 h stream at 1 kHz (86.4 M messages) cannot be sent through DDS
   here in reasonable time, so the RSS slope per million messages is measured and
   extrapolated, and measurement 3 covers the full count without DDS.
3. ``pipeline``: the node's Session fed the full 86.4 M samples of 24 h at 1 kHz in
   the node's block size, bypassing DDS: RSS and accumulator state at every hour.

Usage::

    .venv/bin/python bench/bench_node.py [--executor events,single,multi]
        [--rate 1000] [--seconds 30] [--fit-every 0] [--flood-seconds 60]
        [--pipeline-hours 24] [--only realtime,flood,pipeline]
"""

import argparse
import json
import os
from pathlib import Path
import resource
import subprocess
import sys
import tempfile
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

START_NS = 1_700_000_000 * 10 ** 9
HERE = Path(__file__).resolve()
PARAMS = HERE.parent.parent / 'config' / 'xsens_mti7.yaml'


def _rss_mb() -> float:
    with open('/proc/self/statm') as f:
        return int(f.read().split()[1]) * os.sysconf('SC_PAGE_SIZE') / 2 ** 20


def _sensor_qos(depth: int = 2000):
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.BEST_EFFORT)


# ---------------------------------------------------------------- child processes
def role_publisher(args) -> int:
    """
    Publish at a fixed wall-clock rate; print a JSON line with the count.

    The stamps are those of a 1 kHz IMU whatever the sending rate, so a sending rate
    above 1 kHz is the same sensor fed faster than real time.  One minute of simulated
    samples is replayed with ever-increasing stamps (serialised chunk by chunk).
    """
    import rclpy
    from sensor_msgs.msg import Imu
    from imu_allan.core.noise.params import load_params
    from imu_allan.core.noise.simulate import simulate_imu
    from imu_allan.io.bag_writer import serialize_imu
    _, block = simulate_imu(load_params(PARAMS), 1000.0, 60.0, seed=1)
    rclpy.init(args=[])
    node = rclpy.create_node('bench_imu_publisher')
    pub = node.create_publisher(Imu, 'imu', _sensor_qos())
    deadline = time.monotonic() + 30
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)   # let discovery settle on both sides
    n_total = int(args.rate * args.seconds)
    chunk = 1000
    t0 = time.perf_counter()
    sent = 0
    while sent < n_total:
        k = sent % block.shape[0]
        rows = block[k:k + min(chunk, n_total - sent)]
        stamps = START_NS + (sent + np.arange(rows.shape[0], dtype=np.int64)) * 1_000_000
        payloads = [p.tobytes() for p in serialize_imu(stamps, rows)]
        j = 0
        while j < len(payloads):
            due = min(int((time.perf_counter() - t0) * args.rate) + 1 - sent, len(payloads))
            while j < due:
                pub.publish(payloads[j])
                j += 1
            sent_now = sent + j
            time.sleep(max(0.0, t0 + sent_now / args.rate - time.perf_counter()))
        sent += len(payloads)
    wall = time.perf_counter() - t0
    print(json.dumps({'published': sent, 'wall_s': wall}), flush=True)
    time.sleep(1.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def role_node(args) -> int:
    """Run the node with one executor until the stream ends; print a JSON line."""
    import rclpy
    from rclpy.parameter import Parameter
    from imu_allan.ros.node import ImuAllanNode
    from imu_allan.ros.spin import create_executor
    rclpy.init(args=[])
    out = tempfile.mkdtemp(prefix='bench_node_')
    fit_every = args.fit_every
    node = ImuAllanNode(parameter_overrides=[
        Parameter('output_dir', value=out),
        Parameter('min_duration_s', value=float(fit_every) if fit_every else 1.0e6),
        Parameter('publish_period_s', value=float(fit_every) if fit_every else 86400.0),
        Parameter('checkpoint_period_s', value=60.0),
    ])
    executor = create_executor(args.executor)
    executor.add_node(node)
    done = rclpy.task.Future()
    marks = {}
    fit_cpu = [0.0]

    def fit_cpu_clock():
        # CPU of the worker threads (fits): thread CPU clocks summed by the wrapper.
        return fit_cpu[0]

    original = node._fit_and_publish

    def timed_fit(view):
        c0 = time.thread_time()
        try:
            return original(view)
        finally:
            fit_cpu[0] += time.thread_time() - c0
    node._fit_and_publish = timed_fit

    trace = []

    def watch():
        now = time.monotonic()
        if node.n_received and 'first' not in marks:
            marks['first'] = now
            marks['next'] = now
        if 'first' in marks and now >= marks['next'] and 'end' not in marks:
            acc = node.session.acc
            trace.append((now - marks['first'], node.n_received, _rss_mb(),
                          acc.state_nbytes() / 2 ** 20 if acc is not None else 0.0,
                          len(node.live.buffer)))
            marks['next'] = now + args.seconds / 20
        if 'first' in marks:
            if 'warm' not in marks and now - marks['first'] >= 2.0:
                marks['warm'] = (now, time.process_time(), node.n_received, fit_cpu_clock())
            if now - marks['first'] >= args.seconds and 'end' not in marks:
                marks['end'] = (now, time.process_time(), node.n_received, fit_cpu_clock())
            if now - marks['first'] >= args.seconds + 2.0:
                done.set_result(True)
    node.create_timer(0.1, watch)
    from imu_allan.ros.spin import spin_until_shutdown
    node.create_timer(0.5, lambda: done.done() and rclpy.shutdown())
    spin_until_shutdown(executor)
    w0, c0, n0, f0 = marks['warm']
    w1, c1, n1, f1 = marks['end']
    report = {
        'executor': args.executor, 'received': node.n_received,
        'cpu_pct': 100.0 * (c1 - c0) / (w1 - w0),
        'fit_cpu_pct': 100.0 * (f1 - f0) / (w1 - w0),
        'fits': node.n_fits, 'rx_rate_hz': (n1 - n0) / (w1 - w0),
        'rss_mb': _rss_mb(),
        'max_rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        'used': node.session.stats.n_used, 'warnings': node.session.warnings,
        'trace': trace,
    }
    print(json.dumps(report), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def role_pipeline(args) -> int:
    """Feed the Session the samples of ``--pipeline-hours`` at 1 kHz; RSS per hour."""
    from imu_allan.core.noise.params import load_params
    from imu_allan.core.noise.simulate import simulate_imu
    from imu_allan.pipeline.session import Session
    from imu_allan.ros.params import BY_NAME, session_config
    values = {name: p.default for name, p in BY_NAME.items()}
    values['rate_hz'] = 1000.0
    session = Session(session_config(values))
    _, block = simulate_imu(load_params(PARAMS), 1000.0, 600.0, seed=3)
    per_block = 200   # what the node's process timer hands over at 1 kHz / 0.2 s
    big = 100_000
    n_total = int(args.pipeline_hours * 3600 * 1000)
    sent = 0
    t0 = time.monotonic()
    trace = [(0.0, 0, _rss_mb(), 0.0)]
    hour = 3_600_000
    while sent < n_total:
        k = sent % block.shape[0]
        rows = block[k:k + big]
        stamps = START_NS + (sent + np.arange(rows.shape[0], dtype=np.int64)) * 1_000_000
        for j in range(0, rows.shape[0], per_block):
            session.add(stamps[j:j + per_block], rows[j:j + per_block])
        sent += rows.shape[0]
        if sent % hour < big:
            trace.append((time.monotonic() - t0, sent, _rss_mb(),
                          session.acc.state_nbytes() / 2 ** 20))
    print(json.dumps({'samples': sent, 'used': session.stats.n_used,
                      'wall_s': time.monotonic() - t0, 'trace': trace}), flush=True)
    return 0


# ----------------------------------------------------------------- the parent
def _child(role: str, args, extra=()) -> subprocess.Popen:
    cmd = [sys.executable, str(HERE), '--role', role, '--rate', str(args.rate),
           '--seconds', str(args.seconds), '--fit-every', str(args.fit_every),
           '--flood-seconds', str(args.flood_seconds),
           '--flood-rate', str(getattr(args, 'flood_rate', 20000.0)),
           '--pipeline-hours', str(args.pipeline_hours), *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)


def _last_json(proc: subprocess.Popen) -> dict:
    out, _ = proc.communicate(timeout=600)
    lines = [ln for ln in out.splitlines() if ln.startswith('{')]
    if proc.returncode or not lines:
        raise RuntimeError(f'child failed (exit {proc.returncode}): {out[-2000:]}')
    return json.loads(lines[-1])


def run_realtime(args, executor: str) -> dict:
    """Run a publisher process and a node process; return the merged figures."""
    node = _child('node', args, ('--executor', executor))
    time.sleep(3.0)   # node up before the publisher starts counting
    pub = _child('publisher', args)
    p = _last_json(pub)
    n = _last_json(node)
    n.update(published=p['published'], pub_wall_s=p['wall_s'],
             drops=p['published'] - n['received'])
    return n


def main() -> int:
    """Parse arguments, run the selected measurements, print a summary."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--role', default='parent',
                    choices=('parent', 'publisher', 'node', 'pipeline'))
    ap.add_argument('--executor', default='events,single,multi')
    ap.add_argument('--rate', type=float, default=1000.0)
    ap.add_argument('--seconds', type=float, default=30.0)
    ap.add_argument('--fit-every', type=float, default=0.0)
    ap.add_argument('--flood-seconds', type=float, default=60.0)
    ap.add_argument('--flood-rate', type=float, default=20000.0)
    ap.add_argument('--pipeline-hours', type=float, default=24.0)
    ap.add_argument('--only', default='realtime,flood,pipeline')
    args = ap.parse_args()
    if args.role != 'parent':
        return {'publisher': role_publisher, 'node': role_node,
                'pipeline': role_pipeline}[args.role](args)
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    only = args.only.split(',')
    if 'realtime' in only:
        print(f'realtime: {args.rate:g} Hz for {args.seconds:g} s, publisher in another '
              f'process, best-effort depth 2000; fit every {args.fit_every or "never"} s')
        for ex in args.executor.split(','):
            r = run_realtime(args, ex)
            print(f'  {ex:7s} published {r["published"]:7d} received {r["received"]:7d} '
                  f'drops {r["drops"]:5d}  CPU {r["cpu_pct"]:5.1f}% of one core '
                  f'(fits {r["fit_cpu_pct"]:.1f}%, {r["fits"]} fits)  '
                  f'RSS {r["rss_mb"]:.0f} MB', flush=True)
    if 'flood' in only:
        ex = args.executor.split(',')[0]
        flood = argparse.Namespace(**vars(args))
        flood.rate, flood.seconds, flood.fit_every = args.flood_rate, args.flood_seconds, 0.0
        r = run_realtime(flood, ex)
        tr = np.array(r['trace'], dtype=float)
        half = tr[len(tr) // 2:]
        slope = np.polyfit(half[:, 1] / 1e6, half[:, 2], 1)[0] if len(half) > 2 else 0.0
        print(f'flood ({ex}): publisher process at {flood.rate:,.0f} msg/s for '
              f'{flood.seconds:g} s: {r["received"]:,} of {r["published"]:,} received '
              f'({r["rx_rate_hz"]:,.0f} msg/s = {r["rx_rate_hz"] / 1000:.1f}x real time at '
              f'1 kHz), node CPU {r["cpu_pct"]:.0f}% of one core')
        for t, n, rss, acc, buf in r['trace']:
            print(f'  t {t:6.1f} s  received {int(n):9,d}  RSS {rss:7.1f} MB  '
                  f'accumulator state {acc:5.2f} MB  buffer {int(buf)}')
        print(f'  RSS slope over the second half: {slope:+.3f} MB per million messages '
              f'-> {slope * 86.4:+.1f} MB extrapolated to 86.4 M (24 h at 1 kHz)')
    if 'pipeline' in only:
        r = _last_json(_child('pipeline', args))
        print(f'pipeline: {r["samples"]:,} samples ({r["samples"] / 3.6e6:.1f} h at 1 kHz) '
              f'through the node\'s Session in 200-sample blocks in {r["wall_s"]:.0f} s '
              f'({r["samples"] / r["wall_s"] / 1e6:.2f} M samples/s)')
        for t, n, rss, acc in r['trace']:
            print(f'  {n / 3.6e6:5.1f} h  RSS {rss:7.1f} MB  accumulator state {acc:5.2f} MB')
    return 0


if __name__ == '__main__':
    sys.exit(main())
