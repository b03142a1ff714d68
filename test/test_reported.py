"""
Tests of imu_allan.core.outputs.reported: one decision per parameter, read by every output.

The invariant: change one fitted value and every output that carries it changes with
it, by the same rule; the outputs that do not carry it stay byte for byte the same.
"""

from dataclasses import replace
import math

import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

from conftest import REPO
from imu_allan import AXES, GYRO_AXES
from imu_allan.core.fit import Param
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.outputs.covering import N_MARGIN
from imu_allan.core.outputs.reported import report_axes, report_axis
from imu_allan.io.report import distinct_notes, kalman_yaml, summary_text
from imu_allan.pipeline.analysis import analyze
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session

RATE_HZ = 50.0


@pytest.fixture(scope='module')
def result():
    """Analyse a 20 min simulated u-blox record through the pipeline (seeded)."""
    spec = load_params(REPO / 'config' / 'ublox_c102_f9r.yaml')
    t_s, y = simulate_imu(spec, RATE_HZ, 1200.0, seed=7)
    stamps = 1_700_000_000 * 10 ** 9 + np.round(t_s * 1e9).astype(np.int64)
    session = Session(SessionConfig())
    session.add(stamps, y)
    return analyze(session)


def _cv_real(text: str, key: str) -> float:
    """Read a key of an OpenCV FileStorage file (the VIO files) by plain YAML."""
    body = text.split('\n', 1)[1]                     # after %YAML:1.0
    doc = yaml.safe_load(body)
    return float(doc['imu0'][key] if 'imu0' in doc else doc[key])


def _outputs(res) -> dict:
    """Every output that carries a value, as the user gets it."""
    return {'kalibr': yaml.safe_load(res.kalibr_yaml()), 'vins': res.vins_yaml(),
            'openvins': res.openvins_yaml(), 'ekf': res.robot_localization_yaml(),
            'driver': res.driver_yaml(), 'kalman': yaml.safe_load(kalman_yaml(res)),
            'json': res.to_json(), 'summary': summary_text(res),
            'status': {a: dict(res.axis_status(a)[2]) for a in AXES}}


def _consistent(res, out: dict) -> None:
    """Every random-walk consumer writes the same covering pair; Q/R the reports."""
    gyro_k = max(res.covers[a].K_cover for a in GYRO_AXES)
    gyro_n = max(res.covers[a].N_cover for a in GYRO_AXES)
    assert_allclose(out['kalibr']['gyroscope_random_walk'], gyro_k, rtol=1e-6)
    assert_allclose(out['kalibr']['gyroscope_noise_density'], gyro_n, rtol=1e-6)
    assert_allclose(_cv_real(out['openvins'], 'gyroscope_random_walk'), gyro_k, rtol=1e-6)
    assert_allclose(_cv_real(out['vins'], 'gyr_w'), gyro_k * math.sqrt(res.rate_hz),
                    rtol=1e-6)
    for i, a in enumerate(AXES):
        r = res.reports[a]
        assert_allclose(res.kalman.Qc[2 * i + 1, 2 * i + 1], r.random_walk.value ** 2,
                        rtol=1e-12)
        assert_allclose(res.kalman.Rc[i, i], r.white.value ** 2, rtol=1e-12)
        c = res.covers[a]
        assert c.K_cover >= r.random_walk.value and c.N_cover >= r.white.value
        assert out['json']['axes'][a]['params'] == {
            s: p.to_json() for s, p in r.params.items()}
        # A T_B the report does not identify never reaches the Kalman model.
        t_b = r.params['T_B']
        if t_b.kind == 'not_identified':
            assert res.kalman.axes[i].T_B is None and res.kalman.Phi[2 * i, 2 * i] == 1.0


def test_a_changed_k_changes_every_output_that_carries_it_and_no_other(result):
    before = _outputs(result)
    _consistent(result, before)
    fit = result.fits['gyro_x']
    k = fit.optimised['K']
    k_new = 40.0 * (k.value if math.isfinite(k.value) else 1e-5)
    fits = dict(result.fits, gyro_x=replace(fit, optimised=dict(
        fit.optimised, K=Param(k_new, (0.5 * k_new, 2.0 * k_new), 'estimate', k.unit))))
    changed = replace(result, fits=fits)
    after = _outputs(changed)
    _consistent(changed, after)
    assert changed.reports['gyro_x'].random_walk.value >= k_new
    assert after['kalibr']['gyroscope_random_walk'] >= k_new
    assert after['kalibr']['gyroscope_random_walk'] > before['kalibr']['gyroscope_random_walk']
    assert after['json']['axes']['gyro_x']['params']['K']['value'] == k_new
    assert after['status']['gyro_x']['K'] == f'{k_new:.6g}'
    assert after['summary'] != before['summary']
    # The files that hold no random walk are the same byte for byte.
    for key in ('ekf', 'driver'):
        assert after[key] == before[key]
    # The other axes' reports are untouched.
    for a in AXES[1:]:
        assert changed.reports[a].random_walk == result.reports[a].random_walk


