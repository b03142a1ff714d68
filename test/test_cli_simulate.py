"""Tests of ``imu-allan simulate`` (CSV and bag outputs) and ``imu-allan csv-to-bag``."""

from pathlib import Path
import time

import numpy as np
from numpy.testing import assert_array_equal
import pytest
from rosbags.highlevel import AnyReader

from imu_allan import AXES
from imu_allan.cli import main
from imu_allan.core.noise.params import load_params
from imu_allan.io.bag_reader import open_imu
from imu_allan.io.csv_io import read_csv, write_csv
from imu_allan.io.inputs import open_input

REPO = Path(__file__).resolve().parents[1]
PARAMS = REPO / 'config' / 'xsens_mti7.yaml'


def _cli(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, [line for line in err.splitlines() if line.strip()]


def _read(path):
    with open_input(path) as source:
        blocks = list(source.blocks())
        kind = source.kind
    return (kind, np.concatenate([b[0] for b in blocks]),
            np.concatenate([b[1] for b in blocks]))


@pytest.mark.parametrize('name, kind', [('sim.mcap', 'mcap'), ('sim.db3', 'sqlite3'),
                                        ('simdir', 'mcap'), ('sim.bag', 'ros1')])
def test_simulate_writes_bags_with_realistic_headers(tmp_path, capsys, name, kind):
    before = int(time.time())
    code, out, err = _cli(['simulate', '--params', PARAMS, '--rate', 200, '--duration', 5,
                           '--out', tmp_path / name, '--seed', 3], capsys)
    assert code == 0 and out == '' and len(err) == 1 and 'seed 3' in err[0]
    got_kind, stamps, samples = _read(tmp_path / name)
    assert got_kind == kind and samples.shape == (1000, 6)
    # header.stamp: now (whole seconds), then exactly 5 ms apart.
    assert before <= stamps[0] // 10**9 <= int(time.time()) and stamps[0] % 10**9 == 0
    assert_array_equal(np.diff(stamps), 5_000_000)
    # Same seed, same samples as the CSV output.
    _cli(['simulate', '--params', PARAMS, '--rate', 200, '--duration', 5, '--out',
          tmp_path / 'sim.csv', '--seed', 3], capsys)
    assert_array_equal(read_csv(tmp_path / 'sim.csv').samples, samples)
    assert read_csv(tmp_path / 'sim.csv').t_s[0] == 0.0


def test_simulated_bag_message_fields(tmp_path, capsys):
    code, _, _ = _cli(['simulate', '--params', PARAMS, '--rate', 100, '--duration', 1,
                       '--out', tmp_path / 'b', '--seed', 1, '--start', 1234.5,
                       '--topic', '/sensors/imu', '--frame-id', 'base_imu'], capsys)
    assert code == 0
    spec = load_params(PARAMS)
    with AnyReader([tmp_path / 'b']) as reader:
        conn, stamp, raw = next(reader.messages())
        msg = reader.deserialize(raw, conn.msgtype)
    assert conn.topic == '/sensors/imu' and conn.msgtype == 'sensor_msgs/msg/Imu'
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1234, 500_000_000)
    assert msg.header.frame_id == 'base_imu' and stamp > 1234.5e9
    assert msg.orientation_covariance[0] == -1.0   # orientation unknown (REP 145)
    gyro_var = spec.axes['gyro_x'].N ** 2 * 100
    assert msg.angular_velocity_covariance[0] == pytest.approx(gyro_var)
    assert msg.linear_acceleration_covariance[8] == pytest.approx(
        spec.axes['accel_z'].N ** 2 * 100)


