"""
What a session is set to check, what the checks found, and the warnings they raise.

The three plain objects every part of a :class:`~imu_allan.pipeline.session.Session`
is handed: its :class:`SessionConfig`, its :class:`HygieneStats` counters and its
:class:`WarningLog`.  Each part owns its own state besides these.
"""

from dataclasses import dataclass, field, fields
import math
from typing import Callable

from imu_allan import AXES
from imu_allan.errors import InputError

N_AXES = len(AXES)
NS = 1_000_000_000

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
        A stamp further than this from the newest one (ahead or behind) is confirmed
        by the stamp after it: a lone one is an outlier, a run a gap or a clock restart.
    rate_tolerance : float
        Relative deviation of the sample period, judged over windows of 100 stamp
        steps, that counts as a rate change.
    gyro_range_rad_s, accel_range_m_s2 : float
        Sensor full scale [rad/s], [m/s^2]; |value| >= 0.999 of it is saturated;
        0 disables the check.
    frozen_samples : int
        An axis repeating one value this many samples in a row is frozen [samples].
    spike_sigma : float
        A sample further than this many noise sigmas from the median of its
        neighbours is a spike, replaced by interpolation; 0 disables the check.
    max_spike_share : float
        A record with a larger share of spike samples is refused (InputError).
    motion_window_s : float
        Window over which motion statistics are computed [s]; at least
        :data:`imu_allan.pipeline.motion.MIN_WINDOW` samples (longer below 10 Hz).
    motion_sigma : float
        A window mean that departs from the still reference by more than this many
        sigmas of a still window's mean (the reference's per-sample noise over the
        root of the samples in a window) is motion.
    motion_gyro_rad_s : float
        Cap of the gyro mean-offset threshold [rad/s].
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
    anchor_s : float
        A still stretch this long at another level (or quieter than the reference)
        becomes the new still reference [s].
    min_still_share, min_still_s : float
        Less still data than this share of the samples received, or than this
        duration [s], refuses the analysis (NotEnoughStillData).
    max_fill_samples : int
        A gap of regular stamps that lost at most this many samples is short: it is
        filled (linear interpolation), and no Allan term at short taus uses a
        filled sample; a longer one splits the segment [samples].  0 splits at
        every gap.
    exact_max_m : int
        Largest cluster size the accumulator computes exactly [samples]; 0 = default.
    warmup_window_s : float
        Still time held at the start of the record, and after the sensor restarted,
        to judge where its output settled after power-on (:mod:`imu_allan.pipeline.warmup`)
        [s]; at most 2^20 rows.  0 holds nothing and leaves nothing out.
    units_declared : str
        Comma-separated quantities ('gyro', 'accel', 'time') whose units the user
        declared (``--units``): the unit check takes them as declared.  An undeclared
        quantity whose first samples show a unit mistake with a named fix refuses the
        session (:attr:`imu_allan.pipeline.session.Session.unit_problem`).

    """

    rate_hz: float = 0.0
    rate_window: int = 200
    gap_factor: float = 1.5
    irregular_gap_s: float = 2.0
    rate_tolerance: float = 0.05
    gyro_range_rad_s: float = 0.0
    accel_range_m_s2: float = 0.0
    frozen_samples: int = 200
    spike_sigma: float = 10.0
    max_spike_share: float = 0.05
    motion_window_s: float = 1.0
    motion_sigma: float = 10.0
    motion_gyro_rad_s: float = 0.05
    motion_accel_m_s2: float = 0.5
    motion_std_ratio: float = 8.0
    on_motion: str = 'pause'
    settle_s: float = 5.0
    anchor_s: float = 10.0
    min_still_share: float = 0.2
    min_still_s: float = 10.0
    max_fill_samples: int = 8
    exact_max_m: int = 0
    warmup_window_s: float = 1800.0
    units_declared: str = ''

    def __post_init__(self):
        if self.on_motion not in MOTION_POLICIES:
            raise InputError(f'on_motion must be one of {", ".join(MOTION_POLICIES)}, '
                             f'not {self.on_motion!r}')
        if not set(self.declared_quantities) <= {'gyro', 'accel', 'time'}:
            raise InputError(f'units_declared must name gyro, accel or time, not '
                             f'{self.units_declared!r}')
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ('on_motion', 'units_declared'):
                continue
            if (isinstance(value, str) or not isinstance(value, (int, float))
                    or not math.isfinite(value) or value < 0):
                raise InputError(f'{f.name} must be a finite number >= 0, not {value!r}')

    @property
    def declared_quantities(self) -> tuple:
        """Return the quantities of ``units_declared`` as a tuple of names."""
        return tuple(q for q in str(self.units_declared).split(',') if q)


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
    n_stamp_outliers : int
        Samples dropped for a lone stamp far from its neighbours.
    n_spikes : int
        Spike values replaced by interpolation, over all axes.
    spikes : dict
        Spike values replaced per axis name.
    n_gaps, n_missing : int
        Gaps in the stamps, and the samples they are estimated to have lost.
    n_short_gaps, n_filled : int
        Of those, the short gaps (filled, see ``SessionConfig.max_fill_samples``) and
        the samples filled in them; the others split the record.
    n_clock_restarts : int
        Times the stamps jumped back and went on (a new segment each).
    n_rate_changes, n_motion_events, n_restarts, n_reanchors : int
        Episodes of a changed rate, of motion, motion restarts, and new still
        references.
    n_warmup : int
        Still samples left out because the output was still settling after power-on.
    warmup_s : float
        The time they span [s].
    warmup_axes : list of str
        The axes whose transient set that time.
    frozen_axes, saturated_axes : list of str
        Axes seen frozen or saturated.
    held : dict
        Per axis with held values (a sensor slower than its stream), the share of the
        steps that repeat the value before (0-1), beyond quantization's repeats; the
        spike filter measures it (nothing with ``spike_sigma`` 0).
    interpolated : dict
        Per axis whose values a driver interpolated between its sensor's updates, the
        share of the moving triples on a straight line (0-1;
        :mod:`imu_allan.pipeline.interpolated`).
    jitter_rel : float
        Standard deviation of the stamp steps (gaps left out) over the period,
        pooled over the windows judged so far.
    irregular_stamps : bool
        True when the stamps are too jittery to locate gaps step by step.
    coarse_tick_s : float
        The tick of a stamp clock coarser than the sample period [s] (its stamps are
        rebuilt from the sample count, :mod:`imu_allan.pipeline.ticks`); 0 when the
        stamps are used as they are.
    n_lost_in_ticks : int
        Samples a coarse stamp clock shows lost (counted in ``n_missing`` too once the
        stamp clock sees their gap).
    clipped : dict
        Per axis whose values pile up at the ends of its range (a sensor range below
        the signal), the share of its samples at those ends (0-1).
    n_zero_rows : int
        Rows whose exact zeros are fills of an incomplete packet (a driver that sends 0
        for the fields it did not receive), treated as lost samples
        (:mod:`imu_allan.pipeline.zeros`).
    zero_filled : dict
        Per axis, the exact zeros in those rows.
    value_grid : dict
        Per axis whose first rows take few distinct values, the median step between
        them [unit]: the grid its values lie on (an LSB, the digits a logger writes);
        axes on no grid are absent (:mod:`imu_allan.pipeline.zeros` measures it,
        :mod:`imu_allan.pipeline.resolution` judges it).

    """

    n_received: int = 0
    n_used: int = 0
    n_nonfinite: int = 0
    n_duplicate: int = 0
    n_out_of_order: int = 0
    n_stamp_outliers: int = 0
    n_saturated: int = 0
    n_spikes: int = 0
    spikes: dict = field(default_factory=dict)
    n_motion_dropped: int = 0
    n_gaps: int = 0
    n_missing: int = 0
    n_short_gaps: int = 0
    n_filled: int = 0
    n_clock_restarts: int = 0
    n_rate_changes: int = 0
    n_motion_events: int = 0
    n_restarts: int = 0
    n_reanchors: int = 0
    n_warmup: int = 0
    warmup_s: float = 0.0
    warmup_axes: list = field(default_factory=list)
    frozen_axes: list = field(default_factory=list)
    saturated_axes: list = field(default_factory=list)
    held: dict = field(default_factory=dict)
    interpolated: dict = field(default_factory=dict)
    jitter_rel: float = 0.0
    irregular_stamps: bool = False
    coarse_tick_s: float = 0.0
    n_lost_in_ticks: int = 0
    clipped: dict = field(default_factory=dict)
    n_zero_rows: int = 0
    zero_filled: dict = field(default_factory=dict)
    value_grid: dict = field(default_factory=dict)

    @classmethod
    def restore(cls, state) -> 'HygieneStats':
        """Counters from :func:`dataclasses.asdict`; InputError when any is invalid."""
        if isinstance(state, dict):
            # Counters written before short gaps were filled: none were.
            # ... and before a settling transient was left out, coarse stamps,
            # clipping, zero-filled fields and interpolated values were recognised.
            state = {'n_short_gaps': 0, 'n_filled': 0, 'n_warmup': 0, 'warmup_s': 0.0,
                     'warmup_axes': [], 'coarse_tick_s': 0.0, 'n_lost_in_ticks': 0,
                     'clipped': {}, 'n_zero_rows': 0, 'zero_filled': {}, 'value_grid': {},
                     'interpolated': {}, **state}
        if not isinstance(state, dict) or set(state) != {f.name for f in fields(cls)}:
            raise InputError('the counters are incomplete or unknown')
        stats = cls(**state)
        for f in fields(cls):
            value = getattr(stats, f.name)
            if f.name in ('frozen_axes', 'saturated_axes', 'warmup_axes'):
                ok = isinstance(value, list) and set(value) <= set(AXES)
            elif f.name in ('spikes', 'zero_filled'):
                ok = (isinstance(value, dict) and set(value) <= set(AXES)
                      and all(isinstance(v, int) and v >= 0 for v in value.values()))
            elif f.name in ('held', 'clipped', 'interpolated'):
                ok = (isinstance(value, dict) and set(value) <= set(AXES)
                      and all(isinstance(v, (int, float)) and 0 <= v <= 1
                              for v in value.values()))
            elif f.name == 'value_grid':
                ok = (isinstance(value, dict) and set(value) <= set(AXES)
                      and all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0
                              for v in value.values()))
            elif f.name == 'irregular_stamps':
                ok = isinstance(value, bool)
            elif f.name in ('jitter_rel', 'warmup_s', 'coarse_tick_s'):
                ok = isinstance(value, (int, float)) and math.isfinite(value) and value >= 0
            else:
                ok = isinstance(value, int) and not isinstance(value, bool) and value >= 0
            if not ok:
                raise InputError(f'the counter {f.name} is invalid ({value!r})')
        return stats


