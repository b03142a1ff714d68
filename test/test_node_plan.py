"""
The node's precision plan with real rclpy: statuses, progress, and the self-stop.

Uses the rig of test_node.py (a node and a peer on SingleThreadedExecutors in threads);
the records reach the node's subscription callback as the serialized messages DDS would
deliver (``Rig.deliver``: hours of messages in seconds; test_node.py tests the transport).
"""

import math
from pathlib import Path
import time

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
from rclpy.parameter import Parameter
from test_node import context, rig, statuses, wait  # noqa: F401 - fixtures

from conftest import T0_NS
from imu_allan.core.noise.params import load_params, parse_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.plan import plan_fits
from imu_allan.ros import plan_report

#: A strong bias instability with T_B under a second: 200 s at 200 Hz estimate N, B and
#: T_B (K, with B this strong, stays a bound on most axes).
FAST = parse_params({'name': 'fast IMU', 'axes': {
    'gyro': {'N': 2e-3, 'B': 1e-2, 'T_B': 0.5, 'K': 1e-3},
    'accel': {'N': 4e-3, 'B': 2e-2, 'T_B': 1.0, 'K': 2e-3},
    'accel_z': {'bias': 9.80665}}})


def _record(duration_s: float, seed: int = 3):
    t_s, y = simulate_imu(FAST, 200.0, duration_s, seed=seed)
    return T0_NS + np.round(t_s * 1e9).astype(np.int64), y


def test_statuses_and_progress_carry_the_plan(rig):  # noqa: F811
    r = rig(plan_period_s=0.001, progress_period_s=3600.0)
    diag = []
    r.peer.create_subscription(DiagnosticArray, '/diagnostics', diag.append, 10)
    r.deliver(*_record(200.0))
    result = r.publish()
    assert result.plans and set(result.plans) == {a for a, f in result.fits.items() if f}
    st = statuses(r.last('noise_parameters'))
    # The statuses carry the same plan as the analysis, and the offline planner gives it.
    offline = plan_fits(result.fits, result.rate_hz, result.duration_s)
    for axis, plan in result.plans.items():
        kv = st[f'imu_allan: {axis}'][2]
        for p in plan.params:
            assert kv[f'{p.name}_plan'] == p.kind
            assert _same(float(kv[f'{p.name}_time_to_target_s']), p.time_s)
            assert _same(offline[axis].param(p.name).time_s, p.time_s)
            # A parameter not meeting its target yet needs more than the present record
            # (or is a bound).
            assert p.kind == 'met' or not p.time_s < result.duration_s
        assert kv['plan'] == plan.progress_line()
        # N of this sensor meets +-10 % within seconds.
        assert kv['N_plan'] == 'met' and float(kv['N_width_now']) < 0.1
    waiting = [a for a, p in result.plans.items() if not p.all_met()]
    assert waiting                                # K, at least, is far from +-25 %
    assert not r.node.collection_stopped          # stop_when_met is off by default
    # The progress status says per axis what meets its target and how long the rest takes.
    wait(lambda: any('imu_allan: progress' in statuses(a) and 'met: N' in
                     statuses(a)['imu_allan: progress'][1] for a in list(diag)), 10,
         'a progress status with the plan')
    prog = [statuses(a)['imu_allan: progress'] for a in list(diag)
            if 'met: N' in statuses(a).get('imu_allan: progress', (0, ''))[1]][-1]
    for axis in waiting:
        assert f'{axis} {result.plans[axis].progress_line()}' in prog[1]
    for axis in result.plans:
        assert 'N' in prog[2][f'{axis}_met'].split(',')


