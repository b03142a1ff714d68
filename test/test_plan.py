"""
The planner against fits of simulated records; its command and the analysis' table.

Expected interval widths, times to targets, bounds, separations, targets, the plan
command and the plan table of the analysis.

Small seeded versions of bench/plan_validate.py (the full tables: docs/planning.md).
"""

import json
import math
import re

import numpy as np
from numpy.testing import assert_allclose
import pytest

from conftest import REPO
from imu_allan import AXES
from imu_allan.cli import main
from imu_allan.core.allan import allan_curve
from imu_allan.core.fit.result import Param
from imu_allan.core.noise.model import avar_model
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.shapes import GM_PEAK_TAU
from imu_allan.core.noise.simulate import simulate_axis, simulate_imu
from imu_allan.core.noise.values import AxisNoise, GaussMarkov, Sinusoid
from imu_allan.core.plan import (noise_components, parse_targets, plan_axes, plan_fits,
                                 planning_model)
from imu_allan.core.plan.precision import _avar, CurveModel, relative_width
from imu_allan.core.plan.result import AxisPlan, ParamPlan
from imu_allan.core.plan.separation import LAMBDA_SEPARATED, ORDERING, rivals, SLOW_PROCESS
from imu_allan.core.search import search_axis
from imu_allan.errors import InputError
from imu_allan.io.report import summary_text
from imu_allan.pipeline.analysis import analyze
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session
from imu_allan.ros.plan_report import targets_met


XSENS_GYRO = load_params(REPO / 'config' / 'xsens_mti7.yaml').axes['gyro_x']


def _model(noise: AxisNoise, rate_hz: float) -> CurveModel:
    return CurveModel(planning_model(noise_components(noise))[0], rate_hz)


def test_components_reproduce_the_model_curve():
    noise = AxisNoise(N=1e-4, B=5e-5, T_B=60.0, K=1e-6, Q=1e-6, R=1e-8)
    cm = _model(noise, 100.0)
    tau = np.geomspace(0.01, 1e4, 30)
    assert_rel = np.abs(_avar(cm.comps, cm.theta, tau) / avar_model(tau, noise) - 1.0)
    assert assert_rel.max() < 1e-12
    assert cm.names == ['Q', 'N', 'B', 'T_B', 'K', 'R']


def test_expected_widths_match_the_fits_of_simulated_records():
    """Median width of 6 seeded 40-min records within 25 % of the prediction (N, B)."""
    rate, length = 100.0, 2400.0
    widths = {'N': [], 'B': []}
    for seed in range(6):
        y = simulate_axis(XSENS_GYRO, rate, int(rate * length), np.random.default_rng(seed))
        c = allan_curve(y, rate, 'dense', confidence=0.95)
        fit = search_axis(c.tau_s, c.avar[:, 0], c.edf[:, 0], rate, y.size,
                          unit='rad/s').fit
        for p in widths:
            q = fit.optimised[p]
            widths[p].append(relative_width(q.value, q.ci95) if q.kind == 'estimate'
                             else math.inf)
    predicted = dict(zip(_model(XSENS_GYRO, rate).names,
                         _model(XSENS_GYRO, rate).widths(length)))
    for p, w in widths.items():
        # Tolerance: 6 seeds put the median's own spread at about 15 % for B.
        assert abs(np.median(w) / predicted[p] - 1.0) < 0.25, (p, w, predicted[p])


def test_time_to_target_is_where_the_expected_width_meets_it():
    plans = plan_axes({'g': planning_model(noise_components(XSENS_GYRO))}, 100.0, 0.0)
    cm = _model(XSENS_GYRO, 100.0)
    for p in plans['g'].params:
        assert p.kind == 'predicted' and math.isnan(p.width_now)
        if p.name == 'N':
            continue        # met at the first length (1 min)
        w = dict(zip(cm.names, cm.widths(p.time_s)))[p.name]
        # Tolerance: the log-log interpolation between grid lengths (3x apart).
        assert abs(w / p.target - 1.0) < 0.1, (p, w)
    # Widths fall with the record length; the defaults are 10 % for B, 25 % for T_B, K.
    b = plans['g'].param('B')
    assert b.widths_at[1.0] > b.widths_at[3.0] > b.widths_at[10.0]
    assert (b.target, plans['g'].param('K').target) == (0.1, 0.25)
    assert plans['g'].separations[0].question == 'ramp or random walk'
    assert 3600.0 < plans['g'].separations[0].time_s < plans['g'].param('K').time_s * 2


