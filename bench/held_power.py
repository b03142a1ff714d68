"""
Held values and low rates: a real record degraded, analysed as ``imu-allan analyze`` does.

Usage: ``.venv/bin/python bench/held_power.py --adis DIR [--minutes 30]`` with DIR the
folder of ``adis16405_run1.csv.gz`` (100 Hz, static; see that data's README), and
``bench/held_power.py --simulate 4``: seeded sensors (N 7e-4, B 5e-4 with T_B 20 s, K
3e-5 on all six axes) updating at 33.3 Hz for 30,000 updates, analysed at their own rate
and held 3 times at 100 Hz: the ratio of the held N to the updates' N, and both
relative 95 % half-widths, per axis.

A slice of run 1 (from 1000 s on) is the clean record; each degradation of it is written
to a temporary CSV and analysed by :func:`imu_allan.io.inputs.analyze_input`:

- ``hold k``: a sensor updating every k samples (the mean of its k samples: its own
  decimation filter) read at 100 Hz, each update held k times (zero-order hold);
- ``poll k``: a logger polling at 100 Hz with a jitter of +-0.3 periods a sensor that
  updates every k samples (non-integer k): each update held a varying number of times;
- ``sub k``: every k-th sample held k times (a sensor without a decimation filter:
  its noise density is truly sqrt(k) times higher);
- ``1 Hz mean`` / ``1 Hz pick``: the means of 100 samples, or every 100th sample.

Printed (markdown): per case the share of values held that the gate measured and the
update rate it implies, the spikes replaced, the motion episodes, the outcome, and per
parameter (N, B, K of each sensor's three axes) ``a/b xr``: a axes whose value lies
within the clean slice's 95 % interval, b whose own interval holds the clean value,
and the median ratio r to the clean value; ``*`` marks a sensor with an untrusted axis
(which reports conservative values).
"""

import argparse
from pathlib import Path
import tempfile

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError
from imu_allan.io.csv_io import read_csv, write_csv
from imu_allan.io.inputs import analyze_input
from imu_allan.pipeline.hygiene import SessionConfig

RATE_HZ = 100.0


def hold_means(y: np.ndarray, k: int) -> np.ndarray:
    """Return (n, 6): the mean of every k samples, held k times [unit]."""
    n = y.shape[0] // k * k
    return np.repeat(y[:n].reshape(-1, k, y.shape[1]).mean(axis=1), k, axis=0)


def hold_picks(y: np.ndarray, k: int) -> np.ndarray:
    """Return (n, 6): every k-th sample, held k times [unit]."""
    n = y.shape[0] // k * k
    return np.repeat(y[:n:k], k, axis=0)


def poll(y: np.ndarray, k: float, rng: np.random.Generator) -> np.ndarray:
    """Return (n, 6): a jittered 100 Hz poll of updates every k samples (their means)."""
    ends = np.floor(np.arange(k, y.shape[0] + 1e-9, k)).astype(np.int64)
    starts = np.concatenate(([0], ends[:-1]))
    sums = np.concatenate((np.zeros((1, y.shape[1])), np.cumsum(y, axis=0)))
    means = (sums[ends] - sums[starts]) / (ends - starts)[:, None]
    polled = np.arange(ends[-1]) + rng.uniform(-0.3, 0.3, ends[-1])
    j = np.searchsorted(ends, polled, side='right') - 1
    return means[j[j >= 0]]


def cases(y: np.ndarray) -> list:
    """Return [(name, t_s (n,), samples (n, 6))] of the clean slice and its degradations."""
    def at(rate_hz, s):
        return np.arange(s.shape[0]) / rate_hz, s
    rng = np.random.default_rng(1)
    out = [('clean', *at(RATE_HZ, y))]
    out += [(f'hold {k}', *at(RATE_HZ, hold_means(y, k))) for k in (2, 3, 5)]
    out += [(f'poll {k}', *at(RATE_HZ, poll(y, k, rng))) for k in (1.5, 1.9, 3.6)]
    out += [('sub 2', *at(RATE_HZ, hold_picks(y, 2)))]
    n = y.shape[0] // 100 * 100
    out += [('1 Hz mean', *at(1.0, y[:n].reshape(-1, 100, 6).mean(axis=1))),
            ('1 Hz pick', *at(1.0, y[:n:100]))]
    return out


def analyse(path: Path):
    """Return the AnalysisResult of one CSV, or the one-line error."""
    try:
        return analyze_input(path, None, SessionConfig(background_accumulator=True),
                             quiet=True, workers=2)[0]
    except InputError as exc:
        return str(exc).split(': ', 1)[-1]


