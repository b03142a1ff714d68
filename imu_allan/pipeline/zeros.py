"""
Zero-filled fields: exact zeros a driver sends for the fields of an incomplete packet.

A serial or USB driver that loses part of a packet, or unites separate gyro and accel
streams, may publish the fields it did not receive as 0.0 (ethzasl_xsens_driver#91,
realsense-ros#2551).  Where the axis reads far from 0 the zeros are spikes, but where
it reads near 0 they pass as data: 10 % of the MPU-6050 record's messages with their
gyro or accel zeroed gave gyro_z N 2.7 times the clean record's, with no warning
(docs/robustness.md).

:class:`ZeroWatch` counts, per axis, the exact zeros, the values nearest to 0 on each
side and how often each was seen, and the mean and sd of the non-zero values
(:class:`~imu_allan.pipeline.clipping.ClipWatch` does the same at the ends of the
range), and the least step between distinct values of its first rows (the LSB).  An axis' zeros are
fills when there are at least :data:`~imu_allan.core.rules.ZERO_MIN` of them and
either a value next to 0 (within :data:`~imu_allan.core.rules.ZERO_STEP_MAX` sds, or
:data:`~imu_allan.core.rules.ZERO_GRID` LSBs) is seen
:data:`~imu_allan.core.rules.ZERO_RATIO` times less often (a pile at 0, not a level of
the distribution: a quantised axis reads 0 about as often as the levels next to it),
or no value is near 0 and 0 lies :data:`~imu_allan.core.rules.ZERO_FAR` sds from the
mean.  An axis quantised coarser than its noise, which may read 0 most of the time,
is left alone.  Zeros are no pile either where a level of the axis' values anywhere is
seen as often as 0 would be by the normal of its values (a summary of the most frequent
values, Misra and Gries 1982, :data:`HEAVY_LEVELS` counters): the nearest value to 0 may
be a single value of a stretch off the grid (a quantised axis whose bias a driver or a
warm-up shifted for a while), while 0 is a level of the grid the rest of the record
takes.  Rows whose three gyro (or accel) values are all 0 are fills when they
are :data:`~imu_allan.core.rules.ZERO_RATIO` times as many as the three axes' shares
of zeros make by chance: a packet's vector zeroed on axes that each read 0 now and
then (the ADIS16405's gyros read 0 on 3-4 % of their samples).

A row with a zero-filled field is a lost message: all six values are replaced by the
linear interpolation between the nearest rows without one and marked as fills
(:func:`~imu_allan.pipeline.fills.as_fills`), so the accumulator leaves the terms over
them out at short taus and takes the fills' excess off the others, as for a short gap
in the stamps.  The row keeps its stamp, so irregular stamps keep their rate.  Rows at
an end of a block take the value of their one neighbour (the rows are missing
samples either way; the last row of the block before is the left one), and rows with
no neighbour in their segment are dropped; a run of more than ``max_fill_samples``
such rows is dropped and ends the segment, as a long gap does.  The verdict counts the
rows so far: the first rows of a live stream (fewer than ``ZERO_MIN`` zeros) pass as
data.
"""

import numpy as np

from imu_allan import AXES
from imu_allan.core.rules import ZERO_FAR, ZERO_GRID, ZERO_MIN, ZERO_RATIO, ZERO_STEP_MAX
from imu_allan.errors import InputError
from imu_allan.pipeline.fills import as_fills, filled
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, WarningLog
from imu_allan.pipeline.steps import split_runs

#: What the warning says the rows are (the bench matches 'zero').
ZERO_FILLED = 'zero-filled fields'
#: Values closer than this share of an axis' largest value are one level: a mean or a
#: scaled count computed in another order differs in its last bits (block means of a
#: quantised ADIS16405 spread each level, 0 too, over many float values, so that the
#: value next to 0, 1e-18, seemed 40 times rarer than 0 itself).
LEVEL_TOL = 1e-9
#: Rows over which the least step between levels (the LSB) is looked for.
LEVEL_ROWS = 1 << 17
#: An axis whose first rows take at most this many distinct values lies on a grid; its
#: step (``value_grid``) is the median step between them, which holds where a grid was
#: rounded again onto an incommensurate one (uneven steps: the least step then
#: understates it).  Values on no grid pass this count within the first thousand rows.
GRID_LEVELS = 1024
#: The axes of each sensor, whose fields an incomplete packet zeroes together.
SENSORS = (slice(0, 3), slice(3, 6))
#: Counters of the most frequent non-zero values per axis: every value seen on more than
#: 1 / (HEAVY_LEVELS + 1) of an axis' rows keeps one (a grid's levels near its mean).
HEAVY_LEVELS = 32
#: Rows gathered before they are added to the summary of frequent values (a summary per
#: block would cost a node's one-row blocks a sort each).  The batches start at fixed
#: row counts, so the summary does not depend on how the rows were cut into blocks.
HEAVY_BATCH = 256