def test_a_bound_is_planned_at_its_bound_and_reads_at_least():
    rate = 100.0
    y = simulate_axis(XSENS_GYRO, rate, int(rate * 1200), np.random.default_rng(7))
    c = allan_curve(y, rate, 'dense', confidence=0.95)
    fit = search_axis(c.tau_s, c.avar[:, 0], c.edf[:, 0], rate, y.size, unit='rad/s').fit
    assert fit.optimised['K'].kind == 'upper_bound'     # 20 min cannot resolve K
    plan = plan_fits({'gyro_x': fit}, rate, 1200.0)['gyro_x']
    k = plan.param('K')
    assert k.kind == 'at_least' and math.isinf(k.width_now)
    assert k.value == fit.optimised['K'].value
    # N meets its target: its present width (the fit's interval) meets +-10 %.
    n = plan.param('N')
    assert n.kind == 'met' and n.time_s == 1200.0
    assert n.width_now == relative_width(fit.optimised['N'].value, fit.optimised['N'].ci95)
    assert 'K at least ' in plan.progress_line() or 'K only bounded' in plan.progress_line()


def test_a_parameter_the_model_cannot_plan_is_still_to_come():
    # 11 min of white noise and a 31 Hz line (the MPU-6050's gyro_z): the model has no
    # bias-instability or random-walk term, B is only bounded and K unconstrained.  The
    # plan once listed N and the line alone, read "every target met", and the node's
    # stop_when_met would have stopped there.
    rate, noise = 100.0, AxisNoise(N=1.7e-4, sinusoids=(Sinusoid(1.7e-3, 31.4),))
    y = simulate_axis(noise, rate, int(rate * 660), np.random.default_rng(0))
    c = allan_curve(y, rate, 'dense', confidence=0.95)
    fit = search_axis(c.tau_s, c.avar[:, 0], c.edf[:, 0], rate, y.size, unit='rad/s').fit
    assert fit.terms == ('white', 'sinusoid')
    assert (fit.optimised['B'].kind, fit.optimised['K'].kind) == ('upper_bound',
                                                                  'not_identified')
    plan = plan_fits({'gyro_z': fit}, rate, 660.0)['gyro_z']
    kinds = {p.name: p.kind for p in plan.params}
    assert kinds == {'N': 'met', 'B': 'at_least', 'T_B': 'open', 'K': 'open',
                     'sinusoid.A': 'met', 'sinusoid.f0_hz': 'met'}
    assert [p.name for p in plan.params][:4] == ['N', 'B', 'T_B', 'K']
    assert not plan.all_met() and not targets_met({'gyro_z': plan}, 1)
    assert math.isnan(plan.remaining_s())
    assert 'K not constrained yet' in plan.progress_line()
    assert 'B only bounded yet' in plan.progress_line()


def test_a_weaker_second_gauss_markov_needs_a_longer_record():
    def sep_time(b2: float) -> float:
        noise = AxisNoise(N=1e-4, B=5e-5, T_B=10.0, gauss_markov=(GaussMarkov(b2, 300.0),))
        plan = plan_axes({'a': planning_model(noise_components(noise))}, 50.0, 0.0)['a']
        (sep,) = [s for s in plan.separations if s.question == 'one or two Gauss-Markov']
        return sep.time_s
    assert 600.0 < sep_time(4e-5) < sep_time(2e-5) < math.inf


def _tied_plan(b2: float, t_b_kind: str = 'not_identified'):
    """Plan a bias instability and a second process whose present B intervals overlap."""
    noise = AxisNoise(N=1e-4, B=5e-5, T_B=10.0, gauss_markov=(GaussMarkov(b2, 300.0),))
    nan = math.nan
    t_b = (Param(10.0, (5.0, 20.0), 'estimate', 's') if t_b_kind == 'estimate'
           else Param(nan, (nan, nan), 'not_identified', 's'))
    present = {'B': Param(5e-5, (2.5e-5, 9e-5), 'estimate', 'rad/s'), 'T_B': t_b,
               'gauss_markov.B': Param(b2, (0.5 * b2, 1.5 * b2), 'estimate', 'rad/s')}
    return plan_axes({'a': planning_model(noise_components(noise))}, 50.0, 1800.0,
                     present={'a': present})['a']


