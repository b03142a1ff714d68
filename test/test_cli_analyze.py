"""
Tests of ``imu-allan analyze``: every input format, outputs, JSON contract, bad input.

Bags are real files written in tmp_path by the project's writer, by rosbags (ROS 1 and
rosbag2) or by the mcap package; nothing is mocked.  The fit costs about a second per
input, so most format checks compare the pipeline Sessions (the exact Allan curves)
and only a few runs go through the full command.
"""

import json
import os
from pathlib import Path
import sqlite3
import subprocess
import sys
import threading

from mcap.writer import Writer as McapWriter
import numpy as np
from numpy.testing import assert_array_equal
import pytest
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin, Writer as Ros2Writer
from rosbags.typesys import get_typestore, Stores
import yaml

from conftest import T0_NS
from imu_allan import AXES
from imu_allan.cli import main
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.outputs.short_record import SHORT_RECORD
from imu_allan.io import inputs
from imu_allan.io.bag_writer import serialize_imu, write_imu_bag
from imu_allan.io.csv_io import write_csv
from imu_allan.io.inputs import open_input, stream_input
from imu_allan.io.progress import Progress
from imu_allan.pipeline.hygiene import SessionConfig

REPO = Path(__file__).resolve().parents[1]
IMU = 'sensor_msgs/msg/Imu'
ROS2 = get_typestore(Stores.ROS2_JAZZY)
ROS1 = get_typestore(Stores.ROS1_NOETIC)
RATE = 100.0
N = 9000   # 90 s at 100 Hz: a multiple of the 1 s motion window


@pytest.fixture(scope='module')
def rec():
    """Return (stamps_ns, samples) of a simulated still Xsens MTi-7, 90 s at 100 Hz."""
    spec = load_params(REPO / 'config' / 'xsens_mti7.yaml')
    _, samples = simulate_imu(spec, RATE, N / RATE, seed=5)
    stamps = T0_NS + np.arange(N, dtype=np.int64) * 10_000_000
    return stamps, samples


