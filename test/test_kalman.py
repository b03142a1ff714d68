"""
Tests of imu_allan.core.outputs.kalman: densities, discretisation, Q/R, Kalibr and ROS exports.

Hand values follow the paper's eqs. 8 and 16-23 (exact forms); the six-axis matrices are
also checked against the independent single-axis implementation in imu_allan.core.noise.simulate.
"""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

from imu_allan import AXES
from imu_allan.core.fit import AxisFit, Param
from imu_allan.core.noise.simulate import state_space_matrices
from imu_allan.core.noise.values import AxisNoise, GaussMarkov
from imu_allan.core.outputs.consumers import NOTES
from imu_allan.core.outputs.covering import cover_axes, default_horizon
from imu_allan.core.outputs.exports import kalibr_yaml
from imu_allan.core.outputs.kalman import (axis_densities, AxisDensities, discretise,
                                           imu_covariance, kalman_model)
from imu_allan.core.outputs.reported import report_axis
from imu_allan.errors import InputError

GYRO = AxisNoise(N=1.2e-4, B=5e-5, T_B=80.0, K=2e-6)
ACCEL = AxisNoise(N=6e-4, B=3e-4, T_B=60.0, K=1e-5)


def _six(gyro=GYRO, accel=ACCEL):
    return {a: (gyro if a.startswith('gyro') else accel) for a in AXES}


def test_densities_follow_paper_eq8():
    d = axis_densities(GYRO, 'gyro_x')
    assert_allclose(d.S_N, 1.44e-8, rtol=1e-14)
    assert_allclose(d.S_K, 4e-12, rtol=1e-14)
    # S_B = 2 B^2 ln2 / (pi 0.4365^2 T_B), by hand:
    s_b = 2 * (5e-5) ** 2 * math.log(2) / (math.pi * 0.4365 ** 2 * 80.0)
    assert_allclose(d.S_B, s_b, rtol=1e-12)
    assert d.T_B == 80.0
    flicker = axis_densities(AxisNoise(N=1e-4, B=5e-5))
    assert flicker.S_B == 0.0 and flicker.T_B is None


def test_exact_discretisation_hand_values():
    d = AxisDensities(axis='x', S_N=4.0, S_B=2.0, T_B=10.0, S_K=3.0)
    z = discretise(d, 0.1)
    assert_allclose(z.phi_gm, math.exp(-0.01), rtol=1e-15)
    assert_allclose(z.qd_gm, 2.0 * 10.0 / 2.0 * (1.0 - math.exp(-0.02)), rtol=1e-13)
    assert_allclose(z.qd_gm, 0.19801326693244712, rtol=1e-13)
    assert_allclose(z.qd_rw, 0.3, rtol=1e-15)
    assert_allclose(z.r, 40.0, rtol=1e-15)
    # Stationary variance of the discrete AR(1) equals the continuous S_B T_B / 2.
    assert_allclose(z.qd_gm / (1 - z.phi_gm ** 2), 10.0, rtol=1e-12)
    # dt << T_B keeps its digits (expm1): Qd ~ S_B dt.
    tiny = discretise(d, 1e-9)
    assert_allclose(tiny.qd_gm, 2.0 * 1e-9, rtol=1e-8)
    with pytest.raises(InputError):
        discretise(d, 0.0)


