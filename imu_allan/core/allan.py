"""
Batch Allan curves: overlapping, non-overlapping (octave) and Hadamard variance.

All estimators take rate samples ``y`` (gyro rad/s, accel m/s^2, or fractional
frequency) at a constant sample period ``tau0 = 1 / rate_hz``.  Formulas follow
NIST SP 1065 (Riley, Handbook of Frequency Stability Analysis, 2008):

- overlapping Allan variance, NIST SP 1065 eq. 14 (phase form);
- non-overlapping Allan variance of the octave procedure of the Japanese text
  (m = 1, 2, 4, ... N/2, plain non-overlapping clusters), NIST SP 1065 eq. 12;
- overlapping Hadamard variance, NIST SP 1065 eq. 20 (insensitive to linear drift).

Confidence intervals use equivalent degrees of freedom (EDF) from Greenhall's
algorithm (C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based
on finite differences", PTTI 2003) with chi-square bounds (NIST SP 1065 eq. 45).  The
power-law noise type per tau is identified like Stable32 does: the lag-1
autocorrelation method (W. J. Riley and C. A. Greenhall, "Power law noise
identification using the lag 1 autocorrelation", EFTF 2004) when at least 30 cluster
averages exist, else the B1 ratio (Barnes) with the R(n) ratio to split white and
flicker phase noise, else the local log-log slope of the curve.

Alpha is the exponent of the frequency PSD, S_y(f) ~ f^alpha: 2 white PM (quantisation),
1 flicker PM, 0 white FM (angle/velocity random walk), -1 flicker FM (bias
instability), -2 random-walk FM (rate random walk); the Hadamard variance also
converges for -3 and -4.
"""

from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
import ctypes
from functools import lru_cache
import math
import os
import threading
from typing import NamedTuple, Optional, Sequence, Union

import numpy as np

from imu_allan.core.quantiles import chi2_ppf
from imu_allan.errors import InputError

#: Estimators of :func:`allan_curve`.
METHODS = ('overlapping', 'nonoverlapping', 'hadamard')
#: Named tau sets of :func:`tau_grid`.
TAU_KINDS = ('octave', 'dense', 'all')
#: Log-spaced points per decade of the 'dense' tau set.
DENSE_PER_DECADE = 10
#: Fewest cluster averages for the lag-1 autocorrelation noise identification
#: (Riley & Greenhall 2004 recommend at least 30).
MIN_ACF_POINTS = 30
#: Fewest cluster averages for the B1 ratio; with 2 or 3 averages B1 carries no
#: information (it is 1 for every noise type at N = 2).
MIN_B1_POINTS = 4

# Order of the phase difference (d in Greenhall's notation) of each method.
_DIFF_ORDER = {'overlapping': 2, 'nonoverlapping': 2, 'hadamard': 3}
# Lowest alpha for which each variance converges (alpha + 2 d > 1).
_ALPHA_MIN = {'overlapping': -2, 'nonoverlapping': -2, 'hadamard': -4}
# Elements per tile of the blocked kernels: a few tile-sized arrays stay in L2 (tuned
# with bench/bench_batch.py).  OpenBLAS is held to one thread meanwhile (see
# _single_thread_blas): its threads cost more than they give on tile-sized dots.
_TILE_ELEMS = 65536
# Widest column strip of the blocked kernel, in samples.
_STRIP_COLS = 4096
# Largest cancellation ratio accepted from the fast octave kernels (see _octave_sums):
# with dot products good to a few 1e-16 the result keeps about 1e-10 relative.
_CANCEL_LIMIT = 1e5
# Octave levels done by the moving-sum pyramid; the rest by the Gram kernel.
_PYRAMID_LEVELS = 18
# Rows K of the Gram kernel below which it starts: it costs about K / 2
# multiply-adds per sample, each halving of K one pass over memory.
_GRAM_MAX_ROWS = 128
# Elements per column strip of the Gram kernel's running sums.
_GRAM_TILE = 1 << 20
# Most worker threads (one axis each) used by allan_curve.
_MAX_THREADS = 8
# Most cluster averages fed to the lag-1 autocorrelation test (see _identify_axis).
_ACF_MAX_POINTS = 1 << 16
# Marker of an alpha that the data could not decide (too few clusters).
_ALPHA_UNKNOWN = -99


class AllanCurve(NamedTuple):
    """
    An Allan (or Hadamard) curve for one or more axes.

    Attributes
    ----------
    tau_s : np.ndarray
        Shape (k,), averaging times [s].
    m : np.ndarray
        Shape (k,), cluster sizes [samples], ``tau_s = m / rate_hz``.
    avar : np.ndarray
        Shape (k, n_axes), variance estimate [unit^2].
    n_terms : np.ndarray
        Shape (k,), number of squared differences summed at each tau.
    edf : np.ndarray
        Shape (k, n_axes), equivalent degrees of freedom of each estimate.
    alpha : np.ndarray
        Shape (k, n_axes), power-law exponent of the frequency PSD (S_y ~ f^alpha)
        used for the EDF: 2 white PM, 1 flicker PM, 0 white FM (white rate noise),
        -1 flicker FM (bias instability), -2 random-walk FM (rate random walk).
    adev_lo, adev_hi : np.ndarray
        Shape (k, n_axes), lower and upper deviation bounds at ``confidence`` [unit].
    confidence : float
        Two-sided confidence level of the bounds, e.g. 0.683 or 0.95.
    method : str
        'overlapping', 'nonoverlapping' or 'hadamard'.
    rate_hz : float
        Sample rate [Hz].

    """

    tau_s: np.ndarray
    m: np.ndarray
    avar: np.ndarray
    n_terms: np.ndarray
    edf: np.ndarray
    alpha: np.ndarray
    adev_lo: np.ndarray
    adev_hi: np.ndarray
    confidence: float
    method: str
    rate_hz: float

    @property
    def adev(self) -> np.ndarray:
        """Deviation, shape (k, n_axes) [unit]."""
        return np.sqrt(self.avar)


# --------------------------------------------------------------------------- tau sets

def _check_method(method: str) -> str:
    if method not in METHODS:
        raise InputError(f'unknown method {method!r}; expected one of {", ".join(METHODS)}')
    return method


def max_cluster_size(n_samples: int, method: str = 'overlapping') -> int:
    """
    Largest cluster size with at least one difference term.

    Parameters
    ----------
    n_samples : int
        Number of rate samples M.
    method : str
        'overlapping' or 'nonoverlapping' (M // 2: two clusters), or 'hadamard'
        (M // 3: three clusters).

    Returns
    -------
    int
        Largest m [samples]; 0 when the record is too short for any tau.

    """
    return int(n_samples) // (3 if _check_method(method) == 'hadamard' else 2)


