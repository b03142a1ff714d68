"""
Coverage, power and size of the thermal coefficient's interval on simulated records.

Each record is one gyro axis of ADIS16405-like noise (white N = 7e-4 rad/s/sqrt(Hz),
random walk K = 1.5e-5 rad/s/sqrt(s)) plus c (T - 25), the temperature T either a
40-minute cycle of +-5 degC or a warming from 5 to 16 degC over the record.  The
coefficient is regressed as the analysis regresses it
(:func:`imu_allan.core.search.thermal.thermal_regression`: 512 block means, the random
walk's level re-fitted, the profile-likelihood interval) with the true noise terms as
the model (the analysis uses the fitted, uncompensated ones: a model that took the
drift for noise only widens the interval).  For each rate, length, temperature and c
the table gives the share of records whose 95 % interval holds the true c (coverage)
and the share called significant (power; at c = 0 it is the size, the false alarms).

Run: ``OPENBLAS_NUM_THREADS=1 python bench/thermal_power.py [--reps 30]``
(docs/thermal.md holds its table).
"""

import argparse
import time

import numpy as np

from imu_allan.core.search.thermal import thermal_regression

WHITE = 7e-4
WALK = 1.5e-5


def simulate(rng, rate_hz: float, hours: float, c: float, kind: str) -> tuple:
    """Return (y (n,), temp_c (n,)) of one record."""
    n = int(hours * 3600 * rate_hz)
    dt = 1.0 / rate_hz
    t_s = np.arange(n) * dt
    if kind == 'cycle':
        temp = 25.0 + 5.0 * np.sin(2 * np.pi * t_s / 2400.0 + rng.uniform(0, 2 * np.pi))
    else:
        temp = 5.0 + 11.0 * t_s / t_s[-1]
    temp = np.round(temp / 0.05) * 0.05          # a temperature sensor's resolution
    y = (rng.standard_normal(n) * (WHITE / np.sqrt(dt))
         + np.cumsum(rng.standard_normal(n) * (WALK * np.sqrt(dt))) + c * (temp - 25.0))
    return y, temp


def main() -> None:
    """Print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--reps', type=int, default=30)
    args = ap.parse_args()
    terms = [('white', WHITE ** 2, ()), ('random_walk', WALK ** 2, ())]
    print('| rate Hz | length h | temperature | c rad/s/degC | coverage | significant | '
          'median 95 % half-width |')
    print('| --- | --- | --- | --- | --- | --- | --- |')
    start = time.time()
    for rate_hz, lengths in ((10.0, (0.5, 2.0, 8.0)), (100.0, (2.0,)), (400.0, (2.0,))):
        for hours in lengths:
            for kind in ('cycle', 'warming'):
                for c in (0.0, 1e-5, 1e-4):
                    rng = np.random.default_rng(int(rate_hz * 1000 + hours * 10))
                    inside = sig = 0
                    halves = []
                    for _ in range(args.reps):
                        y, temp = simulate(rng, rate_hz, hours, c, kind)
                        r = thermal_regression(y, temp, rate_hz, terms)
                        inside += r.ci95[0] <= c <= r.ci95[1]
                        sig += r.significant
                        halves.append((r.ci95[1] - r.ci95[0]) / 2)
                    print(f'| {rate_hz:g} | {hours:g} | {kind} | {c:g} | '
                          f'{inside / args.reps:.2f} | {sig / args.reps:.2f} | '
                          f'{np.median(halves):.2g} |', flush=True)
    print(f'\n{args.reps} records per row, {time.time() - start:.0f} s')


if __name__ == '__main__':
    main()