# Long because its counters survive a checkpoint, validated one by one, and the rows
# at a block's ends are filled from the block before.
class ZeroWatch:
    """
    Find the axes whose exact zeros are fills, and make their rows lost samples.

    Parameters
    ----------
    stats : HygieneStats
        ``n_zero_rows`` and ``zero_filled`` count what was found.
    warn : WarningLog
        Where the warning goes.
    max_fill : int
        ``SessionConfig.max_fill_samples``: longer runs of such rows end the segment.

    """

    def __init__(self, stats: HygieneStats, warn: WarningLog, max_fill: int):
        self.stats = stats
        self._warn = warn
        self._max_fill = max_fill
        # Per axis: exact zeros; the nearest value below and above 0 and their counts.
        self.n_zero = np.zeros(N_AXES, dtype=np.int64)
        self.near = np.array([[-np.inf, np.inf]] * N_AXES)
        self.near_count = np.zeros((N_AXES, 2), dtype=np.int64)
        # Count of the non-zero values, their sums (less the first one) and squares.
        self.n = np.zeros(N_AXES, dtype=np.int64)
        self.sums = np.zeros((3, N_AXES))
        # Per axis, the least step between two distinct values of its first rows (the LSB).
        self.quantum = np.full(N_AXES, np.inf)
        # Per axis, the distinct values of its first rows (sorted), while they are few.
        self.levels: list = [np.empty(0)] * N_AXES
        self.many_levels = np.zeros(N_AXES, dtype=bool)
        # Per sensor (gyro, accel): rows, and rows whose three values are all 0.
        self.n_rows = 0
        self.n_all_zero = np.zeros(len(SENSORS), dtype=np.int64)
        # The last row passed on without a zero-filled field (the left neighbour of the
        # next block's first rows; none at the start or after a segment break).
        self.last_row = np.empty((0, N_AXES))
        # Rows were dropped at the end of the last block: the next run is cut from it.
        self.cut = False
        # The last row seen (a repeat of it is not counted again).
        self.prev_row = np.empty((0, N_AXES))
        # Per axis, the most frequent non-zero values (float32: one level computed in
        # another order is one key) and their counts; the rows not yet added.
        self.heavy = [HeavyLevels() for _ in range(N_AXES)]
        self.pending = np.empty((HEAVY_BATCH, N_AXES))
        self.n_pending = 0

    def take(self, stamp_ns: np.ndarray, samples: np.ndarray):
        """
        Count a gap-free run and yield its runs with zero-filled rows made fills.

        Parameters
        ----------
        stamp_ns, samples : numpy.ndarray
            Shapes (n,) and (n, 6): the run's stamps [ns] and finite values [unit].

        Yields
        ------
        tuple
            ``(stamp_ns (m,), samples (m, 6), broken)``: broken means a long run of
            zero-filled rows was dropped just before (the segment ends there).

        """
        # Rows that fill a gap of the stamps are no readings: neither counted nor judged;
        # a row that repeats the one before is counted once (a held or frozen read of
        # zeros is one reading, not a pile: a 300 s freeze made 30,000).
        fill = filled(samples)
        again = np.empty(samples.shape[0], dtype=bool)
        again[0] = bool(self.prev_row.shape[0]) and bool((samples[0] == self.prev_row[0]).all())
        again[1:] = (samples[1:] == samples[:-1]).all(axis=1)
        self.prev_row = samples[-1:].copy()
        counted = ~again if fill is None else ~again & ~fill
        self._count(samples if counted.all() else samples[counted])
        axes, sensors = self.filled_axes(), self.filled_sensors()
        zero = (samples[:, axes] == 0).any(axis=1) if axes.any() else None
        for k in np.flatnonzero(sensors):
            whole = (samples[:, SENSORS[k]] == 0).all(axis=1)
            zero = whole if zero is None else zero | whole
        if zero is not None and fill is not None:
            zero &= ~fill
        if zero is None or not zero.any():
            self.last_row = samples[-1:].copy()
            cut, self.cut = self.cut, False
            yield stamp_ns, samples, cut
            return
        self._note(samples[zero], int(zero.sum()))
        keep = ~_long_runs(zero, self._max_fill)
        h = self.last_row.shape[0]
        if not h and zero.all():
            keep[:] = False     # nothing to fill them from
        out = _filled(np.concatenate((self.last_row, samples)),
                      np.concatenate((np.zeros(h, bool), zero)))[h:]
        good = np.flatnonzero(~zero)
        if good.size:
            self.last_row = samples[good[-1]:good[-1] + 1].copy()
        cut, self.cut = self.cut, not keep[-1]
        runs = split_runs(stamp_ns, out, None if keep.all() else keep)
        for i, (t, y, broken) in enumerate(runs):
            yield t, y, broken or (cut and i == 0)

    def end_segment(self) -> None:
        """Forget the left neighbour: the next rows do not continue these."""
        self.last_row = self.last_row[:0]
        self.cut = False

    def filled_axes(self) -> np.ndarray:
        """Return which axes' exact zeros are fills so far, shape (6,) bool."""
        counted = (self.n_zero >= ZERO_MIN) & (self.n >= ZERO_MIN)
        if not counted.any():
            return counted
        with np.errstate(over='ignore', invalid='ignore', divide='ignore'):
            n = np.maximum(self.n, 1)
            mean = self.sums[1] / n
            sd = np.sqrt(np.maximum(self.sums[2] / n - mean * mean, 0.0))
            centre = self.sums[0] + mean
            # Mean and sd of every value, the zeros too: a level next to 0 is as rare
            # against 0 as a normal of these makes it (an axis quantised coarser than
            # its noise reads 0 most of the time, its next levels 20 times less often).
            n_all = np.maximum(self.n + self.n_zero, 1)
            mean_all = (self.sums[1] - self.n_zero * self.sums[0]) / n_all
            sd_all = np.sqrt(np.maximum((self.sums[2] + self.n_zero * self.sums[0] ** 2)
                                        / n_all - mean_all * mean_all, 0.0))
            mu = (self.sums[0] + mean_all)[:, None]
            odds = np.exp(np.minimum(((self.near - mu) ** 2 - mu ** 2)
                                     / (2.0 * sd_all[:, None] ** 2), 700.0))
            step = np.maximum(ZERO_STEP_MAX * sd, ZERO_GRID * self.quantum)
            close = np.abs(self.near) <= step[:, None]
            expected = np.where(close, self.near_count * np.maximum(odds, 1.0), 0.0)
            pile = close.any(axis=1) & (self.n_zero >= ZERO_RATIO * expected.max(axis=1))
            far = ~close.any(axis=1) & (np.abs(centre) > ZERO_FAR * sd)
            found = counted & (pile | far)
            for j in np.flatnonzero(found):
                found[j] = self.n_zero[j] >= ZERO_RATIO * self._level_expected(
                    int(j), float(mu[j, 0]), float(sd_all[j]))
        return found

    def _level_expected(self, j: int, mu: float, sd: float) -> float:
        """Return the zeros axis j would read by its most frequent levels' normal odds."""
        # The rows not yet in a batch count too (the pile is judged on them as well).
        levels = HeavyLevels(self.heavy[j].keys, self.heavy[j].counts)
        levels.add(_keys(self.pending[:self.n_pending, j]))
        keys, counts = levels.keys.astype(np.float64), levels.counts
        if not keys.size or not sd > 0:
            return 0.0
        odds = np.exp(np.minimum(((keys - mu) ** 2 - mu * mu) / (2.0 * sd * sd), 700.0))
        return float(np.max(counts * odds))

    def _gather(self, samples: np.ndarray) -> None:
        """Add the rows (n, 6) to the summary of frequent values in whole batches."""
        k = 0
        while k < samples.shape[0]:
            m = min(HEAVY_BATCH - self.n_pending, samples.shape[0] - k)
            self.pending[self.n_pending:self.n_pending + m] = samples[k:k + m]
            self.n_pending, k = self.n_pending + m, k + m
            if self.n_pending == HEAVY_BATCH:
                for j in range(N_AXES):
                    self.heavy[j].add(_keys(self.pending[:, j]))
                self.n_pending = 0

    def filled_sensors(self) -> np.ndarray:
        """
        Return which sensors' all-zero rows are fills so far, shape (2,) bool.

        Rows whose three axes read 0 together are fills when they are
        :data:`~imu_allan.core.rules.ZERO_RATIO` times as many as the axes' own shares
        of zeros make by chance (each axis of a quantised sensor may read 0 often, all
        three at once as often as their product): a packet's vector zeroed.
        """
        counted = self.n_all_zero >= ZERO_MIN
        if not counted.any():
            return counted
        total = np.maximum(self.n + self.n_zero, 1)
        share = self.n_zero / total
        chance = np.array([self.n_rows * np.prod(share[sl]) for sl in SENSORS])
        return counted & (self.n_all_zero >= ZERO_RATIO * chance)

    def _count(self, samples: np.ndarray) -> None:
        zero = samples == 0
        self.n_zero = self.n_zero + zero.sum(axis=0)
        self.n_rows += samples.shape[0]
        self.n_all_zero = self.n_all_zero + np.array(
            [int(zero[:, sl].all(axis=1).sum()) for sl in SENSORS], dtype=np.int64)
        # The LSB shows in the first rows, on every axis (zeros may come later); a sort
        # per block all along would double this count's time.
        if self.n_rows - samples.shape[0] < LEVEL_ROWS:
            self._note_levels(samples)
        self._gather(samples)
        # Sums of the non-zero values, over all axes at once (a loop over the axes
        # costs more than the sums on the blocks of a few rows a node passes on).
        nonzero = ~zero
        count = nonzero.sum(axis=0)
        new = (self.n == 0) & (count > 0)
        if new.any():
            self.sums[0, new] = samples[nonzero.argmax(axis=0)[new], np.flatnonzero(new)]
        with np.errstate(over='ignore', invalid='ignore'):
            d = np.where(nonzero, samples - self.sums[0], 0.0)
            self.sums[1] += d.sum(axis=0)
            self.sums[2] += (d * d).sum(axis=0)
        self.n += count
        # Values within tol of 0 are the zero level computed in another order.
        tols = LEVEL_TOL * np.abs(samples).max(axis=0, initial=0.0)
        # Only values as near to 0 as the nearest seen so far can change it.
        bounds = np.abs(self.near).max(axis=1) + tols
        near = nonzero & (np.abs(samples) <= bounds)
        for j in np.flatnonzero(near.any(axis=0)):
            col, tol = samples[near[:, j], j], float(tols[j])
            for side, vals in ((0, col[col < -tol]), (1, col[col > tol])):
                if not vals.size:
                    continue
                v = float(vals.max() if side == 0 else vals.min())
                if abs(v - self.near[j, side]) <= tol:      # the level seen before
                    v = float(self.near[j, side])
                elif abs(v) > abs(self.near[j, side]):
                    continue
                c = int(np.count_nonzero(np.abs(vals - v) <= tol))
                if v == self.near[j, side]:
                    self.near_count[j, side] += c
                else:
                    self.near[j, side], self.near_count[j, side] = v, c

    def _note_levels(self, samples: np.ndarray) -> None:
        """Keep each axis' least step (the LSB) and, while they are few, its levels."""
        ordered = np.sort(samples, axis=0)
        steps = np.diff(ordered, axis=0)
        tols = LEVEL_TOL * np.abs(ordered).max(axis=0, initial=0.0)
        steps = np.where(steps > tols, steps, np.inf)
        self.quantum = np.minimum(self.quantum, steps.min(axis=0, initial=np.inf))
        changed = False
        for j in np.flatnonzero(~self.many_levels):
            levels = np.union1d(self.levels[j], ordered[:, j])
            if levels.size > GRID_LEVELS:       # no grid: nothing to keep
                levels, self.many_levels[j] = np.empty(0), True
            changed = changed or levels.size != self.levels[j].size or self.many_levels[j]
            self.levels[j] = levels
        if changed:
            self._note_grid()

    def _note_grid(self) -> None:
        """Keep ``stats.value_grid``: the median step of the axes with few levels."""
        for j, axis in enumerate(AXES):
            levels = self.levels[j]
            steps = np.diff(levels)
            steps = steps[steps > LEVEL_TOL * float(np.abs(levels).max(initial=0.0))]
            if self.many_levels[j] or not steps.size:
                self.stats.value_grid.pop(axis, None)
            else:
                self.stats.value_grid[axis] = float(np.median(steps))

    def _note(self, rows: np.ndarray, n_rows: int) -> None:
        """Count the zero-filled rows (m, 6); say so, with the totals so far."""
        self.stats.n_zero_rows += n_rows
        per_axis = (rows == 0).sum(axis=0)
        for j in np.flatnonzero(per_axis):
            self.stats.zero_filled[AXES[j]] = (self.stats.zero_filled.get(AXES[j], 0)
                                               + int(per_axis[j]))
        where = ', '.join(f'{a} {n:,}' for a, n in self.stats.zero_filled.items())
        self._warn.tally('zeros', f'{ZERO_FILLED}: {self.stats.n_zero_rows:,} messages read '
                         f'exactly 0 on axes that otherwise rarely do ({where} zeros): a '
                         'driver that sends 0 for the fields of an incomplete packet; they '
                         'are treated as lost samples (filled between their neighbours, no '
                         'Allan term at short taus uses them). Have the driver drop '
                         'incomplete packets', n_rows)

    # ------------------------------------------------------------- checkpoint
    def state(self) -> dict:
        """Return the arrays of the counters and the left neighbour."""
        return {'zero_pending': self.pending[:self.n_pending].copy(),
                'zero_prev_row': self.prev_row.copy(),
                'zero_heavy': np.array([np.pad(h.keys.astype(np.float64),
                                               (0, HEAVY_LEVELS - h.keys.size),
                                               constant_values=np.nan) for h in self.heavy]),
                'zero_heavy_counts': np.array([np.pad(h.counts, (0, HEAVY_LEVELS - h.counts.size))
                                               for h in self.heavy]),
                'zero_n_zero': self.n_zero.copy(), 'zero_near': self.near.copy(),
                'zero_near_count': self.near_count.copy(), 'zero_n': self.n.copy(),
                'zero_sums': self.sums.copy(), 'zero_quantum': self.quantum.copy(),
                'zero_last_row': self.last_row.copy(),
                'zero_cut': np.array([self.cut]),
                'zero_rows': np.array([self.n_rows, *self.n_all_zero], dtype=np.int64),
                'zero_levels': np.array([np.pad(v, (0, GRID_LEVELS + 1 - v.size),
                                                constant_values=np.nan) for v in self.levels]),
                'zero_many_levels': self.many_levels.copy()}

    def restore(self, arrays: dict) -> None:
        """Take the arrays of :meth:`state` (none saved: a checkpoint from before)."""
        shapes = {'zero_n_zero': self.n_zero.shape, 'zero_near': self.near.shape,
                  'zero_near_count': self.near_count.shape, 'zero_n': self.n.shape,
                  'zero_sums': self.sums.shape, 'zero_quantum': self.quantum.shape,
                  'zero_last_row': None, 'zero_cut': (1,), 'zero_rows': (1 + len(SENSORS),)}
        if all(arrays.get(k) is None for k in shapes):
            return
        got: dict = {k: arrays.get(k) for k in shapes}
        if any(a is None for a in got.values()) or any(
                shape is not None and got[k].shape != shape for k, shape in shapes.items()):
            raise InputError('the zero-field counters are incomplete')
        last = got['zero_last_row']
        if (last.ndim != 2 or last.shape[0] > 1 or last.shape[1] != N_AXES
                or (got['zero_quantum'] <= 0).any() or (got['zero_n_zero'] < 0).any()
                or (got['zero_near_count'] < 0).any() or (got['zero_n'] < 0).any()
                or (got['zero_rows'] < 0).any()):
            raise InputError('the zero-field counters are invalid')
        self.n_zero, self.n = got['zero_n_zero'].astype(np.int64), got['zero_n'].astype(np.int64)
        self._restore_levels(arrays.get('zero_levels'), arrays.get('zero_many_levels'))
        self.near = got['zero_near'].astype(np.float64)
        self.near_count = got['zero_near_count'].astype(np.int64)
        self.sums, self.last_row = got['zero_sums'].astype(np.float64), last.astype(np.float64)
        self.cut, self.quantum = bool(got['zero_cut'][0]), got['zero_quantum'].astype(np.float64)
        self.n_rows, self.n_all_zero = int(got['zero_rows'][0]), got['zero_rows'][1:].copy()
        self._restore_heavy(arrays.get('zero_heavy'), arrays.get('zero_heavy_counts'),
                            arrays.get('zero_pending'))
        prev = arrays.get('zero_prev_row')
        if prev is not None:
            if prev.ndim != 2 or prev.shape[0] > 1 or prev.shape[1] != N_AXES:
                raise InputError('the last row of the zero-field counters is invalid')
            self.prev_row = prev.astype(np.float64)

    def _restore_heavy(self, keys, counts, pending) -> None:
        """Take the frequent values of :meth:`state` (none saved: counted from here)."""
        if keys is None and counts is None and pending is None:
            return
        shape = (N_AXES, HEAVY_LEVELS)
        if (keys is None or counts is None or pending is None or keys.shape != shape
                or counts.shape != shape or (counts < 0).any()
                or (np.isfinite(keys) != (counts > 0)).any() or pending.ndim != 2
                or pending.shape[0] >= HEAVY_BATCH or pending.shape[1] != N_AXES):
            raise InputError('the frequent values of the zero-field counters are invalid')
        self.n_pending = pending.shape[0]
        self.pending[:self.n_pending] = pending
        for j in range(N_AXES):
            kept = np.isfinite(keys[j])
            self.heavy[j] = HeavyLevels(keys[j][kept].astype(np.float32),
                                        counts[j][kept].astype(np.int64))

    def _restore_levels(self, levels, many) -> None:
        """Take the distinct values of :meth:`state` (none saved: counted again)."""
        if levels is None and many is None:
            return
        if (levels is None or many is None or levels.shape != (N_AXES, GRID_LEVELS + 1)
                or many.shape != (N_AXES,)):
            raise InputError('the value levels of the zero-field counters are invalid')
        kept = [row[np.isfinite(row)] for row in levels.astype(np.float64)]
        if any(np.any(np.diff(v) <= 0) for v in kept):
            raise InputError('the value levels of the zero-field counters are not sorted')
        self.levels, self.many_levels = kept, many.astype(bool)