def tau_grid(n_samples: int, kind: str, method: str = 'overlapping') -> np.ndarray:
    """
    Cluster sizes of a named tau set.

    Parameters
    ----------
    n_samples : int
        Number of rate samples M.
    kind : str
        'octave' (m = 1, 2, 4, ... as in the octave procedure of the Japanese text),
        'dense' (log-spaced, ``DENSE_PER_DECADE`` = 10 per decade, rounded to integers
        and deduplicated: 7 sizes below m = 10, 9 or 10 in every later decade; the
        streaming accumulator's exact taus use the same grid) or 'all' (every integer m;
        costs O(M) per tau, so O(M^2) in all).
    method : str
        'overlapping', 'nonoverlapping' or 'hadamard': sets the largest m
        (:func:`max_cluster_size`).

    Returns
    -------
    np.ndarray
        Shape (k,), int64 cluster sizes [samples], increasing; empty when the record is
        too short for any tau.

    """
    m_max = max_cluster_size(n_samples, method)
    if kind == 'octave':
        if m_max < 1:
            return np.zeros(0, dtype=np.int64)
        return 2 ** np.arange(int(math.log2(m_max)) + 1, dtype=np.int64)
    if kind == 'dense':
        if m_max < 1:
            return np.zeros(0, dtype=np.int64)
        n_pts = int(math.floor(DENSE_PER_DECADE * math.log10(m_max) + 1e-9)) + 1
        m = np.round(10.0 ** (np.arange(n_pts) / DENSE_PER_DECADE)).astype(np.int64)
        return np.unique(m[m <= m_max])
    if kind == 'all':
        return np.arange(1, m_max + 1, dtype=np.int64)
    raise InputError(f'unknown tau set {kind!r}; expected octave, dense, all or a list of '
                     'tau values in seconds')


def cluster_sizes(taus: Union[str, Sequence[float], np.ndarray], n_samples: int,
                  rate_hz: float, method: str = 'overlapping') -> np.ndarray:
    """
    Cluster sizes for a named tau set or for explicit tau values.

    Parameters
    ----------
    taus : str or sequence of float
        A kind of :func:`tau_grid`, or tau values [s]; these are rounded to the nearest
        cluster size ``round(tau_s * rate_hz)``, sorted and deduplicated.
    n_samples : int
        Number of rate samples M.
    rate_hz : float
        Sample rate [Hz].
    method : str
        'overlapping', 'nonoverlapping' or 'hadamard'.

    Returns
    -------
    np.ndarray
        Shape (k,), int64 cluster sizes [samples], increasing.

    Raises
    ------
    InputError
        A tau that rounds outside 1 .. :func:`max_cluster_size`, or an unknown kind.

    """
    if isinstance(taus, str):
        return tau_grid(n_samples, taus, method)
    tau_s = np.atleast_1d(np.asarray(taus, dtype=np.float64))
    if tau_s.ndim != 1 or tau_s.size == 0:
        raise InputError('tau values must be a non-empty list of numbers [s]')
    m_max = max_cluster_size(n_samples, method)
    m_float = np.round(tau_s * rate_hz)
    bad = ~np.isfinite(m_float) | (m_float < 1) | (m_float > m_max)
    if bad.any():
        t = tau_s[bad][0]
        raise InputError(
            f'tau {t:g} s is outside the range {1.0 / rate_hz:g} .. {m_max / rate_hz:g} s '
            f'that {n_samples} samples at {rate_hz:g} Hz allow for the {method} variance')
    return np.unique(m_float.astype(np.int64))


def terms_count(m: np.ndarray, n_samples: int, method: str = 'overlapping') -> np.ndarray:
    """
    Count the squared differences summed at each cluster size.

    Parameters
    ----------
    m : np.ndarray
        Shape (k,), cluster sizes [samples].
    n_samples : int
        Number of rate samples M.
    method : str
        'overlapping' (M + 1 - 2m), 'nonoverlapping' (M // m - 1) or 'hadamard'
        (M + 1 - 3m), NIST SP 1065 eqs. 12, 14, 20.

    Returns
    -------
    np.ndarray
        Shape (k,), int64 counts.

    """
    m = np.asarray(m, dtype=np.int64)
    if _check_method(method) == 'nonoverlapping':
        return n_samples // m - 1
    return n_samples + 1 - _DIFF_ORDER[method] * m


# ------------------------------------------------------------------ variance kernels

