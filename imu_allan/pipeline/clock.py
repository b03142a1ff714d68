"""
The stamp clock of a session: rate, jitter, gaps, rate changes, stamp outliers.

The session's first stage: :meth:`StampClock.split` cuts blocks into gap-free runs of
rows in stamp order and hands them on.  Stamp steps are judged in windows of a fixed
number of steps, so the verdicts do not depend on how the record is cut into blocks;
ordinary windows (regular, on the nominal rate) are judged together.

A stamp far from the newest one (further than ``irregular_gap_s``, ahead or behind) is
judged by the stamp after it: when that one goes on from it, the far stamp is a gap
(ahead) or a clock that restarted (behind: a new segment); otherwise it is a lone
outlier and dropped.  So one glitched stamp can neither block later data nor be saved
in a checkpoint as the newest stamp.

A short gap of regular stamps (at most ``max_fill_samples`` lost) does not split the
segment: it is filled by linear interpolation, marked as fills
(:mod:`imu_allan.pipeline.fills`), which the accumulator leaves out at short taus.
"""

import math
from typing import Callable

import numpy as np

from imu_allan.errors import InputError
from imu_allan.pipeline.clock_state import check_clock_state
from imu_allan.pipeline.fills import fill_run, missing_line
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, NS, SessionConfig, WarningLog
from imu_allan.pipeline.steps import judge_steps, ordinary_windows, split_runs, stamp_rate

#: Stamp steps per judged window (jitter, regularity and rate changes).  Fixed step
#: counts, not blocks, so that the verdicts do not depend on how the record is cut up.
_CLOCK_WINDOW = 100

#: ``on_run(stamp_ns (n,), samples (n, 6), broken)``: a gap-free run of rows; broken
#: means the segment ends before it.
RunSink = Callable[[np.ndarray, np.ndarray, bool], None]


