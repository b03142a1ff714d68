"""
Stamp clocks coarser than the sample period: recognised, and the stamps rebuilt.

A driver that stamps at a coarse resolution gives several samples one stamp (a 4 kHz
IMU stamped in millisecond ticks: four per tick), or steps of one and two ticks in a
fixed pattern (800 Hz in millisecond ticks: steps of 1, 1, 1 and 2 ticks).  Read as
they are, the repeated stamps are dropped as re-sent messages and the rate is the
tick's; the pattern of 800 Hz reads as 1 kHz that lost every fifth sample.

:class:`TickClock` stands before the stamp clock
(:class:`~imu_allan.pipeline.clock.StampClock`).  It holds the first rows until it can
judge them (:func:`coarse_tick`): stamps on a grid of ticks, steps that vary (repeated
stamps, or steps of several ticks that the stamp clock would read as jitter or gaps),
more or fewer than one sample per tick, and stamps that stay within a tick of a
straight line through the sample count (lost messages would leave it).  Regular stamps
are passed on from the first judgement, which comes within the rows the stamp clock
holds for its rate anyway, so clean records give the same numbers.

Coarse stamps are rebuilt from the sample count: sample j of a lock is stamped on the
line ``origin + j * period`` through the raw stamps (evenly spaced within and across
ticks).  The period is the count over the longest span (its error below a tick over
that span), or the one the user set (``SessionConfig.rate_hz``).  A raw stamp more than
a tick and a period ahead of the line marks lost samples (the count moves on by them, so
the stamp clock sees a gap); one further than a gap of ``irregular_gap_s`` either way
starts a new lock there, so the stamp clock judges the jump (a gap, a restart, a lone
outlier).  Lost samples that fit within one tick cannot be seen.
"""

import numpy as np

from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import HygieneStats, NS, SessionConfig, WarningLog
from imu_allan.pipeline.steps import is_int, MAX_JITTER, number

#: Rows a judgement needs at least, and the rows held at most for one.
MIN_ROWS, MAX_ROWS = 32, 4096
#: Ticks a judgement of coarse stamps needs at least (the count rate's first estimate
#: is within a tick over this many).
MIN_TICKS = 20
#: Stamps within this share of a tick of a whole number of ticks are on the grid.
GRID_TOLERANCE = 0.1
#: One sample per tick within this share is a clock that stamps every sample on its own
#: tick (a jittered 1 kHz IMU in millisecond ticks): a repeated stamp there is a late one, and
#: the stamp clock's rules apply.
ONE_PER_TICK = 0.02
#: The stamps of a quantised clock lie within one tick of the count's line; lost
#: messages (a regular clock's) drift away from it.  A little more than one tick for
#: jitter of the read times.
BAND_TICKS = 1.5
#: The period may move by this share per block while the rebuilt stamps follow a
#: refined count rate, so a refinement is never a step the stamp clock calls jitter.
MAX_SLEW = 0.01


def coarse_tick(stamp_ns: np.ndarray, samples: np.ndarray) -> tuple | None:
    """
    Judge whether stamps are quantised coarser than the sample period.

    Parameters
    ----------
    stamp_ns : numpy.ndarray
        Shape (n,), raw stamps [ns] in arrival order.
    samples : numpy.ndarray
        Shape (n, n_axes), the rows [unit] (a repeated stamp with a repeated row is a
        re-sent message, not a tick).

    Returns
    -------
    tuple of (float, float) or None
        ``(tick_ns, period_ns)``: the tick, and the period from a least-squares line
        through the stamps over the sample count [ns]; None when the stamps are not
        coarse (or cannot be judged: the stamp clock's rules apply).

    """
    t = np.asarray(stamp_ns, dtype=np.int64)
    steps = np.diff(t)
    if t.size < MIN_ROWS or (steps < 0).any():
        return None
    pos = steps[steps > 0].astype(np.float64)
    zero = steps == 0
    if pos.size < 2 or (not zero.any() and pos.max() <= (1 + MAX_JITTER) * pos.min()):
        return None     # regular: the stamp clock reads these as they are
    if zero.any():
        resent = (samples[1:][zero] == samples[:-1][zero]).all(axis=1)
        if resent.mean() > 0.5:
            return None
    lo = pos.min()
    tick = float(pos[pos <= (1 + GRID_TOLERANCE) * lo].mean())
    k = pos / tick
    if np.abs(k - np.round(k)).max() > GRID_TOLERANCE:
        return None
    idx = np.arange(t.size, dtype=np.float64)
    rel = (t - t[0]).astype(np.float64)
    period, offset = np.polyfit(idx, rel, 1)
    if not period > 0 or abs(tick / period - 1) <= ONE_PER_TICK:
        return None
    resid = rel - (offset + period * idx)
    if resid.max() - resid.min() > BAND_TICKS * tick:
        return None
    return tick, float(period)


