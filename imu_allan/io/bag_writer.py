"""
Write sensor_msgs/msg/Imu recordings as bags, fast, from arrays.

Storage follows the path: a ``.mcap`` file, a ``.db3`` file (rosbag2 sqlite3
schema without metadata.yaml), a ROS 1 ``.bag`` file, or a rosbag2 directory
(metadata.yaml plus one MCAP file, or sqlite3 with ``storage='sqlite3'``).

All messages are serialised at once with numpy structured arrays into one byte
buffer (the same CDR layout the reader decodes); only the storage layer loops.
MCAP chunks, message indexes and the summary are written directly (mcap_writer.py; the
``mcap`` package's record classes encode the small records), because the
per-message writer API pays a Python call per message.

Headers are realistic: ``header.stamp`` = ``stamps_ns``, ``frame_id`` as given,
orientation unknown (identity quaternion with ``orientation_covariance[0] = -1``,
ROS REP 145), covariances from ``covariances`` or zero.  The bag's receive time
of each message is its stamp plus a small constant transport latency.
"""

import os
from pathlib import Path
import shutil
import sqlite3
import time
from typing import Sequence

import numpy as np
from rosbags.typesys import get_typestore, Stores
import yaml

from imu_allan import __version__, AXES
from imu_allan.errors import InputError
from imu_allan.io.imu_cdr import imu_msgdef, IMU_MSGTYPE

#: Receive time minus header.stamp of every written message [ns] (transport latency).
DEFAULT_LATENCY_NS = 500_000
#: Target uncompressed MCAP chunk size [bytes].
MCAP_CHUNK_BYTES = 1 << 20
#: rosbag2 metadata version written (ROS 2 Jazzy).
ROSBAG2_VERSION = 9
ROS_DISTRO = 'jazzy'

_CDR_LE_HEADER = np.array([0, 1, 0, 0], np.uint8)
_STORAGES = ('mcap', 'sqlite3', 'ros1')
_SQLITE_SCHEMA = """
CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL,
                      metadata TEXT NOT NULL);
CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
                    serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL,
                    type_description_hash TEXT NOT NULL);
CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL,
                                 encoding TEXT NOT NULL,
                                 encoded_message_definition TEXT NOT NULL,
                                 type_description_hash TEXT NOT NULL);
CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
                      timestamp INTEGER NOT NULL, data BLOB NOT NULL);
"""

PathLike = str | os.PathLike


def _align8(offset: int) -> int:
    return (offset + 7) // 8 * 8


def _imu_dtype(frame_len: int, doubles_offset: int, ros1: bool) -> np.dtype:
    """
    Return the structured dtype of one serialised sensor_msgs/Imu message.

    Parameters
    ----------
    frame_len : int
        Bytes of frame_id as stored (ROS 2 CDR: with the trailing NUL; ROS 1: without).
    doubles_offset : int
        Byte offset of ``orientation.x``, the first of the 37 doubles.
    ros1 : bool
        ROS 1 layout (seq, uint32 secs) instead of ROS 2 CDR (4-byte encapsulation header).

    Returns
    -------
    numpy.dtype
        Little-endian record whose itemsize is the serialised message length.

    """
    names = ['seq' if ros1 else 'encapsulation', 'sec', 'nanosec', 'frame_len', 'frame_id',
             'orientation', 'orientation_covariance', 'angular_velocity',
             'angular_velocity_covariance', 'linear_acceleration',
             'linear_acceleration_covariance']
    formats = ['<u4' if ros1 else ('u1', (4,)), '<u4' if ros1 else '<i4', '<u4', '<u4',
               ('u1', (max(frame_len, 1),)), ('<f8', (4,)), ('<f8', (9,)), ('<f8', (3,)),
               ('<f8', (9,)), ('<f8', (3,)), ('<f8', (9,))]
    o = doubles_offset
    offsets = [0, 4, 8, 12, 16, o, o + 32, o + 104, o + 128, o + 200, o + 224]
    if frame_len == 0:
        # Nothing is stored for an empty ROS 1 frame_id: drop the field.
        del names[4], formats[4], offsets[4]
    return np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                     'itemsize': o + 296})