def test_six_axis_q_and_r_with_labels():
    km = kalman_model(_six(), rate_hz=100.0)
    assert km.Qd.shape == (12, 12) and km.Rd.shape == (6, 6) and km.H.shape == (6, 12)
    assert km.state_labels[:4] == ('gyro_x.b_gm', 'gyro_x.b_rw', 'gyro_y.b_gm', 'gyro_y.b_rw')
    assert km.state_labels[-1] == 'accel_z.b_rw'
    assert km.measurement_labels == AXES
    dt = 0.01
    for i, axis in enumerate(AXES):
        noise = GYRO if axis.startswith('gyro') else ACCEL
        s_b = GaussMarkov(noise.B, noise.T_B).psd
        g, r = 2 * i, 2 * i + 1
        assert_allclose(km.F[g, g], -1.0 / noise.T_B, rtol=1e-15)
        assert km.F[r, r] == 0.0
        assert_allclose(km.Qc[g, g], s_b, rtol=1e-14)
        assert_allclose(km.Qc[r, r], noise.K ** 2, rtol=1e-14)
        assert_allclose(km.Phi[g, g], math.exp(-dt / noise.T_B), rtol=1e-14)
        assert km.Phi[r, r] == 1.0
        assert_allclose(km.Qd[g, g], s_b * noise.T_B / 2 * (1 - math.exp(-2 * dt / noise.T_B)),
                        rtol=1e-9)
        assert_allclose(km.Qd[r, r], noise.K ** 2 * dt, rtol=1e-14)
        assert_allclose(km.Rc[i, i], noise.N ** 2, rtol=1e-14)
        assert_allclose(km.Rd[i, i], noise.N ** 2 / dt, rtol=1e-14)
        assert km.H[i, g] == km.H[i, r] == 1.0 and km.H[i].sum() == 2.0
        # Same numbers as the simulator's independent single-axis model.
        phi, qd, h, rr = state_space_matrices(noise, dt)
        assert_allclose(np.diag(km.Phi)[g:r + 1], np.diag(phi), rtol=1e-14)
        assert_allclose(np.diag(km.Qd)[g:r + 1], np.diag(qd), rtol=1e-12)
        assert_allclose(km.Rd[i, i], rr[0, 0], rtol=1e-14)
    off = km.Qd - np.diag(np.diag(km.Qd))
    assert not off.any()
    doc = km.to_json()
    assert doc['state_labels'][0] == 'gyro_x.b_gm' and len(doc['discrete']['Qd']) == 12


def test_flicker_b_gets_a_frozen_state_and_a_note():
    km = kalman_model(_six(gyro=AxisNoise(N=1e-4, B=5e-5, K=1e-6)), rate_hz=50.0)
    assert km.Phi[0, 0] == 1.0 and km.Qd[0, 0] == 0.0 and km.F[0, 0] == 0.0
    assert any('gyro_x' in n and 'frozen' in n for n in km.notes)


def test_a_b_without_t_b_has_no_state_and_is_named_never_invented():
    # A fitted flicker B (T_B not identified) has no Gauss-Markov state: the model says
    # it leaves B out instead of inventing a correlation time (the middle of the taus).
    tau = np.geomspace(0.1, 1000.0, 9)
    nan = Param(math.nan, (math.nan, math.nan), 'not_identified', 's')
    fit = AxisFit(nominal={}, optimised={
        'N': Param(1e-4, (0.9e-4, 1.1e-4), 'estimate', 'rad/s*s^0.5'),
        'B': Param(5e-5, (4e-5, 6e-5), 'estimate', 'rad/s'), 'T_B': nan,
        'K': Param(1e-6, (0.5e-6, 2e-6), 'estimate', 'rad/s/s^0.5')},
        model=AxisNoise(N=1e-4, B=5e-5, K=1e-6), terms=('white', 'flicker', 'random_walk'),
        notes=(), tau_s=tau)
    report = report_axis(fit, 'gyro_x')
    assert report.gauss_markov is None
    assert any('without an identified T_B' in x for x in report.left_out)
    assert any(x.startswith('flicker') for x in report.left_out)
    km = kalman_model(_six(gyro=fit, accel=AxisNoise(N=1e-3)), rate_hz=50.0)
    assert km.Phi[0, 0] == 1.0 and km.Qd[0, 0] == 0.0 and km.F[0, 0] == 0.0
    assert km.axes[0].T_B is None
    assert any(x.startswith('flicker') for x in km.to_json()['left_out']['gyro_x'])
    # The random-walk consumers cover it: the covering pair's Allan variance lies on or
    # above the flicker floor over the horizon.
    cover = cover_axes(_six(gyro=fit, accel=AxisNoise(N=1e-3)), (0.02, 100.0))['gyro_x']
    taus = np.geomspace(0.02, 100.0, 50)
    pair = cover.N_cover ** 2 / taus + cover.K_cover ** 2 * taus / 3.0
    assert np.all(pair >= report.model_avar(taus) * (1 - 1e-9))


