"""Tests of the streaming Allan accumulator against the batch estimator."""

import json
import os

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from conftest import white_rw_offset
from imu_allan.core.allan import overlapping_avar, tau_grid
from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.errors import InputError


def _strided_sums(y: np.ndarray, m: int, stride: int) -> tuple[np.ndarray, int]:
    """Batch sum of (X[i+2m] - 2 X[i+m] + X[i])^2 over i = 0, stride, 2 stride ..."""
    x = np.zeros((y.shape[0] + 1, y.shape[1]))
    np.cumsum(y - y.mean(axis=0), axis=0, out=x[1:])
    i = np.arange(0, y.shape[0] + 1 - 2 * m, stride)
    d = x[i + 2 * m] - 2.0 * x[i + m] + x[i]
    return (d * d).sum(axis=0), i.size


def _feed_random_blocks(acc: AllanAccumulator, y: np.ndarray, rng, max_block: int) -> None:
    start = 0
    while start < y.shape[0]:
        k = 1 if rng.random() < 0.2 else int(rng.integers(1, max_block))
        acc.add(y[start:start + k])
        start += k


@pytest.fixture(scope='module')
def record():
    """One 6-axis record fed once: (samples, accumulator)."""
    y = white_rw_offset(100_000, 6, seed=1)
    acc = AllanAccumulator(6, 200.0, exact_max_m=256)
    acc.add(y)
    return y, acc


def test_exact_taus_equal_batch(record):
    y, acc = record
    c = acc.curve()
    ex = acc.exact_mask(c.m)
    # The exact taus are the batch 'dense' grid, whatever the record length.
    assert_array_equal(c.m[ex], tau_grid(y.shape[0], 'dense')[:ex.sum()])
    assert c.m[ex].max() <= 256 < c.m[~ex].min()
    avar, n_terms = overlapping_avar(y, c.m[ex])
    assert_allclose(c.avar[ex], avar, rtol=1e-9, atol=0)
    assert_array_equal(c.n_terms[ex], n_terms)
    assert_allclose(c.tau_s, c.m / 200.0, rtol=1e-15)


def test_decimated_taus_are_strided_batch_sums(record):
    # The documented long-tau estimator, term by term: the batch sum at stride D_L.
    y, acc = record
    c = acc.curve()
    strides = {int(m): int(s) for m, s in zip(acc.m, acc._stride)}
    dec = np.flatnonzero(~acc.exact_mask(c.m))
    assert dec.size >= 8
    for k in dec:
        m = int(c.m[k])
        stride = strides[m]
        assert m % stride == 0 and 64 < m // stride <= 128
        sums, count = _strided_sums(y, m, stride)
        assert c.n_terms[k] == count
        assert_allclose(c.avar[k], sums / (2.0 * m * m * count), rtol=1e-9)


def test_curve_fields(record):
    y, acc = record
    c = acc.curve(confidence=0.95)
    k = c.m.size
    assert c.method == 'overlapping' and c.confidence == 0.95 and c.rate_hz == 200.0
    for field in (c.avar, c.edf, c.alpha, c.adev_lo, c.adev_hi):
        assert field.shape == (k, 6)
    assert np.all(c.adev_lo < c.adev) and np.all(c.adev < c.adev_hi)
    assert np.all(np.diff(c.m) > 0)
    # Default min_terms keeps every tau with data: m up to M // 2, as the batch grid.
    assert c.n_terms.min() >= 1 and c.m.max() <= y.shape[0] // 2
    fewer = acc.curve(min_terms=1000)
    assert fewer.n_terms.min() >= 1000 and fewer.m.size < k
    fixed = acc.curve(alpha=0)
    assert np.all(fixed.alpha == 0)
    # White noise rules the short taus, random walk the long ones (crossing near
    # m = 1700); the slope-based alpha must see both (the last taus are noisy).
    assert np.all(c.alpha[c.m <= 100] == 0)
    assert np.all(c.alpha[(c.m >= 2000) & (c.m <= 8000)] <= -1)
    with pytest.raises(InputError):
        acc.curve(alpha=0.5)
    with pytest.raises(InputError):
        acc.curve(confidence=1.5)


