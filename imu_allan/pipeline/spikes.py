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

Held values (a driver or logger that publishes faster than its sensor updates repeats
each update: a zero-order hold) make most first differences 0, and their median, the
noise scale, collapses to one quantum: every update is then a spike (a real record with
47 % of gyro and 72 % of accel values held lost 14,775 values and was refused).  A
chunk where a larger share of the steps are 0 at lag 1 than at a lag past the holds
(twice the mean run of one value) holds values, and its scale comes from the
differences at that lag: two different updates, of the same spread as neighbours
of a white sequence (quantization repeats are as common at both lags, so quantised
data is not taken for held).  The share held per axis is counted for the gate's
warning and ``hygiene.held``.
"""

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, SessionConfig, WarningLog

#: Neighbours on each side of a sample in its median [samples]; bursts up to this long.
CONTEXT = 6
#: Rows judged together: one noise scale per axis and chunk [samples].
CHUNK = 2048
#: |value| beyond this is no IMU reading in SI units [rad/s, m/s^2].
ABSURD = 1e6
#: Share of the spike limit a step must exceed for its rows to be judged.
_SCREEN = 0.6
#: Every this many steps of a chunk give its noise scale.
_THIN = 4
#: Median |x| of a standard normal (MAD to sigma).
_MAD = 0.6744897501960817
#: Upper quartile of |x| of a standard normal.
_Q75 = 1.1503493803760079
#: Steps below this share of the upper quartile are the pile at 0 of a quantised axis
#: (Gaussian steps: 0.05 % of them).
PILE_SHARE = 1e-3
#: Share of a chunk's steps that must be 0 before held values are looked for, and the
#: share of the changing steps held (0 at lag 1, a change at a lag past the holds)
#: that makes an axis held.
HOLD_MIN = 0.1


# Long because a verdict must not depend on how the rows arrive: rows wait for their
# context, and that state survives a checkpoint.
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
        # Steps judged, and of them the estimated steps that held the previous value.
        self.n_steps = np.zeros(N_AXES, dtype=np.int64)
        self.n_held = np.zeros(N_AXES)

    def take(self, t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Add rows; return the rows judged so far (cleaned), in order."""
        if self.sigma <= 0:
            return t, y
        held = self._held_t.size
        n_chunks = (held + t.size - CONTEXT) // CHUNK
        if n_chunks <= 0:
            self._held_t = np.concatenate((self._held_t, t))
            self._held_y = np.concatenate((self._held_y, y))
            return t[:0], y[:0]
        k = n_chunks * CHUNK
        left = self._left.shape[0]
        full = np.concatenate((self._left, self._held_y, y))
        t = np.concatenate((self._held_t, t)) if held else t
        out = self._judge(full, left, k)
        self._held_t, self._held_y = t[k:].copy(), full[left + k:].copy()
        return t[:k], out

    def release(self) -> tuple[np.ndarray, np.ndarray]:
        """
        Judge the held rows now, with the context there is; return them (cleaned).

        The live path calls this after each batch, so no row waits for a whole chunk;
        the cleaned rows stay the left context of the next ones.
        """
        t, y = self._held_t, self._held_y
        if self.sigma <= 0 or y.shape[0] == 0:
            return t[:0], y[:0]
        self._held_t, self._held_y = t[:0], y[:0]
        left = self._left.shape[0]
        return t, self._judge(np.concatenate((self._left, y)), left, y.shape[0])

    def flush(self) -> tuple[np.ndarray, np.ndarray]:
        """Judge the held rows with the context there is (end of a segment); return them."""
        t, y = self._held_t, self._held_y
        self._held_t, self._held_y = t[:0], y[:0]
        if y.shape[0]:
            left = self._left.shape[0]
            y = self._judge(np.concatenate((self._left, y)), left, y.shape[0])
        self._left = np.empty((0, N_AXES))
        return t, y

    def _judge(self, full: np.ndarray, left: int, k: int) -> np.ndarray:
        """
        Return rows ``full[left:left + k]`` cleaned.

        ``full`` (n, 6): ``left`` cleaned rows before them as context, and rows after
        them (the next chunk's) as context only.
        """
        with np.errstate(over='ignore', invalid='ignore'):
            spikes = self._mark(full, left, k)
        out = full[left:left + k]
        if spikes is not None:
            out = _interpolate(full, spikes)[left:left + k]
            self._count(spikes[left:left + k])
        self._left = out[-CONTEXT:].copy() if k >= CONTEXT else np.concatenate(
            (full[:left], out))[-CONTEXT:]
        return out

    def _limits(self, d: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """
        Spike limits (n_chunks, 6) of the judged rows' chunks.

        ``d`` (m, 6) are the absolute steps from each judged row to the next, ``rows``
        (k, 6) the judged rows themselves [unit].
        """
        k = rows.shape[0]
        n_chunks = -(-k // CHUNK)
        limits = np.empty((n_chunks, N_AXES))
        # Whole chunks of steps: the last judged row may have no step (the end of the
        # rows, a multiple of CHUNK long, made the reshape fail: a traceback).
        full = min(k, d.shape[0]) // CHUNK
        if full:
            steps = d[:full * CHUNK].reshape(full, CHUNK, N_AXES)[:, ::_THIN]
            limits[:full] = _noise_sigma(steps.transpose(2, 0, 1)).T
            # Every step counts for the held share: a thinned count aliases with holds.
            self._held_scale(d[:full * CHUNK].reshape(full, CHUNK, N_AXES),
                             rows[:full * CHUNK].reshape(full, CHUNK, N_AXES), limits[:full])
        if full < n_chunks:
            tail = d[full * CHUNK:k]
            limits[full] = _noise_sigma(tail.T[:, None])[:, 0] if tail.shape[0] >= 8 else np.nan
            self._held_scale(tail[None], rows[full * CHUNK:][None], limits[full:])
        for c in range(n_chunks):   # a short chunk, or no noise at all: the last scale
            ok = np.isfinite(limits[c]) & (limits[c] > 0)
            limits[c] = self._scale = np.where(ok, limits[c], self._scale)
        return self.sigma * limits

    def _held_scale(self, steps: np.ndarray, rows: np.ndarray, scale: np.ndarray) -> None:
        """
        Count chunks' held steps; give held axes the scale of distinct updates.

        ``steps`` (c, s, 6) absolute steps of each of c chunks, ``rows`` (c, r, 6)
        their values [unit]; ``scale`` (c, 6) their noise sigma per axis, replaced in
        place where an axis holds.
        """
        if steps.shape[1] < 8 or rows.shape[1] < 16:
            return
        # Counted by a product: a sum over the middle axis takes seven times longer.
        zero = (np.ones(steps.shape[1], np.float32) @ (steps == 0).astype(np.float32)
                / steps.shape[1])
        per_chunk = rows.shape[1] - 1
        self.n_steps += rows.shape[0] * per_chunk
        maybe = (zero >= HOLD_MIN) & (zero < 1)
        for j in np.flatnonzero(maybe.any(axis=0)):
            # Twice the mean run of one value: past nearly every hold.
            lag = min(int(np.ceil(2 / (1 - zero[maybe[:, j], j].max()))), rows.shape[1] // 4)
            # Every _THIN-th: past the holds, differences of two updates at any phase.
            far = np.abs(rows[:, lag:, j][:, ::_THIN] - rows[:, :-lag, j][:, ::_THIN])
            zero_far = np.count_nonzero(far == 0, axis=1) / far.shape[1]
            held = np.where(maybe[:, j] & (zero_far < 1),
                            (zero[:, j] - zero_far) / np.maximum(1 - zero_far, 1e-12), 0.0)
            hit = np.flatnonzero(held >= HOLD_MIN)
            if hit.size:
                self.n_held[j] += float(held[hit].sum()) * per_chunk
                sigma = _noise_sigma(far[hit][None])[0]
                ok = np.isfinite(sigma)
                scale[hit[ok], j] = sigma[ok]

    @property
    def held_share(self) -> np.ndarray:
        """Shape (6,): share of the steps judged that held the previous value."""
        return self.n_held / np.maximum(self.n_steps, 1)

    def _mark(self, full: np.ndarray, left: int, k: int) -> np.ndarray | None:
        """Spikes (n, 6) bool among rows left:left + k of ``full`` (n, 6); None for none."""
        n = full.shape[0]
        # Step i is from row left + i to the next; the last judged row may have none.
        d = np.diff(full[left:], axis=0)
        np.abs(d, out=d)
        limits = self._limits(d, full[left:left + k])
        m = min(d.shape[0], k)
        n_chunks = -(-m // CHUNK)
        pad = n_chunks * CHUNK - m
        steps = np.pad(d[:m], ((0, pad), (0, 0))) if pad else d[:m]
        if m == 0:
            steps = np.zeros((CHUNK, N_AXES))
            n_chunks = 1
        # Candidates: a step into or out of a row of 0.6 limits (NaN limits, no scale
        # yet, flag nothing), spread over a burst's length; each is then judged
        # against its neighbours' median.  Steps in units of the screen: a chunk whose
        # largest is under 1 has none (most chunks of clean data).
        chunks = steps.reshape(n_chunks, CHUNK, N_AXES)
        screen = _SCREEN * limits[:n_chunks, None, :]
        np.divide(chunks, np.where(np.isfinite(screen), screen, np.inf), out=chunks)
        flagged = np.flatnonzero(chunks.reshape(n_chunks, -1).max(axis=1) > 1)
        found_r, found_c = [], []
        for c in flagged:
            r, j = np.nonzero(chunks[c] > 1)
            found_r.append(r + c * CHUNK)
            found_c.append(j)
        rows = np.concatenate(found_r) if found_r else np.empty(0, np.int64)
        cols = np.concatenate(found_c) if found_c else np.empty(0, np.int64)
        cols = cols[rows < m]
        rows = rows[rows < m]
        judged = full[left:left + k]
        if judged.max() > ABSURD or judged.min() < -ABSURD:
            r2, c2 = np.nonzero(~(np.abs(judged) <= ABSURD))
            rows, cols = np.concatenate((rows, r2)), np.concatenate((cols, c2))
        if rows.size == 0:
            return None
        rows = (rows[:, None] + np.arange(-CONTEXT, CONTEXT + 2)).ravel() + left
        cols = np.repeat(cols, 2 * CONTEXT + 2)
        keep = (rows >= left) & (rows < left + k)
        flat = np.unique(rows[keep] * N_AXES + cols[keep])
        rows, cols = flat // N_AXES, flat % N_AXES
        # Near the ends of the data the end row stands in for the missing neighbours.
        near = full[np.clip(rows[:, None] + np.arange(-CONTEXT, CONTEXT + 1), 0, n - 1),
                    cols[:, None]]
        value = full[rows, cols]
        limit = limits[(rows - left) // CHUNK, cols]
        dev = np.abs(value - np.partition(near, CONTEXT, axis=1)[:, CONTEXT])
        hit = (~(dev <= limit) & np.isfinite(limit)) | ~(np.abs(value) <= ABSURD)
        if not hit.any():
            return None
        spikes = np.zeros(full.shape, dtype=bool)
        spikes[rows[hit], cols[hit]] = True
        return spikes

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
        return ({'scale': [None if not np.isfinite(v) else float(v) for v in self._scale],
                 'n_steps': self.n_steps.tolist(), 'n_held': self.n_held.tolist()},
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
        steps, held = meta.get('n_steps'), meta.get('n_held')
        if (not isinstance(steps, list) or not isinstance(held, list)
                or len(steps) != N_AXES or len(held) != N_AXES
                or not all(isinstance(v, int) and v >= 0 for v in steps)
                or not all(isinstance(v, (int, float)) and 0 <= v <= n
                           for v, n in zip(held, steps))):
            raise InputError('the spike filter held-value counts are invalid')
        self.n_steps = np.array(steps, dtype=np.int64)
        self.n_held = np.array(held, dtype=np.float64)
        self._scale = vals
        self._held_t, self._held_y = t.astype(np.int64), y.astype(np.float64)
        self._left = left.astype(np.float64)


def _noise_sigma(d: np.ndarray) -> np.ndarray:
    """Noise sigma (n_axes, n_chunks) from absolute first differences (n_axes, n_chunks, m)."""
    half, upper = d.shape[-1] // 2, (3 * d.shape[-1]) // 4
    part = np.partition(d, (half, upper), axis=-1)  # without np.median's overhead
    median, quartile = part[..., half], part[..., upper]
    # Half the steps or more (nearly) 0: a sensor quantised at about its noise; its
    # scale is the upper quartile.  A driver that shifts such values off the grid (a
    # warm-up or bias correction, a mounting rotation) turns the 0 steps into tiny
    # ones, and the median fell to them (a warm-up on the ADIS16405's accel_y: 11 % of
    # the samples "spikes", refused).  Spikes, at most a quarter of the steps where
    # the record is usable, leave the median alone.
    pile = (d < PILE_SHARE * quartile[..., None]).mean(axis=-1) >= 0.5
    sigma = np.where(pile, quartile / _Q75, median / _MAD) / np.sqrt(2.0)
    # Quantised sensors: most steps may be 0; one quantum is the least noise there is.
    quantum = np.where(d > 0, d, np.inf).min(axis=-1) / np.sqrt(2.0)
    return np.maximum(sigma, np.where(np.isfinite(quantum), quantum, np.nan))


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