def test_kalman_inputs_validated():
    with pytest.raises(InputError):
        kalman_model([GYRO] * 5, rate_hz=100.0)
    with pytest.raises(InputError):
        kalman_model({'gyro_x': GYRO}, rate_hz=100.0)
    with pytest.raises(InputError):
        kalman_model(_six(), rate_hz=-1.0)


def _fit_with_k_bound(k_bound: float) -> AxisFit:
    def p(v, kind='estimate', unit='rad/s'):
        return Param(v, (0.9 * v, 1.1 * v), kind, unit)
    opt = {'N': p(1e-4), 'B': p(4e-5), 'T_B': p(50.0),
           'K': Param(k_bound, (0.0, k_bound), 'upper_bound', 'rad/s/s^0.5')}
    return AxisFit(nominal=opt, optimised=opt, model=AxisNoise(N=1e-4, B=4e-5, T_B=50.0),
                   terms=('white', 'bias_instability'), notes=())


def test_upper_bounds_are_used_at_their_bound():
    fit = _fit_with_k_bound(3e-6)
    report = report_axis(fit)
    assert report.random_walk == (3e-6, 'upper_bound', 'K used at its 95 % upper bound')
    assert report.white == (1e-4, 'estimate', '')
    assert report.gauss_markov.T_B == 50.0 and report.gauss_markov.B == 4e-5
    km = kalman_model({a: fit for a in AXES}, rate_hz=100.0)
    assert_allclose(km.Qd[1, 1], 9e-12 * 0.01, rtol=1e-12)
    assert any('upper bound' in n for n in km.notes)


def test_kalibr_yaml_keys_units_and_worst_axis():
    gyros = [AxisNoise(N=1e-4 * (i + 1), K=1e-6 * (3 - i)) for i in range(3)]
    accels = [AxisNoise(N=6e-4 + 1e-5 * i, K=1e-5) for i in range(3)]
    sources = gyros + accels
    text = kalibr_yaml(sources, rate_hz=200.0)
    doc = yaml.safe_load(text)
    assert set(doc) == {'accelerometer_noise_density', 'accelerometer_random_walk',
                        'gyroscope_noise_density', 'gyroscope_random_walk', 'rostopic',
                        'update_rate'}
    # The covering pair (continuous densities), worst axis.  A white + random-walk model
    # is its own cover, and N gets the run-to-run margin.
    margin = 1.10
    assert_allclose(doc['gyroscope_noise_density'], margin * 3e-4, rtol=1e-4)
    assert_allclose(doc['gyroscope_random_walk'], 3e-6, rtol=1e-4)
    assert_allclose(doc['accelerometer_noise_density'], margin * 6.2e-4, rtol=1e-4)
    assert_allclose(doc['accelerometer_random_walk'], 1e-5, rtol=1e-4)
    assert doc['update_rate'] == 200.0
    assert 'rad/s/sqrt(Hz)' in text and 'm/s^3/sqrt(Hz)' in text
    assert '#   gyro_y: N = 2.000000e-04 -> 2.2000' in text  # per-axis values as comments
    mean = yaml.safe_load(kalibr_yaml(sources, rate_hz=200.0, reduce='mean'))
    assert_allclose(mean['gyroscope_noise_density'], margin * 2e-4, rtol=1e-4)
    with pytest.raises(InputError):
        kalibr_yaml(sources, rate_hz=200.0, reduce='median')


def _fit(n, k, k_kind='estimate'):
    def p(v, kind='estimate', unit='m/s^2'):
        return Param(v, (0.0 if kind == 'upper_bound' else 0.9 * v, 1.1 * v), kind, unit)
    opt = {'N': p(n), 'B': p(3e-4), 'T_B': p(60.0, unit='s'), 'K': p(k, k_kind)}
    return AxisFit(nominal=opt, optimised=opt, model=AxisNoise(N=n, B=3e-4, T_B=60.0, K=k),
                   terms=('white', 'bias_instability'), notes=())