def test_simulate_bad_requests_exit_2_with_one_line(tmp_path, capsys):
    (tmp_path / 'exists.mcap').write_bytes(b'x')
    cases = [(['--rate', -5, '--out', tmp_path / 'a.mcap'], '--rate must be a positive'),
             (['--rate', 100, '--out', tmp_path / 'a.xlsx'], 'cannot tell the output format'),
             (['--rate', 100, '--out', tmp_path / 'exists.mcap'], 'exists already')]
    for args, words in cases:
        code, out, err = _cli(['simulate', '--params', PARAMS, '--duration', 1, *args], capsys)
        assert code == 2 and out == '' and len(err) == 1, (args, err)
        assert err[0].startswith('imu-allan: error: ') and words in err[0], err[0]


@pytest.mark.parametrize('name, storage, kind', [('log.mcap', None, 'mcap'),
                                                 ('log_dir', 'sqlite3', 'sqlite3'),
                                                 ('log.bag', None, 'ros1')])
def test_csv_to_bag_round_trip(tmp_path, capsys, name, storage, kind):
    rng = np.random.default_rng(2)
    t = np.arange(500) * 0.01
    samples = rng.normal(size=(500, 6))
    write_csv(tmp_path / 'log.csv.gz', t, samples, AXES)
    argv = ['csv-to-bag', tmp_path / 'log.csv.gz', tmp_path / name, '--start', 1.7e9]
    code, out, err = _cli(argv + (['--storage', storage] if storage else []), capsys)
    assert code == 0 and out == '' and err == [
        f'imu-allan: wrote 500 sensor_msgs/Imu messages on /imu/data -> {tmp_path / name}']
    got_kind, stamps, back = _read(tmp_path / name)
    assert got_kind == kind
    assert_array_equal(back, samples)
    assert_array_equal(stamps, 1_700_000_000_000_000_000 + np.arange(500) * 10_000_000)


@pytest.mark.parametrize('t0_s', [0.0, 1.7e9])
def test_csv_to_bag_stamps_are_the_csv_times_and_never_zero(tmp_path, capsys, t0_s):
    # A log of relative times (from 0) gets an epoch start: its bag must not read as
    # one whose publisher leaves header.stamp 0.  Epoch times stay as they are.
    t = t0_s + np.arange(300) * 0.01
    write_csv(tmp_path / 'log.csv', t, np.random.default_rng(4).normal(size=(300, 6)), AXES)
    before_s = time.time()
    code, _, _ = _cli(['csv-to-bag', tmp_path / 'log.csv', tmp_path / 'log.mcap'], capsys)
    assert code == 0
    with open_imu(tmp_path / 'log.mcap') as source:
        stamps = source.read_all().stamp_ns
        assert not any('header.stamp is 0' in w for w in source.warnings), source.warnings
    assert_array_equal(np.diff(stamps), np.diff(np.rint(t * 1e9).astype(np.int64)))
    if t0_s:
        assert stamps[0] == 1_700_000_000_000_000_000
    else:
        assert int(before_s) - 1 <= stamps[0] / 1e9 <= time.time()


def test_csv_to_bag_other_column_names_and_errors(tmp_path, capsys):
    names = ['wx', 'wy', 'wz', 'ax', 'ay', 'az']
    write_csv(tmp_path / 'odd.csv', np.arange(10) * 0.1, np.ones((10, 6)), names)
    code, _, _ = _cli(['csv-to-bag', tmp_path / 'odd.csv', tmp_path / 'odd.mcap',
                       '--columns', ','.join(names)], capsys)
    assert code == 0 and _read(tmp_path / 'odd.mcap')[2].shape == (10, 6)
    for args, words in [([tmp_path / 'odd.csv', tmp_path / 'x.mcap'], 'not in the header'),
                        ([tmp_path / 'odd.csv', tmp_path / 'odd.mcap', '--columns',
                          ','.join(names)], 'exists already'),
                        ([tmp_path / 'none.csv', tmp_path / 'y.mcap'], 'no such file')]:
        code, out, err = _cli(['csv-to-bag', *args], capsys)
        assert code == 2 and out == '' and len(err) == 1, (args, err)
        assert err[0].startswith('imu-allan: error: ') and words in err[0], err[0]
