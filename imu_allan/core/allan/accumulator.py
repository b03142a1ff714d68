"""
Streaming overlapping Allan variance for many axes, in bounded memory.

:class:`AllanAccumulator` takes blocks of rate samples of any size (one row from a
ROS callback, a million rows from a bag reader) and keeps, per cluster size m, the
pooled sum of squared second differences of the running sum X of the samples
(NIST SP 1065 eq. 14)::

    AVAR(m tau0) = sum_i (X[i+2m] - 2 X[i+m] + X[i])^2 / (2 m^2 n_terms)

The result does not depend on how the record is cut into blocks: samples are
buffered and processed in chunks of a fixed length counted from the start of each
contiguous segment, so one block, random-sized blocks, and a save/load in between
give bit-identical sums.

Estimator
---------
* Exact part (level 0), m <= ``exact_max_m``: every term i of the batch overlapping
  estimator is summed; the curve equals :func:`imu_allan.core.allan.overlapping_avar` on
  the same samples to rounding (about 1e-12 relative).  Memory: the last
  ``2 * exact_max_m`` samples, since a term needs X up to 2m samples back.
* Decimated part (levels L = 1, 2, ...), m > ``exact_max_m``: level L keeps cluster
  sums of D_L = exact_max_m * 2^(L-1) / 64 samples, i.e. X only at indices that are
  multiples of D_L, and serves m = m' D_L with 64 < m' <= 128 (the dense grid rounded
  to a multiple of D_L, so tau_s is exact for the value reported).  The sum over
  i = 0, D_L, 2 D_L, ... of (X[i+2m] - 2 X[i+m] + X[i])^2 is the batch overlapping
  sum subsampled at stride D_L <= m / 64: each term has the same expectation, so the
  estimator is unbiased, and it is exactly the overlapping estimator of the
  D_L-decimated series (cluster sums) at cluster size m'.  Its EDF is therefore the
  overlapping EDF for (m', N / D_L) (Greenhall's algorithm, as for the batch curve).
  For white, flicker and random-walk FM noise (alpha = 0, -1, -2: the noises that
  rule beyond a few seconds in an IMU) that equals the full-overlap EDF at (m, N) to
  1e-4 once m' > 64 (it gives 3 % less at m' = 33, hence the range); white and
  flicker PM (alpha = 2, 1) lose most of their EDF to the decimation, but they fall
  as tau^-2 and do not matter at such taus.  The estimate differs from the batch
  value by a small fraction of its own confidence interval (checked in
  test/test_accumulator.py).  Memory: 256 cluster sums per level.

Pooling over segments: :meth:`AllanAccumulator.break_segment` ends a contiguous
segment; no term spans the gap, and sums and term counts are pooled, so the AVAR is
the total sum over 2 m^2 times the total number of terms (the batch estimator
applied to each segment and pooled).  The EDF of a pooled estimate is approximated by
that of one segment with the same number of terms (N_eff = n_terms + 2 m' - 1).

Missing samples (:meth:`AllanAccumulator.add` with ``missing``): a short gap filled by
the caller keeps the segment whole; at exact taus the terms over filled samples are
left out, beyond they are used less the fills' white-noise excess
(:mod:`imu_allan.core.allan.fill_terms`).

Precision: the running sum is rebuilt for every chunk from zero, after subtracting a
per-axis reference (the mean of the first chunk) and then the chunk window's own
mean (:mod:`imu_allan.core.allan.window_sums`).  A constant subtracted from all
samples of a window cancels exactly in every second difference, so |X| is bounded by
the window length times the *local* variation of the signal, never by the record
length or by the 9.81 m/s^2 offset.
"""

import numpy as np

from imu_allan.core.allan.accumulator_state import _Persistence
from imu_allan.core.allan.curve import AllanCurve
from imu_allan.core.allan.edf import confidence_bounds, edf_overlapping
from imu_allan.core.allan.fill_terms import gap_excess, used_terms
from imu_allan.core.allan.noise_id import alpha_from_slope
from imu_allan.core.allan.stretches import stretch_view, Stretches, StretchSums
from imu_allan.core.allan.taus import dense_m_grid
from imu_allan.core.allan.window_sums import accumulate, dirty_terms, phase, TILE_COLS
from imu_allan.errors import InputError

#: Decimated levels serve m = m' D_L with _M_LO < m' <= 2 * _M_LO.
_M_LO = 64
#: Levels are pre-allocated up to this cluster size [samples] (35 years at 1 kHz), so
#: the state never grows while data flow.
_MAX_M = 2 ** 40
#: Largest exact_max_m: keeps the state under 1 MB per axis (0.62 MB at this value).
_MAX_EXACT_M = 2 ** 14


