"""
The stamp clock of a session: rate, jitter, gaps, rate changes (Session's first stage).

Stamp steps are judged in windows of a fixed number of steps, so the verdicts do not
depend on how the record is cut into blocks; ordinary windows (regular, on the nominal
rate) are judged together.  A mixin of :class:`imu_allan.pipeline.session.Session`,
whose state it shares.
"""

import math
from typing import Callable

import numpy as np

from imu_allan.pipeline.parts import _Parts


_NS = 1_000_000_000
#: Stamp steps per judged window (jitter, regularity and rate changes).  Fixed step
#: counts, not blocks, so that the verdicts do not depend on how the record is cut up.
_CLOCK_WINDOW = 100
#: Relative jitter of the stamp steps above which the stamps are irregular.
_MAX_JITTER = 0.25


# Long by design: the clock's state (rate, jitter window, gap and step counters) is
# carried from block to block; each judgement of a block is a short method.
class _StampClock(_Parts):
    """Rate estimate, stamp windows and gaps: the gap-free runs go on to the sample checks."""

    def _monotonic_mask(self, stamp_ns: np.ndarray) -> np.ndarray:
        """Mask out duplicate and out-of-order stamps against the newest accepted one."""
        newest = self._newest_ns if self._newest_ns is not None else np.iinfo(np.int64).min
        prev_max = np.maximum.accumulate(np.concatenate(([newest], stamp_ns[:-1])))
        dup = stamp_ns == prev_max
        back = stamp_ns < prev_max
        if dup.any():
            self.stats.n_duplicate += int(dup.sum())
            self._warn('duplicate', f'{int(dup.sum())} samples with a repeated stamp dropped',
                       once=False)
        if back.any():
            self.stats.n_out_of_order += int(back.sum())
            self._warn('order', f'{int(back.sum())} samples with out-of-order stamps dropped',
                       once=False)
        self._newest_ns = max(newest, int(stamp_ns.max())) if stamp_ns.size else newest
        return ~dup & ~back

    def _estimate_rate(self, t: np.ndarray) -> None:
        steps = np.diff(t)
        verdict = _judge_steps(steps, self.config.gap_factor,
                               self.config.irregular_gap_s * _NS)
        if verdict is None:
            # Too few usable steps to judge: the mean rate is all there is.
            self.rate_hz = (t.size - 1) * _NS / float(t[-1] - t[0])
            return
        regular, period_ns, jitter = verdict
        self.rate_hz = _NS / period_ns
        self._note_jitter(jitter, steps.size)
        if not regular:
            self._flag_irregular(jitter)

    def stamp_rate_hz(self, stamp_ns: np.ndarray) -> float:
        """
        Rate of a run of stamps judged as this session judges its own [Hz].

        Gaps of a regular clock count as whole periods (lost messages do not lower
        it); irregular (bursty) stamps give their mean rate.  0 when undecidable.

        Parameters
        ----------
        stamp_ns : numpy.ndarray
            Shape (n,), stamps [ns], in any order.

        """
        t = np.sort(np.asarray(stamp_ns, dtype=np.int64))
        steps = np.diff(t)
        verdict = _judge_steps(steps[steps > 0], self.config.gap_factor,
                               self.config.irregular_gap_s * _NS)
        if verdict is None:
            span = float(t[-1] - t[0]) if t.size > 1 else 0.0
            return (t.size - 1) * _NS / span if span > 0 else 0.0
        return _NS / verdict[1]

    def _note_jitter(self, jitter: float, n_steps: int) -> None:
        self._note_jitters(np.array([jitter]), n_steps)

    def _note_jitters(self, jitters: np.ndarray, n_steps: int) -> None:
        """Add windows' relative jitters, each over ``n_steps`` steps, to the running RMS."""
        # Added one window after the other (add.accumulate is sequential), so the sum
        # has the same bits however the windows were grouped into calls.
        terms = np.concatenate(([self._jitter_sq], jitters * jitters * n_steps))
        self._jitter_sq = float(np.add.accumulate(terms)[-1])
        self._jitter_n += n_steps * jitters.size
        self.stats.jitter_rel = math.sqrt(self._jitter_sq / self._jitter_n)

    def _flag_irregular(self, jitter: float) -> None:
        if self.stats.irregular_stamps:
            return
        self.stats.irregular_stamps = True
        period = _NS / self.rate_hz
        self._warn('irregular', f'irregular stamps (jitter {100 * jitter:.0f}% of the '
                   f'{period / 1e6:.2f} ms period): samples are taken as evenly spaced at '
                   f'{self.rate_hz:.3f} Hz; only steps over {self.config.irregular_gap_s} s '
                   'count as gaps')
        self._refine_rate()

    def _refine_rate(self) -> None:
        """With irregular stamps, take the mean rate of all non-gap steps so far."""
        if self.stats.irregular_stamps and self._clock_n > 0 and self._clock_ns > 0:
            self.rate_hz = self._clock_n * _NS / self._clock_ns
            if self.acc is not None:
                self.acc.rate_hz = self.rate_hz

    def _judge_clock(self, settle: Callable[[], None]) -> None:
        """
        Judge a full window of steps: jitter, regularity, and a change of the period.

        ``settle`` passes the rows up to here on; it is called before anything that
        the rows after the window must see (a new rate or mode, or a warning, which
        must follow those rows' own warnings), so the order never depends on blocks.
        """
        steps = np.concatenate(self._step_buf)
        self._step_buf = []
        verdict = _judge_steps(steps, self.config.gap_factor,
                               self.config.irregular_gap_s * _NS)
        if verdict is None:
            return
        regular, period_ns, jitter = verdict
        self._note_jitter(jitter, steps.size)
        if not regular or self.stats.irregular_stamps:
            settle()
        if not regular:
            self._flag_irregular(jitter)
        elif not self.stats.irregular_stamps:
            tol = self.config.rate_tolerance
            if abs(_NS / self.rate_hz / period_ns - 1) > tol:
                # One warning per episode: a new one only when the period moves again.
                if self._off_period_ns is None or abs(self._off_period_ns / period_ns - 1) > tol:
                    settle()
                    self.stats.n_rate_changes += 1
                    self._warn('rate', f'sample rate changed: {_NS / period_ns:.2f} Hz against '
                               f'the nominal {self.rate_hz:.2f} Hz (gaps are located with the '
                               'nominal rate)', once=False)
                self._off_period_ns = period_ns
            else:
                self._off_period_ns = None
        self._refine_rate()

    def _ordinary_windows(self, steps: np.ndarray) -> np.ndarray:
        """
        Which whole windows of ``steps`` a clock judgement would only note the jitter of.

        Such a window is regular by :func:`_judge_steps`' fast test (every step within
        25 % of the shortest, none beyond the irregular gap) and on the nominal rate,
        outside irregular mode: judging it changes nothing but the jitter sums.  Shape
        (len(steps) // _CLOCK_WINDOW,), bool.
        """
        k = steps.size // _CLOCK_WINDOW
        if k == 0 or self.stats.irregular_stamps or self.rate_hz <= 0:
            return np.zeros(0, bool)
        w = steps[:k * _CLOCK_WINDOW].reshape(k, _CLOCK_WINDOW).astype(np.float64)
        lo, hi, mean = w.min(axis=1), w.max(axis=1), w.mean(axis=1)
        return ((lo > 0) & (hi <= (1 + _MAX_JITTER) * lo)
                & (hi <= self.config.irregular_gap_s * _NS)
                & (np.abs(_NS / self.rate_hz / mean - 1) <= self.config.rate_tolerance))

    def _note_ordinary(self, steps: np.ndarray) -> None:
        """Note the jitter of whole ordinary windows (see :meth:`_ordinary_windows`)."""
        w = steps.reshape(-1, _CLOCK_WINDOW).astype(np.float64)
        self._note_jitters(w.std(axis=1) / w.mean(axis=1), _CLOCK_WINDOW)
        self._off_period_ns = None

    def _ingest_regular(self, stamp_ns: np.ndarray, samples: np.ndarray,
                        judged: bool = False) -> None:
        """
        Locate gaps, then pass the gap-free runs on; feed the steps to the clock windows.

        A window is judged once it is full, so its verdict applies from the next step
        on (whatever the block boundaries); ``judged`` marks the rate-window samples,
        already judged by :meth:`_estimate_rate`.
        """
        prev = self.last_stamp_ns
        # No previous stamp (start, or a resume across lost samples): row 0 is no step.
        steps = np.diff(stamp_ns, prepend=stamp_ns[0] if prev is None else prev)
        first_step = 1 if prev is None else 0
        n = stamp_ns.size
        done = 0        # rows before this one are passed on
        pos = 0         # rows before this one are in the clock windows

        def settle():
            nonlocal done
            if pos > done:
                self._split_gaps(stamp_ns[done:pos], samples[done:pos], steps[done:pos],
                                 max(first_step - done, 0))
            done = pos

        # Once the buffer is empty, the windows are aligned with the block; the
        # ordinary ones (regular, on the nominal rate) are then judged together.
        aligned, ordinary = None, np.zeros(0, bool)
        while not judged and pos < n:
            start = max(pos, first_step)
            # Irregular mode (it may start within this block) judges every window.
            if not self._step_buf and not self.stats.irregular_stamps:
                if aligned is None:
                    aligned, ordinary = start, self._ordinary_windows(steps[start:])
                i = (start - aligned) // _CLOCK_WINDOW
                if i < ordinary.size and ordinary[i]:
                    rest = ordinary[i:]
                    run = rest.size if rest.all() else int(np.argmin(rest))
                    self._note_ordinary(steps[start:start + run * _CLOCK_WINDOW])
                    pos = start + run * _CLOCK_WINDOW
                    continue
            room = _CLOCK_WINDOW - sum(s.size for s in self._step_buf)
            end = min(n, max(pos, first_step) + room)
            self._step_buf.append(steps[max(pos, first_step):end])
            pos = end
            if sum(s.size for s in self._step_buf) >= _CLOCK_WINDOW:
                self._judge_clock(settle)
        pos = n
        settle()
        self.last_stamp_ns = int(stamp_ns[-1])

    def _split_gaps(self, stamp_ns: np.ndarray, samples: np.ndarray, steps: np.ndarray,
                    skip: int) -> None:
        """Accumulate the rows between gaps; ``steps[:skip]`` are no steps."""
        period_ns = _NS / self.rate_hz
        limit = (self.config.irregular_gap_s * _NS if self.stats.irregular_stamps
                 else self.config.gap_factor * period_ns)
        real = steps[skip:]
        ok = real <= limit
        self._clock_n += int(ok.sum())
        self._clock_ns += int(real[ok].sum())
        gap_idx = np.flatnonzero(~ok) + skip
        start = 0
        for g in [int(i) for i in gap_idx] + [stamp_ns.size]:
            if g > start:
                self._accumulate(stamp_ns[start:g], samples[start:g])
            if g < stamp_ns.size:
                missing = max(int(round(steps[g] / period_ns)) - 1, 1)
                self.stats.n_gaps += 1
                self.stats.n_missing += missing
                self._warn('gap', f'gap of {steps[g] / 1e9:.3f} s (~{missing} samples) '
                           'in the stamps: the segment is split there, no term spans it',
                           once=False)
                self._flush_motion(break_after=True)
            start = g


def _judge_steps(steps_ns: np.ndarray, gap_factor: float, max_step_ns: float):
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
    if s.size >= 2 and 0 < hi <= (1 + _MAX_JITTER) * lo and hi <= max_step_ns:
        # The usual window (every step near the median, no gap): what the general case
        # below gives, with the plain mean and std, in a fraction of the time.
        mean = float(s.mean())
        return True, mean, float(s.std() / mean)
    s = s[s <= max_step_ns]
    if s.size < 2:
        return None
    # Median and the steps near it: an isolated gap moves neither, unlike the std.
    med = float(np.median(s))
    near = np.abs(s - med) <= _MAX_JITTER * med
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
        if jitter <= _MAX_JITTER and (isolated or covered >= 0.5):
            # A clock's gap loses whole periods: count them, so gaps do not bias the rate.
            return True, float(s.sum() / np.maximum(np.round(s / period), 1).sum()), jitter
    mean = float(s.mean())
    return False, mean, float(s.std() / mean)
