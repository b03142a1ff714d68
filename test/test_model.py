"""
Tests of imu_allan.core.noise.model: closed-form Allan variances against independent hand values.

The simulated-data check of every closed form lives in test_simulate.py (each generator
against its own copy of the formula); here each formula is pinned to numbers worked
out by hand from IEEE Std 952 annex C, the paper's eq. 8 convention and NIST SP 1065,
and the registry used by the fit is checked for internal consistency.
"""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.integrate import quad
from scipy.optimize import minimize_scalar

from imu_allan.core.noise.model import adev_model, avar_model, avar_terms
from imu_allan.core.noise.shapes import (avar_flicker, avar_gauss_markov, avar_quantization,
                                         avar_random_walk, avar_rate_ramp, avar_sinusoid,
                                         avar_white)
from imu_allan.core.noise.terms import base_name, noise_from_terms, TERMS
from imu_allan.core.noise.values import AxisNoise, GaussMarkov, Sinusoid

E = math.e


def test_polynomial_terms_hand_values():
    # IEEE Std 952 C.1: 3 Q^2/tau^2, N^2/tau, K^2 tau/3, R^2 tau^2/2.
    assert_allclose(avar_quantization([3.0], Q=1.0), [1.0 / 3.0], rtol=1e-15)
    assert_allclose(avar_white([4.0], N=2.0), [1.0], rtol=1e-15)
    assert_allclose(avar_random_walk([3.0], K=3.0), [9.0], rtol=1e-15)
    assert_allclose(avar_rate_ramp([3.0], R=2.0), [18.0], rtol=1e-15)


def test_flicker_floor_is_0664_b_at_every_tau():
    tau = np.array([0.01, 1.0, 1e4])
    adev = np.sqrt(avar_flicker(tau, B=2.0))
    # sqrt(2 ln2 / pi) = 0.66428...
    assert_allclose(adev, 2.0 * 0.6642824702, rtol=1e-9)


def test_sinusoid_hand_values():
    # pi f0 tau = pi/2: (sin^2(pi/2) / (pi/2))^2 = (2/pi)^2; a whole period averages out.
    assert_allclose(avar_sinusoid([0.5], A=1.0, f0_hz=1.0), [(2.0 / math.pi) ** 2],
                    rtol=1e-14)
    assert avar_sinusoid([1.0], A=1.0, f0_hz=1.0)[0] < 1e-30
    # ADEV peak 0.7246 A near tau = 0.371 / f0 (IEEE Std 952 C.1).
    res = minimize_scalar(lambda t: -avar_sinusoid([t], 1.0, 2.0)[0], bounds=(0.05, 0.4),
                          method='bounded', options={'xatol': 1e-10})
    assert_allclose(res.x * 2.0, 0.371, atol=5e-4)
    assert_allclose(math.sqrt(-res.fun), 0.7246, atol=5e-5)


def test_gauss_markov_peak_0437_q_sqrt_t_at_189_t():
    q, T = 3.0, 7.0
    res = minimize_scalar(lambda t: -avar_gauss_markov([t], q, T)[0], bounds=(T, 4 * T),
                          method='bounded', options={'xatol': 1e-9})
    assert_allclose(res.x / T, 1.8926, atol=1e-3)
    assert_allclose(math.sqrt(-res.fun) / (q * math.sqrt(T)), 0.4365, atol=5e-5)


def test_gauss_markov_uses_decaying_exponentials_not_the_papers_typo():
    # At tau = T: 1 - (3 - 4/e + 1/e^2) / 2 = 0.168091... (with the paper's printed
    # exp(+tau/T) the bracket would be 1 - (3 - 4e + e^2)/2 = 1.2420... instead).
    q, T = 2.0, 5.0
    hand = q ** 2 * T * (1.0 - (3.0 - 4.0 / E + 1.0 / E ** 2) / 2.0)
    assert_allclose(avar_gauss_markov([T], q, T), [hand], rtol=1e-14)
    assert_allclose(hand / (q ** 2 * T), 0.1680914, rtol=1e-6)
    typo = q ** 2 * T * (1.0 - (3.0 - 4.0 * E + E ** 2) / 2.0)
    assert typo > 5.0 * avar_gauss_markov([T], q, T)[0]
    # Far beyond T the term is white noise of density q T: exp(+) would explode instead.
    assert_allclose(avar_gauss_markov([400.0 * T], q, T), [(q * T) ** 2 / (400.0 * T)
                                                           * (1 - 1.5 / 400.0)], rtol=1e-12)


def test_gauss_markov_limits_and_series_switch():
    q, T = 1.5, 10.0
    # tau << T: random walk q^2 tau / 3.
    tau = 1e-4 * T
    assert_allclose(avar_gauss_markov([tau], q, T), [q ** 2 * tau / 3.0], rtol=1e-4)
    # The small-x series and the direct formula agree where the code switches (x = 0.05).
    x = np.array([0.05 * (1 - 1e-12), 0.05])
    a = avar_gauss_markov(x * T, q, T)
    assert_allclose(a[0], a[1], rtol=1e-9)


