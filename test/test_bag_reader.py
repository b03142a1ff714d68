"""
Tests of imu_allan.io.bag_reader: every storage, odd layouts, bad inputs, real bags.

Reference values come from rosbags' own per-message (de)serialisers, from the
mcap package's writer, or from the data that was written (exact round trips:
float64 values and integer nanoseconds must come back bit for bit).
"""

import os
from pathlib import Path
import re
import shutil

from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer as McapWriter
import numpy as np
from numpy.testing import assert_array_equal
import pytest
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin, Writer as Ros2Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.typesys import get_typestore, Stores
import yaml

from conftest import T0_NS
from imu_allan.errors import InputError
from imu_allan.io.bag_reader import list_imu_topics, list_topics, open_imu
from imu_allan.io.bag_writer import DEFAULT_LATENCY_NS, serialize_imu, write_imu_bag
from imu_allan.io.bags.base import ImuBlock
from imu_allan.io.bags.sqlite_pages import NotPlain, SqlitePages
from imu_allan.io.imu_cdr import decode_imu_cdr, decode_imu_payloads, payload_frames

IMU = 'sensor_msgs/msg/Imu'
ROS2 = get_typestore(Stores.ROS2_JAZZY)
ROS1 = get_typestore(Stores.ROS1_NOETIC)


def _recording(n: int, seed: int, rate_hz: float = 400.0):
    """Return (stamps_ns (n,) int64 with jitter, samples (n, 6) float64)."""
    rng = np.random.default_rng(seed)
    stamps = T0_NS + np.round(np.arange(n) * 1e9 / rate_hz + rng.uniform(0, 2e5, n))
    samples = rng.normal(size=(n, 6)) * [1e-2, 1e-2, 1e-2, 0.1, 0.1, 0.1]
    samples[:, 5] += 9.80665
    return stamps.astype(np.int64), samples


def _imu_msg(store, stamp_ns: int, values, frame_id: str):
    """Build a sensor_msgs/Imu object of a rosbags type store."""
    types = store.types
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    header = {'stamp': types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec),
              'frame_id': frame_id}
    if store is ROS1:
        header['seq'] = 0
    vec = types['geometry_msgs/msg/Vector3']
    return types[IMU](
        header=types['std_msgs/msg/Header'](**header),
        orientation=types['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.r_[-1.0, np.zeros(8)],
        angular_velocity=vec(x=values[0], y=values[1], z=values[2]),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=vec(x=values[3], y=values[4], z=values[5]),
        linear_acceleration_covariance=np.zeros(9))


def _write_rosbags2(path: Path, topics: dict, storage: StoragePlugin,
                    extra_topic: bool = True) -> None:
    """
    Write a rosbag2 bag with rosbags' per-message serialisation.

    topics maps name -> (stamps_ns, recv_ns, samples, frame_ids); messages of all topics
    are interleaved by receive time, as a recorder writes them.
    """
    with Ros2Writer(path, version=9, storage_plugin=storage) as writer:
        rows = []
        for name, (stamps, recv, samples, frames) in topics.items():
            conn = writer.add_connection(name, IMU, typestore=ROS2)
            for i in range(stamps.size):
                rows.append((int(recv[i]), conn, _imu_msg(ROS2, stamps[i], samples[i], frames[i])))
        if extra_topic:
            conn = writer.add_connection('/status', 'std_msgs/msg/String', typestore=ROS2)
            status = ROS2.types['std_msgs/msg/String'](data='ok')
            rows += [(T0_NS + k * 10**8, conn, status) for k in range(5)]
        for recv, conn, msg in sorted(rows, key=lambda r: r[0]):
            writer.write(conn, recv, bytes(ROS2.serialize_cdr(msg, conn.msgtype)))


def _assert_topic(block: ImuBlock, stamps, recv, samples) -> None:
    assert_array_equal(block.stamp_ns, stamps)
    assert_array_equal(block.recv_ns, recv)
    assert_array_equal(block.samples, samples)
    assert block.stamp_ns.dtype == np.int64 and block.samples.dtype == np.float64


# -- round trips through the project's writer ---------------------------------------

@pytest.mark.parametrize('name, storage, expected', [
    ('single.mcap', None, 'mcap'), ('single.db3', None, 'sqlite3'),
    ('dir_mcap', None, 'mcap'), ('dir_sqlite', 'sqlite3', 'sqlite3'), ('ros1.bag', None, 'ros1')])
def test_round_trip_is_exact(tmp_path, name, storage, expected):
    stamps, samples = _recording(7000, seed=1)
    write_imu_bag(tmp_path / name, stamps, samples, storage=storage)
    with open_imu(tmp_path / name) as source:
        assert (source.topic, source.n_messages, source.storage) == ('/imu/data', 7000,
                                                                     expected)
        blocks = list(source.blocks(block_size=3000))
        assert [b.stamp_ns.size for b in blocks] == [3000, 3000, 1000]
        _assert_topic(source.read_all(), stamps, stamps + DEFAULT_LATENCY_NS, samples)
        assert source.warnings == []
    assert list_imu_topics(tmp_path / name) == [
        ('/imu/data', 'sensor_msgs/Imu' if expected == 'ros1' else IMU, 7000)]


# -- bags written message by message with rosbags ------------------------------------

@pytest.mark.parametrize('storage', [StoragePlugin.SQLITE3, StoragePlugin.MCAP])
def test_rosbags_written_bag_with_two_imu_topics(tmp_path, storage):
    stamps_a, samples_a = _recording(600, seed=2)
    stamps_b, samples_b = _recording(300, seed=3, rate_hz=200.0)
    # Receive time is not header.stamp: later, with its own jitter.
    recv_a = stamps_a + 3_000_000 + np.arange(600) % 7 * 1000
    recv_b = stamps_b + 5_000_000
    # frame_id lengths 1..12 bytes change the payload layout (padding) message by message.
    frames_a = [('imu' + 'x' * (i % 10))[: i % 12] for i in range(600)]
    frames_b = ['imu_b'] * 300
    bag = tmp_path / 'bag'
    _write_rosbags2(bag, {'/imu/a': (stamps_a, recv_a, samples_a, frames_a),
                          '/imu/b': (stamps_b, recv_b, samples_b, frames_b)}, storage)
    with pytest.raises(InputError, match=r'2 Imu topics: /imu/a \(sensor_msgs/msg/Imu, 600 '
                                         r'messages\), /imu/b .*--topic'):
        open_imu(bag)
    with open_imu(bag, topic='imu/b') as source:
        _assert_topic(source.read_all(), stamps_b, recv_b, samples_b)
        assert source.warnings == [] and source.frame_counts == {'imu_b': 300}
    # Twelve frame_ids on /imu/a are twelve sources: refused together, each read alone.
    with pytest.raises(InputError, match=r'/imu/a carries 12 IMUs \(header.frame_id\): '
                                         r'\(empty\) \(50 messages\), i \(50 messages\), '
                                         r'.* and 4 more; choose one with --frame-id NAME'):
        open_imu(bag, topic='/imu/a').read_all()
    for frame in sorted(set(frames_a)):
        mine = np.array(frames_a) == frame
        with open_imu(bag, topic='/imu/a', frame_id=frame) as source:
            _assert_topic(source.read_all(), stamps_a[mine], recv_a[mine], samples_a[mine])
            assert source.n_lost == 0 and source.frame_id == frame
            assert re.fullmatch(rf'{600 - mine.sum()} messages of other IMUs on /imu/a skipped '
                                rf"\(frame_id '{frame}' read; others: .*\)", source.warnings[0])
    assert [t.topic for t in list_imu_topics(bag)] == ['/imu/a', '/imu/b']
    assert {t.topic: t.n_messages for t in list_topics(bag)}['/status'] == 5
    with pytest.raises(InputError, match='/status is std_msgs/msg/String, not sensor_msgs'):
        open_imu(bag, topic='/status')
    with pytest.raises(InputError, match='no topic /nope; Imu topics: /imu/a'):
        open_imu(bag, topic='/nope')


@pytest.mark.parametrize('mode', [CompressionMode.FILE, CompressionMode.MESSAGE])
def test_zstd_compressed_rosbag2(tmp_path, mode):
    stamps, samples = _recording(200, seed=4)
    bag = tmp_path / 'bag'
    writer = Ros2Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3)
    writer.set_compression(mode, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection('/imu', IMU, typestore=ROS2)
        for i in range(200):
            msg = _imu_msg(ROS2, stamps[i], samples[i], 'imu')
            writer.write(conn, int(stamps[i]), bytes(ROS2.serialize_cdr(msg, IMU)))
    with open_imu(bag) as source:
        _assert_topic(source.read_all(), stamps, stamps, samples)


def test_ros1_bag_written_by_rosbags(tmp_path):
    stamps, samples = _recording(500, seed=5)
    bag = tmp_path / 'r1.bag'
    with Ros1Writer(bag) as writer:
        conn = writer.add_connection('/imu/raw', IMU, typestore=ROS1)
        other = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=ROS1)
        for i in range(500):
            msg = _imu_msg(ROS1, stamps[i], samples[i], 'imu_link' if i % 3 else 'i')
            writer.write(conn, int(stamps[i]) + 1_000_000, bytes(ROS1.serialize_ros1(msg, IMU)))
        writer.write(other, T0_NS, bytes(ROS1.serialize_ros1(
            ROS1.types['std_msgs/msg/String'](data='hi'), 'std_msgs/msg/String')))
    assert list_imu_topics(bag) == [('/imu/raw', 'sensor_msgs/Imu', 500)]
    with pytest.raises(InputError, match=r'/imu/raw carries 2 IMUs \(header.frame_id\): '
                                         r'i \(167 messages\), imu_link \(333 messages\)'):
        open_imu(bag).read_all()
    for frame, mine in (('i', np.arange(500) % 3 == 0), ('imu_link', np.arange(500) % 3 > 0)):
        with open_imu(bag, frame_id=frame) as source:
            assert source.storage == 'ros1'
            _assert_topic(source.read_all(), stamps[mine], stamps[mine] + 1_000_000,
                          samples[mine])


