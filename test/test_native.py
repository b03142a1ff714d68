"""
The compiled kernels (imu_allan/core/native/_native.c) against their numpy twins.

``make venv`` builds the library (pip install -e), so it must be there; every kernel
must agree with the numpy code that runs when it is absent.
"""

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from imu_allan.core import native
from imu_allan.core.allan import allan_curve, sums
from imu_allan.core.allan.accumulator import _accumulate, AllanAccumulator


@pytest.fixture
def numpy_only(monkeypatch):
    """Run the numpy twins: the library switched off for this test."""
    monkeypatch.setattr(native, 'LIB', None)


def test_the_library_is_built():
    assert native.LIB is not None, 'imu_allan/core/native/_native.c not built: run make venv'


def test_accumulator_sums_equal_the_numpy_twin(monkeypatch):
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(size=(6, 20_001)), axis=1)
    ms = np.array([1, 2, 7, 100, 4096, 8191, 12_000], dtype=np.int64)  # the last: no term
    got = {}
    for lib in (native.LIB, None):
        monkeypatch.setattr(native, 'LIB', lib)
        sums, counts = np.zeros((ms.size + 2, 6)), np.zeros(ms.size + 2, dtype=np.int64)
        _accumulate(x, 5_000, 20_000, ms, sums, counts, 2)
        got[lib is None] = (sums, counts)
    # Different summation order only: 8 partial sums per block against numpy's pairwise.
    assert_allclose(got[False][0], got[True][0], rtol=1e-13, atol=0)
    assert_array_equal(got[False][1], got[True][1])
    assert not got[False][0][:2].any() and not got[False][0][-1].any()


@pytest.mark.parametrize('order', [2, 3])
@pytest.mark.parametrize('m', [1, 3, 1000, 8192, 8193, 50_000])
def test_batch_sums_equal_the_numpy_twin(monkeypatch, order, m):
    rng = np.random.default_rng(m)
    x = np.cumsum(rng.normal(size=200_003))
    fast = sums._diff_sumsq(x, m, order)
    monkeypatch.setattr(native, 'LIB', None)
    assert_allclose(fast, sums._diff_sumsq(x, m, order), rtol=1e-12)


def test_batch_sums_without_terms_are_nan():
    assert np.isnan(native.diff_sumsq(np.zeros(10), 5, 2))


def test_streaming_and_batch_curves_match_with_either_kernel(monkeypatch):
    rng = np.random.default_rng(7)
    y = rng.normal(size=(300_000, 6)) * 1e-3 + np.array([0, 0, 0, 0, 0, 9.81])
    curves = {}
    for lib in (native.LIB, None):
        monkeypatch.setattr(native, 'LIB', lib)
        acc = AllanAccumulator(6, 100.0)
        for s in range(0, y.shape[0], 7_777):
            acc.add(y[s:s + 7_777])
        curves[lib is None] = (acc.curve(), allan_curve(y, 100.0, taus='dense'))
    for k in (0, 1):
        assert_allclose(curves[False][k].avar, curves[True][k].avar, rtol=1e-12)
    stream, batch = curves[False]
    exact = stream.m <= 8192
    common = np.isin(batch.m, stream.m[exact])
    assert_allclose(stream.avar[exact][np.isin(stream.m[exact], batch.m)], batch.avar[common],
                    rtol=1e-10)


def _as_text(rows) -> bytes:
    return ''.join(','.join(r) + '\n' for r in rows).encode()


def test_parse_csv_gives_the_values_python_gives():
    rng = np.random.default_rng(11)
    values = np.concatenate([rng.normal(size=2000) * 10.0 ** rng.integers(-30, 30, 2000),
                             rng.integers(-10**6, 10**6, 200), [0.0, -0.0, 1e-320, 5e300]])
    formats = ['%.9e', '%.17g', '%g', '%.3f', '%r', '%.25e']
    for fmt in formats:
        texts = [fmt % v if fmt != '%r' else repr(float(v)) for v in values]
        table = native.parse_csv(_as_text([[t] for t in texts]), 1)
        assert table is not None, fmt
        expected = np.array([float(t) for t in texts])
        assert_array_equal(table[:, 0], expected, err_msg=fmt)


def test_parse_csv_layout():
    text = (b'# comment\n'
            b' +1.5 , .25,-7.\r\n'
            b'\n'
            b'   \n'
            b'1e3,2E-2,  3 # trailing comment\n'
            b'0,-0.0,00012')      # no final newline
    table = native.parse_csv(text, 3)
    assert_array_equal(table, [[1.5, 0.25, -7.0], [1000.0, 0.02, 3.0], [0.0, -0.0, 12.0]])
    assert native.parse_csv(b'', 2).shape == (0, 2)