def row(name: str, result, clean) -> str:
    """Return one markdown row: what the gate found and how the parameters compare."""
    if isinstance(result, str):
        return f'| {name} | | | | refused: {result[:60]} |' + ' |' * 6
    h = result.hygiene
    held = h.get('held', {})
    share = np.mean(list(held.values())) if held else 0.0
    found = f'{100 * share:.0f} % ({result.rate_hz * (1 - share):.3g} Hz)' if held else '-'
    cells = []
    for sensor in ('gyro', 'accel'):
        axes = [a for a in AXES if a.startswith(sensor)]
        for sym in ('N', 'B', 'K'):
            inside, covers, ratio = 0, 0, []
            for a in axes:
                got = result.fits[a].optimised.get(sym) if result.fits[a] else None
                ref = clean.fits[a].optimised.get(sym)
                if got is None or ref is None or not ref.value > 0:
                    continue
                inside += int(ref.ci95[0] <= got.value <= ref.ci95[1])
                covers += int(got.ci95[0] <= ref.value <= got.ci95[1])
                ratio.append(got.value / ref.value)
            trusted = sum(bool(result.fits[a] and result.fits[a].trusted) for a in axes)
            mark = '' if trusted == len(axes) else '*'
            cells.append(f'{inside}/{covers}{mark} x{np.median(ratio):.2f}' if ratio
                         else '-')
    outcome = f'{result.n_samples} used'
    return (f'| {name} | {found} | {h["n_spikes"]} | {h["n_motion_events"]} | {outcome} | '
            + ' | '.join(cells) + ' |')


def simulated(seeds: int, k: int = 3, n: int = 30_000) -> None:
    """Print held N over the updates' N (and both half-widths) for seeded sensors."""
    from imu_allan.core.noise.values import AxisNoise
    from imu_allan.core.noise.simulate import simulate_axis
    from imu_allan.pipeline.analysis import analyze
    from imu_allan.pipeline.session import Session

    def fit(t, y):
        s = Session()
        for i in range(0, t.size, 5_000):
            s.add(t[i:i + 5_000], y[i:i + 5_000])
        s.flush()
        return analyze(s, workers=2)
    print(f'\n### Simulated, held {k} times (N ratio; half-widths updates / held)\n')
    print('| seed | ' + ' | '.join(AXES) + ' |')
    print('|---|' + '---|' * len(AXES))
    for seed in range(seeds):
        rng = np.random.default_rng(100 + seed)
        noise = AxisNoise(N=7e-4, B=5e-4, T_B=20.0, K=3e-5)
        updates = np.stack([simulate_axis(noise, RATE_HZ / k, n, rng) for _ in AXES], axis=1)
        t = np.arange(n * k, dtype=np.int64) * 10**7
        clean, held = fit(t[::k], updates), fit(t, np.repeat(updates, k, axis=0))
        cells = []
        for a in AXES:
            c, h = clean.fits[a].optimised['N'], held.fits[a].optimised['N']
            cells.append(f'{h.value / c.value:.4f} ({(c.ci95[1] - c.ci95[0]) / 2 / c.value:.3f}'
                         f' / {(h.ci95[1] - h.ci95[0]) / 2 / h.value:.3f})')
        print(f'| {seed} | ' + ' | '.join(cells) + ' |', flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--adis', type=Path, default=None)
    parser.add_argument('--minutes', type=float, default=30.0)
    parser.add_argument('--simulate', type=int, default=0, metavar='SEEDS')
    args = parser.parse_args()
    if args.simulate:
        simulated(args.simulate)
    if args.adis is None:
        return
    data = read_csv(args.adis / 'adis16405_run1.csv.gz').samples
    y = data[100_000:100_000 + int(args.minutes * 60 * RATE_HZ)]
    print(f'\n### ADIS16405 run 1, {args.minutes:g} min from 1000 s, degraded\n')
    print('| case | held (update rate) | spikes | motion episodes | outcome | gyro N | '
          'gyro B | gyro K | accel N | accel B | accel K |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    with tempfile.TemporaryDirectory() as tmp:
        clean = None
        for name, t_s, s in cases(y):
            path = Path(tmp) / f'{name.replace(" ", "_")}.csv'
            write_csv(path, t_s, s, AXES)
            result = analyse(path)
            if clean is None:
                clean = result
            print(row(name, result, clean), flush=True)


if __name__ == '__main__':
    main()