class HeavyLevels:
    """
    The most frequent values of a stream, with their counts (Misra and Gries 1982).

    A mergeable summary (Agarwal et al. 2012): a batch's distinct values and counts are
    added to the counters, and where more than :data:`HEAVY_LEVELS` remain each count is
    lowered by the next one's and the values left at 0 dropped.  A count is then low by
    at most the values seen over ``HEAVY_LEVELS + 1``; a value on no grid keeps none.
    """

    def __init__(self, keys: np.ndarray | None = None, counts: np.ndarray | None = None):
        self.keys = np.empty(0, np.float32) if keys is None else keys
        self.counts = np.empty(0, np.int64) if counts is None else counts

    def add(self, values: np.ndarray) -> None:
        """Count the values (n,) float32."""
        if not values.size:
            return
        keys, where = np.unique(np.concatenate((self.keys, values)), return_inverse=True)
        counts = np.bincount(where, np.concatenate(
            (self.counts, np.ones(values.size, np.int64)))).astype(np.int64)
        if keys.size > HEAVY_LEVELS:
            cut = np.partition(counts, -(HEAVY_LEVELS + 1))[-(HEAVY_LEVELS + 1)]
            counts = counts - cut
            keys, counts = keys[counts > 0], counts[counts > 0]
        self.keys, self.counts = keys, counts


