"""
The speed guards: each command against a baseline measured in the same run.

Ratios measured in one run hold on a busy machine where wall times do not (the
baselines of issue 28, 1 M messages/s and 15x a rosbags loop, moved by 2x between runs).
Every timing is the median of ``--repeat`` runs (default 3), the command and its
baseline alternating, each as a fresh process (start-up, imports and every output file
included):

* ``imu-allan analyze BAG --format json`` on the bench bag of ``bench_analyze.py``
  (``--hours``, default 3 h, at ``--rate``, default 400 Hz; written once into
  ``--cache``), MCAP and sqlite3 storage, against

  - the ``mcap`` library's bare ``iter_messages`` over the same file (no decoding):
    guard, analyze at least 5x faster;
  - sqlite3's fetch of every payload in time order (``SELECT data FROM messages
    ORDER BY timestamp``, rows only): guard, analyze no slower (at least 1.0x);

* ``imu-allan adev FILE --rate 100 --taus dense`` of one CSV column (``--samples``,
  default 4 M values) against ``np.loadtxt`` plus ``allantools.oadev`` at the same
  taus (``bench_adev.py``'s baseline): guard, at least 2x;
* ``imu-allan diagnose`` of one ADIS16405 run (``--adis``, a .csv.gz; skipped when
  absent): guard, under 60 s.

Usage: ``.venv/bin/python bench/bench_guards.py [--only analyze adev diagnose]
[--storage mcap sqlite3] [--hours H] [--rate HZ] [--samples N] [--repeat R]
[--adis FILE]``.  Prints one line per guard: both medians, the ratio, PASS or FAIL;
exits 1 when a guard fails.
"""

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time

from bench_adev import BASELINE
from bench_analyze import _bag, _warm
from bytecode import byte_compile
import numpy as np

REPO = Path(__file__).resolve().parents[1]
ADIS_RUN = REPO.parent / 'shared' / 'realdata' / 'adis16405' / 'adis16405_run1.csv.gz'

MCAP_ITER = """
import sys
from mcap.reader import make_reader
n = 0
with open(sys.argv[1], 'rb') as f:
    for _ in make_reader(f).iter_messages():
        n += 1
print(n)
"""

SQLITE_FETCH = """
import sqlite3, sys
conn = sqlite3.connect(f'file:{sys.argv[1]}?mode=ro', uri=True)
n = 0
for (data,) in conn.execute('SELECT data FROM messages ORDER BY timestamp'):
    n += 1
print(n)
"""


