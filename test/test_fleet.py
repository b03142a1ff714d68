"""
Tests of imu-allan fleet on a real Dask LocalCluster.

The cluster's worker processes talk over loopback; the inputs are simulated MCAP bags of
several IMUs; the Parquet store and the fleet views are checked on what it produced.
"""

import json
import math
import os
from pathlib import Path
import shutil
import signal

import numpy as np
import pytest

from conftest import T0_NS
from imu_allan import AXES
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.values import AxisNoise, NoiseSpec
from imu_allan.errors import InputError
from imu_allan.fleet.inputs import content_key, fleet_inputs
from imu_allan.fleet.report import fleet_summary, write_fleet_report
from imu_allan.fleet.run import connect, run_fleet
from imu_allan.fleet.store import FleetStore
from imu_allan.fleet.task import analyze_job, FleetJob
from imu_allan.fleet.views import changes, fleet_spread
from imu_allan.io.bag_writer import write_imu_bag
from imu_allan.pipeline.hygiene import SessionConfig

RATE_HZ = 200.0
DURATION_S = 120.0
N_IMUS, N_NIGHTS = 4, 5
#: IMU 2's white noise is raised 30 % from this night on.
DEGRADED_IMU, DEGRADED_FROM = 2, 3
PATTERN = r'robot(?P<imu>\d+)'


def _spec(scale: float = 1.0) -> NoiseSpec:
    gyro = AxisNoise(N=3e-4 * scale, B=2e-5, T_B=20.0, K=2e-6)
    accel = AxisNoise(N=1.5e-3 * scale, B=1e-4, T_B=30.0, K=5e-5)
    return NoiseSpec('sim', {a: gyro if a.startswith('gyro') else accel for a in AXES})


def _write(path: Path, night: int, seed: int, scale: float = 1.0, moving: bool = False):
    t, y = simulate_imu(_spec(scale), RATE_HZ, DURATION_S, seed=seed)
    y[:, 5] += 9.81
    if moving:   # a robot driving around: turns and accelerations far above the noise
        y[:, 2] += 0.5 * np.sin(2 * np.pi * 0.05 * t)
        y[:, 3] += 1.0 * np.sin(2 * np.pi * 0.11 * t)
    stamps = T0_NS + night * 86400 * 10 ** 9 + np.round(t * 1e9).astype(np.int64)
    write_imu_bag(path, stamps, y, frame_id=f'imu_{path.parent.name}')


@pytest.fixture(scope='module')
def bags(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp('fleet_bags')
    for imu in range(N_IMUS):
        for night in range(N_NIGHTS):
            scale = 1.3 if imu == DEGRADED_IMU and night >= DEGRADED_FROM else 1.0
            _write(root / f'robot{imu}' / f'night{night}.mcap', night, 100 * imu + night,
                   scale)
    _write(root / 'robot9' / 'night0.mcap', 0, 999, moving=True)
    (root / 'robot8').mkdir()
    (root / 'robot8' / 'night0.mcap').write_bytes(b'\x89MCAP0\r\n' + bytes(range(256)) * 8)
    return root


@pytest.fixture(scope='module')
def cluster_client():
    client, cluster = connect(n_workers=2, memory_limit='3GiB')
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope='module')
def fleet_run(bags, cluster_client, tmp_path_factory):
    store = FleetStore(tmp_path_factory.mktemp('store'))
    inputs = fleet_inputs([str(bags)], id_pattern=PATTERN)
    summary = run_fleet(inputs, store, cluster_client)
    return inputs, store, summary


def test_the_cluster_gives_what_sequential_analyze_gives(fleet_run):
    inputs, store, summary = fleet_run
    assert len(inputs) == N_IMUS * N_NIGHTS + 2
    assert (summary.n_ok, summary.n_failed, summary.n_skipped) == (N_IMUS * N_NIGHTS, 2, 0)
    stored = {(r['key'], r['axis']): r for r in store.rows('ok')}
    assert len(stored) == 6 * N_IMUS * N_NIGHTS
    for inp in inputs:
        if 'robot8' in inp.path or 'robot9' in inp.path:
            continue
        key = content_key(inp.path)
        _, status, rows = analyze_job(FleetJob(inp.path, key, inp.imu_id, inp.model, None,
                                               SessionConfig()))
        assert status == 'ok'
        for row in rows:
            got = stored[(key, row['axis'])]
            for col in ('N', 'N_lo', 'N_hi', 'B', 'B_hi', 'K', 'T_B', 'start_ns',
                        'n_samples', 'imu_id', 'frame_id', 'effects'):
                assert got[col] == row[col] or (
                    isinstance(row[col], float) and math.isnan(row[col])
                    and math.isnan(got[col])), (inp.path, row['axis'], col)


