"""
The sample checks of a session: saturation, frozen axes, the motion gate.

A mixin of :class:`imu_allan.pipeline.session.Session`, whose state it shares; the
samples that pass reach the Allan accumulator here.
"""

import numpy as np

from imu_allan import AXES
from imu_allan.pipeline.clock import _NS
from imu_allan.pipeline.parts import _Parts


N_AXES = len(AXES)


class _SampleChecks(_Parts):
    """Saturation and frozen-axis checks, then the motion gate before the accumulator."""

    def _accumulate(self, stamp_ns: np.ndarray, samples: np.ndarray) -> None:
        """Gap-free run: saturation split, frozen check, then the motion stage."""
        limits = np.array([self.config.gyro_range_rad_s] * 3 + [self.config.accel_range_m_s2] * 3)
        rows = np.zeros(samples.shape[0], dtype=bool)
        if (limits > 0).any():      # no range given (the default): nothing can saturate
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
        same = np.empty(samples.shape, dtype=bool)
        np.equal(samples[0], self._last_value, out=same[0])
        np.equal(samples[1:], samples[:-1], out=same[1:])
        repeats = same.any(axis=0)
        for j in range(N_AXES):
            col = same[:, j]
            if not repeats[j]:      # noisy data: no value repeats (the usual case)
                run, longest = 0, int(self._repeat[j])
            elif col.all():
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
            means, stds = _window_stats(y[:n_full].reshape(-1, win, N_AXES))
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
                assert self.acc is not None  # samples are judged only once it exists
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
            assert self.acc is not None
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


def _window_stats(blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the mean and standard deviation (ddof 0) of each window.

    Sums of the deviations from each window's first row: three passes instead of the
    five of ``mean`` plus ``std``, and no cancellation (the deviations are noise-sized).

    Parameters
    ----------
    blocks : np.ndarray
        Shape (n_windows, win, n_axes), samples [unit].

    Returns
    -------
    means, stds : np.ndarray
        Shape (n_windows, n_axes) each [unit].

    """
    d = blocks - blocks[:, :1, :]
    win = blocks.shape[1]
    shift = d.sum(axis=1) / win
    var = np.einsum('wij,wij->wj', d, d) / win - shift * shift
    return blocks[:, 0, :] + shift, np.sqrt(np.maximum(var, 0.0))


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
