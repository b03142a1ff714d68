"""
The planner on a real sensor: predict from 20 minutes what 2.78 hours achieve.

Usage: ``.venv/bin/python bench/plan_adis.py [--runs 1,2,3,4,5,6] [--minutes 20]``
(needs ``../shared/realdata``).  Each static ADIS16405 run goes through the pipeline as
``imu-allan analyze`` runs it, once cut to its first ``--minutes`` and once whole.  Per
axis and parameter (N, B, T_B) the full run's relative 95 % half-width w_full is what
the record achieved; the planner, from the fit of the first minutes alone, predicts
the record length at which the half-width reaches w_full.  The ratio of that length to
the run's length is the planner's error (1 = exact).  A parameter the short fit only
bounds is planned at its bound (a lower limit on the length).  The same plan's
half-width at the run's length, against w_full, is the error read in widths (a factor
f in width is about f^2 in length).  Prints a markdown table (docs/planning.md).
"""

import argparse
import math
from pathlib import Path
import sys

import numpy as np
from validate_adis import stream

from imu_allan import AXES
from imu_allan.core.plan import planning_model
from imu_allan.core.plan.planner import _crossing, calibrated
from imu_allan.core.plan.precision import CurveModel, relative_width
from imu_allan.io.csv_io import read_csv
from imu_allan.pipeline.analysis import analyze

DATA = Path(__file__).resolve().parents[2] / 'shared' / 'realdata' / 'adis16405'
PARAMS = ('N', 'B', 'T_B')


def analysis_of(stamps: np.ndarray, samples: np.ndarray):
    """Stream samples through a Session as the CLI does; return the AnalysisResult."""
    session, keeper = stream(stamps, samples)
    return analyze(session, raw=keeper)


def predicted_lengths(fit, rate_hz: float, widths: dict, lengths_s: np.ndarray,
                      full_s: float) -> dict:
    """
    Per parameter: (length at which the short fit's plan reaches widths[p], kind, width).

    ``width`` is the plan's half-width at ``full_s`` (the whole run's length).

    ``lengths_s[0]`` is the short record's length: there the expected widths are scaled
    to the short fit's intervals as the planner does (:func:`calibrated`).
    """
    comps, bounds = planning_model(fit.components, fit.optimised)
    out = {}
    for key, c in {'': comps, **bounds}.items():
        if not c:
            continue
        cm = CurveModel(c, rate_hz)
        rows = np.array([cm.widths(length) for length in lengths_s])
        for j, name in enumerate(cm.names):
            if name in widths and ((key == '' and name not in bounds) or key == name):
                kind = 'at_least' if key else 'predicted'
                col = rows[:, j]
                q = fit.optimised.get(name)
                if not key and q is not None and q.kind == 'estimate':
                    col = calibrated(col, col[0], relative_width(q.value, q.ci95))
                at_full = float(np.exp(np.interp(math.log(full_s), np.log(lengths_s),
                                                 np.log(col))))
                out[name] = (_crossing(lengths_s, col, widths[name]), kind, at_full)
    return out


def compare_run(path: Path, minutes: float) -> list:
    """Rows (run, axis, param, w_short, w_full, predicted length, run length, kind, w_pred)."""
    rec = read_csv(path)
    stamps = np.round(np.asarray(rec.t_s) * 1e9).astype(np.int64)
    samples = np.asarray(rec.samples, dtype=np.float64)
    cut = int(np.searchsorted(rec.t_s, rec.t_s[0] + 60.0 * minutes))
    short = analysis_of(stamps[:cut], samples[:cut])
    full = analysis_of(stamps, samples)
    lengths = np.geomspace(short.duration_s, 20.0 * full.duration_s, 14)
    rows = []
    for axis in AXES:
        fs, ff = short.fits.get(axis), full.fits.get(axis)
        if fs is None or ff is None:
            continue
        achieved = {}
        for p in PARAMS:
            q = ff.optimised.get(p)
            if q is not None and q.kind == 'estimate':
                achieved[p] = relative_width(q.value, q.ci95)
        pred = predicted_lengths(fs, short.rate_hz, achieved, lengths, full.duration_s)
        for p, w_full in achieved.items():
            q = fs.optimised.get(p)
            w_short = relative_width(q.value, q.ci95) if q and q.kind == 'estimate' else math.inf
            t_pred, kind, w_pred = pred.get(p, (math.nan, 'none', math.nan))
            rows.append((path.stem.split('_')[-1], axis, p, w_short, w_full, t_pred,
                         full.duration_s, kind, w_pred))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--runs', default='1,2,3,4,5,6')
    ap.add_argument('--minutes', type=float, default=20.0)
    args = ap.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f'{DATA}: not found (../shared/realdata is needed)')
    print(f'| run | axis | param | width at {args.minutes:g} min | width at full length | '
          'predicted length for it | full length | ratio | predicted width at full length | '
          'width ratio |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    ratios: dict = {p: [] for p in PARAMS}
    width_ratios: dict = {p: [] for p in PARAMS}
    for run in args.runs.split(','):
        for r in compare_run(DATA / f'adis16405_run{run}.csv.gz', args.minutes):
            name, axis, p, w_short, w_full, t_pred, t_full, kind, w_pred = r
            ratio = t_pred / t_full
            ratios[p].append(ratio)
            width_ratios[p].append(w_pred / w_full)
            mark = '>= ' if kind == 'at_least' else ''
            print(f'| {name} | {axis} | {p} | {100 * w_short:.3g} % | {100 * w_full:.3g} % | '
                  f'{mark}{t_pred / 3600:.3g} h | {t_full / 3600:.3g} h | {mark}{ratio:.2f} | '
                  f'{100 * w_pred:.3g} % | {w_pred / w_full:.2f} |')
        print(f'run {run} done', file=sys.stderr)
    for p, rs in ratios.items():
        rs_, ws_ = np.array(rs), np.array(width_ratios[p])
        inside = np.mean((rs_ >= 0.5) & (rs_ <= 2.0)) if rs_.size else math.nan
        w_in = np.mean((ws_ >= 0.5) & (ws_ <= 2.0)) if ws_.size else math.nan
        print(f'{p}: {rs_.size} axes, median length ratio {np.median(rs_):.2f}, '
              f'{100 * inside:.0f} % within a factor of 2; median width ratio '
              f'{np.median(ws_):.2f}, {100 * w_in:.0f} % within a factor of 2', file=sys.stderr)


if __name__ == '__main__':
    main()
