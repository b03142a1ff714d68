"""
rosbag2 sqlite3 storage: the messages table read from its B-tree pages, or by SQL.

Part of :mod:`imu_allan.io.bag_reader`.
"""

import mmap
from pathlib import Path
import sqlite3
import struct
from typing import Callable, Iterator
from urllib.parse import quote

import numpy as np
import yaml

from imu_allan.core import native
from imu_allan.errors import InputError
from imu_allan.io.bags.base import _Backend, _FETCH_ROWS, _make_piece, _Piece, _Topic
from imu_allan.io.imu_cdr import _gather, _join


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

    def __init__(self, path: Path, warnings: list[str],
                 decompress: Callable[[bytes], bytes] | None = None) -> None:
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
        self.ids: dict[str, list[int]] = {}
        self._topics: dict[str, _Topic] = {}
        for topic_id, name, msgtype, fmt in rows:
            self.ids.setdefault(name, []).append(topic_id)
            count = total if total is not None else metadata_counts.get(name)
            self._topics.setdefault(name, _Topic(name, msgtype, count, fmt))

    def _metadata_counts(self) -> dict[str, int]:
        """Return topic counts of the metadata table (schema 3+) of a one-file bag."""
        try:
            row = self.conn.execute(
                'SELECT metadata FROM metadata ORDER BY id DESC LIMIT 1').fetchone()
            info = yaml.safe_load(row[0]) if row else {}
            info = info.get('rosbag2_bagfile_information', info)
            if len(info['relative_file_paths']) != 1:
                return {}   # one part of a split bag: the counts may cover other files
            return {x['topic_metadata']['name']: int(x['message_count'])
                    for x in info['topics_with_message_count']}
        except (sqlite3.DatabaseError, yaml.YAMLError, AttributeError, KeyError, TypeError,
                ValueError):
            return {}

    def topics(self) -> list[_Topic]:
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


def _varint(u8: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Decode one sqlite varint at each offset (big-endian groups of 7 bits, 9th byte 8).

    Returns
    -------
    value : numpy.ndarray
        (n,) int64 values (rowids, sizes and serial types are far below 2**63).
    length : numpy.ndarray
        (n,) int64 bytes used.

    """
    if native.LIB is not None and u8.flags.c_contiguous:
        return native.varints(u8, pos)
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


# Long by design: one walk of one sqlite file's B-tree (page size, encoding, overflow
# pages) whose steps share the open file; each is a short method.
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

    def locate(self, topic_ids: list[int], expected: int):
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
        leaves: list[np.ndarray] = []
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
               topic_ids: list[int], expected: int):
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
                    topic_ids: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
