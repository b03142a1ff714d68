"""
Peak memory of ``imu-allan analyze`` on a CSV against the MCAP path, same record.

Writes one ``--hours`` long (default 24 h) ``--rate`` Hz (default 100 Hz) six-axis record
(config/xsens_mti7.yaml, seeded) as a CSV (``t,gyro_x,...,accel_z``) and as an MCAP
bag (the bag of ``bench_analyze.py``, cached in ``--cache``), then runs
``imu-allan analyze FILE --no-plot --no-plan --jobs 1 --format json`` on each as a fresh
process and prints the peak resident memory of each (the child's ``ru_maxrss``) and
their ratio.  Guard (issue 37): the CSV within 2x of the MCAP path.  Before the CSV was
read in blocks, it was loaded whole (2.6 GB for 24 h at 100 Hz).

Usage: ``.venv/bin/python bench/bench_csv_memory.py [--hours H] [--rate HZ] [--cache DIR]``.
Exits 1 when the guard fails.
"""

import argparse
from pathlib import Path
import resource
import subprocess
import sys
import time

from bench_analyze import _bag
import numpy as np

from imu_allan import AXES
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.io.csv_io import write_csv

REPO = Path(__file__).resolve().parents[1]


def _csv(cache: Path, hours: float, rate: float) -> Path:
    """Return the cached CSV of this size, writing it first when missing."""
    path = cache / f'imu_{hours:g}h_{rate:g}hz.csv'
    if path.exists():
        return path
    cache.mkdir(parents=True, exist_ok=True)
    spec = load_params(REPO / 'config' / 'xsens_mti7.yaml')
    _, samples = simulate_imu(spec, rate, hours * 3600.0, seed=0)
    tmp = path.with_suffix('.tmp.csv')
    write_csv(tmp, np.arange(samples.shape[0]) / rate, samples, AXES)
    tmp.replace(path)
    return path


def _peak_mb(path: Path) -> tuple[float, float]:
    """Run analyze on ``path`` in a fresh process: (peak resident MB, wall s)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, '-m', 'imu_allan', 'analyze', str(path), '--no-plot',
                          '--no-plan', '--jobs', '1', '--format', 'json', '--out',
                          str(path.parent / f'out_{path.stem}')],
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        sys.exit(f'analyze {path} failed: {res.stderr.strip().splitlines()[-1]}')
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    # ru_maxrss of the children is the largest of any child so far (kB on Linux): run
    # the larger-or-equal case last or read each from a fresh interpreter.
    return max(peak, before) / 1024.0, wall


def main() -> int:
    """Write the record both ways, measure, print, return 1 when the guard fails."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--hours', type=float, default=24.0)
    p.add_argument('--rate', type=float, default=100.0)
    p.add_argument('--cache', type=Path, default=Path('/tmp/imu_allan_bench_bags'))
    args = p.parse_args()
    csv = _csv(args.cache, args.hours, args.rate)
    bag = _bag(args.cache, 'mcap', args.hours, args.rate)
    # Each in a process of its own, so that ru_maxrss is that run's peak.
    code = ('import sys; sys.path.insert(0, %r); from bench_csv_memory import _peak_mb; '
            'from pathlib import Path; print(*_peak_mb(Path(sys.argv[1])))'
            % str(Path(__file__).parent))
    peaks = {}
    for name, path in (('csv', csv), ('mcap', bag)):
        out = subprocess.run([sys.executable, '-c', code, str(path)], capture_output=True,
                             text=True, check=True).stdout.split()
        peaks[name] = (float(out[0]), float(out[1]))
    ratio = peaks['csv'][0] / peaks['mcap'][0]
    ok = ratio <= 2.0
    print(f'{args.hours:g} h at {args.rate:g} Hz: CSV peak {peaks["csv"][0]:.0f} MB '
          f'({peaks["csv"][1]:.0f} s), MCAP peak {peaks["mcap"][0]:.0f} MB '
          f'({peaks["mcap"][1]:.0f} s): {ratio:.2f}x (guard 2x) {"PASS" if ok else "FAIL"}')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