def _cli(argv, capsys):
    """Run the CLI in-process; return (exit code, stdout, stderr lines)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, [line for line in err.splitlines() if line.strip()]


# -- writers of every input kind ----------------------------------------------------

def _csv(path, stamps, samples):
    write_csv(path, (stamps - stamps[0]) * 1e-9, samples, AXES)
    return path


def _ros1_bag(path, stamps, samples, extra_topic=True):
    """ROS 1 bag through rosbags' writer (payloads from the project's serialiser)."""
    payloads = serialize_imu(stamps, samples, ros1=True)
    with Ros1Writer(path) as writer:
        conn = writer.add_connection('/imu/raw', IMU, typestore=ROS1)
        if extra_topic:
            other = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=ROS1)
            writer.write(other, int(stamps[0]), bytes(ROS1.serialize_ros1(
                ROS1.types['std_msgs/msg/String'](data='hi'), 'std_msgs/msg/String')))
        for i in range(stamps.size):
            writer.write(conn, int(stamps[i]) + 1_000_000, payloads[i].tobytes())
    return path


def _rosbags2(path, topics, storage=StoragePlugin.SQLITE3, version=9):
    """rosbag2 bag by rosbags; topics maps name -> (type, [(recv_ns, payload bytes)])."""
    with Ros2Writer(path, version=version, storage_plugin=storage) as writer:
        for name, (msgtype, messages) in topics.items():
            conn = writer.add_connection(name, msgtype, typestore=ROS2)
            for recv, raw in messages:
                writer.write(conn, recv, raw)
    return path


def _imu_messages(stamps, samples):
    return [(int(t), p.tobytes()) for t, p in zip(stamps, serialize_imu(stamps, samples))]


def _status_messages(k=5):
    raw = bytes(ROS2.serialize_cdr(ROS2.types['std_msgs/msg/String'](data='ok'),
                                   'std_msgs/msg/String'))
    return [(T0_NS + i * 10**8, raw) for i in range(k)]


def _foxy_bag(path, stamps, samples):
    """Foxy-style rosbag2: metadata version 4, sqlite3 without message definitions."""
    path.mkdir()
    conn = sqlite3.connect(path / f'{path.name}_0.db3')
    conn.executescript(
        'CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,'
        ' serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);'
        'CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,'
        ' timestamp INTEGER NOT NULL, data BLOB NOT NULL);'
        'CREATE INDEX timestamp_idx ON messages (timestamp ASC);')
    conn.execute("INSERT INTO topics VALUES (1, '/imu', ?, 'cdr', '')", (IMU,))
    conn.executemany('INSERT INTO messages (topic_id, timestamp, data) VALUES (1, ?, ?)',
                     [(t + 2_000_000, raw) for t, raw in _imu_messages(stamps, samples)])
    conn.commit()
    conn.close()
    (path / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': {
        'version': 4, 'storage_identifier': 'sqlite3',
        'relative_file_paths': [f'{path.name}/{path.name}_0.db3'],
        'duration': {'nanoseconds': int(stamps[-1] - stamps[0])},
        'starting_time': {'nanoseconds_since_epoch': int(stamps[0])},
        'message_count': int(stamps.size),
        'topics_with_message_count': [{'topic_metadata': {
            'name': '/imu', 'type': IMU, 'serialization_format': 'cdr',
            'offered_qos_profiles': ''}, 'message_count': int(stamps.size)}]}}))
    return path


def _mcap_no_defs(path, stamps, samples):
    """rosbag2 MCAP directory, metadata version 6, schema without a definition."""
    path.mkdir()
    with open(path / f'{path.name}_0.mcap', 'wb') as stream:
        writer = McapWriter(stream)
        writer.start(profile='ros2')
        schema = writer.register_schema(IMU, 'ros2msg', b'')
        channel = writer.register_channel('/imu', 'cdr', schema)
        for t, raw in _imu_messages(stamps, samples):
            writer.add_message(channel, t + 1000, raw, t)
        writer.finish()
    (path / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': {
        'version': 6, 'storage_identifier': 'mcap',
        'relative_file_paths': [f'{path.name}_0.mcap'],
        'message_count': int(stamps.size), 'topics_with_message_count': []}}))
    return path


def _every_format(tmp_path, stamps, samples) -> dict:
    """Write the recording in every supported form; return label -> path."""
    paths = {
        'csv': _csv(tmp_path / 'rec.csv.gz', stamps, samples),
        'dir_sqlite3': tmp_path / 'dir_sqlite3', 'dir_mcap': tmp_path / 'dir_mcap',
        'file_mcap': tmp_path / 'rec.mcap', 'file_db3': tmp_path / 'rec.db3',
        'ros1': _ros1_bag(tmp_path / 'rec.bag', stamps, samples),
        'foxy_no_defs': _foxy_bag(tmp_path / 'foxy', stamps, samples),
        'mcap_v6_no_defs': _mcap_no_defs(tmp_path / 'mcap_v6', stamps, samples),
        'rosbags_v8': _rosbags2(tmp_path / 'v8', {'/imu': (IMU, _imu_messages(
            stamps, samples)), '/status': ('std_msgs/msg/String', _status_messages())},
            version=8),
    }
    write_imu_bag(paths['dir_sqlite3'], stamps, samples, storage='sqlite3')
    write_imu_bag(paths['dir_mcap'], stamps, samples)
    write_imu_bag(paths['file_mcap'], stamps, samples)
    write_imu_bag(paths['file_db3'], stamps, samples)
    return paths


# -- formats --------------------------------------------------------------------------

def test_every_input_format_feeds_the_same_samples_to_the_pipeline(tmp_path, rec):
    stamps, samples = rec
    paths = _every_format(tmp_path, stamps, samples)
    kinds = {}
    curves = {}
    for label, path in paths.items():
        with open_input(path) as source:
            kinds[label] = source.kind
            # A CSV is read in blocks: its count is known once read, not before.
            assert source.n_messages == (None if label == 'csv' else N)
            session = stream_input(source, SessionConfig())
            assert source.warnings == [], (label, source.warnings)
            assert source.read_counts['n_read'] == N
        assert session.stats.n_used == N and session.warnings == [], label
        curves[label] = session.curve()
    assert kinds == {'csv': 'csv', 'dir_sqlite3': 'sqlite3', 'dir_mcap': 'mcap',
                     'file_mcap': 'mcap', 'file_db3': 'sqlite3', 'ros1': 'ros1',
                     'foxy_no_defs': 'sqlite3', 'mcap_v6_no_defs': 'mcap',
                     'rosbags_v8': 'sqlite3'}
    ref = curves.pop('dir_mcap')
    for label, curve in curves.items():
        assert_array_equal(curve.tau_s, ref.tau_s, err_msg=label)
        assert_array_equal(curve.avar, ref.avar, err_msg=label)


def test_several_formats_through_the_command_give_identical_numbers(tmp_path, rec, capsys):
    stamps, samples = rec
    paths = _every_format(tmp_path, stamps, samples)
    picked = [paths[k] for k in ('csv', 'ros1', 'foxy_no_defs')]
    code, out, err = _cli(['analyze', *picked, '--out', tmp_path / 'out', '--format', 'json',
                           '--no-plot', '--jobs', '2'], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert [r['n_samples'] for r in doc['results']] == [N] * 3 and doc['errors'] == []
    first = doc['results'][0]['axes']
    for other in doc['results'][1:]:
        for axis in AXES:
            assert other['axes'][axis]['params'] == first[axis]['params']
            assert other['axes'][axis]['adev'] == first[axis]['adev']
    # A report per input, and the comparison: every run equal, so no spread at all.
    for name in ('rec_1', 'rec_2', 'foxy'):
        assert (tmp_path / 'out' / name / 'result.json').is_file(), name
    table = (tmp_path / 'out' / 'comparison.md').read_text()
    assert '| gyro_x | N |' in table
    spread = doc['comparison']['spread']
    assert spread['gyro_x']['N']['std'] == 0.0
    assert len(spread['gyro_x']['N']['values']) == 3


# -- single input: JSON contract, files, plots ---------------------------------------

def test_json_contract_and_every_output_file(tmp_path, rec, capsys):
    stamps, samples = rec
    bag = tmp_path / 'rec.mcap'
    write_imu_bag(bag, stamps, samples)
    out_dir = tmp_path / 'out'
    code, out, err = _cli(['analyze', bag, '--out', out_dir, '--format', 'json'], capsys)
    assert code == 0
    # A short clean record: only the consumer values it cannot determine are named.
    assert not [line for line in err if ('warning' in line or 'error' in line)
                and SHORT_RECORD not in line], err
    assert out.count('\n') == 1   # exactly one JSON document, nothing else
    doc = json.loads(out)
    assert doc['n_samples'] == N
    assert [w for w in doc['warnings'] if not w.startswith(SHORT_RECORD)] == []
    assert doc['sample_rate_hz'] == pytest.approx(RATE, rel=1e-9)
    assert doc['duration_s'] == pytest.approx(N / RATE, rel=1e-9)
    for axis in AXES:
        entry = doc['axes'][axis]
        assert len(entry['tau_s']) == len(entry['adev']) >= 10
        for sym in ('N', 'B', 'K', 'T_B'):
            p = entry['params'][sym]
            assert {'value', 'ci95'} <= p.keys() and len(p['ci95']) == 2
    # N of the simulated white noise is recovered (the config's MTi-7 values).
    spec = load_params(REPO / 'config' / 'xsens_mti7.yaml')
    for axis in ('gyro_x', 'accel_x'):
        assert doc['axes'][axis]['params']['N']['value'] == pytest.approx(
            spec.axes[axis].N, rel=0.1)
    names = {Path(f).name for f in doc['files']}
    assert {'result.json', 'imu.yaml', 'kalman_qr.yaml', 'imu_covariance.yaml', 'adev.png',
            'adev.svg'} <= names
    assert json.loads((out_dir / 'result.json').read_text())['axes'].keys() == set(AXES)
    kalibr = yaml.safe_load((out_dir / 'imu.yaml').read_text())
    assert {'accelerometer_noise_density', 'accelerometer_random_walk',
            'gyroscope_noise_density', 'gyroscope_random_walk', 'update_rate'} <= kalibr.keys()
    cov = yaml.safe_load((out_dir / 'imu_covariance.yaml').read_text())
    gyro_var = cov['angular_velocity_covariance']
    assert len(gyro_var) == 9 and gyro_var[0] == pytest.approx(
        doc['axes']['gyro_x']['params']['N']['value'] ** 2 * RATE, rel=1e-6)
    qr = (out_dir / 'kalman_qr.yaml').read_text()
    assert 'Qd' in qr or 'Q' in qr
    assert (out_dir / 'adev.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert b'<svg' in (out_dir / 'adev.svg').read_bytes()[:2000]


def test_kalibr_yaml_names_the_analysed_topic(tmp_path, rec, capsys):
    stamps, samples = rec
    bag = tmp_path / 'rec.mcap'
    write_imu_bag(bag, stamps, samples, topic='/robot/imu_front')
    out_dir = tmp_path / 'out'
    code, _, err = _cli(['analyze', bag, '--out', out_dir, '--no-plot'], capsys)
    assert code == 0, err
    kalibr = yaml.safe_load((out_dir / 'imu.yaml').read_text())
    assert kalibr['rostopic'] == '/robot/imu_front'
    assert all(v > 0 for k, v in kalibr.items() if k.endswith(('density', 'walk')))
    # The consumers' files: robot_localization fuses the analysed topic, the driver
    # scalars are N sqrt(rate), the VINS keys are per-step values of the covering pair.
    ekf = yaml.safe_load((out_dir / 'ekf_imu.yaml').read_text())
    assert ekf['ekf_filter_node']['ros__parameters']['imu0'] == '/robot/imu_front'
    driver = yaml.safe_load((out_dir / 'imu_driver_noise.yaml').read_text())
    result = json.loads((out_dir / 'result.json').read_text())
    n_gyro = [result['axes'][a]['params']['N']['value'] for a in ('gyro_x', 'gyro_y', 'gyro_z')]
    assert driver['worst']['angular_velocity_stdev'] == pytest.approx(
        max(n_gyro) * RATE ** 0.5, rel=1e-5)
    head, _, body = (out_dir / 'vins_imu.yaml').read_text().partition('\n')
    assert head == '%YAML:1.0'
    vins = yaml.safe_load(body)
    n_cover = [result['axes'][a]['covering']['covering']['N']
               for a in ('gyro_x', 'gyro_y', 'gyro_z')]
    assert vins['gyr_n'] == pytest.approx(max(n_cover) * (2 * RATE) ** 0.5, rel=1e-5)
    assert result['covering_horizon_s'] == pytest.approx([1 / RATE, 100.0])


def test_text_mode_two_different_runs_comparison_plot_and_table(tmp_path, rec, capsys):
    stamps, samples = rec
    _csv(tmp_path / 'run_a.csv', stamps, samples)
    _ros1_bag(tmp_path / 'run_b.bag', stamps, samples * 1.5 + [0, 0, 0, 0, 0, 1.0])
    code, out, err = _cli(['analyze', tmp_path / 'run_a.csv', tmp_path / 'run_b.bag', '--out',
                           tmp_path / 'cmp', '--jobs', '1'], capsys)
    assert code == 0, err
    assert '== ' in out and 'gyro_x: N ' in out and '| gyro_x | N |' in out
    for name in ('comparison.md', 'comparison.png', 'comparison.svg', 'run_a/adev.png',
                 'run_b/adev.svg', 'run_b/imu.yaml'):
        assert (tmp_path / 'cmp' / name).is_file(), name
    row = next(line for line in (tmp_path / 'cmp' / 'comparison.md').read_text().splitlines()
               if line.startswith('| gyro_x | N |'))
    a, b = (float(x) for x in row.split('|')[4:6])
    assert b == pytest.approx(1.5 * a, rel=1e-3)


def test_one_imu_topic_among_others_is_found_several_need_topic(tmp_path, rec, capsys):
    stamps, samples = rec
    msgs = _imu_messages(stamps, samples)
    bag = _rosbags2(tmp_path / 'two', {'/imu/a': (IMU, msgs), '/imu/b': (IMU, msgs[:500]),
                                       '/status': ('std_msgs/msg/String', _status_messages())},
                    storage=StoragePlugin.MCAP)
    code, out, err = _cli(['analyze', bag, '--out', tmp_path / 'o'], capsys)
    assert code == 2 and out == '' and len(err) == 1
    assert err[0].startswith('imu-allan: error: ') and '/imu/a' in err[0] and '/imu/b' in err[0]
    assert '--topic' in err[0]
    code, out, err = _cli(['analyze', bag, '--topic', '/imu/a', '--out', tmp_path / 'o',
                           '--format', 'json', '--no-plot'], capsys)
    assert code == 0 and json.loads(out)['source'] == 'two /imu/a'


def test_two_imus_on_one_topic_need_frame_id(tmp_path, rec, capsys):
    # Two IMUs on /imu (frame_ids imu_a, imu_b, 5 ms apart): never one 200 Hz IMU.
    stamps, samples = rec
    rows_a = serialize_imu(stamps, samples, 'imu_a')
    rows_b = serialize_imu(stamps + 5_000_000, samples[::-1], 'imu_b')
    msgs = [m for k in range(N) for m in ((int(stamps[k]), rows_a[k].tobytes()),
                                          (int(stamps[k]) + 5_000_000, rows_b[k].tobytes()))]
    bag = _rosbags2(tmp_path / 'two', {'/imu': (IMU, msgs)}, storage=StoragePlugin.MCAP)
    code, out, err = _cli(['analyze', bag, '--out', tmp_path / 'o'], capsys)
    assert code == 2 and out == '' and len(err) == 1, err
    assert err[0].endswith(f'/imu carries 2 IMUs (header.frame_id): imu_a ({N} messages), '
                           f'imu_b ({N} messages); choose one with --frame-id NAME'), err[0]
    code, out, err = _cli(['analyze', bag, '--frame-id', 'imu_b', '--out', tmp_path / 'o',
                           '--format', 'json', '--no-plot', '--no-plan'], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert (doc['n_samples'], doc['sample_rate_hz']) == (N, RATE)
    assert doc['hygiene']['n_lost'] == 0
    assert f"{N} messages of other IMUs on /imu skipped (frame_id 'imu_b' read; others: " \
           f'imu_a ({N}))' in doc['warnings']


# -- bad input: exit 2, one line, no traceback ---------------------------------------

def _bad_inputs(tmp_path, stamps, samples) -> dict:
    """Return name -> (argv tail, expected words in the error line)."""
    cases = {'missing': ([tmp_path / 'nope.mcap'], 'no such file')}
    fifo = tmp_path / 'pipe.mcap'
    os.mkfifo(fifo)
    cases['fifo'] = ([fifo], 'not a regular file')
    write_imu_bag(tmp_path / 'empty.mcap', np.zeros(0, np.int64), np.zeros((0, 6)))
    cases['empty bag'] = ([tmp_path / 'empty.mcap'], 'empty bag')
    _rosbags2(tmp_path / 'notopics', {})
    cases['bag with no topics'] = ([tmp_path / 'notopics'], 'empty bag')
    _rosbags2(tmp_path / 'noimu', {'/status': ('std_msgs/msg/String', _status_messages())})
    cases['no imu topic'] = ([tmp_path / 'noimu'], 'no sensor_msgs/msg/Imu topic')
    _rosbags2(tmp_path / 'wrong', {'/imu': (IMU, _imu_messages(stamps[:300], samples[:300])),
                                   '/status': ('std_msgs/msg/String', _status_messages())})
    cases['wrong type'] = ([tmp_path / 'wrong', '--topic', '/status'],
                           '/status is std_msgs/msg/String, not sensor_msgs/msg/Imu')
    write_imu_bag(tmp_path / 'whole.db3', stamps[:3000], samples[:3000])
    data = (tmp_path / 'whole.db3').read_bytes()
    (tmp_path / 'cut.db3').write_bytes(data[:len(data) // 2])
    cases['truncated sqlite'] = ([tmp_path / 'cut.db3'], 'damaged or not a sqlite3')
    (tmp_path / 'garbage.db3').write_bytes(data[:100] + os.urandom(8192))
    cases['corrupt sqlite'] = ([tmp_path / 'garbage.db3'], 'sqlite3')
    (tmp_path / 'junk.bag').write_bytes(b'not a bag at all' * 10)
    cases['not a bag'] = ([tmp_path / 'junk.bag'], 'not a bag')
    (tmp_path / 'cols.csv').write_text('t,gyro_x,gyro_y,gyro_z,accel_x,accel_y\n0,1,2,3,4,5\n')
    cases['csv missing column'] = ([tmp_path / 'cols.csv'], 'accel_z not in the header')
    rows = ['t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z'] + [
        f'{k * 0.01:.2f},0,0,0,0,0,9.8' for k in range(50)]
    rows[20] = '0.19,0,0,abc,0,0,9.8'
    (tmp_path / 'text.csv').write_text('\n'.join(rows) + '\n')
    cases['csv text in numbers'] = ([tmp_path / 'text.csv'],
                                    "row 21: 'abc' in column gyro_z is not a number")
    (tmp_path / 'empty.csv').write_text('')
    cases['empty csv'] = ([tmp_path / 'empty.csv'], 'file is empty')
    (tmp_path / 'dir.csv').mkdir()
    cases['directory named csv'] = ([tmp_path / 'dir.csv'], 'is a directory')
    return cases


def test_bad_inputs_exit_2_with_one_clear_line(tmp_path, rec, capsys):
    stamps, samples = rec
    for name, (args, words) in _bad_inputs(tmp_path, stamps, samples).items():
        code, out, err = _cli(['analyze', *args, '--out', tmp_path / 'o', '--format', 'json'],
                              capsys)
        assert code == 2, name
        assert len(err) == 1, (name, err)
        assert err[0].startswith('imu-allan: error: ') and words in err[0], (name, err[0])
        # --format json: the same error as the one document on stdout.
        assert json.loads(out) == {'error': err[0].removeprefix('imu-allan: error: '),
                                   'exit_code': 2}, name


@pytest.mark.skipif(os.geteuid() == 0, reason='root reads files whatever their mode')
def test_unreadable_file(tmp_path, capsys):
    path = tmp_path / 'secret.mcap'
    path.write_bytes(b'\x89MCAP0\r\n')
    path.chmod(0)
    code, _, err = _cli(['analyze', path], capsys)
    assert code == 2 and len(err) == 1 and 'permission denied' in err[0]


def test_bad_input_in_a_real_process_has_no_traceback(tmp_path):
    proc = subprocess.run([sys.executable, '-m', 'imu_allan', 'analyze', str(tmp_path / 'x.db3'),
                           '--format', 'json'], capture_output=True, text=True, check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f'imu-allan: error: {tmp_path / "x.db3"}: no such file or directory']
    # --format json: the error as the one document on stdout.
    assert json.loads(proc.stdout) == {
        'error': f'{tmp_path / "x.db3"}: no such file or directory', 'exit_code': 2}


def test_several_inputs_one_bad_still_reports_the_good_one(tmp_path, rec, capsys):
    stamps, samples = rec
    write_imu_bag(tmp_path / 'good.mcap', stamps, samples)
    (tmp_path / 'bad.csv').write_text('t,x\n0,1\n')
    code, out, err = _cli(['analyze', tmp_path / 'good.mcap', tmp_path / 'bad.csv', '--out',
                           tmp_path / 'o', '--format', 'json', '--no-plot', '--jobs', '1'],
                          capsys)
    assert code == 2
    assert [line for line in err if 'error' in line] == [
        f'imu-allan: error: {tmp_path / "bad.csv"}: column(s) gyro_x, gyro_y, gyro_z, accel_x, '
        f'accel_y, accel_z not in the header t, x']
    doc = json.loads(out)
    assert [r['n_samples'] for r in doc['results']] == [N] and len(doc['errors']) == 1


def test_truncated_mcap_recovers_warns_and_gives_a_result(tmp_path, rec, capsys):
    stamps, samples = rec
    write_imu_bag(tmp_path / 'whole.mcap', stamps, samples)
    data = (tmp_path / 'whole.mcap').read_bytes()
    (tmp_path / 'cut.mcap').write_bytes(data[:int(len(data) * 0.7)])
    code, out, err = _cli(['analyze', tmp_path / 'cut.mcap', '--out', tmp_path / 'o',
                           '--format', 'json', '--no-plot'], capsys)
    assert code == 0
    doc = json.loads(out)
    assert 0.5 * N < doc['n_samples'] < N
    assert any('truncated' in w for w in doc['warnings'])
    assert any(line.startswith('imu-allan: warning: cut.mcap: ') and 'truncated' in line
               for line in err)


# -- progress --------------------------------------------------------------------------

def test_progress_goes_to_stderr_and_never_to_stdout(tmp_path, rec, capsys, monkeypatch):
    stamps, samples = rec
    write_imu_bag(tmp_path / 'p.mcap', stamps, samples)
    monkeypatch.setattr(Progress, 'delay_s', 0.0)
    monkeypatch.setattr(Progress, 'log_interval_s', 0.05)
    monkeypatch.setattr(inputs, 'CSV_BLOCK', 500)
    code, out, err = _cli(['analyze', tmp_path / 'p.mcap', '--out', tmp_path / 'o',
                           '--format', 'json', '--no-plot'], capsys)
    assert code == 0
    json.loads(out)
    assert out.count('\n') == 1
    assert any(line.startswith('imu-allan: reading p.mcap') for line in err), err
    assert any('fitting the noise model of p.mcap' in line for line in err), err
    assert all(line.startswith('imu-allan: ') for line in err)


def test_progress_line_counts_messages():
    bar = Progress('x.mcap', 4_000)
    bar.update(1_000)
    assert ' 25.0% 1,000 messages' in bar.line()
    bar.set_stage('fitting the noise model of')
    assert 'fitting the noise model of x.mcap' in bar.line()
    bar.close()


# -- same numbers as the node ----------------------------------------------------------

def test_node_path_and_analyze_give_identical_numbers(tmp_path, rec, capsys):
    """
    The node's path, emulated at the Session level, against ``imu-allan analyze``.

    The node (imu_allan/ros/node.py) receives raw CDR payloads, decodes what accumulated
    at each timer tick with ``imu_cdr.decode_imu_cdr`` and calls ``Session.add``;
    here the bag's raw payloads (read by rosbags, as a raw subscription delivers them)
    take that path in irregular tick-sized blocks.
    """
    from rosbags.rosbag2 import Reader

    from imu_allan.core.allan.raw import RawKeeper
    from imu_allan.io.imu_cdr import decode_imu_cdr
    from imu_allan.pipeline.analysis import analyze
    from imu_allan.pipeline.session import Session

    stamps, samples = rec
    bag = tmp_path / 'rec'
    write_imu_bag(bag, stamps, samples, storage='sqlite3')
    with Reader(bag) as reader:
        raws = [raw for _, _, raw in reader.messages()]
    session = Session(SessionConfig())
    keeper = RawKeeper(None, len(AXES))     # the node's raw copy for the effect search
    rng = np.random.default_rng(1)
    k = 0
    while k < len(raws):
        tick = int(rng.integers(1, 60))   # messages gathered between two timer ticks
        stamp_ns, values = decode_imu_cdr(raws[k:k + tick])
        session.add(stamp_ns, values)
        keeper.add(values[np.isfinite(values).all(axis=1)])
        k += tick
    session.flush()
    node_doc = analyze(session, source='node', raw=keeper, plan=True).to_json()  # plans too
    code, out, err = _cli(['analyze', bag, '--out', tmp_path / 'out', '--format', 'json',
                           '--no-plot'], capsys)
    assert code == 0, err
    cli_doc = json.loads(out)
    # The bag reader alone counts the messages without orientation (the node reads none).
    assert cli_doc['hygiene'].pop('n_no_orientation') == N
    for key in ('sample_rate_hz', 'duration_s', 'n_samples', 'warnings', 'hygiene', 'kalman',
                'imu_covariance'):
        assert cli_doc[key] == node_doc[key], key
    for axis in AXES:
        assert cli_doc['axes'][axis] == node_doc['axes'][axis], axis


def test_read_ahead_keeps_order_and_passes_errors_on():
    assert list(inputs._prefetch(iter(range(1000)))) == list(range(1000))

    def broken():
        yield 1
        raise ValueError('disk on fire')

    got = []
    with pytest.raises(ValueError, match='disk on fire'):
        for item in inputs._prefetch(broken()):
            got.append(item)
    assert got == [1]
    # A consumer that stops early leaves no reader thread behind.
    reader = inputs._prefetch(iter(range(10**6)))
    assert next(reader) == 0
    reader.close()
    assert not [t for t in threading.enumerate() if t.name == 'imu-allan-reader']


def _python(code: str) -> subprocess.CompletedProcess:
    """Run Python code in a fresh process; it must succeed."""
    res = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    return res


def test_main_process_of_a_two_worker_analysis_imports_no_fitting(tmp_path, rec):
    # The search runs in the workers (their fork server imports scipy while the input is
    # read); the main process only reads, checks, accumulates and reports (its curve's
    # bounds take scipy.special's chi-square quantiles, nothing more).
    stamps, samples = rec
    path = tmp_path / 'rec.csv'
    write_csv(path, (stamps - stamps[0]) / 1e9, samples, AXES)
    code = ('import sys\nfrom imu_allan.cli import main\n'
            f'assert main(["analyze", {str(path)!r}, "--out", {str(tmp_path / "o")!r}, '
            '"--format", "json", "--jobs", "2"]) == 0\n'
            'print(sorted(m for m in sys.modules if m in ("scipy.stats", "scipy.optimize", '
            '"scipy.signal")), file=sys.stderr)\n')
    res = _python(code)
    assert res.stderr.strip().splitlines()[-1] == '[]', res.stderr
    assert (tmp_path / 'o' / 'adev.png').exists() and (tmp_path / 'o' / 'adev.svg').exists()


def test_cover_tau_max_sets_the_covering_horizon(tmp_path, rec, capsys):
    stamps, samples = rec
    _csv(tmp_path / 'rec.csv', stamps, samples)
    out_dir = tmp_path / 'out'
    code, _, err = _cli(['analyze', tmp_path / 'rec.csv', '--out', out_dir, '--no-plot',
                         '--jobs', '1', '--cover-tau-max', '10'], capsys)
    assert code == 0, err
    result = json.loads((out_dir / 'result.json').read_text())
    assert result['covering_horizon_s'] == pytest.approx([1 / RATE, 10.0])
    cover = result['axes']['gyro_x']['covering']
    assert cover['horizon_s'] == pytest.approx([1 / RATE, 10.0])
    assert cover['factor']['N'] == pytest.approx(cover['covering']['N'] / cover['fitted']['N'])
    assert 'tau in [0.01, 10] s' in (out_dir / 'summary.txt').read_text()
    assert 'for tau in [0.01, 10] s.' in (out_dir / 'vins_imu.yaml').read_text()
    code, _, err = _cli(['analyze', tmp_path / 'rec.csv', '--out', out_dir, '--no-plot',
                         '--cover-tau-max', '0'], capsys)
    assert code == 2 and len(err) == 1 and '--cover-tau-max' in err[0], err


def test_huge_finite_values_are_spikes_not_a_traceback(tmp_path, rec, capsys):
    # 1e154 squared overflows: the evidence's raw copy once ended in 'array must not
    # contain infs or NaNs'.  The session replaces both values as spikes, warned.
    stamps, samples = rec
    bad = samples.copy()
    bad[4500, 0], bad[6000, 4] = 1e154, -1.7e308
    docs = []
    for name, values in (('clean', samples), ('bad', bad)):
        code, out, err = _cli(['analyze', _csv(tmp_path / f'{name}.csv', stamps, values),
                               '--out', tmp_path / name, '--format', 'json', '--no-plot',
                               '--no-plan', '--jobs', '1'], capsys)
        assert code == 0, err
        docs.append(json.loads(out))
    clean, doc = docs
    assert doc['hygiene']['n_spikes'] == clean['hygiene']['n_spikes'] + 2
    assert any('spikes' in w and 'gyro_x' in w and 'accel_y' in w for w in doc['warnings'])
    # The degraded record's white noise lies within the clean record's interval.
    for axis in ('gyro_x', 'accel_y'):
        low, high = clean['axes'][axis]['params']['N']['ci95']
        assert low <= doc['axes'][axis]['params']['N']['value'] <= high, axis


def _with_orientation(payloads: np.ndarray, every: int) -> np.ndarray:
    """Set orientation_covariance[0] = 0.01 (an orientation) in every ``every``-th one."""
    out = payloads.copy()
    # The first -1.0 of a message is orientation_covariance[0] (the quaternion is 0, 0, 0, 1).
    at = out[0].tobytes().find(np.float64(-1.0).tobytes())
    out[::every, at:at + 8] = np.frombuffer(np.float64(0.01).tobytes(), np.uint8)
    return out


@pytest.mark.parametrize('kind', ['sqlite3', 'ros1'])
@pytest.mark.parametrize('every', [0, 1000])
def test_messages_without_orientation_get_the_no_orientation_ekf_file_first(
        tmp_path, rec, capsys, kind, every):
    stamps, samples = rec
    payloads = serialize_imu(stamps, samples, ros1=kind == 'ros1')   # REP 145: all -1
    if every:
        payloads = _with_orientation(payloads, every)
    if kind == 'ros1':
        bag = tmp_path / 'r.bag'
        with Ros1Writer(bag) as writer:
            conn = writer.add_connection('/imu/raw', IMU, typestore=ROS1)
            for t, p in zip(stamps.tolist(), payloads):
                writer.write(conn, t, p.tobytes())
    else:
        bag = _rosbags2(tmp_path / 'r', {'/imu/raw': (IMU, [
            (t, p.tobytes()) for t, p in zip(stamps.tolist(), payloads)])})
    n_oriented = 0 if not every else -(-N // every)
    from imu_allan.io.bag_reader import open_imu
    with open_imu(bag) as source:
        source.read_all()
        assert (source.n_read, source.n_no_orientation) == (N, N - n_oriented)
    code, out, _ = _cli(['analyze', bag, '--out', tmp_path / 'o', '--no-plot', '--no-plan',
                         '--jobs', '1'], capsys)
    assert code == 0
    listed = out.split('files: ')[1]
    first = listed.index('ekf_imu_no_orientation.yaml') < listed.index('ekf_imu.yaml')
    summary = (tmp_path / 'o' / 'summary.txt').read_text()
    # Only when no message carries an orientation: one that does makes ekf_imu.yaml fit.
    assert first == (not every)
    assert ('robot_localization: use ekf_imu_no_orientation.yaml' in summary) == (not every)
    assert ('robot_localization: use ekf_imu_no_orientation.yaml' in out) == (not every)
    doc = json.loads((tmp_path / 'o' / 'result.json').read_text())
    assert doc['hygiene']['n_no_orientation'] == N - n_oriented
