"""
``imu-allan simulate``: write a simulated six-axis IMU record from a params YAML.

Output by file name: ``.csv`` or ``.csv.gz`` -> CSV with header
``t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z`` (imu_allan.io.csv_io);
``.mcap``, ``.db3``, ``.bag`` (ROS 1) or a directory (a name without suffix) -> bag of
sensor_msgs/Imu (imu_allan.io.bag_writer), whose covariance fields carry the white-noise
variance N^2 * rate of each axis.  A one-line summary goes to stderr.  Bag stamps
start at the current time (whole seconds) unless ``--start`` is given, so that
``header.stamp`` looks like a real recording's.

Also registers ``imu-allan csv-to-bag CSV BAG``: legacy CSV logs (the CSV contract of
docs/contracts.md) to the same bags, through :func:`imu_allan.io.bag_writer.csv_to_bag`.
"""

import argparse
from contextlib import contextmanager
import math
from pathlib import Path
import sys
import time
from typing import Iterator

import numpy as np

from imu_allan import AXES
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.errors import InputError

BAG_SUFFIXES = ('.mcap', '.db3', '.bag')
#: Most samples one simulation makes: six float64 axes and the times, 56 bytes each
#: (5.6 GB at the limit), before writing.
MAX_SAMPLES = 1e8


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
    p.add_argument('--start', type=float, default=None, metavar='S',
                   help='time of the first sample [s]; default 0 for CSV and, for bags, '
                        'the current time in whole seconds (a realistic header.stamp)')
    p.add_argument('--topic', default='/imu/data', help='bag topic (default /imu/data)')
    p.add_argument('--frame-id', default='imu_link', help='bag frame_id (default imu_link)')
    p.set_defaults(run=run)
    _add_csv_to_bag_parser(subparsers)
    return p


def _add_csv_to_bag_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``csv-to-bag`` (legacy CSV logs to rosbag2 or ROS 1 bags)."""
    p = subparsers.add_parser(
        'csv-to-bag', help='convert a CSV IMU log into a bag of sensor_msgs/Imu',
        description='Convert a CSV log (t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z; t in '
                    's, rad/s, m/s^2; optional .gz) into a bag: .mcap, .db3, .bag (ROS 1) '
                    'or a rosbag2 directory (MCAP, or sqlite3 with --storage sqlite3).')
    p.add_argument('csv', metavar='CSV', help='input CSV file')
    p.add_argument('out', metavar='BAG', help='output bag file or directory (must not exist)')
    p.add_argument('--topic', default='/imu/data', help='bag topic (default /imu/data)')
    p.add_argument('--frame-id', default='imu_link', help='frame_id (default imu_link)')
    p.add_argument('--storage', choices=('mcap', 'sqlite3'), default=None,
                   help='storage of a bag directory (default mcap)')
    p.add_argument('--columns', default=None, metavar='A,B,C,D,E,F',
                   help='the six CSV columns in gyro x, y, z, accel x, y, z order '
                        '(default: the contract names)')
    p.add_argument('--start', type=float, default=None, metavar='S',
                   help='added to t [s]: logs with relative time start at this epoch time '
                        '(default: 0 for epoch times, else the current time in whole '
                        'seconds, as header.stamp is never 0 in a real recording)')
    p.set_defaults(run=run_csv_to_bag)
    return p


def run_csv_to_bag(args) -> int:
    """Convert the CSV; a one-line summary goes to stderr."""
    from imu_allan.io.bag_writer import csv_to_bag

    if args.start is not None and not math.isfinite(args.start):
        raise InputError(f'--start must be finite, got {args.start:g}')
    columns = [c.strip() for c in args.columns.split(',')] if args.columns else None
    if columns is not None and len(columns) != len(AXES):
        raise InputError(f'--columns needs {len(AXES)} names, got {len(columns)}')
    try:
        n = csv_to_bag(args.csv, args.out, topic=args.topic, frame_id=args.frame_id,
                       storage=args.storage, columns=columns,
                       start_ns=None if args.start is None else int(round(args.start * 1e9)))
    except OSError as exc:    # a parent that is a file, a read-only place, a full disk
        raise InputError(f'{args.out}: cannot write ({exc.strerror or exc})') from None
    print(f'imu-allan: wrote {n} sensor_msgs/Imu messages on {args.topic} -> {args.out}',
          file=sys.stderr)
    return 0


@contextmanager
def _writing(out: Path) -> Iterator[None]:
    """Turn an OSError while writing ``out`` into a one-line InputError."""
    try:
        yield
    except OSError as exc:
        raise InputError(f'{out}: cannot write ({exc.strerror or exc})') from None


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
    out = Path(args.out)
    kind = _output_kind(out)
    if args.start is None:
        args.start = 0.0 if kind == 'csv' else float(int(time.time()))
    if not math.isfinite(args.start):
        raise InputError(f'--start must be finite, got {args.start:g}')
    if args.seed is not None and args.seed < 0:
        raise InputError(f'--seed must be >= 0, got {args.seed}')
    n = args.rate * args.duration
    if n > MAX_SAMPLES:
        raise InputError(f'--rate {args.rate:g} Hz for --duration {args.duration:g} s is '
                         f'{n:.3g} samples; at most {MAX_SAMPLES:.0e} fit in memory')
    spec = load_params(args.params)
    seed = args.seed if args.seed is not None else int(np.random.default_rng().integers(2**63))
    try:
        t_s, samples = simulate_imu(spec, args.rate, args.duration, seed=seed)
    except MemoryError:
        raise InputError(f'not enough memory for {n:.3g} samples') from None
    if t_s.size < 2:
        raise InputError(f'--duration {args.duration:g} s at {args.rate:g} Hz gives '
                         f'{t_s.size} sample(s); need at least 2')
    if kind == 'csv':
        try:
            from imu_allan.io.csv_io import write_csv
        except ImportError:
            raise InputError('CSV output needs imu_allan.io.csv_io') from None
        with _writing(out):
            write_csv(out, t_s + args.start, samples, AXES)
    else:
        try:
            from imu_allan.io.bag_writer import write_imu_bag
        except ImportError:
            raise InputError('bag output needs imu_allan.io.bag_writer') from None
        # Integer nanoseconds from the sample index, so the stamps carry no float drift.
        # (int64 arithmetic: float64 holds an epoch in ns only to 256 ns.)
        stamps_ns = (int(round(args.start * 1e9))
                     + np.round(np.arange(t_s.size) * (1e9 / args.rate)).astype(np.int64))
        # Per-sample white-noise variance N^2 * rate, what robot_localization reads.
        variances = [spec.axes[a].N ** 2 * args.rate for a in AXES]
        with _writing(out):
            write_imu_bag(out, stamps_ns, samples, topic=args.topic, frame_id=args.frame_id,
                          covariances=(variances[:3], variances[3:]))
    label = spec.name or Path(args.params).name
    print(f'imu-allan: simulated {t_s.size} samples x {len(AXES)} axes at {args.rate:g} Hz '
          f'({t_s.size / args.rate:g} s) of {label!r}, seed {seed} -> {out}', file=sys.stderr)
    return 0
