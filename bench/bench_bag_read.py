"""
Benchmark of imu_allan.io.bag_reader against the plain rosbags decode loop.

Writes a ``--hours`` long (default 3 h) ``--rate`` Hz (default 400 Hz) sensor_msgs/Imu
recording, 4.32 million messages by default, as a rosbag2 directory in MCAP storage
(zstd chunks) and in sqlite3 storage, into a temporary directory that is deleted
afterwards.  For each it prints, measured in the same run:

* imu_allan: ``open_imu(...).blocks()`` over the whole bag (messages/s);
* rosbags: ``rosbags.rosbag2.Reader`` plus ``Typestore.deserialize_cdr`` per message,
  collecting header.stamp and the six values, over the first ``--subset`` messages
  (default 200,000), reported as messages/s;

and the speed-up ratio.  Wall and CPU seconds are both shown: the CPU figure is the
steadier one on a shared machine.  The write times of imu_allan.io.bag_writer are shown too.

Usage: ``.venv/bin/python bench/bench_bag_read.py [--hours H] [--rate HZ] [--subset N]``
"""

import argparse
from pathlib import Path
import tempfile
import time

import numpy as np
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores

from imu_allan.io.bag_reader import open_imu
from imu_allan.io.bag_writer import write_imu_bag

T0_NS = 1_700_000_000_000_000_000


def _timed(fn):
    """Run fn; return (its result, wall seconds, CPU seconds of this process)."""
    w0, c0 = time.perf_counter(), time.process_time()
    result = fn()
    return result, time.perf_counter() - w0, time.process_time() - c0


def _read_ours(bag: Path):
    """Read the whole bag; return (messages, first samples row, last stamp [ns])."""
    n = 0
    first = last = None
    with open_imu(bag) as source:
        for block in source.blocks():
            if first is None:
                first = block.samples[0].copy()
            n += block.stamp_ns.size
            last = int(block.stamp_ns[-1])
    return n, first, last


def _read_rosbags(bag: Path, subset: int):
    """Decode the first ``subset`` messages one by one with rosbags; return the count."""
    store = get_typestore(Stores.ROS2_JAZZY)
    stamps, values = [], []
    with Reader(bag) as reader:
        for conn, _, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            av, la = msg.angular_velocity, msg.linear_acceleration
            values.append((av.x, av.y, av.z, la.x, la.y, la.z))
            if len(stamps) >= subset:
                break
    return len(stamps)


def main() -> None:
    """Write the bags, time both readers, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--hours', type=float, default=3.0)
    parser.add_argument('--rate', type=float, default=400.0, help='message rate [Hz]')
    parser.add_argument('--subset', type=int, default=200_000,
                        help='messages decoded by the rosbags baseline')
    args = parser.parse_args()
    n = int(round(args.hours * 3600 * args.rate))
    rng = np.random.default_rng(0)
    stamps_ns = T0_NS + np.round(np.arange(n) * 1e9 / args.rate).astype(np.int64)
    samples = rng.normal(size=(n, 6)) * 1e-3
    samples[:, 5] += 9.80665
    print(f'{n} sensor_msgs/Imu messages ({args.hours:g} h at {args.rate:g} Hz)')
    print(f'{"storage":8s} {"reader":10s} {"messages":>9s} {"wall s":>7s} {"CPU s":>6s} '
          f'{"msg/s (wall)":>13s} {"msg/s (CPU)":>12s}')
    with tempfile.TemporaryDirectory(prefix='imu_allan_bench_') as tmp:
        for storage in ('mcap', 'sqlite3'):
            bag = Path(tmp) / f'bag_{storage}'
            _, write_wall, _ = _timed(lambda: write_imu_bag(bag, stamps_ns, samples,
                                                            storage=storage))
            size_mb = sum(f.stat().st_size for f in bag.iterdir()) / 1e6
            (count, first, last), wall, cpu = _timed(lambda: _read_ours(bag))
            assert count == n and np.array_equal(first, samples[0]) and last == stamps_ns[-1]
            subset = min(args.subset, n)
            base, base_wall, base_cpu = _timed(lambda: _read_rosbags(bag, subset))
            rows = [('imu_allan', count, wall, cpu), ('rosbags', base, base_wall, base_cpu)]
            for name, k, w, c in rows:
                print(f'{storage:8s} {name:10s} {k:9d} {w:7.2f} {c:6.2f} {k / w:13,.0f} '
                      f'{k / c:12,.0f}')
            print(f'{storage:8s} speed-up {count / wall / (base / base_wall):.1f}x wall, '
                  f'{count / cpu / (base / base_cpu):.1f}x CPU; write {write_wall:.1f} s, '
                  f'{size_mb:.0f} MB')


if __name__ == '__main__':
    main()
