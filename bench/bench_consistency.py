"""
Consistency of a random-walk bias filter with the fitted, the covering and the 10x pair.

Usage: ``.venv/bin/python bench/bench_consistency.py [--hours 3] [--figure PATH]``.

Two held-out static records, each filtered by the consumers' model (white noise N plus a
bias random walk K, :func:`imu_allan.core.outputs.consistency.random_walk_filter`):

* simulated: a full model with bias instability (Gauss-Markov on the gyros, flicker on
  the accelerometers) and a random walk; a training record of ``--hours`` is fitted
  by ``imu-allan analyze``'s pipeline, a second record with another seed is filtered,
  its true bias known (NEES);
* real: ADIS16405 run 1 is fitted, run 2 filtered (skipped without ../shared).

Each record is filtered with (a) the fitted N, K (K at its 95 % bound where only a
bound), (b) the covering pair over [sample period, 100 s], (c) the folk answer, 10 x
both.  For a horizon h the filter sees block means of h seconds; its NIS scores the
prediction of the angle (velocity) the sensor integrates over the next h seconds.
The table gives the mean NIS per sensor (mean of the three axes) at h = 1, 10, 30 and
100 s, the 95 % chi-square interval of a consistent filter, and for the simulated case
the mean NEES of the bias at h = 1 s.

``--horizons`` prints the second table of docs/outputs.md instead: the covering pair
made over [sample period, H] for H = 1, 10, 30, 100 and 1000 s (``--cover-tau-max``),
fitted on ADIS16405 run 1 and filtered on each of runs 2-6 (held out), scored at
h = 1, 10, 100 s and at h = 900 s (a 15 min outage between fixes): the mean NIS pooled
over the five held-out runs and the three axes of each sensor, with the upper end of
its 95 % chi-square interval.
"""

import argparse
from pathlib import Path
import sys
import tempfile

import numpy as np
from scipy.stats import chi2

from imu_allan import ACCEL_AXES, AXES, GYRO_AXES
from imu_allan.core.noise.generators import white_noise
from imu_allan.core.noise.simulate import simulate_axis, simulate_imu
from imu_allan.core.noise.values import AxisNoise, NoiseSpec
from imu_allan.core.outputs.consistency import random_walk_filter
from imu_allan.io.csv_io import read_csv
from imu_allan.io.inputs import analyze_input
from imu_allan.pipeline.hygiene import SessionConfig

DATA = Path(__file__).resolve().parents[2] / 'shared' / 'realdata' / 'adis16405'
HORIZONS_S = (1.0, 10.0, 30.0, 100.0)
RATE_HZ = 100.0
BURN_IN_S = 600.0
#: ADIS16405-like model (values of the same order as the fit of run 1).
GYRO = AxisNoise(N=7.5e-4, B=1.7e-4, T_B=40.0, K=1.4e-5)
ACCEL = AxisNoise(N=4.4e-3, B=4.1e-3, K=1.2e-4)


def _pairs(result) -> dict:
    """Per axis: {'fitted': (N, K), 'covering': (N_c, K_c), 'folk 10x': (10 N, 10 K)}."""
    out = {}
    for a in AXES:
        c = result.covers[a]
        out[a] = {'fitted': (c.N_fit, c.K_fit), 'covering': (c.N_cover, c.K_cover),
                  'folk 10x': (10 * c.N_fit, 10 * c.K_fit)}
    return out