@pytest.mark.parametrize('text', [b'1,2\n3\n', b'1,2\n3,4,5\n', b'nan,1\n', b'inf,1\n',
                                  b'1e,2\n', b'0x10,1\n', b'1_000,1\n', b',1\n', b'abc,1\n',
                                  b'1 2,3\n', b'"1",2\n', b'1.2.3,4\n', b'--1,2\n'])
def test_parse_csv_hands_anything_else_to_numpy(text):
    assert native.parse_csv(text, 2) is None


def test_csv_reader_is_the_same_without_the_library(tmp_path, numpy_only):
    from imu_allan.io.csv_io import read_csv
    path = tmp_path / 'x.csv'
    path.write_text('t,a\n0.0,1.25\n0.01,2.5e-3\n')
    data = read_csv(path)
    assert_array_equal(data.samples[:, 0], [1.25, 2.5e-3])


def test_sqlite_varints_equal_the_numpy_twin(monkeypatch):
    from imu_allan.io.bags.rosbag2_sqlite import _varint
    rng = np.random.default_rng(5)
    values = np.concatenate([rng.integers(0, 2**63 - 1, 300, dtype=np.int64),
                             rng.integers(0, 300, 300), [0, 127, 128, 2**56 - 1, 2**56]])
    chunks = []
    for v in values.tolist():   # sqlite's encoding: 7 bits a byte, the 9th byte all 8
        if v >= 1 << 56:
            groups = [(v >> (8 + 7 * k)) & 0x7F for k in range(7, -1, -1)]
            chunks.append(bytes([g | 0x80 for g in groups]) + bytes([v & 0xFF]))
        else:
            groups = [(v >> (7 * k)) & 0x7F for k in range(max(1, -(-v.bit_length() // 7)))]
            groups = groups[::-1]
            chunks.append(bytes([g | 0x80 for g in groups[:-1]] + [groups[-1]]))
    u8 = np.frombuffer(b''.join(chunks), np.uint8)
    pos = np.cumsum([0] + [len(c) for c in chunks[:-1]])
    got = native.varints(u8, pos)
    assert_array_equal(got[0], values)
    monkeypatch.setattr(native, 'LIB', None)
    want = _varint(u8, pos)
    assert_array_equal(got[0], want[0])
    assert_array_equal(got[1], want[1])
    with pytest.raises(IndexError):
        _varint(u8[:-1], pos)
    monkeypatch.undo()
    with pytest.raises(IndexError):
        _varint(np.ascontiguousarray(u8[:-1]), pos)


@pytest.mark.parametrize('factor', [2, 8, 64])
def test_block_means_are_bitwise_the_numpy_twin(monkeypatch, factor):
    from imu_allan.core.allan.raw import _means
    rng = np.random.default_rng(factor)
    y = rng.normal(size=(factor * 1_001, 6)) * 1e-2 + 9.81
    fast = _means(y, factor)
    monkeypatch.setattr(native, 'LIB', None)
    assert_array_equal(fast, _means(y, factor))   # same additions in the same order


def _motion_case(seed: int, moved_window: int | None) -> tuple:
    """Still windows of 40 rows (a slow drift), one of them shaken when asked."""
    rng = np.random.default_rng(seed)
    win, n_windows = 40, 500
    y = rng.normal(size=(win * n_windows, 6)) * 1e-3
    y += np.linspace(0.0, 2e-3, y.shape[0])[:, None]      # bias drift, not motion
    if moved_window is not None:
        y[moved_window * win + 10:moved_window * win + 20, 1] += 0.5
    thr = np.array([0.05] * 3 + [0.3] * 3)
    return y, win, thr, np.zeros(6), np.full(6, 1e-3)


@pytest.mark.parametrize('moved_window', [None, 0, 1, 377, 499])
def test_motion_scan_equals_the_numpy_twin(monkeypatch, moved_window):
    from imu_allan.pipeline.motion import _still_run
    y, win, thr, ref0, ref_std = _motion_case(11, moved_window)
    ref_fast, ref_slow = ref0.copy(), ref0.copy()
    still, mean, std = native.motion_scan(y, win, thr, 3.0, ref_fast, ref_std)
    still_np, mean_np, std_np = _still_run(y, win, thr, 3.0, ref_slow, ref_std)
    assert still == still_np == (500 if moved_window is None else moved_window)
    # The window statistics differ in summation order only.
    assert_allclose(ref_fast, ref_slow, rtol=1e-12, atol=1e-18)
    if moved_window is not None:
        assert_allclose(mean, mean_np, rtol=1e-12, atol=1e-15)
        assert_allclose(std, std_np, rtol=1e-9)
        assert std[1] > 3.0 * 1e-3


def test_repeat_runs_equal_the_numpy_twin(monkeypatch):
    from imu_allan.pipeline.checks import _repeat_runs
    rng = np.random.default_rng(5)
    y = np.round(rng.normal(size=(5_000, 6)), 1)     # coarse values: short runs
    y[:300, 0] = 0.7                                 # continues the run from before
    y[1_000:1_900, 2] = -0.2
    y[:, 5] = 1.5                                    # frozen all along
    last = np.array([0.7, np.nan, 0.0, 0.0, 0.0, 1.5])
    got = {}
    for lib in (native.LIB, None):
        monkeypatch.setattr(native, 'LIB', lib)
        run = np.array([50, 0, 3, 0, 0, 10_000], dtype=np.int64)
        longest = _repeat_runs(y, last, run)
        got[lib is None] = (longest, run)
    assert_array_equal(got[False][0], got[True][0])
    assert_array_equal(got[False][1], got[True][1])
    assert got[False][0][0] >= 350 and got[False][0][2] >= 899
    assert got[False][0][5] == got[False][1][5] == 15_000


def test_gauss_markov_stencil_sums_equal_the_numpy_twin():
    # Lags across the three branches of e^-x - 1 + x (series, expm1, exp), both signs.
    from imu_allan.core.fit.covariance import _STENCIL_WEIGHTS
    from imu_allan.core.noise.shapes import gcov_gauss_markov
    rng = np.random.default_rng(8)
    t_s = 40.0
    lags = t_s * np.geomspace(1e-6, 60.0, 9 * 3000) * rng.choice([-1.0, 1.0], 9 * 3000)
    lags = rng.permutation(lags).reshape(9, -1)
    got = native.gm_stencil(lags, _STENCIL_WEIGHTS, t_s)
    want = _STENCIL_WEIGHTS @ gcov_gauss_markov(lags, t_s)
    # Same terms; summation order and exp against expm1 (x >= 0.5) round differently.
    assert_allclose(got, want, rtol=0, atol=1e-15 * np.abs(want).max())


def test_pair_sums_equal_the_numpy_twin():
    rng = np.random.default_rng(9)
    g = rng.normal(size=(3, 5000))
    weight = rng.uniform(0.0, 2.0, 5000)
    starts = np.array([0, 1, 9, 10, 777, 4000, 4999], dtype=np.int64)
    a_idx, b_idx = np.triu_indices(3)
    got = native.pair_sums(g, weight, starts, a_idx, b_idx)
    want = np.add.reduceat((g * weight)[a_idx] * g[b_idx], starts, axis=1)
    assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())


def test_fit_is_the_same_without_the_library(monkeypatch):
    # The covariance quadrature's two kernels against their numpy twins, through a fit.
    from imu_allan.core.fit import covariance, fit_axis
    from imu_allan.core.noise.shapes import avar_gauss_markov, avar_random_walk, avar_white
    tau = np.unique(np.round(np.geomspace(1, 200_000, 30))) / 100.0
    avar = (avar_white(tau, 1e-3) + avar_gauss_markov(tau, 2e-5, 50.0)
            + avar_random_walk(tau, 1e-6))
    n_samples = 3_600_000
    edf = np.maximum(n_samples * 0.01 / tau, 2.0)
    fits = {}
    for lib in (native.LIB, None):
        monkeypatch.setattr(native, 'LIB', lib)
        monkeypatch.setattr(covariance, '_COV_CACHE', {})     # no nodes or sums shared
        fits[lib is None] = fit_axis(tau, avar, edf, rate_hz=100.0, n_samples=n_samples)
    for sym, p in fits[False].optimised.items():
        q = fits[True].optimised[sym]
        assert_allclose([p.value, *p.ci95], [q.value, *q.ci95], rtol=1e-6, err_msg=sym)


def test_gauss_markov_shape_equals_the_numpy_twin(monkeypatch):
    from imu_allan.core.noise.shapes import _gm_shape
    x = np.concatenate([np.geomspace(1e-9, 0.0499, 400), np.geomspace(0.05, 1e4, 400)])
    got = _gm_shape(x.reshape(20, 40)).ravel()
    assert _gm_shape(np.float64(0.3)).shape == () and _gm_shape(np.float64(3.0)).shape == ()
    monkeypatch.setattr(native, 'LIB', None)
    want = _gm_shape(x)
    small = x < 0.05
    assert_array_equal(got[small], want[small])     # the series: the same operations
    # exp of libm against numpy's (an ulp apart) in a bracket that cancels to x^3 / 3
    # near x = 0.05 (5e-12 relative there, whichever exp).
    assert_allclose(got[~small], want[~small], rtol=1e-11, atol=0)
