"""
Check that the planner predicts when the intervals reach their targets.

Usage: ``.venv/bin/python bench/plan_validate.py [--seeds 6] [--hours 32] [--models ...]``
(``--quick`` for a small run).  For each model (the paper's Xsens MTi-7 and u-blox
C102-F9R, gyro and accelerometer, from config/, and an ADIS16405-like gyro) it
simulates ``--seeds`` records of ``--hours`` at the sensor's rate, fits prefixes of
growing length as ``imu-allan analyze`` does (dense curve, effect search) and takes,
per parameter and length, the median relative 95 % half-width (hi - lo) / (2 value)
over the seeds; the length at which that median reaches a target (log-log
interpolation) is "actual".  "Predicted" is the planner's length for the same target:
from the true model, and from the fit of each record's first hour as ``imu-allan
analyze`` and the node plan it (:func:`plan_fits`: read against the fit's dispersion
and present widths, waiting for the separations the fit left open).  A parameter the
first hour only bounds is planned at its bound, a lower limit, which holds when it is
at most 1.5x the actual length; as "actual" counts a seed without an estimate as not
there yet, the median of the per-seed plans counts such a seed as not predicted short.
A row is judged on that median where most seeds give a point prediction, else on its
lower limits.  Targets: every round width whose actual length lies inside the simulated
lengths.  Prints one markdown table (docs/planning.md).
"""

import argparse
import math
from pathlib import Path
import sys
import time

import numpy as np

from imu_allan.core.allan import allan_curve
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_axis
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.plan import noise_components, planning_model
from imu_allan.core.plan.planner import plan_fits
from imu_allan.core.plan.precision import CurveModel, relative_width
from imu_allan.core.plan.reading import crossing
from imu_allan.core.search import search_axis

CONFIG = Path(__file__).resolve().parents[1] / 'config'
#: An ADIS16405-like gyro: the six real runs' typical N, B, T_B (docs/fitting.md) and K.
ADIS_GYRO = AxisNoise(N=0.041 * math.pi / 180.0, B=0.011 * math.pi / 180.0, T_B=60.0,
                      K=1.0e-3 * math.pi / 180.0)
TARGETS = (0.5, 0.35, 0.25, 0.2, 0.15, 0.1, 0.07, 0.05, 0.035, 0.025, 0.015, 0.01, 0.007,
           0.005, 0.0035, 0.0025, 0.0015, 0.001)
PARAMS = ('N', 'B', 'T_B', 'K')


def models() -> dict:
    """Name -> (AxisNoise, rate_hz, unit)."""
    xs = load_params(CONFIG / 'xsens_mti7.yaml').axes
    ub = load_params(CONFIG / 'ublox_c102_f9r.yaml').axes
    return {'xsens_gyro': (xs['gyro_x'], 100.0, 'rad/s'),
            'xsens_accel': (xs['accel_x'], 100.0, 'm/s^2'),
            'ublox_gyro': (ub['gyro_x'], 50.0, 'rad/s'),
            'ublox_accel': (ub['accel_x'], 50.0, 'm/s^2'),
            'adis_gyro': (ADIS_GYRO, 100.0, 'rad/s')}


def width_columns(comps: list, bounds: dict, rate_hz: float, lengths_s: np.ndarray) -> dict:
    """Return the expected relative half-width per parameter at every length."""
    out: dict = {}
    variants = {'': comps, **bounds}
    for key, c in variants.items():
        if not c:
            continue
        cm = CurveModel(c, rate_hz)
        rows = np.array([cm.widths(length) for length in lengths_s])
        for j, name in enumerate(cm.names):
            if (key == '' and name not in bounds) or key == name:
                out[name] = rows[:, j]
    return out


def fit_widths(y: np.ndarray, rate_hz: float, unit: str, truth: AxisNoise | None = None):
    """
    Search one record; return its fit, the relative half-width per parameter and cover.

    ``cover`` is, per parameter of ``truth``, 1.0 when the estimate's interval holds the
    true value, 0.0 when not, NaN when it is no estimate.
    """
    c = allan_curve(y, rate_hz, 'dense', confidence=0.95)
    fit = search_axis(c.tau_s, c.avar[:, 0], c.edf[:, 0], rate_hz, y.size, unit=unit).fit
    widths, cover = {}, {}
    for name in PARAMS:
        p = fit.optimised.get(name)
        estimate = p is not None and p.kind == 'estimate'
        widths[name] = relative_width(p.value, p.ci95) if estimate else math.inf
        true = getattr(truth, name, math.nan) if truth is not None else math.nan
        cover[name] = (float(p.ci95[0] <= true <= p.ci95[1]) if estimate and true > 0
                       else math.nan)
    return fit, widths, cover


def early_plans(fit, rate_hz: float, duration_s: float) -> dict:
    """
    Per (parameter, target): the planner's (time [s], kind) from one early fit.

    A lower limit the record has already passed (time NaN: at its bound the term would
    be resolved by now) is the present length.
    """
    out = {}
    for target in TARGETS:
        plan = plan_fits({'axis': fit}, rate_hz, duration_s, {p: target for p in PARAMS})
        for p in plan['axis'].params if 'axis' in plan else ():
            t = duration_s if math.isnan(p.time_s) else p.time_s
            out[(p.name, target)] = (t, p.kind)
    return out


