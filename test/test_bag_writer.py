"""
Tests of imu_allan.io.bag_writer, checked with independent readers.

The vectorised serialiser must produce the very bytes of rosbags' per-message
serialisers; written bags must read back through rosbags' AnyReader and the mcap
package (with CRC validation), with header stamps, receive times, frame_id, REP 145
orientation flag and covariances as asked.
"""

from pathlib import Path

from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
import numpy as np
from numpy.testing import assert_array_equal
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_typestore, Stores
import yaml

from conftest import T0_NS
from imu_allan.errors import InputError
from imu_allan.io.bag_reader import open_imu
from imu_allan.io.bag_writer import csv_to_bag, serialize_imu, write_imu_bag

IMU = 'sensor_msgs/msg/Imu'
ROS2 = get_typestore(Stores.ROS2_JAZZY)
ROS1 = get_typestore(Stores.ROS1_NOETIC)


def _recording(n: int, seed: int):
    """Return (stamps_ns (n,) int64 at about 100 Hz, samples (n, 6) float64)."""
    rng = np.random.default_rng(seed)
    stamps = T0_NS + np.arange(n) * 10_000_000 + rng.integers(0, 100_000, n)
    return stamps.astype(np.int64), rng.normal(size=(n, 6))


def _values(msg) -> list:
    av, la = msg.angular_velocity, msg.linear_acceleration
    return [av.x, av.y, av.z, la.x, la.y, la.z]


@pytest.mark.parametrize('ros1', [False, True])
@pytest.mark.parametrize('frame_id', ['', 'a', 'imu', 'imu_lin', 'imu_link', 'a' * 13])
def test_serialiser_matches_rosbags_byte_for_byte(frame_id, ros1):
    stamps, samples = _recording(4, seed=1)
    stamps[0] = 0
    covariances = ([1e-6, 2e-6, 3e-6], np.arange(9.0).reshape(3, 3))
    payloads = serialize_imu(stamps, samples, frame_id, covariances, ros1=ros1)
    for i in range(stamps.size):
        raw = payloads[i].tobytes()
        if ros1:
            msg = ROS1.deserialize_ros1(raw, IMU)
            again = ROS1.serialize_ros1(msg, IMU)
            assert msg.header.seq == i
        else:
            msg = ROS2.deserialize_cdr(raw, IMU)
            again = ROS2.serialize_cdr(msg, IMU)
        assert bytes(again) == raw
        assert msg.header.frame_id == frame_id
        assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == stamps[i]
        assert _values(msg) == list(samples[i])
        assert msg.orientation_covariance[0] == -1.0 and msg.orientation.w == 1.0
        assert_array_equal(msg.angular_velocity_covariance, np.diag([1e-6, 2e-6, 3e-6]).ravel())
        assert_array_equal(msg.linear_acceleration_covariance, np.arange(9.0))


@pytest.mark.parametrize('name, storage, files', [
    ('one.mcap', None, None), ('one.db3', None, None), ('one.bag', None, None),
    ('dir_mcap', None, ['dir_mcap_0.mcap', 'metadata.yaml']),
    ('dir_db3', 'sqlite3', ['dir_db3_0.db3', 'metadata.yaml'])])
