"""
The offline analysis on real recordings (../shared/realdata; skipped when absent).

* ROS 1 bags of driving robots: flagged as not stationary.
* An old-style (Foxy) rosbag2 sqlite3 bag without message definitions: its constant
  values come back exactly, and the constant axes are reported as frozen.
* An MPU-6050 CSV with bursty host-arrival stamps: analysed, the irregularity reported.
* The six ADIS16405 runs through multi-input analyze (comparison and spread table):
  about a minute of work, so only with ``IMU_ALLAN_SLOW_TESTS=1``.
"""

import json
import os

import numpy as np
import pytest

from imu_allan.cli import main
from imu_allan.io.inputs import open_input, stream_input
from imu_allan.pipeline.hygiene import SessionConfig


def _cli(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize('name, count, rate_hz', [('test1.bag', 11865, 30.0),
                                                  ('test2.bag', 3061, 50.0)])
def test_moving_robot_bags_are_flagged_not_stationary(shared_dir, name, count, rate_hz):
    bag = shared_dir / 'realdata' / 'ros1_moving_robot' / name
    with open_input(bag) as source:
        assert (source.kind, source.topic, source.n_messages) == ('ros1', '/imu/data', count)
        session = stream_input(source, SessionConfig())
    stats = session.stats
    assert stats.n_received == count
    assert stats.n_motion_events >= 1
    assert stats.n_motion_dropped > 0.9 * count   # nearly all of it is driving
    assert session.rate_hz == pytest.approx(rate_hz, rel=0.02)
    assert any('not stationary' in w for w in session.warnings)


def test_moving_robot_analysis_is_refused_for_too_little_still_data(shared_dir, tmp_path,
                                                                    capsys):
    # 2 % of the bag is still: exit code 3, one line, no consumer file.
    bag = shared_dir / 'realdata' / 'ros1_moving_robot' / 'test2.bag'
    code, out, err = _cli(['analyze', bag, '--out', tmp_path, '--format', 'json', '--no-plot'],
                          capsys)
    assert code == 3
    assert err.strip().splitlines()[-1].startswith('imu-allan: error: ')
    assert 'not enough still data' in err
    assert not (tmp_path / 'imu.yaml').exists()


def test_foxy_sqlite_bag_reads_its_exact_constant_values(shared_dir, tmp_path, capsys):
    bag = shared_dir / 'realdata' / 'rosbag2_foxy_db3' / 'rosbag2_test'
    with open_input(bag) as source:
        assert (source.kind, source.topic, source.n_messages) == ('sqlite3', '/imu', 1565)
        blocks = list(source.blocks())
        assert source.warnings == []
    stamps = np.concatenate([b[0] for b in blocks])
    samples = np.concatenate([b[1] for b in blocks])
    assert samples.shape == (1565, 6)
    assert (samples == [131.0, 132.0, 133.0, 151.0, 152.0, 153.0]).all()
    assert (np.diff(stamps) > 0).all()
    code, out, err = _cli(['analyze', bag, '--out', tmp_path, '--format', 'json', '--no-plot'],
                          capsys)
    assert code == 0
    doc = json.loads(out)
    assert doc['n_samples'] == 1565
    assert doc['sample_rate_hz'] == pytest.approx(25.0, rel=0.01)
    assert sorted(doc['hygiene']['frozen_axes']) == sorted(doc['axes'])
    assert all(doc['axes'][a]['params'] == {} for a in doc['axes'])


def test_irregular_mpu6050_csv_is_analysed_and_irregularity_reported(shared_dir, tmp_path,
                                                                     capsys):
    csv = shared_dir / 'realdata' / 'mpu6050_irregular' / 'mpu6050_static_11min.csv.gz'
    code, out, err = _cli(['analyze', csv, '--out', tmp_path, '--format', 'json', '--no-plot'],
                          capsys)
    assert code == 0
    doc = json.loads(out)
    assert doc['hygiene']['irregular_stamps'] is True
    assert doc['hygiene']['jitter_rel'] > 1.0
    assert any(w.startswith('irregular stamps') for w in doc['warnings'])
    assert 'irregular stamps' in err
    # Every row is used: bursty arrival stamps are no gaps (max step 0.5 s < 2 s).
    assert doc['n_samples'] == 65067 and doc['hygiene']['n_gaps'] == 0
    assert doc['sample_rate_hz'] == pytest.approx(99.3, abs=0.5)
    assert doc['hygiene']['n_motion_events'] == 0
    # A hobby-grade MEMS gyro: white noise of a few tenths of a degree per root hour.
    n_gyro = doc['axes']['gyro_x']['params']['N']['value'] * 180 / np.pi * 60
    assert 0.2 < n_gyro < 2.0


@pytest.mark.skipif(os.environ.get('IMU_ALLAN_SLOW_TESTS') != '1',
                    reason='about a minute of work; set IMU_ALLAN_SLOW_TESTS=1')
def test_six_adis16405_runs_comparison_and_spread(shared_dir, tmp_path, capsys):
    runs = [shared_dir / 'realdata' / 'adis16405' / f'adis16405_run{k}.csv.gz'
            for k in range(1, 7)]
    code, out, err = _cli(['analyze', *runs, '--out', tmp_path, '--format', 'json'], capsys)
    assert code == 0
    doc = json.loads(out)
    # Run 4's outlier rows are spikes, interpolated: every sample is used.
    assert [r['n_samples'] for r in doc['results']] == [1_000_000] * 6
    assert doc['results'][3]['hygiene']['n_spikes'] > 60
    assert any('spikes' in w for w in doc['results'][3]['warnings'])
    assert all(r['hygiene']['n_motion_events'] == 0 for r in doc['results'])
    spread = doc['comparison']['spread']
    # Datasheet: gyro noise density 0.05 deg/s/rtHz; the runs agree within a few %.
    n_gyro = np.degrees(spread['gyro_x']['N']['mean'])
    assert 0.02 < n_gyro < 0.1
    assert spread['gyro_x']['N']['cv'] < 0.1
    for name in ('comparison.md', 'comparison.png', 'comparison.svg'):
        assert (tmp_path / name).is_file()
