"""
The sample gate of a session: saturation, frozen axes, spikes, then motion.

:class:`SampleGate` takes the gap-free runs of the stamp clock and passes the rows it
keeps to the accumulator feed: clipped axes are found (values piled at the ends of the
range, :mod:`imu_allan.pipeline.clipping`), saturated rows split the run, frozen axes
are reported, rows with zero-filled fields become fills
(:mod:`imu_allan.pipeline.zeros`), messages lost on irregular stamps are counted
(:mod:`imu_allan.pipeline.lost`), spikes are interpolated
(:mod:`imu_allan.pipeline.spikes`) and windows that moved are dropped
(:mod:`imu_allan.pipeline.motion`).
"""

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError
from imu_allan.pipeline.clipping import ClipWatch
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, SessionConfig, WarningLog
from imu_allan.pipeline.interpolated import InterpWatch
from imu_allan.pipeline.lost import LostWatch
from imu_allan.pipeline.motion import MotionGate
from imu_allan.pipeline.spikes import HOLD_MIN, SpikeFilter
from imu_allan.pipeline.steps import split_runs
from imu_allan.pipeline.zeros import ZeroWatch


#: What held values mean for the analysis (the end of the held-values warning).
HELD_MEANING = ('spikes are judged between distinct updates, and the Allan variance, '
                'low by about T_u / (2 tau) for an update period T_u, is fitted from where '
                'that is under 10 %, corrected: N and B have wider intervals; if the '
                'updates are read an uneven number of times (a polling logger), N reads '
                'high (by up to 20 %, docs/input_gate.md): log at the rate of the sensor')