def test_covering_pair_is_never_below_the_reported_pair_at_any_horizon(result):
    for tau_max in (1.0, 10.0, 30.0, 100.0, 1000.0):
        res = replace(result, covering_tau_max_s=tau_max)
        for a in AXES:
            r, c = res.reports[a], res.covers[a]
            assert c.K_cover >= r.random_walk.value, (tau_max, a)
            assert c.N_cover >= N_MARGIN * r.white.value * (1 - 1e-12), (tau_max, a)


def test_a_bare_model_reports_its_values_and_what_the_filter_leaves_out():
    from imu_allan.core.noise.values import GaussMarkov, Sinusoid
    noise = AxisNoise(N=1e-4, B=5e-5, T_B=80.0, K=2e-6,
                      gauss_markov=(GaussMarkov(B=1e-5, T=500.0),),
                      sinusoids=(Sinusoid(A=1e-4, f0_hz=20.0),))
    r = report_axis(noise, 'gyro_x')
    assert r.white == (1e-4, 'estimate', '') and r.random_walk == (2e-6, 'estimate', '')
    assert r.gauss_markov.T_B == 80.0 and r.gauss_markov.B == 5e-5
    assert [x.split(' ')[0] for x in r.left_out] == ['gauss_markov', 'sinusoid']
    assert r.params['N'].value == 1e-4 and r.params['T_B'].value == 80.0
    # A report is decided once: deciding it again returns the same object.
    assert report_axis(r) is r
    assert set(report_axes({'gyro_x': r, 'gyro_y': None})) == {'gyro_x', 'gyro_y'}


def test_the_summary_marks_bounds_both_ways(result):
    # An upper bound reads '<', a lower bound (a T_B beyond the record) '>'.
    fit = result.fits['gyro_x']
    t_b = Param(300.0, (40.0, math.inf), 'lower_bound', 's', 'fitted',
                'may exceed the longest tau of the record: lower bound')
    k = Param(2e-5, (0.0, 2e-5), 'upper_bound', fit.optimised['K'].unit)
    changed = replace(result, fits=dict(result.fits, gyro_x=replace(
        fit, optimised=dict(fit.optimised, T_B=t_b, K=k))))
    line = changed.summary_line('gyro_x')
    assert 'K < ' in line
    # A lower bound states its interval's lower end (the fit's value said 'T_B > 300 s'
    # where the record supports 40 s at 95 %).
    assert 'T_B > 40 s (fit 300 s)' in line, line


def test_the_summary_gives_each_estimate_its_interval_and_a_floor_only_where_measured(result):
    for axis in AXES:
        report = result.reports[axis]
        parts = dict(part.split(' ', 1) for part in
                     result.summary_line(axis).split(': ', 1)[1].split('; '))
        for sym in ('N', 'B', 'K', 'T_B'):
            p = report.params[sym]
            text = parts[sym]
            if p.kind == 'estimate':
                lo, hi = (float(v) for v in text.split('[')[1].split(']')[0].split(', '))
                assert lo <= float(text.split()[0]) <= hi, (axis, sym, text)
            else:
                assert text[0] == {'upper_bound': '<', 'lower_bound': '>',
                                   'not_identified': 'n'}[p.kind], (axis, sym, text)
        # The gyro N also in a datasheet's unit (deg/s/sqrt(Hz)).
        if axis in GYRO_AXES:
            assert f'({math.degrees(report.params["N"].value):.3g} deg/s/sqrt(Hz))' in parts['N']
        floor = report.floor
        assert ('floor' in parts.get('ADEV', '')) == (floor is not None)
        if floor is not None:
            assert floor.ci95[1] / floor.ci95[0] <= 2.0 and floor.tau_s < result.curve.tau_s[-1]
    text = summary_text(result)
    assert "'<' an upper bound" in text and text.rstrip().splitlines()[-1].startswith('B conv')


def test_notes_are_told_once_whatever_their_figures():
    notes = ['sinusoid at 10.1 Hz (A 0.0076) fits the curve; not added',
             'sinusoid at 10.1 Hz (A 0.0079) fits the curve; not added',
             'K: its 95 % interval reaches 0']
    assert distinct_notes(notes) == [notes[0], notes[2]]