def test_block_size_invariance():
    y = white_rw_offset(120_000, 6, seed=2)
    one = AllanAccumulator(6, 100.0, exact_max_m=128)
    one.add(y)
    many = AllanAccumulator(6, 100.0, exact_max_m=128)
    rng = np.random.default_rng(3)
    for row in y[:1500]:
        many.add(row[None, :])
    _feed_random_blocks(many, y[1500:60_000], rng, 5000)
    many.curve()    # a curve mid-stream must not change what follows
    _feed_random_blocks(many, y[60_000:], rng, 40_000)
    a, b = one.curve(), many.curve()
    assert many.n_samples == one.n_samples == y.shape[0]
    assert_array_equal(a.m, b.m)
    assert_array_equal(a.n_terms, b.n_terms)
    assert_allclose(b.avar, a.avar, rtol=1e-12, atol=0)


def test_save_restore_midstream(tmp_path):
    y = white_rw_offset(90_000, 6, seed=4)
    rng = np.random.default_rng(5)
    ref = AllanAccumulator(6, 100.0, exact_max_m=64)
    ref.add(y[:30_000])
    ref.break_segment()
    ref.add(y[30_000:])

    acc = AllanAccumulator(6, 100.0, exact_max_m=64)
    _feed_random_blocks(acc, y[:30_000], rng, 7000)
    acc.break_segment()
    acc.add(y[30_000:51_234])   # leaves samples pending in the buffer
    path = tmp_path / 'state.acc.npz'
    acc.save(path)
    acc.save(path)              # overwriting is fine
    assert os.listdir(tmp_path) == ['state.acc.npz']   # written at that name, no leftovers
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z['meta']))
        assert meta['pending'] > 0
        assert sum(z[k].nbytes for k in z.files if k != 'meta') <= acc.state_nbytes()
    back = AllanAccumulator.load(path)
    assert (back.n_samples, back.n_segments) == (acc.n_samples, acc.n_segments)
    assert_allclose(back.curve().avar, acc.curve().avar, rtol=0, atol=0)
    _feed_random_blocks(back, y[51_234:], rng, 9000)
    a, b = ref.curve(), back.curve()
    assert (b.m.size, back.n_samples, back.n_segments) == (a.m.size, 90_000, 2)
    assert_array_equal(b.n_terms, a.n_terms)
    assert_allclose(b.avar, a.avar, rtol=1e-12, atol=0)


