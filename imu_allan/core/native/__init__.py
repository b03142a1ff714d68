"""
The core's compiled kernels (``_native.c``), called through ctypes.

setup.py compiles ``_native.c`` into ``_native<EXT_SUFFIX>`` beside this file whenever
the package is built (``pip install``, ``colcon build``).  Its only Python API is an
empty module init; ctypes loads it like any shared object and releases the GIL for
every call, so threads that call these kernels run in parallel.

Each kernel has a numpy twin in the module that uses it (the accumulator, the batch
curve, the raw copy, the session's sample checks, the CSV reader, the Imu payload
decoder, the sqlite page reader).  :data:`LIB` is None when the library was never
built (a bare source tree) or when the environment sets ``IMU_ALLAN_NATIVE=0``; the
twins then do the work, with the same results to rounding (test/test_native.py
compares them).
"""

import ctypes
import importlib.machinery
import os
from pathlib import Path

import numpy as np

_LONG = ctypes.c_long


def _load() -> ctypes.CDLL | None:
    """Return the compiled library, or None when it is absent or switched off."""
    if os.environ.get('IMU_ALLAN_NATIVE', '1') == '0':
        return None
    here = Path(__file__).resolve().parent
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = here / f'_native{suffix}'
        if path.is_file():
            try:
                lib = ctypes.CDLL(str(path))
            except OSError:
                return None
            lib.imu_allan_acc_sums.restype = None
            lib.imu_allan_acc_sums.argtypes = [
                ctypes.c_void_p, _LONG, _LONG, _LONG, _LONG, ctypes.c_void_p, _LONG,
                ctypes.c_void_p]
            lib.imu_allan_phase.restype = None
            lib.imu_allan_phase.argtypes = [ctypes.c_void_p, _LONG, _LONG, _LONG,
                                            ctypes.c_void_p, _LONG, ctypes.c_void_p]
            lib.imu_allan_diff_sumsq.restype = ctypes.c_double
            lib.imu_allan_diff_sumsq.argtypes = [ctypes.c_void_p, _LONG, _LONG, _LONG]
            lib.imu_allan_parse_csv.restype = _LONG
            lib.imu_allan_parse_csv.argtypes = [ctypes.c_void_p, _LONG, _LONG,
                                                ctypes.c_void_p, _LONG]
            lib.imu_allan_varints.restype = _LONG
            lib.imu_allan_varints.argtypes = [ctypes.c_void_p, _LONG, ctypes.c_void_p, _LONG,
                                              ctypes.c_void_p, ctypes.c_void_p]
            lib.imu_allan_decode_imu.restype = _LONG
            lib.imu_allan_decode_imu.argtypes = [
                ctypes.c_void_p, _LONG, ctypes.c_void_p, ctypes.c_void_p, _LONG, _LONG,
                ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
            lib.imu_allan_block_means.restype = None
            lib.imu_allan_block_means.argtypes = [ctypes.c_void_p, _LONG, _LONG, _LONG, _LONG,
                                                  ctypes.c_void_p]
            lib.imu_allan_motion_scan.restype = _LONG
            lib.imu_allan_motion_scan.argtypes = [
                ctypes.c_void_p, _LONG, _LONG, _LONG, _LONG, ctypes.c_void_p, ctypes.c_double,
                ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
            lib.imu_allan_repeats.restype = None
            lib.imu_allan_repeats.argtypes = [ctypes.c_void_p, _LONG, _LONG, _LONG,
                                              ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
            lib.imu_allan_gm_shape.restype = None
            lib.imu_allan_gm_shape.argtypes = [ctypes.c_void_p, _LONG, ctypes.c_void_p, _LONG,
                                               ctypes.c_void_p]
            lib.imu_allan_gm_stencil.restype = None
            lib.imu_allan_gm_stencil.argtypes = [ctypes.c_void_p, _LONG, _LONG, ctypes.c_void_p,
                                                 ctypes.c_double, ctypes.c_void_p]
            lib.imu_allan_pair_sums.restype = None
            lib.imu_allan_pair_sums.argtypes = [
                ctypes.c_void_p, _LONG, ctypes.c_void_p, ctypes.c_void_p, _LONG,
                ctypes.c_void_p, ctypes.c_void_p, _LONG, ctypes.c_void_p]
            return lib
    return None


#: The loaded library, or None (then every caller uses its numpy twin).
LIB = _load()


def phase(win: np.ndarray, x: np.ndarray) -> np.ndarray:
    """
    Compute the running sums of windows, from zero, after removing each one's mean.

    Parameters
    ----------
    win : np.ndarray
        Shape (n_axes, w), float64 samples [unit], rows contiguous (any row stride).
    x : np.ndarray
        Shape (n_axes, w + 1), float64 output, rows contiguous: x[:, 0] = 0 and
        x[:, j] the sum of the first j centred samples [unit * samples].

    Returns
    -------
    np.ndarray
        Shape (n_axes,), the means removed [unit].

    """
    assert LIB is not None and win.dtype == x.dtype == np.float64
    assert win.strides[1] == x.strides[1] == 8 and x.shape[1] == win.shape[1] + 1
    r = np.empty(win.shape[0])
    LIB.imu_allan_phase(win.ctypes.data, win.strides[0] // 8, win.shape[0], win.shape[1],
                        x.ctypes.data, x.strides[0] // 8, r.ctypes.data)
    return r


def acc_sums(x: np.ndarray, j_first: int, j_last: int, ms: np.ndarray) -> np.ndarray:
    """
    Sum the squared second differences of the phase rows ending at j_first .. j_last.

    Parameters
    ----------
    x : np.ndarray
        Shape (n_axes, w + 1), float64 running sums [unit * samples], rows contiguous
        (any row stride).
    j_first, j_last : int
        First and last end points j (local indices into x's rows).
    ms : np.ndarray
        Shape (k,), int64 cluster sizes [samples]; a size m counts the terms with
        j >= 2 m only.

    Returns
    -------
    np.ndarray
        Shape (k, n_axes), sum over j of (x[a, j] + x[a, j - 2m] - 2 x[a, j - m])^2
        [unit^2 * samples^2] (NIST SP 1065 eq. 14, before normalisation).

    """
    assert LIB is not None and x.dtype == np.float64 and x.strides[1] == 8
    ms = np.ascontiguousarray(ms, dtype=np.int64)
    out = np.zeros((ms.size, x.shape[0]))
    LIB.imu_allan_acc_sums(x.ctypes.data, x.strides[0] // 8, x.shape[0], j_first, j_last,
                           ms.ctypes.data, ms.size, out.ctypes.data)
    return out


def diff_sumsq(x: np.ndarray, m: int, order: int) -> float:
    """
    Sum the squared order-th lag-m differences of a phase row (order 2 or 3).

    Parameters
    ----------
    x : np.ndarray
        Shape (n,), contiguous float64 running sum [unit * samples].
    m : int
        Lag (cluster size) [samples].
    order : int
        2 (overlapping Allan, NIST SP 1065 eq. 14) or 3 (Hadamard, eq. 20).

    Returns
    -------
    float
        The sum over the n - order m differences [unit^2 * samples^2]; NaN when there
        are none.

    """
    assert LIB is not None and x.dtype == np.float64 and x.flags.c_contiguous
    return float(LIB.imu_allan_diff_sumsq(x.ctypes.data, x.size, int(m), int(order)))


def parse_csv(data: bytes | memoryview, n_cols: int) -> np.ndarray | None:
    """
    Parse comma-separated decimal numbers, ``n_cols`` per data row.

    Blank lines and ``#`` comments are skipped; values are correctly rounded (as
    Python's float() gives them).

    Parameters
    ----------
    data : bytes or memoryview
        The text after any header (read in place, not copied).
    n_cols : int
        Fields per row.

    Returns
    -------
    np.ndarray or None
        Shape (rows, n_cols) float64, or None when a row has another field count or a
        field is anything but a plain decimal number (nan, inf, text, empty): the caller
        then parses with numpy, which accepts or names the bad row.

    """
    assert LIB is not None
    # Every row takes at least two bytes per field; pages never written cost nothing.
    text = np.frombuffer(data, dtype=np.uint8)
    capacity = text.size // (2 * n_cols) + 1
    table = np.empty((capacity, n_cols))
    rows = LIB.imu_allan_parse_csv(text.ctypes.data, text.size, n_cols, table.ctypes.data,
                                   capacity)
    if rows < 0:
        return None
    return table[:rows]


def decode_imu(u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray, ros1: bool,
               stamp_ns: np.ndarray, samples: np.ndarray, ok: np.ndarray) -> None:
    """
    Decode the serialised sensor_msgs/Imu payloads of one byte buffer that fit the plain layout.

    The twin of :func:`imu_allan.io.imu_cdr._decode_plain` (same arguments, same
    layout rules): rows that do not fit are left as they are.

    Parameters
    ----------
    u8 : np.ndarray
        Shape (size,), uint8 buffer (any read-only or writable memory).
    starts, lengths : np.ndarray
        Shape (n,), int64 offset and length of each payload [bytes].
    ros1 : bool
        ROS 1 serialisation instead of ROS 2 CDR.
    stamp_ns : np.ndarray
        Shape (n,), contiguous int64 output: header.stamp [ns].
    samples : np.ndarray
        Shape (n, 6), contiguous float64 output: angular_velocity [rad/s] and
        linear_acceleration [m/s^2].
    ok : np.ndarray
        Shape (n,), contiguous bool output: True where the payload was decoded.

    """
    assert LIB is not None and stamp_ns.dtype == np.int64 and samples.dtype == np.float64
    assert ok.dtype == bool and all(a.flags.c_contiguous for a in (stamp_ns, samples, ok))
    u8 = np.ascontiguousarray(u8, dtype=np.uint8)
    starts = np.ascontiguousarray(starts, dtype=np.int64)
    lengths = np.ascontiguousarray(lengths, dtype=np.int64)
    LIB.imu_allan_decode_imu(u8.ctypes.data, u8.size, starts.ctypes.data, lengths.ctypes.data,
                             starts.size, int(ros1), stamp_ns.ctypes.data, samples.ctypes.data,
                             ok.ctypes.data)


def varints(u8: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Decode one sqlite varint at each offset of a byte buffer.

    Parameters
    ----------
    u8 : np.ndarray
        Shape (size,), contiguous uint8 buffer (e.g. a memory-mapped database file).
    pos : np.ndarray
        Shape (n,), int64 byte offsets.

    Returns
    -------
    value, length : np.ndarray
        Shape (n,) int64 each: the values and the bytes each one used.

    Raises
    ------
    IndexError
        When a varint runs past the end of the buffer (as its numpy twin,
        ``imu_allan.io.bags.rosbag2_sqlite._varint``, does).

    """
    assert LIB is not None and u8.dtype == np.uint8 and u8.flags.c_contiguous
    pos = np.ascontiguousarray(pos, dtype=np.int64)
    value = np.empty(pos.size, np.int64)
    length = np.empty(pos.size, np.int64)
    if LIB.imu_allan_varints(u8.ctypes.data, u8.size, pos.ctypes.data, pos.size,
                             value.ctypes.data, length.ctypes.data):
        raise IndexError('a varint runs past the end of the file')
    return value, length


def _rows(y: np.ndarray) -> np.ndarray:
    """Return y (n, k) float64 with contiguous rows (a view when it has them)."""
    y = np.asarray(y, dtype=np.float64)
    return y if y.strides[1] == 8 else np.ascontiguousarray(y)


def block_means(y: np.ndarray, factor: int) -> np.ndarray:
    """
    Average each ``factor`` consecutive rows (factor >= 2), bit for bit as the twin.

    The twin is :func:`imu_allan.core.allan.raw._means`.

    Parameters
    ----------
    y : np.ndarray
        Shape (n, n_cols), float64 samples [unit], n a multiple of ``factor``.
    factor : int
        Rows per mean.

    Returns
    -------
    np.ndarray
        Shape (n // factor, n_cols), the means [unit].

    """
    assert LIB is not None and factor >= 2
    y = _rows(y)
    out = np.empty((y.shape[0] // factor, y.shape[1]))
    LIB.imu_allan_block_means(y.ctypes.data, y.strides[0] // 8, out.shape[0], y.shape[1],
                              factor, out.ctypes.data)
    return out


def motion_scan(y: np.ndarray, win: int, thr: np.ndarray, ratio_limit: float,
                ref_mean: np.ndarray, ref_std: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """
    Find the first window that moved; pull the reference along the still ones before it.

    The twin is :func:`imu_allan.pipeline.motion._still_run` (same arguments, same rule).

    Parameters
    ----------
    y : np.ndarray
        Shape (n_windows * win, n_axes), float64 samples [unit].
    win : int
        Rows per window.
    thr : np.ndarray
        Shape (n_axes,), largest still offset of a window mean from the reference [unit].
    ratio_limit : float
        Largest still ratio of a window's std to the reference std.
    ref_mean : np.ndarray
        Shape (n_axes,), contiguous float64 reference means [unit], updated in place.
    ref_std : np.ndarray
        Shape (n_axes,), reference standard deviations [unit].

    Returns
    -------
    still : int
        Windows before the first that moved (n_windows when none did).
    mean, std : np.ndarray
        Shape (n_axes,) each: that window's mean and std [unit] (meaningless when
        still == n_windows).

    """
    assert LIB is not None and ref_mean.dtype == np.float64 and ref_mean.flags.c_contiguous
    y = _rows(y)
    thr = np.ascontiguousarray(thr, dtype=np.float64)
    ref_std = np.ascontiguousarray(ref_std, dtype=np.float64)
    # The kernel reads n_axes values of each: a shorter array would be read past its end.
    assert ref_mean.shape == ref_std.shape == thr.shape == (y.shape[1],)
    mean, std = np.empty(y.shape[1]), np.empty(y.shape[1])
    still = LIB.imu_allan_motion_scan(y.ctypes.data, y.strides[0] // 8, y.shape[0] // win, win,
                                      y.shape[1], thr.ctypes.data, float(ratio_limit),
                                      ref_mean.ctypes.data, ref_std.ctypes.data, mean.ctypes.data,
                                      std.ctypes.data)
    assert still >= 0, 'more axes than the kernel holds'
    return int(still), mean, std


def repeats(y: np.ndarray, last: np.ndarray, run: np.ndarray) -> np.ndarray:
    """
    Continue each axis' run of repeated values over a block; return the longest runs.

    The twin is :func:`imu_allan.pipeline.checks._repeat_runs`.

    Parameters
    ----------
    y : np.ndarray
        Shape (n, n_axes), float64 samples [unit].
    last : np.ndarray
        Shape (n_axes,), the sample before row 0 [unit] (NaN: none).
    run : np.ndarray
        Shape (n_axes,), contiguous int64: the run going on before row 0 [samples];
        updated in place to the run that ends the block.

    Returns
    -------
    np.ndarray
        Shape (n_axes,), int64 longest run per axis, ``run`` on entry included [samples].

    """
    assert LIB is not None and run.dtype == np.int64 and run.flags.c_contiguous
    y = _rows(y)
    last = np.ascontiguousarray(last, dtype=np.float64)
    assert last.shape == run.shape == (y.shape[1],)
    longest = np.empty(y.shape[1], np.int64)
    LIB.imu_allan_repeats(y.ctypes.data, y.strides[0] // 8, y.shape[0], y.shape[1],
                          last.ctypes.data, run.ctypes.data, longest.ctypes.data)
    return longest


def gm_shape(x: np.ndarray, series: np.ndarray) -> np.ndarray:
    """
    Evaluate the Gauss-Markov Allan variance shape h(x) / x^2 at x = tau / T.

    The twin of :func:`imu_allan.core.noise.model._gm_shape` (same branches and constants).

    Parameters
    ----------
    x : np.ndarray
        Any shape, float64 tau / T.
    series : np.ndarray
        Shape (n_c,), contiguous float64 Taylor coefficients of h(x) / x^3, highest
        power first.

    Returns
    -------
    np.ndarray
        Same shape as x, h(x) / x^2.

    """
    assert LIB is not None and x.dtype == series.dtype == np.float64
    out = np.empty(x.shape)      # 0-d for a 0-d x (ascontiguousarray would make it 1-d)
    xc = x if x.flags.c_contiguous else np.ascontiguousarray(x)
    LIB.imu_allan_gm_shape(xc.ctypes.data, x.size, series.ctypes.data, series.size,
                           out.ctypes.data)
    return out


def gm_stencil(lags: np.ndarray, weights: np.ndarray, T: float) -> np.ndarray:
    """
    Sum the weighted Gauss-Markov generalised covariances of stencil lags, per node.

    The twin of ``weights @ _gcov_gauss_markov(lags, T)``
    (:mod:`imu_allan.core.noise.model`).

    Parameters
    ----------
    lags : np.ndarray
        Shape (n_s, n), C-contiguous float64 lags [s].
    weights : np.ndarray
        Shape (n_s,), float64 stencil weights.
    T : float
        Correlation time [s].

    Returns
    -------
    np.ndarray
        Shape (n,), sum over s of weights[s] g(lags[s]) [s^3 per unit coefficient].

    """
    assert LIB is not None and lags.dtype == np.float64 and lags.flags.c_contiguous
    w = np.ascontiguousarray(weights, dtype=np.float64)
    assert lags.ndim == 2 and w.shape == (lags.shape[0],)
    out = np.empty(lags.shape[1])
    LIB.imu_allan_gm_stencil(lags.ctypes.data, lags.shape[1], lags.shape[0], w.ctypes.data,
                             float(T), out.ctypes.data)
    return out


def pair_sums(g: np.ndarray, weight: np.ndarray, starts: np.ndarray, a_idx: np.ndarray,
              b_idx: np.ndarray) -> np.ndarray:
    """
    Sum weight * g[a] * g[b] over each segment of nodes, for every pair (a, b).

    The twin of ``np.add.reduceat(weight * g[a_idx] * g[b_idx], starts, axis=1)``.

    Parameters
    ----------
    g : np.ndarray
        Shape (n_g, n), C-contiguous float64 values at the nodes.
    weight : np.ndarray
        Shape (n,), contiguous float64 node weights.
    starts : np.ndarray
        Shape (n_seg,), int64 first node of each segment (increasing, each segment
        non-empty, the last one running to n).
    a_idx, b_idx : np.ndarray
        Shape (n_ab,), int64 rows of g paired.

    Returns
    -------
    np.ndarray
        Shape (n_ab, n_seg), the sums.

    """
    assert LIB is not None and g.dtype == weight.dtype == np.float64
    assert g.flags.c_contiguous and weight.flags.c_contiguous and weight.shape == g.shape[1:]
    starts = np.ascontiguousarray(starts, dtype=np.int64)
    a_idx = np.ascontiguousarray(a_idx, dtype=np.int64)
    b_idx = np.ascontiguousarray(b_idx, dtype=np.int64)
    assert a_idx.shape == b_idx.shape
    out = np.empty((a_idx.size, starts.size))
    LIB.imu_allan_pair_sums(g.ctypes.data, g.shape[1], weight.ctypes.data, starts.ctypes.data,
                            starts.size, a_idx.ctypes.data, b_idx.ctypes.data, a_idx.size,
                            out.ctypes.data)
    return out
