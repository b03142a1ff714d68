"""
``imu-allan adev`` end to end against ``np.loadtxt`` plus ``allantools.oadev``.

Usage: ``.venv/bin/python bench/bench_adev.py [--samples 4000000] [--repeat 3]``.
Writes one CSV column of ``--samples`` values (white noise plus a random walk) to a
temporary file, then measures, in the same run:

* ``imu-allan adev FILE --rate 100 --taus dense --format json`` as a subprocess,
  process start to JSON on stdout (wall seconds, best of ``--repeat``);
* ``np.loadtxt`` plus ``allantools.oadev`` at the same taus in one fresh Python
  process (its imports included), best of ``--repeat``.

Prints both, their ratio (the guard, at least 2x, is measured by ``bench_guards.py``) and the
largest relative difference of the two curves (target 1e-9).
"""

import argparse
import json
from pathlib import Path
import subprocess
import sys
import tempfile
import time

from bytecode import byte_compile
import numpy as np

BASELINE = """
import json, sys
import numpy as np, allantools
y = np.loadtxt(sys.argv[1])
taus = np.array(json.loads(sys.argv[2]))
taus_used, adev, _, _ = allantools.oadev(y, rate=100.0, data_type='freq', taus=taus)
print(json.dumps([taus_used.tolist(), adev.tolist()]))
"""


def _best(cmd: list, repeat: int) -> tuple:
    """Return (best wall seconds, stdout of the last run) of a command."""
    best, out = float('inf'), ''
    for _ in range(repeat):
        t0 = time.perf_counter()
        run = subprocess.run(cmd, capture_output=True, text=True, check=True)
        best = min(best, time.perf_counter() - t0)
        out = run.stdout
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--samples', type=int, default=4_000_000)
    ap.add_argument('--repeat', type=int, default=3)
    args = ap.parse_args()
    byte_compile()
    rng = np.random.default_rng(1)
    y = rng.normal(size=args.samples) * 1e-3 + np.cumsum(rng.normal(size=args.samples)) * 1e-7
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'column.csv'
        np.savetxt(path, y, fmt='%.9e')
        exe = Path(sys.executable).parent / 'imu-allan'
        ours, out = _best([str(exe), 'adev', str(path), '--rate', '100', '--taus', 'dense',
                           '--format', 'json'], args.repeat)
        doc = json.loads(out)
        base, out = _best([sys.executable, '-c', BASELINE, str(path),
                           json.dumps(doc['tau_s'])], args.repeat)
    # allantools leaves out the taus it finds too long for the record: compare the rest.
    their_tau, theirs = (np.array(v) for v in json.loads(out))
    mine = np.array(doc['adev'])[np.isin(doc['tau_s'], their_tau)]
    diff = float(np.max(np.abs(mine / theirs - 1.0)))
    print(f'{args.samples:,} samples, {len(mine)} dense taus, best of {args.repeat}')
    print(f'imu-allan adev end to end: {ours:.2f} s; np.loadtxt + allantools.oadev: '
          f'{base:.2f} s; ratio {base / ours:.2f}x (guard 2x); curves agree to {diff:.1e}')


if __name__ == '__main__':
    main()
