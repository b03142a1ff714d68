"""
``imu-allan simulate``: write a simulated six-axis IMU record from a params YAML.

Output by file name: ``.csv`` or ``.csv.gz`` -> CSV with header
``t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z`` (imu_allan.csv_io);
``.mcap``, ``.db3``, ``.bag`` (ROS 1) or a directory (a name without suffix) -> bag of
sensor_msgs/Imu (imu_allan.bag_writer), whose covariance fields carry the white-noise
variance N^2 * rate of each axis.  A one-line summary goes to stderr.
"""

import argparse
import math
from pathlib import Path
import sys

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError
from imu_allan.noise_params import load_params
from imu_allan.simulate import simulate_imu

BAG_SUFFIXES = ('.mcap', '.db3', '.bag')


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the ``simulate`` sub-command."""
    p = subparsers.add_parser(
        'simulate', help='simulate an IMU record from a noise-parameter YAML',
        description='Simulate a stationary six-axis IMU (rad/s, m/s^2) from a noise '
                    'model and write it as CSV (.csv, .csv.gz) or a bag '
                    '(.mcap, .db3, .bag or a directory).')
    p.add_argument('--params', required=True, metavar='YAML',
                   help='noise parameters (see config/xsens_mti7.yaml)')
    p.add_argument('--rate', required=True, type=float, metavar='HZ', help='sample rate [Hz]')
    p.add_argument('--duration', required=True, type=float, metavar='S',
                   help='record length [s]')
    p.add_argument('--out', required=True, metavar='FILE', help='output file or bag directory')
    p.add_argument('--seed', type=int, default=None, metavar='N',
                   help='random seed (default: fresh entropy, printed in the summary)')
    p.add_argument('--start', type=float, default=0.0, metavar='S',
                   help='time of the first sample [s] (default 0)')
    p.add_argument('--topic', default='/imu/data', help='bag topic (default /imu/data)')
    p.add_argument('--frame-id', default='imu_link', help='bag frame_id (default imu_link)')
    p.set_defaults(run=run)
    return p


def _output_kind(path: Path) -> str:
    """Return 'csv' or 'bag' for an output path, or raise InputError."""
    name = path.name.lower()
    if name.endswith('.csv') or name.endswith('.csv.gz'):
        return 'csv'
    if path.suffix.lower() in BAG_SUFFIXES or path.is_dir() or not path.suffix:
        return 'bag'
    raise InputError(f'cannot tell the output format of {path}: use .csv, .csv.gz, .mcap, '
                     f'.db3, .bag or a directory')


def run(args) -> int:
    """Simulate and write the record; return the exit code."""
    for name, value in (('--rate', args.rate), ('--duration', args.duration)):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f'{name} must be a positive number, got {value:g}')
    if not math.isfinite(args.start):
        raise InputError(f'--start must be finite, got {args.start:g}')
    out = Path(args.out)
    kind = _output_kind(out)
    spec = load_params(args.params)
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2**63)
    t_s, samples = simulate_imu(spec, args.rate, args.duration, seed=seed)
    if t_s.size < 2:
        raise InputError(f'--duration {args.duration:g} s at {args.rate:g} Hz gives '
                         f'{t_s.size} sample(s); need at least 2')
    if kind == 'csv':
        try:
            from imu_allan.csv_io import write_csv
        except ImportError:
            raise InputError('CSV output needs imu_allan.csv_io') from None
        write_csv(out, t_s + args.start, samples, AXES)
    else:
        try:
            from imu_allan.bag_writer import write_imu_bag
        except ImportError:
            raise InputError('bag output needs imu_allan.bag_writer') from None
        # Integer nanoseconds from the sample index, so the stamps carry no float drift.
        stamps_ns = (np.round(args.start * 1e9)
                     + np.round(np.arange(t_s.size) * (1e9 / args.rate))).astype(np.int64)
        # Per-sample white-noise variance N^2 * rate, what robot_localization reads.
        variances = [spec.axes[a].N ** 2 * args.rate for a in AXES]
        write_imu_bag(out, stamps_ns, samples, topic=args.topic, frame_id=args.frame_id,
                      covariances=(variances[:3], variances[3:]))
    label = spec.name or Path(args.params).name
    print(f'imu-allan: simulated {t_s.size} samples x {len(AXES)} axes at {args.rate:g} Hz '
          f'({t_s.size / args.rate:g} s) of {label!r}, seed {seed} -> {out}', file=sys.stderr)
    return 0
