"""
Read sensor_msgs/Imu from bags fast: rosbag2 (sqlite3 or MCAP), single files, ROS 1.

Inputs: a rosbag2 directory (metadata.yaml of any version, or none: the storage
files are read directly), a single ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag``.
Time comes from ``header.stamp`` (DESIGN.md); the bag's receive time is kept too.

Speed: decoding one message at a time in Python reaches about 27,000 msg/s, so a
3-hour 400 Hz recording would take minutes.  Here raw serialised payloads are
located in bulk (sqlite: the messages table's B-tree pages parsed straight from the
memory-mapped file, with one ordered SELECT as the fallback; MCAP: whole chunks,
located through the message indexes or a record walk, decompressed at once) and
decoded with numpy structured dtypes, one ``frombuffer``/strided view per group of
equally laid-out messages.  The layout of a ROS 2 CDR sensor_msgs/msg/Imu:
4-byte encapsulation header, ``stamp.sec`` int32, ``stamp.nanosec`` uint32,
``frame_id`` (uint32 length including the NUL, bytes), padding to 8 bytes (counted
after the encapsulation header), then 37 doubles: orientation 4,
orientation_covariance 9, angular_velocity 3, its covariance 9,
linear_acceleration 3, its covariance 9.  ROS 1 is packed little-endian:
``seq``, ``secs``, ``nsecs`` uint32, ``frame_id`` (uint32 length, bytes), doubles.
Big-endian CDR is decoded too; any payload that fits neither layout goes through
rosbags' own deserialiser (default Jazzy / Noetic type stores), or is skipped with
a warning.
"""

import mmap
import os
from pathlib import Path, PurePath
import re
import sqlite3
import struct
import tempfile
from typing import Callable, Dict, Iterator, List, NamedTuple, Optional, Tuple, Union
from urllib.parse import quote

import lz4.frame
from mcap.exceptions import McapError
from mcap.reader import make_reader
import numpy as np
import yaml
import zstandard

from imu_allan.errors import InputError
from imu_allan.io.imu_cdr import (_gather, _join, _records, decode_imu_payloads,
                                  IMU_MSGTYPES)

#: Messages per ImuBlock unless asked otherwise.
DEFAULT_BLOCK_SIZE = 65536

_FETCH_ROWS = 32768
_MCAP_MAGIC = b'\x89MCAP0\r\n'
_SQLITE_MAGIC = b'SQLite format 3\x00'
_ROS1_MAGIC = b'#ROSBAG V2.0\n'
_ZSTD_MAGIC = b'\x28\xb5\x2f\xfd'
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL = 0x01, 0x02, 0x03, 0x04
_OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX, _OP_DATA_END = 0x05, 0x06, 0x07, 0x0F
_MAX_LISTED = 8

PathLike = Union[str, os.PathLike]


class TopicInfo(NamedTuple):
    """One topic of a bag: name, message type, message count (None when unknown)."""

    topic: str
    msgtype: str
    n_messages: Optional[int]


class ImuBlock(NamedTuple):
    """
    A block of consecutive Imu messages.

    Attributes
    ----------
    stamp_ns : numpy.ndarray
        (n,) int64 header.stamp [ns since the epoch]: the sensor's clock.
    recv_ns : numpy.ndarray
        (n,) int64 time the bag recorded each message [ns since the epoch].
    samples : numpy.ndarray
        (n, 6) float64 in AXES order: angular_velocity x, y, z [rad/s], then
        linear_acceleration x, y, z [m/s^2].

    """

    stamp_ns: np.ndarray
    recv_ns: np.ndarray
    samples: np.ndarray


class _Topic(NamedTuple):
    """Internal topic record; encoding is 'cdr', 'ros1' or what the bag names."""

    name: str
    msgtype: str
    n_messages: Optional[int]
    encoding: str


class _Piece(NamedTuple):
    """Decoded messages of one fetch or chunk, plus how many were dropped."""

    recv_ns: np.ndarray
    stamp_ns: np.ndarray
    samples: np.ndarray
    n_bad: int


# --------------------------------------------------------------------------------------
# Vectorised decoding
# --------------------------------------------------------------------------------------

#: Header of an MCAP Message record: opcode, record length, channel id, log_time.
_MCAP_MESSAGE = np.dtype({'names': ['op', 'length', 'channel', 'log_time'],
                          'formats': ['u1', '<u8', '<u2', '<u8'], 'offsets': [0, 1, 9, 15],
                          'itemsize': 31})


def _make_piece(u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray, recv_ns: np.ndarray,
                encoding: str, decompress: Optional[Callable[[bytes], bytes]]) -> _Piece:
    """Decode payloads into a _Piece, dropping undecodable ones."""
    if decompress is not None:
        # rosbag2 'message' compression: every payload is its own zstd frame.
        payloads = [decompress(u8[s:s + n].tobytes())
                    for s, n in zip(starts.tolist(), lengths.tolist())]
        u8, starts, lengths = _join(payloads)
    stamp_ns, samples, ok = decode_imu_payloads(u8, starts, lengths, encoding)
    n_bad = int(ok.size - np.count_nonzero(ok))
    if n_bad:
        return _Piece(recv_ns[ok], stamp_ns[ok], samples[ok], n_bad)
    return _Piece(recv_ns, stamp_ns, samples, 0)


def _zstd_decompress(data: bytes) -> bytes:
    """Decompress one zstd frame (rosbag2 message compression)."""
    return zstandard.ZstdDecompressor().decompress(data, max_output_size=1 << 30)


# --------------------------------------------------------------------------------------
# Storage back-ends: each lists topics and yields decoded pieces of one topic
# --------------------------------------------------------------------------------------

class _Backend:
    """Common interface of the storage readers."""

    storage = ''

    def __init__(self, path: Path, warnings: List[str],
                 decompress: Optional[Callable[[bytes], bytes]] = None) -> None:
        self.path = path
        self.warnings = warnings
        self.decompress = decompress  # per-message decompression of rosbag2, or None

    def topics(self) -> List[_Topic]:
        """Return every topic with its type, count (or None) and encoding."""
        raise NotImplementedError

    def count(self, topic: _Topic) -> int:
        """Return the number of messages of a topic (may read the bag)."""
        return 0 if topic.n_messages is None else topic.n_messages

    def pieces(self, topic: _Topic) -> Iterator[_Piece]:
        """Yield decoded Imu messages of a topic in the bag's order."""
        raise NotImplementedError

    def close(self) -> None:
        """Release files."""


def _connect_sqlite(path: Path) -> sqlite3.Connection:
    """Open a sqlite3 file read-only; a read-only directory needs 'immutable'."""
    uri = 'file:' + quote(str(path.resolve()))
    # One thread at a time, but not always the opening one (readers may prefetch).
    try:
        conn = sqlite3.connect(uri + '?mode=ro', uri=True, check_same_thread=False)
        conn.execute('SELECT name FROM sqlite_master LIMIT 1').fetchall()
        return conn
    except sqlite3.OperationalError:
        return sqlite3.connect(uri + '?immutable=1', uri=True, check_same_thread=False)