def early_summary(plans: list, p: str, target: float, t_act: float) -> tuple:
    """
    (median prediction [s], point predictions, lower limits that hold, lower limits).

    As "actual" counts a seed without an estimate as not reaching the target, the
    median counts a seed planned only at a bound as not predicted short (inf).  "Pinned"
    says the target is met by the early length: where the actual length is no longer,
    that is exact (counted as ``t_act``).
    """
    got = [pl.get((p, target), (math.inf, 'beyond')) for pl in plans]
    times = [math.inf if kind == 'at_least' else
             t_act if kind == 'met' and t_act <= t else t for t, kind in got]
    limits = [t for t, kind in got if kind == 'at_least']
    return (float(np.median(times)), len(got) - len(limits),
            sum(t <= 1.5 * t_act for t in limits), len(limits))


def run_model(name: str, noise: AxisNoise, rate_hz: float, unit: str, seeds: int,
              lengths_h: np.ndarray, early_h: float) -> list:
    """Rows (model, param, target, predicted true, early summary, actual) of one model."""
    lengths_s = lengths_h * 3600.0
    actual = {p: np.full((seeds, lengths_h.size), math.inf) for p in PARAMS}
    covered = {p: np.full((seeds, lengths_h.size), math.nan) for p in PARAMS}
    early: list = []
    for seed in range(seeds):
        rng = np.random.default_rng(1000 + seed)
        y = simulate_axis(noise, rate_hz, int(round(lengths_s[-1] * rate_hz)), rng)
        for i, length in enumerate(lengths_s):
            _, w, cov = fit_widths(y[:int(round(length * rate_hz))], rate_hz, unit, noise)
            for p in PARAMS:
                actual[p][seed, i] = w[p]
                covered[p][seed, i] = cov[p]
        n_early = int(round(early_h * 3600.0 * rate_hz))
        fit, _, _ = fit_widths(y[:n_early], rate_hz, unit)
        early.append(early_plans(fit, rate_hz, n_early / rate_hz))
        print(f'{name} seed {seed} done', file=sys.stderr)
    comps, bounds = planning_model(noise_components(noise))
    true_cols = width_columns(comps, bounds, rate_hz, lengths_s)
    rows = []
    # How often the estimates' 95 % intervals hold the truth, per length (over the seeds
    # with an estimate): an "actual" width reached early by over-confident intervals is
    # no fault of the planner.
    for p in PARAMS:
        n_est = np.sum(~np.isnan(covered[p]), axis=0)
        share = np.nansum(covered[p], axis=0) / np.maximum(n_est, 1)
        print(f'{name} {p} coverage by length [h]: ' + ', '.join(
            f'{h:.2g}: {s:.2f} ({n})' for h, s, n in zip(lengths_h, share, n_est) if n),
            file=sys.stderr)
    for p in PARAMS:
        med = np.median(actual[p], axis=0)
        for target in TARGETS:
            t_act = crossing(lengths_s, med, target)
            # Only targets reached inside the simulated lengths (not at the first one).
            if not (lengths_s[0] < t_act < lengths_s[-1]):
                continue
            t_true = crossing(lengths_s, true_cols[p], target)
            rows.append((name, p, target, t_true, early_summary(early, p, target, t_act),
                         t_act))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--seeds', type=int, default=6)
    ap.add_argument('--hours', type=float, default=32.0)
    ap.add_argument('--early-hours', type=float, default=1.0)
    ap.add_argument('--models', default=','.join(models()))
    ap.add_argument('--quick', action='store_true', help='3 seeds, 4 h, two models')
    args = ap.parse_args()
    if args.quick:
        args.seeds, args.hours, args.models = 3, 4.0, 'xsens_gyro,ublox_gyro'
    lengths_h = np.geomspace(args.hours / 256.0, args.hours, 17)
    t0 = time.time()
    rows = []
    for name in args.models.split(','):
        noise, rate, unit = models()[name]
        rows += run_model(name, noise, rate, unit, args.seeds, lengths_h, args.early_hours)
    early = f'{args.early_hours:g} h fit'
    print(f'| model | param | target | predicted (true model) | predicted ({early}, seeds) '
          f'| lower limits ({early}) that hold | actual | ratio true | ratio fit |')
    print('|---|---|---|---|---|---|---|---|---|')
    inside = {'true': 0, 'fit': 0, 'fit rows': 0, 'limit rows': 0, 'limits held': 0}
    for name, p, target, t_true, (t_early, n_points, held, n_limits), t_act in rows:
        r_true, r_early = t_true / t_act, t_early / t_act
        inside['true'] += 1 / 1.5 <= r_true <= 1.5
        # A row is the planner's point prediction where most seeds give one, else its
        # lower limits, which hold when at most 1.5x the actual length.
        if n_points > n_limits:
            inside['fit rows'] += 1
            inside['fit'] += 1 / 1.5 <= r_early <= 1.5
        else:
            inside['limit rows'] += 1
            inside['limits held'] += held == n_limits
        limits = f'{held} of {n_limits}' if n_limits else '-'
        print(f'| {name} | {p} | +-{100 * target:g} % | {t_true / 3600:.3g} h | '
              f'{t_early / 3600:.3g} h ({n_points}) | {limits} | {t_act / 3600:.3g} h | '
              f'{r_true:.2f} | {r_early:.2f} |')
    print(f'\nwithin 1.5x: true model {inside["true"]} of {len(rows)} rows; {early} '
          f'{inside["fit"]} of {inside["fit rows"]} rows of point predictions; rows of lower '
          f'limits that all hold: {inside["limits held"]} of {inside["limit rows"]}; '
          f'{args.seeds} seeds, {args.hours:g} h; {time.time() - t0:.0f} s', file=sys.stderr)


if __name__ == '__main__':
    main()
