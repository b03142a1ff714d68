"""
The warm-up hold: false alarms, power, and the issue's ADIS16405 case.

Usage (each prints a markdown table, docs/input_gate.md quotes them)::

    .venv/bin/python bench/settle_power.py --false-alarms 60
    .venv/bin/python bench/settle_power.py --power 10
    .venv/bin/python bench/settle_power.py --adis ../shared/realdata/adis16405

``--false-alarms SEEDS``: seeded 30 min windows (what the hold judges) of six axes of
white, Gauss-Markov and random-walk noise at 10, 100 and 400 Hz, each axis drawn at
random (N log-uniform in 1e-4..1e-2, B 0.01..0.3 of N, T_B 10..1000 s, K 0.001..0.1 of
B: random walk dominant from 2 min to 300 h); the windows with a cut, and the largest
amplitude in wanders (``|a| / wander``, the statistic the threshold
:data:`~imu_allan.core.rules.SETTLE_SCORE` judges) of any axis.

``--power SEEDS``: one axis (N 2e-3, B 2e-4 with T_B 200 s, K 2e-6 at 100 Hz) with an
exponential transient of amplitude k times the axis' Allan deviation at its time
constant and time constant tau: the windows where it is found, and the median time
left out over the time it takes the transient to fall to that Allan deviation.

``--adis DIR``: ADIS16405 run 6 (2.78 h, 100 Hz), clean and with the issue's transient
(+0.1 deg/s on the gyros, +20 mg on the accelerometers, exp(-t / 200 s)), analysed as
``imu-allan analyze`` does, without the hold (``--warmup-window 0``) and with it: per
sensor and parameter (N, B, K of three axes), ``a/3`` axes whose reported value lies in
the clean run's 95 % interval (a bound: at most the clean bound, or covering the clean
estimate), the median ratio to the clean value, and the warnings.
"""

import argparse
import math
from pathlib import Path
import tempfile

import numpy as np

from imu_allan import AXES
import imu_allan.core.allan.settling as settling
from imu_allan.core.allan.settling import find_settling
from imu_allan.core.noise.model import adev_model
from imu_allan.core.noise.simulate import simulate_axis
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.rules import SETTLE_SCORE

WINDOW_S = 1800.0


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(math.log(lo), math.log(hi))))


def false_alarms(seeds: int) -> None:
    """Print the windows cut, and the largest score, per rate."""
    print('| rate | windows | cut | largest score | 90 % of the largest |')
    print('|---|---|---|---|---|')
    for rate_hz in (10.0, 100.0, 400.0):
        n = int(WINDOW_S * rate_hz)
        cut, worst = 0, []
        for seed in range(seeds):
            rng = np.random.default_rng(seed)
            y = np.empty((n, 6))
            for j in range(6):
                big_n = _log_uniform(rng, 1e-4, 1e-2)
                b = big_n * _log_uniform(rng, 0.01, 0.3)
                noise = AxisNoise(N=big_n, B=b, T_B=_log_uniform(rng, 10, 1000),
                                  K=b * _log_uniform(rng, 1e-3, 1e-1))
                y[:, j] = simulate_axis(noise, rate_hz, n, rng)
            cut += find_settling(y, rate_hz).cut_rows > 0
            worst.append(_largest_score(y, rate_hz))
        print(f'| {rate_hz:g} Hz | {seeds} | {cut} | {max(worst):.1f} | '
              f'{np.quantile(worst, 0.9):.1f} |')


def _largest_score(y: np.ndarray, rate_hz: float) -> float:
    """Return the largest amplitude in wanders of any axis, the threshold set to 0."""
    kept = settling.SETTLE_SCORE
    settling.SETTLE_SCORE = 0.0
    try:
        found = find_settling(y, rate_hz)
    finally:
        settling.SETTLE_SCORE = kept
    return max(t.score for t in found.transients if t.start_s == 0)


POWER_NOISE = AxisNoise(N=2e-3, B=2e-4, T_B=200.0, K=2e-6)


