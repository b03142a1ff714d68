"""
The one analysis session that both the live node and the offline readers feed.

A :class:`Session` takes blocks of ``(stamp_ns (n,), samples (n, 6))`` in AXES order,
checks them (rate, gaps, duplicate or out-of-order stamps, NaN/Inf, saturation, frozen
axes, motion), streams the clean samples through one
:class:`~imu_allan.core.accumulator.AllanAccumulator`, and fits the noise model on demand.
Because every mode goes through this object, the numbers cannot differ between them.
"""

from dataclasses import asdict, dataclass, field, fields, replace
import json
import math
from pathlib import Path
from typing import Callable

import numpy as np

from imu_allan import AXES
from imu_allan.atomic import write_atomic
from imu_allan.core.accumulator import AllanAccumulator
from imu_allan.core.allan import AllanCurve
from imu_allan.errors import InputError

N_AXES = len(AXES)
_NS = 1_000_000_000
#: Stamp steps per judged window (jitter, regularity and rate changes).  Fixed step
#: counts, not blocks, so that the verdicts do not depend on how the record is cut up.
_CLOCK_WINDOW = 100
#: Relative jitter of the stamp steps above which the stamps are irregular.
_MAX_JITTER = 0.25

#: How a session reacts to motion (the robot was bumped or driven).
MOTION_POLICIES = ('warn', 'pause', 'restart')


@dataclass(frozen=True)
class SessionConfig:
    """
    Settings of the input checks and of the accumulator (SI units throughout).

    Attributes
    ----------
    rate_hz : float
        Nominal sample rate [Hz]; 0 estimates it from the first ``rate_window``
        samples (period of the regular steps with gaps counted as whole periods;
        with irregular stamps, the mean rate, robust to bursty arrival stamps).
    rate_window : int
        Samples used to estimate the rate [samples].
    gap_factor : float
        A step longer than ``gap_factor`` nominal periods is a gap (regular stamps).
    irregular_gap_s : float
        With irregular (jittery) stamps, only a step longer than this is a gap [s].
    rate_tolerance : float
        Relative deviation of the sample period, judged over windows of 100 stamp
        steps, that counts as a rate change.
    gyro_range_rad_s, accel_range_m_s2 : float
        Sensor full scale [rad/s], [m/s^2]; |value| >= 0.999 of it is saturated;
        0 disables the check.
    frozen_samples : int
        An axis repeating one value this many samples in a row is frozen [samples].
    motion_window_s : float
        Window over which motion statistics are computed [s].
    motion_gyro_rad_s : float
        A window mean that departs this far from the reference is motion [rad/s].
    motion_accel_m_s2 : float
        The same for the accelerometers (tilt or acceleration) [m/s^2].
    motion_std_ratio : float
        A window standard deviation this many times the reference one is motion
        (vibration from driving).
    on_motion : str
        'warn' keeps the samples, 'pause' drops them until the IMU is still again,
        'restart' discards the segment collected so far and starts again.
    settle_s : float
        Stillness needed after motion before samples are used again [s].
    exact_max_m : int
        Largest cluster size the accumulator computes exactly [samples]; 0 = default.

    """

    rate_hz: float = 0.0
    rate_window: int = 200
    gap_factor: float = 1.5
    irregular_gap_s: float = 2.0
    rate_tolerance: float = 0.05
    gyro_range_rad_s: float = 0.0
    accel_range_m_s2: float = 0.0
    frozen_samples: int = 200
    motion_window_s: float = 1.0
    motion_gyro_rad_s: float = 0.05
    motion_accel_m_s2: float = 0.5
    motion_std_ratio: float = 8.0
    on_motion: str = 'pause'
    settle_s: float = 5.0
    exact_max_m: int = 0

    def __post_init__(self):
        if self.on_motion not in MOTION_POLICIES:
            raise InputError(f'on_motion must be one of {", ".join(MOTION_POLICIES)}, '
                             f'not {self.on_motion!r}')
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name != 'on_motion' and (not math.isfinite(value) or value < 0):
                raise InputError(f'{f.name} must be a finite number >= 0, not {value!r}')


