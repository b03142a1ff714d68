"""
Coarse stamp clocks and clipped gyros: what the session keeps and the N it reports.

Usage: ``.venv/bin/python bench/stamp_ticks.py`` (about a minute).  Seeded white noise
(N 1e-3 rad/s/sqrt(Hz) on the gyros, 1e-2 m/s^2/sqrt(Hz) on the accelerometers), each
case analysed as ``imu-allan analyze`` does (:func:`imu_allan.pipeline.analysis.analyze`):

- coarse stamps: sampled at the rate, stamped ``floor(t / tick) * tick`` (a phase of
  0.37 tick, so no sample sits on a tick's edge); with ``jitter`` the sample times
  jitter by that sd first;
- clipped gyro_x: the values clipped at +-c sample sds around its mean (a range
  below the signal).

Printed (markdown): samples used of those received, the rate, the warning's gist, and
gyro_x N over the truth with its 95 % interval (``left out``: no value reported).
Run it on an older checkout (``PYTHONPATH=/path/to/old``) for the figures before.
"""

import numpy as np

from imu_allan.pipeline.analysis import analyze
from imu_allan.pipeline.session import Session

T0_NS = 1_700_000_000_000_000_000
N_TRUE = np.array([1e-3] * 3 + [1e-2] * 3)


def _coarse(rate_hz, tick_s, seconds, seed, jitter_s=0.0):
    rng = np.random.default_rng(seed)
    n = int(rate_hz * seconds)
    true_s = 0.37 * tick_s + np.arange(n) / rate_hz + rng.normal(0, jitter_s, n)
    t = T0_NS + np.round(np.floor(true_s / tick_s) * tick_s * 1e9).astype(np.int64)
    y = rng.standard_normal((n, 6)) * N_TRUE * np.sqrt(rate_hz)
    y[:, 5] += 9.80665
    return t, y


def _row(name, t, y):
    s = Session()
    for k in range(0, t.size, 4096):
        s.add(t[k:k + 4096], y[k:k + 4096])
    s.flush()
    result = analyze(s)
    fit = result.fits['gyro_x']
    if fit is None:
        n = 'left out'
    else:
        p = fit.optimised['N']
        n = f'{p.value / N_TRUE[0]:.3f} [{p.ci95[0] / N_TRUE[0]:.3f}, {p.ci95[1] / N_TRUE[0]:.3f}]'
    gist = '; '.join(w.split(':')[0] for w in s.warnings) or '-'
    print(f'| {name} | {s.stats.n_used:,} of {t.size:,} | {s.rate_hz:.2f} Hz | {gist} | {n} |')


def main() -> None:
    """Print the table."""
    print('| case | used | rate | warnings | gyro_x N / truth [95 %] |')
    print('|---|---|---|---|---|')
    for rate, tick, secs, jitter in ((4000.0, 1e-3, 30.0, 0.0), (2500.0, 1e-3, 30.0, 0.0),
                                     (800.0, 1e-3, 100.0, 0.0), (200.0, 1e-2, 300.0, 0.0),
                                     (1000.0, 1e-3, 60.0, 2e-4)):
        t, y = _coarse(rate, tick, secs, seed=int(rate))
        if jitter:
            t, y = _coarse(rate, tick, secs, seed=int(rate), jitter_s=jitter)
        _row(f'{rate:g} Hz in {tick * 1e3:g} ms ticks'
             + (f', jitter {jitter * 1e3:g} ms' if jitter else ''), t, y)
    for c in (0.3, 2.0, 3.5):
        rng = np.random.default_rng(5)
        n = 180_000
        t = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
        y = rng.standard_normal((n, 6)) * N_TRUE * 10.0
        y[:, 5] += 9.80665
        y[:, 0] = np.clip(y[:, 0] + 0.01, 0.01 - c * 1e-2, 0.01 + c * 1e-2)
        _row(f'gyro_x clipped at +-{c:g} sd, 100 Hz, 30 min', t, y)


if __name__ == '__main__':
    main()
