"""
Power and false alarms of the session's sample gate: spikes and motion, against size.

Usage: ``.venv/bin/python bench/gate_power.py [--seeds 2] [--minutes 40] [--adis DIR]``.

Every case is a seeded six-axis record at 100 Hz with ADIS16405-like noise (gyro
white sigma 6e-3 rad/s per sample plus a slow bias random walk, accelerometers
0.04 m/s^2 on gravity) streamed through :class:`imu_allan.pipeline.session.Session`
in blocks of 777 samples:

- spikes: singles and bursts of 2-5 samples at 10-50 sigma (random sign, random
  axis) in 0.001-1 % of the samples; power is the share of spike values the filter
  replaced, false spikes are the replaced values that were no spike;
- motion: 30 s to 10 min of driving (vibration 5 sigma, turns of 0.3 rad/s, 0.5 m/s^2
  of acceleration) or of a slow bump (a raised cosine on gyro_z whose peak is 5-50
  sigma of a 1 s mean: 50 sigma is 0.03 rad/s)
  before, between or after still stretches; printed are the share of cases flagged
  and the samples used over the truly still ones (1.0: all still data, no motion);
- the robot that moved first: 2 min of driving, then 38 min still;
- with ``--adis DIR``: the spikes found in each ADIS16405 run (runs 1 and 4 hold real
  outliers, see that data's README).

Printed: markdown tables.
"""

import argparse
from pathlib import Path

import numpy as np

from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session

RATE_HZ = 100.0
SIGMA = np.array([6e-3] * 3 + [0.04] * 3)
#: Noise of a 1 s mean (100 samples): the sigma of the bump sizes.
SIGMA_1S = SIGMA / 10
BLOCK = 777


def still_record(n: int, rng: np.random.Generator) -> np.ndarray:
    """Shape (n, 6): still ADIS-like samples [rad/s, m/s^2]."""
    y = rng.standard_normal((n, 6)) * SIGMA
    y += np.cumsum(rng.standard_normal((n, 6)), axis=0) * SIGMA * 2e-3
    y[:, 5] -= 9.81
    return y


def add_spikes(y: np.ndarray, share: float, sigma: float, burst: bool,
               rng: np.random.Generator) -> np.ndarray:
    """Add spikes in place; return the (n, 6) mask of spike values."""
    n = y.shape[0]
    mask = np.zeros(y.shape, dtype=bool)
    n_events = max(int(round(share * n * 6 / (3.5 if burst else 1))), 1)
    rows = rng.choice(np.arange(10, n - 10), n_events, replace=False)
    cols = rng.integers(0, 6, n_events)
    for r, c in zip(rows, cols):
        length = int(rng.integers(2, 6)) if burst else 1
        sign = rng.choice([-1.0, 1.0])
        y[r:r + length, c] += sign * sigma * SIGMA[c]
        mask[r:r + length, c] = True
    return mask


