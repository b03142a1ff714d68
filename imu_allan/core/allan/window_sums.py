"""
The streaming accumulator's passes over one window of samples.

A window is the history the accumulator keeps plus the samples it takes in (level 0),
or a decimated level's cluster sums.  :func:`phase` builds the window's running sum X
from zero after removing the window's mean (a constant cancels in every second
difference, so X stays small); :func:`accumulate` adds the squared second differences
(X[j] - 2 X[j - m] + X[j - 2m])^2 that end at the new points (NIST SP 1065 eq. 14);
:func:`dirty_terms` sums those of them that span a missing (filled) sample, which
:mod:`imu_allan.core.allan.fill_terms` leaves out or repairs.  Used by
:class:`imu_allan.core.allan.accumulator.AllanAccumulator`.
"""

import numpy as np

#: End points per tile of the exact passes: 6 axes x 16384 doubles (768 KiB) stay in
#: L2; wider tiles cost more, narrower ones hand the GIL over more often (offline, the
#: accumulator runs on a thread beside the checks and the reader).
TILE_COLS = 16384


def phase(win: np.ndarray, x: np.ndarray) -> np.ndarray:
    """
    Compute the running sum of a window, from zero, after removing the window's mean.

    Parameters
    ----------
    win : np.ndarray
        Shape (n_axes, w), samples [unit].
    x : np.ndarray
        Shape (n_axes, w + 1), output: x[:, 0] = 0, x[:, j] = sum of the first j
        centred samples [unit * samples].

    Returns
    -------
    np.ndarray
        Shape (n_axes,), the mean that was removed [unit].

    """
    r = win.mean(axis=1)
    x[:, 0] = 0.0
    np.subtract(win, r[:, None], out=x[:, 1:])
    np.cumsum(x[:, 1:], axis=1, out=x[:, 1:])
    return r


def accumulate(x: np.ndarray, j_first: int, j_last: int, ms: np.ndarray, sums: np.ndarray,
               counts: np.ndarray, row0: int, x2_buf: np.ndarray | None = None,
               tile: np.ndarray | None = None) -> None:
    """
    Add the squared second differences that end at x[:, j_first:j_last + 1].

    Parameters
    ----------
    x : np.ndarray
        Shape (n_axes, w + 1), running sum; index 0 is the oldest point held.
    j_first, j_last : int
        First and last new end points (local indices into x).
    ms : np.ndarray
        Shape (k,), cluster sizes in units of x's samples.
    sums, counts : np.ndarray
        Shapes (K, n_axes) and (K,), updated in place at rows row0 .. row0 + k - 1.
    row0 : int
        Row of ms[0] in sums and counts.
    x2_buf, tile : np.ndarray, optional
        Scratch arrays of the numpy path, shapes (n_axes, >= w + 1) and (n_axes, c)
        with c >= 1 (the end points are taken c at a time).

    """
    j0 = np.maximum(j_first, 2 * ms)
    live = j0 <= j_last
    counts[row0:row0 + ms.size] += np.where(live, j_last - j0 + 1, 0)
    w = x.shape[1]
    x2 = np.multiply(x, 2.0, out=None if x2_buf is None else x2_buf[:, :w])
    if tile is None:
        tile = np.empty((x.shape[0], min(TILE_COLS, max(j_last - j_first + 1, 1))))
    width = tile.shape[1]
    for k in np.flatnonzero(live).tolist():
        m, start = int(ms[k]), int(j0[k])
        total = np.zeros(x.shape[0])
        # d_j = X[j] + X[j - 2m] - 2 X[j - m], a tile of end points at a time: the
        # temporary stays in the core's cache.
        for s in range(start, j_last + 1, width):
            e = min(s + width, j_last + 1)
            d = np.add(x[:, s:e], x[:, s - 2 * m:e - 2 * m], out=tile[:, :e - s])
            np.subtract(d, x2[:, s - m:e - m], out=d)
            # einsum, not np.dot/vecdot: OpenBLAS threads its ddot, which stalls badly on
            # a busy machine; numpy's own loop is as fast single-threaded.
            total += np.einsum('ij,ij->i', d, d)
        sums[row0 + k] += total


def dirty_terms(x: np.ndarray, miss: np.ndarray, j_first: int, ms: np.ndarray,
                totals: np.ndarray, sums: np.ndarray, counts: np.ndarray) -> None:
    """
    Add the squared second differences that hold a missing sample, per cluster size.

    The term ending at x[:, j] spans samples j - 2m .. j - 1 of the window; it is
    dirty when one of them is missing.  Whichever of the dirty and the clean terms
    are fewer is summed (the other part is the window's total less it), so the work
    stays below half a pass per tau.

    Parameters
    ----------
    x : np.ndarray
        Shape (n_axes, w + 1), running sum of the window's samples.
    miss : np.ndarray
        Shape (w,), bool, the window's missing samples.
    j_first : int
        First new end point (local index into x); the last is w.
    ms : np.ndarray
        Shape (k,), cluster sizes [samples].
    totals : np.ndarray
        Shape (k, n_axes), the window's sums over all its new terms per size.
    sums, counts : np.ndarray
        Shapes (k, n_axes) and (k,), updated in place with the dirty terms.

    """
    w = miss.size
    n_miss = np.concatenate(([0], np.cumsum(miss)))
    for k, m in enumerate(ms.tolist()):
        j = np.arange(max(j_first, 2 * m), w + 1)
        if not j.size:
            continue
        dirty = n_miss[j] > n_miss[j - 2 * m]
        n_dirty = int(dirty.sum())
        if not n_dirty:
            continue
        pick = j[dirty] if 2 * n_dirty <= j.size else j[~dirty]
        d = x[:, pick] + x[:, pick - 2 * m] - 2.0 * x[:, pick - m]
        part = np.einsum('ij,ij->i', d, d)
        sums[k] += part if 2 * n_dirty <= j.size else np.maximum(totals[k] - part, 0.0)
        counts[k] += n_dirty
