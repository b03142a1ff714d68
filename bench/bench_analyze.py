"""
End-to-end benchmark of ``imu-allan analyze`` on a long bag, MCAP and sqlite3 storage.

Simulates a ``--hours`` long (default 3 h) ``--rate`` Hz (default 400 Hz) six-axis
record from ``config/xsens_mti7.yaml`` (4.32 million sensor_msgs/Imu messages by
default) and writes it as a rosbag2 directory in MCAP storage and in sqlite3 storage.
The bags are cached in ``--cache`` (default ``/tmp/imu_allan_bench_bags``), so reruns
skip the writing.  For each storage it prints, measured in the same run:

* ``imu-allan analyze BAG --format json`` run as a subprocess ``--repeat`` times
  (default 3): the best wall seconds end to end (start-up, reading, input checks,
  Allan accumulation, fit, every output file and the plots) with the spread of the
  runs, messages per second, and the CPU seconds of all the command's processes (its
  workers included: this process adopts them; steadier on a shared machine, and their
  share per core is the least wall time the work can take; the load average is
  printed too);
* the same with ``--jobs 1`` (one process, the accumulator inline), whose numbers must
  equal the first run's exactly;
* the split of that work, measured in a fresh process, each phase on one thread:
  reading only (``open_imu(...).blocks()``), the input checks, the streaming Allan
  accumulation, the curve plus fit of the six axes (``analysis.analyze``), and the
  output files with plots;
* the plain rosbags loop (``rosbags.rosbag2.Reader`` plus ``deserialize_cdr`` per
  message) over the first ``--subset`` messages, as messages per second.
* the wall time of each stage of the command as it runs (fresh process, its own
  workers): reading with the checks and accumulation, the search, the plan and the
  files; the last three cost the same for any record length.

The guards, ratios against the storage libraries' own reading measured in the same run,
are in ``bench_guards.py``.

Usage: ``.venv/bin/python bench/bench_analyze.py [--hours H] [--rate HZ] [--subset N]
[--cache DIR] [--storage mcap sqlite3] [--repeat R]``
"""

import argparse
import contextlib
import ctypes
import io
import json
import os
from pathlib import Path
import resource
import shutil
import subprocess
import sys
import tempfile
import time

from bytecode import byte_compile
import numpy as np
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores

from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.io.bag_reader import open_imu
from imu_allan.io.bag_writer import write_imu_bag
from imu_allan.io.report import write_outputs
from imu_allan.pipeline.analysis import analyze
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session

REPO = Path(__file__).resolve().parents[1]
_PR_SET_CHILD_SUBREAPER = 36
T0_NS = 1_700_000_000_000_000_000


def _bag(cache: Path, storage: str, hours: float, rate: float) -> Path:
    """Return the cached bag of this storage and size, writing it first when missing."""
    bag = cache / f'imu_{storage}_{hours:g}h_{rate:g}hz'
    if (bag / 'metadata.yaml').exists():
        return bag
    cache.mkdir(parents=True, exist_ok=True)
    spec = load_params(REPO / 'config' / 'xsens_mti7.yaml')
    t0 = time.perf_counter()
    _, samples = simulate_imu(spec, rate, hours * 3600.0, seed=0)
    stamps_ns = T0_NS + np.round(np.arange(samples.shape[0]) * (1e9 / rate)).astype(np.int64)
    tmp = cache / f'.{bag.name}.{os.getpid()}'
    shutil.rmtree(tmp, ignore_errors=True)
    write_imu_bag(tmp, stamps_ns, samples, storage=storage)
    # The file inside keeps the temporary name; metadata.yaml names it, so it is found.
    os.replace(tmp, bag)
    print(f'  wrote {bag} ({samples.shape[0]:,} messages) in {time.perf_counter() - t0:.1f} s',
          file=sys.stderr)
    return bag


def _warm(bag: Path) -> None:
    """
    Read the bag's files once: every timed run then reads from the page cache.

    This machine's kernel reclaims cold pages (DAMON): a bag not read for a while comes
    from disk again, and its first run was 3 s slower than the next.
    """
    for f in sorted(bag.iterdir()):
        with open(f, 'rb') as fh:
            while fh.read(1 << 24):
                pass


def _adopt_orphans() -> bool:
    """
    Make this process the reaper of its descendants' orphans (Linux prctl).

    The worker processes of ``analyze`` fork from a server that the command does not
    wait for; adopted here and waited for, their CPU time counts in this process's
    children usage.  Returns False where the call is not available.
    """
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _reap_orphans() -> None:
    """Wait for every process the command left behind (adopted by this one)."""
    while True:
        try:
            os.waitpid(-1, 0)
        except ChildProcessError:
            return