class _SqliteBackend(_Backend):
    """rosbag2 sqlite3 storage (every schema version since Foxy)."""

    storage = 'sqlite3'

    def __init__(self, path: Path, warnings: List[str],
                 decompress: Optional[Callable[[bytes], bytes]] = None) -> None:
        super().__init__(path, warnings, decompress)
        try:
            self.conn = _connect_sqlite(path)
            tables = {row[0] for row in self.conn.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table'")}
            if not {'messages', 'topics'} <= tables:
                self.conn.close()
                raise InputError(f'{path}: sqlite3 file without the rosbag2 tables '
                                 '(messages, topics): not a rosbag2 bag')
            rows = self.conn.execute(
                'SELECT id, name, type, serialization_format FROM topics ORDER BY id').fetchall()
            metadata_counts = self._metadata_counts() if 'metadata' in tables else {}
            total = None
            if len({row[1] for row in rows}) == 1:
                # One topic: the total (answered from the timestamp index) is its count.
                total = self.conn.execute('SELECT count(*) FROM messages').fetchone()[0]
        except sqlite3.DatabaseError as err:
            raise InputError(f'{path}: damaged or not a sqlite3 database ({err})') from None
        self.ids: Dict[str, List[int]] = {}
        self._topics: Dict[str, _Topic] = {}
        for topic_id, name, msgtype, fmt in rows:
            self.ids.setdefault(name, []).append(topic_id)
            count = total if total is not None else metadata_counts.get(name)
            self._topics.setdefault(name, _Topic(name, msgtype, count, fmt))

    def _metadata_counts(self) -> Dict[str, int]:
        """Return topic counts of the metadata table (schema 3+) of a one-file bag."""
        try:
            row = self.conn.execute(
                'SELECT metadata FROM metadata ORDER BY id DESC LIMIT 1').fetchone()
            info = yaml.safe_load(row[0]) if row else None
            info = info.get('rosbag2_bagfile_information', info)
            if len(info['relative_file_paths']) != 1:
                return {}   # one part of a split bag: the counts may cover other files
            return {x['topic_metadata']['name']: int(x['message_count'])
                    for x in info['topics_with_message_count']}
        except (sqlite3.DatabaseError, yaml.YAMLError, AttributeError, KeyError, TypeError,
                ValueError):
            return {}

    def topics(self) -> List[_Topic]:
        """Return every topic of the database."""
        return list(self._topics.values())

    def count(self, topic: _Topic) -> int:
        """Count a topic's messages (a scan of the messages table when not stored)."""
        if topic.n_messages is not None:
            return topic.n_messages
        ids = self.ids[topic.name]
        try:
            return self.conn.execute(
                f'SELECT count(*) FROM messages WHERE topic_id IN ({",".join("?" * len(ids))})',
                ids).fetchone()[0]
        except sqlite3.DatabaseError as err:
            raise InputError(f'{self.path}: damaged sqlite3 database ({err})') from None

    def pieces(self, topic: _Topic) -> Iterator[_Piece]:
        """
        Yield the topic's messages in receive-time order.

        Fast path: the table's B-tree pages are read straight from the file (see
        :class:`_SqlitePages`); whatever that path cannot vouch for (a write-ahead log
        next to the file, overflow pages of the wanted topic, an unusual schema, any
        inconsistency) is read with SQL instead.
        """
        located = None
        if self.decompress is None:
            try:
                located = _SqlitePages(self.path, self.conn).locate(
                    self.ids[topic.name], self.count(topic))
            except (_NotPlain, OSError):
                located = None
        if located is None:
            yield from self._sql_pieces(topic)
            return
        u8, starts, lengths, recv_ns = located
        step = 4 * _FETCH_ROWS
        for k in range(0, starts.size, step):
            yield _make_piece(u8, starts[k:k + step], lengths[k:k + step],
                              recv_ns[k:k + step], topic.encoding, None)

    def _sql_pieces(self, topic: _Topic) -> Iterator[_Piece]:
        """Yield the topic's messages in receive-time order, one SQL fetch at a time."""
        ids = self.ids[topic.name]
        n_read = 0
        try:
            # One ordered SELECT.  Fetching costs about 1.5 us per row in sqlite and the
            # sqlite3 module; letting sqlite concatenate rows (group_concat) was tried and
            # saves only about 10 %: its aggregate step is just as slow.
            cursor = self.conn.execute(
                'SELECT timestamp, data FROM messages WHERE topic_id IN '
                f'({",".join("?" * len(ids))}) ORDER BY timestamp, id', ids)
            while True:
                rows = cursor.fetchmany(_FETCH_ROWS)
                if not rows:
                    return
                recv, payloads = zip(*rows)
                n_read += len(rows)
                yield _make_piece(*_join(payloads), np.array(recv, np.int64), topic.encoding,
                                  self.decompress)
        except sqlite3.DatabaseError as err:
            self.warnings.append(f'{self.path}: damaged sqlite3 database ({err}); read stopped '
                                 f'after {n_read} messages of {topic.name}')

    def close(self) -> None:
        """Close the database."""
        self.conn.close()


class _NotPlain(Exception):
    """The sqlite3 file is not one the page reader vouches for: use SQL."""


def _varint(u8: np.ndarray, pos: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Decode one sqlite varint at each offset (big-endian groups of 7 bits, 9th byte 8).

    Returns
    -------
    value : numpy.ndarray
        (n,) int64 values (rowids, sizes and serial types are far below 2**63).
    length : numpy.ndarray
        (n,) int64 bytes used.

    """
    b = u8[pos]
    value = (b & 0x7F).astype(np.int64)
    length = np.ones(pos.size, np.int64)
    more = b >= 0x80
    for i in range(1, 9):
        if not more.any():
            break
        b = u8[pos + i].astype(np.int64)
        if i < 8:
            value = np.where(more, (value << 7) | (b & 0x7F), value)
            length += more
            more &= b >= 0x80
        else:
            value = np.where(more, (value << 8) | b, value)
            length += more
    return value, length


#: Bytes of a column value per sqlite serial type (0-9; 10, 11 are reserved).
_SERIAL_SIZE = np.array([0, 1, 2, 3, 4, 6, 8, 8, 0, 0, -1, -1], np.int64)


def _serial_int(u8: np.ndarray, pos: np.ndarray, serial: np.ndarray) -> np.ndarray:
    """Decode big-endian signed integer columns of serial types 1-6, 8 and 9."""
    size = _SERIAL_SIZE[np.minimum(serial, 11)]
    if size.size and size[0] in (1, 2, 4, 8) and (serial == serial[0]).all():
        # One integer width throughout (the usual case): a big-endian view.
        k = int(size[0])
        return _gather(u8, pos, k).view(f'>i{k}').reshape(-1).astype(np.int64)
    value = np.zeros(pos.size, np.int64)
    for i in range(8):
        has = size > i
        if not has.any():
            break
        value[has] = (value[has] << 8) | u8[pos[has] + i].astype(np.int64)
    for k, bits in ((1, 8), (2, 16), (3, 24), (4, 32), (6, 48)):
        neg = (size == k) & (value >= 1 << (bits - 1))
        value[neg] -= 1 << bits
    value[serial == 9] = 1
    return value


class _SqlitePages:
    """
    Locate the rows of rosbag2's messages table by reading the file's pages directly.

    The sqlite3 module costs about 1.5 us per fetched row, most of the reading time of
    a large bag.  rosbag2's table is ``messages(id INTEGER PRIMARY KEY, topic_id,
    timestamp, data)``: a rowid B-tree whose leaf cells hold the record (header of
    serial types, then topic_id, timestamp and the data blob) inline unless it is
    larger than the page.  The interior pages are walked in key order, then every
    leaf cell is parsed at once with numpy (varints, serial types), giving the offset
    of each payload in the memory-mapped file (sqlite file format, sections 1.3, 1.6
    and 2.1 of https://www.sqlite.org/fileformat2.html).  Safety: refused (raise
    _NotPlain, the caller uses SQL) for a file with a write-ahead log or hot journal,
    another table layout, wanted rows that spill to overflow pages, or any page or
    cell that does not check out; and the row count must equal the one sqlite gives.
    """

    def __init__(self, path: Path, conn: sqlite3.Connection) -> None:
        self.path = path
        for suffix in ('-wal', '-journal'):
            side = path.with_name(path.name + suffix)
            if side.exists() and side.stat().st_size > 0:
                raise _NotPlain(f'{side.name} present')
        try:
            columns = [(r[1].lower(), r[2].upper(), r[5]) for r in
                       conn.execute('PRAGMA table_info(messages)').fetchall()]
            row = conn.execute("SELECT rootpage FROM sqlite_master WHERE type = 'table' "
                               "AND name = 'messages'").fetchone()
        except sqlite3.DatabaseError as err:
            raise _NotPlain(str(err)) from None
        names = [c[0] for c in columns]
        key = columns[0][1:] if columns else None
        if names != ['id', 'topic_id', 'timestamp', 'data'] or key != ('INTEGER', 1):
            raise _NotPlain('not the rosbag2 messages layout')
        self.root = int(row[0])

    def locate(self, topic_ids: List[int], expected: int):
        """
        Return (u8, starts, lengths, recv_ns) of the topic's payloads, time-ordered.

        ``u8`` views the memory-mapped file; the map lives as long as the arrays.
        """
        with open(self.path, 'rb') as f:
            try:
                mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
            except ValueError:
                raise _NotPlain('empty file') from None
        u8 = np.frombuffer(mm, np.uint8)
        if u8.size < 512:
            raise _NotPlain('shorter than one page')
        head = bytes(u8[:100])
        page_size = struct.unpack_from('>H', head, 16)[0]
        page_size = 65536 if page_size == 1 else page_size
        if page_size < 512 or page_size & (page_size - 1):
            raise _NotPlain('bad page size')
        usable = page_size - head[20]
        n_pages = u8.size // page_size
        try:
            leaves = self._leaves(u8, page_size, n_pages)
            return self._cells(u8, leaves, page_size, usable, topic_ids, expected)
        except (IndexError, ValueError) as err:
            raise _NotPlain(str(err)) from None

    def _leaves(self, u8: np.ndarray, page_size: int, n_pages: int) -> np.ndarray:
        """Page numbers of the table's leaf pages in key order."""
        leaves: List[np.ndarray] = []
        stack = [np.array([self.root], np.int64)]
        visited = 0
        while stack:
            level = stack.pop()
            if level.size == 0:
                continue
            page = int(level[0])
            stack.append(level[1:])
            visited += 1
            if not 2 <= page <= n_pages or visited > n_pages:
                raise _NotPlain('page number out of range')
            base = (page - 1) * page_size
            kind = u8[base]
            if kind == 0x0D:
                # Runs of leaves named by one interior page: take them all at once.
                rest = stack.pop()
                run = np.concatenate(([page], rest))
                kinds = u8[(run - 1) * page_size] if run.max() <= n_pages else None
                if kinds is None or run.min() < 2:
                    raise _NotPlain('page number out of range')
                k = int(np.argmin(kinds == 0x0D)) if not (kinds == 0x0D).all() else run.size
                leaves.append(run[:k])
                visited += k - 1
                stack.append(run[k:])
                continue
            if kind != 0x05:
                raise _NotPlain(f'page {page} is not a table B-tree page')
            n_cells = int(u8[base + 3]) << 8 | int(u8[base + 4])
            ptr = base + 12 + 2 * np.arange(n_cells)
            cells = base + ((u8[ptr].astype(np.int64) << 8) | u8[ptr + 1])
            if n_cells and (cells.max() + 4 > base + page_size or cells.min() < base + 12):
                raise _NotPlain('cell pointer outside its page')
            children = np.zeros(n_cells + 1, np.int64)
            for i in range(4):
                children[:n_cells] = (children[:n_cells] << 8) | u8[cells + i]
            right = base + 8
            children[n_cells] = int.from_bytes(bytes(u8[right:right + 4]), 'big')
            stack.append(children)
        return np.concatenate(leaves) if leaves else np.zeros(0, np.int64)

    def _cells(self, u8: np.ndarray, leaves: np.ndarray, page_size: int, usable: int,
               topic_ids: List[int], expected: int):
        parts = []
        # Batches of leaves keep the numpy temporaries in the CPU caches.
        for k in range(0, leaves.size, 2048):
            parts.append(self._leaf_cells(u8, leaves[k:k + 2048], page_size, usable,
                                          topic_ids))
        if parts:
            data, length, recv_ns = (np.concatenate(x) for x in zip(*parts))
        else:
            data = length = recv_ns = np.zeros(0, np.int64)
        if data.size != expected:
            raise _NotPlain(f'{data.size} rows found, sqlite counts {expected}')
        if data.size > 1 and (np.diff(recv_ns) < 0).any():
            # SQL orders by (timestamp, id); rows in key order sort stably the same way.
            order = np.argsort(recv_ns, kind='stable')
            data, length, recv_ns = data[order], length[order], recv_ns[order]
        return u8, data, length, recv_ns

    @staticmethod
    def _leaf_cells(u8: np.ndarray, leaves: np.ndarray, page_size: int, usable: int,
                    topic_ids: List[int]) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (data offset, data length, timestamp) of the topic's rows in leaves."""
        base = (leaves - 1) * page_size
        n_cells = (u8[base + 3].astype(np.int64) << 8) | u8[base + 4]
        total = int(n_cells.sum())
        page_of = np.repeat(base, n_cells)
        first = np.cumsum(n_cells) - n_cells
        slot = np.arange(total) - np.repeat(first, n_cells)
        ptr = page_of + 8 + 2 * slot
        cell = page_of + ((u8[ptr].astype(np.int64) << 8) | u8[ptr + 1])
        if total and ((cell < page_of + 8).any() or (cell + 4 > page_of + usable).any()):
            raise _NotPlain('cell outside its page')
        size, len1 = _varint(u8, cell)
        _, len2 = _varint(u8, cell + len1)
        start = cell + len1 + len2                    # the record (payload) starts here
        header_len, len3 = _varint(u8, start)
        pos = start + len3
        serials = []
        for _ in range(4):
            serial, n = _varint(u8, pos)
            serials.append(serial)
            pos = pos + n
        if (pos > start + header_len).any():
            raise _NotPlain('record header shorter than four columns')
        st_id, st_topic, st_time, st_data = serials
        bad_int = (st_topic > 9) | (st_time > 9) | (st_topic == 7) | (st_time == 7)
        if ((st_id != 0) | bad_int | (st_data < 12) | (st_data % 2 == 1)).any():
            raise _NotPlain('unexpected column types')
        body = start + header_len
        topic = _serial_int(u8, body, st_topic)
        time_pos = body + _SERIAL_SIZE[st_topic]
        mine = topic == topic_ids[0] if len(topic_ids) == 1 else np.isin(topic, topic_ids)
        # A payload is stored inline (no overflow page) when size <= usable - 35.
        if (size[mine] > usable - 35).any():
            raise _NotPlain('messages of the topic spill to overflow pages')
        if not mine.all():
            size, start, time_pos = size[mine], start[mine], time_pos[mine]
            st_time, st_data = st_time[mine], st_data[mine]
        recv_ns = _serial_int(u8, time_pos, st_time)
        data = time_pos + _SERIAL_SIZE[st_time]
        length = (st_data - 12) // 2
        if (data + length != start + size).any():
            raise _NotPlain('record sizes do not add up')
        return data, length, recv_ns


class _ChunkInfo(NamedTuple):
    """Location of one MCAP chunk and its message index (None when absent)."""

    record_pos: int
    body_end: int
    complete: bool
    indexes: Optional[Dict[int, np.ndarray]]


class _McapBackend(_Backend):
    """MCAP storage (ros2 or ros1 profile), chunked or not, with or without a summary."""

    storage = 'mcap'

    def __init__(self, path: Path, warnings: List[str],
                 decompress: Optional[Callable[[bytes], bytes]] = None) -> None:
        super().__init__(path, warnings, decompress)
        self.zstd = zstandard.ZstdDecompressor()
        self.file = open(path, 'rb')
        self.mm = mmap.mmap(self.file.fileno(), 0, access=mmap.ACCESS_READ)
        self.u8 = np.frombuffer(self.mm, np.uint8)
        self.schemas: Dict[int, str] = {}
        self.channels: Dict[int, Tuple[str, int, str]] = {}
        self.counts: Optional[Dict[int, int]] = None
        try:
            self._open()
        except BaseException as err:
            self.close()
            if isinstance(err, (struct.error, ValueError, IndexError, UnicodeDecodeError)):
                raise InputError(f'{path}: damaged MCAP file ({err})') from None
            raise

    def _open(self) -> None:
        path, size = self.path, self.mm.size()
        if self.mm[:8] != _MCAP_MAGIC or size < 17 or self.mm[8] != _OP_HEADER:
            raise InputError(f'{path}: not an MCAP file (bad magic or header)')
        self.data_start = 9 + 8 + struct.unpack_from('<Q', self.mm, 9)[0]
        tail = self.mm[size - 37:] if size >= self.data_start + 37 else b''
        self.complete = tail[-8:] == _MCAP_MAGIC and tail[:1] == bytes([_OP_FOOTER])
        self.data_end = size
        if self.complete:
            summary_start = struct.unpack_from('<Q', tail, 9)[0]
            self.data_end = summary_start or size - 37
            if summary_start:
                self._read_summary()
        if not self.channels or self.counts is None:
            self._discover()
        if not self.complete:
            self.warnings.append(f'{path}: MCAP file is truncated (no footer: recording cut '
                                 'short?); every complete message is read')

    # -- summary and discovery ------------------------------------------------------
    def _read_summary(self) -> None:
        try:
            self.file.seek(0)
            summary = make_reader(self.file).get_summary()
        except (McapError, struct.error, ValueError, EOFError, OSError) as err:
            self.warnings.append(f'{self.path}: unreadable MCAP summary ({err}); scanning')
            return
        if summary is None:
            return
        for schema in summary.schemas.values():
            self.schemas[schema.id] = schema.name
        for channel in summary.channels.values():
            self.channels[channel.id] = (channel.topic, channel.schema_id,
                                         channel.message_encoding)
        if summary.statistics is not None:
            self.counts = dict(summary.statistics.channel_message_counts)

    def _add_record(self, op: int, buf, pos: int) -> None:
        """Register a Schema or Channel record whose body starts at pos in buf."""
        if op == _OP_SCHEMA:
            schema_id = struct.unpack_from('<H', buf, pos)[0]
            size = struct.unpack_from('<I', buf, pos + 2)[0]
            name = bytes(buf[pos + 6:pos + 6 + size])
            self.schemas[schema_id] = name.decode('utf-8', 'replace')
        elif op == _OP_CHANNEL:
            channel_id, schema_id = struct.unpack_from('<HH', buf, pos)
            size = struct.unpack_from('<I', buf, pos + 4)[0]
            topic = bytes(buf[pos + 8:pos + 8 + size]).decode('utf-8', 'replace')
            pos += 8 + size
            size2 = struct.unpack_from('<I', buf, pos)[0]
            encoding = bytes(buf[pos + 4:pos + 4 + size2]).decode('utf-8', 'replace')
            self.channels[channel_id] = (topic, schema_id, encoding)

    def _discover(self) -> None:
        """Scan the data section for channels and message counts (no usable summary)."""
        counts: Dict[int, int] = {}
        for item in self._scan():
            if isinstance(item, _ChunkInfo):
                if item.indexes is not None and all(c in self.channels for c in item.indexes):
                    for channel_id, index in item.indexes.items():
                        counts[channel_id] = counts.get(channel_id, 0) + len(index)
                    continue
                raw = self._chunk_data(item)
                if raw is None:
                    continue
                offsets = self._walk(raw)
                channel_ids = _records(np.frombuffer(raw, np.uint8), offsets,
                                       _MCAP_MESSAGE)['channel']
            else:
                channel_ids = _records(self.u8, item, _MCAP_MESSAGE)['channel']
            for channel_id, k in zip(*np.unique(channel_ids, return_counts=True)):
                counts[int(channel_id)] = counts.get(int(channel_id), 0) + int(k)
        self.counts = counts

    # -- data section scan ----------------------------------------------------------
    def _scan(self) -> Iterator[Union[_ChunkInfo, np.ndarray]]:
        """
        Walk the records of the data section.

        Yields
        ------
        _ChunkInfo or numpy.ndarray
            Each chunk (with the message indexes that follow it), or (k,) int64 record
            offsets of a run of messages stored outside chunks.

        """
        mm, end = self.mm, self.data_end
        pos = self.data_start
        pending: Optional[_ChunkInfo] = None
        loose: List[int] = []
        while True:
            if pos + 9 > end:
                break
            op = mm[pos]
            body_end = pos + 9 + struct.unpack_from('<Q', mm, pos + 1)[0]
            if body_end > end:
                if pending is not None:
                    # Cut among the chunk's message indexes: they may be incomplete.
                    yield pending._replace(indexes=None)
                    pending = None
                if op == _OP_CHUNK:
                    yield _ChunkInfo(pos, end, False, None)
                break
            if op == _OP_MESSAGE_INDEX and pending is not None:
                channel_id, size = struct.unpack_from('<HI', mm, pos + 9)
                size = min(size, body_end - pos - 15) // 16 * 16
                index = np.frombuffer(mm, '<u8', count=size // 8, offset=pos + 15)
                if pending.indexes is None:
                    pending = pending._replace(indexes={})
                pending.indexes[channel_id] = index.reshape(-1, 2)
                pos = body_end
                continue
            if pending is not None:
                yield pending
                pending = None
            if op == _OP_MESSAGE:
                loose.append(pos)
                if len(loose) >= _FETCH_ROWS:
                    yield np.array(loose, np.int64)
                    loose = []
                pos = body_end
                continue
            if loose:
                yield np.array(loose, np.int64)
                loose = []
            if op == _OP_CHUNK:
                pending = _ChunkInfo(pos, body_end, True, None)
            elif op in (_OP_SCHEMA, _OP_CHANNEL):
                self._add_record(op, mm, pos + 9)
            elif op in (_OP_DATA_END, _OP_FOOTER):
                break
            pos = body_end
        if pending is not None:
            yield pending
        if loose:
            yield np.array(loose, np.int64)

    def _chunk_data(self, chunk: _ChunkInfo) -> Optional[bytes]:
        """Return a chunk's records decompressed (what is readable, if cut short)."""
        mm, body = self.mm, chunk.record_pos + 9
        try:
            size = struct.unpack_from('<Q', mm, body + 16)[0]
            name_len = struct.unpack_from('<I', mm, body + 28)[0]
            compression = bytes(mm[body + 32:body + 32 + name_len]).decode()
            data_len = struct.unpack_from('<Q', mm, body + 32 + name_len)[0]
        except (struct.error, UnicodeDecodeError):
            return None
        data_pos = body + 40 + name_len
        data = mm[data_pos:min(data_pos + data_len, chunk.body_end)]
        try:
            if compression == '':
                raw = data
            elif compression == 'zstd' and chunk.complete:
                raw = self.zstd.decompress(data, max_output_size=size)
            elif compression == 'zstd':
                # A chunk cut short: keep what its complete zstd blocks hold.
                raw = self.zstd.decompressobj().decompress(data)
            elif compression == 'lz4' and chunk.complete:
                raw = lz4.frame.decompress(data)
            elif compression == 'lz4':
                raw = lz4.frame.LZ4FrameDecompressor().decompress(data)
            else:
                self.warnings.append(f'{self.path}: chunk compression {compression!r} is not '
                                     'supported; chunk skipped')
                return None
        except (zstandard.ZstdError, RuntimeError, ValueError) as err:
            if chunk.complete:
                self.warnings.append(f'{self.path}: damaged chunk at byte {chunk.record_pos} '
                                     f'skipped ({err})')
            return None
        if chunk.complete and len(raw) != size:
            self.warnings.append(f'{self.path}: damaged chunk at byte {chunk.record_pos} '
                                 f'({len(raw)} of {size} bytes); its complete records are read')
        return raw

    def _walk(self, raw: bytes) -> np.ndarray:
        """
        Return (k,) int64 offsets of the Message records in decompressed chunk data.

        Runs of equally long messages (one topic recorded alone) are stepped over with
        one vectorised check instead of one Python iteration per record.
        """
        u8 = np.frombuffer(raw, np.uint8)
        end = len(raw)
        pos = 0
        runs = []
        unpack = struct.Struct('<Q').unpack_from
        while pos + 9 <= end:
            op = raw[pos]
            length = unpack(raw, pos + 1)[0]
            stride = 9 + length
            if pos + stride > end:
                break
            if op != _OP_MESSAGE:
                if op in (_OP_SCHEMA, _OP_CHANNEL):
                    self._add_record(op, raw, pos + 9)
                pos += stride
                continue
            run = 1
            nxt = pos + stride
            if (length >= 22 and nxt + 9 <= end and raw[nxt] == _OP_MESSAGE
                    and unpack(raw, nxt + 1)[0] == length):
                # Check growing windows of candidates: long runs cost a few numpy calls,
                # short ones (interleaved topics) only a small window.
                k = (end - pos) // stride
                window = 32
                while run < k:
                    cand = pos + stride * np.arange(run, min(k, run + window), dtype=np.int64)
                    if cand[-1] + 31 > end:
                        cand = cand[:-1]
                    heads = _records(u8, cand, _MCAP_MESSAGE)
                    same = (heads['op'] == _OP_MESSAGE) & (heads['length'] == length)
                    if not same.size:
                        break
                    if not same.all():
                        run += int(np.argmin(same))
                        break
                    run += cand.size
                    window *= 8
            runs.append(pos + stride * np.arange(run, dtype=np.int64))
            pos += stride * run
        return np.concatenate(runs) if runs else np.zeros(0, np.int64)

    # -- reading --------------------------------------------------------------------
    def topics(self) -> List[_Topic]:
        """Return one entry per topic (channels with the same topic are merged)."""
        found: Dict[str, _Topic] = {}
        for channel_id, (name, schema_id, encoding) in sorted(self.channels.items()):
            count = (self.counts or {}).get(channel_id, 0)
            msgtype = self.schemas.get(schema_id, '')
            if name in found:
                old = found[name]
                found[name] = old._replace(n_messages=old.n_messages + count)
            else:
                found[name] = _Topic(name, msgtype, count, encoding)
        return list(found.values())

    def _message_piece(self, buf: np.ndarray, offsets: np.ndarray, wanted: set,
                       encoding: str) -> Optional[_Piece]:
        """Decode the Message records at (k,) offsets of buf that belong to wanted."""
        if offsets.size == 0:
            return None
        inside = offsets + 31 <= buf.size
        if not inside.all():
            offsets = offsets[inside]
        heads = _records(buf, offsets, _MCAP_MESSAGE)
        channels = heads['channel']
        if len(wanted) == 1:
            mine = channels == next(iter(wanted))
        else:
            mine = np.isin(channels, list(wanted))
        lengths = heads['length'].astype(np.int64) - 22
        mine &= (lengths >= 0) & (offsets + 31 + lengths <= buf.size)
        if not mine.all():
            offsets, heads, lengths = offsets[mine], heads[mine], lengths[mine]
        if offsets.size == 0:
            return None
        recv_ns = heads['log_time'].astype(np.int64)
        if recv_ns.size > 1 and (np.diff(recv_ns) < 0).any():
            order = np.argsort(recv_ns, kind='stable')
            offsets, lengths, recv_ns = offsets[order], lengths[order], recv_ns[order]
        return _make_piece(buf, offsets + 31, lengths, recv_ns, encoding, self.decompress)

    def pieces(self, topic: _Topic) -> Iterator[_Piece]:
        """Yield the topic's messages chunk by chunk (stop with a warning at damage)."""
        try:
            yield from self._pieces(topic)
        except (struct.error, ValueError, IndexError) as err:
            self.warnings.append(f'{self.path}: damaged MCAP data ({err}); read stopped')

    def _pieces(self, topic: _Topic) -> Iterator[_Piece]:
        wanted = {cid for cid, (name, _, _) in self.channels.items() if name == topic.name}
        for item in self._scan():
            if isinstance(item, _ChunkInfo):
                if item.indexes is not None and not wanted & item.indexes.keys():
                    continue   # the index says: nothing of this topic inside
                raw = self._chunk_data(item)
                if raw is None:
                    continue
                buf = np.frombuffer(raw, np.uint8)
                offsets = None
                if item.indexes is not None:
                    parts = [item.indexes[c][:, 1] for c in wanted if c in item.indexes]
                    offsets = np.concatenate(parts).astype(np.int64)
                    if not ((offsets + 31 <= buf.size).all()
                            and (buf[offsets] == _OP_MESSAGE).all()):
                        offsets = None   # an index that does not match the chunk: walk it
                if offsets is None:
                    offsets = self._walk(raw)
                piece = self._message_piece(buf, offsets, wanted, topic.encoding)
            else:
                piece = self._message_piece(self.u8, item, wanted, topic.encoding)
            if piece is not None:
                yield piece

    def close(self) -> None:
        """Release the memory map and the file."""
        self.u8 = None
        try:
            self.mm.close()
        except BufferError:
            pass   # a block still views the map; it closes when collected
        self.file.close()


class _Ros1Backend(_Backend):
    """ROS 1 bag (format 2.0) through rosbags' reader; payloads decoded in batches."""

    storage = 'ros1'

    def __init__(self, path: Path, warnings: List[str]) -> None:
        super().__init__(path, warnings)
        from rosbags.rosbag1 import Reader, ReaderError

        self.error = ReaderError
        try:
            self.reader = Reader(path)
            self.reader.open()
        except (ReaderError, OSError, struct.error, ValueError) as err:
            raise InputError(f'{path}: unreadable ROS 1 bag ({err}); a bag cut short needs '
                             '`rosbag reindex`') from None

    def topics(self) -> List[_Topic]:
        """Return one entry per topic, with ROS 1 type names (sensor_msgs/Imu)."""
        found: Dict[str, _Topic] = {}
        for conn in self.reader.connections:
            msgtype = conn.msgtype.replace('/msg/', '/')
            if conn.topic in found:
                old = found[conn.topic]
                found[conn.topic] = old._replace(n_messages=old.n_messages + conn.msgcount)
            else:
                found[conn.topic] = _Topic(conn.topic, msgtype, conn.msgcount, 'ros1')
        return list(found.values())

    def pieces(self, topic: _Topic) -> Iterator[_Piece]:
        """Yield the topic's messages in time order, decoded in batches."""
        conns = [c for c in self.reader.connections if c.topic == topic.name]
        recv: List[int] = []
        payloads: List[bytes] = []
        try:
            for _, stamp, raw in self.reader.messages(connections=conns):
                recv.append(stamp)
                payloads.append(raw)
                if len(payloads) >= _FETCH_ROWS:
                    yield _make_piece(*_join(payloads), np.array(recv, np.int64), 'ros1', None)
                    recv, payloads = [], []
        except (self.error, OSError, struct.error, ValueError) as err:
            self.warnings.append(f'{self.path}: damaged ROS 1 bag ({err}); read stopped')
        if payloads:
            yield _make_piece(*_join(payloads), np.array(recv, np.int64), 'ros1', None)

    def close(self) -> None:
        """Close the bag."""
        self.reader.close()


def _sniff(path: Path) -> bytes:
    try:
        with open(path, 'rb') as stream:
            return stream.read(16)
    except OSError as err:
        raise InputError(f'{path}: cannot read ({err.strerror})') from None


def _open_file(path: Path, warnings: List[str],
               decompress: Optional[Callable[[bytes], bytes]] = None) -> _Backend:
    """Open one storage file, recognised by its signature rather than its suffix."""
    head = _sniff(path)
    if not head:
        raise InputError(f'{path}: empty file (0 bytes)')
    if head.startswith(_MCAP_MAGIC):
        return _McapBackend(path, warnings, decompress)
    if head.startswith(_SQLITE_MAGIC):
        return _SqliteBackend(path, warnings, decompress)
    if head.startswith(_ROS1_MAGIC):
        return _Ros1Backend(path, warnings)
    if head.startswith(b'#ROSBAG V'):
        raise InputError(f'{path}: ROS 1 bag format {head[9:12].decode(errors="replace")} is '
                         'not supported (only 2.0; migrate it with `rosbag fix`)')
    if head.startswith(_ZSTD_MAGIC):
        raise InputError(f'{path}: zstd-compressed file; open the rosbag2 directory that '
                         'holds it (its metadata.yaml names the compression)')
    raise InputError(f'{path}: not a bag (no MCAP, sqlite3 or ROS 1 bag signature)')


def _natural_key(path: Path) -> list:
    return [int(t) if t.isdigit() else t for t in re.split(r'(\d+)', path.name)]


class _Rosbag2DirBackend(_Backend):
    """A rosbag2 directory: metadata.yaml (any version) plus storage files."""

    def __init__(self, path: Path, warnings: List[str]) -> None:
        super().__init__(path, warnings)
        self.tmp: Optional[tempfile.TemporaryDirectory] = None
        self.parts: List[_Backend] = []
        info = self._metadata()
        files, decompress = self._files(info)
        try:
            for file in files:
                self.parts.append(_open_file(file, warnings, decompress))
        except BaseException:
            self.close()
            raise
        self.storage = self.parts[0].storage
        self._topics = self._merge_topics(info)

    def _metadata(self) -> Optional[dict]:
        meta = self.path / 'metadata.yaml'
        if not meta.exists():
            self.warnings.append(f'{self.path}: no metadata.yaml; reading the storage files '
                                 'directly')
            return None
        try:
            info = yaml.safe_load(meta.read_text())['rosbag2_bagfile_information']
            if not isinstance(info, dict):
                raise TypeError('not a mapping')
            return info
        except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError) as err:
            reason = str(err).splitlines()[0] if str(err) else type(err).__name__
            self.warnings.append(f'{meta}: unparsable ({reason}); reading the storage files '
                                 'directly')
            return None

    def _files(self, info: Optional[dict]) -> Tuple[List[Path], Optional[Callable]]:
        """Return the storage files in order and the per-message decompressor, if any."""
        decompress = None
        listed: List[Path] = []
        if info is not None:
            mode = str(info.get('compression_mode') or '').lower()
            fmt = str(info.get('compression_format') or '').lower()
            if mode not in ('', 'none') and fmt != 'zstd':
                raise InputError(f'{self.path}: compression format {fmt!r} is not supported '
                                 '(only zstd)')
            for name in info.get('relative_file_paths') or []:
                # Old bags store 'bagname/bagname_0.db3'; the file sits in the directory.
                candidates = [self.path / PurePath(name).name, self.path / name]
                found = next((c for c in candidates if c.is_file()), None)
                if found is None:
                    self.warnings.append(f'{self.path}: listed storage file {name} is missing')
                else:
                    listed.append(found)
            if mode == 'file':
                listed = [self._unpack(f) if f.suffix == '.zstd' else f for f in listed]
            elif mode == 'message':
                decompress = _zstd_decompress
        if not listed:
            listed = sorted((f for f in self.path.iterdir()
                             if f.suffix in ('.mcap', '.db3') and f.is_file()), key=_natural_key)
            if info is not None and listed:
                self.warnings.append(f'{self.path}: metadata.yaml names no readable storage '
                                     f'file; reading {", ".join(f.name for f in listed)}')
        if not listed:
            raise InputError(f'{self.path}: no rosbag2 storage files (.db3 or .mcap) found')
        return listed, decompress

    def _unpack(self, packed: Path) -> Path:
        """Decompress a file-compressed storage file into a private temporary directory."""
        if self.tmp is None:
            self.tmp = tempfile.TemporaryDirectory(prefix='imu_allan_bag_')
        target = Path(self.tmp.name) / packed.stem
        try:
            with open(packed, 'rb') as src, open(target, 'wb') as dst:
                zstandard.ZstdDecompressor().copy_stream(src, dst)
        except (OSError, zstandard.ZstdError) as err:
            raise InputError(f'{packed}: cannot decompress ({err})') from None
        return target

    def _merge_topics(self, info: Optional[dict]) -> Dict[str, _Topic]:
        merged: Dict[str, _Topic] = {}
        for part in self.parts:
            for topic in part.topics():
                old = merged.get(topic.name)
                if old is None:
                    merged[topic.name] = topic
                else:
                    both = (None if old.n_messages is None or topic.n_messages is None
                            else old.n_messages + topic.n_messages)
                    merged[topic.name] = old._replace(n_messages=both)
        try:
            entries = (info or {}).get('topics_with_message_count') or []
            counts = {x['topic_metadata']['name']: int(x['message_count']) for x in entries}
        except (KeyError, TypeError, ValueError):
            counts = {}
        for name, count in counts.items():
            # metadata.yaml counts the whole bag: it wins over what the files say.
            if name in merged:
                merged[name] = merged[name]._replace(n_messages=count)
        return merged

    def topics(self) -> List[_Topic]:
        """Return the topics of all storage files."""
        return list(self._topics.values())

    def count(self, topic: _Topic) -> int:
        """Count a topic's messages over all files."""
        if topic.n_messages is not None:
            return topic.n_messages
        total = 0
        for part in self.parts:
            own = next((t for t in part.topics() if t.name == topic.name), None)
            total += part.count(own) if own is not None else 0
        return total

    def pieces(self, topic: _Topic) -> Iterator[_Piece]:
        """Yield the topic's messages file after file (split bags)."""
        for part in self.parts:
            own = next((t for t in part.topics() if t.name == topic.name), None)
            if own is not None:
                yield from part.pieces(own)

    def close(self) -> None:
        """Close every file and remove decompressed copies."""
        for part in self.parts:
            part.close()
        if self.tmp is not None:
            self.tmp.cleanup()


def _open_backend(path: PathLike, warnings: List[str]) -> _Backend:
    path = Path(path)
    if not path.exists():
        raise InputError(f'{path}: no such file or directory')
    if path.is_dir():
        if not ((path / 'metadata.yaml').exists() or any(
                f.suffix in ('.mcap', '.db3', '.zstd') for f in path.iterdir())):
            raise InputError(f'{path}: directory without metadata.yaml or .db3/.mcap files: '
                             'not a rosbag2 bag')
        return _Rosbag2DirBackend(path, warnings)
    if path.name == 'metadata.yaml':
        return _Rosbag2DirBackend(path.parent, warnings)
    return _open_file(path, warnings)


# --------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------

def _is_imu(topic: _Topic) -> bool:
    return topic.msgtype in IMU_MSGTYPES


def _describe(topics: List[_Topic]) -> str:
    """List topics for an error message: '/a (type, 10 messages), ...'."""
    parts = []
    for topic in topics[:_MAX_LISTED]:
        count = topic.n_messages
        parts.append(f'{topic.name} ({topic.msgtype}'
                     + ('' if count is None else f', {count} messages') + ')')
    if len(topics) > _MAX_LISTED:
        parts.append(f'and {len(topics) - _MAX_LISTED} more')
    return ', '.join(parts) if parts else 'none'


def list_topics(path: PathLike) -> List[TopicInfo]:
    """
    List every topic of a bag with its type and message count.

    Parameters
    ----------
    path : str or os.PathLike
        rosbag2 directory, ``.mcap`` / ``.db3`` file, or ROS 1 ``.bag``.

    Returns
    -------
    list of TopicInfo
        In the bag's order; counts always filled (may scan a bare sqlite3 file).

    Raises
    ------
    InputError
        If the path is missing or not a readable bag.

    """
    backend = _open_backend(path, [])
    try:
        return [TopicInfo(t.name, t.msgtype, backend.count(t)) for t in backend.topics()]
    finally:
        backend.close()


def list_imu_topics(path: PathLike) -> List[TopicInfo]:
    """
    List the sensor_msgs/Imu topics of a bag.

    Parameters
    ----------
    path : str or os.PathLike
        rosbag2 directory, ``.mcap`` / ``.db3`` file, or ROS 1 ``.bag``.

    Returns
    -------
    list of TopicInfo
        Topics of type sensor_msgs/msg/Imu (ROS 1: sensor_msgs/Imu), with counts.

    Raises
    ------
    InputError
        If the path is missing or not a readable bag.

    """
    backend = _open_backend(path, [])
    try:
        return [TopicInfo(t.name, t.msgtype, backend.count(t))
                for t in backend.topics() if _is_imu(t)]
    finally:
        backend.close()


class ImuSource:
    """
    The Imu messages of one topic of a bag, read block by block.

    Attributes
    ----------
    path : pathlib.Path
        The bag.
    topic : str
        Topic name.
    msgtype : str
        Type name as the bag stores it.
    n_messages : int or None
        Message count when the bag states it (None: unknown until read).
    storage : str
        'mcap', 'sqlite3' or 'ros1'.
    warnings : list of str
        Problems met so far (truncation, skipped messages, unfilled headers ...);
        complete once ``blocks()`` has been consumed.

    """

    def __init__(self, path: Path, backend: _Backend, topic: _Topic,
                 warnings: List[str]) -> None:
        self.path = path
        self.topic = topic.name
        self.msgtype = topic.msgtype
        self.n_messages = topic.n_messages
        self.storage = backend.storage
        self.warnings = warnings
        self._backend = backend
        self._topic = topic

    def _warn(self, text: str) -> None:
        if text not in self.warnings:
            self.warnings.append(text)

    def blocks(self, block_size: int = DEFAULT_BLOCK_SIZE) -> Iterator[ImuBlock]:
        """
        Yield the messages in blocks of ``block_size`` (the last one may be shorter).

        Parameters
        ----------
        block_size : int
            Messages per block.

        Yields
        ------
        ImuBlock
            stamp_ns (n,) int64 [ns], recv_ns (n,) int64 [ns], samples (n, 6) float64.

        """
        if block_size < 1:
            raise ValueError('block_size must be positive')
        pending: List[_Piece] = []
        n_pending = n_total = n_bad = n_zero = 0
        for piece in self._backend.pieces(self._topic):
            n_bad += piece.n_bad
            if not piece.recv_ns.size:
                continue
            n_zero += int(np.count_nonzero(piece.stamp_ns == 0))
            pending.append(piece)
            n_pending += piece.recv_ns.size
            while n_pending >= block_size:
                block, rest = _split(pending, block_size)
                pending = [rest] if rest is not None else []
                n_pending -= block_size
                n_total += block_size
                yield block
        if n_pending:
            n_total += n_pending
            yield _split(pending, n_pending)[0]
        if n_bad:
            self._warn(f'{n_bad} messages on {self.topic} are not decodable sensor_msgs/Imu '
                       'and were skipped')
        if n_zero:
            self._warn(f'header.stamp is 0 in {n_zero} of {n_total} messages on {self.topic}: '
                       'the publisher does not fill the header; only recv_ns carries time')
        if not n_total:
            self._warn(f'no readable messages on {self.topic} in {self.path}')

    def read_all(self) -> ImuBlock:
        """Return every message as one ImuBlock."""
        blocks = list(self.blocks())
        if not blocks:
            return ImuBlock(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 6)))
        return ImuBlock(*(np.concatenate([getattr(b, f) for b in blocks])
                          for f in ImuBlock._fields))

    def close(self) -> None:
        """Release the bag's files."""
        self._backend.close()

    def __enter__(self) -> 'ImuSource':
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _split(pieces: List[_Piece], n: int) -> Tuple[ImuBlock, Optional[_Piece]]:
    """Concatenate pieces and cut the first n messages off as a block."""
    if len(pieces) == 1:
        joined = pieces[0]
    else:
        joined = _Piece(np.concatenate([p.recv_ns for p in pieces]),
                        np.concatenate([p.stamp_ns for p in pieces]),
                        np.concatenate([p.samples for p in pieces]), 0)
    block = ImuBlock(joined.stamp_ns[:n], joined.recv_ns[:n], joined.samples[:n])
    if joined.recv_ns.size == n:
        return block, None
    return block, _Piece(joined.recv_ns[n:], joined.stamp_ns[n:], joined.samples[n:], 0)