def test_t_b_of_tied_processes_waits_until_their_levels_are_ordered():
    # The fit reports T_B not identified while another process's B interval reaches
    # B's (ambiguous_bias): T_B is known once the levels are ordered, not before.
    plan = _tied_plan(3e-5)
    (order,) = [s for s in plan.separations if s.question == ORDERING]
    assert not order.separated and 1800.0 < order.time_s < math.inf
    assert plan.param('T_B').time_s >= order.time_s
    # Levels about equal are never ordered: T_B is beyond any record.
    even = _tied_plan(4.9e-5)
    assert [s.time_s for s in even.separations if s.question == ORDERING] == [math.inf]
    assert even.param('T_B').kind == 'beyond'
    # A weaker second process is ordered sooner.
    (weaker,) = [s for s in _tied_plan(2e-5).separations if s.question == ORDERING]
    assert weaker.time_s < order.time_s
    # With T_B identified there is no such question.
    assert ORDERING not in {s.question for s in _tied_plan(3e-5, 'estimate').separations}


def test_k_found_replaceable_by_a_slower_process_waits_for_their_separation():
    noise = AxisNoise(N=1e-4, B=5e-5, T_B=10.0, K=2e-6)
    comps, bounds = planning_model(noise_components(noise))
    k = Param(3e-6, (0.0, 3e-6), 'upper_bound', 'rad/s/s^0.5')
    args = ({'a': (comps, bounds)}, 50.0, 3600.0)
    plain = plan_axes(*args, present={'a': {'K': k}})['a']
    slow = plan_axes(*args, present={'a': {'K': k}}, slow_process={'a'})['a']
    assert SLOW_PROCESS not in {s.question for s in plain.separations}
    (sep,) = [s for s in slow.separations if s.question == SLOW_PROCESS]
    # The rival turns over inside the present record; a longer one shows the curve
    # still rising.
    assert not sep.separated and sep.lambda_now < LAMBDA_SEPARATED
    assert 3600.0 < sep.time_s < math.inf
    assert slow.param('K').time_s >= sep.time_s
    (rival,) = [r for q, r in rivals(comps, 1e4, slow_peak_s=900.0) if q == SLOW_PROCESS]
    assert 'random_walk' not in [c.label for c in rival]
    assert GM_PEAK_TAU * rival[-1].phi[0] == pytest.approx(900.0, rel=1e-12)


def test_a_time_does_not_depend_on_where_the_length_grid_stops():
    # The plan reads the expected widths inflated by the fit's dispersion; the grid
    # must not stop where only the plain widths meet their targets (the time would
    # read 'beyond 1000 h').
    noise = AxisNoise(N=XSENS_GYRO.N, B=XSENS_GYRO.B, T_B=XSENS_GYRO.T_B)
    args = ({'a': planning_model(noise_components(noise))}, 100.0, 3600.0)
    usual = plan_axes(*args, inflations={'a': 1.7})['a']
    # An N target no record meets keeps the grid going to 1000 h.
    full = plan_axes(*args, targets={'N': 1e-9}, inflations={'a': 1.7})['a']
    plain = plan_axes(*args)['a']
    for name in ('B', 'T_B'):
        assert math.isfinite(full.param(name).time_s)
        assert usual.param(name).time_s == pytest.approx(full.param(name).time_s, rel=1e-9)
        # Widths ~ L^-1/2 once resolved: z 1.7x wider needs about 1.7^2 the record.
        assert 2.0 < usual.param(name).time_s / plain.param(name).time_s < 4.0


def test_the_plan_of_a_1_h_fit_agrees_with_the_plan_of_the_true_model():
    """As analyze plans it: the median over 4 seeded 1 h records within 1.5x (B, T_B)."""
    rate, targets = 100.0, {'B': 0.25, 'T_B': 0.5}
    true = plan_axes({'a': planning_model(noise_components(XSENS_GYRO))}, rate, 0.0,
                     targets)['a']
    times: dict = {'B': [], 'T_B': []}
    for seed in range(4):
        y = simulate_axis(XSENS_GYRO, rate, int(rate * 3600), np.random.default_rng(seed))
        c = allan_curve(y, rate, 'dense', confidence=0.95)
        fit = search_axis(c.tau_s, c.avar[:, 0], c.edf[:, 0], rate, y.size,
                          unit='rad/s').fit
        plan = plan_fits({'a': fit}, rate, 3600.0, targets)['a']
        for name in times:
            assert plan.param(name).kind == 'predicted'
            times[name].append(plan.param(name).time_s)
    for name, t in times.items():
        # The bench's factor (docs/planning.md).
        assert 1 / 1.5 < np.median(t) / true.param(name).time_s < 1.5, (name, t)


