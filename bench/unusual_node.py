"""
Node situations of the unusual-input campaign: SIGTERM during a fit, sim time without a clock.

Each case starts the node of this checkout (``python -m imu_allan.ros.node``) on a
ROS domain of its own, publishes a seeded simulation (bench/unusual.py's noise model,
400 Hz) to ``/imu`` from this process, then

* ``sigterm``: fits every 0.5 s, and SIGTERM comes 0-2 s (seeded) after the data: the
  node must exit 0 with no traceback on stderr and write result.json whose N holds
  its truth (bench/unusual_campaign.py's rule);
* ``sim_time``: ``use_sim_time:=true`` and no ``/clock`` (a bag played without
  ``--clock``): a checkpoint must be written within 10 s of the data, so a ``kill -9``
  loses at most one checkpoint period (else a silent loss).

Outcomes as bench/unusual_campaign.py's; rclpy is imported only here.
"""

import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import numpy as np

import unusual

REPO = Path(__file__).resolve().parents[1]
RATE_HZ, SECONDS = 400.0, 30.0


def _start(out: Path, env: dict, *params: str) -> subprocess.Popen:
    cmd = [sys.executable, '-m', 'imu_allan.ros.node', '--ros-args', '-p',
           f'output_dir:={out}', '-p', 'process_period_s:=0.05', '-p',
           'checkpoint_period_s:=0.5', '-p', 'min_duration_s:=5.0']
    for p in params:
        cmd += ['-p', p]
    return subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _play(node, pub, stamps, samples) -> None:
    """Wait for the node's subscription, then publish every sample at 10 kHz."""
    from imu_allan.io.bag_writer import serialize_imu
    deadline = time.monotonic() + 30
    while not node.get_subscriptions_info_by_topic('/imu'):
        if time.monotonic() > deadline:
            raise RuntimeError('the node process did not subscribe')
        time.sleep(0.05)
    time.sleep(2.0)     # the graph shows the reader before DDS has matched it
    t0 = time.monotonic()
    for k, row in enumerate(serialize_imu(stamps, samples)):
        pub.publish(row.tobytes())
        if k % 100 == 99:
            time.sleep(max(0.0, t0 + (k + 1) / 10_000.0 - time.monotonic()))


def node_case(kind: str, seed: int, folder: Path) -> tuple:
    """Run one node situation; return (outcome, note)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu
    from unusual_campaign import AXES, _n_misses
    domain = str(100 + (os.getpid() + seed) % 100)
    os.environ['ROS_DOMAIN_ID'] = domain
    env = dict(os.environ, ROS_DOMAIN_ID=domain)
    ctx = Context()
    rclpy.init(args=[], context=ctx, domain_id=int(domain))
    node = rclpy.create_node('unusual_player', context=ctx)
    pub = node.create_publisher(Imu, 'imu', QoSProfile(
        depth=5000, reliability=ReliabilityPolicy.RELIABLE))
    rng = np.random.default_rng([seed, 7])
    n = int(RATE_HZ * SECONDS)
    stamps = unusual.grid(RATE_HZ, n, rng)
    samples = unusual.simulate(RATE_HZ, n, seed)
    out = folder / 'out'
    params = ['publish_period_s:=0.5'] if kind == 'sigterm' else ['use_sim_time:=true']
    proc = _start(out, env, *params)
    try:
        _play(node, pub, stamps, samples)
        if kind == 'sigterm':
            time.sleep(float(rng.uniform(0.0, 2.0)))
            proc.send_signal(signal.SIGTERM)
            _, err = proc.communicate(timeout=120)
            if 'Traceback' in err or proc.returncode != 0:
                return 'TRACEBACK', f'exit {proc.returncode}: {err[-600:]}'
            doc = json.loads((out / 'result.json').read_text())
            misses = [f'{a} {m}' for a, t in zip(AXES, unusual.truth_n())
                      if (m := _n_misses(doc['axes'].get(a, {}), t))]
            if misses:
                return 'WRONG RESULT', '; '.join(misses)
            return ('warned' if doc['warnings'] else 'ok'), f'{doc["n_samples"]} samples'
        deadline = time.monotonic() + 10.0
        while not (out / 'checkpoint.npz').exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        proc.kill()
        _, err = proc.communicate(timeout=30)
        if not (out / 'checkpoint.npz').exists():
            return 'SILENT LOSS', 'no checkpoint 10 s after the data (kill -9 loses all)'
        if 'Traceback' in err:
            return 'TRACEBACK', err[-600:]
        return ('warned' if '/clock' in err else 'ok'), 'checkpoint written'
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=30)
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def node_cases(rounds: int, seed: int) -> list:
    """Return the (kind, seed) of ``rounds`` draws of each node situation."""
    return [(kind, seed * 100 + r) for r in range(rounds) for kind in ('sigterm', 'sim_time')]