def _columns(y2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Axis-major copy of the samples (n_axes, M) [unit] and their means (n_axes,) [unit].

    The transpose goes in row blocks that fit in cache (a plain .T copy of a tall
    array is several times slower), split over the worker threads; each block is
    summed while it is still in cache.  Raises InputError on a non-finite sample.
    """
    n, n_axes = y2.shape
    cols = np.empty((n_axes, n))
    step = max(1, _TILE_ELEMS * 4 // max(1, n_axes))
    workers = _workers(n_axes)
    share = -(-n // (step * workers)) * step  # rows per worker, whole blocks

    def copy(w: int) -> list:
        totals = []
        for r0 in range(w * share, min(n, (w + 1) * share), step):
            blk = cols[:, r0:r0 + step]
            blk[...] = y2[r0:r0 + step].T
            totals.append(blk.sum(axis=1))
        return totals

    # Block sums added in block order: the same means whatever the thread count.
    blocks = [np.zeros(n_axes)] + sum(_map_threads(copy, workers, workers), [])
    means = np.sum(blocks, axis=0) / max(n, 1)
    if not np.isfinite(means).all():
        # Only an inf or NaN (or sums beyond 1e308) makes a mean non-finite.
        bad = int(np.flatnonzero(~np.isfinite(y2).all(axis=1))[0])
        raise InputError(f'sample {bad} is not a finite number')
    return cols, means


def _phase_row(col: np.ndarray) -> np.ndarray:
    """Return the running sum X (M + 1,) of one centred axis col (M,): phase / tau0."""
    x = np.empty(col.size + 1)
    x[0] = 0.0
    np.cumsum(col, out=x[1:])
    return x


def _tile_sumsq(tile: np.ndarray, order: int, buf_a: np.ndarray,
                buf_b: np.ndarray) -> float:
    """Sum of squares of the order-th difference of ``tile`` along axis 0."""
    rows, cols = tile.shape
    src = tile
    bufs = (buf_a, buf_b)
    for k in range(order):
        out = bufs[k % 2][:(rows - k - 1) * cols].reshape(rows - k - 1, cols)
        np.subtract(src[1:], src[:-1], out=out)
        src = out
    flat = src.reshape(-1)
    return float(np.dot(flat, flat))


def _diff_sumsq(x: np.ndarray, m: int, order: int) -> float:
    """
    Sum over i of (order-th difference of ``x`` at lag m)[i]^2, exactly.

    The 1-D phase row x (n,) is viewed as a (n // m, m) matrix whose row k holds
    x[k m .. k m + m - 1]: the lag-m difference is then a difference along axis 0.
    Tiles of at most ``_TILE_ELEMS`` elements (column strips of at most
    ``_STRIP_COLS``, walked down the rows) keep the work in cache, so each sample is
    read from memory about once per tau, with no large temporaries; tiles stay below
    OpenBLAS's 10,000-element threshold so its dot never spawns threads.
    """
    n = x.size
    n_terms = n - order * m
    if n_terms <= 0:
        return math.nan
    rows = n // m
    full = rows - order  # rows of terms lying wholly inside the matrix
    total = 0.0
    if full > 0:
        x2 = x[:rows * m].reshape(rows, m)
        cols = min(m, _STRIP_COLS)
        r_blk = max(4, _TILE_ELEMS // cols)
        buf_a = np.empty((r_blk + order) * cols)
        buf_b = np.empty_like(buf_a)
        for j0 in range(0, m, cols):
            j1 = min(m, j0 + cols)
            for r0 in range(0, full, r_blk):
                r1 = min(full, r0 + r_blk)
                total += _tile_sumsq(x2[r0:r1 + order, j0:j1], order, buf_a, buf_b)
    start = max(full, 0) * m
    if start < n_terms:
        # The ragged tail (fewer than m terms): plain slices.
        d = x[start:n]
        for _ in range(order):
            d = d[m:] - d[:-m]
        total += float(np.dot(d, d))
    return total


def _octave_sums(col: np.ndarray, mean: float, levels: int,
                 blocks: Optional[list]) -> tuple[np.ndarray, np.ndarray]:
    """
    Overlapping Allan sums of squares at m = 1, 2, 4, ... 2^(levels-1), one axis.

    Levels below ``_PYRAMID_LEVELS`` come from :func:`_pyramid_sums`, the others from
    :func:`_gram_sums` on the pyramid's top moving sums, which it leaves in ``col``.
    Both are exact identities that trade a little cancellation for speed; the returned
    ratio tells the caller where to recompute exactly.

    Parameters
    ----------
    col : np.ndarray
        Shape (M,), samples [unit]; overwritten.
    mean : float
        Reference subtracted from the samples (their mean) [unit].
    levels : int
        Number of octave levels, 2^(levels-1) <= M // 2.
    blocks : list or None
        If a list, receives per level j the first block sums of 2^j centred samples,
        shape (min(_ACF_MAX_POINTS, M // 2^j),) [unit], for the noise identification.

    Returns
    -------
    sums : np.ndarray
        Shape (levels,), sum of squared second differences of the phase [unit^2].
    cancel : np.ndarray
        Shape (levels,), size of the cancelled terms relative to the sum.

    """
    sums = np.zeros(levels)
    big = np.zeros(levels)
    n = col.size
    j = min(levels, _PYRAMID_LEVELS)
    _pyramid_sums(col, mean, j, sums, big, blocks, keep_top=levels > j)
    # col now starts with S_(2^j); on long records double it in place until the Gram
    # matrix has at most _GRAM_MAX_ROWS rows.
    while j < levels and (n + 1 - (1 << j)) >> j > _GRAM_MAX_ROWS:
        _double_in_place(col, j, sums, big, blocks)
        j += 1
    if j < levels:
        m0 = 1 << j
        top = col[:n + 1 - m0]  # S_m0, the moving sums of m0 samples
        _gram_sums(col, top.size, m0, levels - j, sums[j:], big[j:])
        if blocks is not None:
            starts = top[::m0]  # block sums of m0 samples
            for jj in range(j, levels):
                s = 1 << (jj - j)
                k = min(_ACF_MAX_POINTS, n >> jj)
                blocks.append(starts[:k * s].reshape(k, s).sum(axis=1))
    with np.errstate(divide='ignore', invalid='ignore'):
        cancel = np.where(sums > 0, big / sums, math.inf)
    return sums, cancel


def _pyramid_sums(col: np.ndarray, mean: float, levels: int, sums: np.ndarray,
                  big: np.ndarray, blocks: Optional[list], keep_top: bool) -> None:
    """
    Small octave levels from a pyramid of moving sums, fused in cache-sized tiles.

    S_1 = y - mean and S_2m[i] = S_m[i] + S_m[i+m]; with a = S_m[i], b = S_m[i+m] the
    second difference of the phase is b - a, and (b - a)^2 = 2 a^2 + 2 b^2 - (a + b)^2:
    one add and one dot per level (the squares of a + b are the next level's).  For
    white rate noise nothing cancels (ratio about 2).  Adds to sums[j] and to big[j]
    (the cancelled magnitude) for m = 2^j, j < levels; with ``keep_top`` it writes
    S_(2^levels) over the first M + 1 - 2^levels entries of col (each tile is read
    before its own part is written, and later tiles only read beyond it).
    """
    n = col.size
    halo = (1 << levels) - 1
    tile = max(_TILE_ELEMS, 2 * halo)  # keeps the halo a minor part of each tile
    bufs = (np.empty(tile + halo), np.empty(tile + halo))
    n_top = n + 1 - (1 << levels)
    stores = [[] for _ in range(levels)] if blocks is not None else None
    for t0 in range(0, n, tile):
        src = col[t0:min(n, t0 + tile + halo)]
        cur = np.subtract(src, mean, out=bufs[1][:src.size])
        q_next = None
        for j in range(levels):
            m = 1 << j
            if stores is not None:
                # Block sums S_m[k m] owned by this tile, for k < min(ACF points, M // m).
                first = -(-t0 // m) * m
                stop = min(t0 + tile, min(_ACF_MAX_POINTS, n // m) * m)
                if first < stop:
                    stores[j].append(cur[first - t0:stop - t0:m].copy())
            t = min(tile, n + 1 - 2 * m - t0)  # terms owned by this tile
            if t <= 0:
                break
            nxt = bufs[j % 2][:cur.size - m]
            np.add(cur[:-m], cur[m:], out=nxt)
            qa = q_next if q_next is not None and q_next[0] == t else None
            qa = qa[1] if qa is not None else _dot(cur[:t], cur[:t])
            qb = qa - _dot(cur[:m], cur[:m]) + _dot(cur[t:t + m], cur[t:t + m])
            qs = _dot(nxt[:t], nxt[:t])
            sums[j] += 2.0 * (qa + qb) - qs
            big[j] += 2.0 * (qa + qb)
            q_next = (t, qs)
            cur = nxt
        else:
            own = min(tile, n_top - t0)
            if keep_top and own > 0:
                col[t0:t0 + own] = cur[:own]
    if stores is not None:
        blocks.extend(np.concatenate(s) if s else np.empty(0) for s in stores)


def _double_in_place(buf: np.ndarray, j: int, sums: np.ndarray, big: np.ndarray,
                     blocks: Optional[list]) -> None:
    """
    Octave level m = 2^j from the moving sums S_m in buf, leaving S_2m there.

    The identity of :func:`_pyramid_sums`, in one pass over memory in tiles no longer
    than m.  Appends the level's block sums to ``blocks`` when it is a list.
    """
    m = 1 << j
    n = buf.size
    if blocks is not None:
        blocks.append(buf[:min(_ACF_MAX_POINTS, n // m) * m:m].copy())
    n_terms = n + 1 - 2 * m
    step = min(m, _TILE_ELEMS)
    for c0 in range(0, n_terms, step):
        c1 = min(n_terms, c0 + step)
        a, b = buf[c0:c1], buf[c0 + m:c1 + m]
        sq = 2.0 * (_dot(a, a) + _dot(b, b))
        np.add(a, b, out=a)  # b lies past every later tile's a: nothing is read twice
        sums[j] += sq - _dot(a, a)
        big[j] += sq


def _gram_sums(buf: np.ndarray, n_top: int, m0: int, levels: int, sums: np.ndarray,
               big: np.ndarray) -> None:
    """
    Octave levels m = m0 2^q, q < levels, from the Gram matrix of the moving sums.

    buf[:n_top] holds D = S_m0, the moving sums of m0 samples.  Viewed as a (K, m0)
    matrix, the second difference of the phase at m = s m0, row k and column c is
    d = sum_{r<s} (D[k+s+r, c] - D[k+r, c]), so with H = D D^T (one BLAS product
    for every level) and A = [k, k+s), B = [k+s, k+2s) the sum over c of d^2 is
    H(A, A) + H(B, B) - 2 H(A, B), each an s x s block sum of H.  The block sums
    of every level come from those of the level below (four blocks each), and those
    of |H| bound the rounding.  The moving sums are centred, so H holds no large
    offset.  The fewer than m0 terms past the last full row are summed directly
    from running sums down the rows.
    """
    k_rows, rest = divmod(n_top, m0)
    d_mat = buf[:k_rows * m0].reshape(k_rows, m0)
    q_sum = d_mat @ d_mat.T
    q_abs = np.abs(q_sum)
    for q in range(levels):
        s = 1 << q
        if q:
            h = s // 2
            q_sum = q_sum[:-h, :-h] + q_sum[h:, :-h] + q_sum[:-h, h:] + q_sum[h:, h:]
            q_abs = q_abs[:-h, :-h] + q_abs[h:, :-h] + q_abs[:-h, h:] + q_abs[h:, h:]
        n_k = k_rows + 1 - 2 * s  # rows k whose terms lie wholly in full rows
        if n_k > 0:
            for q_mat, sign, acc in ((q_sum, -2.0, sums), (q_abs, 2.0, big)):
                diag = np.diagonal(q_mat)
                acc[q] += float(np.sum(diag[:n_k] + diag[s:s + n_k]
                                       + sign * np.diagonal(q_mat, offset=s)))
    if rest:
        # Tail terms at row k_rows + 1 - 2s, columns < rest: run[r] sums the D rows
        # p0 .. p0 + r - 1 (buf reaches (K + 1) m0 when rest > 0), in column strips.
        s_max = 1 << (levels - 1)
        p0 = k_rows + 1 - 2 * s_max
        rows = buf[p0 * m0:(k_rows + 1) * m0].reshape(2 * s_max, m0)
        width = max(256, _GRAM_TILE // (2 * s_max + 1))
        run = np.empty((2 * s_max + 1, min(width, rest)))
        for c0 in range(0, rest, width):
            c1 = min(rest, c0 + width)
            r = run[:, :c1 - c0]
            r[0] = 0.0
            for i in range(2 * s_max):
                np.add(r[i], rows[i, c0:c1], out=r[i + 1])
            for q in range(levels):
                s = 1 << q
                a = 2 * (s_max - s)
                d = r[a + 2 * s] - 2.0 * r[a + s] + r[a]
                val = _dot(d, d)
                sums[q] += val
                big[q] += val


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.dot(a, b))


def _openblas_thread_apis() -> list:
    """
    Return (get, set) of every OpenBLAS loaded in the process (numpy's, scipy's).

    numpy and scipy wheels each bundle their own OpenBLAS; scipy's (L-BFGS-B, LAPACK)
    is loaded only when a scipy module needs it, so the list is read again each time
    (the libraries already opened are remembered).
    """
    try:
        with open('/proc/self/maps', encoding='ascii', errors='replace') as f:
            paths = {ln.split()[-1] for ln in f if 'openblas' in ln.lower()}
    except OSError:
        return []
    for path in sorted(paths - set(_BLAS_LIBS)):
        _BLAS_LIBS[path] = None
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for suffix in ('64_', '_64_', ''):
            for prefix in ('scipy_openblas', 'openblas'):
                get = getattr(lib, f'{prefix}_get_num_threads{suffix}', None)
                put = getattr(lib, f'{prefix}_set_num_threads{suffix}', None)
                if get is not None and put is not None and _BLAS_LIBS[path] is None:
                    get.restype = ctypes.c_int
                    put.argtypes = [ctypes.c_int]
                    _BLAS_LIBS[path] = (get, put)
    return [api for api in _BLAS_LIBS.values() if api is not None]


_BLAS_LOCK = threading.Lock()
_BLAS_LIBS: dict = {}
_BLAS_STATE: dict = {'depth': 0, 'saved': []}


@contextmanager
def _single_thread_blas():
    """
    Hold the OpenBLAS libraries to one thread (what threadpoolctl does; else a no-op).

    The kernels call dot on many cache-sized tiles, and already run one thread per
    axis; the fits work on matrices of a few tens of rows.  OpenBLAS's own threads
    would only oversubscribe the cores (measured: twice the CPU time of a search).
    """
    with _BLAS_LOCK:
        st = _BLAS_STATE
        if st['depth'] == 0:
            st['saved'] = [(api, api[0]()) for api in _openblas_thread_apis()]
            for api, _ in st['saved']:
                api[1](1)
        st['depth'] += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            st['depth'] -= 1
            if st['depth'] == 0:
                for api, n in st['saved']:
                    if n:
                        api[1](n)


def _is_octave(m: np.ndarray) -> bool:
    return bool(m.size) and bool(np.all((m & (m - 1)) == 0))


def _axis_work(y2: np.ndarray, col: np.ndarray, a: int, mean: float, m: np.ndarray,
               method: str, identify: bool) -> tuple[np.ndarray, Optional[np.ndarray]]:
    """
    Return the sums of squared phase differences and maybe alpha of axis a, (k,) each.

    col (M,) is the axis' contiguous copy and gets overwritten.  Its mean is removed
    first: the variances ignore a constant offset, and without it the running sums of
    an accelerometer at 9.81 m/s^2 with 1e-4 m/s^2 of noise would lose their digits.
    """
    order = _DIFF_ORDER[method]
    out = np.empty(m.size)
    cache = []

    def phase() -> np.ndarray:
        if not cache:
            cache.append(_phase_row(y2[:, a] - mean))
        return cache[0]

    if method == 'overlapping' and _is_octave(m) and m.size > 2:
        # The fast octave kernels never need the running sum X (a pass and a copy the
        # size of the record) unless they cancel too much or B1 asks for R(n).
        blocks = [] if identify else None
        sums, cancel = _octave_sums(col, mean, int(m.max()).bit_length(), blocks)
        pick = np.array([int(mj).bit_length() - 1 for mj in m])
        out[:] = sums[pick]
        # Where the identity cancelled more than 1e5 x the result (error ~1e-11
        # relative), recompute exactly from the running sum.
        for j in np.flatnonzero(~(cancel[pick] < _CANCEL_LIMIT)):
            out[j] = _diff_sumsq(phase(), int(m[j]), order)

        def cluster_means(j: int) -> np.ndarray:
            return blocks[pick[j]] / float(m[j])
    else:
        col -= mean
        x = _phase_row(col)
        cache.append(x)
        for j, mj in enumerate(m):
            mj = int(mj)
            if method == 'nonoverlapping':
                d = np.diff(x[::mj], 2)
                out[j] = float(np.dot(d, d))
            else:
                out[j] = _diff_sumsq(x, mj, order)

        def cluster_means(j: int) -> np.ndarray:
            mj = int(m[j])
            return np.diff(x[:_ACF_MAX_POINTS * mj + 1:mj]) / mj
    ids = _identify_axis(cluster_means, m, method, phase) if identify else None
    return out, ids


def _workers(n_axes: int) -> int:
    """Worker threads for n_axes axes: one per axis, at most one per core."""
    return max(1, min(n_axes, os.cpu_count() or 1, _MAX_THREADS))


def _map_threads(func, n_items: int, workers: int) -> list:
    """Return [func(i) for i < n_items], on threads: numpy and BLAS release the GIL."""
    if workers <= 1:
        return [func(i) for i in range(n_items)]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(func, range(n_items)))


def _normalise(sums: np.ndarray, m: np.ndarray, n_terms: np.ndarray,
               method: str) -> np.ndarray:
    # AVAR = sum / (2 m^2 n_terms), HVAR = sum / (6 m^2 n_terms) in units of y^2
    # (NIST SP 1065 eqs. 12, 14, 20 with x = tau0 X and tau = m tau0).
    scale = 6.0 if method == 'hadamard' else 2.0
    mf = m.astype(np.float64)
    return sums / (scale * mf * mf * n_terms.astype(np.float64))[:, None]


def _as_2d(y: np.ndarray) -> tuple[np.ndarray, bool]:
    y = np.asarray(y, dtype=np.float64)
    if y.ndim == 1:
        return y[:, None], True
    if y.ndim != 2:
        raise InputError(f'samples must be 1-D or 2-D, got shape {y.shape}')
    return y, False


def _check_m(m: np.ndarray, n: int, method: str) -> np.ndarray:
    m = np.asarray(m, dtype=np.int64).reshape(-1)
    m_max = max_cluster_size(n, method)
    if m.size and (m.min() < 1 or m.max() > m_max):
        raise ValueError(f'cluster sizes must lie in 1..{m_max} for {n} samples ({method})')
    return m


def _curve_core(y2: np.ndarray, m: np.ndarray, method: str,
                identify: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Variance and identified alpha per tau and axis (threads over the axes).

    Returns var (k, n_axes) [unit^2], n_terms (k,), alpha (k, n_axes) with
    ``_ALPHA_UNKNOWN`` where the record has too few clusters for a data-based test.
    """
    n, n_axes = y2.shape
    with _single_thread_blas():
        cols, means = _columns(y2)
        results = _map_threads(
            lambda a: _axis_work(y2, cols[a], a, float(means[a]), m, method, identify),
            n_axes, _workers(n_axes))
    n_terms = terms_count(m, n, method)
    sums = np.stack([r[0] for r in results], axis=1).reshape(m.size, n_axes)
    var = _normalise(sums, m, n_terms, method)
    alpha = (np.stack([r[1] for r in results], axis=1).reshape(m.size, n_axes)
             if identify else np.zeros((m.size, n_axes), dtype=np.int64))
    return var, n_terms, alpha


def _variance(y: np.ndarray, m: np.ndarray, method: str) -> tuple[np.ndarray, np.ndarray]:
    y2, one_d = _as_2d(y)
    m = _check_m(m, y2.shape[0], method)
    var, n_terms, _ = _curve_core(y2, m, method, identify=False)
    return (var[:, 0] if one_d else var), n_terms


def overlapping_avar(y: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Overlapping Allan variance at cluster sizes ``m`` (NIST SP 1065 eq. 14).

    AVAR(m tau0) = sum_i (X[i+2m] - 2 X[i+m] + X[i])^2 / (2 m^2 (M + 1 - 2m)), with
    X the running sum of the M samples (the phase divided by tau0).  A per-axis
    reference (the mean) is subtracted first, so a 9.81 m/s^2 offset costs no digits.

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit].
    m : np.ndarray
        Shape (k,), cluster sizes [samples], each in 1 .. M // 2.

    Returns
    -------
    avar : np.ndarray
        Shape (k, n_axes) (or (k,) for 1-D input), Allan variance [unit^2].
    n_terms : np.ndarray
        Shape (k,), number of second differences summed, M + 1 - 2m.

    """
    return _variance(y, m, 'overlapping')


def nonoverlapping_avar(y: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Non-overlapping Allan variance at cluster sizes ``m`` (NIST SP 1065 eq. 12).

    AVAR(m tau0) = sum_k (ybar[k+1] - ybar[k])^2 / (2 (K - 1)) over the K = M // m
    plain (non-overlapping) cluster averages ybar: the octave procedure of the
    Japanese text when m = 1, 2, 4, ...

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit].
    m : np.ndarray
        Shape (k,), cluster sizes [samples], each in 1 .. M // 2.

    Returns
    -------
    avar : np.ndarray
        Shape (k, n_axes) (or (k,) for 1-D input), Allan variance [unit^2].
    n_terms : np.ndarray
        Shape (k,), number of differences summed, M // m - 1.

    """
    return _variance(y, m, 'nonoverlapping')


def hadamard_var(y: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Overlapping Hadamard variance at cluster sizes ``m`` (NIST SP 1065 eq. 20).

    HVAR(m tau0) = sum_i (X[i+3m] - 3 X[i+2m] + 3 X[i+m] - X[i])^2 / (6 m^2 (M + 1 - 3m)):
    a third difference of the phase, so a linear frequency drift (a ramp in y)
    cancels exactly.

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit].
    m : np.ndarray
        Shape (k,), cluster sizes [samples], each in 1 .. M // 3.

    Returns
    -------
    hvar : np.ndarray
        Shape (k, n_axes) (or (k,) for 1-D input), Hadamard variance [unit^2].
    n_terms : np.ndarray
        Shape (k,), number of third differences summed, M + 1 - 3m.

    """
    return _variance(y, m, 'hadamard')


# ---------------------------------------------------------- equivalent degrees of freedom

# Greenhall & Riley 2003, table 2: (a0, a1) of 1/edf ~ (a0 - a1 / r) / r for the
# unmodified variances, by alpha (rows) and d = 1, 2, 3 (columns); None = divergent.
_GH_TABLE2 = {
    2: ((1.5, 0.5), (35.0 / 18.0, 1.0), (2.31, 1.5)),
    1: ((78.6, 25.2), (790.0, 410.0), (9950.0, 6520.0)),
    0: ((2.0 / 3.0, 1.0 / 6.0), (2.0 / 3.0, 1.0 / 3.0), (7.0 / 9.0, 0.5)),
    -1: (None, (0.852, 0.375), (0.997, 0.617)),
    -2: (None, (1.079, 0.368), (1.033, 0.607)),
    -3: (None, None, (1.053, 0.553)),
    -4: (None, None, (1.302, 0.535)),
}
# Greenhall & Riley 2003, table 3: (b0, b1) of sz(0) ~ b0 + b1 ln m for alpha = 1.
_GH_TABLE3 = ((6.0, 4.0), (15.23, 12.0), (47.8, 40.0))
_GH_J_MAX = 100


def _gh_sw(t: np.ndarray, alpha: int) -> np.ndarray:
    """Greenhall's generalised autocovariance sw(t) of the power-law phase (eq. 7)."""
    # -|t|, t^2 ln|t|, |t|^3, t^4 ln|t|, |t|^5, t^6 ln|t|, |t|^7 for alpha = 2 .. -4.
    at = np.abs(t)
    if alpha == 2:
        return -at
    if alpha % 2 == 0:
        return at ** (3 - alpha)
    with np.errstate(divide='ignore', invalid='ignore'):
        val = at ** (3 - alpha) * np.log(at)
    return np.where(at == 0, 0.0, val)


def _gh_sx(t: np.ndarray, f: float, alpha: int) -> np.ndarray:
    """Autocovariance after the frequency pre-filter of factor F (eq. 8)."""
    if math.isinf(f):
        return _gh_sw(t, alpha + 2)
    h = np.longdouble(1.0) / np.longdouble(f)
    ff = np.longdouble(f) ** 2
    return ff * (2 * _gh_sw(t, alpha) - _gh_sw(t - h, alpha) - _gh_sw(t + h, alpha))


def _gh_sz(t: np.ndarray, f: float, alpha: int, d: int) -> np.ndarray:
    """Autocovariance of the d-th difference (eq. 9): binomial combination of sx."""
    t = np.asarray(t, dtype=np.longdouble)
    acc = np.zeros_like(t)
    for k in range(-d, d + 1):
        acc += (-1) ** k * math.comb(2 * d, d + k) * _gh_sx(t + k, f, alpha)
    return acc


def _gh_basic_sum(j_n: int, m_n: float, s: float, f: float, alpha: int, d: int) -> float:
    """Greenhall's basic sum (eq. 10), vectorised over the lag j."""
    if alpha == 2 and s > 1:
        # White PM: sx vanishes beyond 1/F of an integer, so sz(j/S) is zero except
        # next to multiples of S; summing only those keeps huge J cheap.
        near = np.arange(1, d + 2)[:, None] * int(s) + np.array([-1, 0, 1])
        j = np.unique(near[(near >= 1) & (near < j_n)]).astype(np.longdouble)
    else:
        j = np.arange(1, j_n, dtype=np.longdouble)
    sz0 = _gh_sz(np.zeros(1), f, alpha, d)[0]
    szj = _gh_sz(np.array([j_n / s], dtype=np.longdouble), f, alpha, d)[0]
    body = _gh_sz(j / np.longdouble(s), f, alpha, d) if j.size else np.zeros(0)
    total = (sz0 ** 2 + (1 - j_n / m_n) * szj ** 2
             + 2 * np.sum((1 - j / np.longdouble(m_n)) * body ** 2))
    return float(total)


@lru_cache(maxsize=4096)
def _edf_greenhall_scalar(alpha: int, d: int, m: int, n_phase: int,
                          overlapping: bool) -> float:
    """Greenhall's EDF algorithm for the unmodified variances (F = m), one point."""
    f = float(m)
    s = float(m) if overlapping else 1.0
    span = 1 + m * d  # L = m / F + m d: phase points spanned by one term
    if n_phase < span:
        return math.nan
    m_n = 1 + math.floor(s * (n_phase - span) / m)  # number of terms
    j_n = int(min(m_n, (d + 1) * s))
    r = m_n / s
    jm = _GH_J_MAX
    if alpha == 2:
        if math.ceil(r) > d:
            a0 = math.comb(4 * d, 2 * d) / math.comb(2 * d, d) ** 2
            inv = (a0 - d / 2.0 / r) / m_n
        else:
            # So few terms that the closed form does not hold: the exact basic sum.
            sz0 = float(_gh_sz(np.zeros(1), f, 2, d)[0])
            inv = _gh_basic_sum(j_n, m_n, s, f, 2, d) / (m_n * sz0 ** 2)
    elif alpha == 1:
        b0, b1 = _GH_TABLE3[d - 1]
        if j_n <= jm:
            sz0 = float(_gh_sz(np.zeros(1), f, 1, d)[0])
            inv = _gh_basic_sum(j_n, m_n, s, f, 1, d) / (m_n * sz0 ** 2)
        elif r > d + 1:
            a0, a1 = _GH_TABLE2[1][d - 1]
            inv = (a0 - a1 / r) / (r * (b0 + b1 * math.log(m)) ** 2)
        else:
            mp = jm / r
            inv = _gh_basic_sum(jm, jm, mp, mp, 1, d) / (jm * (b0 + b1 * math.log(m)) ** 2)
    else:
        if j_n <= jm:
            fp = f if m * (d + 1) <= jm else math.inf
            sz0 = float(_gh_sz(np.zeros(1), fp, alpha, d)[0])
            inv = _gh_basic_sum(j_n, m_n, s, fp, alpha, d) / (m_n * sz0 ** 2)
        elif r > d + 1:
            a0, a1 = _GH_TABLE2[alpha][d - 1]
            inv = (a0 - a1 / r) / r
        else:
            mp = jm / r
            sz0 = float(_gh_sz(np.zeros(1), math.inf, alpha, d)[0])
            inv = _gh_basic_sum(jm, jm, mp, math.inf, alpha, d) / (jm * sz0 ** 2)
    return 1.0 / inv if inv > 0 else math.nan


def edf_greenhall(alpha, m, n_samples, d: int = 2, overlapping: bool = True) -> np.ndarray:
    """
    Equivalent degrees of freedom of an unmodified difference variance (Greenhall).

    Greenhall & Riley 2003 (also NIST SP 1065 section 5.2.3 and Stable32): the exact
    "basic sum" (their eq. 10) for up to 100 lags, the tabulated large-sample forms
    (their tables 2 and 3) beyond.

    Parameters
    ----------
    alpha : array_like of int
        Power-law exponent of S_y(f), in 2 .. -2 (down to -4 when d = 3).
    m : array_like of int
        Cluster sizes [samples]; broadcast with ``alpha`` and ``n_samples``.
    n_samples : array_like of int
        Number of rate samples M (M + 1 phase points).
    d : int
        Order of the phase difference: 2 Allan, 3 Hadamard.
    overlapping : bool
        True for the fully overlapping estimators (stride 1 sample).

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs; NaN where undefined.

    """
    a, mm, nn = np.broadcast_arrays(np.asarray(alpha, dtype=np.int64),
                                    np.asarray(m, dtype=np.int64),
                                    np.asarray(n_samples, dtype=np.int64))
    lo = -2 * d + 2
    if a.size and (a.max() > 2 or a.min() < lo):
        raise ValueError(f'alpha must lie in {lo} .. 2 for a difference of order {d}')
    out = np.empty(a.shape)
    for idx in np.ndindex(a.shape):
        out[idx] = _edf_greenhall_scalar(int(a[idx]), d, int(mm[idx]), int(nn[idx]) + 1,
                                         bool(overlapping))
    return out


def edf_overlapping(alpha, m, n_samples) -> np.ndarray:
    """
    EDF of the overlapping Allan variance (Greenhall's algorithm, d = 2).

    Parameters
    ----------
    alpha : array_like of int
        Noise exponent of S_y(f), in {2, 1, 0, -1, -2}.
    m : array_like of int
        Cluster sizes [samples].
    n_samples : array_like of int
        Number of rate samples M.

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs.

    """
    return edf_greenhall(alpha, m, n_samples, d=2, overlapping=True)


def edf_nonoverlapping(alpha, m, n_samples) -> np.ndarray:
    """
    EDF of the non-overlapping Allan variance (Greenhall's algorithm, d = 2).

    Parameters
    ----------
    alpha : array_like of int
        Noise exponent of S_y(f), in {2, 1, 0, -1, -2}.
    m : array_like of int
        Cluster sizes [samples].
    n_samples : array_like of int
        Number of rate samples M.

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs.

    """
    return edf_greenhall(alpha, m, n_samples, d=2, overlapping=False)


def edf_hadamard(alpha, m, n_samples) -> np.ndarray:
    """
    EDF of the overlapping Hadamard variance (Greenhall's algorithm, d = 3).

    Parameters
    ----------
    alpha : array_like of int
        Noise exponent of S_y(f), in {2, 1, 0, -1, -2, -3, -4}.
    m : array_like of int
        Cluster sizes [samples].
    n_samples : array_like of int
        Number of rate samples M.

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs.

    """
    return edf_greenhall(alpha, m, n_samples, d=3, overlapping=True)


def edf_for_method(alpha, m, n_samples, method: str = 'overlapping') -> np.ndarray:
    """
    EDF of the estimator ``method`` ('overlapping', 'nonoverlapping', 'hadamard').

    Parameters
    ----------
    alpha : array_like of int
        Noise exponent of S_y(f).
    m : array_like of int
        Cluster sizes [samples].
    n_samples : array_like of int
        Number of rate samples M.
    method : str
        Estimator name.

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs.

    """
    _check_method(method)
    return edf_greenhall(alpha, m, n_samples, d=_DIFF_ORDER[method],
                         overlapping=method != 'nonoverlapping')


def confidence_bounds(avar, edf, confidence: float) -> tuple[np.ndarray, np.ndarray]:
    """
    Chi-square confidence bounds on the deviation (NIST SP 1065 eq. 45).

    edf * avar / var ~ chi2(edf), so the two-sided interval at level p is
    var in [edf avar / chi2_{(1+p)/2}, edf avar / chi2_{(1-p)/2}].

    Parameters
    ----------
    avar : array_like
        Variance estimates [unit^2].
    edf : array_like
        Equivalent degrees of freedom, broadcast with ``avar``.
    confidence : float
        Two-sided confidence level in (0, 1), e.g. 0.683.

    Returns
    -------
    adev_lo, adev_hi : np.ndarray
        Lower and upper deviation bounds [unit], the broadcast shape; NaN where the
        EDF is not positive and finite.

    """
    if not 0.0 < confidence < 1.0:
        raise InputError(f'confidence must lie strictly between 0 and 1, got {confidence}')
    avar, edf = np.broadcast_arrays(np.asarray(avar, dtype=np.float64),
                                    np.asarray(edf, dtype=np.float64))
    ok = np.isfinite(edf) & (edf > 0)
    e = np.where(ok, edf, 1.0)
    chi_hi = chi2_ppf(0.5 * (1.0 + confidence), e)
    chi_lo = chi2_ppf(0.5 * (1.0 - confidence), e)
    with np.errstate(all='ignore'):
        lo = np.sqrt(e * avar / chi_hi)
        hi = np.sqrt(e * avar / chi_lo)
    return np.where(ok, lo, np.nan), np.where(ok, hi, np.nan)


# ------------------------------------------------------------------ noise identification

# Boundaries on the local slope mu of log AVAR against log tau between neighbouring
# alphas 2 | 1 | 0 | -1 | -2 | -3 | -4.  White PM falls as tau^-2; flicker PM as
# tau^-2 times a log factor, which makes its local slope -1.33 .. -1.88 at
# m = 1 .. 1000 (f_h = 1 / (2 tau0)); white FM -1, flicker FM 0, random-walk FM +1
# (NIST SP 1065 table 1).
_SLOPE_EDGES = np.array([-1.9, -1.35, -0.5, 0.5, 1.5, 2.5])


def alpha_from_slope(tau_s, avar, method: str = 'overlapping') -> np.ndarray:
    """
    Integer noise exponent per point from the local log-log slope of the curve.

    For when raw data are not at hand (the streaming accumulator): mu = d ln AVAR /
    d ln tau from neighbouring points (one-sided at the ends), then alpha = -mu - 1
    with the boundaries of ``_SLOPE_EDGES`` (white and flicker PM both fall as
    tau^-2; the flicker log factor flattens its slope to -1.3 .. -1.9).

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s], increasing.
    avar : array_like
        Shape (k,) or (k, n_axes), variances [unit^2].
    method : str
        'hadamard' allows alpha down to -4, the Allan variances down to -2.

    Returns
    -------
    np.ndarray
        int64 alpha, the shape of ``avar``; 0 (white FM) where the slope is undefined.

    """
    tau_s = np.asarray(tau_s, dtype=np.float64)
    avar = np.asarray(avar, dtype=np.float64)
    a2 = avar[:, None] if avar.ndim == 1 else avar
    alpha = np.zeros(a2.shape, dtype=np.int64)
    if tau_s.size >= 2:
        with np.errstate(divide='ignore', invalid='ignore'):
            mu = np.gradient(np.log(a2), np.log(tau_s), axis=0)
        labels = np.array([2, 1, 0, -1, -2, -3, -4])
        idx = np.searchsorted(_SLOPE_EDGES, np.nan_to_num(mu, nan=-1.0))
        alpha = np.where(np.isfinite(mu), labels[idx], 0)
    alpha = np.clip(alpha, _ALPHA_MIN[_check_method(method)], 2)
    return alpha[:, 0] if avar.ndim == 1 else alpha


def _detrended(z: np.ndarray) -> np.ndarray:
    """Remove the least-squares line from z (n,): a frequency drift (Riley 2004)."""
    n = z.size
    t = np.arange(n, dtype=np.float64)
    t -= 0.5 * (n - 1)
    e = z - z.mean()
    tt = float(np.dot(t, t))
    if tt > 0:
        e -= (float(np.dot(t, e)) / tt) * t
    return e


def _lag1_alpha(z: np.ndarray, d_max: int) -> int:
    """
    Lag-1 autocorrelation noise identification of cluster averages z (Riley 2004).

    r1 is the lag-1 autocorrelation and delta = r1 / (1 + r1); while delta >= 0.25 and
    fewer than d_max differences were taken, difference z once more.  Then
    alpha = -round(2 delta) - 2 d for frequency data.
    """
    e = _detrended(z)
    d = 0
    while True:
        e = e - e.mean()
        den = float(np.dot(e, e))
        r1 = float(np.dot(e[:-1], e[1:])) / den if den > 0 else 0.0
        delta = r1 / (1.0 + r1) if r1 > -1.0 else -1.0
        if delta < 0.25 or d >= d_max:
            return int(-round(2.0 * delta)) - 2 * d
        e = np.diff(e)
        d += 1


def _b1_theory(n: int, mu: int) -> float:
    """Return the B1 ratio (N-sample / 2-sample variance) expected for AVAR ~ tau^mu."""
    if mu == 0:
        return n * math.log(n) / (2.0 * (n - 1) * math.log(2.0))
    return n * (1.0 - n ** mu) / (2.0 * (n - 1) * (1.0 - 2.0 ** mu))


def _mvar_ratio(x_row: np.ndarray, m: int) -> float:
    """
    R(n) = MVAR / AVAR at cluster size m from one phase row X (n,) (NIST SP 1065).

    Only a noise-type decision rests on it, so for m >= 64 the terms are taken at a
    stride of m / 16 (still 16 per cluster) from block sums, one pass over X.
    """
    n = x_row.size
    step = m // 16 if m >= 64 and m % 16 == 0 else 1
    blocks = n // step
    # P[q] = sum of X over the first q * step points (prefix sums at the stride).
    p = np.zeros(blocks + 1)
    np.cumsum(x_row[:blocks * step].reshape(blocks, step).sum(axis=1), out=p[1:])
    ms = m // step
    k = blocks - 3 * ms + 1
    if k < 1:
        return math.nan
    inner = p[3 * ms:3 * ms + k] - 3 * p[2 * ms:2 * ms + k] + 3 * p[ms:ms + k] - p[:k]
    mvar = float(np.dot(inner, inner)) / (2.0 * m ** 4 * k)
    xs = x_row[::step]
    d = xs[2 * ms:] - 2 * xs[ms:-ms] + xs[:-2 * ms]
    avar = float(np.dot(d, d)) / (2.0 * m ** 2 * d.size)
    return mvar / avar if avar > 0 else math.nan


def _rn_theory(m: int, alpha: int) -> float:
    """Return the R(n) expected for white PM (1/m) or flicker PM (f_h = 0.5 / tau0)."""
    if alpha == 2:
        return 1.0 / m
    return 3.0 * math.log(256.0 / 27.0) / (2.0 * (1.038 + 3.0 * math.log(math.pi * m)))


def _b1_alpha(z: np.ndarray, phase, m: int, alpha_min: int) -> int:
    """
    B1-ratio noise identification of n cluster averages z (n,), 4 <= n < 30.

    phase() returns the running sum X (M + 1,), needed only to split phase noises.
    """
    n = z.size
    dz = np.diff(z)
    avar = 0.5 * float(np.dot(dz, dz)) / dz.size
    if avar <= 0:
        return 0
    b1 = float(np.var(z, ddof=1)) / avar
    mus = list(range(-2, -alpha_min))  # mu = -alpha - 1 for alpha <= 0; -2 for PM
    expected = [_b1_theory(n, mu) for mu in mus]
    mu = mus[-1]
    for i in range(len(mus) - 1):
        edge = math.sqrt(expected[i] * expected[i + 1])
        if b1 < edge:
            mu = mus[i]
            break
    if mu > -2:
        return -mu - 1
    # Phase noise: white and flicker PM share mu = -2; the R(n) ratio separates them.
    rn = _mvar_ratio(phase(), m)
    if not math.isfinite(rn) or rn <= 0:
        return 1
    r_white, r_flicker = _rn_theory(m, 2), _rn_theory(m, 1)
    return 2 if abs(math.log(rn / r_white)) < abs(math.log(rn / r_flicker)) else 1


def _identify_axis(cluster_means, m: np.ndarray, method: str, phase) -> np.ndarray:
    """
    Alpha per cluster size for one axis, shape (k,).

    cluster_means(j) returns the first min(_ACF_MAX_POINTS, M // m[j]) non-overlapping
    cluster averages [unit] and phase() the running sum X (M + 1,) of the axis.  The
    lag-1 test uses at most _ACF_MAX_POINTS averages: r1 then has a standard error of
    0.004, well inside the decision margins, and the test stays cheap at m = 1 on long
    records.  ``_ALPHA_UNKNOWN`` where fewer than ``MIN_B1_POINTS`` clusters exist.
    """
    alpha_min = _ALPHA_MIN[method]
    d_max = _DIFF_ORDER[method]
    out = np.full(m.size, _ALPHA_UNKNOWN, dtype=np.int64)
    for j, mj in enumerate(m):
        z = cluster_means(j)
        if z.size >= MIN_ACF_POINTS:
            out[j] = max(alpha_min, min(2, _lag1_alpha(z, d_max)))
        elif z.size >= MIN_B1_POINTS:
            out[j] = max(alpha_min, min(2, _b1_alpha(z, phase, int(mj), alpha_min)))
    return out


def _fill_unknown(alpha: np.ndarray, tau_s: np.ndarray, var: np.ndarray,
                  method: str) -> np.ndarray:
    """Replace ``_ALPHA_UNKNOWN`` entries by the local-slope estimate."""
    unknown = alpha == _ALPHA_UNKNOWN
    if unknown.any():
        alpha = np.where(unknown, alpha_from_slope(tau_s, var, method), alpha)
    return alpha


def identify_alpha(y: np.ndarray, m: np.ndarray, method: str = 'overlapping') -> np.ndarray:
    """
    Integer noise exponent alpha per cluster size and axis, as Stable32 does.

    Lag-1 autocorrelation (Riley & Greenhall 2004) of the linearly detrended
    non-overlapping cluster averages when there are at least 30 of them; else the
    B1 ratio (and R(n) for phase noise) with at least 4; else the local slope.

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit].
    m : np.ndarray
        Shape (k,), cluster sizes [samples].
    method : str
        'overlapping', 'nonoverlapping' or 'hadamard' (sets the alpha range).

    Returns
    -------
    np.ndarray
        Shape (k, n_axes) (or (k,) for 1-D input), int64 alpha.

    """
    y2, one_d = _as_2d(y)
    _check_method(method)
    m = _check_m(m, y2.shape[0], method)
    var, _, alpha = _curve_core(y2, m, method, identify=True)
    alpha = _fill_unknown(alpha, m.astype(np.float64), var, method)
    return alpha[:, 0] if one_d else alpha


# ---------------------------------------------------------------------------- the curve

def allan_curve(y: np.ndarray, rate_hz: float,
                taus: Union[str, Sequence[float], np.ndarray] = 'octave',
                method: str = 'overlapping', confidence: float = 0.683,
                alpha: Optional[Union[int, np.ndarray]] = None) -> AllanCurve:
    """
    Allan (or Hadamard) curve with noise-aware confidence bounds for every axis.

    Parameters
    ----------
    y : np.ndarray
        Shape (M,) or (M, n_axes), rate samples [unit] at a constant rate.
    rate_hz : float
        Sample rate [Hz].
    taus : str or sequence of float
        'octave', 'dense', 'all' (:func:`tau_grid`) or tau values [s]
        (:func:`cluster_sizes`).
    method : str
        'overlapping' (NIST SP 1065 eq. 14), 'nonoverlapping' (eq. 12, the octave
        procedure of the Japanese text) or 'hadamard' (overlapping, eq. 20).
    confidence : float
        Two-sided confidence level of the bounds, e.g. 0.683 or 0.95.
    alpha : int or np.ndarray, optional
        Noise exponent for the EDF, broadcast to (k, n_axes); None identifies it per
        tau and axis from the data (:func:`identify_alpha`).

    Returns
    -------
    AllanCurve
        Arrays of shape (k, n_axes) (n_axes = 1 for 1-D input).

    Raises
    ------
    InputError
        Non-finite samples, a record too short for any tau, a bad rate, tau or method.

    """
    _check_method(method)
    if not (isinstance(rate_hz, (int, float, np.floating)) and math.isfinite(rate_hz)
            and rate_hz > 0):
        raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
    if not 0.0 < confidence < 1.0:
        raise InputError(f'confidence must lie strictly between 0 and 1, got {confidence}')
    y2, _ = _as_2d(y)
    n, n_axes = y2.shape
    m_max = max_cluster_size(n, method)
    if m_max < 1:
        need = 3 if method == 'hadamard' else 2
        raise InputError(f'{n} samples are too few for any tau of the {method} variance '
                         f'(need at least {need})')
    m = cluster_sizes(taus, n, float(rate_hz), method)
    avar, n_terms, alpha_arr = _curve_core(y2, m, method, identify=alpha is None)
    tau_s = m / float(rate_hz)
    if alpha is None:
        alpha_arr = _fill_unknown(alpha_arr, tau_s, avar, method)
    else:
        alpha_arr = np.broadcast_to(np.asarray(alpha, dtype=np.int64),
                                    (m.size, n_axes)).copy()
    edf = edf_for_method(alpha_arr, m[:, None], n, method)
    lo, hi = confidence_bounds(avar, edf, confidence)
    return AllanCurve(tau_s=tau_s, m=m, avar=avar, n_terms=n_terms, edf=edf,
                      alpha=alpha_arr, adev_lo=lo, adev_hi=hi,
                      confidence=float(confidence), method=method, rate_hz=float(rate_hz))
