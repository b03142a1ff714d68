"""
Detection power of the effect search against record length, and its false alarms.

Usage: ``.venv/bin/python bench/search_power.py [--seeds 5] [--hours 1,3,6]``.

Each case is one simulated gyro axis at 50 Hz: the paper's model (white noise,
Gauss-Markov bias instability, random walk) with +-30 % seeded variation, plus one
hidden effect at a fixed size (or none, for the false-alarm rate):

- sinusoid: A = 2 N sqrt(rate) / 40 at 0.05 Hz (a line 1/40 of the white deviation);
- gauss_markov: a second process 15x faster than T_B, B 0.6 of the base B (the blind
  case that was named flicker);
- rate_ramp: three times the base deviation at a tenth of the record (the blind case a
  random walk absorbed);
- quantization: Q such that it equals white noise at tau = 2 samples;
- flicker: flicker noise at 0.8 of the base B.

Printed: a markdown table of the share of seeds in which the hidden effect is named
first (its 'power') per record length, the clean axes that got an effect, and the CPU
seconds per search.
"""

import argparse
import math
import time

import numpy as np

from imu_allan.core.allan import allan_curve
from imu_allan.core.noise.model import avar_model
from imu_allan.core.noise.shapes import avar_white
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.values import AxisNoise, GaussMarkov, NoiseSpec, Sinusoid
from imu_allan.core.search import search_axis

RATE_HZ = 50.0
EFFECTS = ('sinusoid', 'gauss_markov', 'rate_ramp', 'quantization', 'flicker')


def base_noise(rng: np.random.Generator) -> AxisNoise:
    """Return the clean axis, each parameter varied by +-30 %."""
    def v(x):
        return float(x * rng.uniform(0.7, 1.3))
    return AxisNoise(N=v(1e-3), B=v(1e-3), T_B=v(60.0), K=v(2e-6))


def with_effect(effect: str, noise: AxisNoise, hours: float) -> AxisNoise:
    """Add one effect to a clean axis at the sizes of the module doc."""
    kw = dict(noise.__dict__)
    if effect == 'sinusoid':
        kw['sinusoids'] = (Sinusoid(2.0 * noise.N * math.sqrt(RATE_HZ) / 40.0, 0.05),)
    elif effect == 'gauss_markov':
        kw['gauss_markov'] = (GaussMarkov(0.6 * noise.B, noise.T_B / 15.0),)
    elif effect == 'rate_ramp':
        tau = hours * 360.0
        kw['R'] = 3.0 * math.sqrt(float(avar_model(np.array([tau]), noise)[0])) * math.sqrt(
            2.0) / tau
    elif effect == 'quantization':
        tau = 2.0 / RATE_HZ
        kw['Q'] = math.sqrt(float(avar_white(tau, noise.N)) * tau ** 2 / 3.0)
    elif effect == 'flicker':
        kw['gauss_markov'] = (GaussMarkov(noise.B, noise.T_B),)
        kw['B'], kw['T_B'] = 0.8 * noise.B, None
    return AxisNoise(**kw)


def run(noise: AxisNoise, hours: float, seed: int):
    """Simulate, build the curve, search; return (effects named, CPU seconds)."""
    _, y = simulate_imu(NoiseSpec(name='p', axes={'gyro_x': noise}), RATE_HZ, hours * 3600.0,
                        seed=seed)
    y = y[:, 0]
    taus = 2.0 ** (np.arange(0, 44) / 2.0) / RATE_HZ
    curve = allan_curve(y, RATE_HZ, taus[taus <= y.size / RATE_HZ / 4.0], confidence=0.95)
    t0 = time.process_time()
    s = search_axis(curve.tau_s, curve.avar[:, 0], curve.edf[:, 0], RATE_HZ, y.size, raw=y,
                    unit='rad/s')
    return [st.effect for st in s.steps], time.process_time() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--seeds', type=int, default=5)
    ap.add_argument('--hours', default='1,3,6')
    args = ap.parse_args()
    hours = [float(h) for h in args.hours.split(',')]
    print('| effect | ' + ' | '.join(f'{h:g} h' for h in hours) + ' |')
    print('|---|' + '---|' * len(hours))
    cpu = []
    for effect in EFFECTS + ('none',):
        cells = []
        for h in hours:
            named = 0
            for seed in range(args.seeds):
                rng = np.random.default_rng(1000 * seed + int(10 * h))
                noise = base_noise(rng)
                if effect != 'none':
                    noise = with_effect(effect, noise, h)
                found, seconds = run(noise, h, seed)
                cpu.append(seconds)
                named += (found[:1] == [effect]) if effect != 'none' else bool(found)
            cells.append(f'{named}/{args.seeds}')
        label = 'clean: any effect named' if effect == 'none' else effect
        print(f'| {label} | ' + ' | '.join(cells) + ' |', flush=True)
    print(f'\nsearch CPU time per axis: median {np.median(cpu):.1f} s, max {np.max(cpu):.1f} s')


if __name__ == '__main__':
    main()
