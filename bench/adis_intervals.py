"""
Intervals across the six ADIS16405 runs: one value inside every run's interval, per pair.

Usage: ``.venv/bin/python bench/adis_intervals.py [--runs 1,2,3,4,5,6] [--cache DIR]``
(needs ``../shared/realdata``).  Each run goes through the path of
``bench/validate_adis.py`` (CSV reader, Session, dense curve, effect search with the
raw-sample evidence); the curves and the kept raw samples are cached in ``--cache``
(default /tmp/adis_intervals), the searches always run (their fits are
kept in ``DIR/fits.pkl``).

Per axis and parameter (B, K, T_B) it prints each run's value, kind and 95 % interval,
and counts the pairs that pass.  The rule: a pair passes when one value satisfies the
constraint of every run.  A run constrains the pair by what it reports:

- an estimate: the value lies inside its 95 % interval;
- a one-sided bound: only that side (an upper bound: the value lies below it; a lower
  bound: above it), since the other side is not measured;
- not identified: no constraint.

A pair that no run identifies passes (it is reported as not identified everywhere);
such pairs are counted apart.
"""

import argparse
import math
from pathlib import Path
import pickle
import sys

import numpy as np
from validate_adis import curve_of, DATA   # bench/ is the script's directory

from imu_allan import AXES, AXIS_UNITS
from imu_allan.core.search import search_axis

PARAMS = ('B', 'K', 'T_B')


def cached_curve(run: int, cache: Path) -> dict:
    """Return the run's curve arrays and raw samples, from the cache or the CSV."""
    path = cache / f'run{run}.npz'
    if not path.exists():
        curve, n_used, keeper = curve_of(DATA / f'adis16405_run{run}.csv.gz')
        cache.mkdir(parents=True, exist_ok=True)
        np.savez(path, tau_s=curve.tau_s, avar=curve.avar, edf=curve.edf,
                 rate_hz=curve.rate_hz, n_used=n_used, raw=keeper.samples,
                 raw_rate_hz=keeper.kept_rate_hz)
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def constraint(p) -> tuple[float, float] | None:
    """Return the (lo, hi) a reported parameter puts on the common value, or None."""
    if p.kind == 'estimate':
        return p.ci95
    if p.kind == 'upper_bound':
        return (-math.inf, p.ci95[1])
    if p.kind == 'lower_bound':
        return (p.ci95[0], math.inf)
    return None


def passes(params: list) -> tuple[bool, bool]:
    """Whether one value satisfies every run's constraint; whether any run constrains."""
    cons = [c for c in (constraint(p) for p in params) if c is not None]
    if not cons:
        return True, False
    lo = max(c[0] for c in cons)
    hi = min(c[1] for c in cons)
    return lo <= hi, True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--runs', default='1,2,3,4,5,6')
    ap.add_argument('--cache', default='/tmp/adis_intervals')
    args = ap.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f'{DATA}: not found (../shared/realdata is needed)')
    runs = [int(r) for r in args.runs.split(',')]
    fits = {}
    for run in runs:
        c = cached_curve(run, Path(args.cache))
        for j, axis in enumerate(AXES):
            s = search_axis(c['tau_s'], c['avar'][:, j], c['edf'][:, j], float(c['rate_hz']),
                            int(c['n_used']), raw=c['raw'][:, j],
                            raw_rate_hz=float(c['raw_rate_hz']), unit=AXIS_UNITS[axis])
            fits[run, axis] = s.fit
            print(f'run {run} {axis}: {", ".join(s.fit.terms)}', file=sys.stderr, flush=True)
    with open(Path(args.cache) / 'fits.pkl', 'wb') as f:
        pickle.dump(fits, f)   # for a closer look at the rival models and notes
    n_pass = n_unconstrained = 0
    failing = []
    for axis in AXES:
        for sym in PARAMS:
            params = [fits[run, axis].optimised[sym] for run in runs]
            ok, constrained = passes(params)
            n_pass += ok
            n_unconstrained += not constrained
            if not ok:
                failing.append(f'{axis} {sym}')
            print(f'{axis} {sym}: {"pass" if ok else "FAIL"}')
            for run, p in zip(runs, params):
                print(f'    run {run}: {p.value:.4g} [{p.ci95[0]:.4g}, {p.ci95[1]:.4g}] '
                      f'{p.kind}  ({", ".join(fits[run, axis].terms)})')
    total = len(AXES) * len(PARAMS)
    print(f'\n{n_pass} of {total} (axis, parameter) pairs pass '
          f'({n_unconstrained} of them not identified in any run)')
    if failing:
        print('failing: ' + ', '.join(failing))


if __name__ == '__main__':
    main()
