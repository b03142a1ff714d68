"""
The planner on a real sensor: predict from 20 minutes what 2.78 hours achieve.

Usage: ``.venv/bin/python bench/plan_adis.py [--runs 1,2,3,4,5,6] [--minutes 20]``
(needs ``../shared/realdata``).  Each static ADIS16405 run goes through the pipeline as
``imu-allan analyze`` runs it, once cut to its first ``--minutes`` and once whole.  Per
axis and parameter (N, B, T_B) the full run's relative 95 % half-width w_full is what
the record achieved; the planner as ``analyze`` runs it, from the fit of the first
minutes alone, predicts the record length at which the half-width reaches w_full.  The
ratio of that length to the run's length is the planner's error (1 = exact).  A
parameter the short fit only bounds is planned at its bound (a lower limit on the
length).  The same plan's half-width at the run's length, against w_full, is the error
read in widths (a factor f in width is about f^2 in length).  Prints a markdown table
(docs/planning.md).
"""

import argparse
from collections import Counter
import math
from pathlib import Path
import sys

import numpy as np
from validate_adis import stream

from imu_allan import AXES
from imu_allan.core.noise.terms import base_name
from imu_allan.core.plan.planner import plan_fits
from imu_allan.core.plan.precision import relative_width
from imu_allan.io.csv_io import read_csv
from imu_allan.pipeline.analysis import analyze

DATA = Path(__file__).resolve().parents[2] / 'shared' / 'realdata' / 'adis16405'
PARAMS = ('N', 'B', 'T_B')


def analysis_of(stamps: np.ndarray, samples: np.ndarray, workers: int = 1):
    """Stream samples through a Session as the CLI does; return the AnalysisResult."""
    session, keeper = stream(stamps, samples)
    return analyze(session, raw=keeper, workers=workers)


def predicted_lengths(fit, rate_hz: float, duration_s: float, widths: dict,
                      full_s: float) -> dict:
    """
    Per parameter (length at which the short plan reaches widths[p], kind, width); caveat.

    The plan is the one ``imu-allan analyze`` reports (:func:`plan_fits`) with the
    achieved widths as targets.  ``width`` is its half-width at ``full_s`` (the whole
    run's length), interpolated in log-log between the widths it reports at 1, 3 and
    10 h.  A lower limit the short record has passed (NaN) is the short length.
    """
    plan = plan_fits({'axis': fit}, rate_hz, duration_s, widths)['axis']
    out = {}
    for p in plan.params:
        if p.name not in widths:
            continue
        hours = sorted(p.widths_at)
        at_full = float(np.exp(np.interp(math.log(full_s / 3600.0), np.log(hours),
                                         np.log([p.widths_at[h] for h in hours]))))
        t = duration_s if math.isnan(p.time_s) else p.time_s
        out[p.name] = (t, 'at_least' if p.kind == 'at_least' else 'predicted', at_full)
    return out, plan.caveat


def compare_run(path: Path, minutes: float, workers: int = 1) -> list:
    """
    Compare the plan of a run's first minutes with the whole run, per axis and parameter.

    Rows (run, axis, param, w_short, w_full, predicted, run length, kind, w_pred, caveat,
    grew): ``grew`` names the terms the whole run's model has that the short one lacks.
    ``workers``: processes for the axes' searches.
    """
    rec = read_csv(path)
    stamps = np.round(np.asarray(rec.t_s) * 1e9).astype(np.int64)
    samples = np.asarray(rec.samples, dtype=np.float64)
    cut = int(np.searchsorted(rec.t_s, rec.t_s[0] + 60.0 * minutes))
    short = analysis_of(stamps[:cut], samples[:cut], workers)
    full = analysis_of(stamps, samples, workers)
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
        pred, caveat = predicted_lengths(fs, short.rate_hz, short.duration_s, achieved,
                                         full.duration_s)
        grew = sorted((Counter(base_name(t) for t in ff.terms)
                       - Counter(base_name(t) for t in fs.terms)).elements())
        for p, w_full in achieved.items():
            q = fs.optimised.get(p)
            w_short = relative_width(q.value, q.ci95) if q and q.kind == 'estimate' else math.inf
            t_pred, kind, w_pred = pred.get(p, (math.nan, 'none', math.nan))
            rows.append((path.stem.split('_')[-1], axis, p, w_short, w_full, t_pred,
                         full.duration_s, kind, w_pred, caveat, ', '.join(grew)))
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
          'width ratio | caveat | terms the whole run adds |')
    print('|---|---|---|---|---|---|---|---|---|---|---|---|')
    # Per parameter, how each row ended: a point prediction within 2x, a lower limit
    # that holds, or outside 2x: where the whole run's model has terms the short one
    # lacks, or its interval is wider than the short one's (the model grew with the
    # record: no plan of the short model foresees it), with the plan's caveat ("times
    # may be short"), or none of these.
    ends: dict = {p: {'within': 0, 'limit holds': 0, 'outside, model grew': 0,
                      'outside, caveat': 0, 'outside, other': 0} for p in PARAMS}
    width_ratios: dict = {p: [] for p in PARAMS}
    for run in args.runs.split(','):
        for r in compare_run(DATA / f'adis16405_run{run}.csv.gz', args.minutes):
            name, axis, p, w_short, w_full, t_pred, t_full, kind, w_pred, caveat, grew = r
            ratio = t_pred / t_full
            width_ratios[p].append(w_pred / w_full)
            if kind == 'at_least' and ratio <= 2.0:
                ends[p]['limit holds'] += 1
            elif 0.5 <= ratio <= 2.0:
                ends[p]['within'] += 1
            elif grew or w_full > w_short:
                ends[p]['outside, model grew'] += 1
            else:
                ends[p]['outside, caveat' if caveat else 'outside, other'] += 1
            mark = '>= ' if kind == 'at_least' else ''
            print(f'| {name} | {axis} | {p} | {100 * w_short:.3g} % | {100 * w_full:.3g} % | '
                  f'{mark}{t_pred / 3600:.3g} h | {t_full / 3600:.3g} h | {mark}{ratio:.2f} | '
                  f'{100 * w_pred:.3g} % | {w_pred / w_full:.2f} | '
                  f'{"yes" if caveat else "-"} | {grew or "-"} |')
        print(f'run {run} done', file=sys.stderr)
    for p, counts in ends.items():
        ws_ = np.array(width_ratios[p])
        w_in = np.mean((ws_ >= 0.5) & (ws_ <= 2.0)) if ws_.size else math.nan
        print(f'{p}: {sum(counts.values())} axes, ' + ', '.join(
            f'{k} {v}' for k, v in counts.items()) + f'; in width {100 * w_in:.0f} % within '
            'a factor of 2', file=sys.stderr)


if __name__ == '__main__':
    main()
