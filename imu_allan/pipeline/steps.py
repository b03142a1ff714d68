"""
Stamp steps judged as a clock judges them, and the cutting of blocks into runs.

Pure functions of :mod:`imu_allan.pipeline.clock` (the stamp clock of a session).
"""

import math

import numpy as np

from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import NS

#: Relative jitter of the stamp steps above which the stamps are irregular.
MAX_JITTER = 0.25
#: Gaps that lie within this share of a period of whole periods (90 % of them) are a
#: regular clock's lost messages (a window of 100 steps of a link that lost 60 % holds
#: 3-5): 3 waits that fall anywhere do so by chance 0.8 % of the time, and one window
#: judged irregular flags the whole record so.
_WHOLE_TOL = 0.1
#: ... and none longer than this many periods (beyond, a tenth of a period is no test).
_WHOLE_MAX = 1000.0


def is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def number(value, name: str) -> float:
    """Return a finite number >= 0 from a checkpoint; InputError otherwise."""
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or not math.isfinite(value) or value < 0):
        raise InputError(f'the field {name} is invalid ({value!r})')
    return float(value)


def split_runs(stamp_ns: np.ndarray, samples: np.ndarray, keep: np.ndarray | None):
    """
    Yield the runs of kept rows as (stamps, samples, broken).

    ``broken`` is True when rows were dropped just before the run, i.e. the run does
    not continue the previous data.  ``keep`` None keeps every row.
    """
    if keep is None or keep.all():
        yield stamp_ns, samples, False
        return
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        return
    cuts = np.flatnonzero(np.diff(idx) > 1) + 1
    for run in np.split(idx, cuts):
        broken = run[0] > 0 and not keep[run[0] - 1]
        yield stamp_ns[run], samples[run], bool(broken)


def judge_steps(steps_ns: np.ndarray, gap_factor: float, max_step_ns: float):
    """
    Judge one window of stamp steps: regular clock (with isolated gaps) or irregular.

    Parameters
    ----------
    steps_ns : numpy.ndarray
        Positive stamp steps [ns].
    gap_factor : float
        A step longer than this many periods is a gap of a regular clock.
    max_step_ns : float
        Steps longer than this are gaps whatever the verdict, and left out [ns].

    Returns
    -------
    tuple of (bool, float, float) or None
        ``(regular, period_ns, jitter_rel)``, or None with fewer than two usable steps.
        A regular window's period counts each gap as whole periods; an irregular
        window's is the mean step.

    """
    s = np.asarray(steps_ns, dtype=np.float64)
    lo, hi = (float(s.min()), float(s.max())) if s.size else (0.0, 0.0)
    if s.size >= 2 and 0 < hi <= (1 + MAX_JITTER) * lo and hi <= max_step_ns:
        # The usual window (every step near the median, no gap): what the general case
        # below gives, with the plain mean and std, in a fraction of the time.
        mean = float(s.mean())
        return True, mean, float(s.std() / mean)
    s = s[s <= max_step_ns]
    if s.size < 2:
        return None
    # Median and the steps near it: an isolated gap moves neither, unlike the std.
    med = float(np.median(s))
    near = np.abs(s - med) <= MAX_JITTER * med
    if med > 0 and near.any():
        period = float(s[near].mean())
        clock = s <= gap_factor * period
        jitter = float(np.sqrt(np.mean((s[clock] - period) ** 2)) / period)
        n_long = int(s.size - clock.sum())
        # Bursty arrival stamps also show a tight cluster of short steps, but the waits
        # between bursts are many and take most of the time; gaps of a clock are few,
        # or (a lossy link) leave most of the time to the regular steps.
        isolated = n_long <= max(2, 0.02 * s.size)
        covered = float(s[clock].sum() / s.sum())
        # A subscriber starved of CPU loses bursts of messages of a regular clock: its
        # gaps are whole periods however much time they take; waits between bursts of
        # arrival stamps fall anywhere between multiples.
        gaps = s[~clock] / period
        whole = (n_long > 0 and float(gaps.max()) <= _WHOLE_MAX
                 and float(np.mean(np.abs(gaps - np.round(gaps)) <= _WHOLE_TOL)) >= 0.9)
        if jitter <= MAX_JITTER and (isolated or covered >= 0.5 or whole):
            # A clock's gap loses whole periods: count them, so gaps do not bias the rate.
            return True, float(s.sum() / np.maximum(np.round(s / period), 1).sum()), jitter
    mean = float(s.mean())
    return False, mean, float(s.std() / mean)


def stamp_rate(stamp_ns: np.ndarray, gap_factor: float, max_step_ns: float) -> float:
    """
    Return the rate of a run of stamps judged as a stamp clock judges its own [Hz].

    Gaps of a regular clock count as whole periods (lost messages do not lower it);
    irregular (bursty) stamps give their mean rate.  0 when undecidable.

    Parameters
    ----------
    stamp_ns : numpy.ndarray
        Shape (n,), stamps [ns], in any order.
    gap_factor, max_step_ns : float
        As :func:`judge_steps`.

    """
    t = np.sort(np.asarray(stamp_ns, dtype=np.int64))
    steps = np.diff(t)
    verdict = judge_steps(steps[steps > 0], gap_factor, max_step_ns)
    if verdict is None:
        span = float(t[-1] - t[0]) if t.size > 1 else 0.0
        return (t.size - 1) * NS / span if span > 0 else 0.0
    return NS / verdict[1]


def ordinary_windows(steps: np.ndarray, window: int, period_ns: float, max_step_ns: float,
                     tolerance: float) -> np.ndarray:
    """
    Tell which whole windows of stamp steps a clock judgement would only note the jitter of.

    Such a window is regular by :func:`judge_steps`' fast test (every step within 25 %
    of the shortest, none beyond ``max_step_ns``) and within ``tolerance`` of the
    nominal ``period_ns``: judging it changes nothing but the jitter sums.

    Returns
    -------
    numpy.ndarray
        Shape (len(steps) // window,), bool.

    """
    k = steps.size // window
    w = steps[:k * window].reshape(k, window).astype(np.float64)
    if k == 0:
        return np.zeros(0, bool)
    lo, hi, mean = w.min(axis=1), w.max(axis=1), w.mean(axis=1)
    return ((lo > 0) & (hi <= (1 + MAX_JITTER) * lo) & (hi <= max_step_ns)
            & (np.abs(period_ns / mean - 1) <= tolerance))
