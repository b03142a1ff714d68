"""
Spikes: isolated outliers, single samples and short bursts, found and interpolated.

A sample is a spike on an axis when it lies more than ``spike_sigma`` noise sigmas
from the median of the ``2 * CONTEXT + 1`` samples around it, the noise sigma being
the sensor's own: the median absolute first difference of the surrounding chunk over
0.6745 * sqrt(2) (the MAD of white noise's differences; robust to the spikes
themselves).  Bursts of up to CONTEXT samples leave the median on the clean level.
Values beyond :data:`ABSURD` are spikes whatever their neighbours (1e154 never
reaches the accumulator).

Spikes are replaced by linear interpolation between their clean neighbours rather
than cut out as gaps.  A gap ends the segment, and no Allan term spans it: spikes in
1 % of the samples would leave no term longer than about a hundred samples.  An
interpolated sample only smooths the two first differences it takes part in, which
lowers the Allan variance at the shortest tau by at most 1.5 times the spike share
(white noise: each such difference has variance sigma^2 / 2 instead of 2 sigma^2);
longer taus average it away.  ``max_spike_share`` refuses records where that matters.
"""

import warnings

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, SessionConfig, WarningLog

#: Neighbours on each side of a sample in its median [samples]; bursts up to this long.
CONTEXT = 6
#: Rows judged together: one noise scale per axis and chunk [samples].
CHUNK = 4096
#: |value| beyond this is no IMU reading in SI units [rad/s, m/s^2].
ABSURD = 1e6
#: Median |x| of a standard normal (MAD to sigma).
_MAD = 0.6744897501960817


