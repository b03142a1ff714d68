"""
The one-model fit on a sensor nobody simulated: the six static ADIS16405 runs.

Usage: ``.venv/bin/python bench/validate_adis.py [--runs 1,2,3,4,5,6]`` (needs
``../shared/realdata``).  Each run goes through the pipeline as ``imu-allan analyze``
runs it (CSV reader, Session, dense curve, effect search with the raw-sample evidence);
per axis it prints the terms of the final model, the share of taus where the model lies
inside the measured 95 % band or within 5 % of the curve, N against the curve's white
level (median sqrt(avar tau) where white noise carries >= 80 % of the model, and
between 0.1 s and 2 s), B against the datasheet (gyros: 0.007 deg/s) and the search time.
"""

import argparse
import math
from pathlib import Path
import time

import numpy as np

from imu_allan import AXES, AXIS_UNITS
from imu_allan.core.allan.raw import RawKeeper
from imu_allan.core.fit.judge import white_region, white_share
from imu_allan.core.search import search_axis
from imu_allan.io.csv_io import read_csv
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session

DATA = Path(__file__).resolve().parents[2] / 'shared' / 'realdata' / 'adis16405'
B_DATASHEET = 0.007 * math.pi / 180.0   # rad/s, in-run bias stability


def stream(stamps: np.ndarray, samples: np.ndarray):
    """Stream samples through a Session as the CLI does; return it and the raw copy."""
    session = Session(SessionConfig())
    keeper = None
    for i in range(0, samples.shape[0], 100_000):
        session.add(stamps[i:i + 100_000], samples[i:i + 100_000])
        if keeper is None and session.rate_hz > 0:
            keeper = RawKeeper(session.rate_hz)
        if keeper is not None:
            keeper.add(samples[i:i + 100_000])
    return session, keeper


def curve_of(path: Path):
    """Stream one run through a Session as the CLI does; return the curve and the raw copy."""
    rec = read_csv(path)
    stamps = np.round(np.asarray(rec.t_s) * 1e9).astype(np.int64)
    session, keeper = stream(stamps, np.asarray(rec.samples, dtype=np.float64))
    return session.curve(confidence=0.95), int(session.stats.n_used), keeper


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--runs', default='1,2,3,4,5,6')
    args = ap.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f'{DATA}: not found (../shared/realdata is needed)')
    rows, follow, n_err, run_cpu = [], [], [], {}
    print('| run | axis | terms | inside | N / white(model) | N / white(0.1-2 s) | '
          'B / datasheet | T_B [s] | s |')
    print('|---|---|---|---|---|---|---|---|---|')
    for run in [int(r) for r in args.runs.split(',')]:
        curve, n_used, keeper = curve_of(DATA / f'adis16405_run{run}.csv.gz')
        for j, axis in enumerate(AXES):
            t0 = time.process_time()
            s = search_axis(curve.tau_s, curve.avar[:, j], curve.edf[:, j], curve.rate_hz,
                            n_used, raw=keeper.samples[:, j], raw_rate_hz=keeper.kept_rate_hz,
                            unit=AXIS_UNITS[axis])
            cpu = time.process_time() - t0
            run_cpu[run] = run_cpu.get(run, 0.0) + cpu
            fit = s.fit
            model = np.sqrt(fit.avar_at(curve.tau_s))
            adev = curve.adev[:, j]
            ok = np.isfinite(adev)
            inside = ((model >= curve.adev_lo[:, j]) & (model <= curve.adev_hi[:, j])) | (
                np.abs(model / adev - 1.0) <= 0.05)
            share = float(np.mean(inside[ok]))
            follow.append(share >= 0.85)
            band = (curve.tau_s >= 0.1) & (curve.tau_s <= 2.0)
            white_02 = float(np.median(adev[band] * np.sqrt(curve.tau_s[band])))
            share_w = white_share(fit)
            wr = None if share_w is None else white_region(
                fit.tau_s, fit.avar_meas, fit.edf, share_w)
            n = fit.optimised['N'].value
            b = fit.optimised['B']
            tb = fit.optimised['T_B']
            n_wr = n / wr[0] if wr else math.nan
            if axis.startswith('gyro'):
                n_err.append(abs(n / white_02 - 1.0))
            b_ratio = b.value / B_DATASHEET if axis.startswith('gyro') else math.nan
            rows.append((run, axis, share))
            print(f'| {run} | {axis} | {", ".join(fit.terms)} | {share:.2f} | {n_wr:.3f} | '
                  f'{n / white_02:.3f} | {b_ratio:.2f} | {tb.value:.3g} ({tb.kind}) | '
                  f'{cpu:.1f} |', flush=True)
    print(f'\nmodel follows the curve (>= 85 % of taus) on {sum(follow)} of {len(follow)} axes')
    print('search CPU s per six-axis run (target 15 s on one core): '
          + ', '.join(f'run {r}: {c:.1f}' for r, c in run_cpu.items()))
    if n_err:
        print(f'gyro N vs white level 0.1-2 s: median error {100 * np.median(n_err):.1f} %, '
              f'max {100 * np.max(n_err):.1f} %')


if __name__ == '__main__':
    main()
