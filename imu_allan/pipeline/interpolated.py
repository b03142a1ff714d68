"""
Interpolated values: a driver that interpolates a slower sensor onto a faster stream.

A driver that unites two streams of different rates may publish the slower one
interpolated between its updates onto the faster one's stamps: realsense-ros'
``unite_imu_method: linear_interpolation`` publishes each gyro message with the
accelerometer interpolated to its stamp (realsense-ros#558; a D435i's default 200 Hz
gyro and 63 Hz accelerometer interpolate about 3.2 messages per update).  Such values
are no samples of the sensor: they smooth its noise, so the Allan curve falls below the
white line at the shortest taus (by about 0.7 k / m of the variance at m samples for k
samples per update, a simulation of 1,000,000 samples, docs/input_gate.md) and the fit
mistakes the bend for a filter or a missing term.

Where three messages in a row fall between the same two updates, the middle one lies on
the straight line through its neighbours, in time; a sensor's own noisy samples almost
never do.  :class:`InterpWatch` counts, per axis, the moving triples (both steps
non-zero) and those on a straight line within :data:`~imu_allan.core.rules.
INTERP_REL_TOL` of the values (float32 arithmetic and full-precision logs keep far
more); an axis is interpolated once at least :data:`~imu_allan.core.rules.
INTERP_MIN_TRIPLES` moving triples were counted and a share of
:data:`~imu_allan.core.rules.INTERP_MIN` lies on a line (k samples per update make
(k - 2) / k of them: 0.2 at k = 2.5, 0.38 at 3.2; a sensor's own samples 0-0.05 on the
bench's records).  Axes on a value grid (an LSB about the noise: their steps repeat by
chance) are not judged.  Below three messages per update (k <= 2: a 400 Hz gyro and
250 Hz accelerometer) no triple shares an interval and nothing can be told.
"""

import numpy as np

from imu_allan import AXES
from imu_allan.core.rules import INTERP_MIN, INTERP_MIN_TRIPLES, INTERP_REL_TOL
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, WarningLog

#: What the warning says the values are (the bench matches 'linear_interpolation').
INTERPOLATED = 'interpolated values'


class InterpWatch:
    """
    Count the triples on a straight line per axis; warn when an axis is interpolated.

    Parameters
    ----------
    stats : HygieneStats
        ``interpolated`` gets the share per axis found interpolated.
    warn : WarningLog
        Where the warning goes.

    """

    def __init__(self, stats: HygieneStats, warn: WarningLog):
        self.stats = stats
        self._warn = warn
        # Per axis: moving triples, and those on a straight line.
        self.counts = np.zeros((2, N_AXES), dtype=np.int64)
        # The last two rows of the segment (the next block's first triples need them).
        self._tail_ns = np.empty(0, dtype=np.int64)
        self._tail = np.empty((0, N_AXES))

    def take(self, stamp_ns: np.ndarray, samples: np.ndarray) -> None:
        """
        Count a gap-free run's triples (:meth:`judge` decides).

        Parameters
        ----------
        stamp_ns, samples : numpy.ndarray
            Shapes (n,) and (n, 6): the run's stamps [ns] and finite values [unit].

        """
        t = np.concatenate((self._tail_ns, stamp_ns)) if self._tail_ns.size else stamp_ns
        y = np.concatenate((self._tail, samples)) if self._tail_ns.size else samples
        self._tail_ns, self._tail = t[-2:].copy(), y[-2:].copy()
        if t.size < 3:
            return
        dt = np.diff(t).astype(np.float64)[:, None]
        # Huge finite values (spikes near the float range) overflow to inf: not on a line.
        with np.errstate(over='ignore', invalid='ignore'):
            step = np.diff(y, axis=0)
            # Twice the signed area of each triple over (t, y): 0 on a straight line.
            cross = step[1:] * dt[:-1] - step[:-1] * dt[1:]
            span = dt[1:] + dt[:-1]
            tol = INTERP_REL_TOL * (np.abs(y[:-2]) + 2 * np.abs(y[1:-1]) + np.abs(y[2:])) * span
            moving = (np.abs(step[1:]) * span > tol) & (np.abs(step[:-1]) * span > tol)
            self.counts[0] += moving.sum(axis=0)
            self.counts[1] += (moving & (np.abs(cross) <= tol)).sum(axis=0)

    def end_segment(self) -> None:
        """Forget the last rows: no triple spans a break."""
        self._tail_ns, self._tail = self._tail_ns[:0], self._tail[:0]

    def judge(self, rate_hz: float) -> None:
        """
        Note the interpolated axes' shares; warn when an axis is first found.

        Called once the run's values were seen by the zero watch, which finds the axes
        on a value grid (``stats.value_grid``).

        Parameters
        ----------
        rate_hz : float
            The stream's rate [Hz] (for the warning).

        """
        share = self.counts[1] / np.maximum(self.counts[0], 1)
        found = (self.counts[0] >= INTERP_MIN_TRIPLES) & (share >= INTERP_MIN)
        if not found.any() and not self.stats.interpolated:    # the usual case, judged fast
            return
        found &= [axis not in self.stats.value_grid for axis in AXES]
        known = set(self.stats.interpolated)
        for j in np.flatnonzero(found):
            self.stats.interpolated[AXES[j]] = 0.0
        for axis in self.stats.interpolated:     # once found, the share of the whole record
            self.stats.interpolated[axis] = round(float(share[AXES.index(axis)]), 4)
        if set(self.stats.interpolated) == known:
            return
        axes = list(self.stats.interpolated)
        # The median: an axis offset by gravity counts a few more lines (its tolerance).
        share_mid = float(np.median([self.stats.interpolated[a] for a in axes]))
        # (k - 2) / k of the triples of k messages per update lie on a line.
        per_update = 2.0 / max(1.0 - share_mid, 1e-3)
        self._warn.tally('interpolated', (
            f'{INTERPOLATED} (a driver that interpolates a slower sensor between its updates '
            'onto the stamps of a faster stream, e.g. realsense-ros unite_imu_method '
            f'linear_interpolation): on {", ".join(axes)} {100 * share_mid:.0f} % of the samples '
            'lie on the straight line through their neighbours (updates about every '
            f'{per_update:.2g} samples, {rate_hz / per_update:.3g} Hz); interpolation '
            'smooths the noise, so the shortest taus lie below the white line and the fit may '
            "not be trusted. Analyse the sensor's own samples (its separate topic, or "
            'unite_imu_method copy, whose held values are modelled)'))

    # ------------------------------------------------------------- checkpoint
    def state(self) -> dict:
        """Return the arrays of the counts."""
        return {'interp_counts': self.counts.copy()}

    def restore(self, arrays: dict) -> None:
        """Take the arrays of :meth:`state` (none saved: a checkpoint from before)."""
        counts = arrays.get('interp_counts')
        if counts is None:
            return
        if counts.shape != (2, N_AXES) or (counts < 0).any() or (counts[1] > counts[0]).any():
            raise InputError('the interpolation counts are invalid')
        self.counts = counts.astype(np.int64)