class WarningLog:
    """
    One line per kind of problem seen, with how often it happened.

    Parameters
    ----------
    on_warning : callable, optional
        Called with each new one-line warning at its 1st, 2nd, 4th, 8th ... occurrence
        (the node logs it; the CLI prints it).

    """

    def __init__(self, on_warning: Callable[[str], None] | None = None):
        self.on_warning = on_warning
        self.text: dict[str, str] = {}
        self.count: dict[str, int] = {}

    def __call__(self, key: str, text: str, once: bool = True) -> None:
        """Note one occurrence of the problem ``key`` described by ``text``."""
        n = self.count.get(key, 0) + 1
        self.count[key] = n
        if once and n > 1:
            return
        self.text[key] = text if n == 1 else f'{text} [{n} times so far]'
        # Tell the user at 1, 2, 4, 8 ... occurrences: informative without flooding.
        if self.on_warning is not None and n & (n - 1) == 0:
            self.on_warning(self.text[key])

    def tally(self, key: str, text: str, n: int = 1) -> None:
        """
        Note ``n`` more occurrences of ``key``, whose ``text`` states the totals itself.

        The text replaces the previous one (no count is appended); the user is told at
        the first occurrence and whenever the count passes a power of two.
        """
        before = self.count.get(key, 0)
        self.count[key] = before + n
        self.text[key] = text
        if self.on_warning is not None and (before + n).bit_length() > before.bit_length():
            self.on_warning(text)

    def forget(self, *keys: str) -> None:
        """Drop the problems ``keys``: they turned out to have another cause."""
        for key in keys:
            self.text.pop(key, None)
            self.count.pop(key, None)

    @property
    def lines(self) -> list[str]:
        """Return the warnings in the order their kinds first appeared."""
        return list(self.text.values())

    def state(self) -> dict:
        """Return the log as JSON-able data."""
        return {'text': dict(self.text), 'count': dict(self.count)}

    def restore(self, state) -> None:
        """Take the log saved by :meth:`state`; InputError when it is invalid."""
        if not isinstance(state, dict) or set(state) != {'text', 'count'}:
            raise InputError('the warning log is incomplete')
        text, count = state['text'], state['count']
        if (not isinstance(text, dict) or not isinstance(count, dict)
                or not all(isinstance(v, str) for v in text.values())
                or not all(isinstance(v, int) and v > 0 for v in count.values())):
            raise InputError('the warning log is invalid')
        self.text, self.count = dict(text), dict(count)
