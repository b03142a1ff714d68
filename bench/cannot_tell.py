"""
Check "cannot tell" against simulation (issue 25 item 7).

Two questions: a ramp or more random walk, two Gauss-Markov processes or one.

Usage: ``.venv/bin/python bench/cannot_tell.py [--seeds 3]``.  A ramp (or a second
Gauss-Markov process) of a size from invisible to obvious is hidden in white noise, a
Gauss-Markov process and a random walk at 10 Hz.  Per size it counts the seeds where the
search names the effect, says "cannot tell" (with the record length it asks for) or
sees nothing; then it simulates records of the asked-for length (the median over the
"cannot tell" seeds) and counts how often the effect is named there.
"""

import argparse
import math
import re

import numpy as np

from imu_allan.core.allan import allan_curve
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.values import AxisNoise, GaussMarkov, NoiseSpec
from imu_allan.core.search import search_axis

RATE_HZ = 10.0
BASE = AxisNoise(N=1e-3, B=3e-4, T_B=30.0, K=2e-6)
_HOURS = re.compile(r'a record of about ([\d.e+]+) h would')


def outcome(effect: str, size: float, hours: float, seed: int) -> tuple[str, float]:
    """Return ('named' | 'cannot_tell' | 'none', hours asked for or nan)."""
    if effect == 'rate_ramp':
        noise = AxisNoise(N=BASE.N, B=BASE.B, T_B=BASE.T_B, K=BASE.K, R=size)
    else:
        noise = AxisNoise(N=BASE.N, B=BASE.B, T_B=BASE.T_B, K=BASE.K,
                          gauss_markov=(GaussMarkov(size, 1.0),))
    spec = NoiseSpec(name='t', axes={'gyro_x': noise})
    _, y = simulate_imu(spec, RATE_HZ, hours * 3600.0, seed=seed)
    y = y[:, 0]
    taus = 2.0 ** (np.arange(0, 40) / 2.0) / RATE_HZ
    taus = taus[taus <= y.size / RATE_HZ / 4.0]
    curve = allan_curve(y, RATE_HZ, taus, confidence=0.95)
    s = search_axis(curve.tau_s, curve.avar[:, 0], curve.edf[:, 0], RATE_HZ, y.size, raw=y,
                    unit='rad/s')
    if effect in [st.effect for st in s.steps]:
        return 'named', math.nan
    for note in s.fit.notes:
        if note.startswith(effect) and 'cannot tell' in note:
            return 'cannot_tell', float(_HOURS.search(note).group(1))
    return 'none', math.nan


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--hours', type=float, default=2.0)
    args = ap.parse_args()
    cases = [('rate_ramp', r) for r in (0.0, 2e-8, 5e-8, 1e-7, 3e-7)] + [
        ('gauss_markov', b) for b in (0.0, 3e-4, 6e-4, 1.2e-3, 3e-3)]
    print('| effect | size | hours | named | cannot tell | nothing | asked for [h] | '
          'named at that length |')
    print('|---|---|---|---|---|---|---|---|')
    for effect, size in cases:
        got = [outcome(effect, size, args.hours, 200 + s) for s in range(args.seeds)]
        asked = [h for k, h in got if k == 'cannot_tell']
        check = ''
        if asked:
            h = float(np.median(asked))
            if h <= 12.0:
                later = [outcome(effect, size, h, 300 + s)[0] for s in range(args.seeds)]
                check = f'{later.count("named")} of {len(later)}'
            else:
                check = 'not simulated (> 12 h)'
        kinds = [k for k, _ in got]
        print(f'| {effect} | {size:g} | {args.hours:g} | {kinds.count("named")} | '
              f'{kinds.count("cannot_tell")} | {kinds.count("none")} | '
              f'{", ".join(f"{h:.2g}" for h in asked)} | {check} |', flush=True)


if __name__ == '__main__':
    main()
