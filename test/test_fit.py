"""
Tests of imu_allan.core.fit: covariance model, exact recovery, round trips, coverage, bounds.

Records are short (minutes to an hour at 10-20 Hz) so the file stays fast; the 3-hour,
50-seed validation is bench/validate_fit.py.
"""

import json
import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan.core.allan import allan_curve, overlapping_avar
from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.core.fit import fit_axis, fit_curve, nominal_fit
from imu_allan.core.fit.covariance import CurveCovariance
from imu_allan.core.noise.model import avar_model
from imu_allan.core.noise.simulate import simulate_axis, simulate_imu
from imu_allan.core.noise.terms import TERMS
from imu_allan.core.noise.values import AxisNoise, FLICKER_FLOOR, GaussMarkov, NoiseSpec, Sinusoid
from imu_allan.errors import InputError
from imu_allan.io.csv_io import read_csv

PAPER = AxisNoise(N=1e-3, B=4e-4, T_B=8.0, K=3e-5)   # the paper's model, visible in 1 h


def _curve(noise, rate_hz, n, seed, taus='octave'):
    y = simulate_axis(noise, rate_hz, n, np.random.default_rng(seed))
    c = allan_curve(y, rate_hz, taus)
    return c.tau_s, c.avar[:, 0], c.edf[:, 0]


def _covers(p, truth):
    return p.ci95[0] <= truth <= p.ci95[1]


def test_covariance_model_matches_monte_carlo():
    # Sigma of the overlapping estimates (white + Gauss-Markov + random walk +
    # quantization) against the spread of 300 simulated records.
    rate, n, reps = 10.0, 8192, 300
    noise = AxisNoise(N=1e-3, B=3e-4, T_B=2.0, K=2e-5, Q=5e-5)
    m = 2 ** np.arange(12)
    cov = CurveCovariance(m, n + 1 - 2 * m, 1.0 / rate, n)
    terms = [TERMS['white'], TERMS['bias_instability'], TERMS['random_walk'],
             TERMS['quantization']]
    coef = np.array([noise.N ** 2, GaussMarkov(noise.B, noise.T_B).psd, noise.K ** 2,
                     noise.Q ** 2])
    sigma = cov.sigma(terms, coef, [(), (noise.T_B,), (), ()])
    rng = np.random.default_rng(11)
    sims = np.array([overlapping_avar(simulate_axis(noise, rate, n, rng), m)[0]
                     for _ in range(reps)])
    emp = np.cov(sims.T)
    sd_ratio = np.sqrt(np.diag(emp) / np.diag(sigma))
    # A sample variance from 300 replicas of a chi-square-like quantity: ~10 % (2 se).
    assert np.all(np.abs(sd_ratio - 1.0) < 0.16), sd_ratio
    d, de = np.sqrt(np.diag(sigma)), np.sqrt(np.diag(emp))
    rho = np.diag(sigma, 1) / (d[:-1] * d[1:])
    rho_emp = np.diag(emp, 1) / (de[:-1] * de[1:])
    assert np.all(np.abs(rho - rho_emp) < 0.16), (rho, rho_emp)
    assert np.all((rho > 0.3) & (rho < 0.8))   # neighbours are far from independent