def _keys(values: np.ndarray) -> np.ndarray:
    """Return the non-zero values (n,) as float32 keys, those beyond its range left out."""
    with np.errstate(over='ignore'):
        keys = values[values != 0].astype(np.float32)
    return keys[np.isfinite(keys)]


def _filled(samples: np.ndarray, lost: np.ndarray) -> np.ndarray:
    """
    Return the rows (n, 6) with the ``lost`` ones (n,) bool interpolated, marked as fills.

    Each axis is interpolated between the nearest rows not lost; rows before the first
    or after the last of them take its value.  All lost: returned as they are (the
    caller drops them, with nothing to fill from).
    """
    idx = np.flatnonzero(~lost)
    if not idx.size:
        return samples
    out = samples.copy()
    where = np.flatnonzero(lost)
    for j in range(samples.shape[1]):
        out[where, j] = np.interp(where, idx, samples[idx, j])
    out[where] = as_fills(out[where])
    return out


def _long_runs(lost: np.ndarray, max_fill: int) -> np.ndarray:
    """Return the rows (n,) bool in runs of more than ``max_fill`` lost rows."""
    edges = np.diff(np.concatenate(([0], lost.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    out = np.zeros(lost.size, dtype=bool)
    for s, e in zip(starts, ends):
        if e - s > max_fill:
            out[s:e] = True
    return out