# Long by design: the clock's state (rate, jitter window, gap and step counters) is
# carried from block to block; each judgement of a block is a short method.
class StampClock:
    """
    Rate estimate, stamp screening, stamp windows and gaps.

    Parameters
    ----------
    config : SessionConfig
        The session's settings.
    stats : HygieneStats
        Counters this clock adds to.
    warn : WarningLog
        Where its warnings go.

    """

    def __init__(self, config: SessionConfig, stats: HygieneStats, warn: WarningLog):
        self.config = config
        self.stats = stats
        self._warn = warn
        self.rate_hz = float(config.rate_hz)
        self.first_stamp_ns: int | None = None
        self.last_stamp_ns: int | None = None
        self._newest_ns: int | None = None
        self._break_next = False
        # Rows that wait for the rate estimate, and a far stamp that waits for the next.
        self._pending_t: list[np.ndarray] = []
        self._pending_y: list[np.ndarray] = []
        self._far: tuple[int, np.ndarray] | None = None
        # Steps waiting for their window's verdict, and the count and sum of the non-gap
        # steps (the mean rate of irregular stamps comes from these, so neither gaps nor
        # a resume across lost samples bias it).
        self._step_buf: list[np.ndarray] = []
        self._clock_n = 0
        self._clock_ns = 0
        self._jitter_sq = 0.0
        self._jitter_n = 0
        self._off_period_ns: float | None = None
        # The last row passed on in this segment (a short gap's left neighbour), and the
        # real rows that reached the gap search (the share of samples missing).
        self._last_row = np.empty((0, N_AXES))
        self._n_rows = 0
        self._on_run: RunSink = _nowhere

    # ------------------------------------------------------------------ input
    def split(self, stamp_ns: np.ndarray, samples: np.ndarray, on_run: RunSink) -> None:
        """
        Cut a block into gap-free runs in stamp order and hand each to ``on_run``.

        NaN/Inf rows are dropped and break the segment; repeated and out-of-order
        stamps are dropped (re-sent messages) without a break.

        Parameters
        ----------
        stamp_ns : numpy.ndarray
            Shape (n,), header stamps [ns], int64.
        samples : numpy.ndarray
            Shape (n, 6), samples in AXES order.
        on_run : callable
            Gets each run, see :data:`RunSink`.

        """
        self._on_run = on_run
        n = stamp_ns.size
        if np.isfinite(samples).all():  # one whole-block reduction: the usual case
            finite = None
        else:
            finite = np.isfinite(samples).all(axis=1)
            bad = int(n - finite.sum())
            self.stats.n_nonfinite += bad
            self._warn('nonfinite', f'{bad} samples with NaN/Inf values dropped '
                       '(the segment is broken there)')
        for t_part, y_part, broken in split_runs(stamp_ns, samples, finite):
            if broken:
                self._break()
            for t_ok, y_ok, restart in self._screen(t_part, y_part):
                if restart:
                    self._restart_clock()
                self._ingest(t_ok, y_ok)
        # NaN rows that end a block break the segment before the next block's rows.
        if finite is not None and not finite[-1]:
            self._break()
        self._note_missing()    # the share over the rows so far, not up to the last gap

    def flush(self, on_run: RunSink) -> None:
        """Pass on the rows held for the rate estimate (end of a recording)."""
        self._on_run = on_run
        if self._far is not None:
            # A far stamp that nothing confirmed: one row, an outlier.
            self._far = None
            self._drop_outlier()
        if self.rate_hz <= 0 and self._pending_t:
            if sum(t.size for t in self._pending_t) >= 3:
                self._begin()
            else:
                self._pending_t, self._pending_y = [], []
        self._refine_rate()
        self._note_missing()

    def _break(self) -> None:
        # Before the rate is known, rows are only collected; a break there is moot.
        if self.rate_hz > 0:
            self._break_next = True
            self._last_row = self._last_row[:0]

    def _restart_clock(self) -> None:
        """Start a new segment: the stamps jumped back and went on (no step across)."""
        self.stats.n_clock_restarts += 1
        self._warn('clock-restart', 'the stamps jumped back and went on (the device clock '
                   'restarted): a new segment starts there', once=False)
        self.last_stamp_ns = None
        if self.rate_hz <= 0 and self._pending_t:
            # Rows of the old clock still waiting for the rate: they cannot be ordered
            # with the new ones.
            lost = sum(t.size for t in self._pending_t)
            self._pending_t, self._pending_y = [], []
            self.stats.n_stamp_outliers += lost
        self._break()

    def _drop_outlier(self) -> None:
        self.stats.n_stamp_outliers += 1
        self._warn('stamp-outlier', 'a sample whose stamp lies far from its neighbours '
                   '(a glitched clock) dropped', once=False)

    def _screen(self, t: np.ndarray, y: np.ndarray) -> list:
        """
        Drop repeated, out-of-order and lone far stamps; find clock restarts.

        Returns a list of (stamps, samples, restart): runs of rows in increasing stamp
        order; restart marks a run that starts a new clock.  A far stamp in the last
        row is held until the next block.
        """
        if self._far is not None:
            stamp, row = self._far
            self._far = None
            t = np.concatenate(([stamp], t))
            y = np.concatenate((row[None, :], y))
        far_ns = self.config.irregular_gap_s * NS
        steps = np.diff(t)
        steps = steps[steps > 0]
        if steps.size > 1:      # far is also far against the record's own step
            far_ns = max(far_ns, 100.0 * float(np.median(steps)))
        out: list = []
        restart = False
        pos, n = 0, t.size
        while pos < n:
            seg = t[pos:]
            newest = self._newest_ns if self._newest_ns is not None else int(seg[0]) - 1
            prev = np.maximum.accumulate(np.concatenate(([newest], seg[:-1])))
            is_far = np.abs(seg.astype(np.float64) - prev) > far_ns
            k = int(np.argmax(is_far)) if is_far.any() else seg.size
            if k:
                ok = self._ordered(seg[:k], prev[:k])
                self._newest_ns = max(newest, int(seg[:k].max()))
                if ok.all():    # the usual case: the block's own arrays, not copies
                    out.append((seg[:k], y[pos:pos + k], restart))
                elif ok.any():
                    out.append((seg[:k][ok], y[pos:pos + k][ok], restart))
                restart = restart and not ok.any()
            j = pos + k
            if j >= n:
                break
            if j == n - 1:
                self._far = (int(t[j]), y[j].copy())
                break
            step = int(t[j + 1]) - int(t[j])
            if 0 < step <= far_ns:
                # The next stamp goes on from this one: a gap ahead, a restart behind.
                restart = restart or int(t[j]) < int(prev[k])
                self._newest_ns = int(t[j]) - 1
                pos = j
            else:
                self._drop_outlier()
                pos = j + 1
        return out

    def _ordered(self, t: np.ndarray, prev_max: np.ndarray) -> np.ndarray:
        """Mask out duplicate and out-of-order stamps against the newest before each."""
        dup = t == prev_max
        back = t < prev_max
        # The lines state the totals so far (the counts in hygiene), not the last block's.
        if dup.any():
            self.stats.n_duplicate += int(dup.sum())
            self._warn.tally('duplicate', f'{self.stats.n_duplicate:,} samples with a '
                             'repeated stamp dropped', int(dup.sum()))
        if back.any():
            self.stats.n_out_of_order += int(back.sum())
            self._warn.tally('order', f'{self.stats.n_out_of_order:,} samples with '
                             'out-of-order stamps dropped', int(back.sum()))
        return ~dup & ~back

    def _ingest(self, stamp_ns: np.ndarray, samples: np.ndarray) -> None:
        if self.first_stamp_ns is None:
            self.first_stamp_ns = int(stamp_ns[0])
        if self.rate_hz <= 0:
            self._pending_t.append(stamp_ns)
            self._pending_y.append(samples)
            if sum(t.size for t in self._pending_t) >= max(self.config.rate_window, 3):
                self._begin()
            return
        self._ingest_regular(stamp_ns, samples)

    def _begin(self) -> None:
        """Estimate the rate on exactly the first ``rate_window`` samples, then go on."""
        t = np.concatenate(self._pending_t)
        y = np.concatenate(self._pending_y)
        self._pending_t, self._pending_y = [], []
        # Exactly rate_window samples, whatever the block sizes: same verdict either way.
        k = min(t.size, max(self.config.rate_window, 3))
        self._estimate_rate(t[:k])
        if self.rate_hz <= 0:
            raise InputError('the stamps of the first samples span no time: no rate')
        self._ingest_regular(t[:k], y[:k], judged=True)
        if k < t.size:
            self._ingest_regular(t[k:], y[k:])

    def _pass_on(self, stamp_ns: np.ndarray, samples: np.ndarray) -> None:
        broken, self._break_next = self._break_next, False
        self._on_run(stamp_ns, samples, broken)

    def _estimate_rate(self, t: np.ndarray) -> None:
        steps = np.diff(t)
        verdict = judge_steps(steps, self.config.gap_factor,
                              self.config.irregular_gap_s * NS)
        if verdict is None:
            # Too few usable steps to judge: the mean rate is all there is.
            self.rate_hz = (t.size - 1) * NS / float(t[-1] - t[0])
            return
        regular, period_ns, jitter = verdict
        self.rate_hz = NS / period_ns
        self._note_jitters(np.array([jitter]), steps.size)
        if not regular:
            self._flag_irregular(jitter)

    def stamp_rate_hz(self, stamp_ns: np.ndarray) -> float:
        """Return the rate of a run of stamps as this session judges its own [Hz]."""
        return stamp_rate(stamp_ns, self.config.gap_factor, self.config.irregular_gap_s * NS)

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
        # No rate in the text: the one used is the mean over every step of the record,
        # known at its end (the result states it); the steps so far are only a window.
        gap_s = self.config.irregular_gap_s
        self._warn('irregular', f'irregular stamps (jitter {100 * jitter:.0f}% of the mean '
                   f'step, {NS / self.rate_hz / 1e6:.2f} ms where first seen): samples are '
                   f'taken as evenly spaced at the mean rate of all steps up to {gap_s} s '
                   '(the rate the results state); only longer steps count as gaps')
        self._refine_rate()

    def _refine_rate(self) -> None:
        """With irregular stamps, take the mean rate of all non-gap steps so far."""
        if self.stats.irregular_stamps and self._clock_n > 0 and self._clock_ns > 0:
            self.rate_hz = self._clock_n * NS / self._clock_ns

    def _judge_clock(self, settle: Callable[[], None]) -> None:
        """
        Judge a full window of steps: jitter, regularity, and a change of the period.

        ``settle`` passes the rows up to here on; it is called before anything that
        the rows after the window must see (a new rate or mode, or a warning, which
        must follow those rows' own warnings), so the order never depends on blocks.
        """
        steps = np.concatenate(self._step_buf)
        self._step_buf = []
        verdict = judge_steps(steps, self.config.gap_factor,
                              self.config.irregular_gap_s * NS)
        if verdict is None:
            return
        regular, period_ns, jitter = verdict
        self._note_jitters(np.array([jitter]), steps.size)
        if not regular or self.stats.irregular_stamps:
            settle()
        if not regular:
            self._flag_irregular(jitter)
        elif not self.stats.irregular_stamps:
            tol = self.config.rate_tolerance
            if abs(NS / self.rate_hz / period_ns - 1) > tol:
                # One warning per episode: a new one only when the period moves again.
                if self._off_period_ns is None or abs(self._off_period_ns / period_ns - 1) > tol:
                    settle()
                    self.stats.n_rate_changes += 1
                    self._warn('rate', f'sample rate changed: {NS / period_ns:.2f} Hz against '
                               f'the nominal {self.rate_hz:.2f} Hz (gaps are located with the '
                               'nominal rate)', once=False)
                self._off_period_ns = period_ns
            else:
                self._off_period_ns = None
        self._refine_rate()

    def _ordinary_windows(self, steps: np.ndarray) -> np.ndarray:
        """Which whole windows of ``steps`` only need their jitter noted (bool per window)."""
        if self.stats.irregular_stamps or self.rate_hz <= 0:
            return np.zeros(0, bool)
        return ordinary_windows(steps, _CLOCK_WINDOW, NS / self.rate_hz,
                                self.config.irregular_gap_s * NS, self.config.rate_tolerance)

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
        """
        Fill the short gaps, split at the long ones; ``steps[:skip]`` are no steps.

        A gap of regular stamps that lost at most ``max_fill_samples`` samples, with
        rows of the same segment before it, is short.
        """
        period_ns = NS / self.rate_hz
        irregular = self.stats.irregular_stamps
        limit = (self.config.irregular_gap_s * NS if irregular
                 else self.config.gap_factor * period_ns)
        real = steps[skip:]
        ok = real <= limit
        self._clock_n += int(ok.sum())
        self._clock_ns += int(real[ok].sum())
        gap_idx = np.flatnonzero(~ok) + skip
        lost = np.maximum(np.round(steps[gap_idx] / period_ns).astype(np.int64) - 1, 1)
        short = np.zeros(gap_idx.size, bool)
        if not irregular and self.config.max_fill_samples > 0:
            short = lost <= self.config.max_fill_samples
            if gap_idx.size and gap_idx[0] == 0 and (self._break_next or not self._last_row.size):
                short[0] = False    # the rows before it are not of this segment
        if short.any():
            self.stats.n_short_gaps += int(short.sum())
            self.stats.n_filled += int(lost[short].sum())
        start = 0
        for i in [int(i) for i in np.flatnonzero(~short)] + [gap_idx.size]:
            g = int(gap_idx[i]) if i < gap_idx.size else stamp_ns.size
            if g > start:
                inner = (gap_idx > start) | ((gap_idx == start) & (start == 0))
                inner &= (gap_idx < g) & short
                self._fill_and_pass(stamp_ns[start:g], samples[start:g],
                                    gap_idx[inner] - start, lost[inner], steps[gap_idx[inner]])
            if i < gap_idx.size:
                self.stats.n_gaps += 1
                self.stats.n_missing += int(lost[i])
                self._warn('gap', f'gap of {steps[g] / 1e9:.3f} s (~{int(lost[i])} samples) '
                           'in the stamps: the segment is split there, no term spans it',
                           once=False)
                self._break()
            start = g
        if short.any():
            self.stats.n_gaps += int(short.sum())
            self.stats.n_missing += int(lost[short].sum())
            self._note_missing(int(short.sum()))

    def _fill_and_pass(self, stamp_ns: np.ndarray, samples: np.ndarray, at: np.ndarray,
                       lost: np.ndarray, steps_at: np.ndarray) -> None:
        """Pass a run on with its short gaps filled (see :func:`fill_run`)."""
        self._n_rows += stamp_ns.size
        self._pass_on(*fill_run(stamp_ns, samples, self._last_row, at, lost, steps_at))
        self._last_row = samples[-1:].copy()

    def _note_missing(self, n: int = 0) -> None:
        """Count ``n`` short gaps in the one line on missing samples, with today's share."""
        if self.stats.n_short_gaps:
            self._warn.tally('missing', missing_line(self.stats, self._n_rows,
                                                     self.config.max_fill_samples), n)

    # ------------------------------------------------------------- checkpoint
    def state(self) -> dict:
        """Return the clock's state as JSON-able data."""
        return {
            'rate_hz': self.rate_hz, 'first_stamp_ns': self.first_stamp_ns,
            'last_stamp_ns': self.last_stamp_ns, 'newest_stamp_ns': self._newest_ns,
            'break_next': self._break_next,
            'far': None if self._far is None else [self._far[0], self._far[1].tolist()],
            'clock_n': self._clock_n, 'clock_ns': self._clock_ns,
            'step_buf': [int(s) for b in self._step_buf for s in b],
            'jitter_sq': self._jitter_sq, 'jitter_n': self._jitter_n,
            'off_period_ns': self._off_period_ns,
            'last_row': self._last_row.tolist(), 'n_rows': self._n_rows,
        }

    def restore(self, state) -> None:
        """Take the state of :meth:`state`; InputError when it is invalid."""
        ok = check_clock_state(state, set(self.state()), _CLOCK_WINDOW)
        self.rate_hz = ok['rate_hz']
        self.first_stamp_ns = ok['first_stamp_ns']
        self.last_stamp_ns = ok['last_stamp_ns']
        self._newest_ns = ok['newest_stamp_ns']
        self._break_next = ok['break_next']
        self._far = ok['far']
        steps = ok['step_buf']
        self._step_buf = [np.array(steps, dtype=np.int64)] if steps else []
        self._clock_n, self._clock_ns = ok['clock_n'], ok['clock_ns']
        self._jitter_n, self._jitter_sq = ok['jitter_n'], ok['jitter_sq']
        self._off_period_ns = ok['off_period_ns']
        self._last_row, self._n_rows = ok['last_row'], ok['n_rows']


def _nowhere(stamp_ns: np.ndarray, samples: np.ndarray, broken: bool) -> None:
    raise AssertionError('rows passed on outside split() or flush()')
