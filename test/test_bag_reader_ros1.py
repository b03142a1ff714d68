"""
Damaged ROS 1 bags: a damaged chunk costs its own messages only.

The bags are written in tmp_path by rosbags' rosbag1 Writer with small chunks, then one
or two chunks' data bytes are damaged in place (their byte ranges and messages come
from rosbags' own Reader); what is read is compared with what was written.
"""

import json
from pathlib import Path

import numpy as np
from numpy.testing import assert_array_equal
import pytest
from rosbags.rosbag1 import Reader as Ros1Reader, Writer as Ros1Writer
from rosbags.typesys import get_typestore, Stores

from conftest import T0_NS
from imu_allan.cli import main
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.io.bag_reader import open_imu
from imu_allan.io.bag_writer import serialize_imu
from imu_allan.io.bags import ros1

REPO = Path(__file__).resolve().parents[1]
IMU = 'sensor_msgs/msg/Imu'
ROS1 = get_typestore(Stores.ROS1_NOETIC)
LATENCY_NS = 1000
COMPRESSION = {'none': None, 'bz2': Ros1Writer.CompressionFormat.BZ2,
               'lz4': Ros1Writer.CompressionFormat.LZ4}


def _write(path: Path, stamps, samples, compression: str, chunk_bytes: int) -> Path:
    """Write /imu (and a /chatter message per 50) with chunks of about chunk_bytes."""
    payloads = serialize_imu(stamps, samples, ros1=True)
    writer = Ros1Writer(path)
    writer.chunk_threshold = chunk_bytes
    if COMPRESSION[compression] is not None:
        writer.set_compression(COMPRESSION[compression])
    with writer:
        conn = writer.add_connection('/imu', IMU, typestore=ROS1)
        other = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=ROS1)
        hello = bytes(ROS1.serialize_ros1(ROS1.types['std_msgs/msg/String'](data='hi'),
                                          'std_msgs/msg/String'))
        for i in range(stamps.size):
            writer.write(conn, int(stamps[i]) + LATENCY_NS, payloads[i].tobytes())
            if i % 50 == 0:
                writer.write(other, int(stamps[i]) + LATENCY_NS, hello)
    return path