def test_mcap_library_files_lz4_chunks_without_index_and_unchunked(tmp_path):
    # Files from the mcap package's own writer: schema and channel records inside the
    # chunks, lz4 chunks without message indexes, or no chunks at all.
    stamps, samples = _recording(3000, seed=6)
    payloads = serialize_imu(stamps, samples, 'imu')
    msgdef, _ = ROS2.generate_msgdef(IMU, ros_version=2)
    for name, options in [('lz4.mcap', {'compression': CompressionType.LZ4,
                                        'index_types': IndexType.NONE, 'chunk_size': 50_000}),
                          ('plain.mcap', {'use_chunking': False})]:
        with open(tmp_path / name, 'wb') as stream:
            writer = McapWriter(stream, **options)
            writer.start(profile='ros2')
            schema = writer.register_schema(IMU, 'ros2msg', msgdef.encode())
            channel = writer.register_channel('/imu', 'cdr', schema)
            for i in range(stamps.size):
                writer.add_message(channel, int(stamps[i]) + 7, payloads[i].tobytes(),
                                   int(stamps[i]))
            writer.finish()
        with open_imu(tmp_path / name) as source:
            assert source.n_messages == 3000
            _assert_topic(source.read_all(), stamps, stamps + 7, samples)
    # The ros1 profile: ROS 1 serialised messages in MCAP.
    with open(tmp_path / 'ros1.mcap', 'wb') as stream:
        writer = McapWriter(stream)
        writer.start(profile='ros1')
        schema = writer.register_schema('sensor_msgs/Imu', 'ros1msg', b'')
        channel = writer.register_channel('/imu1', 'ros1', schema)
        for i, raw in enumerate(serialize_imu(stamps[:99], samples[:99], ros1=True)):
            writer.add_message(channel, int(stamps[i]), raw.tobytes(), int(stamps[i]))
        writer.finish()
    assert list_imu_topics(tmp_path / 'ros1.mcap') == [('/imu1', 'sensor_msgs/Imu', 99)]
    with open_imu(tmp_path / 'ros1.mcap') as source:
        _assert_topic(source.read_all(), stamps[:99], stamps[:99], samples[:99])


