"""
The motion gate: still windows go on to the accumulator, windows that moved do not.

Samples are judged in windows of ``motion_window_s`` (at least :data:`MIN_WINDOW`
samples) against a still reference: the
per-axis mean and noise of still data.  A window moved when its mean is off by more
than ``motion_sigma`` times the noise of a window mean (the reference's per-sample
noise over the root of the window's samples; capped by ``motion_gyro_rad_s`` and
``motion_accel_m_s2``), when it is ``motion_std_ratio`` times noisier, or when most
axes are :data:`QUIETER` times quieter (the reference itself was taken in motion).

The reference does not depend on how the recording starts.  The first window gives a
provisional one; while the gate is closed, a stretch of mutually consistent windows
is followed, and when it lasts ``anchor_s`` and is not noisier than the reference, it
becomes the reference (the IMU settled at another level, or was moving when the
reference was taken).  A reference replaced by a quieter one was motion: with
``pause`` or ``restart``, the samples used under it are dropped.
"""

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, NS, SessionConfig, WarningLog

#: A window whose noise is this many times below the reference's on most axes means
#: the reference was taken while the IMU moved.
QUIETER = 3.0
#: A stretch noisier than the reference by more than this never replaces it.
NOISIER = 1.5
#: Steps between still window means kept to measure a window mean's noise, and the
#: fewest that do.
NOISE_WINDOWS = 300
MIN_STEPS = 20
#: Steps taken from the end of each run of still windows.
_RUN_TAIL = 60
#: Reference noise floor as a share of the threshold caps (quantised sensors).
_FLOOR = 0.01
#: Fewest samples a window holds [samples]: below 10 Hz a window is longer than
#: ``motion_window_s``.  The mean and standard deviation of two samples (a 1 s window at
#: 1 Hz) judge nothing, and the first window is the reference: still 1 Hz records gave
#: 1082 false episodes in 20 seeded records of 2 h with windows of 2 samples, 20 with
#: 4, 1 with 6 and none with 10 (9 degrees of freedom per window standard deviation).
MIN_WINDOW = 10


