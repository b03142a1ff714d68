"""
The difference sums behind the batch curve, fast and exact.

Sums of squared differences of the phase (the running sum of the samples) per cluster
size: a moving-sum pyramid and Gram kernels for octave cluster sizes, strip-wise
differences of the phase otherwise, one thread per axis.  Part of
:mod:`imu_allan.core.allan`; :mod:`.kernels` normalises the sums into variances.
"""

from concurrent.futures import ThreadPoolExecutor
import math
import os

import numpy as np

from imu_allan.core.allan.noise_id import _ACF_MAX_POINTS, _identify_axis
from imu_allan.core.allan.taus import _DIFF_ORDER
from imu_allan.errors import InputError


# Elements per tile of the blocked kernels: a few tile-sized arrays stay in L2 (tuned
# with bench/bench_batch.py).
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
        _means(y2)  # only an inf or NaN (or sums beyond 1e308) gets here: names the row
    return cols, means


def _means(y2: np.ndarray) -> np.ndarray:
    """Per-axis means (n_axes,) of the samples (M, n_axes); InputError if not finite."""
    means = y2.sum(axis=0) / max(y2.shape[0], 1)
    if not np.isfinite(means).all():
        bad = int(np.flatnonzero(~np.isfinite(y2).all(axis=1))[0])
        raise InputError(f'sample {bad} is not a finite number')
    return means


def _phase_row(col: np.ndarray, mean: float = 0.0) -> np.ndarray:
    """Return the running sum X (M + 1,) of one axis col (M,) less mean: phase / tau0."""
    x = np.empty(col.size + 1)
    x[0] = 0.0
    np.subtract(col, mean, out=x[1:])
    np.cumsum(x[1:], out=x[1:])
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
                 blocks: list | None) -> tuple[np.ndarray, np.ndarray]:
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
                  big: np.ndarray, blocks: list | None, keep_top: bool) -> None:
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
    stores: list[list] | None = [[] for _ in range(levels)] if blocks is not None else None
    for t0 in range(0, n, tile):
        src = col[t0:min(n, t0 + tile + halo)]
        cur = np.subtract(src, mean, out=bufs[1][:src.size])
        q_next: tuple[int, float] | None = None
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
            qa = q_next[1] if q_next is not None and q_next[0] == t else _dot(cur[:t], cur[:t])
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
    if stores is not None and blocks is not None:
        blocks.extend(np.concatenate(s) if s else np.empty(0) for s in stores)


def _double_in_place(buf: np.ndarray, j: int, sums: np.ndarray, big: np.ndarray,
                     blocks: list | None) -> None:
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


def _is_octave(m: np.ndarray) -> bool:
    return bool(m.size) and bool(np.all((m & (m - 1)) == 0))


def _axis_work(y2: np.ndarray, col: np.ndarray | None, a: int, mean: float, m: np.ndarray,
               method: str, identify: bool,
               tau_threads: int = 1) -> tuple[np.ndarray, np.ndarray | None]:
    """
    Return the sums of squared phase differences and maybe alpha of axis a, (k,) each.

    col (M,) is the axis' contiguous copy that the octave kernels overwrite (None on
    the other paths, which read y2).  The mean is removed first: the variances ignore
    a constant offset, and without it the running sums of an accelerometer at 9.81
    m/s^2 with 1e-4 m/s^2 of noise would lose their digits.
    With ``tau_threads`` > 1 the taus of the running-sum path are shared by threads
    (one axis on several cores).
    """
    order = _DIFF_ORDER[method]
    out = np.empty(m.size)
    cache: list[np.ndarray] = []

    def phase() -> np.ndarray:
        if not cache:
            cache.append(_phase_row(y2[:, a], mean))
        return cache[0]

    if col is not None:
        # The fast octave kernels never need the running sum X (a pass and a copy the
        # size of the record) unless they cancel too much or B1 asks for R(n).
        blocks: list | None = [] if identify else None
        sums, cancel = _octave_sums(col, mean, int(m.max()).bit_length(), blocks)
        pick = np.array([int(m_j).bit_length() - 1 for m_j in m])
        out[:] = sums[pick]
        # Where the identity cancelled more than 1e5 x the result (error ~1e-11
        # relative), recompute exactly from the running sum.
        for j in np.flatnonzero(~(cancel[pick] < _CANCEL_LIMIT)):
            out[j] = _diff_sumsq(phase(), int(m[j]), order)

        def cluster_means(j: int) -> np.ndarray:
            assert blocks is not None  # kept when identify asks for them
            return blocks[pick[j]] / float(m[j])
    else:
        x = phase()

        def tau_sums(part: int) -> None:
            # Every tau is summed by one thread alone: the same result for any count.
            for k in range(part, m.size, tau_threads):
                m_k = int(m[k])
                if method == 'nonoverlapping':
                    d = np.diff(x[::m_k], 2)
                    out[k] = float(np.dot(d, d))
                else:
                    out[k] = _diff_sumsq(x, m_k, order)
        _map_threads(tau_sums, tau_threads, tau_threads)

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
