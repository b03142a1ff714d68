"""
No confident wrong number, over sizes: filtered and decimated sensors (issue 25).

Usage: ``.venv/bin/python bench/trust_power.py [--seeds 5] [--hours 0.5,2,6]
[--rate 10]``.  White noise, a Gauss-Markov process and a random walk (N 9.2e-4, B 3e-4
at T_B 50 s, K 1e-5) at ten times ``--rate``, low-passed as drivers do (forward-backward
Butterworth, one-pole; the cut-offs in the table are those of a 10 Hz output, scaled
with the rate) and decimated by 10.  Per case and size it counts the axes whose N is within 10 % of
the truth as a trusted estimate ("ok"), the axes marked not trusted whose conservative
N covers the truth within 10 % or bounds it from above ("warned"), and the confident
wrong numbers ("wrong": trusted, N off by more than 10 %).  Clean axes at the output
rate without a filter give the false alarms (marked not trusted).
"""

import argparse

import numpy as np

from imu_allan.core.allan import allan_curve
from imu_allan.core.diagnose.drivers import driver_filtered
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.values import AxisNoise, NoiseSpec
from imu_allan.core.search import search_axis

TRUTH = AxisNoise(N=9.2e-4, B=3e-4, T_B=50.0, K=1e-5)
CASES = (('none', 0.0), ('filtfilt', 4.0), ('filtfilt', 0.5), ('one_pole', 2.0),
         ('one_pole', 0.05))


def one(kind: str, cutoff_hz: float, hours: float, seed: int, rate_hz: float = 10.0) -> str:
    """Return 'ok', 'warned', 'wrong' (or 'false_alarm' on an unfiltered axis)."""
    spec = NoiseSpec(name='t', axes={'gyro_x': TRUTH})
    if kind == 'none':
        _, y = simulate_imu(spec, rate_hz, hours * 3600.0, seed=seed)
        y, rate = y[:, 0], rate_hz
    else:
        _, y = simulate_imu(spec, 10.0 * rate_hz, hours * 3600.0, seed=seed)
        y, rate = driver_filtered(y[:, 0], 10.0 * rate_hz, kind, cutoff_hz * rate_hz / 10.0,
                                  10)
    taus = 2.0 ** (np.arange(0, 40) / 2.0) / rate
    taus = taus[taus <= y.size / rate / 4.0]
    curve = allan_curve(y, rate, taus, confidence=0.95)
    fit = search_axis(curve.tau_s, curve.avar[:, 0], curve.edf[:, 0], rate, y.size, raw=y,
                      unit='rad/s').fit
    n = fit.optimised['N']
    close = n.kind == 'estimate' and abs(n.value / TRUTH.N - 1.0) <= 0.10
    if fit.trusted:
        return 'ok' if close else 'wrong'
    if kind == 'none':
        return 'false_alarm'
    return 'warned' if close or (n.kind == 'upper_bound' and n.value >= TRUTH.N) else 'wrong'


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--seeds', type=int, default=5)
    ap.add_argument('--hours', default='0.5,2,6')
    ap.add_argument('--rate', type=float, default=10.0, help='output rate [Hz]')
    args = ap.parse_args()
    print(f'output rate {args.rate:g} Hz (cut-offs of a 10 Hz output, scaled)')
    print('| filter | cut-off [Hz] | hours | ok | warned | wrong | false alarm |')
    print('|---|---|---|---|---|---|---|')
    for kind, cutoff in CASES:
        for hours in [float(h) for h in args.hours.split(',')]:
            got = [one(kind, cutoff, hours, 100 + s, args.rate) for s in range(args.seeds)]
            print(f'| {kind} | {cutoff:g} | {hours:g} | {got.count("ok")} | '
                  f'{got.count("warned")} | {got.count("wrong")} | '
                  f'{got.count("false_alarm")} |', flush=True)


if __name__ == '__main__':
    main()
