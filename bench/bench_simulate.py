"""
Benchmark of imu_allan.core.noise.simulate: a 3-hour, 100 Hz, six-axis record.

Prints wall times measured in one run and their ratio to the record length, for the
paper's model (Gauss-Markov B) and for a model with every term (flicker B, quantization,
ramp, sinusoid), plus the state-space generator with 100 replicas.

Usage: ``.venv/bin/python bench/bench_simulate.py [--hours H] [--rate HZ]``
"""

import argparse
from pathlib import Path
import time

import numpy as np

from imu_allan import AXES
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu, simulate_state_space
from imu_allan.core.noise.values import AxisNoise, NoiseSpec, Sinusoid

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'xsens_mti7.yaml'


def _timed(fn):
    """Return (seconds, result) of one call."""
    start = time.perf_counter()
    result = fn()
    return time.perf_counter() - start, result


def main() -> None:
    """Run the benchmark and print one line per case."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--hours', type=float, default=3.0)
    parser.add_argument('--rate', type=float, default=100.0)
    args = parser.parse_args()
    duration_s = args.hours * 3600.0
    n = int(round(duration_s * args.rate))

    paper = load_params(CONFIG)
    every = NoiseSpec('every term', {
        a: AxisNoise(N=1e-3, B=1e-4, K=1e-5, Q=1e-6, R=1e-9,
                     sinusoids=(Sinusoid(1e-4, 0.1),)) for a in AXES})
    for label, spec in (('paper model (GM B, T_B)', paper), ('every term (flicker B)', every)):
        seconds, (_, samples) = _timed(lambda: simulate_imu(spec, args.rate, duration_s, 1))
        assert samples.shape == (n, 6)
        print(f'{label:28s} {n} x 6 samples: {seconds:6.2f} s wall, '
              f'{seconds / (n * 6) * 1e9:6.1f} ns/sample, '
              f'simulated/real time 1:{duration_s / seconds:,.0f}')

    rng = np.random.default_rng(2)
    n_ss, replicas = 100_000, 100
    seconds, run = _timed(lambda: simulate_state_space(paper.axes['gyro_x'], args.rate, n_ss,
                                                       rng, n_replicas=replicas))
    print(f'{"state space, 100 replicas":28s} {n_ss} x {replicas} samples: {seconds:6.2f} s wall, '
          f'{seconds / (n_ss * replicas) * 1e9:6.1f} ns/sample')


if __name__ == '__main__':
    main()
