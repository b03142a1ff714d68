"""
``imu-allan demo``: the node characterising a built-in simulated IMU, over real topics.

A publisher node plays a simulated six-axis record (config/xsens_mti7.yaml by default)
as sensor_msgs/Imu with synthetic header stamps, faster than real time, to the
imu_allan node in the same process; then the node's result is printed beside the truth.
"""

import argparse
from pathlib import Path
import sys
import time

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError

DEFAULT_PARAMS = Path(__file__).resolve().parent.parent / 'config' / 'xsens_mti7.yaml'
START_NS = 1_700_000_000 * 10 ** 9


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the sub-command."""
    p = subparsers.add_parser('demo', help='run the node on a simulated IMU (make demo)',
                              description=__doc__.split('\n\n')[1])
    p.add_argument('--params', type=Path, default=None,
                   help='noise parameter YAML (default: config/xsens_mti7.yaml)')
    p.add_argument('--rate', type=float, default=100.0, help='IMU rate [Hz]')
    p.add_argument('--duration', type=float, default=2 * 3600.0,
                   help='simulated recording length [s]')
    p.add_argument('--seed', type=int, default=1)
    p.add_argument('--out', type=Path, default=Path('imu_allan_demo_out'),
                   help='output directory of the node')
    p.set_defaults(run=run)
    return p


def _params_file(path: Path | None) -> Path:
    if path is not None:
        return path
    if DEFAULT_PARAMS.exists():
        return DEFAULT_PARAMS
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('imu_allan')) / 'config' / 'xsens_mti7.yaml'


def play(payloads: np.ndarray, node, publisher_node, publisher, chunk: int = 200,
         window: int = 1000, executor=None, timeout_s: float = 600.0) -> int:
    """
    Publish serialized Imu messages, keeping at most ``window`` of them in flight.

    The best-effort subscription would drop what its queue cannot hold, so the player
    waits for the node to have received the earlier messages (in-process pacing).

    Returns
    -------
    int
        Messages published.

    """
    sent = 0
    deadline = time.monotonic() + timeout_s
    n = payloads.shape[0]
    while sent < n:
        if node.n_received >= sent - window:
            for row in payloads[sent:sent + chunk]:
                publisher.publish(row.tobytes())
            sent = min(sent + chunk, n)
        else:
            time.sleep(0.0005)
        if time.monotonic() > deadline:
            raise InputError(f'demo stalled: {node.n_received} of {sent} messages received')
    while node.n_received < n and time.monotonic() < deadline:
        time.sleep(0.01)
    return sent


def run(args) -> int:
    """Simulate, publish, characterise, and print the fit beside the truth."""
    import threading

    import rclpy
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu

    from imu_allan.bag_writer import serialize_imu
    from imu_allan.node import ImuAllanNode
    from imu_allan.noise_params import load_params
    from imu_allan.simulate import simulate_imu
    from imu_allan.units import format_quoted, sensor_of

    params = _params_file(args.params)
    spec = load_params(params)
    t0 = time.monotonic()
    t_s, samples = simulate_imu(spec, args.rate, args.duration, seed=args.seed)
    stamps = START_NS + np.round(t_s * 1e9).astype(np.int64)
    payloads = serialize_imu(stamps, samples, frame_id='imu_link')
    print(f'demo: simulated {spec.name}: {samples.shape[0]:,} messages '
          f'({args.duration / 3600:.2f} h at {args.rate:g} Hz) in '
          f'{time.monotonic() - t0:.1f} s', file=sys.stderr)

    rclpy.init(args=[])
    try:
        node = ImuAllanNode(parameter_overrides=[
            Parameter('min_duration_s', value=float(args.duration) * 0.99),
            Parameter('output_dir', value=str(args.out.resolve())),
            Parameter('publish_period_s', value=3600.0),
            Parameter('progress_period_s', value=5.0),
            Parameter('checkpoint_period_s', value=0.0),
        ])
        pub_node = rclpy.create_node('simulated_imu')
        publisher = pub_node.create_publisher(
            Imu, 'imu', QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT))
        executor = MultiThreadedExecutor(num_threads=2)
        executor.add_node(node)
        executor.add_node(pub_node)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        while publisher.get_subscription_count() == 0:
            time.sleep(0.05)
        t0 = time.monotonic()
        sent = play(payloads, node, pub_node, publisher)
        seconds = time.monotonic() - t0
        print(f'demo: published {sent:,} Imu messages over rclpy in {seconds:.1f} s '
              f'({sent / seconds:,.0f} msg/s, {args.duration / seconds:.0f}x real time)',
              file=sys.stderr)
        files = node.save()
        node.publish_now()
        result = node.last_result
        executor.shutdown()
        node.destroy_node()
        pub_node.destroy_node()
    finally:
        rclpy.try_shutdown()

    print(f'\nimu_allan demo: {spec.name}')
    print(f'{result.n_samples:,} samples, {result.duration_s / 3600:.2f} h at '
          f'{result.rate_hz:.2f} Hz; fitted (95 % interval) vs truth\n')
    print(f'{"axis":8} {"param":5} {"fitted":>26} {"95% interval":>34} {"truth":>26}')
    for axis in AXES:
        fit = result.fits[axis]
        truth = spec.axes[axis]
        sensor = sensor_of(axis)
        for sym in ('N', 'B', 'K', 'T_B'):
            p = fit.optimised[sym]
            true_value = getattr(truth, sym) or float('nan')
            lo = format_quoted(sym, sensor, p.ci95[0], 3)
            hi = format_quoted(sym, sensor, p.ci95[1], 3)
            mark = '<' if p.kind == 'upper_bound' else ' '
            print(f'{axis:8} {sym:5} {mark}{format_quoted(sym, sensor, p.value, 4):>25} '
                  f'{"[" + lo + ", " + hi + "]":>34} '
                  f'{format_quoted(sym, sensor, true_value, 4):>26}')
    if result.warnings:
        print('\nwarnings: ' + ' | '.join(result.warnings))
    print(f'\nfiles written by the node: {Path(files[0]).parent}/')
    for f in files:
        print(f'  {Path(f).name}')
    return 0