def test_curve_covariance_of_a_1000_h_record_at_1_khz():
    # The planner reaches 1000 h: 3.6e9 samples at 1 kHz, whose term counts multiplied
    # overflowed int64 and made Sigma indefinite (a traceback from a 20 min record).
    from imu_allan.core.fit.covariance import CurveCovariance
    from imu_allan.core.noise.terms import TERMS
    from imu_allan.core.plan.precision import fit_taus

    def first_variance(n: int) -> float:
        m, _ = fit_taus(1000.0, n)
        cov = CurveCovariance(m, np.maximum(n + 1 - 2 * m, 1), 1e-3, n)
        sigma = cov.sigma([TERMS['white']], np.array([1.0]), [()])
        assert np.all(np.diag(sigma) > 0)
        return float(sigma[0, 0])
    # White noise at the shortest tau: the variance falls as 1 / n (to 1e-6).
    n = 3_600_000_000
    assert_allclose(first_variance(n) * 16.0, first_variance(n // 16), rtol=1e-6)


def test_targets_parse_and_refuse():
    assert parse_targets('N=5%, K=0.3 T_B=none') == {'N': 0.05, 'K': 0.3, 'T_B': math.inf}
    assert parse_targets(['B=0.2']) == {'B': 0.2}
    for bad in ('N', 'N=0', 'N=abc', '=0.1'):
        with pytest.raises(InputError, match='PARAM=WIDTH'):
            parse_targets(bad)


def test_plan_command_from_datasheet_numbers(capsys):
    code = main(['plan', '--N', '0.041 deg/s/sqrt(Hz)', '--B', '0.011 deg/s', '--T_B', '60',
                 '--K', '1e-3 deg/s/sqrt(s)', '--rate', '100', '--target', 'B=20%',
                 '--format', 'json'])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0 and doc['targets']['B'] == 0.2 and doc['profile'] == 'full'
    params = doc['axes']['gyro']['params']
    assert set(params) == {'N', 'B', 'T_B', 'K'}
    assert params['B']['target'] == 0.2 and params['B']['time_s'] > 3600.0
    assert set(params['B']['widths_at_h']) == {'1', '3', '10'}
    assert main(['plan', '--rate', '100']) == 2
    assert 'nothing to plan from' in capsys.readouterr().err
    assert main(['plan', '--N', '1e-4']) == 2
    assert '--rate' in capsys.readouterr().err


def test_every_example_in_the_plan_help_is_accepted(capsys):
    from imu_allan.cli import build_parser
    from imu_allan.core.noise.units import to_si

    helps = {}
    parser = build_parser(['plan'])
    for action in parser._subparsers._group_actions[0].choices['plan']._actions:
        helps.update({opt: action.help for opt in action.option_strings})
    for flag in ('N', 'B', 'T_B', 'K'):
        examples = re.findall(r"'([^']+)'", helps[f'--{flag}'])
        assert examples, helps[f'--{flag}']
        # The first in gyro units, a second one 'for --sensor accel'.
        for value, sensor in zip(examples, ('gyro', 'accel')):
            assert to_si(value, flag, sensor) > 0, (flag, value)
            assert main(['plan', f'--{flag}', value, '--rate', '100', '--sensor', sensor]
                        + (['--B', '1e-4'] if flag == 'T_B' else [])) == 0, (flag, value)
    capsys.readouterr()
    for target in re.findall(r'e\.g\. (\S+) or (\S+) ', helps['--target'])[0]:
        assert parse_targets([target]), target


def test_analysis_plan_in_summary_json_and_plan_command(tmp_path, capsys):
    spec = load_params(REPO / 'config' / 'ublox_c102_f9r.yaml')
    t_s, y = simulate_imu(spec, 50.0, 600.0, seed=4)
    stamps = 1_700_000_000 * 10 ** 9 + np.round(t_s * 1e9).astype(np.int64)
    session = Session(SessionConfig())
    session.add(stamps, y)
    result = analyze(session, plan=True, plan_targets={'N': 0.05})
    assert set(result.plans) == {a for a, f in result.fits.items() if f is not None}
    doc = result.to_json()
    plan = doc['axes']['gyro_x']['plan']
    assert plan['params']['N']['target'] == 0.05 and plan['params']['N']['kind'] == 'met'
    assert plan['params']['B']['kind'] in ('predicted', 'at_least', 'beyond')
    text = summary_text(result)
    assert 'record length to reach each target' in text
    assert result.plans['gyro_x'].table_lines()[1] in text
    # Without plan=True nothing changes: no plan in the JSON.
    assert 'plan' not in analyze(session).to_json()['axes']['gyro_x']
    # The plan command on the same record as a CSV prints the same tables.
    from imu_allan.io.csv_io import write_csv
    path = tmp_path / 'short.csv'
    write_csv(path, t_s, y, AXES)
    capsys.readouterr()
    assert main(['plan', str(path), '--target', 'N=0.05']) == 0
    out = capsys.readouterr().out
    assert 'predicted from a record of 10.0 min at 50 Hz' in out
    assert result.plans['gyro_x'].table_lines()[0] in out and 'gyro_x: met: N' in out


def test_a_plan_from_a_model_that_does_not_hold_says_so():
    """White noise alone fitted to a Gauss-Markov curve: its plan carries a caveat."""
    from imu_allan.core.fit import fit_axis
    from imu_allan.core.fit.trust import judge_fit
    from imu_allan.ros.plan_report import progress_report, targets_met
    rate = 100.0
    y = simulate_axis(XSENS_GYRO, rate, int(rate * 1800), np.random.default_rng(3))
    c = allan_curve(y, rate, 'dense', confidence=0.95)
    args = (c.tau_s, c.avar[:, 0], c.edf[:, 0], rate, y.size)
    right = search_axis(*args, unit='rad/s').fit
    wrong = judge_fit(fit_axis(*args, terms=('white',), unit='rad/s'))
    assert right.model_consistent and not wrong.model_consistent
    plans = plan_fits({'gyro_x': right, 'gyro_y': wrong}, rate, 1800.0, {'N': 0.5})
    assert plans['gyro_x'].caveat == ''
    assert 'does not' in plans['gyro_y'].caveat
    assert plans['gyro_y'].to_json()['caveat'] == plans['gyro_y'].caveat
    assert plans['gyro_y'].table_lines()[-1] == f'  caveat: {plans["gyro_y"].caveat}'
    assert 'times may be short' in plans['gyro_y'].progress_line()
    assert 'model does not hold on gyro_y' in progress_report(plans)[0]
    # Every target met, but the model does not hold: no self-stop on it.
    met = plans['gyro_x']._replace(params=tuple(
        p._replace(kind='met') for p in plans['gyro_x'].params))
    assert targets_met({'gyro_x': met}, 1)
    assert not targets_met({'gyro_x': met._replace(caveat=plans['gyro_y'].caveat)}, 1)


def test_profiles_name_their_targets_and_explicit_targets_override_them():
    from imu_allan.core.plan.targets import PROFILES, profile_targets
    from imu_allan.core.plan.planner import target_of
    vio = profile_targets('vio')
    assert PROFILES['kalibr'] == vio and profile_targets(None) == PROFILES['full']
    assert [k for k, v in vio.items() if math.isfinite(v)] == ['N', 'K']
    # The extra terms follow '*': no target for vio, +-25 % for full.
    assert math.isinf(target_of('sinusoid.A', vio))
    assert target_of('sinusoid.A', profile_targets('full')) == 0.25
    assert profile_targets('vio', 'K=25%')['K'] == 0.25
    with pytest.raises(InputError, match='unknown target profile'):
        profile_targets('slam')


def test_times_read_more_and_total_and_extrapolations_read_at_least():
    from imu_allan.core.plan.result import more_total
    assert more_total(5.0 * 3600, 1.8 * 3600) == '3.2 h more (5 h total)'
    assert more_total(7200.0, 0.0) == '2 h total'
    assert more_total(math.inf, 60.0) == 'more than 1000 h'
    p = ParamPlan('K', 1e-3, 0.8, 0.25, 1320.0, 'predicted', {})
    # 22 min planned from 2 min: a lower limit; from 10 min: not.
    assert p.lower_limit(120.0) and not p.lower_limit(600.0)
    plan = AxisPlan(120.0, (p,), ())
    assert plan.progress_line() == 'met: none; K at least 20 min more (22 min total)'
    assert plan.lower_limit() and plan.to_json()['params']['K']['lower_limit']