def test_paper_eq8_puts_the_gauss_markov_peak_on_0664_b():
    # S_B = 2 B^2 ln2 / (pi 0.4365^2 T_B): ADEV peak = 0.664 B, like flicker of level B.
    noise = AxisNoise(B=3e-4, T_B=40.0)
    adev = adev_model([1.8926 * 40.0], noise)[0]
    assert_allclose(adev, 0.66428 * 3e-4, rtol=2e-4)


def test_avar_terms_names_and_sum():
    noise = AxisNoise(Q=1e-5, N=1e-3, B=2e-4, T_B=30.0, K=1e-5, R=1e-7,
                      gauss_markov=(GaussMarkov(1e-4, 2.0), GaussMarkov(5e-5, 300.0)),
                      sinusoids=(Sinusoid(1e-4, 0.05),))
    tau = np.geomspace(0.01, 1000.0, 12)
    terms = avar_terms(tau, noise)
    assert set(terms) == {'quantization', 'white', 'bias_instability', 'gauss_markov_1',
                          'gauss_markov_2', 'random_walk', 'rate_ramp', 'sinusoid'}
    assert_allclose(terms['gauss_markov_2'], avar_gauss_markov(tau, GaussMarkov(
        5e-5, 300.0).q, 300.0), rtol=1e-14)
    assert_allclose(avar_model(tau, noise), sum(terms.values()), rtol=1e-14)
    # One further Gauss-Markov term keeps the plain name; no T_B means flicker.
    one = avar_terms(tau, AxisNoise(B=2e-4, gauss_markov=(GaussMarkov(1e-4, 2.0),)))
    assert set(one) == {'flicker', 'gauss_markov'}
    assert_allclose(one['flicker'], avar_flicker(tau, 2e-4), rtol=1e-14)
    assert_allclose(avar_model(tau, AxisNoise()), np.zeros(tau.size))


@pytest.mark.parametrize('name', sorted(TERMS))
def test_registry_shape_matches_closed_form(name):
    term = TERMS[name]
    tau = np.geomspace(0.02, 500.0, 9)
    level = 3e-4
    nl = {'T': (20.0,), 'T_B': (20.0,), 'f0_hz': (0.03,), 'T_f': (0.05,)}
    nonlinear = nl[term.nonlinear[0]] if term.nonlinear else ()
    c = term.to_coef(level, *nonlinear)
    params = term.to_params(c, *nonlinear)
    assert_allclose(params[term.symbols[0]], level, rtol=1e-12)
    value = {'quantization': lambda: avar_quantization(tau, level),
             'white': lambda: avar_white(tau, level),
             'flicker': lambda: avar_flicker(tau, level),
             'gauss_markov': lambda: avar_gauss_markov(tau, GaussMarkov(level, 20.0).q, 20.0),
             'bias_instability': lambda: avar_model(tau, AxisNoise(B=level, T_B=20.0)),
             'random_walk': lambda: avar_random_walk(tau, level),
             'rate_ramp': lambda: avar_rate_ramp(tau, level),
             'sinusoid': lambda: avar_sinusoid(tau, level, 0.03),
             # White noise through a first-order filter of 0.05 s (IEEE Std 952 C.1 with
             # q T = N): N^2 / tau (1 - T / (2 tau) (3 - 4 e^(-tau/T) + e^(-2 tau/T))).
             'filtered_white': lambda: level ** 2 / tau * (1.0 - 0.05 / (2.0 * tau) * (
                 3.0 - 4.0 * np.exp(-tau / 0.05) + np.exp(-2.0 * tau / 0.05)))}[name]()
    assert_allclose(c * term.shape(tau, *nonlinear), value, rtol=1e-12)


@pytest.mark.parametrize('name', [n for n in sorted(TERMS) if TERMS[n].gcov is not None])
def test_generalised_covariance_reproduces_the_allan_variance(name):
    # E (X[2m] - 2 X[m] + X[0])^2 / (2 tau^2) = shape(tau): the phase covariance used for
    # the fit's covariance matrix is scaled like the closed form.
    term = TERMS[name]
    nonlinear = (7.0,) if term.nonlinear else ()
    a = np.array([1.0, -2.0, 1.0])
    for tau in (0.5, 3.0, 40.0):
        u = tau * (np.arange(3)[:, None] - np.arange(3)[None, :])
        second_moment = a @ term.gcov(u, *nonlinear) @ a
        assert_allclose(second_moment / (2 * tau ** 2), term.shape(np.array([tau]),
                                                                   *nonlinear)[0],
                        rtol=1e-9)