def test_failed_inputs_are_listed_with_their_reason(fleet_run):
    _, store, _ = fleet_run
    failed = {Path(r['path']).parent.name: r['reason'] for r in store.rows('failed')}
    assert set(failed) == {'robot8', 'robot9'}
    assert 'MCAP' in failed['robot8'] or 'damaged' in failed['robot8']
    assert 'moved' in failed['robot9'] or 'motion' in failed['robot9'] \
        or 'usable' in failed['robot9']
    assert all('\n' not in reason for reason in failed.values())


def test_the_degraded_imu_is_flagged_and_the_clean_ones_are_not(fleet_run):
    _, store, _ = fleet_run
    rows = store.rows()
    moved = changes(rows)
    n_moves = {(c.imu_id, c.axis) for c in moved if c.param == 'N'}
    assert n_moves == {(str(DEGRADED_IMU), a) for a in AXES}
    assert all(abs(c.ratio / 1.3 - 1) < 0.05 for c in moved if c.param == 'N')
    assert all(c.start_ns >= T0_NS + DEGRADED_FROM * 86400 * 10 ** 9 for c in moved)
    for clean in ('0', '1'):
        assert not [c for c in moved if c.imu_id == clean]
    outliers = {o.imu_id for s in fleet_spread(rows) for o in s.outliers if o.param == 'N'}
    assert outliers == {str(DEGRADED_IMU)}


def test_a_rerun_skips_by_content_and_a_copy_is_not_counted_twice(
        fleet_run, bags, cluster_client, tmp_path):
    inputs, store, _ = fleet_run
    n_files = len(list(store.results.glob('*.parquet')))
    copy = tmp_path / 'renamed_robot0' / 'other_name.mcap'
    copy.parent.mkdir()
    shutil.copy(bags / 'robot0' / 'night0.mcap', copy)
    again = run_fleet(inputs + fleet_inputs([str(copy)], model='default'), store,
                      cluster_client)
    assert (again.n_ok, again.n_failed, again.n_skipped) == (0, 0, len(inputs) + 1)
    assert len(list(store.results.glob('*.parquet'))) == n_files


def test_the_report_names_the_change(fleet_run, tmp_path):
    _, store, _ = fleet_run
    files = write_fleet_report(store.rows(), tmp_path / 'report')
    names = {f.name for f in files}
    assert {'fleet.json', 'fleet_report.md', 'fleet_N.png', 'trend_N.png'} <= names
    text = (tmp_path / 'report' / 'fleet_report.md').read_text()
    assert f'| {DEGRADED_IMU} | gyro_x | N |' in text and 'robot8' in text
    summary = fleet_summary(store.rows())
    assert summary['inputs']['ok'] == N_IMUS * N_NIGHTS and len(summary['failures']) == 2


def test_a_killed_worker_has_its_inputs_retried_and_nothing_counted_twice(tmp_path, bags):
    store = FleetStore(tmp_path / 'store')
    inputs = fleet_inputs([str(bags / f'robot{i}') for i in (0, 1)], id_pattern=PATTERN)
    client, cluster = connect(n_workers=2, memory_limit='3GiB')
    killed = []

    def kill_one(key, status, rows):
        if not killed:   # both workers are busy with the next inputs now
            pids = client.run(os.getpid)
            pid = sorted(pids.values())[0]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
    try:
        summary = run_fleet(inputs, store, client, on_record=kill_one)
    finally:
        client.close()
        cluster.close()
    assert killed
    assert (summary.n_ok, summary.n_failed) == (len(inputs), 0)
    rows = store.rows()
    keys = [r['key'] for r in rows]
    assert len(set(keys)) == len(inputs)
    assert all(keys.count(k) == 6 for k in set(keys))
    assert sorted((r['key'], r['axis']) for r in rows) == sorted(
        {(r['key'], r['axis']) for r in rows})


def _row(imu, night, n, lo, hi, axis='gyro_x'):
    return {'status': 'ok', 'imu_id': imu, 'model': 'm', 'axis': axis, 'key': f'{imu}{night}',
            'path': f'{imu}/{night}', 'start_ns': night, 'N': n, 'N_lo': lo, 'N_hi': hi,
            'N_kind': 'estimate'}