# Long because it wires five checks (clipping, zero fields, lost messages, spikes,
# motion) into one pass over a run and saves their state in one checkpoint.
class SampleGate:
    """
    Saturation and frozen-axis checks, the spike filter, then the motion gate.

    Parameters
    ----------
    config : SessionConfig
        Check settings.
    stats : HygieneStats
        Counters the checks add to.
    warn : WarningLog
        Where warnings go.
    feed : imu_allan.pipeline.feed.AccumulatorFeed
        Where the kept rows go.

    """

    def __init__(self, config: SessionConfig, stats: HygieneStats, warn: WarningLog, feed):
        self.config = config
        self.stats = stats
        self._warn = warn
        self.feed = feed
        self.spikes = SpikeFilter(config, stats, warn)
        self.motion = MotionGate(config, stats, warn, feed)
        self.clips = ClipWatch(stats, warn, ('rad/s',) * 3 + ('m/s^2',) * 3)
        self.zeros = ZeroWatch(stats, warn, config.max_fill_samples)
        self.lost = LostWatch(stats, warn)
        self.interp = InterpWatch(stats, warn)
        self._limits = np.array([config.gyro_range_rad_s] * 3 + [config.accel_range_m_s2] * 3)
        self._last_value = np.full(N_AXES, np.nan)
        self._repeat = np.zeros(N_AXES, dtype=np.int64)
        self._rate_hz = 0.0

    def take(self, stamp_ns: np.ndarray, samples: np.ndarray, rate_hz: float) -> None:
        """Check a gap-free run; pass the rows kept on towards the accumulator."""
        self._rate_hz = rate_hz
        self.lost.take(stamp_ns)
        self.clips.take(samples)
        rows = None
        if (self._limits > 0).any():      # no range given (the default): nothing saturates
            sat = (np.abs(samples) >= 0.999 * self._limits) & (self._limits > 0)
            rows = ~sat.any(axis=1)
            if not rows.all():
                self._note_saturated(sat, int((~rows).sum()))
        for t_part, y_part, broken in split_runs(stamp_ns, samples, rows):
            if broken:
                self.end_segment()
            self.interp.take(t_part, y_part)
            self._check_frozen(y_part)
            for t_run, y_run, cut in self.zeros.take(t_part, y_part):
                if cut:
                    self._cut()
                judged = self.spikes.take(t_run, y_run)
                self._note_held(rate_hz)
                self.motion.take(*judged, rate_hz)
        self.interp.judge(rate_hz)

    def release(self) -> None:
        """Pass the rows the spike filter holds on now (live: no wait for a chunk)."""
        if self._rate_hz > 0:
            self.motion.take(*self.spikes.release(), self._rate_hz)

    def end_segment(self) -> None:
        """End the segment here (a gap, NaN, saturation, a restart): no term spans it."""
        self.zeros.end_segment()
        self.lost.end_segment()
        self.interp.end_segment()
        self._cut()

    def _cut(self) -> None:
        """End the segment after the rows passed so far."""
        self.flush()
        self.feed.break_segment()

    def flush(self) -> None:
        """Pass every held row on (the end of a segment or of the recording)."""
        if self._rate_hz > 0:
            self.motion.take(*self.spikes.flush(), self._rate_hz)
        self.motion.flush()

    def _note_saturated(self, sat: np.ndarray, n: int) -> None:
        for j in np.flatnonzero(sat.any(axis=0)):
            if AXES[j] not in self.stats.saturated_axes:
                self.stats.saturated_axes.append(AXES[j])
        self.stats.n_saturated += n
        self._warn('saturated', f'{n} saturated samples on '
                   f'{", ".join(self.stats.saturated_axes)} dropped (segment split there)',
                   once=False)

    def _note_held(self, rate_hz: float) -> None:
        """Count the held share per axis; warn when an axis is first seen held."""
        share = self.spikes.held_share
        self.motion.held = np.where(share >= HOLD_MIN, share, 0.0)
        known = set(self.stats.held)
        for j in np.flatnonzero(share >= HOLD_MIN):
            self.stats.held[AXES[j]] = 0.0
        for axis in self.stats.held:     # once held, the share of the whole record so far
            self.stats.held[axis] = round(float(share[AXES.index(axis)]), 4)
        if set(self.stats.held) == known:
            return
        found = []
        for kind in ('gyro', 'accel'):
            axes = [a for a in self.stats.held if a.startswith(kind)]
            if axes:
                held = float(np.mean([self.stats.held[a] for a in axes]))
                found.append(f'{kind if len(axes) == 3 else ", ".join(axes)} '
                             f'{100 * held:.0f} % (updates at about '
                             f'{rate_hz * (1 - held):.2g} Hz)')
        self._warn('held', f'held values (a driver or logger faster than its sensor): at '
                   f'{rate_hz:.3g} Hz, {"; ".join(found)} of the samples repeat the one '
                   'before; ' + HELD_MEANING, once=False)

    def _check_frozen(self, samples: np.ndarray) -> None:
        """Warn once per axis whose value repeats for ``frozen_samples`` samples or more."""
        longest = _repeat_runs(samples, self._last_value, self._repeat)
        for j in np.flatnonzero(longest >= self.config.frozen_samples):
            if AXES[j] not in self.stats.frozen_axes:
                self.stats.frozen_axes.append(AXES[j])
                self._warn(f'frozen-{AXES[j]}', f'{AXES[j]} is frozen: one value repeated for '
                           f'{longest[j]} samples (a dead or disconnected sensor, or a '
                           'replayed constant)')
        self._last_value = samples[-1].copy()

    # ------------------------------------------------------------- checkpoint
    def state(self) -> tuple[dict, dict]:
        """Return (JSON-able state, arrays) of the gate and its parts."""
        spike_meta, spike_arrays = self.spikes.state()
        motion_meta, motion_arrays = self.motion.state()
        clip_meta, clip_arrays = self.clips.state()
        meta = {'repeat': self._repeat.tolist(), 'rate_hz': self._rate_hz,
                'spikes': spike_meta, 'motion': motion_meta, 'clips': clip_meta}
        return meta, {'last_value': self._last_value, **spike_arrays, **motion_arrays,
                      **clip_arrays, **self.zeros.state(),
                      **self.lost.state(), **self.interp.state()}

    def restore(self, meta, arrays: dict) -> None:
        """Take the state of :meth:`state`; InputError when it is invalid."""
        if not isinstance(meta, dict) or set(meta) - {'clips'} != {'repeat', 'rate_hz',
                                                                   'spikes', 'motion'}:
            raise InputError('the sample gate state is incomplete')
        repeat, last = meta['repeat'], arrays.get('last_value')
        if (not isinstance(repeat, list) or len(repeat) != N_AXES
                or not all(isinstance(r, int) and r >= 0 for r in repeat)
                or last is None or last.shape != (N_AXES,)):
            raise InputError('the frozen-axis counters are invalid')
        rate = meta['rate_hz']
        if not isinstance(rate, (int, float)) or not np.isfinite(rate) or rate < 0:
            raise InputError('the sample gate rate is invalid')
        self.spikes.restore(meta['spikes'], arrays)
        self.motion.restore(meta['motion'], arrays)
        self.clips.restore(meta.get('clips'), arrays)
        self.zeros.restore(arrays)
        self.lost.restore(arrays)
        self.interp.restore(arrays)
        self._repeat = np.array(repeat, dtype=np.int64)
        self._last_value = last.astype(np.float64)
        self._rate_hz = float(rate)


def _repeat_runs(samples: np.ndarray, last: np.ndarray, run: np.ndarray) -> np.ndarray:
    """
    Continue each axis' run of repeated values over a block; return the longest runs.

    ``run`` (n_axes,) int64, the run going on before row 0 (``last`` is the sample
    there, NaN for none), becomes in place the run that ends the block; the result
    (n_axes,) is the longest run per axis, the one on entry included [samples].
    """
    same = np.empty(samples.shape, dtype=bool)
    np.equal(samples[0], last, out=same[0])
    np.equal(samples[1:], samples[:-1], out=same[1:])
    longest = run.copy()
    for j in range(samples.shape[1]):
        col = same[:, j]
        if not col.any():          # noisy data: no value repeats (the usual case)
            run[j] = 0
        elif col.all():
            run[j] = longest[j] = run[j] + col.size
        else:
            breaks = np.flatnonzero(~col)
            runs = np.diff(np.concatenate((breaks, [col.size]))) - 1
            longest[j] = max(run[j] + breaks[0], int(runs.max()))
            run[j] = col.size - 1 - breaks[-1]
    return longest