def power(seeds: int) -> None:
    """Print found / seeds and the median left-out time over the true one per case."""
    rate_hz = 100.0
    n = int(WINDOW_S * rate_hz)
    t_s = np.arange(n) / rate_hz
    sizes = (10, 20, 40, 80, 160)
    print('| tau | ' + ' | '.join(f'{k} ADEV' for k in sizes) + ' |')
    print('|---|' + '---|' * len(sizes))
    for tau_s in (30.0, 100.0, 300.0):
        adev = float(adev_model(np.array([tau_s]), POWER_NOISE)[0])
        cells = []
        for k in sizes:
            found, ratio = 0, []
            for seed in range(seeds):
                rng = np.random.default_rng(seed)
                y = simulate_axis(POWER_NOISE, rate_hz, n, rng)
                y += k * adev * np.exp(-t_s / tau_s)
                got = find_settling(y[:, None], rate_hz)
                if got.cut_rows:
                    found += 1
                    ratio.append(got.cut_s / (tau_s * math.log(k)))
            cells.append(f'{found}/{seeds}' + (f', x{np.median(ratio):.2f}' if ratio else ''))
        print(f'| {tau_s:g} s | ' + ' | '.join(cells) + ' |')
    print(f'\n(threshold {SETTLE_SCORE:g} wanders; ADEV at 30, 100, 300 s: '
          + ', '.join(f'{v:.3g}' for v in adev_model(np.array([30.0, 100.0, 300.0]),
                                                     POWER_NOISE)) + ')')


def adis(folder: Path) -> None:
    """Print the issue's case: run 6 clean, and with the transient without and with the hold."""
    from imu_allan.io.csv_io import read_csv, write_csv
    from imu_allan.io.inputs import analyze_input
    from imu_allan.pipeline.hygiene import SessionConfig
    d = read_csv(folder / 'adis16405_run6.csv.gz')
    warm = d.samples.copy()
    shape = np.exp(-(d.t_s - d.t_s[0]) / 200.0)[:, None]
    warm[:, :3] += math.radians(0.1) * shape
    warm[:, 3:] += 0.02 * 9.80665 * shape
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'warm.csv'
        write_csv(path, d.t_s, warm, AXES)
        clean = analyze_input(folder / 'adis16405_run6.csv.gz', None, SessionConfig(),
                              quiet=True, workers=2)[0]
        runs = {'transient, no hold': analyze_input(path, None,
                                                    SessionConfig(warmup_window_s=0),
                                                    quiet=True, workers=2)[0],
                'transient, hold': analyze_input(path, None, SessionConfig(), quiet=True,
                                                 workers=2)[0]}
    names = [f'{s} {p}' for s in ('gyro', 'accel') for p in ('N', 'B', 'K')]
    print('| case | ' + ' | '.join(names) + ' |')
    print('|---|' + '---|' * 6)
    print(f'| clean (left out: {clean.hygiene["warmup_s"]:g} s) |' + ' |' * 6)
    for name, result in runs.items():
        print(f'| {name} | ' + ' | '.join(_cells(result, clean)) + ' |')
    for name, result in runs.items():
        print(f'\n{name}: left out {result.hygiene["warmup_s"]:g} s; warnings:')
        for w in result.warnings:
            print(f'- {w}')


def _cells(result, clean) -> list:
    """Return per sensor and parameter: axes within the clean interval, median ratio."""
    cells = []
    for sensor in ('gyro', 'accel'):
        axes = [a for a in AXES if a.startswith(sensor)]
        for sym in ('N', 'B', 'K'):
            inside, ratio = 0, []
            for a in axes:
                got = result.reports[a].params.get(sym)
                ref = clean.reports[a].params.get(sym)
                if got is None or ref is None:
                    continue
                if ref.kind == 'estimate':
                    inside += int(ref.ci95[0] <= got.value <= ref.ci95[1]
                                  or (got.kind == 'upper_bound' and got.value >= ref.value))
                else:
                    inside += int(got.value <= ref.value or got.ci95[0] <= ref.value)
                if ref.value > 0:
                    ratio.append(got.value / ref.value)
            cells.append(f'{inside}/3 x{np.median(ratio):.2f}' if ratio else '-')
    return cells


def main() -> None:
    """Run the parts asked for."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    p.add_argument('--false-alarms', type=int, default=0, metavar='SEEDS')
    p.add_argument('--power', type=int, default=0, metavar='SEEDS')
    p.add_argument('--adis', type=Path, metavar='DIR')
    args = p.parse_args()
    if args.false_alarms:
        false_alarms(args.false_alarms)
    if args.power:
        power(args.power)
    if args.adis:
        adis(args.adis)


if __name__ == '__main__':
    main()
