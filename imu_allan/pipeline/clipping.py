"""
Clipped axes: values that pile up at the ends of a sensor's range.

A sensor whose range is below its signal (a gyro set to its narrowest full scale, an
accelerometer at +-2 g on a vibrating mount) reports every value beyond the range as
the range itself.  Its noise then reads low (every difference of two clipped values
shrinks), with no warning: a gyro clipped at its noise peaks gave N 0.22 times the
truth.

:class:`ClipWatch` keeps, per axis and end, the two most extreme distinct values and
how often each was seen.  Noise thins out towards its extremes (the most extreme value
is rare, a quantised one no more frequent than the value next to it); a clipped axis
piles its samples on the extreme: at least :data:`PILE_MIN` of them and
:data:`PILE_RATIO` times the next value's count, that next value within
:data:`STEP_MAX` sds of the axis (a fine resolution: a sensor quantised coarser than
its noise has a few levels only, its top level may well hold most samples).
Quantisation repeats values at every level alike, and held values (a driver faster
than its sensor) repeat every value alike, so neither is taken for clipping.

What it means: clipping a white noise of sd sigma at +-c sigma leaves the variance at
1 - s - 2 c phi(c) + s c^2 of its own (s = 2 (1 - Phi(c)) the share clipped; the
moments of a censored normal, e.g. Johnson, Kotz and Balakrishnan, Continuous
Univariate Distributions 1, ch. 13): 0.9998 at s = 1e-4, 0.998 at 1e-3, 0.982 at 1e-2.
Up to :data:`KEEP_SHARE` the axis is analysed as it is (its N reads at most about 0.1 %
low, inside a long record's interval) and named in a warning; above, its parameters
are left out: no bound of them is honest once the curve's shape is clipped.
"""

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, WarningLog

#: Samples on an extreme value before it can be a pile.
PILE_MIN = 10
#: An extreme value seen at least this many times as often as the next is a pile.
PILE_RATIO = 4.0
#: The value next to a pile is within this many of the axis' sds (else: a coarse
#: quantisation whose levels are the only values).
STEP_MAX = 0.5
#: Share of an axis' samples clipped up to which the axis is still analysed.
KEEP_SHARE = 1e-3
#: What every clipping warning says (consumer files carry those lines).
CLIPPED = ' is clipped: '


def left_out(stats: HygieneStats) -> set:
    """Return the axes too clipped to report (more than :data:`KEEP_SHARE` clipped)."""
    return {axis for axis, share in stats.clipped.items() if share > KEEP_SHARE}