@dataclass
class HygieneStats:
    """
    Counters of what the input checks found; all counts are in samples unless named.

    Attributes
    ----------
    n_received, n_used : int
        Samples offered to the session, and samples that reached the accumulator.
    n_nonfinite, n_duplicate, n_out_of_order, n_saturated, n_motion_dropped : int
        Samples dropped for each reason.
    n_gaps, n_missing : int
        Gaps in the stamps, and the samples they are estimated to have lost.
    n_rate_changes, n_motion_events, n_restarts : int
        Episodes of a changed rate, of motion, and motion restarts.
    frozen_axes, saturated_axes : list of str
        Axes seen frozen or saturated.
    jitter_rel : float
        Standard deviation of the stamp steps (gaps left out) over the period,
        pooled over the windows judged so far.
    irregular_stamps : bool
        True when the stamps are too jittery to locate gaps step by step.

    """

    n_received: int = 0
    n_used: int = 0
    n_nonfinite: int = 0
    n_duplicate: int = 0
    n_out_of_order: int = 0
    n_saturated: int = 0
    n_motion_dropped: int = 0
    n_gaps: int = 0
    n_missing: int = 0
    n_rate_changes: int = 0
    n_motion_events: int = 0
    n_restarts: int = 0
    frozen_axes: list = field(default_factory=list)
    saturated_axes: list = field(default_factory=list)
    jitter_rel: float = 0.0
    irregular_stamps: bool = False


