"""
Fuzz campaign of the input readers against the reference libraries.

Small valid files are written by other libraries (MCAP by the mcap package with zstd,
lz4, no compression and no chunks; sqlite3 by rosbags and by sqlite3 with 512-byte
pages; ROS 1 by rosbags; CSV by numpy), then mutated (truncations, byte flips,
zeroed regions, bad record lengths, damaged indexes and pages; seeded).  Each mutated
file is read by imu_allan and by the reference library (mcap with CRC validation,
sqlite3 SQL row by row, rosbags chunk by chunk, numpy), and the outcome is classed:

* ``same``: the same samples as the reference library;
* ``complete``: every sample of the intact file (the reference lost some);
* ``warned``: only samples of the intact file or of the reference, and a warning
  that states exactly how many of the intact file's messages were lost;
* ``more``: every sample the reference reads and more, all authentic, with a warning
  naming the damage, where the file keeps no count to state the loss against (a
  truncated MCAP file has lost its summary);
* ``error``: a one-line InputError;
* failures: ``silent`` (different samples without that warning) and ``traceback``
  (any other exception, or an error of more than one line).

bench/fuzz_readers.py runs the same campaign with more cases and prints the table
that docs/limits.md shows.
"""

from collections import Counter
import os
from pathlib import Path
import sqlite3
import struct

from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer as McapWriter
import numpy as np
import pytest
from rosbags.rosbag1 import Reader as Ros1Reader, Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin, Writer as Ros2Writer
from rosbags.typesys import get_typestore, Stores

from conftest import T0_NS
from imu_allan.errors import InputError
from imu_allan.io.bag_reader import open_imu
from imu_allan.io.inputs import open_input

IMU = 'sensor_msgs/msg/Imu'
ROS2 = get_typestore(Stores.ROS2_JAZZY)
ROS1 = get_typestore(Stores.ROS1_NOETIC)
N_MESSAGES = 240
KINDS = ('mcap_zstd', 'mcap_lz4', 'mcap_none', 'mcap_unchunked', 'sqlite3_rosbags',
         'sqlite3_512', 'ros1', 'csv')
MUTATIONS = ('truncate', 'flip', 'zero', 'length', 'index')
PASS = ('same', 'complete', 'warned', 'more', 'error')


# -- the intact files -----------------------------------------------------------------

def _recording(seed: int, t0_ns: int = T0_NS):
    """(stamps_ns (n,) int64, samples (n, 6)); CSV time starts at 0 (t in s is exact)."""
    rng = np.random.default_rng(seed)
    stamps = t0_ns + np.arange(N_MESSAGES) * 2_500_000 + rng.integers(0, 200_000, N_MESSAGES)
    samples = rng.normal(size=(N_MESSAGES, 6)) * 0.01 + [0, 0, 0, 0, 0, 9.81]
    return stamps.astype(np.int64), samples