def _end_to_end(bag: Path, out: Path, *extra: str) -> tuple:
    """Run the CLI once; return (wall seconds, CPU seconds of all its processes, JSON)."""
    cmd = [sys.executable, '-m', 'imu_allan', 'analyze', str(bag), '--out', str(out),
           '--format', 'json', *extra]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    _reap_orphans()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        raise SystemExit(f'analyze failed ({proc.returncode}): {proc.stderr.strip()}')
    return wall, cpu, json.loads(proc.stdout)


def _split(bag: Path, out: Path) -> dict:
    """Time the stages in this process: read only, read + Session, fit, outputs."""
    times = {}
    t0, c0 = time.perf_counter(), time.process_time()
    with open_imu(bag) as source:
        n = sum(b.stamp_ns.size for b in source.blocks())
    times['read'] = time.perf_counter() - t0
    times['read_cpu'] = time.process_time() - c0
    session = Session(SessionConfig())
    t0 = time.perf_counter()
    with open_imu(bag) as source:
        for block in source.blocks():
            session.add(block.stamp_ns, block.samples)
    session.flush()
    times['session'] = time.perf_counter() - t0 - times['read']
    # The accumulator alone on the same samples: the session's rest is input hygiene.
    with open_imu(bag) as source:
        blocks = [b.samples for b in source.blocks()]
    acc = AllanAccumulator(6, session.rate_hz)
    t0 = time.perf_counter()
    for samples in blocks:
        acc.add(samples)
    acc.curve()
    times['accumulate'] = time.perf_counter() - t0
    del blocks
    t0 = time.perf_counter()
    result = analyze(session, source=str(bag))
    times['allan+fit'] = time.perf_counter() - t0
    t0 = time.perf_counter()
    session.curve()
    times['allan curve only'] = time.perf_counter() - t0
    t0 = time.perf_counter()
    write_outputs(result, out, plot=True)
    times['outputs+plots'] = time.perf_counter() - t0
    times['messages'] = n
    return times


def _stages(bag: Path, out: Path) -> dict:
    """
    Wall seconds of each stage of ``imu-allan analyze BAG`` as the command runs it.

    The stages are timed around the functions that run them (reading with the checks
    and accumulation, the axes' searches, the plan, the files), in this process, with
    the command's own workers; the first three do the same work for any record length
    but the first.
    """
    import imu_allan.io.inputs as inputs
    import imu_allan.io.report as report
    import imu_allan.pipeline.analysis as analysis
    from imu_allan.cli import main as cli_main

    wall: dict = {}

    def timed(module, name: str, stage: str) -> None:
        inner = getattr(module, name)

        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                wall[stage] = wall.get(stage, 0.0) + time.perf_counter() - t0
        setattr(module, name, wrapper)

    timed(inputs, 'stream_input', 'stream')
    timed(analysis, '_map_axes', 'search')
    timed(analysis, '_plans', 'plan')
    timed(report, 'write_outputs', 'files')
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):    # this process prints the times
        assert cli_main(['analyze', str(bag), '--out', str(out), '--format', 'json']) == 0
    wall['total'] = time.perf_counter() - t0
    return wall


