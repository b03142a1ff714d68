"""
Benchmark of ``imu-allan fleet``: 2 local Dask workers against the sequential loop.

Simulates ``--imus`` x ``--nights`` static bags (MCAP, ``--rate`` Hz, lengths spread
evenly from ``--minutes`` to ``--long-minutes``: like real nights, no two alike, so no
run reuses another's fit geometry; cached in ``--cache``), then measures in the same
run:

* the sequential loop: :func:`imu_allan.fleet.task.analyze_job` over every input in this
  process, one after the other (wall and CPU seconds per input);
* the fleet run: :func:`imu_allan.fleet.run.run_fleet` on a LocalCluster of
  ``--workers`` single-threaded processes into a fresh store (content keys included;
  the cluster's start-up is timed apart);
* the ratio sequential / fleet wall time (target >= 1.8 on 2 workers), and that both
  give identical rows;
* the cost per input as a + b * messages (least squares over the inputs' CPU seconds),
  and the extrapolation to a night of a ``--robots`` robot fleet recording ``--hours``
  h at ``--rate`` Hz each;
* one whole ``--hours`` long bag analysed in a fresh process (CPU seconds and peak
  memory: what one worker needs per robot-night), which checks the extrapolation.

Usage: ``.venv/bin/python bench/bench_fleet.py [--imus 4] [--nights 4] [--workers 2]``
"""

import argparse
import os
from pathlib import Path
import resource
import sys
import tempfile
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from imu_allan import AXES  # noqa: E402
from imu_allan.core.noise.simulate import simulate_imu  # noqa: E402
from imu_allan.core.noise.values import AxisNoise, NoiseSpec  # noqa: E402
from imu_allan.fleet.inputs import content_key, fleet_inputs  # noqa: E402
from imu_allan.fleet.run import connect, run_fleet  # noqa: E402
from imu_allan.fleet.store import FleetStore  # noqa: E402
from imu_allan.fleet.task import analyze_job, FleetJob  # noqa: E402
from imu_allan.io.bag_writer import write_imu_bag  # noqa: E402
from imu_allan.pipeline.hygiene import SessionConfig  # noqa: E402


def _spec() -> NoiseSpec:
    """Return the simulated IMU of every bag: a MEMS-grade gyro and accelerometer."""
    gyro = AxisNoise(N=2.5e-4, B=1.5e-5, T_B=40.0, K=3e-6)
    accel = AxisNoise(N=1.2e-3, B=8e-5, T_B=60.0, K=4e-5)
    return NoiseSpec('bench', {a: gyro if a.startswith('gyro') else accel for a in AXES})


def _bags(args) -> Path:
    root = Path(args.cache) / f'{args.imus}x{args.nights}_{args.rate:g}_{args.minutes:g}-' \
        f'{args.long_minutes:g}'
    n_bags = args.imus * args.nights
    spec = _spec()
    for imu in range(args.imus):
        for night in range(args.nights):
            path = root / f'robot{imu}' / f'night{night}.mcap'
            if path.exists():
                continue
            k = (7 * (imu * args.nights + night)) % n_bags    # lengths shuffled over the IMUs
            minutes = args.minutes + (args.long_minutes - args.minutes) * k / max(n_bags - 1, 1)
            t, y = simulate_imu(spec, args.rate, 60.0 * minutes, seed=10 * imu + night)
            y[:, 5] += 9.81
            stamps = 1_700_000_000 * 10 ** 9 + night * 86400 * 10 ** 9 \
                + np.round(t * 1e9).astype(np.int64)
            write_imu_bag(path, stamps, y, frame_id=f'imu{imu}')
    return root