def _fit(t_s: np.ndarray, y: np.ndarray):
    """Fit a record the way ``imu-allan analyze`` does (through a CSV file)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'train.csv'
        np.savetxt(path, np.column_stack([t_s, y]), delimiter=',', fmt='%.10g',
                   header='t,' + ','.join(AXES), comments='')
        result, _ = analyze_input(path, None, SessionConfig(), quiet=True, progress=False)
    return result


def _simulated(hours: float, seed: int) -> tuple:
    """Simulate a held-out record: samples (n, 6) and the true bias (n, 6)."""
    n = int(round(hours * 3600 * RATE_HZ))
    rng = np.random.default_rng(seed)
    bias = np.empty((n, 6))
    y = np.empty((n, 6))
    for j, a in enumerate(AXES):
        m = GYRO if a in GYRO_AXES else ACCEL
        bias[:, j] = simulate_axis(AxisNoise(B=m.B, T_B=m.T_B, K=m.K), RATE_HZ, n, rng)
        y[:, j] = bias[:, j] + white_noise(m.N, RATE_HZ, n, rng)
    return y, bias


def score(y: np.ndarray, pairs: dict, truth: np.ndarray | None = None) -> dict:
    """Mean NIS (and NEES at 1 s) per (sensor, pair, horizon), averaged over the axes."""
    rows = {}
    for sensor, axes in (('gyro', GYRO_AXES), ('accel', ACCEL_AXES)):
        for name in ('fitted', 'covering', 'folk 10x'):
            nis, bounds, nees = [], [], []
            for h in HORIZONS_S:
                runs = [random_walk_filter(y[:, AXES.index(a)], RATE_HZ, *pairs[a][name],
                                           block_s=h, burn_in_s=BURN_IN_S,
                                           truth=None if truth is None
                                           else truth[:, AXES.index(a)]) for a in axes]
                nis.append(float(np.mean([r.mean_nis for r in runs])))
                bounds.append(runs[0].bounds)
                if truth is not None and h == HORIZONS_S[0]:
                    nees.append(float(np.mean([r.mean_nees for r in runs])))
            rows[(sensor, name)] = {'nis': nis, 'bounds': bounds,
                                    'nees': nees[0] if nees else None}
    return rows


def _table(case: str, rows: dict, pairs: dict) -> list:
    lines = []
    for (sensor, name), row in rows.items():
        axes = GYRO_AXES if sensor == 'gyro' else ACCEL_AXES
        n_k = [pairs[a][name] for a in axes]
        nk = (f'{max(p[0] for p in n_k):.2e} / {max(p[1] for p in n_k):.2e}')
        cells = []
        for m, (lo, hi) in zip(row['nis'], row['bounds']):
            mark = ' over' if m > hi else (' cons' if m < lo else '')
            cells.append(f'{m:.2f}{mark}')
        nees = '' if row['nees'] is None else f'{row["nees"]:.2f}'
        lines.append(f'| {case} | {sensor} | {name} | {nk} | ' + ' | '.join(cells)
                     + f' | {nees} |')
    return lines


def _bounds_line(rows: dict) -> str:
    row = next(iter(rows.values()))
    cells = [f'{lo:.2f}-{hi:.2f}' for lo, hi in row['bounds']]
    return '| | | 95 % interval | | ' + ' | '.join(cells) + ' | |'


def _figure(results: list, path: Path) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(results), figsize=(5 * len(results), 3.6), squeeze=False)
    for ax, (case, rows) in zip(axes[0], results):
        for name, style in (('fitted', 'o-'), ('covering', 's-'), ('folk 10x', '^-')):
            ax.loglog(HORIZONS_S, rows[('gyro', name)]['nis'], style, label=name)
        lo = [b[0] for b in rows[('gyro', 'fitted')]['bounds']]
        hi = [b[1] for b in rows[('gyro', 'fitted')]['bounds']]
        ax.fill_between(HORIZONS_S, lo, hi, color='0.85', label='95 % interval')
        ax.set_title(f'{case}: gyros, mean NIS')
        ax.set_xlabel('horizon h [s]')
        ax.grid(True, which='both', alpha=0.3)
    axes[0][0].set_ylabel('mean NIS [-] (1 = consistent)')
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


COVER_TAU_MAX_S = (1.0, 10.0, 30.0, 100.0, 1000.0)
OUTAGE_HORIZONS_S = (1.0, 10.0, 100.0, 900.0)


def horizons() -> int:
    """Print the covering pair's horizon against the NIS on held-out ADIS runs (outputs.md)."""
    from dataclasses import replace
    if not (DATA / 'adis16405_run1.csv.gz').is_file():
        print('(real data absent: ../shared/realdata/adis16405)', file=sys.stderr)
        return 2
    result, _ = analyze_input(DATA / 'adis16405_run1.csv.gz', None, SessionConfig(),
                              quiet=True, progress=False)
    held = [np.asarray(read_csv(DATA / f'adis16405_run{i}.csv.gz').samples, dtype=np.float64)
            for i in range(2, 7)]
    print('| cover tau_max | sensor | N_c / N | K_c / K | '
          + ' | '.join(f'NIS h={h:g} s' for h in OUTAGE_HORIZONS_S) + ' |')
    print('|' + ' --- |' * (4 + len(OUTAGE_HORIZONS_S)))
    for tau_max in COVER_TAU_MAX_S:
        covers = replace(result, covering_tau_max_s=tau_max).covers
        for sensor, axes in (('gyro', GYRO_AXES), ('accel', ACCEL_AXES)):
            cells = []
            for h in OUTAGE_HORIZONS_S:
                # Pooled over the held-out runs and the sensor's axes; a long horizon
                # leaves few blocks per run, so the burn-in is one block at most.
                runs = [random_walk_filter(y[:, AXES.index(a)], RATE_HZ, covers[a].N_cover,
                                           covers[a].K_cover, block_s=h,
                                           burn_in_s=min(BURN_IN_S, h) if h < 600 else 0.0)
                        for y in held for a in axes]
                m = sum(r.n_steps for r in runs)
                pooled = sum(r.mean_nis * r.n_steps for r in runs) / m
                hi = float(chi2.ppf(0.975, m) / m)
                cells.append(f'{pooled:.2f}{" over" if pooled > hi else ""} ({hi:.2f})')
            f_n = max(covers[a].factor_N or 0.0 for a in axes)
            f_k = max(covers[a].factor_K or 0.0 for a in axes)
            print(f'| {tau_max:g} s | {sensor} | {f_n:.3g} | {f_k:.3g} | '
                  + ' | '.join(cells) + ' |', flush=True)
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--hours', type=float, default=3.0, help='length of each simulated record')
    p.add_argument('--figure', type=Path, help='write the NIS-versus-horizon figure here')
    p.add_argument('--horizons', action='store_true',
                   help='the horizon table on the held-out ADIS runs instead')
    args = p.parse_args(argv)
    if args.horizons:
        return horizons()
    head = ('| case | sensor | pair | N / K (worst axis) | ' +
            ' | '.join(f'NIS h={h:g} s' for h in HORIZONS_S) + ' | NEES h=1 s |')
    print(head)
    print('|' + ' --- |' * (5 + len(HORIZONS_S)))
    results = []
    models = {a: (GYRO if a in GYRO_AXES else ACCEL) for a in AXES}
    spec = NoiseSpec(name='ADIS-like', axes=models)
    t_s, train = simulate_imu(spec, RATE_HZ, args.hours * 3600, seed=1)
    pairs = _pairs(_fit(t_s, train))
    y, truth = _simulated(args.hours, seed=2)
    rows = score(y, pairs, truth)
    results.append(('simulated', rows))
    print('\n'.join(_table('simulated', rows, pairs)))
    print(_bounds_line(rows))
    if (DATA / 'adis16405_run1.csv.gz').is_file():
        result, _ = analyze_input(DATA / 'adis16405_run1.csv.gz', None, SessionConfig(),
                                  quiet=True, progress=False)
        pairs = _pairs(result)
        held = np.asarray(read_csv(DATA / 'adis16405_run2.csv.gz').samples, dtype=np.float64)
        rows = score(held, pairs)
        results.append(('ADIS16405 run 1 -> run 2', rows))
        print('\n'.join(_table('ADIS run1->run2', rows, pairs)))
        print(_bounds_line(rows))
    else:
        print('(real data absent: ../shared/realdata/adis16405)', file=sys.stderr)
    if args.figure:
        _figure(results, args.figure)
    return 0


if __name__ == '__main__':
    sys.exit(main())