class _Level:
    """Decimated level: cluster sums of ``stride`` samples and their short history."""

    def __init__(self, stride: int, m_prime: np.ndarray, index: np.ndarray, n_axes: int):
        self.stride = stride
        self.m_prime = m_prime          # (k_L,) cluster sizes in level samples
        self.index = index              # (k_L,) rows of the accumulator's sums
        self.capacity = 4 * _M_LO       # 2 * max m'
        self.hist = np.zeros((n_axes, self.capacity))
        self.h = 0                      # valid history values (the last ones)
        self.n = 0                      # level samples in the current segment


# Long by design (about 300 lines): one streaming state machine whose level-0 buffer,
# decimated levels and pooled sums every method updates together; its persistence is in
# accumulator_state.py.
class AllanAccumulator(_Persistence):
    """
    Streaming overlapping Allan variance of ``n_axes`` axes in bounded memory.

    Parameters
    ----------
    n_axes : int
        Number of axes (columns of every block), 6 for an IMU.
    rate_hz : float
        Sample rate [Hz]; tau_s = m / rate_hz.
    exact_max_m : int
        Largest cluster size computed exactly [samples]; a multiple of 64 up to
        16384.  Taus with m <= exact_max_m equal the batch overlapping AVAR; longer
        taus use the decimated estimator described in the module docstring.
    per_decade : int
        Taus per decade of the log grid.

    Notes
    -----
    Trade-off of ``exact_max_m`` (default 8192, i.e. 8.2 s at 1 kHz): every exact tau
    costs about three in-cache passes over the data, a decimated one almost nothing,
    and the exact taus need 2 * exact_max_m samples of history
    (bench/bench_accumulator.py --sweep measures the rate and state of each value).
    Decimated taus keep the full EDF of the FM noises, so a larger exact_max_m buys
    agreement with the batch curve to rounding, not precision; it is capped at 16384
    so that the state stays under 1 MB per axis.

    Which taus are exact: ``m <= exact_max_m`` (see :meth:`exact_mask`), i.e.
    ``tau_s <= exact_max_m / rate_hz``.

    Memory: :meth:`state_nbytes` is the persistent state (what :meth:`save` writes):
    a buffer of 2 * exact_max_m history samples plus one chunk of pending samples per
    axis, 256 values per decimated level, and the pooled sums.  While a chunk is
    processed, work arrays of about twice that size exist in addition.

    """

    def __init__(self, n_axes: int, rate_hz: float, exact_max_m: int = 8192,
                 per_decade: int = 10):
        n_axes, exact_max_m, per_decade = int(n_axes), int(exact_max_m), int(per_decade)
        rate_hz = float(rate_hz)
        if n_axes < 1:
            raise InputError(f'n_axes must be at least 1, not {n_axes}')
        if not np.isfinite(rate_hz) or rate_hz <= 0:
            raise InputError(f'rate_hz must be a positive number, not {rate_hz}')
        if not _M_LO <= exact_max_m <= _MAX_EXACT_M or exact_max_m % _M_LO:
            raise InputError(f'exact_max_m must be a multiple of {_M_LO} in '
                             f'{_M_LO}..{_MAX_EXACT_M}, not {exact_max_m}')
        if not 1 <= per_decade <= 100:
            raise InputError(f'per_decade must lie in 1..100, not {per_decade}')
        self.n_axes = n_axes
        self.rate_hz = rate_hz
        self.exact_max_m = exact_max_m
        self.per_decade = per_decade
        # Level 0: history of 2 * exact_max_m samples, then one chunk of pending ones.
        self._hist_cap = 2 * exact_max_m
        self._chunk = max(32768, 2 * exact_max_m)
        self._buf = np.zeros((n_axes, self._hist_cap + self._chunk))
        self._h0 = 0                    # history samples at the front of _buf
        self._pending = 0               # raw samples after the history
        self._seg_n = 0                 # processed samples in the current segment
        self._ref = np.zeros(n_axes)
        self._ref_set = False
        # Missing (filled) samples in the level-0 buffer, and the exact taus' sums and
        # counts of the terms that hold one.
        self._miss = np.zeros(self._hist_cap + self._chunk, dtype=bool)
        self._n_missing = 0
        # Sum of g + g^2 / 2 over the gaps of g missing samples, and the missing samples
        # that end the segment so far (a gap that goes on in the next block).
        self._fill_excess = 0.0
        self._miss_run = 0
        self._n_samples = 0
        self._n_segments = 0
        self._build_grid()
        self._sums = np.zeros((self._m.size, n_axes))
        self._counts = np.zeros(self._m.size, dtype=np.int64)
        self._dirty_sums = np.zeros((self._m0.size, n_axes))
        self._dirty_counts = np.zeros(self._m0.size, dtype=np.int64)
        self._work: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        # The curve's and the stretches' copy with the pending samples processed (not state).
        self._flushed_copy: tuple[tuple[int, int], 'AllanAccumulator'] | None = None
        #: The exact taus' sums per stretch of the record (noise level changes).
        self.stretch_sums = StretchSums(self._m0.size, n_axes)

    # ------------------------------------------------------------------ grid
    def _build_grid(self) -> None:
        grid = dense_m_grid(_MAX_M, self.per_decade)
        m0 = grid[grid <= self.exact_max_m]
        all_m = [m0]
        strides = [np.ones(m0.size, dtype=np.int64)]
        self._m0 = m0
        self._levels = []
        stride = self.exact_max_m // _M_LO
        lo = self.exact_max_m
        k = m0.size
        while lo < _MAX_M:
            sel = grid[(grid > lo) & (grid <= 2 * lo)]
            m_prime = np.unique(np.clip(np.round(sel / stride).astype(np.int64),
                                        _M_LO + 1, 2 * _M_LO))
            index = np.arange(k, k + m_prime.size)
            self._levels.append(_Level(stride, m_prime, index, self.n_axes))
            all_m.append(m_prime * stride)
            strides.append(np.full(m_prime.size, stride, dtype=np.int64))
            k += m_prime.size
            stride *= 2
            lo *= 2
        self._m = np.concatenate(all_m)
        self._stride = np.concatenate(strides)

    # ------------------------------------------------------------ properties
    @property
    def n_samples(self) -> int:
        """Return the number of samples added so far (all segments, buffered ones too)."""
        return self._n_samples

    @property
    def n_missing(self) -> int:
        """Return the number of samples added as missing (filled by the caller)."""
        return self._n_missing

    @property
    def n_segments(self) -> int:
        """Return the number of contiguous segments that received at least one sample."""
        return self._n_segments

    @property
    def m(self) -> np.ndarray:
        """Return every cluster size the accumulator can serve, shape (k,) [samples]."""
        return self._m.copy()

    def exact_mask(self, m: np.ndarray) -> np.ndarray:
        """
        Tell which cluster sizes are computed exactly (equal to the batch estimator).

        Parameters
        ----------
        m : np.ndarray
            Shape (k,), cluster sizes [samples], e.g. ``curve.m``.

        Returns
        -------
        np.ndarray
            Shape (k,), bool: True where m <= exact_max_m.

        """
        return np.asarray(m) <= self.exact_max_m

    def state_nbytes(self) -> int:
        """Return the bytes of persistent state (independent of the record length)."""
        st = self.stretch_sums
        return int(self._buf.nbytes + self._ref.nbytes + self._sums.nbytes
                   + self._counts.nbytes + sum(lv.hist.nbytes for lv in self._levels)
                   + st.sums.nbytes + st.counts.nbytes + st.rows.nbytes)

    # ------------------------------------------------------------- streaming
    def add(self, samples: np.ndarray, missing: np.ndarray | None = None) -> None:
        """
        Add a block of consecutive samples to the current segment.

        Parameters
        ----------
        samples : np.ndarray
            Shape (n, n_axes), rate samples [unit], any n >= 0.
        missing : np.ndarray, optional
            Shape (n,), bool: rows that stand in for lost samples (a short gap the
            caller filled, e.g. by linear interpolation).  Exact taus leave the terms
            over them out while that keeps at least
            :data:`~imu_allan.core.allan.fill_terms.SKIP_SHARE` of the terms; those
            sums are differences, so fills should be of the samples' own size.

        """
        block = np.asarray(samples)
        if block.ndim != 2 or block.shape[1] != self.n_axes:
            raise InputError(f'expected a block of shape (n, {self.n_axes}), '
                             f'got {block.shape}')
        n = block.shape[0]
        if n == 0:
            return
        if missing is not None:
            missing = np.asarray(missing, dtype=bool).reshape(-1)
            if missing.size != n:
                raise InputError(f'missing must have one flag per row ({n}), '
                                 f'not {missing.size}')
            self._n_missing += int(missing.sum())
            excess, self._miss_run = gap_excess(missing, self._miss_run)
            self._fill_excess += excess
        if not np.issubdtype(block.dtype, np.number) or np.iscomplexobj(block):
            raise InputError(f'samples must be real numbers, not {block.dtype}')
        for s in range(0, n, self._chunk):   # checked by chunks: bounded temporaries
            if not np.isfinite(block[s:s + self._chunk]).all():
                raise InputError('samples contain NaN or infinite values')
        if self._seg_n + self._pending == 0:
            self._n_segments += 1
        start = 0
        while start < n:
            take = min(n - start, self._chunk - self._pending)
            at = self._h0 + self._pending
            self._buf[:, at:at + take] = block[start:start + take].T
            self._miss[at:at + take] = False if missing is None else missing[start:start + take]
            self._pending += take
            self._n_samples += take
            start += take
            if self._pending == self._chunk:
                self._flush()

    def break_segment(self) -> None:
        """
        End the current contiguous segment (a gap in the data).

        No second difference spans the gap; sums and term counts are kept and pooled
        with those of the next segment.

        """
        if self._pending:
            self._flush()
        self._h0 = 0
        self._seg_n = 0
        self._miss_run = 0
        for level in self._levels:
            level.h = 0
            level.n = 0

    def _work_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # Kept between chunks (not state): avoids page-faulting fresh buffers each time.
        if self._work is None:
            a, w = self.n_axes, self._buf.shape[1]
            self._work = (np.empty((a, w + 1)), np.empty((a, w + 1)),
                          np.empty((a, TILE_COLS)))
        return self._work

    def _flush(self) -> None:
        """Process the pending samples of level 0 and feed the decimated levels."""
        h, p = self._h0, self._pending
        w = h + p
        buf = self._buf
        if not self._ref_set:
            self._ref = buf[:, h:w].mean(axis=1)
            self._ref_set = True
        buf[:, h:w] -= self._ref[:, None]
        x_all, x2_all, tile = self._work_arrays()
        x = x_all[:, :w + 1]
        r = phase(buf[:, :w], x)
        k0 = self._m0.size
        sums = np.zeros((k0, self.n_axes))
        counts = np.zeros(k0, dtype=np.int64)
        accumulate(x, h + 1, w, self._m0, sums, counts, 0, x2_all, tile)
        self._sums[:k0] += sums
        self._counts[:k0] += counts
        if self._miss[h:w].any():
            dirty = np.zeros((k0, self.n_axes)), np.zeros(k0, dtype=np.int64)
            dirty_terms(x, self._miss[:w], h + 1, self._m0, sums, *dirty)
            self._dirty_sums += dirty[0]
            self._dirty_counts += dirty[1]
            sums, counts = np.maximum(sums - dirty[0], 0.0), counts - dirty[1]
        self.stretch_sums.add(sums, counts, p)
        # Cluster sums for level 1 end at segment indices that are multiples of D_1.
        base = self._seg_n - h
        if self._levels:
            stride = self._levels[0].stride
            first = (self._seg_n // stride + 1) * stride
            ends = np.arange(first, self._seg_n + p + 1, stride) - base
            clusters = x[:, ends] - x[:, ends - stride] + stride * r[:, None]
        self._seg_n += p
        keep = min(self._hist_cap, self._seg_n)
        buf[:, :keep] = buf[:, w - keep:w]
        self._miss[:keep] = self._miss[w - keep:w]
        self._h0, self._pending = keep, 0
        if self._levels and clusters.shape[1]:
            self._push(0, clusters)

    def _push(self, k: int, values: np.ndarray) -> None:
        """Feed cluster sums (n_axes, c) to decimated level k (and on upwards)."""
        while True:
            level = self._levels[k]
            h, c = level.h, values.shape[1]
            win = np.concatenate((level.hist[:, level.capacity - h:], values), axis=1)
            x = np.empty((self.n_axes, h + c + 1))
            r = phase(win, x)
            accumulate(x, h + 1, h + c, level.m_prime, self._sums, self._counts,
                       level.index[0] if level.index.size else 0)
            # Pairs of this level's values form the next level's cluster sums.
            first = (level.n // 2 + 1) * 2
            ends = np.arange(first, level.n + c + 1, 2) - (level.n - h)
            level.n += c
            keep = min(level.capacity, level.n)
            level.hist[:, level.capacity - keep:] = win[:, h + c - keep:]
            level.h = keep
            k += 1
            if k == len(self._levels) or not ends.size:
                return
            values = x[:, ends] - x[:, ends - 2] + 2.0 * r[:, None]

    # ----------------------------------------------------------------- curve
    def _flushed(self) -> 'AllanAccumulator':
        """Return self, or a copy with the pending samples processed (kept till the next add)."""
        if not self._pending:
            return self
        key = (self._n_samples, self._n_segments)
        if self._flushed_copy is None or self._flushed_copy[0] != key:
            clone = self._copy()
            clone._flush()
            self._flushed_copy = (key, clone)
        return self._flushed_copy[1]

    def _sums_now(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Pooled sums and counts, then the exact taus' terms over missing samples."""
        done = self._flushed()
        return done._sums, done._counts, done._dirty_sums, done._dirty_counts

    def stretches(self) -> Stretches:
        """
        Return the AVAR of each stretch of the record at the exact taus.

        Returns
        -------
        Stretches
            Per stretch of :mod:`imu_allan.core.allan.stretches` (the samples not yet
            processed in the last), terms over filled samples left out.

        """
        return stretch_view(self._flushed().stretch_sums, self._m0, self.rate_hz)

    def curve(self, confidence: float = 0.683, alpha=None, min_terms: int = 1,
              bounds: bool = True) -> AllanCurve:
        """
        Overlapping Allan curve of all axes from the data added so far.

        Parameters
        ----------
        confidence : float
            Two-sided confidence level of adev_lo/adev_hi, e.g. 0.683 or 0.95.
        alpha : float or np.ndarray, optional
            Power-law exponent(s) for the EDF, broadcastable to (k, n_axes); by default
            estimated from the local slope (:func:`imu_allan.core.allan.alpha_from_slope`).
        min_terms : int
            Taus with fewer pooled second differences are left out.  The default 1
            keeps every tau with data, m <= M // 2 for one segment of M samples, as
            :func:`imu_allan.core.allan.tau_grid` does; the EDF says how little the last
            taus are worth.
        bounds : bool
            Compute adev_lo/adev_hi (chi-square quantiles per tau and axis); False leaves
            them NaN, for a caller that adds them later
            (:func:`imu_allan.core.allan.confidence_bounds` on avar and edf).

        Returns
        -------
        AllanCurve
            method 'overlapping'; edf from the level's effective (m', N_eff) as in the
            module docstring; taus with ``m <= exact_max_m`` are exact.  With missing
            samples, n_terms counts the terms used, or (where the terms over filled
            samples are kept) their number scaled by the share of real samples.

        """
        if not 0.0 < confidence < 1.0:
            raise InputError(f'confidence must lie strictly between 0 and 1, not {confidence}')
        sums, counts, eff = used_terms(self._m, *self._sums_now(), self._n_missing,
                                       self._n_samples, self._fill_excess)
        sel = counts >= max(int(min_terms), 1)
        m = self._m[sel]
        tau_s = m / self.rate_hz
        avar = sums[sel] / (2.0 * m.astype(float) ** 2 * counts[sel])[:, None]
        n_terms = eff[sel]
        k, a = m.size, self.n_axes
        if k == 0:
            empty = np.zeros((0, a))
            return AllanCurve(tau_s, m, empty, n_terms, empty, np.zeros((0, a), np.int64),
                              empty, empty, float(confidence), 'overlapping', self.rate_hz)
        m_eff = m // self._stride[sel]
        n_eff = n_terms + 2 * m_eff - 1
        if alpha is None:
            alpha = alpha_from_slope(tau_s, avar, n_clusters=n_eff // m_eff)
        try:
            alpha_f = np.broadcast_to(np.asarray(alpha, dtype=float), (k, a))
        except ValueError:
            raise InputError(f'alpha must broadcast to ({k}, {a})') from None
        if not np.isin(alpha_f, (-2, -1, 0, 1, 2)).all():
            raise InputError('alpha must be an integer in -2..2 (S_y ~ f^alpha)')
        alpha_arr = alpha_f.astype(np.int64)
        edf = np.broadcast_to(np.asarray(edf_overlapping(alpha_arr, m_eff[:, None],
                                                         n_eff[:, None]), dtype=float),
                              (k, a)).copy()
        if bounds:
            adev_lo, adev_hi = confidence_bounds(avar, edf, confidence)
        else:
            adev_lo, adev_hi = np.full(avar.shape, np.nan), np.full(avar.shape, np.nan)
        return AllanCurve(tau_s, m, avar, n_terms, edf, alpha_arr, np.asarray(adev_lo),
                          np.asarray(adev_hi), float(confidence), 'overlapping',
                          self.rate_hz)
