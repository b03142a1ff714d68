"""
Benchmark of imu_allan.core.fit: fit_curve on the six axes of a simulated record.

A record of config/xsens_mti7.yaml (default 3 h at 100 Hz, six axes) is simulated once;
its Allan curve is computed two ways, the streaming accumulator's dense curve (what the
node and the offline reader fit, 10 taus per decade) and the batch octave curve, and
fit_curve is timed on each axis of each.  Printed: seconds per axis and in total, and
N, B, T_B, K of gyro_x against the truth, so a speed-up that loses accuracy shows.

Usage: ``.venv/bin/python bench/bench_fit.py [--hours H] [--rate HZ] [--repeat R]``
(``--repeat`` fits each curve R times and reports the fastest run.)
"""

import argparse
from pathlib import Path
import time

import numpy as np

from imu_allan import AXES
from imu_allan.core.allan import allan_curve
from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.core.fit import fit_curve
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'xsens_mti7.yaml'


def _fit_all(curve, n_samples: int) -> tuple[list, list]:
    """Fit every axis; return (seconds per axis, fits)."""
    seconds, fits = [], []
    for i in range(len(AXES)):
        t0 = time.perf_counter()
        fits.append(fit_curve(curve, i, n_samples))
        seconds.append(time.perf_counter() - t0)
    return seconds, fits


def main() -> None:
    """Simulate, build both curves, time the fits and print one line per curve."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--hours', type=float, default=3.0)
    parser.add_argument('--rate', type=float, default=100.0)
    parser.add_argument('--repeat', type=int, default=1)
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args()
    spec = load_params(CONFIG)
    _, samples = simulate_imu(spec, args.rate, args.hours * 3600.0, args.seed)
    n = samples.shape[0]
    acc = AllanAccumulator(len(AXES), args.rate)
    acc.add(samples)
    curves = (('accumulator (dense)', acc.curve()),
              ('batch octave', allan_curve(samples, args.rate, 'octave')))
    truth = spec.axes['gyro_x']
    print(f'{args.hours:g} h at {args.rate:g} Hz, {n} x 6 samples; fit_curve per axis '
          f'(fastest of {args.repeat})')
    for label, curve in curves:
        best = None
        for _ in range(max(args.repeat, 1)):
            seconds, fits = _fit_all(curve, n)
            if best is None or sum(seconds) < sum(best[0]):
                best = (seconds, fits)
        seconds, fits = best
        p = fits[0].optimised
        print(f'{label:20s} {curve.tau_s.size:3d} taus: {sum(seconds):6.2f} s total, '
              f'{np.mean(seconds):5.2f} s/axis (max {max(seconds):5.2f} s)')
        print(' ' * 21 + 'gyro_x ' + ', '.join(
            f'{s} {p[s].value:.3g} [{p[s].ci95[0]:.3g}, {p[s].ci95[1]:.3g}] '
            f'(true {getattr(truth, s):.3g})' for s in ('N', 'B', 'T_B', 'K')))


if __name__ == '__main__':
    main()