def _same(a: float, b: float) -> bool:
    """Equal to 1e-5, or both NaN, or both infinite."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a / b - 1.0) < 1e-5


def test_stop_when_met_stops_collecting_after_the_floor(rig):  # noqa: F811
    # The vio profile waits for N and K only; K of 200 s stays a bound (a slower
    # Gauss-Markov process could stand in for the random walk: hours to tell), so K's
    # target is lifted here: what is tested is that the profile's targets decide.
    r = rig(plan_period_s=0.001, stop_when_met=True, plan_profile='vio',
            plan_targets='K=none', min_duration_s=1000.0)
    t, y = _record(300.0)
    r.deliver(t[:40000], y[:40000])
    result = r.publish()
    # min_duration_s is a floor: 200 s of data, targets met or not, collection goes on.
    assert not r.node.collection_stopped
    r.node.set_parameters([Parameter('min_duration_s', value=100.0)])
    result = r.publish()
    assert all(p.all_met() for p in result.plans.values()), \
        {a: p.progress_line() for a, p in result.plans.items()}
    assert r.node.collection_stopped
    n_used = r.node.session.stats.n_used
    r.deliver(t[40000:], y[40000:])               # received, but no longer collected
    r.node.live.process()
    assert r.node.session.stats.n_used == n_used
    level, message, kv = statuses(r.last('noise_parameters'))['imu_allan: gyro_x']
    assert kv['plan'].startswith('met: ') and kv['plan_remaining_s'] == '0'
    assert 'stopped collecting: vio targets (N) met' in r.node.reports.progress_status().message
    # ~/reset starts over: collecting again.
    r.node.service_handlers.on_reset(None, type('R', (), {})())
    assert not r.node.collection_stopped


#: The README's simulated MTi-7 (paper table 2) at 2 Hz: hours of stamps in seconds of
#: messages.  The vio targets (N +-10 %, K +-50 %) need about 16 h on its gyros.
MTI7 = load_params(Path(__file__).resolve().parents[1] / 'config' / 'xsens_mti7.yaml')


@pytest.mark.slow
def test_the_vio_profile_stops_by_itself_once_n_and_k_of_an_mti7_are_met(rig):  # noqa: F811
    r = rig(plan_period_s=0.001, stop_when_met=True, plan_profile='vio',
            min_duration_s=3600.0)
    t_s, y = simulate_imu(MTI7, 2.0, 20 * 3600.0, seed=4)
    t_ns = T0_NS + np.round(t_s * 1e9).astype(np.int64)
    half = t_s.size // 2
    r.deliver(t_ns[:half], y[:half])
    result = r.publish()
    # 10 h: N is met on every axis, K not yet on some: collection goes on.
    assert all(p.param('N').kind == 'met' for p in result.plans.values())
    assert not all(p.all_met() for p in result.plans.values())
    assert not r.node.collection_stopped
    r.deliver(t_ns[half:], y[half:])
    result = r.publish()
    # 20 h: K meets +-50 % too; the node stops collecting and says so.
    assert all(p.all_met() for p in result.plans.values()), \
        {a: p.progress_line() for a, p in result.plans.items()}
    assert all(result.reports[a].params['K'].kind == 'estimate' for a in result.plans)
    assert r.node.collection_stopped
    assert ('stopped collecting: vio targets (N, K) met'
            in r.node.reports.progress_status().message)
    n_used = r.node.session.stats.n_used
    r.deliver(t_ns[-10:] + 10 ** 10, y[-10:])     # received, no longer collected
    r.node.live.process()
    assert r.node.session.stats.n_used == n_used


def test_the_old_name_stop_when_pinned_is_read_with_a_warning(rig, capfd):  # noqa: F811
    # Renamed with the plan's 'met': a parameter file of the last release still stops.
    r = rig(stop_when_pinned=True)
    assert r.node.values['stop_when_met'] is True
    assert 'the parameter stop_when_pinned is now stop_when_met' in capfd.readouterr().err


def test_the_first_plan_comes_before_min_duration_and_counts_toward_the_profile(
        rig, monkeypatch):  # noqa: F811
    # The first plan after FIRST_PLAN_S (shortened here), well within plan_period_s
    # and long before min_duration_s; nothing is published before that floor.
    monkeypatch.setattr(plan_report, 'FIRST_PLAN_S', 1.0)
    r = rig(plan_profile='vio', plan_period_s=300.0, publish_period_s=0.5,
            min_duration_s=1.0e5)
    started = time.monotonic()
    r.deliver(*_record(120.0))
    wait(lambda: bool(r.node.reports.plans), 120, 'the first plan')
    assert time.monotonic() - started < 300.0
    assert r.node.n_fits == 0 and r.last('noise_parameters') is None
    plans = r.node.reports.plans
    message = r.node.reports.progress_status().message
    assert 'vio targets (N, K): ' in message and ' total)' in message, message
    # Only N and K carry targets: B and T_B are met by definition.
    for plan in plans.values():
        assert plan.param('B').kind == 'met' and math.isinf(plan.param('B').target)
    # 2 min of data cannot promise K: every time of it is a lower limit.
    more_s, total_s, at_least = plan_report.remaining(plans)
    assert at_least and 'at least' in message
    kv = dict(plan_report.progress_report(plans)[1])
    assert kv['plan_lower_limit'] == 'true'