class Session:
    """
    Input checks plus streaming Allan accumulation for the six IMU axes.

    Parameters
    ----------
    config : SessionConfig
        Check and accumulator settings.
    on_warning : callable, optional
        Called with each new one-line warning (the node logs it; the CLI prints it).

    """

    def __init__(self, config: SessionConfig = SessionConfig(),
                 on_warning: Callable[[str], None] | None = None):
        self.config = config
        self.stats = HygieneStats()
        self._on_warning = on_warning
        self._warn_text: dict[str, str] = {}
        self._warn_count: dict[str, int] = {}
        self.rate_hz = float(config.rate_hz)
        self.acc: AllanAccumulator | None = None
        self._pending_t: list[np.ndarray] = []
        self._pending_y: list[np.ndarray] = []
        self.first_stamp_ns: int | None = None
        self.last_stamp_ns: int | None = None
        self._newest_ns: int | None = None
        self._nan_break = False
        # Stamp clock: steps waiting for their window's verdict, and the count and sum
        # of the non-gap steps (the mean rate of irregular stamps comes from these, so
        # neither gaps nor a resume across lost samples bias it).
        self._step_buf: list[np.ndarray] = []
        self._clock_n = 0
        self._clock_ns = 0
        self._jitter_sq = 0.0
        self._jitter_n = 0
        self._off_period_ns: float | None = None
        # Motion reference: per-axis mean and std of the first still window.
        self._ref_mean: np.ndarray | None = None
        self._ref_std: np.ndarray | None = None
        self._win_t: list[np.ndarray] = []
        self._win_y: list[np.ndarray] = []
        self._pending: list[np.ndarray] = []   # still samples on their way to the accumulator
        self._moving = False
        self._in_motion = False
        self._still_since_ns: int | None = None
        self._last_value = np.full(N_AXES, np.nan)
        self._repeat = np.zeros(N_AXES, dtype=np.int64)
        if self.rate_hz > 0:
            self._start_accumulator()

    # ------------------------------------------------------------------ input
    def add(self, stamp_ns, samples) -> None:
        """
        Check a block of samples and accumulate the clean ones.

        Parameters
        ----------
        stamp_ns : array_like
            Shape (n,), header stamps [ns] (int64).
        samples : array_like
            Shape (n, 6), rates [rad/s] and accelerations [m/s^2] in AXES order.

        """
        stamp_ns, samples = _as_block(stamp_ns, samples)
        n = stamp_ns.size
        if n == 0:
            return
        self.stats.n_received += n
        finite = np.isfinite(samples).all(axis=1)
        if not finite.all():
            bad = int(n - finite.sum())
            self.stats.n_nonfinite += bad
            self._warn('nonfinite', f'{bad} samples with NaN/Inf values dropped '
                       '(the segment is broken there)')
        # A NaN sample is a missing sample: the segment breaks there.  A repeated or
        # out-of-order stamp is a re-sent message: dropping it breaks nothing.
        for t_part, y_part, broken in _split_runs(stamp_ns, samples, finite):
            if (broken or self._nan_break) and self.acc is not None:
                self._flush_motion(break_after=True)
            self._nan_break = False
            ok = self._monotonic_mask(t_part)
            self._ingest(t_part[ok], y_part[ok])
        # NaN rows that end a block break the segment before the next block's rows, just
        # as they would inside one block.
        self._nan_break = self._nan_break or not finite[-1]

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

    def _ingest(self, stamp_ns: np.ndarray, samples: np.ndarray) -> None:
        if stamp_ns.size == 0:
            return
        if self.first_stamp_ns is None:
            self.first_stamp_ns = int(stamp_ns[0])
        if self.acc is None:
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
        self._start_accumulator()
        self._ingest_regular(t[:k], y[:k], judged=True)
        if k < t.size:
            self._ingest_regular(t[k:], y[k:])

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
        self._jitter_sq += jitter ** 2 * n_steps
        self._jitter_n += n_steps
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
        jitter = w.std(axis=1) / w.mean(axis=1)
        self._jitter_sq += float(np.sum(jitter ** 2)) * _CLOCK_WINDOW
        self._jitter_n += steps.size
        self.stats.jitter_rel = math.sqrt(self._jitter_sq / self._jitter_n)
        self._off_period_ns = None

    def _start_accumulator(self) -> None:
        kwargs = {'exact_max_m': self.config.exact_max_m} if self.config.exact_max_m else {}
        self.acc = AllanAccumulator(N_AXES, self.rate_hz, **kwargs)

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
            if not self._step_buf:
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
        for g in list(gap_idx) + [stamp_ns.size]:
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

    def _accumulate(self, stamp_ns: np.ndarray, samples: np.ndarray) -> None:
        """Gap-free run: saturation split, frozen check, then the motion stage."""
        limits = np.array([self.config.gyro_range_rad_s] * 3 + [self.config.accel_range_m_s2] * 3)
        sat = (np.abs(samples) >= 0.999 * limits) & (limits > 0)
        rows = sat.any(axis=1)
        if rows.any():
            for j in np.flatnonzero(sat.any(axis=0)):
                if AXES[j] not in self.stats.saturated_axes:
                    self.stats.saturated_axes.append(AXES[j])
            self.stats.n_saturated += int(rows.sum())
            self._warn('saturated', f'{int(rows.sum())} saturated samples on '
                       f'{", ".join(self.stats.saturated_axes)} dropped (segment split there)',
                       once=False)
        for t_part, y_part, broken in _split_runs(stamp_ns, samples, ~rows):
            if broken:
                self._flush_motion(break_after=True)
            self._check_frozen(y_part)
            self._motion_stage(t_part, y_part)

    def _check_frozen(self, samples: np.ndarray) -> None:
        # Length of the run of identical values that ends each axis' block.
        same = np.diff(samples, axis=0, prepend=self._last_value[None, :]) == 0
        for j in range(N_AXES):
            col = same[:, j]
            if col.all():
                run = longest = self._repeat[j] + col.size
            else:
                breaks = np.flatnonzero(~col)
                runs = np.diff(np.concatenate((breaks, [col.size]))) - 1
                longest = max(self._repeat[j] + breaks[0], int(runs.max()))
                run = col.size - 1 - breaks[-1]
            self._repeat[j] = run
            if longest >= self.config.frozen_samples and AXES[j] not in self.stats.frozen_axes:
                self.stats.frozen_axes.append(AXES[j])
                self._warn(f'frozen-{AXES[j]}', f'{AXES[j]} is frozen: one value repeated for '
                           f'{longest} samples (a dead or disconnected sensor, or a replayed '
                           'constant)')
        self._last_value = samples[-1].copy()

    def _motion_stage(self, stamp_ns: np.ndarray, samples: np.ndarray) -> None:
        """
        Hold samples until their motion window is judged, then accumulate or drop them.

        Rows wait at most one window (``motion_window_s``), so no sample reaches the
        accumulator before the check that could reject it.
        """
        self._win_t.append(stamp_ns)
        self._win_y.append(samples)
        t = np.concatenate(self._win_t)
        y = np.concatenate(self._win_y)
        win = max(int(round(self.config.motion_window_s * self.rate_hz)), 2)
        n_full = (y.shape[0] // win) * win
        self._win_t, self._win_y = [t[n_full:]], [y[n_full:]]
        if n_full:
            # The statistics of all whole windows at once; the decisions stay in order.
            blocks = y[:n_full].reshape(-1, win, N_AXES)
            means, stds = blocks.mean(axis=1), blocks.std(axis=1)
            for i, k in enumerate(range(0, n_full, win)):
                self._judge_window(t[k:k + win], y[k:k + win], means[i], stds[i])
        self._drain()

    def _flush_motion(self, break_after: bool = False) -> None:
        """Accumulate the held partial window as still (end of data or a segment break)."""
        if self._win_y and self._win_y[0].shape[0]:
            t, y = np.concatenate(self._win_t), np.concatenate(self._win_y)
            if not self._moving:
                self._use(t, y)
        self._drain()
        self._win_t, self._win_y = [], []
        if break_after and self.acc is not None:
            self.acc.break_segment()

    def _judge_window(self, t: np.ndarray, y: np.ndarray, mean: np.ndarray,
                      std: np.ndarray) -> None:
        moving = self._window_moving(mean, std)
        if moving and not self._in_motion:
            self.stats.n_motion_events += 1
        self._in_motion = moving
        policy = self.config.on_motion
        if policy == 'warn':
            self._use(t, y)
            return
        if moving:
            self._still_since_ns = None
            self.stats.n_motion_dropped += t.size
            if not self._moving:
                self._moving = True
                self._drain()
                self.acc.break_segment()
                if policy == 'restart':
                    self.stats.n_restarts += 1
                    self._start_accumulator()
                    self.stats.n_used = 0
            return
        if self._moving:
            # Still again: wait settle_s before trusting the samples.
            if self._still_since_ns is None:
                self._still_since_ns = int(t[0])
            if t[-1] - self._still_since_ns < self.config.settle_s * _NS:
                self.stats.n_motion_dropped += t.size
                return
            self._moving = False
            self._warn('resume', 'the IMU is still again: accumulation resumed', once=False)
        self._use(t, y)

    def _use(self, t: np.ndarray, y: np.ndarray) -> None:
        # Held until _drain: consecutive still windows reach the accumulator in one call.
        self._pending.append(y)
        self.stats.n_used += t.size

    def _drain(self) -> None:
        """Pass the samples :meth:`_use` holds to the accumulator (one call)."""
        if self._pending:
            self.acc.add(self._pending[0] if len(self._pending) == 1
                         else np.concatenate(self._pending))
            self._pending = []

    def _window_moving(self, mean: np.ndarray, std: np.ndarray) -> bool:
        """Whether one motion window moved, from its per-axis mean and std (6,) each."""
        thr = np.array([self.config.motion_gyro_rad_s] * 3 + [self.config.motion_accel_m_s2] * 3)
        if self._ref_mean is None:
            # Quantised sensors can show zero spread: floor the reference noise.
            self._ref_mean, self._ref_std = mean, np.maximum(std, thr / 20)
            return False
        dev = np.abs(mean - self._ref_mean)
        ratio = std / self._ref_std
        moving_axes = (dev > thr) | (ratio > self.config.motion_std_ratio)
        if moving_axes.any():
            names = ', '.join(AXES[j] for j in np.flatnonzero(moving_axes))
            action = {'warn': 'samples kept (on_motion=warn)',
                      'pause': 'accumulation paused until still',
                      'restart': 'restarting from scratch once still'}[self.config.on_motion]
            self._warn('motion', f'motion detected on {names} (mean off by up to '
                       f'{dev.max():.3g}, noise x{ratio.max():.1f}): the IMU is not '
                       f'stationary; {action}', once=False)
            return True
        # Follow slow bias drift so that temperature drift is not taken for motion.
        self._ref_mean = 0.99 * self._ref_mean + 0.01 * mean
        return False

    def break_segment(self) -> None:
        """
        End the contiguous segment here (e.g. after a restart that lost samples).

        The samples held for the motion check count as still, as at a gap, and no
        Allan term spans the break.
        """
        self._flush_motion(break_after=True)

    def flush(self) -> None:
        """Accumulate samples still held back (call at the end of a recording)."""
        if self.acc is None and self._pending_t:
            if sum(t.size for t in self._pending_t) >= 3:
                self._begin()
            else:
                self._pending_t, self._pending_y = [], []
        self._refine_rate()
        self._flush_motion()

    # ----------------------------------------------------------------- output
    @property
    def duration_s(self) -> float:
        """Duration of the samples used so far [s]."""
        return self.stats.n_used / self.rate_hz if self.rate_hz > 0 else 0.0

    def curve(self, confidence: float = 0.95) -> AllanCurve | None:
        """Allan curve of the samples used so far, or None before any tau is computable."""
        if self.acc is None or self.acc.n_samples < 4:
            return None
        return self.acc.curve(confidence=confidence)

    @property
    def warnings(self) -> list[str]:
        """One line per kind of problem seen, with how often it happened."""
        return list(self._warn_text.values())

    def _warn(self, key: str, text: str, once: bool = True) -> None:
        n = self._warn_count.get(key, 0) + 1
        self._warn_count[key] = n
        if once and n > 1:
            return
        self._warn_text[key] = text if n == 1 else f'{text} [{n} times so far]'
        # Tell the user at 1, 2, 4, 8 ... occurrences: informative without flooding.
        if self._on_warning is not None and n & (n - 1) == 0:
            self._on_warning(self._warn_text[key])

    # ------------------------------------------------------------- checkpoint
    def _restore_clock(self, meta: dict, rate_hz: float) -> None:
        """Restore the stamp-clock state; older checkpoints get a neutral equivalent."""
        self._newest_ns = meta.get('newest_stamp_ns', meta.get('last_stamp_ns'))
        self._nan_break = bool(meta.get('nan_break', False))
        if 'clock_n' in meta:
            self._clock_n = int(meta['clock_n'])
            self._clock_ns = int(meta['clock_ns'])
            self._jitter_sq = float(meta['jitter_sq'])
            self._jitter_n = int(meta['jitter_n'])
            buf = np.array(meta['step_buf'], dtype=np.int64)
            self._step_buf = [buf] if buf.size else []
            off = meta['off_period_ns']
            self._off_period_ns = None if off is None else float(off)
            return
        # Version 1 kept no step counts: weigh the saved rate as if every used sample
        # had been one step at it, so a later mean-rate refinement stays anchored.
        self._clock_n = int(self.stats.n_used)
        self._clock_ns = int(round(self._clock_n * _NS / rate_hz))
        self._jitter_n = self._clock_n
        self._jitter_sq = self.stats.jitter_rel ** 2 * self._clock_n

    def save_state(self, path) -> None:
        """
        Save the whole session atomically (accumulator state plus counters; no pickle).

        Parameters
        ----------
        path : str or Path
            Target file; written to a temporary file first, then renamed.

        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if self.acc is None:
            return
        meta = {
            'version': 3, 'rate_hz': self.rate_hz, 'axes': list(AXES),
            'config': asdict(self.config), 'stats': asdict(self.stats),
            'warn_text': self._warn_text, 'warn_count': self._warn_count,
            'first_stamp_ns': self.first_stamp_ns,
            'last_stamp_ns': self.last_stamp_ns,
            # Everything the stamp checks and the rate estimate carry over (version 2).
            'newest_stamp_ns': self._newest_ns,
            'clock_n': self._clock_n, 'clock_ns': self._clock_ns,
            'step_buf': [int(s) for b in self._step_buf for s in b],
            'jitter_sq': self._jitter_sq, 'jitter_n': self._jitter_n,
            'off_period_ns': self._off_period_ns, 'nan_break': self._nan_break,
            'ref_mean': None if self._ref_mean is None else self._ref_mean.tolist(),
            'ref_std': None if self._ref_std is None else self._ref_std.tolist(),
            # The motion and frozen-axis checks in progress (version 3).
            'moving': self._moving, 'in_motion': self._in_motion,
            'still_since_ns': self._still_since_ns, 'repeat': self._repeat.tolist(),
        }
        # The accumulator's state in memory, under the keys its own file uses.
        acc_meta, acc_arrays = self.acc.to_state()
        arrays = {f'acc__{k}': v for k, v in acc_arrays.items()}
        arrays['acc__meta'] = np.array(json.dumps(acc_meta))
        arrays['session_meta'] = np.array(json.dumps(meta))
        # Samples held for the motion check of a window not yet complete (version 3).
        arrays['held_stamp_ns'] = np.concatenate(self._win_t or [np.empty(0, np.int64)])
        arrays['held_samples'] = np.concatenate(self._win_y or [np.empty((0, N_AXES))])
        arrays['last_value'] = self._last_value
        write_atomic(path, lambda f: np.savez(f, **arrays))

    @classmethod
    def load_state(cls, path, config: SessionConfig | None = None,
                   on_warning: Callable[[str], None] | None = None) -> 'Session':
        """
        Restore a session saved by :meth:`save_state`.

        Parameters
        ----------
        path : str or Path
            Checkpoint file.
        config : SessionConfig, optional
            Settings for the resumed session; a rate that differs from the saved one
            by more than ``rate_tolerance`` refuses the resume with an InputError.
        on_warning : callable, optional
            Warning sink of the new session.

        Returns
        -------
        Session
            The restored session, ready for more samples.

        """
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z['session_meta']))
                acc_arrays = {k[5:]: z[k] for k in z.files if k.startswith('acc__')}
                held = {k: z[k] for k in ('held_stamp_ns', 'held_samples', 'last_value')
                        if k in z.files}
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f'cannot read checkpoint {path}: {exc}') from None
        try:
            return cls._restore(path, meta, acc_arrays, held, config, on_warning)
        except InputError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise InputError(f'checkpoint {path} is damaged: {exc!r}') from None

    @classmethod
    def _restore(cls, path, meta: dict, acc_arrays: dict, held: dict,
                 config: SessionConfig | None,
                 on_warning: Callable[[str], None] | None) -> 'Session':
        if not isinstance(meta, dict):
            raise TypeError('its metadata is not a JSON object')
        if meta.get('axes') != list(AXES):
            raise InputError(f'checkpoint {path} has axes {meta.get("axes")}, not {list(AXES)}')
        saved_cfg = SessionConfig(**meta['config'])
        config = config or saved_cfg
        rate = float(meta['rate_hz'])
        if config.rate_hz > 0 and abs(config.rate_hz / rate - 1) > config.rate_tolerance:
            raise InputError(f'checkpoint {path} was taken at {rate:.3f} Hz but the rate is now '
                             f'{config.rate_hz:.3f} Hz: not resuming')
        try:
            acc = AllanAccumulator.from_state(
                json.loads(str(acc_arrays['meta'])),
                {k: v for k, v in acc_arrays.items() if k != 'meta'})
        except InputError as exc:
            raise InputError(f'checkpoint {path}: accumulator state: {exc}') from None
        session = cls(replace(config, rate_hz=rate), on_warning=on_warning)
        session.acc = acc
        session.stats = HygieneStats(**meta['stats'])
        session._warn_text = dict(meta['warn_text'])
        session._warn_count = {k: int(v) for k, v in meta['warn_count'].items()}
        session.first_stamp_ns = meta['first_stamp_ns']
        session.last_stamp_ns = meta['last_stamp_ns']
        session._restore_clock(meta, rate)
        if meta['ref_mean'] is not None:
            session._ref_mean = np.array(meta['ref_mean'])
            session._ref_std = np.array(meta['ref_std'])
        if 'held_samples' in held:  # version 3; older checkpoints lost these
            rows = held['held_stamp_ns'].shape
            if (held['held_samples'].shape != rows + (N_AXES,)
                    or held['last_value'].shape != (N_AXES,) or len(meta['repeat']) != N_AXES):
                raise ValueError('the held samples or axis counters have the wrong shape')
            if rows[0]:
                session._win_t = [held['held_stamp_ns'].astype(np.int64)]
                session._win_y = [held['held_samples'].astype(np.float64)]
            session._last_value = held['last_value'].astype(np.float64)
            session._repeat = np.array(meta['repeat'], dtype=np.int64)
            session._moving = bool(meta['moving'])
            session._in_motion = bool(meta['in_motion'])
            session._still_since_ns = meta['still_since_ns']
        return session


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


def _as_block(stamp_ns, samples) -> tuple[np.ndarray, np.ndarray]:
    """Validate a block's types and shapes; return int64 stamps and float64 samples."""
    try:
        t = np.asarray(stamp_ns)
        y = np.asarray(samples, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f'samples must be numbers: {exc}') from None
    if t.dtype.kind not in 'iu':
        if t.dtype.kind == 'f' and np.all(np.isfinite(t)):
            t = np.round(t).astype(np.int64)
        else:
            raise InputError(f'stamps must be integer nanoseconds, got dtype {t.dtype}')
    t = t.astype(np.int64, copy=False).reshape(-1)
    if y.ndim == 1 and y.size == N_AXES and t.size == 1:
        y = y[None, :]
    if y.ndim != 2 or y.shape[1] != N_AXES or y.shape[0] != t.size:
        raise InputError(f'a block needs stamps (n,) and samples (n, {N_AXES}); got '
                         f'{t.shape} and {y.shape}')
    return t, y


def _split_runs(stamp_ns: np.ndarray, samples: np.ndarray, keep: np.ndarray):
    """
    Yield the runs of kept rows as (stamps, samples, broken).

    ``broken`` is True when rows were dropped just before the run, i.e. the run does
    not continue the previous data.
    """
    if keep.all():
        yield stamp_ns, samples, False
        return
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        return
    cuts = np.flatnonzero(np.diff(idx) > 1) + 1
    for run in np.split(idx, cuts):
        broken = run[0] > 0 and not keep[run[0] - 1]
        yield stamp_ns[run], samples[run], bool(broken)