def _rosbags_loop(bag: Path, subset: int) -> tuple:
    """Decode the first ``subset`` messages one by one with rosbags; return (n, seconds)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    values = []
    t0 = time.perf_counter()
    with Reader(bag) as reader:
        for conn, _, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            av, la = msg.angular_velocity, msg.linear_acceleration
            values.append((msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                           av.x, av.y, av.z, la.x, la.y, la.z))
            if len(values) >= subset:
                break
    return len(values), time.perf_counter() - t0


def main() -> None:
    """Write (or reuse) the bags, time everything, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--hours', type=float, default=3.0)
    parser.add_argument('--rate', type=float, default=400.0, help='message rate [Hz]')
    parser.add_argument('--subset', type=int, default=100_000,
                        help='messages decoded by the rosbags baseline')
    parser.add_argument('--cache', type=Path, default=Path('/tmp/imu_allan_bench_bags'))
    parser.add_argument('--storage', nargs='+', default=['mcap', 'sqlite3'],
                        choices=['mcap', 'sqlite3'])
    parser.add_argument('--repeat', type=int, default=3,
                        help='end-to-end runs per storage; the best one is reported')
    parser.add_argument('--split-only', type=Path, default=None, metavar='BAG',
                        help=argparse.SUPPRESS)
    parser.add_argument('--stages-only', type=Path, default=None, metavar='BAG',
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    for bag, measure in ((args.split_only, _split), (args.stages_only, _stages)):
        if bag is not None:
            # Run in a fresh process, so that no cache of an earlier run helps the fit.
            with tempfile.TemporaryDirectory(prefix='imu_allan_bench_out_') as tmp:
                print(json.dumps(measure(bag, Path(tmp))))
            return
    byte_compile()
    n = int(round(args.hours * 3600 * args.rate))
    print(f'{n:,} sensor_msgs/Imu messages ({args.hours:g} h at {args.rate:g} Hz), '
          f'{os.cpu_count()} cores')
    cpu_scope = (' in all its processes' if _adopt_orphans()
                 else ' in the command (its worker processes not counted)')
    for storage in args.storage:
        bag = _bag(args.cache, storage, args.hours, args.rate)
        _warm(bag)
        with tempfile.TemporaryDirectory(prefix='imu_allan_bench_out_') as tmp:
            runs = [_end_to_end(bag, Path(tmp) / f'cli{k}') for k in range(max(1, args.repeat))]
            walls = sorted(r[0] for r in runs)
            wall, cpu, doc = min(runs, key=lambda r: r[0])
            assert doc['n_samples'] == n, (doc['n_samples'], n)
            assert all(r[2]['axes'] == doc['axes'] for r in runs), 'the runs differ'
            wall_1, _, doc_1 = _end_to_end(bag, Path(tmp) / 'one', '--jobs', '1')
        same = all(doc[k] == doc_1[k] for k in ('axes', 'hygiene', 'kalman', 'imu_covariance'))
        proc = subprocess.run([sys.executable, __file__, '--split-only', str(bag)],
                              capture_output=True, text=True, check=True)
        split = json.loads(proc.stdout)
        proc = subprocess.run([sys.executable, __file__, '--stages-only', str(bag)],
                              capture_output=True, text=True, check=True)
        stages = json.loads(proc.stdout)
        base_n, base_s = _rosbags_loop(bag, min(args.subset, n))
        read_rate = split['messages'] / split['read']
        rate = n / wall
        base_rate = base_n / base_s
        print(f'[{storage}] analyze end to end: {wall:6.2f} s wall (best of {len(walls)}: '
              f'{", ".join(f"{w:.2f}" for w in walls)} s), {rate / 1e6:.2f} M msg/s, '
              f'{rate / base_rate:.1f}x the rosbags loop; '
              f'{cpu:.2f} CPU s{cpu_scope} (at least {cpu / (os.cpu_count() or 1):.2f} s '
              f'of wall on these cores); load average {os.getloadavg()[0]:.1f}')
        print(f'[{storage}]   --jobs 1 (one process, accumulator inline): {wall_1:.2f} s; '
              f'numbers {"IDENTICAL" if same else "DIFFERENT"} to the two-core run')
        print(f'[{storage}]   split: read {split["read"]:.2f} s ({read_rate / 1e6:.2f} M msg/s; '
              f'{split["read_cpu"]:.2f} CPU s = '
              f'{split["messages"] / split["read_cpu"] / 1e6:.2f} M msg/s per CPU second), '
              f'session checks + Allan accumulation {split["session"]:.2f} s, '
              f'curve + fit {split["allan+fit"]:.2f} s '
              f'(curve alone {split["allan curve only"]:.2f} s), '
              f'outputs + plots {split["outputs+plots"]:.2f} s')
        print(f'[{storage}]   rosbags one-at-a-time decode: {base_n:,} messages in {base_s:.2f} s '
              f'= {base_n / base_s / 1e6:.3f} M msg/s; imu_allan reading is '
              f'{read_rate / (base_n / base_s):.0f}x faster, analyze end to end '
              f'{n / wall / (base_n / base_s):.1f}x')
        phases = {'read': split['read'],
                  'hygiene': split['session'] - split['accumulate'],
                  'accumulate': split['accumulate'],
                  'curve + fit': split['allan+fit'],
                  'report': split['outputs+plots']}
        total = sum(phases.values())
        print(f'[{storage}]   phases, one thread each (sum {total:.2f} s; end to end overlaps '
              'reading with the rest): ' + ', '.join(
                  f'{k} {v:.2f} s ({100 * v / total:.0f} %)' for k, v in phases.items()))
        fixed = stages['search'] + stages['plan'] + stages['files']
        print(f'[{storage}]   wall by stage, as the command runs: reading with the checks and '
              f'accumulation {stages["stream"]:.2f} s ({n / stages["stream"] / 1e6:.2f} M msg/s), '
              f'search {stages["search"]:.2f} s, plan {stages["plan"]:.2f} s, files '
              f'{stages["files"]:.2f} s (these three, {fixed:.2f} s, do not grow with the '
              f'record), {stages["total"]:.2f} s in all')
        sys.stdout.flush()


if __name__ == '__main__':
    main()