def _msg(store, stamp_ns: int, values):
    types = store.types
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    header = {'stamp': types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec),
              'frame_id': 'imu'}
    if store is ROS1:
        header['seq'] = 0
    vec = types['geometry_msgs/msg/Vector3']
    return types[IMU](
        header=types['std_msgs/msg/Header'](**header),
        orientation=types['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.zeros(9), angular_velocity=vec(*values[:3]),
        angular_velocity_covariance=np.zeros(9), linear_acceleration=vec(*values[3:]),
        linear_acceleration_covariance=np.zeros(9))


def write_intact(kind: str, folder: Path, seed: int = 0) -> Path:
    """Write one valid file of a kind with another library; return the path to mutate."""
    stamps, samples = _recording(seed, 0 if kind == 'csv' else T0_NS)
    if kind.startswith('mcap'):
        path = folder / f'{kind}.mcap'
        options = {'mcap_zstd': {'compression': CompressionType.ZSTD, 'chunk_size': 8000},
                   'mcap_lz4': {'compression': CompressionType.LZ4, 'chunk_size': 8000},
                   'mcap_none': {'compression': CompressionType.NONE, 'chunk_size': 8000},
                   'mcap_unchunked': {'use_chunking': False}}[kind]
        msgdef, _ = ROS2.generate_msgdef(IMU, ros_version=2)
        with open(path, 'wb') as stream:
            writer = McapWriter(stream, **options)
            writer.start(profile='ros2')
            schema = writer.register_schema(IMU, 'ros2msg', msgdef.encode())
            channel = writer.register_channel('/imu', 'cdr', schema)
            for stamp, values in zip(stamps.tolist(), samples):
                raw = bytes(ROS2.serialize_cdr(_msg(ROS2, stamp, values), IMU))
                writer.add_message(channel, stamp + 1000, raw, stamp)
            writer.finish()
        return path
    if kind.startswith('sqlite3'):
        bag = folder / kind
        with Ros2Writer(bag, version=8, storage_plugin=StoragePlugin.SQLITE3) as writer:
            conn = writer.add_connection('/imu', IMU, typestore=ROS2)
            for stamp, values in zip(stamps.tolist(), samples):
                writer.write(conn, stamp + 1000,
                             bytes(ROS2.serialize_cdr(_msg(ROS2, stamp, values), IMU)))
        db3 = next(bag.glob('*.db3'))
        if kind == 'sqlite3_512':
            small = folder / 'small.db3'
            src, dst = sqlite3.connect(db3), sqlite3.connect(small)
            dst.execute('PRAGMA page_size = 512')
            for (sql,) in src.execute('SELECT sql FROM sqlite_master WHERE sql IS NOT NULL'):
                dst.execute(sql)
            for table in ('topics', 'messages'):
                rows = src.execute(f'SELECT * FROM {table}').fetchall()
                dst.executemany(f'INSERT INTO {table} VALUES ({",".join("?" * len(rows[0]))})',
                                rows)
            dst.commit()
            src.close()
            dst.close()
            os.replace(small, db3)
        return db3
    if kind == 'ros1':
        path = folder / 'ros1.bag'
        writer = Ros1Writer(path)
        writer.chunk_threshold = 8000
        with writer:
            conn = writer.add_connection('/imu', 'sensor_msgs/msg/Imu', typestore=ROS1)
            for stamp, values in zip(stamps.tolist(), samples):
                writer.write(conn, stamp + 1000,
                             bytes(ROS1.serialize_ros1(_msg(ROS1, stamp, values), IMU)))
        return path
    path = folder / 'imu.csv'
    table = np.column_stack([stamps / 1e9, samples])
    np.savetxt(path, table, fmt='%.9f,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g',
               header='t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z', comments='')
    return path


# -- mutations ------------------------------------------------------------------------

def _mcap_records(data: bytes) -> list[int]:
    """Offsets of the top-level records of an intact MCAP file."""
    pos, out = 8, []
    while pos + 9 <= len(data) - 8:
        out.append(pos)
        pos += 9 + struct.unpack_from('<Q', data, pos + 1)[0]
    return out


def _ros1_records(data: bytes) -> list[int]:
    """Offsets of the top-level records of an intact ROS 1 bag (format 2.0)."""
    pos, out = 13, []
    while pos + 8 <= len(data):
        out.append(pos)
        header_len = struct.unpack_from('<I', data, pos)[0]
        pos += 4 + header_len
        pos += 4 + struct.unpack_from('<I', data, pos)[0]
    return out


def mutate(kind: str, data: bytes, rng: np.random.Generator, mutation: str) -> bytes:
    """Return a damaged copy of an intact file."""
    buf = bytearray(data)
    n = len(buf)
    if mutation == 'truncate':
        return bytes(buf[:int(rng.integers(1, n))])
    if mutation == 'flip':
        for at in rng.integers(0, n, int(rng.integers(1, 5))).tolist():
            buf[at] ^= 1 << int(rng.integers(0, 8))
        return bytes(buf)
    if mutation == 'zero':
        size = int(rng.integers(16, 513))
        at = int(rng.integers(0, max(n - size, 1)))
        buf[at:at + size] = bytes(len(buf[at:at + size]))
        return bytes(buf)
    if mutation == 'length':
        if kind.startswith('mcap'):
            at = int(rng.choice(_mcap_records(data))) + 1
            old = struct.unpack_from('<Q', buf, at)[0]
            new = int(rng.choice([2**64 - 1, 0, old + int(rng.integers(-40, 41)),
                                  int(rng.integers(0, 2**32))]))
            struct.pack_into('<Q', buf, at, max(new, 0) % 2**64)
        elif kind == 'ros1':
            at = int(rng.choice(_ros1_records(data)))
            struct.pack_into('<I', buf, at, int(rng.integers(0, 2**32)))
        elif kind == 'csv':
            lines = data.split(b'\n')
            k = int(rng.integers(1, len(lines)))
            lines[k] = lines[k] + b',0'
            return b'\n'.join(lines)
        else:
            at = int(rng.integers(0, n - 2))
            struct.pack_into('>H', buf, at, int(rng.integers(0, 2**16)))
        return bytes(buf)
    # 'index': damage the parts that say where things are.
    if kind.startswith('sqlite3'):
        page = struct.unpack_from('>H', data, 16)[0]
        k = int(rng.integers(1, n // page))
        region = bytes(page) if rng.random() < 0.5 else rng.bytes(page)
        buf[k * page:(k + 1) * page] = region
    elif kind.startswith('mcap'):
        summary = struct.unpack_from('<Q', data, n - 37 + 9)[0] or n - 37
        indexes = [p for p in _mcap_records(data) if data[p] == 0x07]
        starts = [summary] + indexes
        at = int(rng.choice(starts)) + int(rng.integers(9, 40))
        for k in range(int(rng.integers(1, 4))):
            if at + k < n:
                buf[at + k] ^= 0xFF
    elif kind == 'ros1':
        at = int(rng.integers(int(n * 0.8), n))
        buf[at] ^= 1 << int(rng.integers(0, 8))
    else:
        lines = data.split(b'\n')
        k = int(rng.integers(1, len(lines)))
        del lines[k]
        return b'\n'.join(lines)
    return bytes(buf)


# -- readers --------------------------------------------------------------------------

def _rows(stamps, samples) -> Counter:
    """Messages as a multiset of exact bit patterns (stamp, six values)."""
    stamps = np.asarray(stamps, np.int64).reshape(-1, 1)
    samples = np.asarray(samples, np.float64).reshape(-1, 6)
    table = np.hstack([stamps.view(np.uint64), samples.view(np.uint64)])
    return Counter(row.tobytes() for row in table)


def _decoded(msg) -> tuple:
    av, la = msg.angular_velocity, msg.linear_acceleration
    return (msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
            [av.x, av.y, av.z, la.x, la.y, la.z])


def reference(kind: str, path: Path) -> Counter | None:
    """Read a file with the reference library; what it gives before any error."""
    got: list = []
    try:
        if kind.startswith('mcap'):
            got = _mcap_reference(path)
        elif kind.startswith('sqlite3'):
            db3 = next(path.glob('*.db3')) if path.is_dir() else path
            conn = sqlite3.connect(f'file:{db3}?immutable=1', uri=True)
            try:
                for rowid in range(1, N_MESSAGES + 1):
                    try:
                        row = conn.execute('SELECT topic_id, data FROM messages WHERE id = ?',
                                           (rowid,)).fetchone()
                        if row is not None and row[0] == 1:
                            got.append(_decoded(ROS2.deserialize_cdr(row[1], IMU)))
                    except Exception:   # noqa: B902 - a damaged row or page: not read
                        pass
            finally:
                conn.close()
        elif kind == 'ros1':
            got = _ros1_reference(path)
        else:
            table = np.loadtxt(path, delimiter=',', skiprows=1, ndmin=2)
            if table.shape[1] != 7 or not np.isfinite(table).all():
                return None
            got = [(int(round(t * 1e9)), v) for t, *v in table.tolist()]
    except Exception:   # noqa: B902 - the reference gives up here
        if not got:
            return None
    got = [g for g in got if g is not None]
    return _rows([g[0] for g in got], [g[1] for g in got]) if got else Counter()


def _ros1_reference(path: Path) -> list:
    """
    Read with rosbags chunk by chunk: what it reads in each chunk's time window.

    rosbags' reader stops at the first damaged chunk; the windows (from one chunk's
    start time to the next's, the first and last open) let it read every chunk up to
    that chunk's damage.
    """
    got: list = []
    with Ros1Reader(path) as reader:
        starts = sorted({info.start_time for info in reader.chunk_infos})
        for start, stop in zip([None] + starts[1:], starts[1:] + [None]):
            try:
                for conn, _, raw in reader.messages(start=start, stop=stop):
                    if conn.topic == '/imu':
                        try:
                            got.append(_decoded(ROS1.deserialize_ros1(raw, IMU)))
                        except Exception:   # noqa: B902 - not an Imu payload: not read
                            pass
            except Exception:   # noqa: B902 - this chunk ends here
                pass
    return got


def _mcap_reference(path: Path) -> list:
    """Read with the mcap library: indexed, or record by record when that fails at once."""
    got: list = []
    try:
        with open(path, 'rb') as stream:
            reader = make_reader(stream, validate_crcs=True)
            for _, channel, message in reader.iter_messages():
                if channel.topic == '/imu':
                    got.append(_imu_or_none(message.data))
        return got
    except Exception:   # noqa: B902 - the indexed reader gives up: read the records
        if got:
            return got
    channels: dict = {}
    try:
        with open(path, 'rb') as stream:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Channel):
                    channels[record.id] = record.topic
                elif isinstance(record, Message) and channels.get(record.channel_id) == '/imu':
                    got.append(_imu_or_none(record.data))
    except Exception:   # noqa: B902 - what came before the error is the reference
        pass
    return got


def _imu_or_none(raw: bytes):
    try:
        return _decoded(ROS2.deserialize_cdr(raw, IMU))
    except Exception:   # noqa: B902 - not an Imu payload: not read
        return None


def ours(kind: str, path: Path) -> tuple:
    """Read with imu_allan: (rows, warnings, n_lost), or ('error', text) / ('traceback', ...)."""
    try:
        if kind == 'csv':
            with open_input(path) as source:
                blocks = list(source.blocks())
                stamps = np.concatenate([b[0] for b in blocks])
                samples = np.concatenate([b[1] for b in blocks])
                return _rows(stamps, samples), list(source.warnings), 0
        with open_imu(path) as source:
            block = source.read_all()
            return _rows(block.stamp_ns, block.samples), list(source.warnings), source.n_lost
    except InputError as err:
        return ('error', str(err))
    except Exception as err:   # noqa: B902 - any other exception is a failure of the reader
        return ('traceback', f'{type(err).__name__}: {err}')


def classify(kind: str, intact: Counter, path: Path) -> tuple[str, str]:
    """Class of one mutated file's outcome, with a note for failures."""
    got = ours(kind, path)
    if got[0] == 'error':
        return ('error', '') if '\n' not in got[1] else ('traceback', got[1])
    if got[0] == 'traceback':
        return 'traceback', got[1]
    rows, warnings, n_lost = got
    oracle = reference(kind, path)
    if oracle is not None and rows == oracle:
        return 'same', ''
    if rows == intact:
        return 'complete', ''
    authentic = intact if oracle is None else intact | oracle
    lost = sum(intact.values()) - sum(rows.values())
    if (not rows - authentic and n_lost == lost
            and any(f'{lost} of {sum(intact.values())} messages' in w for w in warnings)):
        return 'warned', ''
    if (oracle is not None and not oracle - rows and not rows - authentic and warnings
            and n_lost in (None, lost)):
        return 'more', ''
    return 'silent', (f'read {sum(rows.values())}, reference '
                      f'{None if oracle is None else sum(oracle.values())}, intact '
                      f'{sum(intact.values())}, n_lost {n_lost}, warnings {warnings}')


def campaign(kinds, cases_per_kind: int, seed: int, folder: Path) -> dict:
    """Run the campaign; return {kind: Counter of classes} and the failures' notes."""
    table: dict = {}
    notes: list = []
    for kind in kinds:
        base = write_intact(kind, folder / f'intact_{kind}')
        data = base.read_bytes()
        intact = _rows(*_recording(0, 0 if kind == 'csv' else T0_NS))
        rng = np.random.default_rng([seed, KINDS.index(kind)])
        counts: Counter = Counter()
        for case in range(cases_per_kind):
            mutation = MUTATIONS[case % len(MUTATIONS)]
            base.write_bytes(mutate(kind, data, rng, mutation))
            outcome, note = classify(kind, intact, base.parent if kind.startswith('sqlite3')
                                     else base)
            counts[outcome] += 1
            if outcome not in PASS:
                notes.append((kind, mutation, case, outcome, note))
        base.write_bytes(data)
        table[kind] = counts
    return {'table': table, 'failures': notes}


def _folders(tmp: Path, kinds) -> None:
    for kind in kinds:
        (tmp / f'intact_{kind}').mkdir(parents=True, exist_ok=True)


#: Cases per kind in the test: 240 MCAP, 150 sqlite3, 120 ROS 1, 150 CSV.
CASES = {'mcap_zstd': 60, 'mcap_lz4': 60, 'mcap_none': 60, 'mcap_unchunked': 60,
         'sqlite3_rosbags': 75, 'sqlite3_512': 75, 'ros1': 120, 'csv': 150}


@pytest.mark.parametrize('kind', KINDS)
def test_every_mutated_file_is_read_as_the_reference_or_warned_or_refused(kind, tmp_path):
    _folders(tmp_path, [kind])
    result = campaign([kind], CASES[kind], seed=2026, folder=tmp_path)
    assert result['failures'] == []
    assert sum(result['table'][kind].values()) == CASES[kind]


def test_the_intact_files_read_as_the_reference_reads_them(tmp_path):
    _folders(tmp_path, KINDS)
    for kind in KINDS:
        base = write_intact(kind, tmp_path / f'intact_{kind}')
        where = base.parent if kind.startswith('sqlite3') else base
        intact = _rows(*_recording(0, 0 if kind == 'csv' else T0_NS))
        assert reference(kind, where) == intact, kind
        got = ours(kind, where)
        assert got[0] == intact and got[1] == [] and got[2] == 0, kind