def open_imu(path: PathLike, topic: Optional[str] = None) -> ImuSource:
    """
    Open the sensor_msgs/Imu topic of a bag for reading.

    Parameters
    ----------
    path : str or os.PathLike
        rosbag2 directory (sqlite3 or MCAP; metadata.yaml optional), a single ``.mcap`` or
        ``.db3`` file, or a ROS 1 ``.bag``.
    topic : str, optional
        Topic to read; by default the only Imu topic of the bag.

    Returns
    -------
    ImuSource
        Reader of that topic (close it, or use it as a context manager).

    Raises
    ------
    InputError
        If the bag is missing, unreadable or empty, has no Imu topic, several Imu topics
        and no ``topic``, or ``topic`` is missing or not of type Imu.

    """
    warnings: List[str] = []
    backend = _open_backend(path, warnings)
    try:
        chosen = _choose_topic(Path(path), backend, topic)
    except BaseException:
        backend.close()
        raise
    return ImuSource(Path(path), backend, chosen, warnings)


def _choose_topic(path: Path, backend: _Backend, name: Optional[str]) -> _Topic:
    topics = backend.topics()
    if not topics:
        raise InputError(f'{path}: empty bag (no topics)')
    imu = [t for t in topics if _is_imu(t)]
    if name is not None:
        wanted = name if name.startswith('/') else '/' + name
        match = next((t for t in topics if t.name in (name, wanted)), None)
        if match is None:
            raise InputError(f'{path}: no topic {name}; Imu topics: {_describe(imu)}'
                             + ('' if imu else f'; topics: {_describe(topics)}'))
        if not _is_imu(match):
            raise InputError(f'{path}: topic {match.name} is {match.msgtype or "untyped"}, '
                             f'not sensor_msgs/msg/Imu; Imu topics: {_describe(imu)}')
        chosen = match
    elif len(imu) == 1:
        chosen = imu[0]
    elif not imu:
        raise InputError(f'{path}: no sensor_msgs/msg/Imu topic; topics: '
                         f'{_describe(topics)}')
    else:
        raise InputError(f'{path}: {len(imu)} Imu topics: {_describe(imu)}; '
                         'choose one with --topic')
    if chosen.encoding not in ('cdr', 'ros1'):
        raise InputError(f'{path}: topic {chosen.name} is serialised as {chosen.encoding!r}; '
                         'only CDR (ROS 2) and ROS 1 messages are supported')
    if chosen.n_messages == 0:
        total = sum(t.n_messages or 0 for t in topics)
        raise InputError(f'{path}: topic {chosen.name} has no messages'
                         + (' (empty bag)' if not total else ''))
    return chosen
