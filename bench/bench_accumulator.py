"""
Benchmark of the streaming Allan accumulator (imu_allan.core.allan.accumulator).

Feeds ``--rows`` six-axis rows (default 10 million) in blocks of 1000 rows (as the
ROS node does) and in blocks of 1 million rows (as a bag reader does), and prints
rows per second next to two baselines measured in the same run on the same data, so
the ratios stay meaningful on a shared machine:

* batch: :func:`imu_allan.core.allan.overlapping_avar` on 1 million rows, for the taus the
  accumulator computes exactly (the streaming result equals it there);
* pass: one ``np.cumsum`` over the rows, the cheapest thing any estimator must do.

Also prints the persistent state per axis for 24 h at 1 kHz.  ``--sweep`` adds a
table over exact_max_m (speed against the number of exact taus).

Usage: ``.venv/bin/python bench/bench_accumulator.py [--rows N] [--sweep]``
"""

import argparse
import os
import time

# The batch baseline calls np.dot, which OpenBLAS threads; on a shared machine its
# threads stall each other (tens of times slower, erratic).  One BLAS thread keeps the
# baseline fair and repeatable; the accumulator itself uses no BLAS.  Must precede
# the numpy import.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from imu_allan.core.allan import overlapping_avar  # noqa: E402
from imu_allan.core.allan.accumulator import AllanAccumulator  # noqa: E402

N_AXES = 6
BASE_ROWS = 1_000_000


def _timed(fn) -> tuple[float, float]:
    """Run fn once; return (wall seconds, CPU seconds of this process)."""
    w0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w0, time.process_time() - c0


def _feed(acc: AllanAccumulator, base: np.ndarray, rows: int, block: int) -> None:
    fed = 0
    while fed < rows:
        start = fed % base.shape[0]
        take = min(block, rows - fed, base.shape[0] - start)
        acc.add(base[start:start + take])
        fed += take


def _stream_rate(base: np.ndarray, rows: int, block: int, exact_max_m: int) -> tuple:
    acc = AllanAccumulator(N_AXES, 1000.0, exact_max_m=exact_max_m)
    wall, cpu = _timed(lambda: _feed(acc, base, rows, block))
    return rows / wall, rows / cpu, acc


def main() -> int:
    """Run the benchmark and print the figures; return 0."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--rows', type=int, default=10_000_000)
    parser.add_argument('--exact-max-m', type=int, default=None)
    parser.add_argument('--sweep', action='store_true')
    args = parser.parse_args()
    exact = args.exact_max_m or AllanAccumulator(1, 1.0).exact_max_m
    rng = np.random.default_rng(0)
    # An accelerometer-like record: 9.81 offset, white noise and a random-walk bias;
    # the content does not change the speed, so one million rows are fed cyclically.
    base = (9.81 + 1e-3 * rng.standard_normal((BASE_ROWS, N_AXES))
            + 1e-6 * np.cumsum(rng.standard_normal((BASE_ROWS, N_AXES)), axis=0))

    acc24 = AllanAccumulator(N_AXES, 1000.0, exact_max_m=exact)
    m_exact = acc24.m[acc24.exact_mask(acc24.m)]
    print(f'exact_max_m = {exact} ({exact / 1000.0:g} s at 1 kHz), '
          f'{m_exact.size} exact taus, {acc24.m.size - m_exact.size} decimated taus '
          f'up to m = {acc24.m.max():.3g}')
    print(f'state for 24 h at 1 kHz: {acc24.state_nbytes() / N_AXES / 1e6:.3f} MB per axis '
          f'(limit 1 MB)')

    wall_pass, cpu_pass = _timed(lambda: np.cumsum(base, axis=0))
    wall_batch, cpu_batch = _timed(lambda: overlapping_avar(base, m_exact))
    pass_rate, batch_rate = BASE_ROWS / cpu_pass, BASE_ROWS / cpu_batch
    batch_wall_rate = BASE_ROWS / wall_batch
    print(f'baseline pass  (np.cumsum, 1e6 rows): {BASE_ROWS / wall_pass / 1e6:8.2f} M rows/s '
          f'wall, {pass_rate / 1e6:8.2f} M rows/s CPU')
    print(f'baseline batch (overlapping_avar, {m_exact.size} taus, 1e6 rows): '
          f'{BASE_ROWS / wall_batch / 1e6:6.2f} M rows/s wall, '
          f'{batch_rate / 1e6:6.2f} M rows/s CPU')

    for block in (1000, 1_000_000):
        wall_rate, cpu_rate, acc = _stream_rate(base, args.rows, block, exact)
        assert acc.state_nbytes() == acc24.state_nbytes()
        print(f'stream, blocks of {block:>9,} rows, {args.rows:,} rows: '
              f'{wall_rate / 1e6:5.2f} M rows/s wall, {cpu_rate / 1e6:5.2f} M rows/s CPU')
        print(f'    speed ratio to batch: {wall_rate / batch_wall_rate:4.2f} wall, '
              f'{cpu_rate / batch_rate:4.2f} CPU; to one pass: {cpu_rate / pass_rate:5.3f} CPU '
              f'(costs {pass_rate / cpu_rate:.0f} passes)')
    wall, cpu = _timed(acc.curve)
    print(f'curve() with {acc.curve().m.size} taus: {wall * 1e3:.0f} ms')

    if args.sweep:
        rows = min(args.rows, 3_000_000)
        print(f'\nsweep ({rows:,} rows, blocks of 1000): exact_max_m, exact taus, '
              'M rows/s CPU, MB/axis')
        for em in (1024, 2048, 4096, 8192, 16384):
            _, cpu_rate, acc = _stream_rate(base, rows, 1000, em)
            n_exact = int(acc.exact_mask(acc.m).sum())
            print(f'{em:>8} {n_exact:>5} {cpu_rate / 1e6:8.2f} '
                  f'{acc.state_nbytes() / N_AXES / 1e6:8.3f}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