def _saved_arrays(tmp_path) -> dict:
    acc = AllanAccumulator(2, 50.0, exact_max_m=64)
    acc.add(white_rw_offset(3000, 2, seed=6))
    acc.save(tmp_path / 'good.npz')
    with np.load(tmp_path / 'good.npz', allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _with_meta(arrays: dict, **changes) -> dict:
    meta = json.loads(str(arrays['meta']))
    meta.update(changes)
    return {**arrays, 'meta': np.array(json.dumps(meta))}


@pytest.mark.parametrize('damage', [
    'missing', 'truncated', 'garbage', 'no_sums', 'format', 'version', 'shape', 'grid',
    'nan', 'counters', 'pickle', 'meta_not_json'])
def test_corrupt_state_raises_input_error(tmp_path, damage):
    arrays = _saved_arrays(tmp_path)
    path = tmp_path / 'bad.npz'
    good = (tmp_path / 'good.npz').read_bytes()
    if damage == 'truncated':
        path.write_bytes(good[:len(good) // 2])
    elif damage == 'garbage':
        path.write_bytes(np.random.default_rng(0).bytes(4096))
    elif damage == 'pickle':
        np.savez(path, **{**arrays, 'sums': np.array([{'x': 1}], dtype=object)})
    elif damage != 'missing':
        changed = {
            'no_sums': {k: v for k, v in arrays.items() if k != 'sums'},
            'format': _with_meta(arrays, format='something.else'),
            'version': _with_meta(arrays, version=99),
            'shape': {**arrays, 'sums': arrays['sums'][:-1]},
            'grid': {**arrays, 'm': arrays['m'] + 1},
            'nan': {**arrays, 'sums': arrays['sums'] * np.nan},
            'counters': _with_meta(arrays, h0=5),
            'meta_not_json': {**arrays, 'meta': np.array('{not json')},
        }[damage]
        np.savez(path, **changed)
    with pytest.raises(InputError, match='bad.npz'):
        AllanAccumulator.load(path)


def test_break_segment_pools_per_segment_batch_sums():
    lengths = [5000, 37, 20_000, 1, 0, 12_000, 3]
    y = white_rw_offset(sum(lengths), 3, seed=7)
    acc = AllanAccumulator(3, 100.0, exact_max_m=64)
    rng = np.random.default_rng(8)
    segments, start = [], 0
    for n in lengths:
        _feed_random_blocks(acc, y[start:start + n], rng, 3000)
        acc.break_segment()
        acc.break_segment()     # repeated breaks add no empty segment
        segments.append(y[start:start + n])
        start += n
    assert acc.n_segments == 6 and acc.n_samples == y.shape[0]
    c = acc.curve(alpha=0)
    strides = dict(zip(acc.m.tolist(), acc._stride.tolist()))
    for k, m in enumerate(c.m.tolist()):
        parts = [_strided_sums(s, m, strides[m]) for s in segments if s.shape[0] >= 2 * m]
        total = sum(p[0] for p in parts)
        count = sum(p[1] for p in parts)
        assert c.n_terms[k] == count
        assert_allclose(c.avar[k], total / (2.0 * m * m * count), rtol=1e-9)
    # Taus that no segment is long enough for are left out, not reported as 0 or NaN.
    assert c.m.max() <= 20_000 // 2 < acc.m.max()
    assert np.isfinite(c.avar).all() and np.isfinite(c.edf).all()


def test_decimated_taus_agree_with_batch_within_confidence():
    # Long record (white + random walk), taus far beyond exact_max_m: the decimated
    # estimate differs from the full-overlap batch value by a small fraction of its
    # own confidence interval (the two share most of their terms).
    y = white_rw_offset(2 ** 17, 2, seed=9)
    acc = AllanAccumulator(2, 100.0, exact_max_m=64)
    acc.add(y)
    c = acc.curve()
    sel = ~acc.exact_mask(c.m) & (c.m <= y.shape[0] // 8)
    avar, _ = overlapping_avar(y, c.m[sel])
    rel = np.abs(c.avar[sel] / avar - 1.0)
    half_width = (c.adev_hi[sel] ** 2 - c.adev_lo[sel] ** 2) / (2.0 * c.avar[sel])
    assert sel.sum() >= 20
    assert np.all(rel < 0.25 * half_width), (rel / half_width).max()


def test_decimated_spread_matches_stated_edf():
    # White noise of unit variance: AVAR(m) = 1 / m exactly.  Over 6 axes x 12 seeds
    # the scatter of avar * m must match var = 2 / EDF (chi-square with EDF degrees).
    n, scaled = 2 ** 17, []
    for seed in range(12):
        acc = AllanAccumulator(6, 100.0, exact_max_m=64)
        acc.add(np.random.default_rng(100 + seed).standard_normal((n, 6)))
        c = acc.curve(alpha=0)
        sel = ~acc.exact_mask(c.m) & (c.m <= n // 16)
        scaled.append(c.avar[sel] * c.m[sel, None])
        edf = c.edf[sel, 0]
    z = np.concatenate(scaled, axis=1)          # (taus, 72 replicas)
    ratios = z.var(axis=1, ddof=1) * edf / 2.0
    assert z.shape[0] >= 15
    se_mean = np.sqrt(2.0 / edf / z.shape[1])
    assert np.all(np.abs(z.mean(axis=1) - 1.0) < 4.0 * se_mean)     # unbiased
    assert np.all((ratios > 0.5) & (ratios < 1.8)), ratios          # chi2(71) range
    assert 0.85 < ratios.mean() < 1.2, ratios.mean()


def _exact_reference(k: np.ndarray, m_list, scale: float, stride: dict) -> np.ndarray:
    """AVAR from integer samples k * scale, phase exact in int64 (no rounding at all)."""
    x = np.zeros(k.size + 1, dtype=np.int64)
    np.cumsum(k, out=x[1:])
    out = []
    for m in m_list:
        i = np.arange(0, k.size + 1 - 2 * m, stride.get(m, 1))
        d = (x[i + 2 * m] - 2 * x[i + m] + x[i]).astype(np.float64) * scale
        out.append(np.einsum('i,i->', d, d) / (2.0 * m * m * i.size))
    return np.array(out)


def test_large_offset_precision():
    # An accelerometer axis at 9.81 m/s^2 with 1e-4 m/s^2 of noise and a drifting bias,
    # and an adversarial axis whose bias jumps by 0.5 m/s^2 every 20 s.  Samples are
    # multiples of 2^-30 m/s^2, so an int64 running sum is an exact reference; a plain
    # float64 running sum of the raw samples needs 55 bits and does round.
    #
    # Worst case of the accumulator: each chunk window of W = 2 exact_max_m + chunk
    # samples (49152 by default) is summed from zero after removing its own mean, so
    # |X| <= W * D with D the largest deviation of the signal from that mean, and a
    # term's rounding error is about eps * W * D against a second difference of about
    # sigma * sqrt(2 m).  For 24 h at 1 kHz with a drift of even 1e-2 m/s^2 inside
    # one 49 s window that is 1e-16 * 5e4 * 1e-2 / 1.4e-4 = 4e-10 per term at m = 1,
    # and the independent errors of millions of terms average further down.  The
    # record length never enters.  The jumping axis has D = 0.25 (400x worse).
    rate_hz, n, scale = 1000.0, 2_000_000, 2.0 ** -30
    rng = np.random.default_rng(11)
    t = np.arange(n) / rate_hz
    drift = 2e-3 * np.sin(2 * np.pi * t / 900.0) + 5e-6 * t
    jumps = 0.5 * ((np.arange(n) // 20_000) % 2)
    true = 9.81 + 1e-4 * rng.standard_normal((n, 2)) + np.stack([drift, jumps], axis=1)
    k = np.round(true / scale).astype(np.int64)
    y = k * scale                                   # exact in float64
    acc = AllanAccumulator(2, rate_hz, exact_max_m=8192)
    acc.add(y)
    c = acc.curve(alpha=0)
    strides = dict(zip(acc.m.tolist(), acc._stride.tolist()))
    pick = [0, 1, 4, 10, 20, 30, 36, 40, 45]        # exact and decimated taus
    m_list = [int(c.m[j]) for j in pick]
    assert m_list[-1] > acc.exact_max_m >= m_list[-3]
    naive_x = np.concatenate(([0.0], np.cumsum(y[:, 0])))
    naive = np.mean((naive_x[2:] - 2 * naive_x[1:-1] + naive_x[:-2]) ** 2) / 2.0
    for axis in range(2):
        ref = _exact_reference(k[:, axis], m_list, scale, strides)
        assert_allclose(c.avar[pick, axis], ref, rtol=1e-9, atol=0)
    # The case has teeth: the naive float64 phase misses the reference at m = 1.
    assert abs(naive / _exact_reference(k[:, 0], [1], scale, {})[0] - 1.0) > 1e-9


def test_memory_bound_for_24h_at_1khz():
    acc = AllanAccumulator(6, 1000.0)
    nbytes = acc.state_nbytes()
    assert nbytes / 6 <= 1_000_000
    # Every level a 24 h record needs (m up to 86.4e6 / 2) is allocated from the start,
    # so the state cannot grow with the duration ...
    assert acc.m.max() >= 86_400_000 // 2
    # ... and feeding data (many levels active here) does not change its size.
    small = AllanAccumulator(6, 1000.0, exact_max_m=64)
    before = small.state_nbytes()
    y = np.random.default_rng(12).standard_normal((2 ** 19, 6))
    small.add(y)
    small.break_segment()
    small.add(y[:1000])
    assert small.state_nbytes() == before
    assert small.curve().m.max() > 2 ** 17


def test_bad_input():
    acc = AllanAccumulator(6, 100.0)
    with pytest.raises(InputError):
        acc.add(np.zeros((10, 5)))
    with pytest.raises(InputError):
        acc.add(np.zeros(6))
    bad = np.zeros((10, 6))
    bad[3, 2] = np.nan
    with pytest.raises(InputError):
        acc.add(bad)
    assert acc.n_samples == 0 and acc.n_segments == 0
    acc.add(np.zeros((0, 6)))
    assert acc.n_segments == 0 and acc.curve().m.size == 0
    for kwargs in ({'n_axes': 0, 'rate_hz': 1.0}, {'n_axes': 6, 'rate_hz': -1.0},
                   {'n_axes': 6, 'rate_hz': 1.0, 'exact_max_m': 100},
                   {'n_axes': 6, 'rate_hz': 1.0, 'per_decade': 0}):
        with pytest.raises(InputError):
            AllanAccumulator(**kwargs)
