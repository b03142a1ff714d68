"""
The one analysis session that both the live node and the offline readers feed.

A :class:`Session` takes blocks of ``(stamp_ns (n,), samples (n, 6))`` in AXES order,
checks them (rate, gaps, duplicate or out-of-order stamps, NaN/Inf, saturation, frozen
axes, motion), streams the clean samples through one
:class:`~imu_allan.core.allan.accumulator.AllanAccumulator`, and fits the noise model on demand.
Because every mode goes through this object, the numbers cannot differ between them.
"""

from dataclasses import dataclass, field, fields
import math
from typing import Callable

import numpy as np

from imu_allan import AXES
from imu_allan.core.allan import AllanCurve
from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.errors import InputError
from imu_allan.pipeline.checks import _SampleChecks, _split_runs
from imu_allan.pipeline.clock import _StampClock
from imu_allan.pipeline.feed import BackgroundAccumulator
from imu_allan.pipeline.session_state import _StateFile

N_AXES = len(AXES)

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
    background_accumulator : bool
        The accumulator sums on a thread of its own while the checks go on (one input
        on two cores: ``imu-allan analyze``).  The sums are identical either way.  The
        thread reads the blocks given to :meth:`Session.add` later, so the caller must
        not change them afterwards (the offline readers make a new array per block).

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
    background_accumulator: bool = False

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


# Slightly long: the pipeline's one entry point (add, flush, curve, break_segment) over
# its three mixins; the stamp clock, sample checks and state file live in their modules.
class Session(_StampClock, _SampleChecks, _StateFile):
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
        self.acc: AllanAccumulator | BackgroundAccumulator | None = None
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
        # One whole-block reduction first: rows are looked at only when one is bad.
        if np.isfinite(samples).all():
            finite = np.ones(n, dtype=bool)
        else:
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
            if ok.all():    # the usual case: the block's own arrays, not copies
                self._ingest(t_part, y_part)
            else:
                self._ingest(t_part[ok], y_part[ok])
        # NaN rows that end a block break the segment before the next block's rows, just
        # as they would inside one block.
        self._nan_break = self._nan_break or not finite[-1]

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

    def _start_accumulator(self) -> None:
        kwargs = {'exact_max_m': self.config.exact_max_m} if self.config.exact_max_m else {}
        acc = AllanAccumulator(N_AXES, self.rate_hz, **kwargs)
        self.acc = BackgroundAccumulator(acc) if self.config.background_accumulator else acc

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
        if isinstance(self.acc, BackgroundAccumulator):
            # The end of the recording: its thread stops, later calls run inline.
            self.acc = self.acc.close()

    # ----------------------------------------------------------------- output
    @property
    def duration_s(self) -> float:
        """Duration of the samples used so far [s]."""
        return self.stats.n_used / self.rate_hz if self.rate_hz > 0 else 0.0

    def curve(self, confidence: float = 0.95, bounds: bool = True) -> AllanCurve | None:
        """
        Allan curve of the samples used so far, or None before any tau is computable.

        ``bounds=False`` leaves adev_lo/adev_hi NaN (see
        :meth:`imu_allan.core.allan.accumulator.AllanAccumulator.curve`).
        """
        if self.acc is None or self.acc.n_samples < 4:
            return None
        return self.acc.curve(confidence=confidence, bounds=bounds)

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