def test_kalibr_takes_every_axis_a_larger_bound_included():
    # Accel K estimated on x and y (~8e-6) but only bounded on z (1.08e-4): the bound is
    # what the record allows on z, so the worst axis is z (an estimate-only reduction
    # under-stated it by 13x).
    accels = [_fit(6e-4, 8.1e-6), _fit(6.1e-4, 7.9e-6), _fit(6.2e-4, 1.08e-4, 'upper_bound')]
    gyros = [_fit(1.2e-4, 2e-6, 'upper_bound'), _fit(1.3e-4, 3e-6, 'upper_bound'),
             _fit(1.1e-4, 2.5e-6, 'upper_bound')]
    text = kalibr_yaml(gyros + accels, rate_hz=100.0)
    doc = yaml.safe_load(text)
    covers = cover_axes(dict(zip(AXES, gyros + accels)), default_horizon(100.0))
    assert_allclose(doc['accelerometer_random_walk'],
                    max(covers[a].K_cover for a in AXES[3:]), rtol=1e-6)
    assert doc['accelerometer_random_walk'] >= 1.08e-4
    assert doc['gyroscope_random_walk'] >= 3e-6
    assert doc['accelerometer_noise_density'] >= 1.1 * 6.2e-4 * (1 - 1e-9)
    assert '(95 % upper bound)' in text
    # A sensor with no value on any axis (no term, no curve): its keys are left out
    # (Kalibr stops on them) rather than written as 0, which Kalibr's reader rejects.
    text = kalibr_yaml([AxisNoise()] * 3 + accels, rate_hz=100.0)
    lean = yaml.safe_load(text)
    assert 'gyroscope_random_walk' not in lean and 'gyroscope_noise_density' not in lean
    assert 'gyroscope_random_walk: not available on any axis; left out' in text
    assert all(v > 0 for k, v in lean.items() if k.endswith(('density', 'walk')))


def test_kalibr_falls_back_to_the_bound_the_curve_sets():
    # K not identified on any gyro axis (no estimate, no bound): the curve's own bound
    # min sqrt(3 AVAR / tau) is the reported K, and the written pair is never below it.
    tau = np.geomspace(0.01, 1000.0, 12)
    avar = 1e-8 / tau + 1e-12 * tau          # white N = 1e-4 plus a tiny walk
    gyros = []
    for n in (1.0e-4, 1.1e-4, 0.9e-4):
        fit = _fit(n, 1.0, 'not_identified')
        opt = dict(fit.optimised, K=Param(math.nan, (math.nan, math.nan), 'not_identified',
                                          'rad/s^2/sqrt(Hz)'))
        gyros.append(AxisFit(nominal=opt, optimised=opt,
                             model=AxisNoise(N=n, B=3e-4, T_B=60.0), terms=fit.terms,
                             notes=(), tau_s=tau, avar_meas=avar))
    accels = [_fit(6e-4, 8e-6)] * 3
    bound = np.sqrt(np.min(3.0 * avar / tau))
    assert report_axis(gyros[0]).random_walk.kind == 'curve_bound'
    assert_allclose(report_axis(gyros[0]).random_walk.value, bound, rtol=1e-12)
    text = kalibr_yaml(gyros + accels, rate_hz=100.0)
    doc = yaml.safe_load(text)
    assert doc['gyroscope_random_walk'] >= bound
    assert "(the curve's bound)" in text
    assert all(v > 0 for k, v in doc.items() if k.endswith(('density', 'walk')))


def test_robot_localization_covariance_is_n2_rate_and_clamped():
    sources = _six()
    sources = dict(sources, accel_y=AxisNoise(N=1e-6))  # variance 1e-10 at 100 Hz
    cov = imu_covariance(sources, rate_hz=100.0)
    assert_allclose(cov.angular_velocity_variance, [1.44e-8 * 100.0] * 3, rtol=1e-12)
    assert_allclose(cov.linear_acceleration_variance, [3.6e-7 * 100.0, 1e-9, 3.6e-5],
                    rtol=1e-12)
    assert cov.clamped == ('accel_y',)
    field = np.array(cov.linear_acceleration_covariance).reshape(3, 3)
    assert_allclose(np.diag(field), cov.linear_acceleration_variance, rtol=0)
    assert not (field - np.diag(np.diag(field))).any()
    assert len(cov.angular_velocity_covariance) == 9


def test_notes_cover_the_packages():
    for name in ('Kalibr', 'OpenVINS', 'ORB-SLAM3', 'VINS-Mono', 'robot_localization',
                 'sqrt(IMU.Frequency)', '1e-9'):
        assert name in NOTES
