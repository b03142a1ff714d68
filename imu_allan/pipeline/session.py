"""
The one analysis session that both the live node and the offline readers feed.

A :class:`Session` takes blocks of ``(stamp_ns (n,), samples (n, 6))`` in AXES order
and passes them through three parts, each a plain object that owns its state:

1. the tick clock (:class:`~imu_allan.pipeline.ticks.TickClock`) rebuilds stamps coarser
   than the sample period from the sample count (and passes others on as they are);
   the stamp clock (:class:`~imu_allan.pipeline.clock.StampClock`) splits them into
   gap-free runs in stamp order (rate, gaps, duplicate, out-of-order and outlying
   stamps, clock restarts, NaN/Inf rows); the first rows of the runs are checked for
   unit mistakes (:func:`~imu_allan.core.noise.unit_check.first_look`) before any other
   judgement, so a deg/s gyro is named, not called moving;
2. the sample gate (:class:`~imu_allan.pipeline.checks.SampleGate`) keeps the still
   rows (saturation, frozen axes, spikes, motion);
3. the warm-up hold (:class:`~imu_allan.pipeline.warmup.WarmupGate`) holds the first
   still rows of the record, and of a run after the sensor restarted, until it has
   judged where the output settled after power-on, and leaves the rows before out;
4. the feed (:class:`~imu_allan.pipeline.feed.AccumulatorFeed`) accumulates them in one
   :class:`~imu_allan.core.allan.accumulator.AllanAccumulator`.

Because every mode goes through this object, the numbers cannot differ between them.
A checkpoint is each part's own state (:mod:`imu_allan.pipeline.session_state`).
"""

from typing import Callable, Self

import numpy as np

from imu_allan.core.allan.curve import AllanCurve
from imu_allan.core.allan.stretches import Stretches
from imu_allan.core.noise.unit_check import (first_look, FIRST_LOOK_ROWS, unit_error,
                                             unit_warnings)
from imu_allan.errors import InputError, NotEnoughStillData, UnitMistake
from imu_allan.pipeline import session_state
from imu_allan.pipeline.checks import SampleGate
from imu_allan.pipeline.clock import StampClock
from imu_allan.pipeline.feed import AccumulatorFeed
from imu_allan.pipeline.hygiene import (HygieneStats, MOTION_POLICIES, N_AXES, SessionConfig,
                                        WarningLog)
from imu_allan.pipeline.thermal import ThermalFeed
from imu_allan.pipeline.ticks import TickClock
from imu_allan.pipeline.warmup import WarmupGate

__all__ = ['HygieneStats', 'MOTION_POLICIES', 'Session', 'SessionConfig']