def add_motion(y: np.ndarray, start: int, length: int, kind: str, size: float,
               rng: np.random.Generator) -> None:
    """Add driving or a slow bump of ``size`` sigma (bumps) to rows start:start+length."""
    k = slice(start, start + length)
    if kind == 'driving':
        y[k] += rng.standard_normal((length, 6)) * SIGMA * 5
        turns = np.repeat(rng.uniform(-0.3, 0.3, length // 500 + 1), 500)[:length]
        y[k, 2] += turns
        y[k, 3] += np.repeat(rng.uniform(-0.5, 0.5, length // 300 + 1), 300)[:length]
    else:
        y[k, 2] += size * SIGMA_1S[2] * 0.5 * (1 - np.cos(2 * np.pi * np.arange(length) / length))


def run(y: np.ndarray, **config) -> Session:
    """Stream a record through a Session; return it flushed."""
    t = np.arange(y.shape[0], dtype=np.int64) * int(1e9 / RATE_HZ)
    s = Session(SessionConfig(**config))
    for k in range(0, y.shape[0], BLOCK):
        s.add(t[k:k + BLOCK], y[k:k + BLOCK])
    s.flush()
    return s


def cleaned_values(y: np.ndarray) -> np.ndarray:
    """Return the spike filter's output alone for a record (n, 6)."""
    from imu_allan.pipeline.hygiene import HygieneStats, SessionConfig as Cfg, WarningLog
    from imu_allan.pipeline.spikes import SpikeFilter
    f = SpikeFilter(Cfg(), HygieneStats(), WarningLog())
    t = np.arange(y.shape[0])
    parts = []
    for k in range(0, y.shape[0], BLOCK):
        parts.append(f.take(t[k:k + BLOCK], y[k:k + BLOCK])[1])
    parts.append(f.flush()[1])
    return np.concatenate(parts)


def spike_table(seeds: int, minutes: float) -> None:
    n = int(minutes * 60 * RATE_HZ)
    print(f'\n### Spikes ({minutes:g} min at 100 Hz, {seeds} seeds; power / false spikes)\n')
    shares = (1e-5, 1e-4, 1e-3, 1e-2)
    print('| sigma | kind | ' + ' | '.join(f'{100 * p:g} %' for p in shares) + ' |')
    print('|---|---|' + '---|' * len(shares))
    for sigma in (10, 20, 30, 50):
        for burst in (False, True):
            cells = []
            for share in shares:
                found = total = false = 0
                for seed in range(seeds):
                    rng = np.random.default_rng(1000 * seed + int(sigma) + 7 * burst)
                    y = still_record(n, rng)
                    mask = add_spikes(y, share, sigma, burst, rng)
                    changed = cleaned_values(y) != y
                    found += int((changed & mask).sum())
                    total += int(mask.sum())
                    false += int((changed & ~mask).sum())
                cells.append(f'{found / total:.3f} / {false}')
            print(f'| {sigma} | {"burst 2-5" if burst else "single"} | ' + ' | '.join(cells)
                  + ' |')
    clean = sum(int((cleaned_values(still_record(n, np.random.default_rng(s))) !=
                     still_record(n, np.random.default_rng(s))).sum()) for s in range(seeds))
    print(f'\nClean records: {clean} false spikes in {seeds * n * 6:,} values.')


def motion_table(seeds: int, minutes: float) -> None:
    n = int(minutes * 60 * RATE_HZ)
    print(f'\n### Motion ({minutes:g} min at 100 Hz, {seeds} seeds; flagged / used over '
          'truly still)\n')
    lengths_s = (30, 120, 600)
    print('| motion | where | ' + ' | '.join(f'{s} s' for s in lengths_s) + ' |')
    print('|---|---|' + '---|' * len(lengths_s))
    kinds = [('driving', 0)] + [('bump', a) for a in (5, 10, 20, 50)]
    for kind, size in kinds:
        for where in ('before', 'between', 'after'):
            cells = []
            for length_s in lengths_s:
                flagged, ratio = 0, []
                for seed in range(seeds):
                    rng = np.random.default_rng(seed + 31 * size + len(where))
                    y = still_record(n, rng)
                    length = int(length_s * RATE_HZ)
                    start = {'before': 0, 'between': (n - length) // 2,
                             'after': n - length}[where]
                    add_motion(y, start, length, kind, size, rng)
                    s = run(y)
                    flagged += s.stats.n_motion_events > 0 or s.stats.n_reanchors > 0
                    ratio.append(s.stats.n_used / (n - length))
                cells.append(f'{flagged}/{seeds}, {np.mean(ratio):.3f}')
            label = kind if kind == 'driving' else f'bump {size} sigma'
            print(f'| {label} | {where} | ' + ' | '.join(cells) + ' |')
    false = 0
    for seed in range(seeds):
        s = run(still_record(n, np.random.default_rng(500 + seed)))
        false += s.stats.n_motion_events
    print(f'\nClean records: {false} motion events in {seeds} x {minutes:g} min.')


def moved_first(seeds: int) -> None:
    print('\n### A robot that moved first (2 min driving, 38 min still, 100 Hz)\n')
    print('| seed | on_motion | still share (truth 0.950) | reanchors |')
    print('|---|---|---|---|')
    for seed in range(seeds):
        for policy in ('pause', 'restart'):
            rng = np.random.default_rng(77 + seed)
            n = int(40 * 60 * RATE_HZ)
            y = still_record(n, rng)
            add_motion(y, 0, int(120 * RATE_HZ), 'driving', 0, rng)
            s = run(y, on_motion=policy)
            print(f'| {seed} | {policy} | {s.stats.n_used / n:.4f} | {s.stats.n_reanchors} |')


def adis_table(folder: Path) -> None:
    from imu_allan.io.inputs import open_input, stream_input
    print('\n### ADIS16405 runs (spikes replaced per axis, motion events)\n')
    print('| run | spikes | per axis | motion events | used |')
    print('|---|---|---|---|---|')
    for k in range(1, 7):
        with open_input(folder / f'adis16405_run{k}.csv.gz', None) as src:
            s = stream_input(src, SessionConfig(), prefetch=False)
        axes = ', '.join(f'{a} {v}' for a, v in s.stats.spikes.items()) or '-'
        print(f'| {k} | {s.stats.n_spikes} | {axes} | {s.stats.n_motion_events} | '
              f'{s.stats.n_used}/{s.stats.n_received} |')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seeds', type=int, default=2)
    parser.add_argument('--minutes', type=float, default=40.0)
    parser.add_argument('--adis', type=Path, default=None)
    parser.add_argument('--only', choices=('spikes', 'motion', 'first', 'adis'), default=None)
    args = parser.parse_args()
    if args.only in (None, 'spikes'):
        spike_table(args.seeds, args.minutes)
    if args.only in (None, 'motion'):
        motion_table(args.seeds, args.minutes)
    if args.only in (None, 'first'):
        moved_first(args.seeds)
    if args.adis is not None and args.only in (None, 'adis'):
        adis_table(args.adis)


if __name__ == '__main__':
    main()