def test_mcap_log_times_out_of_order_and_a_damaged_payload(tmp_path):
    stamps, samples = _recording(400, seed=13)
    payloads = [p.tobytes() for p in serialize_imu(stamps, samples, 'imu')]
    payloads[150] = payloads[150][:20]                      # not an Imu any more
    recv = stamps + 9
    recv[10], recv[11] = recv[11], recv[10]                 # log times out of order
    msgdef, _ = ROS2.generate_msgdef(IMU, ros_version=2)
    with open(tmp_path / 'odd.mcap', 'wb') as stream:
        writer = McapWriter(stream, chunk_size=4_000)
        writer.start(profile='ros2')
        schema = writer.register_schema(IMU, 'ros2msg', msgdef.encode())
        channel = writer.register_channel('/imu', 'cdr', schema)
        for i in range(stamps.size):
            writer.add_message(channel, int(recv[i]), payloads[i], int(stamps[i]))
        writer.finish()
    with open_imu(tmp_path / 'odd.mcap') as source:
        block = source.read_all()
        warnings = list(source.warnings)
        assert (source.n_read, source.n_lost) == (399, 1)
    keep = np.arange(400) != 150
    # Header-stamp order, whatever the log times say.
    _assert_topic(block, stamps[keep], recv[keep][np.argsort(stamps[keep])], samples[keep])
    assert any('1 messages on /imu are not decodable' in w for w in warnings)
    assert any('1 of 400 messages on /imu lost (399 read)' in w for w in warnings)


def _mixed_cdr(seed: int):
    """Six Imu messages, both byte orders, frame ids of 0-5 characters, then garbage."""
    stamps, samples = _recording(6, seed=seed)
    msgs = [_imu_msg(ROS2, stamps[i], samples[i], 'f' * i) for i in range(6)]
    payloads = [bytes(ROS2.serialize_cdr(m, IMU, little_endian=i % 2 == 0))
                for i, m in enumerate(msgs)]
    payloads.append(b'\x00\x01\x00\x00' + b'\x07' * 10)   # too short to be an Imu
    return stamps, samples, msgs, payloads


def test_decoder_handles_big_endian_odd_lengths_and_garbage():
    stamps, samples, _, payloads = _mixed_cdr(seed=7)
    stamp_ns, values, ok = decode_imu_payloads(
        np.frombuffer(b''.join(payloads), np.uint8),
        np.cumsum([0] + [len(p) for p in payloads[:-1]]), [len(p) for p in payloads])
    assert_array_equal(ok, [True] * 6 + [False])
    assert_array_equal(stamp_ns[:6], stamps)
    assert_array_equal(values[:6], samples)
    assert_array_equal(decode_imu_cdr(payloads[:6])[1], samples)
    with pytest.raises(InputError, match='1 of 7 payloads'):
        decode_imu_cdr(payloads)


def test_ros1_payloads_decode_alike():
    stamps, samples = _recording(5, seed=9)
    payloads = [bytes(ROS1.serialize_ros1(_imu_msg(ROS1, stamps[i], samples[i], 'x' * i), IMU))
                for i in range(5)]
    payloads[2] = payloads[2][:40]      # cut short: rosbags cannot decode it either
    stamp_ns, values, ok = decode_imu_payloads(
        np.frombuffer(b''.join(payloads), np.uint8),
        np.cumsum([0] + [len(p) for p in payloads[:-1]]), [len(p) for p in payloads], 'ros1')
    assert_array_equal(ok, [True, True, False, True, True])
    assert_array_equal(stamp_ns[ok], stamps[ok])
    assert_array_equal(values[ok], samples[ok])
    assert np.isnan(values[2]).all()


@pytest.mark.parametrize('ros1', [False, True])
def test_payload_frames_match_rosbags_in_both_byte_orders(ros1):
    # Equal frames take the one-comparison path, mixed ones the per-message path; both
    # give rosbags' header.frame_id, for either CDR byte order and for ROS 1.
    stamps, samples = _recording(8, seed=33)
    store = ROS1 if ros1 else ROS2
    for frames in (['imu_link'] * 8, [''] * 8, ['a', 'imu', '', 'a', 'bb', 'imu', 'a', ''],
                   ['x' * 20] * 7 + ['x' * 19 + 'y']):
        msgs = [_imu_msg(store, stamps[i], samples[i], frames[i]) for i in range(8)]
        for big in ([False], [True], [i % 2 == 1 for i in range(8)])[:1 if ros1 else 3]:
            payloads = [bytes(ROS1.serialize_ros1(m, IMU)) if ros1 else
                        bytes(ROS2.serialize_cdr(m, IMU, little_endian=not big[i % len(big)]))
                        for i, m in enumerate(msgs)]
            u8, starts, lengths = (np.frombuffer(b''.join(payloads), np.uint8),
                                   np.cumsum([0] + [len(p) for p in payloads[:-1]]),
                                   np.array([len(p) for p in payloads]))
            names, index = payload_frames(u8, starts, lengths, 'ros1' if ros1 else 'cdr')
            got = [names[0]] * 8 if index is None else [names[k] for k in index]
            assert got == [m.header.frame_id for m in msgs], (frames, big)
            assert names == list(dict.fromkeys(frames))   # in order of first appearance
            assert (index is None) == (len(set(frames)) == 1)


# -- bad inputs ---------------------------------------------------------------------

def test_bad_paths_and_files(tmp_path):
    with pytest.raises(InputError, match='no such file'):
        open_imu(tmp_path / 'missing.mcap')
    (tmp_path / 'empty.mcap').write_bytes(b'')
    with pytest.raises(InputError, match='empty file'):
        open_imu(tmp_path / 'empty.mcap')
    (tmp_path / 'junk.db3').write_bytes(os.urandom(4096))
    with pytest.raises(InputError, match='not a bag'):
        list_imu_topics(tmp_path / 'junk.db3')
    (tmp_path / 'fake.db3').write_bytes(b'SQLite format 3\x00' + bytes(5000))
    with pytest.raises(InputError, match='damaged or not a sqlite3 database'):
        open_imu(tmp_path / 'fake.db3')
    (tmp_path / 'somedir').mkdir()
    with pytest.raises(InputError, match='not a rosbag2 bag'):
        open_imu(tmp_path / 'somedir')