class ClipWatch:
    """
    Find the axes whose values pile up at the ends of their range.

    Parameters
    ----------
    stats : HygieneStats
        ``clipped`` holds the share per clipped axis.
    warn : WarningLog
        Where the warning goes.
    units : tuple of str
        Unit of each axis, for the warning.

    """

    def __init__(self, stats: HygieneStats, warn: WarningLog, units: tuple):
        self.stats = stats
        self._warn = warn
        self._units = units
        # Per axis, for the top end and (negated) the bottom end: the extreme value and
        # the next one, and their counts.
        self.value = np.full((2, N_AXES, 2), -np.inf)
        self.count = np.zeros((2, N_AXES, 2), dtype=np.int64)
        self.n = 0
        # Sums of the values (less the first row's, against cancellation) and squares.
        self.sums = np.zeros((3, N_AXES))

    def take(self, samples: np.ndarray) -> None:
        """Count a block's extremes (n, 6); warn when an axis is first seen clipped."""
        y = samples[np.isfinite(samples).all(axis=1)]
        if not y.shape[0]:
            return
        if not self.n:
            self.sums[0] = y[0]
        d = y - self.sums[0]
        with np.errstate(over='ignore', invalid='ignore'):
            self.sums[1] += d.sum(axis=0)
            self.sums[2] += (d * d).sum(axis=0)
        self.n += y.shape[0]
        for end, vals in ((0, y), (1, -y)):
            keep = vals >= self.value[end, :, 1]
            for j in np.flatnonzero(keep.any(axis=0)):
                self._merge(end, int(j), vals[keep[:, j], j])
        self._judge()

    def _merge(self, end: int, j: int, values: np.ndarray) -> None:
        vals, counts = np.unique(values, return_counts=True)
        old = np.isfinite(self.value[end, j])
        vals = np.concatenate((vals, self.value[end, j][old]))
        counts = np.concatenate((counts, self.count[end, j][old]))
        keys, where = np.unique(vals, return_inverse=True)
        sums = np.bincount(where, weights=counts).astype(np.int64)
        top = min(2, keys.size)
        self.value[end, j, :top] = keys[::-1][:top]
        self.count[end, j, :top] = sums[::-1][:top]

    def _judge(self) -> None:
        n1, n2 = self.count[..., 0], self.count[..., 1]
        if not (n1 >= PILE_MIN).any():      # no pile anywhere: nothing to judge
            return
        # A value no sensor reads (1e154, a spike for the filter after) overflows the
        # sums: that axis' sd is NaN and it is not judged clipped.
        with np.errstate(over='ignore', invalid='ignore'):
            mean = self.sums[1] / self.n
            sd = np.sqrt(np.maximum(self.sums[2] / self.n - mean * mean, 0.0))
            fine = (self.value[..., 0] - self.value[..., 1]) <= STEP_MAX * sd
        pile = (n1 >= PILE_MIN) & (n1 >= PILE_RATIO * n2) & fine
        clipped = (n1 * pile).sum(axis=0)
        new = [int(j) for j in np.flatnonzero(clipped) if AXES[j] not in self.stats.clipped]
        for j in np.flatnonzero(clipped):
            self.stats.clipped[AXES[j]] = round(float(clipped[j] / self.n), 6)
        for k in new:
            self._warn_clipped(k, pile[:, k])

    def _warn_clipped(self, j: int, ends: np.ndarray) -> None:
        axis, share = AXES[j], self.stats.clipped[AXES[j]]
        levels = [f'{self.value[0, j, 0]:.6g}'] if ends[0] else []
        levels += [f'{-self.value[1, j, 0]:.6g}'] if ends[1] else []
        what = ('its noise is analysed as it is (at this share it reads under 0.2 % low)'
                if share <= KEEP_SHARE else 'its parameters are left out (its noise reads '
                'low, and no bound of it is honest)')
        self._warn(f'clipped-{axis}', f'{axis}{CLIPPED}{100 * share:.3g} % of its samples '
                   f'so far sit at {" and ".join(levels)} {self._units[j]}, the end of the '
                   f"sensor's range; {what}. Set a wider range (the driver's full-scale "
                   'setting) and record again')

    # ------------------------------------------------------------- checkpoint
    def state(self) -> tuple[dict, dict]:
        """Return (JSON-able state, arrays)."""
        return {'n': self.n}, {'clip_value': self.value.copy(), 'clip_count': self.count.copy(),
                               'clip_sums': self.sums.copy()}

    def restore(self, meta, arrays: dict) -> None:
        """Take the state of :meth:`state` (nothing saved: a checkpoint from before)."""
        value, count = arrays.get('clip_value'), arrays.get('clip_count')
        sums = arrays.get('clip_sums')
        if value is None and count is None:
            return
        n = meta.get('n') if isinstance(meta, dict) else None
        if (value is None or count is None or sums is None or value.shape != self.value.shape
                or count.shape != self.count.shape or sums.shape != self.sums.shape
                or not isinstance(n, int) or n < 0 or (count < 0).any()):
            raise InputError('the clipping counters are invalid')
        self.value, self.count, self.n = value.astype(np.float64), count.astype(np.int64), n
        self.sums = sums.astype(np.float64)
