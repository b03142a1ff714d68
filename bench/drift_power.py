"""
False alarms and power of the slow-drift test on simulated records.

Each record is one gyro axis of ADIS16405-like noise (white N = 7e-4 rad/s/sqrt(Hz),
Gauss-Markov B = 1.5e-4 rad/s with T_B = 100 s, random walk K) plus, for the power rows,
a drift of amplitude A: a 40-minute ``cycle`` A sin(2 pi t / 2400 s), a ``warming``
ramp A t / T over the record, or an ``exponential`` warming A (1 - exp(-4 t / T)).
The test runs as the analysis runs it
(:func:`imu_allan.core.search.drift.drift_test`: 512 block means, m = 4 and 12 smooth
cosines, 400 bootstrap draws, alpha 0.01) with the true noise terms as the model (the
analysis uses the fitted ones) and K re-fitted.  The table gives the share of records
named a drift: with a true random walk and no drift it is the false-alarm rate (the
size), with a drift the power.

Run: ``OPENBLAS_NUM_THREADS=1 python bench/drift_power.py [--reps 100]``
(docs/thermal.md holds its table).  ``--real adis1,adis6+issue,...`` instead analyses
real records as ``imu-allan analyze --no-plan`` does (``../shared/realdata`` beside the
repository; ``+issue``: issue 35's 40-minute cycle, ``+deg2``: ``degrade.thermal_no_temp``
at 2 degC, ``+ramp5`` / ``+exp5``: a linear / exponential warming of 11 degC at 5 times
issue 35's coefficients; any temperature column left out) and prints, per axis, K as
reported and the drift test's p-value on the axis' samples with its fitted terms.
"""

import argparse
import math
from pathlib import Path
import sys
import time

import numpy as np

# This checkout's package first (the venv's editable install may point at another).
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from imu_allan.core.noise.generators import gauss_markov_noise  # noqa: E402, I100
from imu_allan.core.noise.values import AxisNoise, GaussMarkov  # noqa: E402
from imu_allan.core.search.drift import drift_test  # noqa: E402
from imu_allan.core.search.thermal import model_terms  # noqa: E402

WHITE = 7e-4
GM_B, GM_T_S = 1.5e-4, 100.0
#: Random walk of the power rows [rad/s/sqrt(s)]: weak, as the ADIS16405 gyros' (a bound).
POWER_WALK = 2e-6

#: (rate [Hz], record lengths [h]) of the false-alarm rows.
SIZES = ((10.0, (0.5, 2.0, 8.0)), (100.0, (0.5, 1.0, 2.0)), (400.0, (0.25, 0.5, 1.0)))
#: Random-walk levels [rad/s/sqrt(s)] of the false-alarm rows: weak and strong.
WALKS = (2e-6, 1.5e-5)


def added_drift(kind: str, amp: float, t_s: np.ndarray) -> np.ndarray:
    """Return the drift (n,) [rad/s] of one kind and amplitude."""
    if kind == 'cycle':
        return amp * np.sin(2 * math.pi * t_s / 2400.0)
    if kind == 'warming':
        return amp * t_s / t_s[-1]
    return amp * (1.0 - np.exp(-4.0 * t_s / t_s[-1]))


def simulate(rng, rate_hz: float, n: int, walk: float) -> np.ndarray:
    """Return (n,) white + Gauss-Markov (the package's generator) + random walk [rad/s]."""
    dt = 1.0 / rate_hz
    gm = gauss_markov_noise(GaussMarkov(GM_B, GM_T_S), rate_hz, n, rng)
    return (rng.standard_normal(n) * (WHITE / math.sqrt(dt)) + gm
            + np.cumsum(rng.standard_normal(n) * (walk * math.sqrt(dt))))


def share(rng, rate_hz: float, hours: float, walk: float, kind: str, amp: float,
          reps: int) -> float:
    """Return the share of ``reps`` records named a drift."""
    noise = AxisNoise(N=WHITE, B=GM_B, T_B=GM_T_S, K=walk)
    terms = model_terms(noise)
    n = int(hours * 3600 * rate_hz)
    t_s = np.arange(n) / rate_hz
    named = 0
    for _ in range(reps):
        y = simulate(rng, rate_hz, n, walk)
        if amp:
            y = y + added_drift(kind, amp, t_s)
        check = drift_test(y, rate_hz, terms)
        named += bool(check is not None and check.named)
    return named / reps