# Long because a window is judged across blocks (held rows, a still reference that
# re-anchors, event counts) and that state survives a checkpoint.
class MotionGate:
    """
    Hold samples until their window is judged; pass the still ones to the feed.

    Parameters
    ----------
    config : SessionConfig
        Motion settings.
    stats : HygieneStats
        Counters (``n_motion_dropped``, ``n_motion_events``, ...).
    warn : WarningLog
        Where motion warnings go.
    feed : imu_allan.pipeline.feed.AccumulatorFeed
        Where still samples go.

    """

    def __init__(self, config: SessionConfig, stats: HygieneStats, warn: WarningLog, feed):
        self.config = config
        self.stats = stats
        self._warn = warn
        self.feed = feed
        self._caps = np.array([config.motion_gyro_rad_s] * 3 + [config.motion_accel_m_s2] * 3)
        self.ref_mean: np.ndarray | None = None
        self.ref_std: np.ndarray | None = None
        self._win_t: list[np.ndarray] = []
        self._win_y: list[np.ndarray] = []
        self._win = 2                  # rows per window, set from the rate
        # Share of the samples that repeat the one before (held values), per axis: a
        # window holds only win * (1 - held) independent samples.
        self.held = np.zeros(N_AXES)
        # Squared steps between the means of consecutive still windows (the last
        # NOISE_WINDOWS): the noise of a window mean, coloured noise included.
        self._steps2 = np.empty((0, N_AXES))
        self._last_mean: np.ndarray | None = None
        self._ref_windows = 0          # still windows seen under the reference
        self.moving = False            # the gate is closed
        self._in_motion = False        # the last window moved
        self._still_since_ns: int | None = None
        # The stretch of mutually consistent windows while the gate is closed.
        self._cand_mean: np.ndarray | None = None
        self._cand_std: np.ndarray | None = None
        self._cand_n = 0
        self._cand_since_ns: int | None = None

    # ------------------------------------------------------------------ input
    def take(self, stamp_ns: np.ndarray, samples: np.ndarray, rate_hz: float) -> None:
        """
        Hold samples until their motion window is judged, then pass or drop them.

        Rows wait at most one window, so no sample reaches the accumulator before the
        check that could reject it.  Windows are cut from the stream, not from the
        blocks: only the rows held from the last block are copied.
        """
        if stamp_ns.size == 0:
            return
        win = self._win = max(int(round(self.config.motion_window_s * rate_hz)), MIN_WINDOW)
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
                self.feed.pass_on()
                return
            self._judge_windows(head_t, head_y, win)
        n_full = (t.size // win) * win
        if n_full:
            self._judge_windows(t[:n_full], y[:n_full], win)
        # Copies (at most one window): the caller may reuse its arrays after add().
        self._win_t, self._win_y = (([t[n_full:].copy()], [y[n_full:].copy()])
                                    if n_full < t.size else ([], []))
        self.feed.pass_on()

    def flush(self) -> None:
        """Pass the held partial window on as still (end of data or a segment break)."""
        if self._win_y and self._win_y[0].shape[0]:
            if not self.moving:
                self.feed.queue(np.concatenate(self._win_y), np.concatenate(self._win_t))
        self.feed.pass_on()
        self._win_t, self._win_y = [], []

    def thresholds(self) -> np.ndarray:
        """Shape (6,): largest still offset of a window mean, per axis [rad/s, m/s^2]."""
        if self.ref_std is None:
            return self._caps
        if self._steps2.shape[0] < MIN_STEPS:
            return self.thresholds_for(self.ref_std)
        # Median of chi-square(1) = 0.4549; a step holds two window means' noise.
        noise = np.sqrt(np.median(self._steps2, axis=0) / (2 * 0.4549))
        floor = _FLOOR * self._caps / np.sqrt(self._win)
        return np.minimum(self._caps, self.config.motion_sigma * np.maximum(noise, floor))

    def _note_still(self, means: np.ndarray, whole: bool = True) -> None:
        """Note the means (k, 6) of consecutive still windows; ``whole``: none skipped."""
        if whole and self._last_mean is not None:
            means = np.concatenate((self._last_mean[None], means))
        steps2 = np.diff(means, axis=0) ** 2
        self._steps2 = np.concatenate((self._steps2, steps2))[-NOISE_WINDOWS:]
        self._last_mean = means[-1].copy()

    # ------------------------------------------------------------ judgement
    def _judge_windows(self, t: np.ndarray, y: np.ndarray, win: int) -> None:
        """
        Judge whole windows in order; runs of still ones are found by one scan.

        While the gate is open, the still windows up to the next that moved go on as
        one run; that window, and every window while the gate is closed, are judged
        one by one.  The last window of a run is checked for being much quieter than
        the reference (the scan does not look at that).
        """
        n_windows = t.size // win
        ratio = self.config.motion_std_ratio
        i = 0
        while i < n_windows:
            if self.ref_mean is not None and self.ref_std is not None and not self.moving:
                still, mean, std = _still_run(y[i * win:], win, self.thresholds(), ratio,
                                              self.ref_mean, self.ref_std)
                if still:
                    self._in_motion = False
                    self.feed.queue(y[i * win:(i + still) * win], t[i * win:(i + still) * win])
                    k = min(still, _RUN_TAIL + 1)     # the run's last windows
                    tail = y[(i + still - k) * win:(i + still) * win]
                    self._note_still(tail.reshape(k, win, -1).mean(axis=1), k == still)
                    self._ref_windows += still
                    i += still
                    last_std = _window_stats(y[(i - 1) * win:i * win][None])[1][0]
                    if last_std.any() and self._quieter(last_std, self.ref_std):
                        self._close()       # (a frozen window is no quieter stillness)
                if i == n_windows:
                    return
                if mean is None or self.moving:
                    continue
            else:
                means, stds = _window_stats(y[i * win:(i + 1) * win][None])
                mean, std = means[0], stds[0]
            k = slice(i * win, (i + 1) * win)
            self._judge_window(t[k], y[k], mean, std)
            i += 1

    def _judge_window(self, t: np.ndarray, y: np.ndarray, mean: np.ndarray,
                      std: np.ndarray) -> None:
        if not std.any() and self.ref_mean is not None:
            # Six values repeated for a whole window: a frozen read (the sample checks
            # name it), never a quieter stretch to take as the reference (a 300 s freeze
            # of ADIS16405 run 5 became it, and the hour was refused as motion).
            if self.moving:
                self.stats.n_motion_dropped += t.size
            else:
                self.feed.queue(y, t)
            return
        std = np.maximum(std, _FLOOR * self._caps)
        if self.ref_mean is None or self.ref_std is None:
            # The first window: a provisional reference, replaced when it was motion.
            self.ref_mean, self.ref_std = np.array(mean, dtype=np.float64), std
            self.feed.queue(y, t)
            return
        moved = self._moved(mean, std)
        if moved and not self._in_motion:
            self.stats.n_motion_events += 1
        self._in_motion = moved
        if self.config.on_motion == 'warn':
            if not moved:
                _follow_drift(self.ref_mean, mean)
            self.feed.queue(y, t)
            return
        if not moved and not self.moving:
            _follow_drift(self.ref_mean, mean)
            self._note_still(mean[None])
            self._ref_windows += 1
            self.feed.queue(y, t)
            return
        if not self.moving:
            self._close()
        self._follow_stretch(int(t[0]), mean, std)
        if not moved:
            # Still again: wait settle_s before trusting the samples.
            if self._still_since_ns is None:
                self._still_since_ns = int(t[0])
            if t[-1] - self._still_since_ns >= self.config.settle_s * NS:
                self._open()
                self._warn('resume', 'the IMU is still again: accumulation resumed',
                           once=False)
                self.feed.queue(y, t)
                return
        else:
            self._still_since_ns = None
        assert self._cand_since_ns is not None and self._cand_std is not None
        if (t[-1] - self._cand_since_ns >= self.config.anchor_s * NS
                and np.median(self._cand_std / self.ref_std) <= NOISIER
                and self._may_reanchor()):
            self._reanchor()
            self.feed.queue(y, t)
            return
        self.stats.n_motion_dropped += t.size

    def _moved(self, mean: np.ndarray, std: np.ndarray) -> bool:
        """Whether a window moved against the reference (the scan's rule), with a warning."""
        assert self.ref_mean is not None and self.ref_std is not None
        moving_axes, dev, ratio = _moved_axes(mean, std, self.thresholds(),
                                              self.config.motion_std_ratio, self.ref_mean,
                                              self.ref_std)
        quieter = self._quieter(std, self.ref_std)
        if not moving_axes.any() and not quieter:
            return False
        names = ', '.join(AXES[j] for j in np.flatnonzero(moving_axes))
        what = (f'on {names} (mean off by up to {dev.max():.3g}, noise x{ratio.max():.2g})'
                if names else f'(the noise dropped to 1/{np.median(1 / ratio):.2g} of the '
                'reference: it was taken in motion)')
        action = {'warn': 'samples kept (on_motion=warn)',
                  'pause': 'accumulation paused until still',
                  'restart': 'restarting from scratch once still'}[self.config.on_motion]
        self._warn('motion', f'motion detected {what}: the IMU is not stationary; {action}',
                   once=False)
        return True

    def thresholds_for(self, ref_std: np.ndarray) -> np.ndarray:
        """
        Mean-offset thresholds (6,) from a per-sample noise (6,) alone.

        ``motion_sigma`` times 1.5 times the white noise of a window's mean,
        ``ref_std / sqrt(n)`` with ``n`` the window's distinct updates (its samples
        less the held ones): room for coloured noise until the steps between still
        windows measure it (:meth:`thresholds`).
        """
        updates = np.maximum(self._win * (1.0 - self.held), 1.0)
        return np.minimum(self._caps,
                          self.config.motion_sigma * 1.5 * ref_std / np.sqrt(updates))

    def _quieter(self, std: np.ndarray, ref_std: np.ndarray) -> bool:
        std = np.maximum(std, _FLOOR * self._caps)
        return bool(np.median(ref_std / std) > QUIETER)

    def _close(self) -> None:
        """Close the gate: stop passing samples on (pause) or start again (restart)."""
        self.moving = True
        self._still_since_ns = None
        self._cand_n = 0
        self._last_mean = None
        self.feed.pass_on()
        self.feed.break_segment()
        if self.config.on_motion == 'restart':
            self.stats.n_restarts += 1
            self.feed.restart()

    def _open(self) -> None:
        self.moving = False
        self._still_since_ns = None
        self._cand_n = 0

    def _follow_stretch(self, start_ns: int, mean: np.ndarray, std: np.ndarray) -> None:
        """Extend the stretch of consistent windows with this one, or start a new one."""
        if (self._cand_n and self._cand_mean is not None and self._cand_std is not None
                and not _moved_axes(mean, std, self.thresholds_for(self._cand_std),
                                    self.config.motion_std_ratio, self._cand_mean,
                                    self._cand_std)[0].any()
                and not self._quieter(std, self._cand_std)):
            self._cand_n += 1
            self._cand_mean += (mean - self._cand_mean) / self._cand_n
            self._cand_std += (std - self._cand_std) / self._cand_n
            return
        self._cand_n = 1
        self._cand_mean = np.array(mean, dtype=np.float64)
        self._cand_std = np.array(std, dtype=np.float64)
        self._cand_since_ns = start_ns

    def _may_reanchor(self) -> bool:
        """
        Whether the consistent stretch may become the reference.

        When it is much quieter (the reference was motion), when it has lasted as long
        as the still data under the reference (the dominant level wins), or when the
        gyros are at their old level (an IMU parked at another tilt has other
        accelerometer means; one that keeps turning slowly, other gyro means).
        """
        assert self._cand_mean is not None and self._cand_std is not None
        assert self.ref_mean is not None and self.ref_std is not None
        if self._quieter(self._cand_std, self.ref_std) or self._cand_n >= self._ref_windows:
            return True
        return bool((np.abs(self._cand_mean - self.ref_mean) <= self.thresholds())[:3].all())

    def _reanchor(self) -> None:
        """Make the consistent stretch the still reference and open the gate."""
        assert self._cand_mean is not None and self._cand_std is not None
        assert self.ref_std is not None
        quieter = self._quieter(self._cand_std, self.ref_std)
        self.ref_mean, self.ref_std = self._cand_mean.copy(), self._cand_std.copy()
        self._steps2, self._last_mean = self._steps2[:0], None
        self._ref_windows = self._cand_n
        self.stats.n_reanchors += 1
        if quieter and self.stats.n_used:
            # What passed for still under the old reference was motion.
            self.stats.n_motion_dropped += self.stats.n_used
            self.feed.restart()
            self._warn('reanchor', 'the still reference was taken while the IMU moved (the '
                       'data got much quieter later): the samples before the quiet stretch '
                       'are dropped', once=False)
        else:
            self._warn('reanchor', 'the IMU settled at another still level: it is the new '
                       'reference', once=False)
        self._open()

    # ------------------------------------------------------------- checkpoint
    def state(self) -> tuple[dict, dict]:
        """Return (JSON-able state, arrays) of the gate."""
        def listed(a):
            return None if a is None else a.tolist()
        return ({'ref_mean': listed(self.ref_mean), 'ref_std': listed(self.ref_std),
                 'moving': self.moving, 'in_motion': self._in_motion,
                 'still_since_ns': self._still_since_ns,
                 'cand_mean': listed(self._cand_mean), 'cand_std': listed(self._cand_std),
                 'cand_n': self._cand_n, 'cand_since_ns': self._cand_since_ns,
                 'last_mean': listed(self._last_mean), 'win': self._win,
                 'ref_windows': self._ref_windows},
                {'held_stamp_ns': np.concatenate(self._win_t or [np.empty(0, np.int64)]),
                 'held_samples': np.concatenate(self._win_y or [np.empty((0, N_AXES))]),
                 'motion_steps2': self._steps2})

    def restore(self, meta, arrays: dict) -> None:
        """Take the state of :meth:`state`; InputError when it is invalid."""
        if not isinstance(meta, dict) or set(meta) != set(self.state()[0]):
            raise InputError('the motion gate state is incomplete')
        vectors = {}
        for key in ('ref_mean', 'ref_std', 'cand_mean', 'cand_std', 'last_mean'):
            v = meta[key]
            if v is not None:
                v = np.asarray(v, dtype=np.float64)
                if v.shape != (N_AXES,) or not np.isfinite(v).all():
                    raise InputError(f'the motion reference {key} is invalid')
                if key.endswith('std') and (v <= 0).any():
                    raise InputError(f'the motion reference {key} is not positive')
            vectors[key] = v
        if (vectors['ref_mean'] is None) != (vectors['ref_std'] is None):
            raise InputError('the motion reference is half missing')
        for key in ('still_since_ns', 'cand_since_ns'):
            if meta[key] is not None and not isinstance(meta[key], int):
                raise InputError(f'the motion field {key} is invalid')
        n = meta['cand_n']
        if not isinstance(n, int) or n < 0 or (n and vectors['cand_std'] is None):
            raise InputError('the motion stretch is invalid')
        steps2 = arrays.get('motion_steps2')
        if (steps2 is None or steps2.ndim != 2 or steps2.shape[1] != N_AXES
                or steps2.shape[0] > NOISE_WINDOWS or not np.isfinite(steps2).all()):
            raise InputError('the steps between still windows are invalid')
        if not isinstance(meta['win'], int) or meta['win'] < 2:
            raise InputError('the motion window is invalid')
        if not isinstance(meta['ref_windows'], int) or meta['ref_windows'] < 0:
            raise InputError('the count of still windows is invalid')
        t, y = arrays.get('held_stamp_ns'), arrays.get('held_samples')
        if (t is None or y is None or t.ndim != 1 or y.shape != (t.size, N_AXES)
                or not np.isfinite(y).all()):
            raise InputError('the samples held for the motion check are invalid')
        self.ref_mean, self.ref_std = vectors['ref_mean'], vectors['ref_std']
        self._cand_mean, self._cand_std = vectors['cand_mean'], vectors['cand_std']
        self._cand_n, self._cand_since_ns = n, meta['cand_since_ns']
        self._steps2, self._last_mean = steps2.astype(np.float64), vectors['last_mean']
        self._win, self._ref_windows = meta['win'], meta['ref_windows']
        self.moving, self._in_motion = bool(meta['moving']), bool(meta['in_motion'])
        self._still_since_ns = meta['still_since_ns']
        self._win_t, self._win_y = (([t.astype(np.int64)], [y.astype(np.float64)])
                                    if t.size else ([], []))


def _moved_axes(mean: np.ndarray, std: np.ndarray, thr: np.ndarray, ratio_limit: float,
                ref_mean: np.ndarray, ref_std: np.ndarray) -> tuple:
    """
    Judge one window against the still reference (the rule :func:`_still_run` scans with).

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


def _still_run(y: np.ndarray, win: int, thr: np.ndarray, ratio_limit: float,
               ref_mean: np.ndarray, ref_std: np.ndarray) -> tuple:
    """
    Find the first window that moved; pull the reference along the still ones before it.

    Window by window with :func:`_moved_axes` and :func:`_follow_drift`, as
    :meth:`_SampleChecks._window_moving` judges one window.

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
