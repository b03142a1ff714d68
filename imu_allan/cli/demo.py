"""
``imu-allan demo``: the node characterising a built-in simulated IMU, over real topics.

A publisher process plays a simulated six-axis record (config/xsens_mti7.yaml by
default) as sensor_msgs/Imu with synthetic header stamps, faster than real time, to the
imu_allan node in this process; then the node's result is printed beside the truth.
"""

import argparse
import math
from pathlib import Path
import sys
import time

import numpy as np

from imu_allan import AXES
from imu_allan.cli.outdir import prepare_out_dir
from imu_allan.errors import InputError

DEFAULT_PARAMS = Path(__file__).resolve().parents[2] / 'config' / 'xsens_mti7.yaml'
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
    p.add_argument('--speed', type=float, default=10000.0,
                   help='messages per second sent to the node [1/s]')
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
    # An installed package: the config is in its share directory.
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory('imu_allan')) / 'config' / 'xsens_mti7.yaml'
    except (ImportError, LookupError, OSError) as exc:
        raise InputError(f'no default parameter file ({exc}); give one with --params') from None


def publish_main(argv=None) -> int:
    """
    Play serialized Imu messages at a fixed pace (the publisher process of the demo).

    Parameters
    ----------
    argv : list of str, optional
        ``[payloads.npy, messages_per_second]`` (default: sys.argv[1:]).

    Returns
    -------
    int
        Exit code.

    """
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu

    path, per_second = (argv or sys.argv[1:])[:2]
    per_second = float(per_second)
    payloads = np.load(path)
    rclpy.init(args=[])
    node = rclpy.create_node('simulated_imu')
    try:
        pub = node.create_publisher(
            Imu, 'imu', QoSProfile(depth=2000, reliability=ReliabilityPolicy.BEST_EFFORT))
        deadline = time.monotonic() + 30
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.0)   # the graph shows the reader before DDS has matched it
        t0 = time.monotonic()
        chunk = 100
        for k in range(0, payloads.shape[0], chunk):
            for row in payloads[k:k + chunk]:
                pub.publish(row.tobytes())
            time.sleep(max(0.0, t0 + (k + chunk) / per_second - time.monotonic()))
        time.sleep(0.5)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def run(args) -> int:
    """Simulate, publish, characterise, and print the fit beside the truth."""
    import subprocess
    import tempfile

    import rclpy
    from rclpy.parameter import Parameter

    from imu_allan.core.noise.params import load_params
    from imu_allan.core.noise.simulate import simulate_imu
    from imu_allan.core.noise.units import format_quoted, sensor_of
    from imu_allan.io.bag_writer import serialize_imu
    from imu_allan.ros.node import ImuAllanNode
    from imu_allan.ros.spin import create_executor

    if not (math.isfinite(args.speed) and args.speed > 0):
        raise InputError(f'--speed must be a positive number of messages/s, got {args.speed:g}')
    prepare_out_dir(args.out)
    params = _params_file(args.params)
    spec = load_params(params)
    t_start = t0 = time.monotonic()
    t_s, samples = simulate_imu(spec, args.rate, args.duration, seed=args.seed)
    stamps = START_NS + np.round(t_s * 1e9).astype(np.int64)
    payloads = serialize_imu(stamps, samples, frame_id='imu_link')
    n = payloads.shape[0]
    t_b = [a.T_B for a in spec.axes.values() if a.T_B] or [0.0]
    print(f'demo: simulated {spec.name}: {n:,} messages ({args.duration / 3600:.2f} h at '
          f'{args.rate:g} Hz) in {time.monotonic() - t0:.1f} s.\n'
          f'demo: why {args.duration / 3600:.2f} h at {args.rate:g} Hz: T_B of this model is '
          f'{min(t_b):.0f}-{max(t_b):.0f} s and the random walk K shows only beyond ~1000 s, '
          f'so the record must span hours; N needs no high rate, and {args.rate:g} Hz keeps '
          'the message count '
          f'low enough to send through real topics at {args.speed:,.0f} msg/s '
          f'({args.speed / args.rate:.0f}x real time).', file=sys.stderr)

    rclpy.init(args=[])
    with tempfile.TemporaryDirectory(prefix='imu_allan_demo_') as tmp:
        npy = Path(tmp) / 'payloads.npy'
        np.save(npy, payloads)
        node = ImuAllanNode(parameter_overrides=[
            Parameter('min_duration_s', value=float(args.duration) * 0.99),
            Parameter('output_dir', value=str(args.out.resolve())),
            Parameter('publish_period_s', value=86400.0),
            Parameter('progress_period_s', value=10.0),
            Parameter('checkpoint_period_s', value=0.0),
        ])
        executor = create_executor('events')
        executor.add_node(node)
        player = subprocess.Popen(
            [sys.executable, '-c', 'import sys; from imu_allan.cli.demo import publish_main; '
             'sys.exit(publish_main())', str(npy), str(args.speed)])
        try:
            t_first: float | None = None
            last_n, last_change = 0, time.monotonic()
            while node.n_received < n:
                executor.spin_once(timeout_sec=0.1)
                if node.n_received and t_first is None:
                    t_first = time.monotonic()
                if node.n_received != last_n:
                    last_n, last_change = node.n_received, time.monotonic()
                elif player.poll() is not None and time.monotonic() - last_change > 2.0:
                    break          # the player is done and nothing more arrives
            seconds = time.monotonic() - (t_first or t_start)
            print(f'demo: {node.n_received:,} of {n:,} Imu messages received over rclpy '
                  f'topics in {seconds:.1f} s ({node.n_received / seconds:,.0f} msg/s, '
                  f'{args.duration / seconds:.0f}x real time)', file=sys.stderr)
            files = node.save()
            result = node.last_result
        finally:
            player.wait(30)
            node.destroy_node()
            rclpy.try_shutdown()
    print(f'demo: total {time.monotonic() - t_start:.0f} s', file=sys.stderr)

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