def _covariance_rows(covariances) -> tuple:
    """Return (angular_velocity, linear_acceleration) covariances as (9,) arrays."""
    if covariances is None:
        return np.zeros(9), np.zeros(9)
    if len(covariances) != 2:
        raise InputError('covariances must be a pair (angular_velocity, linear_acceleration)')
    rows = []
    for name, cov in zip(('angular_velocity', 'linear_acceleration'), covariances):
        cov = np.asarray(cov, dtype=np.float64)
        if cov.shape == (3,):
            cov = np.diag(cov)
        if cov.size != 9:
            raise InputError(f'{name} covariance must have 3 (diagonal) or 9 values, '
                             f'got shape {cov.shape}')
        rows.append(cov.reshape(9))
    return tuple(rows)


def _check_arrays(stamps_ns, samples) -> tuple:
    stamps_ns = np.asarray(stamps_ns)
    samples = np.asarray(samples, dtype=np.float64)
    if stamps_ns.ndim != 1 or samples.shape != (stamps_ns.size, 6):
        raise InputError(f'need stamps_ns (n,) and samples (n, 6); got {stamps_ns.shape} '
                         f'and {samples.shape}')
    if stamps_ns.size and not np.issubdtype(stamps_ns.dtype, np.integer):
        raise InputError('stamps_ns must be integer nanoseconds')
    return stamps_ns.astype(np.int64), samples


class _ImuSerializer:
    """
    Serialise batches of sensor_msgs/Imu messages with one constant frame_id.

    A template message holds every constant byte (encapsulation, frame_id, orientation,
    covariances, padding); a batch is the template broadcast to n rows plus four
    vectorised field writes.
    """

    def __init__(self, frame_id: str, covariances, ros1: bool) -> None:
        frame = frame_id.encode()
        if ros1:
            frame_len = len(frame)
            doubles_offset = 16 + frame_len
        else:
            frame += b'\0'
            frame_len = len(frame)
            # CDR aligns the doubles to 8 bytes counted after the encapsulation header.
            doubles_offset = 4 + _align8(12 + frame_len)
        self.ros1 = ros1
        self.dtype = _imu_dtype(frame_len, doubles_offset, ros1)
        self.size = self.dtype.itemsize
        template = np.zeros(1, self.dtype)
        if not ros1:
            template['encapsulation'] = _CDR_LE_HEADER
        template['frame_len'] = frame_len
        if frame_len:
            template['frame_id'] = np.frombuffer(frame, np.uint8)
        template['orientation'] = np.array([0.0, 0.0, 0.0, 1.0])
        template['orientation_covariance'][:, 0] = -1.0   # REP 145: no orientation estimate
        gyro_cov, accel_cov = _covariance_rows(covariances)
        template['angular_velocity_covariance'] = gyro_cov
        template['linear_acceleration_covariance'] = accel_cov
        self.template = template.view(np.uint8)

    def check_stamps(self, stamps_ns: np.ndarray) -> None:
        """Raise InputError unless every (n,) int64 stamp [ns] fits the header's seconds."""
        if not stamps_ns.size:
            return
        limits = (0, 2**32 - 1) if self.ros1 else (-2**31, 2**31 - 1)
        sec_min, sec_max = np.floor_divide([stamps_ns.min(), stamps_ns.max()], 1_000_000_000)
        if sec_min < limits[0] or sec_max > limits[1]:
            raise InputError('time stamps do not fit the message header ('
                             + ('unsigned ' if self.ros1 else 'signed ') + '32-bit seconds)')

    def __call__(self, stamps_ns: np.ndarray, samples: np.ndarray,
                 first_seq: int = 0) -> np.ndarray:
        """Return (n, size) uint8 messages for (n,) int64 stamps and (n, 6) samples."""
        n = stamps_ns.size
        sec, nanosec = np.divmod(stamps_ns, 1_000_000_000)
        raw = np.empty((n, self.size), np.uint8)
        raw[:] = self.template
        msgs = raw.view(self.dtype).reshape(n)
        if self.ros1:
            msgs['seq'] = (np.arange(n, dtype=np.uint64) + first_seq) % 2**32
        msgs['sec'] = sec
        msgs['nanosec'] = nanosec
        msgs['angular_velocity'] = samples[:, :3]
        msgs['linear_acceleration'] = samples[:, 3:]
        return raw