def _wall(cmd: list) -> tuple:
    """Run a command once; return (wall seconds, stdout)."""
    t0 = time.perf_counter()
    run = subprocess.run(cmd, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if run.returncode != 0:
        raise SystemExit(f'{" ".join(cmd[:4])} ... failed ({run.returncode}): '
                         f'{run.stderr.strip()[-400:]}')
    return wall, run.stdout


def _medians(commands: dict, repeat: int) -> tuple:
    """Alternate the commands ``repeat`` times; return (median wall per name, last stdout)."""
    walls: dict = {k: [] for k in commands}
    outs: dict = {}
    for _ in range(repeat):
        for name, cmd in commands.items():
            wall, outs[name] = _wall(cmd)
            walls[name].append(wall)
    return {k: statistics.median(v) for k, v in walls.items()}, outs


def _verdict(ok: bool) -> str:
    return 'PASS' if ok else 'FAIL'


def _analyze(args, failed: list) -> None:
    """Guards of ``imu-allan analyze`` against the storage libraries' bare reading."""
    n = int(round(args.hours * 3600 * args.rate))
    for storage in args.storage:
        bag = _bag(args.cache, storage, args.hours, args.rate)
        (data_file,) = [f for f in bag.iterdir() if f.suffix in ('.mcap', '.db3')]
        _warm(bag)
        base = MCAP_ITER if storage == 'mcap' else SQLITE_FETCH
        with tempfile.TemporaryDirectory(prefix='imu_allan_guard_') as tmp:
            med, outs = _medians({
                'ours': [sys.executable, '-m', 'imu_allan', 'analyze', str(bag), '--out',
                         str(Path(tmp) / 'out'), '--format', 'json'],
                'base': [sys.executable, '-c', base, str(data_file)]}, args.repeat)
        assert json.loads(outs['ours'])['n_samples'] == n
        ratio = med['base'] / med['ours']
        need = 5.0 if storage == 'mcap' else 1.0
        what = ('mcap iter_messages (no decoding)' if storage == 'mcap'
                else 'sqlite3 ordered fetch of the payloads')
        ok = ratio >= need
        failed += [] if ok else [f'analyze {storage}']
        print(f'[{storage}] analyze {med["ours"]:.2f} s ({n / med["ours"] / 1e6:.2f} M msg/s) '
              f'against {what} {med["base"]:.2f} s: {ratio:.2f}x (guard {need:g}x) '
              f'{_verdict(ok)}; load average {os.getloadavg()[0]:.1f}', flush=True)


def _adev(args, failed: list) -> None:
    """Guard of ``imu-allan adev`` against numpy loading plus allantools."""
    rng = np.random.default_rng(1)
    y = rng.normal(size=args.samples) * 1e-3 + np.cumsum(rng.normal(size=args.samples)) * 1e-7
    with tempfile.TemporaryDirectory(prefix='imu_allan_guard_') as tmp:
        path = Path(tmp) / 'column.csv'
        np.savetxt(path, y, fmt='%.9e')
        ours = [sys.executable, '-m', 'imu_allan', 'adev', str(path), '--rate', '100',
                '--taus', 'dense', '--format', 'json']
        taus = json.loads(_wall(ours)[1])['tau_s']
        med, _ = _medians({'ours': ours,
                           'base': [sys.executable, '-c', BASELINE, str(path), json.dumps(taus)]},
                          args.repeat)
    ratio = med['base'] / med['ours']
    ok = ratio >= 2.0
    failed += [] if ok else ['adev']
    print(f'[adev] {args.samples:,} values, {len(taus)} dense taus: {med["ours"]:.2f} s against '
          f'np.loadtxt + allantools.oadev {med["base"]:.2f} s: {ratio:.2f}x (guard 2x) '
          f'{_verdict(ok)}; load average {os.getloadavg()[0]:.1f}', flush=True)


def _diagnose(args, failed: list) -> None:
    """Guard of ``imu-allan diagnose`` on one ADIS16405 run: under a minute."""
    if not args.adis.is_file():
        print(f'[diagnose] skipped: {args.adis} not found (--adis)')
        return
    walls = []
    with tempfile.TemporaryDirectory(prefix='imu_allan_guard_') as tmp:
        for k in range(args.repeat):
            walls.append(_wall([sys.executable, '-m', 'imu_allan', 'diagnose', str(args.adis),
                                '--out', str(Path(tmp) / f'd{k}')])[0])
    wall = statistics.median(walls)
    ok = wall < 60.0
    failed += [] if ok else ['diagnose']
    print(f'[diagnose] {args.adis.name}: {wall:.1f} s (runs: '
          f'{", ".join(f"{w:.1f}" for w in walls)} s; guard 60 s) {_verdict(ok)}; '
          f'load average {os.getloadavg()[0]:.1f}', flush=True)


def main() -> None:
    """Measure the chosen guards; exit 1 when one fails."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--only', nargs='+', default=['analyze', 'adev', 'diagnose'],
                        choices=['analyze', 'adev', 'diagnose'])
    parser.add_argument('--storage', nargs='+', default=['mcap', 'sqlite3'],
                        choices=['mcap', 'sqlite3'])
    parser.add_argument('--hours', type=float, default=3.0)
    parser.add_argument('--rate', type=float, default=400.0, help='message rate [Hz]')
    parser.add_argument('--cache', type=Path, default=Path('/tmp/imu_allan_bench_bags'))
    parser.add_argument('--samples', type=int, default=4_000_000)
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--adis', type=Path, default=ADIS_RUN)
    args = parser.parse_args()
    byte_compile()
    print(f'{os.cpu_count()} cores; medians of {args.repeat} alternating runs', flush=True)
    failed: list = []
    for name, guard in (('analyze', _analyze), ('adev', _adev), ('diagnose', _diagnose)):
        if name in args.only:
            guard(args, failed)
    if failed:
        print(f'FAILED: {", ".join(failed)}')
        sys.exit(1)


if __name__ == '__main__':
    main()