@pytest.mark.parametrize('name', ['white', 'flicker', 'gauss_markov', 'random_walk'])
def test_phase_psd_reproduces_the_allan_variance(name):
    # The phase PSDs feed the sinusoid's beat term in the fit's covariance.  With the
    # two-sided rate PSD S_y = (2 pi f)^2 S_X, AVAR(tau) = 4 int_0^inf S_y(f)
    # sin^4(pi f tau) / (pi f tau)^2 df (NIST SP 1065 eq. 65, one-sided there).
    term = TERMS[name]
    nonlinear = (7.0,) if term.nonlinear else ()
    for tau in (0.5, 3.0, 40.0):
        def integrand(x):
            f = x / (math.pi * tau)
            s_y = (2 * math.pi * f) ** 2 * term.psd_phase(f, 0.01, *nonlinear)
            return 4.0 * s_y * math.sin(x) ** 4 / x ** 2 / (math.pi * tau)
        edges = np.concatenate([[1e-9], np.arange(1, 1501) * math.pi])
        total = sum(quad(integrand, a, b)[0] for a, b in zip(edges[:-1], edges[1:]))
        # Beyond x = 1500 pi, sin^4 averages 3/8 and S_y is at most flat (white).
        tail = 4.0 * integrand_tail_bound(term, tau, nonlinear, edges[-1])
        assert_allclose(total + tail, term.shape(np.array([tau]), *nonlinear)[0],
                        rtol=2e-3, err_msg=f'{name} at tau {tau}')


def integrand_tail_bound(term, tau: float, nonlinear: tuple, x0: float) -> float:
    """(3/8) int_x0^inf S_y(f) / x^2 dx / (pi tau) with S_y frozen at x0 (white tail)."""
    f = x0 / (math.pi * tau)
    s_y = (2 * math.pi * f) ** 2 * term.psd_phase(f, 0.01, *nonlinear)
    return 0.375 * s_y / x0 / (math.pi * tau)


def test_gauss_markov_tail_matches_direct_sum():
    # Where the direct 9-term sum has no cancellation problem (m dt ~ T), the closed-form
    # tail agrees with it.
    term = TERMS['gauss_markov']
    T, dt, m1, m2 = 2.0, 0.5, 3, 5
    a = np.array([1.0, -2.0, 1.0])
    for d in (0.0, 1.0, 7.0):
        h = 2 * m1 + d
        u = dt * (np.arange(3)[:, None] * m1 - np.arange(3)[None, :] * m2 - h)
        direct = a @ term.gcov(u, T) @ a
        tail = term.tail(np.array([d]), np.array([m1]), np.array([m2]), dt, T)[0]
        assert_allclose(tail, direct, rtol=1e-10)


def test_base_name_and_noise_from_terms_round_trip():
    assert base_name('gauss_markov_2') == 'gauss_markov'
    assert base_name('white') == 'white'
    with pytest.raises(KeyError):
        base_name('pink')
    noise = noise_from_terms({'white': {'N': 1e-3}, 'bias_instability': {'B': 2e-4, 'T_B': 9.0},
                              'gauss_markov_2': {'B': 1e-4, 'T': 2.0},
                              'random_walk': {'K': 1e-5}, 'quantization': {'Q': 1e-6},
                              'rate_ramp': {'R': 1e-8},
                              'sinusoid': {'A': 1e-4, 'f0_hz': 0.1}})
    assert noise == AxisNoise(N=1e-3, B=2e-4, T_B=9.0, K=1e-5, Q=1e-6, R=1e-8,
                              gauss_markov=(GaussMarkov(1e-4, 2.0),),
                              sinusoids=(Sinusoid(1e-4, 0.1),))


def test_quantiles_from_scipy_special_equal_scipy_stats():
    # allan.quantiles, the package's one chi-square quantile, equals scipy.stats.
    from scipy.stats import chi2, f

    from imu_allan.core.allan.quantiles import chi2_ppf, chi2_sf, f_ppf
    edf = np.array([0.5, 1.0, 2.7, 10.0, 1e3, 1e6])
    for q in (0.025, 0.5, 0.95, 0.975):
        assert_allclose(chi2_ppf(q, edf), chi2.ppf(q, edf), rtol=1e-12)
    x = np.array([0.1, 3.0, 20.0])
    assert_allclose(chi2_sf(x, 7), chi2.sf(x, 7), rtol=1e-12)
    assert_allclose(f_ppf(0.95, 1, [3, 17, 200]), f.ppf(0.95, 1, [3, 17, 200]), rtol=1e-12)
    df = np.geomspace(0.3, 1e7, 60)     # the Allan bounds' range of EDF
    for q in (1e-4, 0.025, 0.5, 0.975, 0.9999):
        assert_allclose(chi2_ppf(q, df), chi2.ppf(q, df), rtol=1e-12)