def test_truncated_sqlite_is_a_clear_error(tmp_path):
    stamps, samples = _recording(3000, seed=8)
    write_imu_bag(tmp_path / 'whole.db3', stamps, samples)
    data = (tmp_path / 'whole.db3').read_bytes()
    (tmp_path / 'cut.db3').write_bytes(data[:len(data) // 2])
    with pytest.raises(InputError, match=r'cut.db3: damaged or not a sqlite3 database'):
        open_imu(tmp_path / 'cut.db3')


def test_empty_bag_and_bag_without_imu(tmp_path):
    write_imu_bag(tmp_path / 'empty.mcap', np.zeros(0, np.int64), np.zeros((0, 6)))
    with pytest.raises(InputError, match=r'/imu/data has no messages \(empty bag\)'):
        open_imu(tmp_path / 'empty.mcap')
    bag = tmp_path / 'status_only'
    _write_rosbags2(bag, {}, StoragePlugin.SQLITE3)
    with pytest.raises(InputError, match=r'no sensor_msgs/msg/Imu topic; topics: /status '
                                         r'\(std_msgs/msg/String, 5 messages\)'):
        open_imu(bag)
    assert list_imu_topics(bag) == []


@pytest.mark.parametrize('compressed', [True, False])
def test_truncated_mcap_recovers_every_complete_message(tmp_path, compressed):
    stamps, samples = _recording(12000, seed=9)
    whole = tmp_path / 'whole.mcap'
    if compressed:
        write_imu_bag(whole, stamps, samples)   # zstd chunks of about 1 MiB
    else:
        payloads = serialize_imu(stamps, samples)
        with open(whole, 'wb') as stream:
            writer = McapWriter(stream, compression=CompressionType.NONE)
            writer.start(profile='ros2')
            schema = writer.register_schema(IMU, 'ros2msg', b'')
            channel = writer.register_channel('/imu/data', 'cdr', schema)
            for i in range(stamps.size):
                writer.add_message(channel, int(stamps[i]), payloads[i].tobytes(),
                                   int(stamps[i]))
            writer.finish()
    data = whole.read_bytes()
    log_ns = stamps + (DEFAULT_LATENCY_NS if compressed else 0)
    with open(whole, 'rb') as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes
    for fraction in (0.37, 0.81):
        cut_at = int(len(data) * fraction)
        cut = tmp_path / f'cut_{fraction}.mcap'
        cut.write_bytes(data[:cut_at])
        with open_imu(cut) as source:
            block = source.read_all()
            assert any('truncated' in w for w in source.warnings)
        k = block.stamp_ns.size
        # Bounds from the intact file: all messages of the chunks before the cut, at most
        # those of the chunk that is cut (its complete records, or zstd blocks, come back).
        done = [c for c in chunks if c.chunk_start_offset + c.chunk_length <= cut_at]
        torn = next(c for c in chunks if c.chunk_start_offset + c.chunk_length > cut_at)
        k_min = np.count_nonzero(log_ns <= done[-1].message_end_time)
        k_max = np.count_nonzero(log_ns <= torn.message_end_time)
        assert k_min <= k <= k_max
        if not compressed:
            assert k > k_min   # the torn chunk's complete messages are recovered
        _assert_topic(block, stamps[:k], log_ns[:k], samples[:k])
    # Summary and footer lost, data section complete.
    summary_start = int.from_bytes(data[-37 + 9:-37 + 17], 'little')
    (tmp_path / 'nosummary.mcap').write_bytes(data[:summary_start])
    with open_imu(tmp_path / 'nosummary.mcap') as source:
        assert source.read_all().stamp_ns.size == stamps.size
        assert source.n_messages == stamps.size


def test_metadata_missing_or_broken_falls_back_to_storage_files(tmp_path):
    stamps, samples = _recording(1000, seed=10)
    for storage in ('mcap', 'sqlite3'):
        bag = tmp_path / f'bag_{storage}'
        write_imu_bag(bag, stamps, samples, storage=storage)
        (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: [unclosed\n')
        with open_imu(bag) as source:
            _assert_topic(source.read_all(), stamps, stamps + DEFAULT_LATENCY_NS, samples)
            assert any('metadata.yaml: unparsable' in w for w in source.warnings)
        (bag / 'metadata.yaml').unlink()
        with open_imu(bag) as source:
            assert source.read_all().stamp_ns.size == 1000
            assert any('no metadata.yaml' in w for w in source.warnings)
    write_imu_bag(tmp_path / 'intact', stamps, samples)
    with open_imu(tmp_path / 'intact' / 'metadata.yaml') as source:   # the file names the bag
        assert source.n_messages == 1000 and source.warnings == []


def test_split_bag_reads_files_in_order(tmp_path):
    stamps, samples = _recording(900, seed=11)
    bag = tmp_path / 'split'
    bag.mkdir()
    for part, (begin, end) in enumerate([(0, 400), (400, 900)]):
        write_imu_bag(bag / f'split_{part}.db3', stamps[begin:end], samples[begin:end])
    # Foxy-style metadata (version 4): paths prefixed with the bag name, QoS as a string.
    (bag / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  version: 4\n  storage_identifier: sqlite3\n'
        '  relative_file_paths: [split/split_0.db3, split/split_1.db3]\n'
        '  duration: {nanoseconds: 1}\n  starting_time: {nanoseconds_since_epoch: 1}\n'
        '  message_count: 900\n  topics_with_message_count:\n'
        '    - topic_metadata: {name: /imu/data, type: sensor_msgs/msg/Imu,'
        " serialization_format: cdr, offered_qos_profiles: ''}\n      message_count: 900\n")
    with open_imu(bag) as source:
        assert source.n_messages == 900
        _assert_topic(source.read_all(), stamps, stamps + DEFAULT_LATENCY_NS, samples)
        assert source.warnings == []


def test_zero_header_stamps_are_reported(tmp_path):
    _, samples = _recording(50, seed=12)
    write_imu_bag(tmp_path / 'z.mcap', np.zeros(50, np.int64), samples)
    with open_imu(tmp_path / 'z.mcap') as source:
        source.read_all()
        assert any('header.stamp is 0 in 50 of 50' in w for w in source.warnings)


# -- real recordings -----------------------------------------------------------------

def test_real_foxy_sqlite_bag_constant_values(shared_dir):
    bag = shared_dir / 'realdata' / 'rosbag2_foxy_db3' / 'rosbag2_test'
    assert list_imu_topics(bag) == [('/imu', IMU, 1565)]
    with open_imu(bag) as source:
        block = source.read_all()
        assert source.warnings == []
    assert block.samples.shape == (1565, 6)
    assert (block.samples == [131.0, 132.0, 133.0, 151.0, 152.0, 153.0]).all()
    # header.stamp is the publisher's clock, recv_ns the recorder's: they differ.
    assert (np.diff(block.stamp_ns) > 0).all() and (block.stamp_ns != block.recv_ns).all()
    assert abs(block.stamp_ns[0] - block.recv_ns[0]) < 10**9
    assert 62.0 < (block.stamp_ns[-1] - block.stamp_ns[0]) * 1e-9 < 63.0


@pytest.mark.parametrize('name, count', [('test1.bag', 11865), ('test2.bag', 3061)])
def test_real_ros1_bags_match_rosbags_deserialiser(shared_dir, name, count):
    from rosbags.rosbag1 import Reader

    bag = shared_dir / 'realdata' / 'ros1_moving_robot' / name
    with open_imu(bag) as source:
        assert (source.topic, source.n_messages, source.storage) == ('/imu/data', count,
                                                                     'ros1')
        block = source.read_all()
    assert block.stamp_ns.size == count and np.isfinite(block.samples).all()
    picks = {0, 1, count // 2, count - 1}
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == '/imu/data']
        for i, (_, recv, raw) in enumerate(reader.messages(connections=conns)):
            if i in picks:
                msg = ROS1.deserialize_ros1(raw, IMU)
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                av, la = msg.angular_velocity, msg.linear_acceleration
                assert block.stamp_ns[i] == stamp and block.recv_ns[i] == recv
                assert_array_equal(block.samples[i], [av.x, av.y, av.z, la.x, la.y, la.z])


def test_truncated_ros1_bag_is_a_clear_error(shared_dir, tmp_path):
    data = (shared_dir / 'realdata' / 'ros1_moving_robot' / 'test2.bag').read_bytes()
    (tmp_path / 'cut.bag').write_bytes(data[:len(data) // 2])
    with pytest.raises(InputError, match='unreadable ROS 1 bag .*rosbag reindex'):
        open_imu(tmp_path / 'cut.bag')


def test_single_db3_file_is_read_directly(shared_dir):
    db3 = shared_dir / 'realdata' / 'rosbag2_foxy_db3' / 'rosbag2_test' / 'rosbag2_test_0.db3'
    with open_imu(db3) as source:
        assert source.topic == '/imu'
        assert source.read_all().stamp_ns.size == 1565
        assert source.warnings == []
    assert {t.topic: t.n_messages for t in list_topics(db3)}['/battery'] == 1565


# -- the direct sqlite page reader ----------------------------------------------------

def _sqlite_both_ways(db3: Path, topic: str):
    """Read a topic with the page reader (asserting it was used) and with SQL."""
    with open_imu(db3, topic) as source:
        backend = source._backend
        own = next(t for t in backend.topics() if t.name == source.topic)
        pages = SqlitePages(db3, backend.conn)
        got = list(pages.pieces(backend.ids[own.name, own.msgtype], own.encoding))
        assert sum(p.recv_ns.size for p, _ in got) == backend.count(own)
        fast = source.read_all()
    with open_imu(db3, topic) as source:
        backend = source._backend
        backend.pieces = lambda topic: backend._sql_pieces(topic, 0)
        slow = source.read_all()
    for field in ImuBlock._fields:
        assert_array_equal(getattr(fast, field), getattr(slow, field))
    return fast


@pytest.mark.parametrize('page_size', [512, 4096, 65536])
def test_sqlite_page_reader_matches_sql(tmp_path, page_size):
    import sqlite3

    stamps, samples = _recording(3000, seed=13)
    db3 = tmp_path / 'mixed.db3'
    write_imu_bag(tmp_path / 'src.db3', stamps, samples)
    src = sqlite3.connect(tmp_path / 'src.db3')
    conn = sqlite3.connect(db3)
    conn.execute(f'PRAGMA page_size = {page_size}')
    for (sql,) in src.execute('SELECT sql FROM sqlite_master WHERE sql IS NOT NULL'):
        conn.execute(sql)
    rows = src.execute('SELECT topic_id, timestamp, data FROM messages ORDER BY id').fetchall()
    topics = src.execute('SELECT * FROM topics').fetchall()
    conn.executemany(f'INSERT INTO topics VALUES ({",".join("?" * len(topics[0]))})', topics)
    conn.execute('INSERT INTO topics (id, name, type, serialization_format, '
                 'offered_qos_profiles, type_description_hash) VALUES '
                 "(7, '/camera', 'sensor_msgs/msg/Image', 'cdr', '', '')")
    rng = np.random.default_rng(14)
    out = []
    for k, (topic_id, stamp, data) in enumerate(rows):
        out.append((k + 1, topic_id, stamp, data))
        if k % 97 == 0:
            # Large messages of another topic spill to overflow pages.
            out.append((10**6 + k, 7, stamp + 1, rng.bytes(int(rng.integers(10, 20000)))))
    # Rows out of time order and rowids of every varint length (1 to 9 bytes).
    out[10], out[11] = out[11], out[10]
    out[20] = (2**40,) + out[20][1:]
    out[21] = (2**62,) + out[21][1:]
    conn.executemany('INSERT INTO messages (id, topic_id, timestamp, data) VALUES (?, ?, ?, ?)',
                     out)
    conn.commit()
    conn.close()
    block = _sqlite_both_ways(db3, '/imu/data')
    assert block.stamp_ns.size == 3000
    assert (np.diff(block.recv_ns) >= 0).all()


def test_sqlite_page_reader_refuses_what_it_cannot_vouch_for(tmp_path):
    import sqlite3

    stamps, samples = _recording(500, seed=15)
    # Messages larger than a page: the topic itself spills to overflow pages.
    db3 = tmp_path / 'big.db3'
    write_imu_bag(db3, stamps, samples, frame_id='f' * 5000)
    with open_imu(db3) as source:
        backend = source._backend
        pages = SqlitePages(db3, backend.conn)
        with pytest.raises(NotPlain, match='overflow'):
            list(pages.pieces(list(backend.ids['/imu/data', IMU]), 'cdr'))
        _assert_topic(source.read_all(), stamps, stamps + DEFAULT_LATENCY_NS, samples)
    # A write-ahead log next to the file: SQL reads it (committed rows live in the log).
    db3 = tmp_path / 'wal.db3'
    write_imu_bag(db3, stamps, samples)
    conn = sqlite3.connect(db3)
    conn.execute('PRAGMA journal_mode = WAL')
    conn.execute('PRAGMA wal_autocheckpoint = 0')
    conn.execute('DELETE FROM messages WHERE id > 400')
    conn.commit()
    try:
        with pytest.raises(NotPlain, match='wal'):
            SqlitePages(db3, conn)
        with open_imu(db3) as source:
            assert source.read_all().stamp_ns.size == 400
    finally:
        conn.close()


# -- damaged and unusual inputs: what is lost is counted ------------------------------

def _mcap_by_library(path: Path, stamps, recv, samples, **options) -> None:
    """Write an MCAP file with the mcap package, messages in the given order."""
    payloads = serialize_imu(stamps, samples, 'imu')
    with open(path, 'wb') as stream:
        writer = McapWriter(stream, **options)
        writer.start(profile='ros2')
        schema = writer.register_schema(IMU, 'ros2msg', b'')
        channel = writer.register_channel('/imu', 'cdr', schema)
        for i in range(stamps.size):
            writer.add_message(channel, int(recv[i]), payloads[i].tobytes(), int(stamps[i]))
        writer.finish()


def test_mcap_overlapping_chunks_and_jittered_log_times_lose_nothing(tmp_path):
    stamps, samples = _recording(4000, seed=21)
    # Even messages first, then odd ones: the chunks overlap in time (valid MCAP).
    order = np.r_[np.arange(0, 4000, 2), np.arange(1, 4000, 2)]
    _mcap_by_library(tmp_path / 'overlap.mcap', stamps[order], stamps[order], samples[order],
                     chunk_size=20_000)
    # Log times that jitter by more than the sample period against the stamps.
    rng = np.random.default_rng(22)
    jitter = stamps + rng.integers(0, 6_000_000, 4000)
    _mcap_by_library(tmp_path / 'jitter.mcap', stamps, jitter, samples, chunk_size=20_000)
    for name, recv in (('overlap.mcap', stamps), ('jitter.mcap', jitter)):
        with open_imu(tmp_path / name) as source:
            block = source.read_all()
            assert (source.warnings, source.n_read, source.n_lost) == ([], 4000, 0)
        _assert_topic(block, stamps, recv, samples)


def _chunks(path: Path) -> list:
    with open(path, 'rb') as stream:
        return make_reader(stream).get_summary().chunk_indexes


@pytest.mark.parametrize('compression, damage', [
    (CompressionType.NONE, 'flip'), (CompressionType.ZSTD, 'flip'),
    (CompressionType.ZSTD, 'length')])
def test_mcap_damaged_chunk_or_record_length_costs_that_chunk_only(tmp_path, compression,
                                                                   damage):
    stamps, samples = _recording(3000, seed=23)
    path = tmp_path / 'bag.mcap'
    _mcap_by_library(path, stamps, stamps, samples, chunk_size=20_000, compression=compression)
    second = _chunks(path)[1]
    inside = (stamps >= second.message_start_time) & (stamps <= second.message_end_time)
    lost = int(np.count_nonzero(inside))
    data = bytearray(path.read_bytes())
    if damage == 'flip':        # one byte of the chunk's last message or compressed data
        data[second.chunk_start_offset + second.chunk_length - 100] ^= 0x10
    else:                       # a record length of 2**64 - 1
        data[second.chunk_start_offset + 1:second.chunk_start_offset + 9] = b'\xff' * 8
    path.write_bytes(bytes(data))
    with open_imu(path) as source:
        block = source.read_all()
        assert (source.n_read, source.n_lost) == (3000 - lost, lost)
        assert f'{lost} of 3000 messages on /imu lost ({3000 - lost} read)' in source.warnings
    _assert_topic(block, stamps[~inside], stamps[~inside], samples[~inside])


def test_mcap_resync_reads_the_messages_of_an_uncompressed_chunk_whose_length_is_bad(
        tmp_path):
    stamps, samples = _recording(3000, seed=23)
    path = tmp_path / 'bag.mcap'
    _mcap_by_library(path, stamps, stamps, samples, chunk_size=20_000,
                     compression=CompressionType.NONE)
    second = _chunks(path)[1]
    data = bytearray(path.read_bytes())
    data[second.chunk_start_offset + 1:second.chunk_start_offset + 9] = b'\xff' * 8
    path.write_bytes(bytes(data))
    with open_imu(path) as source:
        _assert_topic(source.read_all(), stamps, stamps, samples)
        assert source.n_lost == 0 and any('resumed at byte' in w for w in source.warnings)


def test_mcap_file_that_shrinks_while_read_is_a_truncation(tmp_path):
    stamps, samples = _recording(20000, seed=24)
    path = tmp_path / 'shrinks.mcap'
    _mcap_by_library(path, stamps, stamps, samples, chunk_size=50_000)
    with open_imu(path) as source:
        blocks = source.blocks(block_size=1000)
        next(blocks)
        os.truncate(path, path.stat().st_size // 3)
        rest = sum(b.stamp_ns.size for b in blocks)
        assert 1000 + rest < 20000 and source.n_lost == 20000 - source.n_read
        assert any('lost' in w for w in source.warnings)


def _rowwise(db3: Path) -> int:
    """Rows SQL can read one rowid at a time (the most a damaged file gives)."""
    import sqlite3

    conn = sqlite3.connect(f'file:{db3}?immutable=1', uri=True)
    good = 0
    for rowid in range(1, 3001):
        try:
            good += conn.execute('SELECT data FROM messages WHERE id = ?',
                                 (rowid,)).fetchone() is not None
        except sqlite3.DatabaseError:
            pass
    conn.close()
    return good


def test_sqlite_damaged_page_is_read_around(tmp_path):
    stamps, samples = _recording(3000, seed=25)
    db3 = tmp_path / 'bag.db3'
    write_imu_bag(db3, stamps, samples)
    data = bytearray(db3.read_bytes())
    page = int.from_bytes(data[16:18], 'big')
    middle = len(data) // page // 2
    data[middle * page:(middle + 1) * page] = bytes(page)     # one leaf page zeroed
    db3.write_bytes(bytes(data))
    readable = _rowwise(db3)
    assert 2900 < readable < 3000
    with open_imu(db3) as source:
        block = source.read_all()
        assert (source.n_read, source.n_lost) == (readable, 3000 - readable)
        assert any('damaged sqlite3 page' in w for w in source.warnings)
    assert np.isin(block.stamp_ns, stamps).all()


def test_sqlite_wal_bag_in_a_read_only_place_is_copied_aside(tmp_path, monkeypatch):
    import sqlite3

    from imu_allan.io.bags import rosbag2_sqlite

    stamps, samples = _recording(600, seed=26)
    db3 = tmp_path / 'wal.db3'
    write_imu_bag(db3, stamps[:300], samples[:300])
    writer = sqlite3.connect(db3)
    writer.execute('PRAGMA journal_mode = WAL')
    writer.execute('PRAGMA wal_autocheckpoint = 0')
    rows = writer.execute('SELECT topic_id, timestamp, data FROM messages').fetchall()
    payloads = serialize_imu(stamps[300:], samples[300:])
    writer.executemany('INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)',
                       [(rows[0][0], int(s), p.tobytes()) for s, p in zip(stamps[300:],
                                                                          payloads)])
    writer.commit()
    assert (tmp_path / 'wal.db3-wal').stat().st_size > 0
    # As in a read-only directory: read-only mode cannot make its shared-memory file.
    connect = sqlite3.connect

    def read_only_place(database, *args, **kwargs):
        if str(tmp_path) in str(database) and 'mode=ro' in str(database):
            raise sqlite3.OperationalError('unable to open database file')
        return connect(database, *args, **kwargs)
    monkeypatch.setattr(rosbag2_sqlite.sqlite3, 'connect', read_only_place)
    try:
        with open_imu(db3) as source:
            block = source.read_all()
            assert any('copied to a temporary directory' in w for w in source.warnings)
        assert (block.stamp_ns.size, source.n_lost) == (600, 0)
    finally:
        writer.close()


def test_metadata_counts_are_hints_and_odd_file_names_are_skipped(tmp_path):
    stamps, samples = _recording(500, seed=27)
    bag = tmp_path / 'bag'
    write_imu_bag(bag, stamps, samples, storage='sqlite3')
    meta = bag / 'metadata.yaml'
    text = meta.read_text().replace('message_count: 500', 'message_count: 0')
    meta.write_text(text)
    with open_imu(bag) as source:
        assert source.read_all().stamp_ns.size == 500 and source.n_lost == 0
    meta.write_text(re.sub(r'relative_file_paths:\n(\s+- .*\n)+',
                           'relative_file_paths:\n  - 17\n  - null\n', text))
    with open_imu(bag) as source:
        assert source.read_all().stamp_ns.size == 500
        assert any('not a file name' in w for w in source.warnings)


def test_undecompressable_message_is_counted(tmp_path):
    import sqlite3

    stamps, samples = _recording(200, seed=28)
    bag = tmp_path / 'bag'
    writer = Ros2Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3)
    writer.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection('/imu', IMU, typestore=ROS2)
        for i in range(200):
            msg = _imu_msg(ROS2, stamps[i], samples[i], 'imu')
            writer.write(conn, int(stamps[i]), bytes(ROS2.serialize_cdr(msg, IMU)))
    db = sqlite3.connect(next(bag.glob('*.db3')))
    db.execute("UPDATE messages SET data = x'28b52ffd0000' WHERE id = 7")
    db.commit()
    db.close()
    with open_imu(bag) as source:
        assert source.read_all().stamp_ns.size == 199
        assert (source.n_read, source.n_lost) == (199, 1)
        assert any('1 messages on /imu are not decodable' in w for w in source.warnings)


# -- one source per analysis: message type, frame_id, split files ----------------------

def _mcap_two_types(path: Path, stamps, samples) -> None:
    """Write an Imu and a MagneticField channel on /imu, interleaved (mcap library)."""
    payloads = serialize_imu(stamps, samples, 'imu')
    with open(path, 'wb') as stream:
        writer = McapWriter(stream)
        writer.start(profile='ros2')
        imu = writer.register_channel('/imu', 'cdr', writer.register_schema(IMU, 'ros2msg',
                                                                            b''))
        mag = writer.register_channel('/imu', 'cdr', writer.register_schema(
            'sensor_msgs/msg/MagneticField', 'ros2msg', b''))
        for i in range(stamps.size):
            # The same bytes under the other type: decodable as Imu, so only the type
            # tells them apart.
            writer.add_message(imu, int(stamps[i]), payloads[i].tobytes(), int(stamps[i]))
            writer.add_message(mag, int(stamps[i]) + 1, payloads[i].tobytes(), int(stamps[i]))
        writer.finish()


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_another_message_type_on_the_imu_topic_is_skipped_and_named(tmp_path, storage):
    stamps, samples = _recording(3000, seed=29)
    path = tmp_path / 'two_types.mcap'
    _mcap_two_types(path, stamps, samples)
    # The oracle: the mcap library's own count of Imu messages on /imu.
    with open(path, 'rb') as stream:
        n_imu = sum(1 for schema, _, _ in make_reader(stream).iter_messages(topics=['/imu'])
                    if schema.name == IMU)
    if storage == 'sqlite3':
        # The same two rows in rosbag2's topics table, by rosbags' writer.
        path = tmp_path / 'bag'
        with Ros2Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
            imu = writer.add_connection('/imu', IMU, typestore=ROS2)
            mag = writer.add_connection('/imu', 'sensor_msgs/msg/MagneticField',
                                        typestore=ROS2)
            payloads = serialize_imu(stamps, samples, 'imu')
            for i in range(stamps.size):
                writer.write(imu, int(stamps[i]), payloads[i].tobytes())
                writer.write(mag, int(stamps[i]) + 1, payloads[i].tobytes())
    with open_imu(path) as source:
        assert source.n_messages == n_imu == 3000
        _assert_topic(source.read_all(), stamps, stamps, samples)
        assert (source.n_read, source.n_lost) == (n_imu, 0)
        assert source.warnings == [f'{path}: 3000 messages of type sensor_msgs/msg/MagneticField '
                                   f'on /imu skipped (only {IMU} is read)']
    assert sorted(list_topics(path)) == [('/imu', IMU, 3000),
                                         ('/imu', 'sensor_msgs/msg/MagneticField', 3000)]


def test_two_imus_on_one_topic_are_two_sources(tmp_path):
    # Two IMUs interleaved on /imu: read together they would be one IMU at twice the rate.
    stamps, samples = _recording(4000, seed=30, rate_hz=100.0)
    _, other = _recording(4000, seed=31, rate_hz=100.0)
    both = np.concatenate([stamps, stamps + 5_000_000])
    order = np.argsort(both, kind='stable')
    frames = np.repeat(['imu_a', 'imu_b'], 4000)[order]
    values = np.concatenate([samples, other])[order]
    payloads = [serialize_imu(both[order][i:i + 1], values[i:i + 1], str(frames[i]))[0]
                for i in range(both.size)]
    path = tmp_path / 'two.mcap'
    with open(path, 'wb') as stream:
        writer = McapWriter(stream, chunk_size=50_000)
        writer.start(profile='ros2')
        channel = writer.register_channel('/imu', 'cdr', writer.register_schema(
            IMU, 'ros2msg', b''))
        for i, stamp in enumerate(both[order].tolist()):
            writer.add_message(channel, stamp, payloads[i].tobytes(), stamp)
        writer.finish()
    with pytest.raises(InputError, match=r'^\S+two.mcap: /imu carries 2 IMUs \(header.frame_id\)'
                                         r': imu_a \(4000 messages\), imu_b \(4000 messages\); '
                                         r'choose one with --frame-id NAME$'):
        with open_imu(path) as source:
            source.read_all()
    for name, expected, shift in (('imu_a', samples, 0), ('imu_b', other, 5_000_000)):
        with open_imu(path, frame_id=name) as source:
            _assert_topic(source.read_all(), stamps + shift, stamps + shift, expected)
            assert (source.frame_id, source.n_read, source.n_lost) == (name, 4000, 0)
            assert source.frame_counts == {'imu_a': 4000, 'imu_b': 4000}
            assert source.warnings[0].startswith('4000 messages of other IMUs on /imu skipped')
    with pytest.raises(InputError, match=r"no message of /imu has frame_id 'imu_c'; it "
                                         r'carries imu_a \(4000 messages\), imu_b'):
        open_imu(path, frame_id='imu_c').read_all()


def _split_bag(tmp_path: Path, stamps, samples, storage: str, listed: list) -> Path:
    """Write a record as three files; metadata.yaml lists ``listed`` (file names)."""
    bag = tmp_path / f'split_{storage}'
    bag.mkdir()
    suffix = 'mcap' if storage == 'mcap' else 'db3'
    for part, (begin, end) in enumerate([(0, 700), (700, 1500), (1500, 2400)]):
        write_imu_bag(bag / f'split_{part}.{suffix}', stamps[begin:end], samples[begin:end])
    (bag / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': {
        'version': 9, 'storage_identifier': storage, 'relative_file_paths': listed}}))
    return bag


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_split_bag_files_are_read_in_time_order_whatever_metadata_lists(tmp_path, storage,
                                                                        monkeypatch):
    from imu_allan.io import bag_reader

    # A merge window shorter than a file, as for files of more than 2**20 messages: the
    # files themselves must come in time order.
    monkeypatch.setattr(bag_reader, '_MAX_HELD', 100)
    stamps, samples = _recording(2400, seed=32)
    suffix = 'mcap' if storage == 'mcap' else 'db3'
    listed = [f'split_{k}.{suffix}' for k in (2, 0, 1)]
    bag = _split_bag(tmp_path, stamps, samples, storage, listed)
    with open_imu(bag) as source:
        _assert_topic(source.read_all(), stamps, stamps + DEFAULT_LATENCY_NS, samples)
        assert source.warnings == [] and source.n_lost == 0
    # A copy of a file (or the same record in the other storage) is read once, and said so.
    shutil.copyfile(bag / listed[1], bag / f'copy.{suffix}')
    write_imu_bag(bag / f'other.{"db3" if storage == "mcap" else "mcap"}', stamps[700:1500],
                  samples[700:1500])
    for extra, first, count in (([f'copy.{suffix}'], listed[1], 700),
                                ([f'other.{"db3" if storage == "mcap" else "mcap"}'],
                                 listed[2], 800)):
        (bag / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': {
            'relative_file_paths': listed + extra + ['gone.mcap']}}))
        with open_imu(bag) as source:
            _assert_topic(source.read_all(), stamps, stamps + DEFAULT_LATENCY_NS, samples)
            assert source.warnings == [   # the file listed first is the one read
                f'{bag}: listed storage file gone.mcap is missing',
                f'{bag}: {extra[0]} repeats {first} (the same {count} messages over the same '
                'time span); read once']
