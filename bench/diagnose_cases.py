"""
Seeded six-axis cases for the diagnosis: one axis carries a hidden effect.

Usage: ``.venv/bin/python bench/diagnose_cases.py [--seeds N] [--clean N]``.
Prints, per effect, how often the effect axis is named correctly, how often a
clean axis gets an invented effect, and the gaps; then the false-alarm rate on
clean records.
"""

import argparse
import time

import numpy as np

from imu_allan import AXES
from imu_allan.core.allan import allan_curve
from imu_allan.core.diagnose import diagnose_curve
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.values import AxisNoise, GaussMarkov, NoiseSpec, Sinusoid

RATE_HZ = 50.0
DURATION_S = 2000.0
TAUS = 2.0 ** (np.arange(0, 2 * 16) / 2.0) / RATE_HZ
#: Clean axes: the paper's model (white, Gauss-Markov bias instability, random walk).
CLEAN = {'gyro': AxisNoise(N=1e-3, B=1e-3, T_B=10.0, K=5e-6),
         'accel': AxisNoise(N=2e-3, B=2e-3, T_B=8.0, K=1e-5, bias=9.80665)}


def clean_noise(axis: str, rng: np.random.Generator, white: bool = True) -> AxisNoise:
    """Clean-axis model with seeded +-30 % variation of each parameter."""
    base = CLEAN['gyro' if axis.startswith('gyro') else 'accel']

    def v(x):
        return float(x * rng.uniform(0.7, 1.3))
    return AxisNoise(N=v(base.N) if white else 0.0, B=v(base.B), T_B=v(base.T_B),
                     K=v(base.K), bias=base.bias if axis == 'accel_z' else 0.0)


def hidden(effect: str, noise: AxisNoise, rng: np.random.Generator) -> tuple:
    """Add one effect to a clean model; return (noise, true params)."""
    u = rng.uniform(0.8, 1.25)
    if effect == 'quantization':
        q = 4e-4 * u
        return AxisNoise(**{**noise.__dict__, 'Q': q}), {'Q': q}
    if effect == 'white':
        n = 3e-3 * u
        return AxisNoise(**{**noise.__dict__, 'N': n}), {'N': n}
    if effect == 'flicker':
        b = 2e-3 * u
        return AxisNoise(**{**noise.__dict__, 'B': b, 'T_B': None}), {'B': b}
    if effect == 'gauss_markov':
        b, t = 3e-3 * u, 5.0 * rng.uniform(0.8, 1.25)
        return AxisNoise(**{**noise.__dict__, 'gauss_markov': (GaussMarkov(b, t),)}), \
            {'B': b, 'T': t}
    if effect == 'random_walk':
        k = 1.5e-4 * u
        return AxisNoise(**{**noise.__dict__, 'K': k}), {'K': k}
    if effect == 'rate_ramp':
        r = 1.5e-4 * u * rng.choice([-1.0, 1.0])
        return AxisNoise(**{**noise.__dict__, 'R': r}), {'R': abs(r)}
    if effect == 'sinusoid':
        a, f = 5e-3 * u, 0.02 * rng.uniform(0.8, 1.25)
        return AxisNoise(**{**noise.__dict__, 'sinusoids': (Sinusoid(a, f),)}), \
            {'A': a, 'f0_hz': f}
    raise ValueError(effect)


#: Base model per effect.  A term already in the base cannot be missing, and a base
#: Gauss-Markov term with a free T absorbs a random walk (T beyond the record) or most
#: of a flicker floor, so those cases use a smaller base, and their clean axes carry
#: exactly that base model.
BASE = {'white': ('bias_instability', 'random_walk'), 'random_walk': ('white',),
        'gauss_markov': ('white', 'random_walk'), 'flicker': ('white', 'random_walk')}


def make_case(effect: str | None, seed: int, axis_index: int | None = None):
    """Six-axis record; ``effect`` (or none) on one axis; return data and truth."""
    rng = np.random.default_rng(seed)
    j = int(rng.integers(len(AXES))) if axis_index is None else axis_index
    axes = {a: clean_noise(a, rng, white=effect != 'white') for a in AXES}
    base = BASE.get(effect, ('white', 'bias_instability', 'random_walk'))
    strip = {}
    if 'bias_instability' not in base:
        strip.update(B=0.0, T_B=None)
    if 'random_walk' not in base:
        strip.update(K=0.0)
    axes = {a: AxisNoise(**{**n.__dict__, **strip}) for a, n in axes.items()}
    truth = None
    if effect is not None:
        axes[AXES[j]], truth = hidden(effect, axes[AXES[j]], rng)
    _, y = simulate_imu(NoiseSpec(name='case', axes=axes), RATE_HZ, DURATION_S,
                        seed=seed + 1000)
    return y, AXES[j], truth


def run_case(effect, seed, n_replicas=4, axis_index=None):
    """Diagnose one case; return (result, effect axis, truth)."""
    y, axis, truth = make_case(effect, seed, axis_index)
    curve = allan_curve(y, RATE_HZ, TAUS, confidence=0.95)
    base = BASE.get(effect, ('white', 'bias_instability', 'random_walk'))
    res = diagnose_curve(curve, y.shape[0], raw=y, base_model=base, seed=seed,
                         n_replicas=n_replicas)
    return res, axis, truth


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument('--seeds', type=int, default=5)
    ap.add_argument('--clean', type=int, default=20)
    ap.add_argument('--effects', default=','.join(
        ('quantization', 'white', 'flicker', 'gauss_markov', 'random_walk', 'rate_ramp',
         'sinusoid')))
    args = ap.parse_args()
    for effect in [e for e in args.effects.split(',') if e]:
        hit = inv = n_clean = shrink = 0
        gaps = []
        t0 = time.time()
        for seed in range(args.seeds):
            res, axis, truth = run_case(effect, seed)
            d = res.axes[axis]
            names = [f.effect for f in d.missing]
            ok = names[:1] == [effect]
            hit += ok
            gaps.append((d.gap_before, d.gap_after))
            shrink += d.gap_after <= 2 and d.gap_before >= 2 * d.gap_after
            for a, other in res.axes.items():
                if a != axis:
                    n_clean += 1
                    inv += bool(other.missing)
            if not ok:
                print(f'  {effect} seed {seed}: {d.summary}')
            else:
                f = d.missing[0]
                inside = {k: f.ci95[k][0] <= v <= f.ci95[k][1] for k, v in truth.items()}
                if not all(inside.values()):
                    print(f'  {effect} seed {seed}: truth {truth} outside {f.ci95} ({f.params})')
        g = np.array(gaps)
        print(f'{effect:17s} named {hit}/{args.seeds}, gap shrank>=2x to <=2: {shrink}/'
              f'{args.seeds}, invented on clean axes {inv}/{n_clean}, gap before median '
              f'{np.median(g[:, 0]):.1f} after {np.median(g[:, 1]):.2f} '
              f'({time.time() - t0:.0f} s)', flush=True)
    inv = n = 0
    t0 = time.time()
    for seed in range(args.clean):
        res, _, _ = run_case(None, 10_000 + seed)
        for a, d in res.axes.items():
            n += 1
            if d.missing:
                inv += 1
                print(f'  clean seed {seed}: {d.summary}')
    if n:
        print(f'clean records: invented effect on {inv}/{n} axes ({100.0 * inv / n:.1f} %), '
              f'{time.time() - t0:.0f} s')


if __name__ == '__main__':
    main()