def serialize_imu(stamps_ns: np.ndarray, samples: np.ndarray, frame_id: str = 'imu_link',
                  covariances=None, ros1: bool = False) -> np.ndarray:
    """
    Serialise many sensor_msgs/Imu messages at once.

    Parameters
    ----------
    stamps_ns : numpy.ndarray
        (n,) int64 header.stamp [ns since the epoch].
    samples : numpy.ndarray
        (n, 6) float64 angular_velocity x, y, z [rad/s], linear_acceleration x, y, z [m/s^2].
    frame_id : str
        header.frame_id of every message.
    covariances : pair of array_like, optional
        (angular_velocity, linear_acceleration) covariance, each 3 variances (diagonal) or
        a 3x3 / 9-value row-major matrix, in (rad/s)^2 and (m/s^2)^2; zero when omitted.
    ros1 : bool
        ROS 1 serialisation (packed little-endian, header.seq) instead of ROS 2 CDR
        (little-endian encapsulation).

    Returns
    -------
    numpy.ndarray
        (n, L) uint8, one serialised message per row (L bytes each).

    """
    stamps_ns, samples = _check_arrays(stamps_ns, samples)
    serializer = _ImuSerializer(frame_id, covariances, ros1)
    serializer.check_stamps(stamps_ns)
    return serializer(stamps_ns, samples)


def _resolve_storage(path: Path, storage: str | None) -> tuple:
    """Return (storage, is_directory) for an output path."""
    suffix = path.suffix.lower()
    by_suffix = {'.mcap': 'mcap', '.db3': 'sqlite3', '.bag': 'ros1'}.get(suffix)
    if storage is not None and storage not in _STORAGES:
        raise InputError(f'unknown storage {storage!r}; use one of {", ".join(_STORAGES)}')
    if by_suffix is not None:
        if storage is not None and storage != by_suffix:
            raise InputError(f'{path.name} names {by_suffix} storage but storage={storage!r}')
        return by_suffix, False
    storage = storage or 'mcap'
    if storage == 'ros1':
        raise InputError('a ROS 1 bag is a single file: give a path ending in .bag')
    return storage, True


def _bag_info(storage: str, file_name: str, topic: str, rihs01: str,
              recv_ns: np.ndarray) -> dict:
    """Return the rosbag2_bagfile_information mapping (metadata.yaml, version 9)."""
    n = int(recv_ns.size)
    start = int(recv_ns.min()) if n else 0
    duration = int(recv_ns.max()) - start if n else 0
    return {
        'version': ROSBAG2_VERSION,
        'storage_identifier': storage,
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': n,
        'topics_with_message_count': [{
            'topic_metadata': {'name': topic, 'type': IMU_MSGTYPE,
                               'serialization_format': 'cdr', 'offered_qos_profiles': [],
                               'type_description_hash': rihs01},
            'message_count': n}],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [file_name],
        'files': [{'path': file_name, 'starting_time': {'nanoseconds_since_epoch': start},
                   'duration': {'nanoseconds': duration}, 'message_count': n}],
        'custom_data': {'writer': f'imu_allan {__version__}'},
        'ros_distro': ROS_DISTRO,
    }


def _write_sqlite(db_path: Path, topic: str, batches, info: dict) -> None:
    """
    Write a rosbag2 sqlite3 database (schema version 4, as ROS 2 Jazzy writes it).

    Parameters
    ----------
    db_path : pathlib.Path
        New .db3 file.
    topic : str
        Topic name.
    batches : iterable of (numpy.ndarray, numpy.ndarray)
        ((k, L) uint8 serialised messages, (k,) int64 receive time [ns]) pairs.
    info : dict
        rosbag2_bagfile_information, stored in the metadata table.

    """
    msgdef, rihs01 = imu_msgdef()
    conn = sqlite3.connect(db_path)
    try:
        # A fresh file that nobody else reads yet: no journal, no fsync per page.
        conn.execute('PRAGMA journal_mode=OFF')
        conn.execute('PRAGMA synchronous=OFF')
        conn.executescript(_SQLITE_SCHEMA)
        conn.execute('INSERT INTO schema VALUES (4, ?)', (ROS_DISTRO,))
        conn.execute('INSERT INTO topics VALUES (1, ?, ?, ?, ?, ?)',
                     (topic, IMU_MSGTYPE, 'cdr', '', rihs01))
        conn.execute('INSERT INTO message_definitions VALUES (1, ?, ?, ?, ?)',
                     (IMU_MSGTYPE, 'ros2msg', msgdef, rihs01))
        for payloads, recv_ns in batches:
            size = payloads.shape[1]
            # One statement per batch: sqlite splits the concatenated blob itself
            # (json_each walks the receive times), faster than executemany.
            conn.execute(
                'INSERT INTO messages (topic_id, timestamp, data) '
                f'SELECT 1, j.value, substr(?, j.key * {size} + 1, {size}) '
                'FROM json_each(?) AS j ORDER BY j.key',
                (payloads.data, '[' + ','.join(map(str, recv_ns.tolist())) + ']'))
        # Building the index once after the bulk insert is faster than maintaining it.
        conn.execute('CREATE INDEX timestamp_idx ON messages (timestamp ASC)')
        conn.execute('INSERT INTO metadata (metadata_version, metadata) VALUES (?, ?)',
                     (ROSBAG2_VERSION, yaml.safe_dump(info, sort_keys=False)))
        conn.commit()
    finally:
        conn.close()


