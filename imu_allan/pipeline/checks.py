"""
The sample checks of a session: saturation, frozen axes, the motion gate.

A mixin of :class:`imu_allan.pipeline.session.Session`, whose state it shares; the
samples that pass reach the Allan accumulator here.
"""

import numpy as np

from imu_allan import AXES
from imu_allan.core import native
from imu_allan.pipeline.clock import _NS
from imu_allan.pipeline.parts import _Parts


N_AXES = len(AXES)
#: Still runs at least this long reach the accumulator as they are, shorter ones joined.
_DIRECT_ROWS = 4096


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
        """Warn once per axis whose value repeats for ``frozen_samples`` samples or more."""
        longest = _repeat_runs(samples, self._last_value, self._repeat)
        for j in np.flatnonzero(longest >= self.config.frozen_samples):
            if AXES[j] not in self.stats.frozen_axes:
                self.stats.frozen_axes.append(AXES[j])
                self._warn(f'frozen-{AXES[j]}', f'{AXES[j]} is frozen: one value repeated for '
                           f'{longest[j]} samples (a dead or disconnected sensor, or a '
                           'replayed constant)')
        self._last_value = samples[-1].copy()

    def _motion_stage(self, stamp_ns: np.ndarray, samples: np.ndarray) -> None:
        """
        Hold samples until their motion window is judged, then accumulate or drop them.

        Rows wait at most one window (``motion_window_s``), so no sample reaches the
        accumulator before the check that could reject it.  Windows are cut from the
        stream, not from the blocks: only the rows held from the last block are copied.
        """
        win = max(int(round(self.config.motion_window_s * self.rate_hz)), 2)
        t, y = stamp_ns, samples
        held = sum(h.shape[0] for h in self._win_y)
        if held >= win:     # the window shrank (a refined rate): start from the held rows
            t, y = np.concatenate(self._win_t + [t]), np.concatenate(self._win_y + [y])
        elif held:
            take = min(win - held, t.size)
            head_t = np.concatenate(self._win_t + [t[:take]])
            head_y = np.concatenate(self._win_y + [y[:take]])
            t, y = t[take:], y[take:]
            if head_t.size < win:
                self._win_t, self._win_y = [head_t], [head_y]
                self._drain()
                return
            self._judge_windows(head_t, head_y, win)
        n_full = (t.size // win) * win
        if n_full:
            self._judge_windows(t[:n_full], y[:n_full], win)
        # Copies (at most one window): the caller may reuse its arrays after add().
        self._win_t, self._win_y = (([t[n_full:].copy()], [y[n_full:].copy()])
                                    if n_full < t.size else ([], []))
        self._drain()

    def _judge_windows(self, t: np.ndarray, y: np.ndarray, win: int) -> None:
        """
        Judge whole windows in order; runs of still ones are found by one scan.

        While the gate is open (a reference exists and the IMU was not moving), the
        still windows up to the next that moved are passed on as one run; that window,
        and every window while the IMU is held as moving, go through
        :meth:`_judge_window` one by one.
        """
        n_windows = t.size // win
        thr = self._motion_thresholds()
        i = 0
        while i < n_windows:
            if self._ref_mean is not None and self._ref_std is not None and not self._moving:
                still, mean, std = _scan_still(y[i * win:], win, thr,
                                               self.config.motion_std_ratio, self._ref_mean,
                                               self._ref_std)
                if still:
                    self._in_motion = False
                    self._use(t[i * win:(i + still) * win], y[i * win:(i + still) * win])
                    i += still
                if i == n_windows:
                    return
            else:
                means, stds = _window_stats(y[i * win:(i + 1) * win][None])
                mean, std = means[0], stds[0]
            k = slice(i * win, (i + 1) * win)
            self._judge_window(t[k], y[k], mean, std)
            i += 1

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
        """Pass the samples :meth:`_use` holds to the accumulator, in order."""
        # Long runs go as they are (the accumulator copies them anyway); short ones,
        # window by window while the IMU moved now and then, are joined into one call.
        if not self._pending:
            return
        assert self.acc is not None
        short: list = []
        for piece in self._pending + [None]:
            if piece is not None and piece.shape[0] < _DIRECT_ROWS:
                short.append(piece)
                continue
            if short:
                self.acc.add(short[0] if len(short) == 1 else np.concatenate(short))
                short = []
            if piece is not None:
                self.acc.add(piece)
        self._pending = []

    def _motion_thresholds(self) -> np.ndarray:
        """Shape (6,): largest still offset of a window mean, per axis [rad/s, m/s^2]."""
        return np.array([self.config.motion_gyro_rad_s] * 3
                        + [self.config.motion_accel_m_s2] * 3)

    def _window_moving(self, mean: np.ndarray, std: np.ndarray) -> bool:
        """Whether one motion window moved, from its per-axis mean and std (6,) each."""
        thr = self._motion_thresholds()
        if self._ref_mean is None or self._ref_std is None:
            # Quantised sensors can show zero spread: floor the reference noise.  The
            # reference is this session's own array: the scan updates it in place.
            self._ref_mean = np.array(mean, dtype=np.float64)
            self._ref_std = np.maximum(std, thr / 20)
            return False
        moving_axes, dev, ratio = _moved_axes(mean, std, thr, self.config.motion_std_ratio,
                                              self._ref_mean, self._ref_std)
        if moving_axes.any():
            names = ', '.join(AXES[j] for j in np.flatnonzero(moving_axes))
            action = {'warn': 'samples kept (on_motion=warn)',
                      'pause': 'accumulation paused until still',
                      'restart': 'restarting from scratch once still'}[self.config.on_motion]
            self._warn('motion', f'motion detected on {names} (mean off by up to '
                       f'{dev.max():.3g}, noise x{ratio.max():.1f}): the IMU is not '
                       f'stationary; {action}', once=False)
            return True
        _follow_drift(self._ref_mean, mean)
        return False


def _moved_axes(mean: np.ndarray, std: np.ndarray, thr: np.ndarray, ratio_limit: float,
                ref_mean: np.ndarray, ref_std: np.ndarray) -> tuple:
    """
    Judge one window against the still reference: the rule of the compiled scan too.

    Returns (moved (n_axes,) bool, |mean - ref_mean| (n_axes,), std / ref_std (n_axes,)):
    an axis moved when its mean is more than ``thr`` off or its std more than
    ``ratio_limit`` times the reference's.
    """
    dev = np.abs(mean - ref_mean)
    ratio = std / ref_std
    return (dev > thr) | (ratio > ratio_limit), dev, ratio


def _follow_drift(ref_mean: np.ndarray, mean: np.ndarray) -> None:
    """Move the reference 1 % of the way to a still window's mean, in place (bias drift)."""
    # Slow temperature drift of the bias is thus not taken for motion.
    ref_mean[:] = 0.99 * ref_mean + 0.01 * mean


def _scan_still(y: np.ndarray, win: int, thr: np.ndarray, ratio_limit: float,
                ref_mean: np.ndarray, ref_std: np.ndarray) -> tuple:
    """Count the still windows before the first that moved (compiled or :func:`_still_run`)."""
    scan = native.motion_scan if native.LIB is not None else _still_run
    return scan(y, win, thr, ratio_limit, ref_mean, ref_std)


def _still_run(y: np.ndarray, win: int, thr: np.ndarray, ratio_limit: float,
               ref_mean: np.ndarray, ref_std: np.ndarray) -> tuple:
    """
    Find the first window that moved; pull the reference along the still ones before it.

    The numpy twin of :func:`imu_allan.core.native.motion_scan`, window by window with
    :func:`_moved_axes` and :func:`_follow_drift`, as :meth:`_SampleChecks._window_moving`
    judges one window.

    Parameters
    ----------
    y : np.ndarray
        Shape (n_windows * win, n_axes), samples [unit].
    win : int
        Rows per window.
    thr : np.ndarray
        Shape (n_axes,), offset limits [unit].
    ratio_limit : float
        Std ratio limit.
    ref_mean : np.ndarray
        Shape (n_axes,), reference means [unit], updated in place.
    ref_std : np.ndarray
        Shape (n_axes,), reference standard deviations [unit].

    Returns
    -------
    tuple
        (still windows, mean (n_axes,) and std (n_axes,) of the window that moved);
        mean and std are None when none moved.

    """
    means, stds = _window_stats(y.reshape(-1, win, y.shape[1]))
    for w in range(means.shape[0]):
        if _moved_axes(means[w], stds[w], thr, ratio_limit, ref_mean, ref_std)[0].any():
            return w, means[w], stds[w]
        _follow_drift(ref_mean, means[w])
    return means.shape[0], None, None


def _repeat_runs(samples: np.ndarray, last: np.ndarray, run: np.ndarray) -> np.ndarray:
    """
    Continue each axis' run of repeated values over a block; return the longest runs.

    ``run`` (n_axes,) int64, the run going on before row 0 (``last`` is the sample
    there, NaN for none), becomes in place the run that ends the block; the result
    (n_axes,) is the longest run per axis, the one on entry included [samples].  The
    compiled twin is :func:`imu_allan.core.native.repeats`.
    """
    if native.LIB is not None:
        return native.repeats(samples, last, run)
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