class SpikeFilter:
    """
    Find and interpolate spikes in a stream of gap-free runs.

    Rows are held until ``CONTEXT`` rows after them have arrived (and a whole
    chunk of ``CHUNK`` rows is complete), so the verdicts do not depend on the blocks.

    Parameters
    ----------
    config : SessionConfig
        Its ``spike_sigma`` (0 disables the filter).
    stats : HygieneStats
        Counters (``n_spikes``, ``spikes``).
    warn : WarningLog
        Where the spike warning goes.

    """

    def __init__(self, config: SessionConfig, stats: HygieneStats, warn: WarningLog):
        self.sigma = float(config.spike_sigma)
        self.stats = stats
        self._warn = warn
        self._held_t = np.empty(0, np.int64)
        self._held_y = np.empty((0, N_AXES))
        self._left = np.empty((0, N_AXES))   # cleaned rows before the held ones
        self._scale = np.full(N_AXES, np.nan)  # noise sigma of the last chunk [unit]

    def take(self, t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Add rows; return the rows judged so far (cleaned), in order."""
        if self.sigma <= 0:
            return t, y
        if self._held_t.size:
            t = np.concatenate((self._held_t, t))
            y = np.concatenate((self._held_y, y))
        n_chunks = (t.size - CONTEXT) // CHUNK if t.size > CONTEXT else 0
        if n_chunks <= 0:
            self._held_t, self._held_y = t, y
            return t[:0], y[:0]
        k = n_chunks * CHUNK
        out = self._judge(y[:k + CONTEXT], k)
        self._held_t, self._held_y = t[k:], y[k:]
        return t[:k], out

    def flush(self) -> tuple[np.ndarray, np.ndarray]:
        """Judge the held rows with the context there is (end of a segment); return them."""
        t, y = self._held_t, self._held_y
        self._held_t, self._held_y = t[:0], y[:0]
        out = self._judge(y, y.shape[0]) if y.shape[0] else y
        self._left = np.empty((0, N_AXES))
        return t, out

    def _judge(self, y: np.ndarray, k: int) -> np.ndarray:
        """Return rows ``y[:k]`` cleaned; rows from k on are right context only."""
        left = self._left.shape[0]
        full = np.concatenate((self._left, y)) if left else y
        out = y[:k]
        chunks = [(s, min(s + CHUNK, k)) for s in range(0, k, CHUNK)]
        spikes = np.zeros((full.shape[0], N_AXES), dtype=bool)
        with np.errstate(over='ignore', invalid='ignore'), warnings.catch_warnings():
            warnings.simplefilter('ignore', RuntimeWarning)   # all-NaN medians
            for s, e in chunks:
                self._mark(full, left + s, left + e, spikes)
        found = spikes[left:left + k]
        if found.any():
            out = _interpolate(full, spikes)[left:left + k]
            self._count(found)
        self._left = out[-CONTEXT:].copy() if k >= CONTEXT else np.concatenate(
            (self._left, out))[-CONTEXT:]
        return out

    def _mark(self, full: np.ndarray, s: int, e: int, spikes: np.ndarray) -> None:
        """Mark the spikes among rows s:e of ``full`` in ``spikes`` (same shape)."""
        lo, hi = max(s - CONTEXT, 0), min(e + CONTEXT, full.shape[0])
        part = full[lo:hi]
        absurd = ~(np.abs(part) <= ABSURD)
        d = np.abs(np.diff(part, axis=0))
        if d.shape[0] >= 8:
            scale = _noise_sigma(d[::max(d.shape[0] // 1024, 1)])
            ok = np.isfinite(scale) & (scale > 0)
            self._scale = np.where(ok, scale, self._scale)
        limit = self.sigma * self._scale          # (6,), NaN while no scale is known
        # Candidates: a step into or out of the row of half the limit, spread over a
        # burst's length; each is then judged against its neighbours' median.
        big = np.zeros(part.shape, dtype=bool)
        step = d > 0.5 * limit
        big[1:] |= step
        big[:-1] |= step
        big |= absurd
        rows, cols = np.nonzero(big)
        if rows.size:
            cand = np.zeros(part.shape, dtype=bool)
            for shift in range(-CONTEXT, CONTEXT + 1):
                r = rows + shift
                keep = (r >= 0) & (r < part.shape[0])
                cand[r[keep], cols[keep]] = True
            cand[:s - lo] = False
            cand[e - lo:] = False
            rows, cols = np.nonzero(cand)
            padded = np.pad(part, ((CONTEXT, CONTEXT), (0, 0)), constant_values=np.nan)
            near = padded[rows[:, None] + np.arange(2 * CONTEXT + 1), cols[:, None]]
            near[~(np.abs(near) <= ABSURD)] = np.nan
            med = np.nanmedian(near, axis=1) if near.size else near[:, 0]
            dev = np.abs(part[rows, cols] - med)
            hit = (dev > limit[cols]) | absurd[rows, cols] | np.isnan(med)
            spikes[rows[hit] + lo, cols[hit]] = True

    def _count(self, found: np.ndarray) -> None:
        per_axis = found.sum(axis=0)
        for j in np.flatnonzero(per_axis):
            self.stats.spikes[AXES[j]] = self.stats.spikes.get(AXES[j], 0) + int(per_axis[j])
        self.stats.n_spikes += int(per_axis.sum())
        where = ', '.join(f'{a} ({n})' for a, n in self.stats.spikes.items())
        self._warn('spikes', f'{self.stats.n_spikes} spikes (samples over {self.sigma:g} '
                   f'noise sigmas off their neighbours) replaced by interpolation: {where}',
                   once=False)

    # ------------------------------------------------------------- checkpoint
    def state(self) -> tuple[dict, dict]:
        """Return (JSON-able state, arrays) of the filter."""
        return ({'scale': [None if not np.isfinite(v) else float(v) for v in self._scale]},
                {'spike_held_stamp_ns': self._held_t, 'spike_held_samples': self._held_y,
                 'spike_left': self._left})

    def restore(self, meta, arrays: dict) -> None:
        """Take the state of :meth:`state`; InputError when it is invalid."""
        scale = meta.get('scale') if isinstance(meta, dict) else None
        if not isinstance(scale, list) or len(scale) != N_AXES:
            raise InputError('the spike filter state is invalid')
        keys = ('spike_held_stamp_ns', 'spike_held_samples', 'spike_left')
        t, y, left = (arrays.get(k) for k in keys)
        if (t is None or y is None or left is None or t.ndim != 1
                or y.shape != (t.size, N_AXES) or left.ndim != 2
                or left.shape[1] != N_AXES or left.shape[0] > CONTEXT
                or not np.isfinite(y).all() or not np.isfinite(left).all()):
            raise InputError('the rows held by the spike filter are invalid')
        vals = np.array([np.nan if v is None else v for v in scale], dtype=np.float64)
        if (vals[np.isfinite(vals)] <= 0).any() or np.isinf(vals).any():
            raise InputError('the spike filter noise scale is invalid')
        self._scale = vals
        self._held_t, self._held_y = t.astype(np.int64), y.astype(np.float64)
        self._left = left.astype(np.float64)


def _noise_sigma(d: np.ndarray) -> np.ndarray:
    """Noise sigma per axis (n_axes,) from absolute first differences (m, n_axes)."""
    d = np.where(np.abs(d) <= ABSURD, d, np.nan)
    sigma = np.nanmedian(d, axis=0) / (_MAD * np.sqrt(2.0))
    # Quantised sensors: most steps may be 0; one quantum is the least noise there is.
    pos = np.where(d > 0, d, np.inf).min(axis=0) / np.sqrt(2.0)
    return np.maximum(sigma, np.where(np.isfinite(pos), pos, np.nan))


def _interpolate(full: np.ndarray, spikes: np.ndarray) -> np.ndarray:
    """Replace the marked values by linear interpolation along each axis."""
    out = full.copy()
    idx = np.arange(full.shape[0])
    for j in np.flatnonzero(spikes.any(axis=0)):
        good = ~spikes[:, j]
        if good.any():
            out[~good, j] = np.interp(idx[~good], idx[good], full[good, j])
        else:
            out[:, j] = 0.0   # nothing clean on the axis: the share check refuses it
    return out