def real_record(name: str):
    """Return the Record of a --real name (module docstring), without temperature."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import degrade
    import metamorphic

    base, _, kind = name.partition('+')
    rec = metamorphic.load(base)._replace(temp_c=None)
    if kind.startswith('deg'):
        return degrade.thermal_no_temp(rec, float(kind[3:]), np.random.default_rng(0))
    age = rec.t_s - rec.t_s[0]
    coef = np.r_[[1e-4] * 3, [2e-3] * 3]       # issue 35: rad/s/degC, m/s^2/degC
    if kind == 'issue':
        temp = 5.0 * np.sin(2 * math.pi * age / 2400.0)
    elif kind.startswith('ramp'):
        temp = float(kind[4:]) * 11.0 * age / age[-1]
    elif kind.startswith('exp'):
        temp = float(kind[3:]) * 11.0 * (1.0 - np.exp(-4.0 * age / age[-1]))
    else:
        return rec
    return rec._replace(samples=rec.samples + coef * temp[:, None])


def real(names: list) -> None:
    """Print K as reported and the drift test's p-value per axis of real records."""
    import tempfile

    from imu_allan import AXES
    from imu_allan.io.inputs import analyze_input
    from imu_allan.pipeline.hygiene import SessionConfig
    import metamorphic

    print('| record | axis | K as reported | drift p-value |')
    print('| --- | --- | --- | --- |')
    for name in names:
        rec = real_record(name)
        with tempfile.TemporaryDirectory(prefix='imu_drift_') as tmp:
            path = Path(tmp) / 'record.csv'
            metamorphic.write(rec, path)
            result, _ = analyze_input(path, None, SessionConfig(), quiet=True,
                                      progress=False, workers=1, prefetch=False, units=None)
        for j, axis in enumerate(AXES):
            fit = result.fits.get(axis)
            if fit is None:
                continue
            k = result.reports[axis].params['K']
            check = drift_test(rec.samples[:, j], result.rate_hz, model_terms(fit.model))
            p = 'n/a' if check is None else f'{check.p_value:.3g}'
            print(f'| {name} | {axis} | {k.value:.3g} {k.kind} | {p} |', flush=True)
        for w in result.warnings:
            if w.startswith('slow drift'):
                print(f'|  | {w.split(":")[0]} |  |  |')


def main() -> None:
    """Print the two tables (or, with --real, the real records' one)."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--reps', type=int, default=100)
    ap.add_argument('--power-reps', type=int, default=30)
    ap.add_argument('--real', default='', help='comma-separated real records')
    args = ap.parse_args()
    if args.real:
        real(args.real.split(','))
        return
    start = time.time()
    print('False alarms (a true random walk, no drift):\n')
    print('| rate Hz | length h | K rad/s/sqrt(s) | named a drift |')
    print('| --- | --- | --- | --- |')
    for rate_hz, lengths in SIZES:
        for hours in lengths:
            for walk in WALKS:
                rng = np.random.default_rng(int(rate_hz * 100 + hours * 10))
                got = share(rng, rate_hz, hours, walk, '', 0.0, args.reps)
                print(f'| {rate_hz:g} | {hours:g} | {walk:g} | {got:.2f} |', flush=True)
    print(f'\nPower (10 Hz, K = {POWER_WALK:g}, {args.power_reps} records a row):\n')
    print('| drift | length h | amplitude rad/s | named a drift |')
    print('| --- | --- | --- | --- |')
    for kind in ('cycle', 'warming', 'exponential'):
        for hours in (2.0, 8.0):
            for amp in (3e-4, 1e-3, 3e-3):
                rng = np.random.default_rng(int(hours * 10 + amp * 1e5))
                got = share(rng, 10.0, hours, POWER_WALK, kind, amp, args.power_reps)
                print(f'| {kind} | {hours:g} | {amp:g} | {got:.2f} |', flush=True)
    print(f'\n{time.time() - start:.0f} s')


if __name__ == '__main__':
    main()