def test_the_change_test_weighs_the_intervals():
    # The same 30 % jump: flagged with 1 % intervals, not with 40 % ones.
    narrow = [_row('a', k, v, 0.99 * v, 1.01 * v) for k, v in enumerate([1, 1, 1.3])]
    wide = [_row('b', k, v, 0.6 * v, 1.4 * v) for k, v in enumerate([1, 1, 1.3])]
    moved = changes(narrow + wide, params=('N',))
    assert [(c.imu_id, c.start_ns) for c in moved] == [('a', 2)]
    assert moved[0].ratio == pytest.approx(1.3, rel=1e-9)
    # A significant but tiny move (2 %) is below MIN_CHANGE.
    assert not changes([_row('c', k, v, 0.999 * v, 1.001 * v)
                        for k, v in enumerate([1, 1, 1.02])], params=('N',))


def test_an_outlier_needs_siblings_and_a_narrow_interval():
    fleet = [_row(f'i{k}', 0, v, 0.98 * v, 1.02 * v) for k, v in
             enumerate([1.0, 1.01, 0.99, 1.0, 1.02])]
    odd = _row('odd', 0, 1.5, 1.47, 1.53)
    vague = _row('vague', 0, 1.5, 0.5, 4.0)
    names = {o.imu_id for s in fleet_spread(fleet + [odd, vague], params=('N',))
             for o in s.outliers}
    assert names == {'odd'}
    assert not [o for s in fleet_spread(fleet[:2] + [odd], params=('N',)) for o in s.outliers]


def test_inputs_from_a_manifest_and_bad_patterns(tmp_path, bags):
    manifest = tmp_path / 'fleet.csv'
    manifest.write_text(f'path,imu_id,model\n{bags}/robot1/night0.mcap,front,xsens\n')
    got = fleet_inputs([str(bags / 'robot1')], manifest=manifest)
    assert got[0].imu_id == 'front' and got[0].model == 'xsens'
    assert {g.imu_id for g in got[1:]} == {''} and len(got) == N_NIGHTS
    with pytest.raises(InputError, match='does not match'):
        fleet_inputs([str(bags / 'robot1')], id_pattern=r'truck(\d+)')
    with pytest.raises(InputError, match='no input matches'):
        fleet_inputs([str(tmp_path / 'none*.mcap')])
    bad = tmp_path / 'bad.yaml'
    bad.write_text('- {path: x.mcap}\n')
    with pytest.raises(InputError, match='needs a path and an imu_id'):
        fleet_inputs([], manifest=bad)


def test_without_a_pattern_the_imu_is_the_topic_and_frame(bags):
    path = str(bags / 'robot3' / 'night0.mcap')
    _, status, rows = analyze_job(FleetJob(path, 'k', '', 'm', None, SessionConfig()))
    assert status == 'ok'
    assert {r['imu_id'] for r in rows} == {'/imu/data@imu_robot3'}


def test_the_store_replaces_a_failure_by_its_result(tmp_path):
    store = FleetStore(tmp_path)
    store.write('abc', 'failed', [{'key': 'abc', 'path': 'p', 'status': 'failed',
                                   'reason': 'boom'}])
    assert store.done() == {'abc': 'failed'}
    store.write('abc', 'ok', [{'key': 'abc', 'status': 'ok', 'axis': a, 'N': 1.0}
                              for a in AXES])
    assert store.done() == {'abc': 'ok'}
    rows = store.rows()
    assert len(rows) == 6 and rows[0]['N'] == 1.0 and math.isnan(rows[0]['B'])
    assert not list(tmp_path.glob('results/.*'))   # no temporary files left


def test_the_command_reports_a_store_and_fails_in_one_line(fleet_run, tmp_path, capsys):
    from imu_allan.cli import main

    _, store, _ = fleet_run
    assert main(['fleet', '--store', str(store.root), '--report-only', '--format', 'json',
                 '--no-plot', '--report', str(tmp_path / 'r')]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc['run'] is None and doc['views']['inputs']['failed'] == 2
    assert main(['fleet', '--store', str(tmp_path / 'empty'), '--report-only']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'holds no results yet' in err[0]
    assert main(['fleet', str(tmp_path / 'nothing*.mcap'), '--store', str(tmp_path / 's')]) == 2
    assert 'no input matches' in capsys.readouterr().err