# Long because it is the one path for live and offline data: it wires the clock, the
# gate and the feed and answers the node's and the CLI's questions; the work is in
# those parts.
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
        self.log = WarningLog(on_warning)
        self.ticks = TickClock(config, self.stats, self.log)
        self.clock = StampClock(config, self.stats, self.log)
        self.feed = AccumulatorFeed(config, self.stats)
        self.warmup = WarmupGate(config, self.stats, self.log, self.feed)
        self.gate = SampleGate(config, self.stats, self.log, self.warmup)
        #: The unit mistake that refuses this session (one line), or None.
        self.unit_problem: str | None = None
        # The first finite rows, until the unit check has judged them (None: judged).
        self._first_rows: list[np.ndarray] | None = []
        if config.rate_hz > 0:
            self.feed.start(float(config.rate_hz))

    # ------------------------------------------------------------------ input
    def add(self, stamp_ns, samples, temp_c=None) -> None:
        """
        Split a block into gap-free runs, keep the still rows, accumulate them.

        Parameters
        ----------
        stamp_ns : array_like
            Shape (n,), header stamps [ns] (int64).
        samples : array_like
            Shape (n, 6), rates [rad/s] and accelerations [m/s^2] in AXES order.
        temp_c : array_like, optional
            Shape (n,), the temperature at each row [degC] (:meth:`add_temperature`).

        Raises
        ------
        UnitMistake
            When the first samples show a unit mistake (:attr:`unit_problem`), at this
            block and every later one.

        """
        if self.unit_problem is not None:
            raise UnitMistake(self.unit_problem)
        stamp_ns, samples = _as_block(stamp_ns, samples)
        if stamp_ns.size == 0:
            return
        if temp_c is not None:
            self.add_temperature(stamp_ns, temp_c)
        self.stats.n_received += stamp_ns.size
        for t, y in self.ticks.take(stamp_ns, samples):
            self.clock.split(t, y, self._keep_still)
        self._set_rate()

    def _set_rate(self) -> None:
        """Follow the clock's rate, or a coarse clock's count rate as it is refined."""
        if self.ticks.rate_hz > 0 and self.clock.rate_hz > 0:
            self.clock.rate_hz = self.ticks.rate_hz
        self.feed.set_rate(self.clock.rate_hz)

    def add_temperature(self, stamp_ns, temp_c) -> None:
        """
        Take temperature readings (n,) [degC] at stamps (n,) [ns] (pipeline/thermal.py).

        The first reading turns the thermal analysis on when no row was accumulated
        yet (or :meth:`expect_temperature` did); later, it is left out with a warning.
        """
        if self.feed.thermal is None and not self.expect_temperature():
            self.log('thermal-late', 'the temperature came after the first samples were '
                     'accumulated: not used (give it from the start)')
            return
        assert self.feed.thermal is not None
        self.feed.thermal.add_temperature(stamp_ns, temp_c)

    def expect_temperature(self) -> bool:
        """Turn the thermal analysis on (rows wait for a temperature); False if too late."""
        if self.feed.thermal is None:
            if self.feed.acc is not None and self.feed.acc.n_samples:
                return False
            self.feed.thermal = ThermalFeed(self.config)
            if self.feed.acc is not None:
                self.feed.thermal.start(self.feed.rate_hz)
        return True

    def _keep_still(self, stamp_ns: np.ndarray, samples: np.ndarray, broken: bool) -> None:
        """Take one gap-free run of the clock: the gate passes its still rows on."""
        if self.feed.acc is None:
            self.feed.start(self.clock.rate_hz)
        elif broken:
            self.gate.end_segment()
        if self._first_rows is not None:
            self._first_rows.append(samples[np.isfinite(samples).all(axis=1)])
            self._judge_units(FIRST_LOOK_ROWS)
        self.warmup.follow(stamp_ns)
        self.gate.take(stamp_ns, samples, self.clock.rate_hz)

    def _judge_units(self, rows: int) -> None:
        """Judge the units once ``rows`` finite rows are in; refuse a unit mistake."""
        assert self._first_rows is not None
        # No row passed the clock (stamps that never step): nothing to judge.
        y = np.concatenate(self._first_rows) if self._first_rows else np.zeros((0, 6))
        if y.shape[0] < rows:
            self._first_rows = [y]
            return
        self._first_rows = None
        findings = first_look(self.clock.rate_hz, y[:FIRST_LOOK_ROWS])
        problem = unit_error([f for f in findings
                              if f.quantity not in self.config.declared_quantities])
        if problem is not None:
            self.unit_problem = problem
            raise UnitMistake(problem)

    def break_segment(self) -> None:
        """
        End the contiguous segment here (e.g. after a restart that lost samples).

        The samples held for the checks count as still, as at a gap, and no Allan term
        spans the break.
        """
        self.gate.end_segment()

    def release(self) -> None:
        """Judge the rows the spike filter holds now (the live path, after each batch)."""
        self.gate.release()

    def flush(self) -> None:
        """Accumulate samples still held back (call at the end of a recording)."""
        for t, y in self.ticks.flush():
            self.clock.split(t, y, self._keep_still)
        self.clock.flush(self._keep_still)
        self._set_rate()
        self.gate.flush()
        self.warmup.close()

    # ----------------------------------------------------------------- output
    @property
    def rate_hz(self) -> float:
        """Sample rate [Hz]; 0 until it is known."""
        return self.clock.rate_hz

    @property
    def first_stamp_ns(self) -> int | None:
        """Stamp of the first sample taken [ns]."""
        return self.clock.first_stamp_ns

    @property
    def last_stamp_ns(self) -> int | None:
        """Stamp of the last sample taken [ns]; None means the next is no clock step."""
        return self.clock.last_stamp_ns

    @last_stamp_ns.setter
    def last_stamp_ns(self, value: int | None) -> None:
        self.clock.last_stamp_ns = value

    def stamp_rate_hz(self, stamp_ns) -> float:
        """Rate of a run of stamps judged as this session judges its own [Hz]."""
        if self.ticks.mode == 'coarse':     # coarse stamps: the count over their span
            return self.ticks.count_rate_hz(stamp_ns)
        return self.clock.stamp_rate_hz(stamp_ns)

    @property
    def acc(self):
        """Return the accumulator (None until the rate is known)."""
        return self.feed.acc

    @property
    def duration_s(self) -> float:
        """Duration of the samples used so far [s] (held for the settling judgement too)."""
        return self.stats.n_used / self.rate_hz if self.rate_hz > 0 else 0.0

    def judge_settling(self) -> None:
        """Judge the rows held at the start now, on what there is: a curve is needed."""
        self.warmup.judge_now()

    @property
    def settling(self) -> tuple[float, float] | None:
        """(held, window) [s] while rows wait for the settling judgement, else None."""
        if not self.warmup.holding or self.rate_hz <= 0:
            return None
        return (self.warmup.held_rows / self.rate_hz,
                self.warmup.window_rows() / self.rate_hz)

    def curve(self, confidence: float = 0.95, bounds: bool = True) -> AllanCurve | None:
        """
        Allan curve of the samples used so far, or None before any tau is computable.

        Rows held for the settling judgement are not in it (:meth:`flush` and
        :meth:`judge_settling` judge them).

        ``bounds=False`` leaves adev_lo/adev_hi NaN (see
        :meth:`imu_allan.core.allan.accumulator.AllanAccumulator.curve`).
        """
        self.feed.pass_on()
        acc = self.feed.acc
        if acc is None or acc.n_samples < 4:
            return None
        return acc.curve(confidence=confidence, bounds=bounds)

    def stretches(self) -> Stretches | None:
        """Return the AVAR of each stretch of the record (core/allan/stretches.py), or None."""
        self.feed.pass_on()
        return None if self.feed.acc is None else self.feed.acc.stretches()

    @property
    def warnings(self) -> list[str]:
        """One line per kind of problem seen, with how often it happened."""
        return self.log.lines

    @property
    def still_problem(self) -> str | None:
        """Why the data so far cannot be analysed yet (too little still data), or None."""
        s, c = self.stats, self.config
        share = 1.0 - s.n_motion_dropped / s.n_received if s.n_received else 0.0
        if share < c.min_still_share:
            return (f'only {100 * share:.1f} % of the samples are still (at least '
                    f'{100 * c.min_still_share:g} % needed): the IMU moved most of the time')
        if self.duration_s < c.min_still_s:
            return (f'only {self.duration_s:.1f} s of still data (at least {c.min_still_s:g} s '
                    'needed)')
        return None

    def check_usable(self) -> None:
        """
        Refuse data that cannot give an honest analysis.

        Raises
        ------
        InputError
            When the first samples show a unit mistake, or a larger share than
            ``max_spike_share`` of an axis' samples are spikes.
        NotEnoughStillData
            When too little still data remains (see :attr:`still_problem`).

        """
        if self._first_rows is not None:    # a short record: judged on what there is
            self._judge_units(min(FIRST_LOOK_ROWS, 20))
        if self.unit_problem is not None:
            raise UnitMistake(self.unit_problem)
        # Motion first: vibration while driving also looks like spikes.
        problem = self.still_problem
        if problem is not None:
            # Stamps in the wrong unit shrink or stretch the record: say so here too.
            hints = unit_warnings(self.rate_hz, None, None) if self.rate_hz > 0 else []
            raise NotEnoughStillData(f'not enough still data: {problem}'
                                     + ''.join(f' ({h})' for h in hints))
        s = self.stats
        checked = max(s.n_received - s.n_nonfinite, 1)
        worst = max(s.spikes.items(), key=lambda kv: kv[1], default=None)
        if worst is not None and worst[1] > self.config.max_spike_share * checked:
            raise InputError(f'{worst[0]}: {100 * worst[1] / checked:.1f} % of the samples are '
                             f'spikes (over {100 * self.config.max_spike_share:g} %): the '
                             'record is mostly outliers, not noise')

    # ------------------------------------------------------------- checkpoint
    def save_state(self, path) -> None:
        """
        Save the whole session atomically (each part's state; no pickle).

        Parameters
        ----------
        path : str or Path
            Target file; written to a temporary file first, then renamed.

        """
        session_state.save(self, path)

    @classmethod
    def load_state(cls, path, config: SessionConfig | None = None,
                   on_warning: Callable[[str], None] | None = None) -> Self:
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

        Raises
        ------
        InputError
            One line, for a missing, foreign, damaged or inconsistent checkpoint.

        """
        saved = session_state.load(path)
        config = session_state.resume_config(path, saved, config)
        session = cls(config, on_warning=on_warning)
        session_state.restore(path, saved, session)
        return session


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