def _one_night(args) -> tuple:
    """Write one --hours bag (cached) and analyse it in a fresh process: CPU s, peak MB."""
    import subprocess

    path = Path(args.cache) / f'night_{args.hours:g}h_{args.rate:g}.mcap'
    if not path.exists():
        t, y = simulate_imu(_spec(), args.rate, 3600.0 * args.hours, seed=7)
        y[:, 5] += 9.81
        write_imu_bag(path, 1_700_000_000 * 10 ** 9 + np.round(t * 1e9).astype(np.int64), y)
        del t, y
    code = ('import resource, sys, time\n'
            'from imu_allan.fleet.task import analyze_job, FleetJob\n'
            'from imu_allan.pipeline.session import SessionConfig\n'
            'c = time.process_time()\n'
            f'k, st, rows = analyze_job(FleetJob({str(path)!r}, "k", "x", "m", None, '
            'SessionConfig()))\n'
            'print(st, rows[0]["n_samples"], time.process_time() - c, '
            'resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=str(REPO)), check=True)
    status, n, cpu, mb = out.stdout.split()
    return status, int(n), float(cpu), float(mb)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--imus', type=int, default=4)
    p.add_argument('--nights', type=int, default=4)
    p.add_argument('--rate', type=float, default=400.0)
    p.add_argument('--minutes', type=float, default=20.0)
    p.add_argument('--long-minutes', type=float, default=40.0)
    p.add_argument('--workers', type=int, default=2)
    p.add_argument('--robots', type=int, default=300)
    p.add_argument('--hours', type=float, default=8.0)
    p.add_argument('--cache', default='/tmp/imu_allan_bench_fleet')
    p.add_argument('--no-night', action='store_true', help='skip the one --hours bag')
    args = p.parse_args()

    t = time.monotonic()
    root = _bags(args)
    inputs = fleet_inputs([str(root)], id_pattern=r'robot(?P<imu>\d+)')
    print(f'{len(inputs)} bags in {root} ({time.monotonic() - t:.1f} s to make or find); '
          f'load average {os.getloadavg()[0]:.2f}')

    # Sequential loop, this process.
    seq_rows, per_input = {}, []
    t0 = time.monotonic()
    for inp in inputs:
        key = content_key(inp.path)
        w, c = time.monotonic(), time.process_time()
        _, status, rows = analyze_job(FleetJob(inp.path, key, inp.imu_id, inp.model, None,
                                               SessionConfig()))
        assert status == 'ok', rows[0]['reason']
        per_input.append((rows[0]['n_samples'], time.process_time() - c,
                          time.monotonic() - w))
        seq_rows[key] = rows
    seq_wall = time.monotonic() - t0
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    # Fleet run on a local cluster.
    t = time.monotonic()
    client, cluster = connect(n_workers=args.workers, memory_limit='4GiB')
    startup = time.monotonic() - t
    with tempfile.TemporaryDirectory() as tmp:
        store = FleetStore(tmp)
        t, c = time.monotonic(), time.process_time()
        summary = run_fleet(inputs, store, client)
        fleet_wall, client_cpu = time.monotonic() - t, time.process_time() - c
        stored = store.rows('ok')
    client.close()
    cluster.close()
    same = all(r[c] == s[c] for r in stored for s in seq_rows[r['key']]
               if s['axis'] == r['axis'] for c in ('N', 'N_lo', 'N_hi', 'B', 'K', 'T_B')
               if not (isinstance(s[c], float) and np.isnan(s[c]) and np.isnan(r[c])))

    n = np.array([x[0] for x in per_input], dtype=float)
    cpu = np.array([x[1] for x in per_input])
    a, b = np.linalg.lstsq(np.column_stack([np.ones_like(n), n]), cpu, rcond=None)[0]
    msgs = args.rate * 3600.0 * args.hours
    night_cpu_h = args.robots * (a + b * msgs) / 3600.0
    ratio = seq_wall / fleet_wall
    print(f'sequential loop: {seq_wall:.1f} s wall for {int(n.sum()):,} messages '
          f'({cpu.sum():.1f} CPU s)')
    print(f'fleet, {args.workers} workers: {fleet_wall:.1f} s wall (+{startup:.1f} s cluster '
          f'start-up and imports; content keys {summary.keys_s:.1f} s), {summary.n_ok} ok, '
          f'{summary.n_failed} failed, '
          f'{summary.cpu_s:.1f} CPU s in the workers, {client_cpu:.1f} in the client and '
          'scheduler')
    print(f'speed-up: {ratio:.2f}x (target >= 1.8); identical rows: {same}')
    print(f'cost per input: {a:.2f} CPU s + {b * 1e6:.3f} CPU us per message '
          f'({1e-6 / b:.2f} M messages per CPU second beyond the fit); peak memory of this '
          f'process (largest bag {int(n.max()):,} messages): {peak_mb:.0f} MB')
    print(f'extrapolated: {args.robots} robots x {args.hours:g} h x {args.rate:g} Hz = '
          f'{args.robots * msgs / 1e9:.2f} G messages a night -> {night_cpu_h:.1f} CPU hours '
          f'({night_cpu_h / 8:.1f} cores busy for 8 h)')
    if not args.no_night:
        status, n_night, cpu_night, mb_night = _one_night(args)
        print(f'one {args.hours:g} h bag ({n_night:,} messages, {status}): {cpu_night:.1f} CPU s '
              f'(the fit above predicts {a + b * n_night:.1f}), peak memory {mb_night:.0f} MB; '
              f'{args.robots} such nights: {args.robots * cpu_night / 3600:.1f} CPU hours')
    return 0 if same else 1


if __name__ == '__main__':
    sys.exit(main())