def _write_ros1(bag_path: Path, topic: str, batches) -> None:
    """Write a ROS 1 bag (v2.0) through rosbags' writer, with pre-serialised messages."""
    from rosbags.rosbag1 import Writer

    store = get_typestore(Stores.ROS1_NOETIC)
    with Writer(bag_path) as writer:
        conn = writer.add_connection(topic, IMU_MSGTYPE, typestore=store)
        for payloads, recv_ns in batches:
            for stamp, data in zip(recv_ns.tolist(), payloads):
                writer.write(conn, stamp, data.data)


def write_imu_bag(path: PathLike, stamps_ns: np.ndarray, samples: np.ndarray,
                  topic: str = '/imu/data', frame_id: str = 'imu_link',
                  storage: str | None = None, covariances: Sequence | None = None,
                  latency_ns: int = DEFAULT_LATENCY_NS) -> None:
    """
    Write an Imu recording as a bag; storage follows the path.

    Parameters
    ----------
    path : str or os.PathLike
        ``*.mcap``: one MCAP file; ``*.db3``: one rosbag2 sqlite3 file; ``*.bag``: a ROS 1
        bag; anything else: a rosbag2 directory (metadata.yaml plus ``<name>_0.mcap``,
        or ``<name>_0.db3`` with ``storage='sqlite3'``).  Must not exist yet.
    stamps_ns : numpy.ndarray
        (n,) int64 header.stamp of each message [ns since the epoch].
    samples : numpy.ndarray
        (n, 6) float64 in AXES order: angular_velocity [rad/s], linear_acceleration [m/s^2].
    topic : str
        Topic name.
    frame_id : str
        header.frame_id.
    storage : {'mcap', 'sqlite3', 'ros1'}, optional
        Storage for a directory path (default 'mcap'); must agree with a file suffix.
    covariances : pair of array_like, optional
        (angular_velocity, linear_acceleration) covariance: 3 variances or 9 values
        (row-major 3x3), in (rad/s)^2 and (m/s^2)^2, the same in every message.
    latency_ns : int
        Receive time minus header.stamp [ns]: the bag's own time stamp of each message.

    Raises
    ------
    InputError
        If the path exists, storage and suffix disagree, the arrays do not fit, or the
        bag cannot be written (a full disk, a read-only place).

    """
    path = Path(path)
    if path.exists():
        raise InputError(f'{path} exists already; not overwriting')
    storage, is_dir = _resolve_storage(path, storage)
    stamps_ns, samples = _check_arrays(stamps_ns, samples)
    serializer = _ImuSerializer(frame_id, covariances, ros1=storage == 'ros1')
    serializer.check_stamps(stamps_ns)
    recv_ns = stamps_ns + int(latency_ns)
    # Batches bound the memory (a 3 h, 400 Hz bag is 1.4 GB serialised); for MCAP one
    # batch is one chunk of about MCAP_CHUNK_BYTES.
    batch = max(1, MCAP_CHUNK_BYTES // (31 + serializer.size)) if storage == 'mcap' else 65536

    def batches():
        for begin in range(0, stamps_ns.size, batch):
            stop = min(begin + batch, stamps_ns.size)
            yield (serializer(stamps_ns[begin:stop], samples[begin:stop], first_seq=begin),
                   recv_ns[begin:stop])

    created = path
    try:
        if storage == 'ros1':
            path.parent.mkdir(parents=True, exist_ok=True)
            _write_ros1(path, topic, batches())
            return
        _, rihs01 = imu_msgdef()
        if is_dir:
            path.mkdir(parents=True)
            file_path = path / f'{path.name}_0.{"mcap" if storage == "mcap" else "db3"}'
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            file_path = path
        info = _bag_info(storage, file_path.name, topic, rihs01, recv_ns)
        if storage == 'mcap':
            from imu_allan.io.mcap_writer import _write_mcap  # the mcap library, when needed
            _write_mcap(file_path, topic, batches(), info)
        else:
            _write_sqlite(file_path, topic, batches(), info)
        if is_dir:
            text = yaml.safe_dump({'rosbag2_bagfile_information': info}, sort_keys=False)
            (path / 'metadata.yaml').write_text(text)
    except BaseException as err:
        # Leave no half-written bag behind (only what this call created).
        if created.is_dir():
            shutil.rmtree(created, ignore_errors=True)
        elif created.exists():
            created.unlink()
        if isinstance(err, (OSError, sqlite3.Error)):
            # A full disk, a read-only place, a size limit: sqlite says so in its own
            # words ('database or disk is full'), the file system in strerror.
            reason = (getattr(err, 'strerror', None)
                      or (str(err).strip() or type(err).__name__).splitlines()[0])
            raise InputError(f'{path}: cannot write ({reason})') from None
        raise


#: A CSV time from which on ``csv_to_bag`` reads it as seconds since the epoch [s]
#: (2001-09-09); earlier first times are relative (time since the logger started).
EPOCH_MIN_S = 1e9


def csv_to_bag(csv_path: PathLike, out_path: PathLike, topic: str = '/imu/data',
               frame_id: str = 'imu_link', storage: str | None = None,
               columns: Sequence[str] | None = None, rate_hz: float | None = None,
               start_ns: int | None = None, covariances: Sequence | None = None) -> int:
    """
    Convert a CSV log (docs/contracts.md CSV contract) into an Imu bag.

    Parameters
    ----------
    csv_path : str or os.PathLike
        CSV file (``t,gyro_x,...,accel_z``, optional ``.gz``), read by
        :func:`imu_allan.io.csv_io.read_csv`.
    out_path : str or os.PathLike
        Output bag; storage from the path as in :func:`write_imu_bag`.
    topic, frame_id, storage, covariances
        As in :func:`write_imu_bag`.
    columns : sequence of str, optional
        The six CSV columns to use, in AXES order (default: the AXES names).
    rate_hz : float, optional
        Sample rate [Hz] for a CSV without a ``t`` column.
    start_ns : int, optional
        Added to ``round(t * 1e9)``: lets logs with relative time start at a real epoch
        [ns].  Default: 0 when the first ``t`` is an epoch time (from
        :data:`EPOCH_MIN_S` on), else the current time in whole seconds, so that no
        message has the zero stamp of a publisher that does not fill its header.

    Returns
    -------
    int
        Number of messages written.

    """
    from imu_allan.io.csv_io import read_csv

    # Explicit columns: six arbitrary ones taken in file order would be a silent mix-up.
    data = read_csv(csv_path, columns=list(columns) if columns else list(AXES),
                    rate_hz=rate_hz)
    samples = np.asarray(data.samples, dtype=np.float64)
    if samples.ndim != 2 or samples.shape[1] != 6:
        raise InputError(f'{csv_path}: need 6 columns (gyro x, y, z, accel x, y, z) for an Imu '
                         f'bag, got {samples.shape[-1] if samples.ndim == 2 else samples.ndim}')
    stamps_ns = np.rint(np.asarray(data.t_s, dtype=np.float64) * 1e9).astype(np.int64)
    if start_ns is None:
        relative = stamps_ns.size and stamps_ns[0] < EPOCH_MIN_S * 1e9
        start_ns = int(time.time()) * 1_000_000_000 if relative else 0
    write_imu_bag(out_path, stamps_ns + int(start_ns), samples, topic=topic,
                  frame_id=frame_id, storage=storage, covariances=covariances)
    return int(stamps_ns.size)