# Long because it is one stateful stage: the held rows, the judgement and the lock that
# rebuilds the stamps, with its checkpoint; each step is a short method.
class TickClock:
    """
    Recognise a coarse stamp clock and rebuild its stamps from the sample count.

    Parameters
    ----------
    config : SessionConfig
        Its ``rate_hz`` (a set rate is the rebuilt period) and ``irregular_gap_s``.
    stats : HygieneStats
        ``coarse_tick_s`` and ``n_lost_in_ticks`` are set here.
    warn : WarningLog
        Where the warning goes.

    """

    def __init__(self, config: SessionConfig, stats: HygieneStats, warn: WarningLog):
        self.config = config
        self.stats = stats
        self._warn = warn
        self.mode = 'detect'       # then 'plain' (passed on as they are) or 'coarse'
        self._held_t: list[np.ndarray] = []
        self._held_y: list[np.ndarray] = []
        self.tick_ns = 0.0
        self.period_ns = 0.0
        self._fixed = config.rate_hz > 0
        # The lock: the raw stamp and count of its origin, the next sample's count, and
        # the last rebuilt stamp (None: the next one starts the line).
        self._origin_ns = 0
        self._origin_idx = 0
        self._next_idx = 0
        self._last_out: float | None = None
        self._last_idx = 0

    @property
    def rate_hz(self) -> float:
        """Return the rebuilt rate [Hz]; 0 unless the stamps are coarse."""
        return NS / self.period_ns if self.mode == 'coarse' else 0.0

    @staticmethod
    def count_rate_hz(stamp_ns: np.ndarray) -> float:
        """Return the rate of the sample count over the span of raw stamps [Hz] (0: none)."""
        t = np.asarray(stamp_ns, dtype=np.int64)
        span = float(t.max() - t.min()) if t.size > 1 else 0.0
        return (t.size - 1) * NS / span if span > 0 else 0.0

    def take(self, stamp_ns: np.ndarray, samples: np.ndarray) -> list:
        """
        Return the rows to pass on as [(stamp_ns, samples)], stamps rebuilt if coarse.

        Rows are held (an empty list) until the stamps can be judged.
        """
        if self.mode == 'plain':
            return [(stamp_ns, samples)]
        if self.mode == 'coarse':
            return [(self._rebuild(stamp_ns), samples)]
        self._held_t.append(stamp_ns)
        self._held_y.append(samples)
        return self._judge(final=False)

    def flush(self) -> list:
        """Return the rows still held (the end of a recording), judged on what there is."""
        if self.mode != 'detect' or not self._held_t:
            return []
        return self._judge(final=True)

    def _judge(self, final: bool) -> list:
        """Judge the held rows once they can be; return them, or [] while waiting."""
        t = np.concatenate(self._held_t)
        if t.size < MIN_ROWS and not final:
            return []
        y = np.concatenate(self._held_y)
        steps = np.diff(t)
        fast_regular = (steps.size >= MIN_ROWS - 1 and steps.min() > 0
                        and steps.max() <= (1 + MAX_JITTER) * steps.min())
        found = None if fast_regular else coarse_tick(t, y)
        if not (final or t.size >= MAX_ROWS):
            # Wait for enough ticks: to see several samples per tick, or to time them.
            if found is None and not fast_regular and np.unique(t).size <= MIN_TICKS:
                return []
            if found is not None and (t[-1] - t[0]) < MIN_TICKS * found[0]:
                return []
        self._held_t, self._held_y = [], []
        if found is None:
            self.mode = 'plain'
            if t.size > 1 and t[0] == t[-1] and (steps == 0).all():
                self._warn('stamps-constant', f'the first {t.size:,} stamps are all {t[0]} '
                           'ns: they carry no time (a publisher that does not fill '
                           'header.stamp?), and every sample after the first is a repeated '
                           "stamp; give the samples times (a bag's log times are used "
                           'when its header stamps are one value)')
            return [(t, y)]
        self._start(found, t)
        return [(self._rebuild(t), y)]

    def _start(self, found: tuple, t: np.ndarray) -> None:
        tick_ns, period_ns = found
        self.mode = 'coarse'
        self.tick_ns = tick_ns
        self.period_ns = NS / self.config.rate_hz if self._fixed else period_ns
        self._origin_ns, self._origin_idx, self._next_idx = int(t[0]), 0, 0
        self._last_out = None
        per_tick = tick_ns / self.period_ns
        self.stats.coarse_tick_s = tick_ns / NS
        how = ('the rate set' if self._fixed else
               'the rate of the sample count over the longest span')
        self._warn('coarse-ticks', f'coarse stamps: the stamps come in ticks of '
                   f'{tick_ns / 1e6:.4g} ms, {per_tick:.3g} samples per tick at '
                   f'{NS / self.period_ns:.6g} Hz: every sample is kept, stamped evenly at '
                   f'{how} (set --rate to override it)')

    def _rebuild(self, stamp_ns: np.ndarray) -> np.ndarray:
        """Return the rebuilt stamps of a block [ns] (int64), following the lock."""
        s = stamp_ns.astype(np.int64)
        out = np.empty(s.size)
        start = 0
        while start < s.size:
            # A piece no longer than the lock's span so far: the period's error over that
            # span (under a tick) moves the line by under a tick over the piece.
            stop = min(s.size, start + max(MIN_ROWS, self._next_idx - self._origin_idx))
            idx, end, lone = self._count(s[start:stop + 1], stop - start)
            if end:
                self._next_idx = int(idx[end - 1]) + 1
                kept = [k for k in range(end - 1, -1, -1) if k not in lone][:1]
                if kept and not self._fixed:
                    self._refine(int(s[start + kept[0]]), int(idx[kept[0]]))
                line = self._origin_ns + (idx[:end] - self._origin_idx) * self.period_ns
                out[start:start + end] = self._follow(line, idx[:end])
                for k in lone:
                    out[start + k] = s[start + k]
            if start + end < stop:
                # A jump the stamp clock must judge (a gap, a restart, an outlier): the
                # raw stamp starts a new lock.
                self._origin_ns, self._origin_idx = int(s[start + end]), self._next_idx
                self._last_out = None
            start += end
        return np.round(out).astype(np.int64)

    def _count(self, s: np.ndarray, n: int) -> tuple:
        """
        Return the sample counts of rows ``s[:n]``, the rows the lock keeps, lone outliers.

        A raw stamp more than a tick and a period ahead of the line marks lost samples:
        the count moves on by them.  One further than a long gap either way is a lone
        outlier when the row after it (``s[n]`` at the end, when there) is back on the
        line (its raw stamp goes on, for the stamp clock to drop); otherwise it ends the
        rows the lock keeps.
        """
        idx = self._next_idx + np.arange(s.size, dtype=np.int64)
        far_ns = max(self.config.irregular_gap_s * NS, 100.0 * self.period_ns)
        ahead_ns = 1.5 * self.tick_ns + self.period_ns
        lone: list[int] = []
        pos = 0
        while pos < n:
            d = (s[pos:n] - self._origin_ns) - (idx[pos:n] - self._origin_idx) * self.period_ns
            bad = np.flatnonzero((d > ahead_ns) | (d < -far_ns))
            if not bad.size:
                break
            i, off = pos + int(bad[0]), float(d[bad[0]])
            if abs(off) > far_ns:
                back = (i + 1 < s.size and abs((s[i + 1] - self._origin_ns) - (
                    idx[i + 1] - self._origin_idx) * self.period_ns) <= ahead_ns)
                if not back:
                    return idx[:n], i, lone
                lone.append(i)
            else:
                lost = max(int(round(off / self.period_ns)), 1)
                idx[i:] += lost
                self.stats.n_lost_in_ticks += lost
            pos = i + 1
        return idx[:n], n, lone

    def _refine(self, newest_ns: int, newest_idx: int) -> None:
        """Take the count rate over the lock's whole span (within a tick over it)."""
        span = newest_idx - self._origin_idx
        if span * self.period_ns > 50 * self.tick_ns:
            self.period_ns = (newest_ns - self._origin_ns) / span

    def _follow(self, line: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """
        Return stamps that follow the lock's line without a jump at a refinement.

        The line of a refined period is reached by a period changed by at most
        :data:`MAX_SLEW` for the block; jumps of the line itself (lost samples, a new
        lock) are kept.
        """
        if self._last_out is None:
            self._last_out = float(line[-1])
            self._last_idx = int(idx[-1])
            return line
        n = (idx - self._last_idx).astype(np.float64)
        # Where the count moved on (lost samples) the line is taken as it is.
        k = (line[-1] - self._last_out) / max(n[-1], 1.0)
        k = min(max(k, (1 - MAX_SLEW) * self.period_ns), (1 + MAX_SLEW) * self.period_ns)
        out = self._last_out + n * k
        self._last_out, self._last_idx = float(out[-1]), int(idx[-1])
        return out

    # ------------------------------------------------------------- checkpoint
    def state(self) -> dict:
        """
        Return the stage's state as JSON-able data.

        Rows held for the judgement are not saved: a session is saved once its rate is
        known, and only a set rate (``rate_hz``) makes it known before the judgement.
        """
        return {'mode': self.mode, 'tick_ns': self.tick_ns, 'period_ns': self.period_ns,
                'fixed': self._fixed, 'origin_ns': self._origin_ns,
                'origin_idx': self._origin_idx, 'next_idx': self._next_idx,
                'last_out': self._last_out,
                'last_idx': self._last_idx}

    def restore(self, state) -> None:
        """Take the state of :meth:`state` (None: saved before this stage, plain)."""
        if state is None:
            self.mode = 'plain'
            return
        if not isinstance(state, dict) or set(state) != set(self.state()):
            raise InputError('the tick clock state is incomplete')
        if state['mode'] not in ('detect', 'plain', 'coarse'):
            raise InputError(f'the tick clock mode {state["mode"]!r} is invalid')
        ints = [state[k] for k in ('origin_ns', 'origin_idx', 'next_idx', 'last_idx')]
        if not all(is_int(v) for v in ints):
            raise InputError('the tick clock counts are invalid')
        tick = number(state['tick_ns'], 'tick_ns')
        period = number(state['period_ns'], 'period_ns')
        last = state['last_out']
        if state['mode'] == 'coarse' and not (tick > 0 and period > 0):
            raise InputError('the tick clock has no period')
        self.mode, self.tick_ns, self.period_ns = state['mode'], tick, period
        self._fixed = bool(state['fixed'])
        self._origin_ns, self._origin_idx, self._next_idx, self._last_idx = ints
        self._last_out = None if last is None else number(last, 'last_out')
        self._held_t, self._held_y = [], []