def _damage(path: Path, which: list[int], compression: str) -> np.ndarray:
    """
    Damage the data of the chunks numbered ``which`` (in file order) in place.

    Returns the receive times [ns] of the /imu messages the damaged chunks hold, from
    rosbags' index.
    """
    with Ros1Reader(path) as reader:
        positions = sorted(reader.chunks)
        spans = [(reader.chunks[p].datapos, reader.chunks[p].datasize) for p in positions]
        conn = next(c for c in reader.connections if c.topic == '/imu')
        damaged = {positions[k] for k in which}
        lost = np.array([e.time for e in reader.indexes[conn.id] if e.chunk_pos in damaged],
                        np.int64)
    data = bytearray(path.read_bytes())
    for k in which:
        start, size = spans[k]
        if compression == 'bz2':
            # A few flipped bytes in the middle: bz2's block CRC catches them.
            for at in range(start + size // 2, start + size // 2 + 4):
                data[at] ^= 0x5A
        else:
            # No checksum covers these: zeroed, no record can be parsed.
            data[start:start + size] = bytes(size)
    path.write_bytes(bytes(data))
    return lost


@pytest.mark.parametrize('compression', ['none', 'bz2', 'lz4'])
@pytest.mark.parametrize('where', ['first', 'middle', 'last', 'first and middle'])
def test_a_damaged_chunk_costs_its_own_messages_only(tmp_path, monkeypatch, compression, where):
    rng = np.random.default_rng(11)
    n = 400
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 2_500_000 + rng.integers(0, 1000, n)
    samples = rng.normal(size=(n, 6))
    bag = _write(tmp_path / 'd.bag', stamps, samples, compression, chunk_bytes=4000)
    with Ros1Reader(bag) as reader:
        n_chunks = len(reader.chunks)
    assert n_chunks >= 10
    which = {'first': [0], 'middle': [n_chunks // 2], 'last': [n_chunks - 1],
             'first and middle': [0, n_chunks // 2]}[where]
    lost_recv = _damage(bag, which, compression)
    keep = ~np.isin(stamps + LATENCY_NS, lost_recv)
    assert 0 < lost_recv.size == n - np.count_nonzero(keep)
    # Batches smaller than a chunk: the batching goes on across the damage.
    monkeypatch.setattr(ros1, '_FETCH_ROWS', 7)

    with open_imu(bag) as source:
        block = source.read_all()
        assert_array_equal(block.stamp_ns, stamps[keep])
        assert_array_equal(block.recv_ns, stamps[keep] + LATENCY_NS)
        assert_array_equal(block.samples, samples[keep])   # exact: float64 round trip
        assert source.n_read == n - lost_recv.size
        assert source.n_lost == lost_recv.size
        damage = [w for w in source.warnings if 'damaged chunk' in w]
        assert len(damage) == 1 and '\n' not in damage[0], source.warnings
        assert damage[0].startswith(f'{bag}: {len(which)} damaged chunk(s)')
        assert f'; {lost_recv.size} messages of /imu' in damage[0]
        assert f'{lost_recv.size} of {n} messages on /imu lost' in ' '.join(source.warnings)


def test_an_intact_bag_reads_whole_without_warnings(tmp_path):
    rng = np.random.default_rng(12)
    stamps = T0_NS + np.arange(300, dtype=np.int64) * 5_000_000
    samples = rng.normal(size=(300, 6))
    bag = _write(tmp_path / 'ok.bag', stamps, samples, 'bz2', chunk_bytes=3000)
    with open_imu(bag) as source:
        block = source.read_all()
        assert_array_equal(block.stamp_ns, stamps)
        assert_array_equal(block.samples, samples)
        assert source.n_lost == 0 and source.warnings == []


def test_cli_analyses_the_rest_of_a_bag_with_a_damaged_chunk(tmp_path, capsys):
    rate_hz, n = 100.0, 9000
    spec = load_params(REPO / 'config' / 'xsens_mti7.yaml')
    _, samples = simulate_imu(spec, rate_hz, n / rate_hz, seed=5)
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    bag = _write(tmp_path / 'rec.bag', stamps, samples, 'bz2', chunk_bytes=100_000)
    with Ros1Reader(bag) as reader:
        n_chunks = len(reader.chunks)
    lost_recv = _damage(bag, [n_chunks // 2], 'bz2')
    code = main(['analyze', str(bag), '--out', str(tmp_path / 'o'), '--format', 'json',
                 '--no-plot'])
    out, err = capsys.readouterr()
    assert code == 0, err
    doc = json.loads(out)
    assert doc['n_samples'] == n - lost_recv.size
    assert any(line.startswith('imu-allan: warning: ') and 'damaged chunk' in line
               for line in err.splitlines()), err
    assert any('damaged chunk' in w for w in doc['warnings'])


def test_a_record_of_another_connection_costs_the_rest_of_its_chunk(tmp_path):
    rng = np.random.default_rng(13)
    n = 300
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 2_500_000
    samples = rng.normal(size=(n, 6))
    bag = _write(tmp_path / 'c.bag', stamps, samples, 'none', chunk_bytes=4000)
    with Ros1Reader(bag) as reader:
        middle = sorted(reader.chunks)[len(reader.chunks) // 2]
        datapos = reader.chunks[middle].datapos
        conn = next(c for c in reader.connections if c.topic == '/imu')
        entries = [e for e in reader.indexes[conn.id] if e.chunk_pos == middle]
    # The 5th message of the chunk names connection 99 (no such connection): rosbags'
    # reader raises KeyError there; the chunk's earlier messages are read, later not.
    bad = entries[4]
    data = bytearray(bag.read_bytes())
    at = data.index(b'conn=', datapos + bad.offset) + len(b'conn=')
    data[at:at + 4] = (99).to_bytes(4, 'little')
    bag.write_bytes(bytes(data))
    lost = np.array([e.time for e in entries[4:]], np.int64)
    keep = ~np.isin(stamps + LATENCY_NS, lost)
    with open_imu(bag) as source:
        block = source.read_all()
        assert_array_equal(block.stamp_ns, stamps[keep])
        assert_array_equal(block.samples, samples[keep])
        assert source.n_lost == lost.size > 0
        assert any(w.startswith(f'{bag}: 1 damaged chunk(s)') and
                   f'; {lost.size} messages of /imu' in w for w in source.warnings)