def test_bags_read_back_with_rosbags(tmp_path, name, storage, files):
    stamps, samples = _recording(1500, seed=2)
    path = tmp_path / name
    write_imu_bag(path, stamps, samples, topic='/sensors/imu', frame_id='base_imu',
                  storage=storage, covariances=([1.0, 2.0, 3.0], [4.0, 5.0, 6.0]),
                  latency_ns=1234)
    if files is not None:
        assert sorted(p.name for p in path.iterdir()) == files
        info = yaml.safe_load((path / 'metadata.yaml').read_text())
        info = info['rosbag2_bagfile_information']
        assert info['message_count'] == 1500 and info['version'] == 9
        assert info['storage_identifier'] == (storage or 'mcap')
    store = ROS1 if name.endswith('.bag') else ROS2
    with AnyReader([path], default_typestore=store) as reader:
        assert [(c.topic, c.msgcount) for c in reader.connections] == [('/sensors/imu', 1500)]
        rows = [(t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]
    assert len(rows) == 1500
    for i in (0, 1, 777, 1499):
        recv, msg = rows[i]
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        assert (stamp, recv, msg.header.frame_id) == (stamps[i], stamps[i] + 1234, 'base_imu')
        assert _values(msg) == list(samples[i])
        assert msg.orientation_covariance[0] == -1.0
        assert msg.angular_velocity_covariance[4] == 2.0
        assert msg.linear_acceleration_covariance[8] == 6.0


def test_mcap_file_is_valid_for_the_mcap_library(tmp_path):
    stamps, samples = _recording(9000, seed=3)   # several chunks of about 1 MiB
    path = tmp_path / 'x.mcap'
    write_imu_bag(path, stamps, samples)
    with open(path, 'rb') as stream:
        records = list(StreamReader(stream, validate_crcs=True).records)
    kinds = {type(r).__name__ for r in records}
    assert {'Header', 'Schema', 'Channel', 'Message', 'DataEnd', 'Statistics', 'ChunkIndex',
            'Metadata', 'Footer'} <= kinds
    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        assert summary.statistics.message_count == 9000
        assert len(summary.chunk_indexes) == summary.statistics.chunk_count >= 3
        log_times = [m.log_time for _, _, m in reader.iter_messages()]
        assert next(reader.iter_metadata()).name == 'rosbag2'
    assert_array_equal(log_times, stamps + 500_000)


def test_empty_recording_gives_a_readable_empty_bag(tmp_path):
    for name in ('e.mcap', 'e.db3', 'edir'):
        write_imu_bag(tmp_path / name, np.zeros(0, np.int64), np.zeros((0, 6)))
        with AnyReader([tmp_path / name], default_typestore=ROS2) as reader:
            assert [c.msgcount for c in reader.connections] == [0]


def test_bad_requests_raise_and_leave_nothing(tmp_path):
    stamps, samples = _recording(10, seed=4)
    cases = [
        ({'path': tmp_path / 'a.mcap', 'storage': 'sqlite3'}, 'names mcap storage'),
        ({'path': tmp_path / 'b', 'storage': 'hdf5'}, 'unknown storage'),
        ({'path': tmp_path / 'c', 'storage': 'ros1'}, 'ending in .bag'),
        ({'path': tmp_path / 'd.mcap', 'samples': samples[:, :3]}, r'samples \(n, 6\)'),
        ({'path': tmp_path / 'e.mcap', 'stamps_ns': stamps * 1.0}, 'integer nanoseconds'),
        ({'path': tmp_path / 'f.db3', 'stamps_ns': stamps + 2**62}, 'signed 32-bit seconds'),
        ({'path': tmp_path / 'g.bag', 'stamps_ns': stamps - 2 * T0_NS}, 'unsigned 32-bit'),
        ({'path': tmp_path / 'h.mcap', 'covariances': ([1, 2], [1, 2, 3])}, '3 .diagonal.'),
    ]
    for overrides, message in cases:
        args = {'stamps_ns': stamps, 'samples': samples, **overrides}
        with pytest.raises(InputError, match=message):
            write_imu_bag(**args)
        assert not Path(overrides['path']).exists()
    (tmp_path / 'taken.mcap').write_bytes(b'x')
    with pytest.raises(InputError, match='exists already'):
        write_imu_bag(tmp_path / 'taken.mcap', stamps, samples)


def test_csv_to_bag_round_trip(tmp_path):
    stamps, samples = _recording(200, seed=5)
    t_s = np.arange(200) * 0.01   # relative seconds, exactly representable steps
    csv = tmp_path / 'log.csv'
    lines = ['t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z']
    lines += [','.join([f'{t:.2f}'] + [repr(float(v)) for v in row])
              for t, row in zip(t_s, samples)]
    csv.write_text('\n'.join(lines) + '\n')
    assert csv_to_bag(csv, tmp_path / 'log.mcap', start_ns=T0_NS) == 200
    with open_imu(tmp_path / 'log.mcap') as source:
        block = source.read_all()
    assert_array_equal(block.stamp_ns, T0_NS + np.arange(200) * 10_000_000)
    assert_array_equal(block.samples, samples)