def _exact_case(noise, terms, rate_hz=20.0, n=72000):
    m = 2 ** np.arange(int(math.log2(n // 2)) + 1)
    tau = m / rate_hz
    edf = 1.5 * (n + 1 - 2 * m) / m
    return fit_axis(tau, avar_model(tau, noise), edf, rate_hz, n, terms=terms)


@pytest.mark.parametrize('noise, terms, expect', [
    (PAPER, None, {'N': 1e-3, 'B': 4e-4, 'T_B': 8.0, 'K': 3e-5}),
    (AxisNoise(Q=3e-4, N=1e-3, K=3e-5), None, {'Q': 3e-4, 'N': 1e-3, 'K': 3e-5}),
    (AxisNoise(N=1e-3, B=4e-4, K=3e-5), ('white', 'flicker', 'random_walk'),
     {'N': 1e-3, 'B': 4e-4, 'K': 3e-5}),
    (AxisNoise(N=1e-3, B=4e-4, T_B=8.0, gauss_markov=(GaussMarkov(5e-4, 120.0),)),
     ('white', 'bias_instability', 'gauss_markov'),
     {'N': 1e-3, 'B': 4e-4, 'T_B': 8.0, 'gauss_markov.B': 5e-4, 'gauss_markov.T': 120.0}),
    (AxisNoise(N=1e-3, sinusoids=(Sinusoid(4e-4, 0.02),)), ('white', 'sinusoid'),
     {'N': 1e-3, 'sinusoid.A': 4e-4, 'sinusoid.f0_hz': 0.02}),
    (AxisNoise(N=1e-3, K=3e-5, R=1e-6), ('white', 'random_walk', 'rate_ramp'),
     {'N': 1e-3, 'K': 3e-5, 'R': 1e-6}),
])
def test_noise_free_curve_is_recovered(noise, terms, expect):
    fit = _exact_case(noise, terms)
    for sym, value in expect.items():
        p = fit.optimised[sym]
        if sym == 'K' and p.kind == 'upper_bound':
            # Exact, but its interval reaches 0 (the EDF of 1 h do not show it beside
            # the other terms): reported as the bound at the interval's upper end.
            assert value <= p.value == p.ci95[1] and p.ci95[0] == 0.0, p
            continue
        assert p.kind == 'estimate', (sym, p)
        assert_allclose(p.value, value, rtol=2e-3, err_msg=sym)
        assert p.ci95[0] < value < p.ci95[1]
    assert fit.chi2 < 1e-3


def test_round_trip_paper_model_and_json():
    tau, avar, edf = _curve(PAPER, 20.0, 72000, seed=0)
    fit = fit_axis(tau, avar, edf, 20.0, 72000, unit='rad/s')
    assert {'white', 'bias_instability', 'random_walk'} <= set(fit.terms)
    for sym in ('N', 'B', 'T_B', 'K'):
        assert _covers(fit.optimised[sym], getattr(PAPER, sym)), (sym, fit.optimised[sym])
    assert fit.optimised['N'].unit == 'rad/s*s^0.5'
    assert fit.optimised['K'].unit == 'rad/s/s^0.5'
    assert fit.optimised['T_B'].unit == 's'
    doc = fit.to_json()
    assert set(doc) >= {'params', 'nominal', 'terms', 'notes'}
    assert set(doc['params']) >= {'N', 'B', 'T_B', 'K'}
    assert len(doc['params']['N']['ci95']) == 2
    json.dumps(doc, allow_nan=False)
    # The optimised model is the fitted curve, close to the data.
    assert_allclose(avar_model(fit.tau_s, fit.model), fit.avar_fit, rtol=1e-9)


@pytest.mark.parametrize('noise, terms, syms', [
    (AxisNoise(Q=2e-4, N=1e-3), ('quantization', 'white'), ('Q', 'N')),
    (AxisNoise(N=1e-3, B=4e-4), ('white', 'flicker'), ('N', 'B')),
    (AxisNoise(N=1e-3, sinusoids=(Sinusoid(6e-4, 0.05),)), ('white', 'sinusoid'),
     ('N', 'sinusoid.A', 'sinusoid.f0_hz')),
    (AxisNoise(N=1e-3, B=4e-4, T_B=5.0, gauss_markov=(GaussMarkov(6e-4, 100.0),)),
     ('white', 'bias_instability', 'gauss_markov_2'),
     ('N', 'B', 'T_B', 'gauss_markov_2.B', 'gauss_markov_2.T')),
])
def test_round_trip_other_terms(noise, terms, syms):
    tau, avar, edf = _curve(noise, 20.0, 72000, seed=2)
    fit = fit_axis(tau, avar, edf, 20.0, 72000, terms=terms)
    truth = {'Q': noise.Q, 'N': noise.N, 'B': noise.B, 'T_B': noise.T_B,
             'sinusoid.A': noise.sinusoids[0].A if noise.sinusoids else 0,
             'sinusoid.f0_hz': noise.sinusoids[0].f0_hz if noise.sinusoids else 0,
             'gauss_markov_2.B': noise.gauss_markov[0].B if noise.gauss_markov else 0,
             'gauss_markov_2.T': noise.gauss_markov[0].T if noise.gauss_markov else 0}
    for sym in syms:
        assert fit.optimised[sym].kind == 'estimate', (sym, fit.optimised[sym])
        assert _covers(fit.optimised[sym], truth[sym]), (sym, fit.optimised[sym])


def test_interval_coverage_on_a_small_seed_set():
    # 10 half-hour records x 4 parameters: honest 95 % intervals cover about 95 % of the
    # time (at least 85 % pooled, no parameter below 7/10); the 50-seed, 3-hour version
    # is bench/validate_fit.py.
    hits = dict.fromkeys(('N', 'B', 'T_B', 'K'), 0)
    seeds = range(100, 110)
    for seed in seeds:
        tau, avar, edf = _curve(PAPER, 20.0, 36000, seed)
        fit = fit_axis(tau, avar, edf, 20.0, 36000)
        for sym in hits:
            hits[sym] += _covers(fit.optimised[sym], getattr(PAPER, sym))
    pooled = sum(hits.values()) / (4 * len(seeds))
    assert 0.85 <= pooled <= 1.0, hits
    assert min(hits.values()) >= 7, hits


def test_too_short_record_reports_upper_bounds():
    # 10 minutes: the random walk (crossing near 1 h) is invisible; B is tiny.
    noise = AxisNoise(N=1e-3, B=2e-5, T_B=8.0, K=3e-6)
    tau, avar, edf = _curve(noise, 20.0, 12000, seed=3)
    fit = fit_axis(tau, avar, edf, 20.0, 12000)
    k = fit.optimised['K']
    assert k.kind == 'upper_bound' and k.ci95 == (0.0, k.value)
    assert noise.K <= k.value < 1e-2
    b = fit.optimised['B']
    assert b.kind == 'upper_bound' and noise.B <= b.value
    assert fit.optimised['T_B'].kind == 'not_identified'
    assert math.isnan(fit.optimised['T_B'].value)
    assert fit.terms == ('white',)
    assert any(n.startswith('K:') and 'upper bound' in n for n in fit.notes)
    doc = fit.to_json()
    assert doc['params']['T_B']['value'] is None
    json.dumps(doc, allow_nan=False)


def test_nominal_readoff_on_exact_curves():
    tau = 2.0 ** np.arange(-4, 12)
    edf = np.full(tau.size, 100.0)
    white = nominal_fit(tau, avar_model(tau, AxisNoise(N=2e-3)), edf)
    assert_allclose(white['N'].value, 2e-3, rtol=1e-12)
    rw = nominal_fit(tau, avar_model(tau, AxisNoise(K=5e-5)), edf)
    assert_allclose(rw['K'].value, 5e-5, rtol=1e-12)
    assert rw['N'].kind == 'upper_bound'        # no -1/2 slope anywhere
    flat = nominal_fit(tau, avar_model(tau, AxisNoise(N=1e-9, B=3e-4)), edf)
    assert_allclose(flat['B'].value, 3e-4, rtol=1e-6)
    # T_B = tau at the minimum / 1.89; the interval brackets it.
    bowl = nominal_fit(tau, avar_model(tau, AxisNoise(N=1e-3, K=1e-5)), edf)
    i = int(np.argmin(avar_model(tau, AxisNoise(N=1e-3, K=1e-5))))
    assert_allclose(bowl['T_B'].value, tau[i] / 1.8926, rtol=1e-9)
    assert bowl['T_B'].ci95[0] <= bowl['T_B'].value <= bowl['T_B'].ci95[1]


def test_fit_curve_wrapper_units_and_method():
    spec = NoiseSpec(name='t', axes={a: (PAPER if a.startswith('gyro') else
                                         AxisNoise(N=6e-3, B=2e-3, T_B=8.0, K=1e-4))
                                     for a in ('gyro_x', 'gyro_y', 'gyro_z', 'accel_x',
                                               'accel_y', 'accel_z')})
    _, samples = simulate_imu(spec, 20.0, 1800.0, seed=4)
    curve = allan_curve(samples, 20.0, 'octave')
    fit = fit_curve(curve, 3)   # n_samples from the curve's term counts
    assert fit.optimised['N'].unit == 'm/s^2*s^0.5'
    assert fit.optimised['B'].unit == 'm/s^2'
    # (One interval misses its truth 5 % of the time; coverage is tested on seed sets.)
    n_fit = fit.optimised['N']
    assert abs(n_fit.value / 6e-3 - 1.0) < 0.02
    assert n_fit.ci95[0] < n_fit.value < n_fit.ci95[1]
    same = fit_axis(curve.tau_s, curve.avar[:, 3], curve.edf[:, 3], 20.0,
                    samples.shape[0], unit='m/s^2')
    assert same.optimised == fit.optimised
    had = allan_curve(samples[:, :1], 20.0, 'octave', method='hadamard')
    with pytest.raises(InputError):
        fit_curve(had, 0, samples.shape[0])
    with pytest.raises(InputError):
        fit_curve(curve, 6, samples.shape[0])


def test_input_errors_are_one_line():
    tau = np.array([0.1, 0.2, 0.4, 0.8])
    avar = np.array([1e-5, 5e-6, 2.5e-6, 1.25e-6])
    edf = np.full(4, 100.0)
    with pytest.raises(InputError, match='same length'):
        fit_axis(tau, avar[:3], edf, 10.0, 1000)
    with pytest.raises(InputError, match='unknown noise term'):
        fit_axis(tau, avar, edf, 10.0, 1000, terms=('white', 'pink'))
    with pytest.raises(InputError, match='once'):
        fit_axis(tau, avar, edf, 10.0, 1000, terms=('white', 'white'))
    with pytest.raises(InputError, match='at least 3'):
        fit_axis(tau[:2], avar[:2], edf[:2], 10.0, 1000)
    with pytest.raises(InputError, match='sample rate'):
        fit_axis(tau, avar, edf, 0.0, 1000)


def test_streaming_curve_fits_like_the_batch_curve():
    # The accumulator's dense, partly decimated curve goes through the same fit.
    y = simulate_axis(PAPER, 20.0, 36000, np.random.default_rng(5))
    acc = AllanAccumulator(n_axes=1, rate_hz=20.0, exact_max_m=256)
    for block in np.array_split(y[:, None], 7):
        acc.add(block)
    fit = fit_curve(acc.curve(), 0)
    assert fit.tau_s.size >= 12     # dense grid thinned to two points per octave
    for sym in ('N', 'B', 'T_B'):
        assert _covers(fit.optimised[sym], getattr(PAPER, sym)), (sym, fit.optimised[sym])


def test_sensor_filter_bend_at_short_tau_is_left_out():
    # A 4-tap moving average (a decimation filter) keeps the low-frequency density N
    # but flattens the first octaves; fitting them would pull N down.
    n_density, rate, n = 1e-3, 20.0, 36000
    w = np.random.default_rng(6).standard_normal(n + 3) * n_density * math.sqrt(rate)
    y = np.convolve(w, np.full(4, 0.25), mode='valid')
    c = allan_curve(y, rate, 'octave')
    fit = fit_axis(c.tau_s, c.avar[:, 0], c.edf[:, 0], rate, n, terms=('white',))
    assert fit.tau_s[0] >= 4.0 / rate
    assert any('left out' in note for note in fit.notes)
    # The first point alone sits 50 % low in AVAR; what remains of the bend costs ~2 %.
    assert abs(fit.optimised['N'].value / n_density - 1.0) < 0.03, fit.optimised['N']
    assert c.avar[0, 0] < 0.6 * n_density ** 2 * rate
    white = fit_axis(*_curve(AxisNoise(N=n_density), rate, n, seed=6), rate, n)
    assert white.tau_s[0] == 1.0 / rate       # plain white noise keeps every tau


def test_a_gentle_rise_at_a_slow_rate_is_no_filter():
    # White noise plus a slower process, an hour at 1 Hz: the first step falls at
    # -0.465, within twice its noise (0.024) of white noise, and the curve flattens
    # further out.  Read as a filter the bend never ended: every tau below 64 s was left
    # out and the fit turned untrusted (on the ADIS16405 as 1 Hz block means N's bound
    # then lay 1.4x over the curve).  A filter flattens the first step far beyond its
    # noise.
    rate, n = 1.0, 3600
    y = simulate_axis(AxisNoise(N=7e-4, B=5e-4, T_B=20.0), rate, n,
                      np.random.default_rng(1))
    c = allan_curve(y, rate, 'octave')
    slope = 0.5 * math.log(c.avar[1, 0] / c.avar[0, 0]) / math.log(2.0)
    assert -0.49 < slope < -0.43
    fit = fit_curve(c, 0, n)
    assert fit.tau_s[0] == 1.0 and fit.filter_end_s == 1.0
    assert fit.optimised['N'].kind == 'estimate'
    assert fit.optimised['N'].ci95[0] <= 7e-4 <= fit.optimised['N'].ci95[1]
    # A 4-tap moving average at the same length is still left out (first step -0.3).
    w = np.random.default_rng(6).standard_normal(n + 3) * 7e-4 * math.sqrt(rate)
    y4 = np.convolve(w, np.full(4, 0.25), mode='valid')
    c4 = allan_curve(y4, rate, 'octave')
    assert fit_curve(c4, 0, n).tau_s[0] >= 4.0


def test_adis16405_gyro_against_the_datasheet(shared_dir):
    # A real record: run 2 of the six static ADIS16405 runs (100 Hz, 2.78 h, no
    # outliers; ../shared/realdata/README.md).  Datasheet: rate noise density
    # 0.05 deg/s/sqrt(Hz), in-run bias stability 0.007 deg/s (quoted by Analog Devices
    # as the Allan deviation minimum, i.e. 0.664 B in the paper's convention).
    # Tolerance: N within 0.7-1.2 x the datasheet (a typical value, not a bound; the six
    # runs give 0.79-0.93 on x and y), the ADEV floor 0.664 B within 0.6-2 x.  The z
    # gyro carries an effect outside the default model (ADEV flat from 0.01 to 0.02 s,
    # then halved at 0.04 s); the fit must say that the model does not explain it.
    deg = math.pi / 180.0
    data = read_csv(shared_dir / 'realdata' / 'adis16405' / 'adis16405_run2.csv.gz',
                    columns=('gyro_x', 'gyro_y', 'gyro_z'))
    curve = allan_curve(data.samples, data.rate_hz, 'octave')
    n = data.samples.shape[0]
    for axis in (0, 1):
        fit = fit_curve(curve, axis, n, unit='rad/s')
        n_p, b_p = fit.optimised['N'], fit.optimised['B']
        assert n_p.kind == 'estimate' and b_p.kind == 'estimate', fit.optimised
        assert 0.7 < n_p.value / deg / 0.05 < 1.2, n_p
        assert 0.6 < b_p.value * FLICKER_FLOOR / deg / 0.007 < 2.0, b_p
    z = fit_curve(curve, 2, n, unit='rad/s')
    assert any('does not explain the curve' in note for note in z.notes), z.notes


def test_a_record_too_short_gives_no_degenerate_bounds():
    """60 samples cannot constrain B or K: never a bound of 0 or inf, which Q/R would use."""
    rng = np.random.default_rng(11)
    y = 1e-3 * rng.standard_normal((60, 6))
    curve = allan_curve(y, 30.0, 'octave', confidence=0.95)
    for j in range(6):
        fit = fit_curve(curve, j, 60, unit='rad/s')
        for sym, p in fit.optimised.items():
            if p.kind in ('estimate', 'upper_bound'):
                assert math.isfinite(p.value) and p.value > 0, (j, sym, p)
            else:
                assert math.isnan(p.value), (j, sym, p)


def test_an_estimate_reaching_zero_is_a_bound_and_bounds_stay_under_the_curve():
    from imu_allan.core.fit.caps import curve_caps
    from imu_allan.core.fit.params import bound_by_curve
    from imu_allan.core.fit.result import Param
    from imu_allan.core.allan.edf import curve_k_bound, floor_b_bound
    tau = np.geomspace(0.01, 30.0, 12)
    avar = 1e-6 / tau + 1e-9 * tau             # white noise and a random walk
    edf = np.geomspace(5e3, 3.0, 12)
    k_cap, b_cap = curve_k_bound(tau, avar, edf), floor_b_bound(avar, edf)
    opt = {'N': Param(1e-3, (9e-4, 1.1e-3), 'estimate', 'u'),
           'B': Param(b_cap / 2, (-1e-5, b_cap / 1.5), 'estimate', 'u'),
           'T_B': Param(2.0, (1.0, 4.0), 'estimate', 's'),
           'K': Param(100 * k_cap, (0.0, 100 * k_cap), 'upper_bound', 'u')}
    notes: list = []
    out = bound_by_curve(opt, curve_caps(tau, avar, edf), notes)
    assert out['N'] == opt['N']
    assert out['B'][:4] == (b_cap / 1.5, (0.0, b_cap / 1.5), 'upper_bound', 'u')
    assert out['B'].reason == 'its 95 % interval reaches 0: upper bound'
    assert out['T_B'].kind == 'not_identified'
    assert out['K'][:4] == (k_cap, (0.0, k_cap), 'upper_bound', 'u')
    assert out['K'].source == 'curve' and 'capped' in out['K'].reason
    assert len(notes) == 2


def test_bounds_made_after_the_fit_are_capped_at_its_curve():
    # A later step (a rival model, a drift test) makes a bound from an interval's upper
    # end; cap_fit brings it under the curve's own bound and leaves estimates alone.
    from dataclasses import replace
    from imu_allan.core.allan.edf import avar_upper
    from imu_allan.core.fit.caps import cap_fit, curve_caps
    from imu_allan.core.fit.result import Param
    tau = np.geomspace(0.01, 1000.0, 30)
    avar = 1e-6 / tau + 1e-9 * tau
    edf = np.geomspace(5e4, 3.0, 30)
    fit = fit_axis(tau, avar, edf, 100.0, 200_000)
    assert fit.filter_end_s == tau[0]             # white from the first tau: no filter
    assert fit.caps == curve_caps(tau, avar, edf, tau[0])
    assert cap_fit(fit) is fit
    k = fit.optimised['K']
    late = replace(fit, optimised={**fit.optimised, 'K': Param(
        10 * fit.caps.K, (0.0, 10 * fit.caps.K), 'upper_bound', k.unit, 'fitted', 'rival')})
    out = cap_fit(late)
    assert out.optimised['K'][:3] == (fit.caps.K, (0.0, fit.caps.K), 'upper_bound')
    assert out.optimised['N'] is fit.optimised['N'] and len(out.notes) == len(fit.notes) + 1
    assert cap_fit(out) is out
    # The cap is what a random walk under the joint upper band allows, at every tau.
    np.testing.assert_allclose(fit.caps.K, np.sqrt(np.min(3 * avar_upper(avar, edf) / tau)),
                               rtol=1e-12)


def test_n_bound_is_capped_only_where_the_filter_is_seen_to_end():
    # White noise lies under the curve past the sensor's filter: an N bound above that
    # line (a held record's profile widened by its misfit ran 1.3x over its curve) is
    # capped there; a filter whose bend is not seen to end may lower the curve below
    # N's line, so then there is no cap.
    from imu_allan.core.allan.edf import avar_upper
    from imu_allan.core.fit.caps import cap_bounds, curve_caps
    from imu_allan.core.fit.result import Param
    tau = np.geomspace(0.01, 30.0, 12)
    avar = 1e-6 / tau
    avar[:2] *= 0.3                            # the filter lowers the first two points
    edf = np.geomspace(5e3, 3.0, 12)
    caps = curve_caps(tau, avar, edf, tau[2])
    assert_allclose(caps.N, np.sqrt(np.min(avar_upper(avar[2:], edf[2:]) * tau[2:])),
                    rtol=1e-12)
    assert 1e-3 < caps.N < 1.1e-3              # over the true N, under the filtered points
    assert curve_caps(tau, avar, edf).N == math.inf
    notes: list = []
    bound = {'N': Param(5e-3, (0.0, 5e-3), 'upper_bound', 'u')}
    out = cap_bounds(bound, caps, notes)
    assert out['N'][:3] == (caps.N, (0.0, caps.N), 'upper_bound')
    assert out['N'].source == 'curve' and notes[0].startswith('N: the bound 0.005')
    estimate = {'N': Param(5e-3, (4e-3, 6e-3), 'estimate', 'u')}
    assert cap_bounds(estimate, caps, [])['N'] is estimate['N']


def test_a_3_min_real_record_reports_no_bound_above_its_own_curve(shared_dir):
    # Issue 35: on 2-3 min of the ADIS16405 the profile bounds of B and K ran up to
    # hundreds of times the curve's own bounds (accel_z K 6.8 m/s^2.5 beside a curve
    # bound of 2e-3), and estimates of K had intervals starting at 0.
    from imu_allan.core.allan.edf import curve_k_bound, curve_n_bound, floor_b_bound
    data = read_csv(shared_dir / 'realdata' / 'adis16405' / 'adis16405_run1.csv.gz',
                    columns=['gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z'])
    curve = allan_curve(data.samples[1000:19000], 100.0, confidence=0.95)  # past 7 s
    for j in range(6):
        fit = fit_curve(curve, j)
        caps = {'K': curve_k_bound(fit.tau_s, fit.avar_meas, fit.edf),
                'B': floor_b_bound(fit.avar_meas, fit.edf)}
        white = fit.tau_s >= fit.filter_end_s * (1 - 1e-9)    # NaN: no N cap
        if white.any():
            caps['N'] = curve_n_bound(fit.tau_s[white], fit.avar_meas[white],
                                      fit.edf[white])
        for sym in ('N', 'B', 'K'):
            p = fit.optimised[sym]
            assert p.kind != 'estimate' or p.ci95[0] > 0, (j, sym, p)
            if p.kind == 'upper_bound' and sym in caps:
                assert p.value <= caps[sym] * (1 + 1e-12), (j, sym, p, caps[sym])
