"""
rosbag2 sqlite3 storage: the messages table read from its B-tree pages, or by SQL.

Part of :mod:`imu_allan.io.bag_reader`.
"""

import os
from pathlib import Path
import shutil
import sqlite3
import struct
import tempfile
from typing import Callable, Iterator
from urllib.parse import quote

import numpy as np
import yaml

from imu_allan.errors import InputError
from imu_allan.io.bags.base import _FETCH_ROWS, _make_piece, Backend, Piece, Topic
from imu_allan.io.imu_cdr import gather_bytes, join_payloads


_Opened = tuple[sqlite3.Connection, Path, tempfile.TemporaryDirectory | None]


def _connect_sqlite(path: Path, warnings: list[str]) -> _Opened:
    """
    Open a sqlite3 file read-only: (connection, file opened, temporary copy or None).

    A file in a read-only directory cannot get the shared-memory file that read-only
    mode needs: without a write-ahead log it is opened 'immutable'; with one (rosbag2's
    resilient profile writes WAL) the file and its log are copied to a temporary
    directory first, since 'immutable' would ignore the rows that live in the log.
    """
    uri = 'file:' + quote(str(path.resolve()))
    # One thread at a time, but not always the opening one (readers may prefetch).
    try:
        conn = sqlite3.connect(uri + '?mode=ro', uri=True, check_same_thread=False)
        conn.execute('SELECT name FROM sqlite_master LIMIT 1').fetchall()
        return conn, path, None
    except sqlite3.OperationalError:
        pass
    except sqlite3.DatabaseError as err:
        raise InputError(f'{path}: damaged or not a sqlite3 database ({_line(err)})') from None
    wal = path.with_name(path.name + '-wal')
    if not (wal.exists() and wal.stat().st_size > 0):
        conn = sqlite3.connect(uri + '?immutable=1', uri=True, check_same_thread=False)
        return conn, path, None
    tmp = tempfile.TemporaryDirectory(prefix='imu_allan_wal_')
    copy = Path(tmp.name) / path.name
    try:
        shutil.copyfile(path, copy)
        shutil.copyfile(wal, copy.with_name(copy.name + '-wal'))
    except OSError as err:
        tmp.cleanup()
        raise InputError(f'{path}: a write-ahead-log bag in a read-only place, and no room '
                         f'to copy it aside ({err.strerror}); copy the bag somewhere '
                         'writable') from None
    warnings.append(f'{path}: write-ahead log in a read-only directory: bag and log copied to '
                    'a temporary directory to read every committed message')
    uri = 'file:' + quote(str(copy))
    return sqlite3.connect(uri + '?mode=ro', uri=True, check_same_thread=False), copy, tmp


#: Rowids read one by one around a damaged page at most.
_MAX_POINT_READS = 1 << 16


def _line(err: BaseException) -> str:
    """Return the first line of an error's text (sqlite quotes whole schemas in some)."""
    text = str(err).strip()
    return text.splitlines()[0] if text else type(err).__name__


# Long because rosbag2's sqlite3 schema changed between releases and a damaged file
# is read up to its damage: one short method per case.
class _SqliteBackend(Backend):
    """rosbag2 sqlite3 storage (every schema version since Foxy)."""

    storage = 'sqlite3'

    def __init__(self, path: Path, warnings: list[str],
                 decompress: Callable[[bytes], bytes] | None = None) -> None:
        super().__init__(path, warnings, decompress)
        self.conn, self.db_path, self.tmp = _connect_sqlite(path, warnings)
        try:
            tables = {row[0] for row in self.conn.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table'")}
            if not {'messages', 'topics'} <= tables:
                self.close()
                raise InputError(f'{path}: sqlite3 file without the rosbag2 tables '
                                 '(messages, topics): not a rosbag2 bag')
            rows = self.conn.execute(
                'SELECT id, name, type, serialization_format FROM topics ORDER BY id').fetchall()
            metadata_counts = self._metadata_counts() if 'metadata' in tables else {}
            total = None
            if len({(row[1], row[2]) for row in rows}) == 1:
                # One topic: the total (answered from the timestamp index) is its count.
                total = self._total()
        except sqlite3.DatabaseError as err:
            self.close()
            raise InputError(f'{path}: damaged or not a sqlite3 database ({_line(err)})') from None
        # Keyed by name and type: another message type on the same topic is another topic.
        self.ids: dict[tuple[str, str], list[int]] = {}
        self._topics: dict[tuple[str, str], Topic] = {}
        for topic_id, name, msgtype, fmt in rows:
            self.ids.setdefault((name, msgtype), []).append(topic_id)
            count = total if total is not None else metadata_counts.get((name, msgtype))
            self._topics.setdefault((name, msgtype), Topic(name, msgtype, count, fmt))

    def _total(self) -> int | None:
        """All rows of the messages table (None when a damaged page hides the count)."""
        try:
            return self.conn.execute('SELECT count(*) FROM messages').fetchone()[0]
        except sqlite3.DatabaseError:
            return None

    def _metadata_counts(self) -> dict[tuple[str, str], int]:
        """Return topic counts of the metadata table (schema 3+) of a one-file bag."""
        try:
            row = self.conn.execute(
                'SELECT metadata FROM metadata ORDER BY id DESC LIMIT 1').fetchone()
            info = yaml.safe_load(row[0]) if row else {}
            info = info.get('rosbag2_bagfile_information', info)
            if len(info['relative_file_paths']) != 1:
                return {}   # one part of a split bag: the counts may cover other files
            return {(x['topic_metadata']['name'], x['topic_metadata']['type']):
                    int(x['message_count'])
                    for x in info['topics_with_message_count']}
        except (sqlite3.DatabaseError, yaml.YAMLError, AttributeError, KeyError, TypeError,
                ValueError):
            return {}

    def topics(self) -> list[Topic]:
        """Return every topic of the database."""
        return list(self._topics.values())

    def extent(self) -> tuple[int | None, int | None, int | None]:
        """Return the first and last receive time and the row count, by SQL."""
        try:
            first, last, count = self.conn.execute(
                'SELECT min(timestamp), max(timestamp), count(*) FROM messages').fetchone()
        except sqlite3.DatabaseError:
            return None, None, None
        return first, last, count

    def count(self, topic: Topic) -> int | None:
        """Count a topic's messages by SQL (the stored hint where a damaged page hides it)."""
        if len(self.ids) == 1:
            total = self._total()
            return topic.n_messages if total is None else total
        ids = self.ids[topic.name, topic.msgtype]
        try:
            return self.conn.execute(
                f'SELECT count(*) FROM messages WHERE topic_id IN ({",".join("?" * len(ids))})',
                ids).fetchone()[0]
        except sqlite3.DatabaseError:
            return topic.n_messages

    def pieces(self, topic: Topic) -> Iterator[Piece]:
        """
        Yield the topic's messages in rowid (recording) order.

        Fast path: the table's B-tree pages are read straight from the file (see
        :class:`_SqlitePages`); from the first row that path cannot vouch for (a
        write-ahead log next to the file, overflow pages of the wanted topic, an unusual
        schema, any inconsistency) on, the rest is read with SQL.
        """
        after = 0
        if self.decompress is None:
            try:
                pages = _SqlitePages(self.db_path, self.conn)
                ids = self.ids[topic.name, topic.msgtype]
                for piece, last_rowid in pages.pieces(ids, topic.encoding):
                    after = last_rowid
                    yield piece
                return
            except (_NotPlain, OSError):
                pass
        yield from self._sql_pieces(topic, after)

    def _sql_pieces(self, topic: Topic, start: int) -> Iterator[Piece]:
        """
        Yield the topic's messages with rowid > after, one SQL fetch at a time.

        Rows are read in rowid order, the table's own B-tree, so a damaged page costs
        only its own rows: the read resumes past it (:meth:`_past_damage`).
        """
        ids = self.ids[topic.name, topic.msgtype]
        sql = ('SELECT id, timestamp, data FROM messages WHERE id > ? AND topic_id IN '
               f'({",".join("?" * len(ids))}) ORDER BY id')
        repeated = 0
        after: int | None = start
        while after is not None:
            rows: list = []
            error = None
            try:
                # Row by row (as fetchmany steps anyway): an error keeps the rows before it.
                for row in self.conn.execute(sql, [after, *ids]):
                    if row[0] <= (rows[-1][0] if rows else after):
                        # A damaged cell pointer shows a row twice: once is enough.
                        repeated += 1
                        continue
                    rows.append(row)
                    if len(rows) >= _FETCH_ROWS:
                        after = rows[-1][0]
                        yield self._piece(rows, topic)
                        rows = []
            except sqlite3.DatabaseError as err:
                error = err
            assert after is not None
            if rows:
                after = rows[-1][0]
                yield self._piece(rows, topic)
            if error is None:
                break
            nxt = self._past_damage(after)
            # The rows between, one at a time: all but those on the damaged page come back.
            rows = self._one_by_one(after, nxt, ids)
            if rows:
                yield self._piece(rows, topic)
            self.warnings.append(f'{self.path}: damaged sqlite3 page after row {after} '
                                 f'({_line(error)}); ' + ('read stopped' if nxt is None else
                                                          f'read resumed after row {nxt}'))
            after = nxt
        if repeated:
            self.warnings.append(f'{self.path}: {repeated} rows out of rowid order (a damaged '
                                 'page) skipped')

    def _one_by_one(self, after: int, bound: int | None, ids: list[int]) -> list:
        """Rows after < id <= bound of the topic that SQL reads one rowid at a time."""
        rows = []
        stop = after + _MAX_POINT_READS if bound is None else min(bound, after + _MAX_POINT_READS)
        for rowid in range(after + 1, stop + 1):
            try:
                row = self.conn.execute('SELECT id, topic_id, timestamp, data FROM messages '
                                        'WHERE id = ?', (rowid,)).fetchone()
            except sqlite3.DatabaseError:
                continue
            if row is not None and row[1] in ids:
                rows.append((row[0], row[2], row[3]))
        return rows

    def _piece(self, rows: list, topic: Topic) -> Piece:
        _, recv, payloads = zip(*rows)
        return _make_piece(*join_payloads(payloads), np.array(recv, np.int64), topic.encoding,
                           self.decompress)

    def _past_damage(self, after: int) -> int | None:
        """Return the smallest rowid bound past a damaged page that SQL reads again."""
        def readable(bound: int) -> bool:
            try:
                self.conn.execute('SELECT id, timestamp, data FROM messages WHERE id > ? '
                                  'ORDER BY id LIMIT 64', (bound,)).fetchall()
                return True
            except sqlite3.DatabaseError:
                return False
        step = 1
        while not readable(after + step):
            step *= 2
            if after + step >= 1 << 63:
                return None
        low, high = after + step // 2, after + step     # unreadable, readable
        while high - low > 1:
            mid = (low + high) // 2
            low, high = (low, mid) if readable(mid) else (mid, high)
        return high

    def close(self) -> None:
        """Close the database (and remove a temporary copy)."""
        self.conn.close()
        if self.tmp is not None:
            self.tmp.cleanup()


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
        return gather_bytes(u8, pos, k).view(f'>i{k}').reshape(-1).astype(np.int64)
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
    Read the rows of rosbag2's messages table from the file's pages directly.

    Fetching the rows one by one through the sqlite3 module is most of the reading
    time of a large bag.  rosbag2's table is ``messages(id INTEGER PRIMARY KEY, topic_id,
    timestamp, data)``: a rowid B-tree whose leaf cells hold the record (header of
    serial types, then topic_id, timestamp and the data blob) inline unless it is
    larger than the page.  The interior pages are walked level by level, then the leaf
    pages are read in batches (plain reads: a file that shrinks is a short read, never
    a SIGBUS) and every leaf cell is parsed at once with numpy (varints, serial types)
    (sqlite file format, sections 1.3, 1.6 and 2.1 of
    https://www.sqlite.org/fileformat2.html).  Safety: refused (raise _NotPlain, the
    caller reads the rest with SQL) for a file with a write-ahead log or hot journal,
    another table layout, wanted rows that spill to overflow pages, rowids that do not
    increase, or any page or cell that does not check out.
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

    def pieces(self, topic_ids: list[int], encoding: str) -> Iterator[tuple[Piece, int]]:
        """Yield (decoded piece, its last rowid) per batch of leaf pages, in rowid order."""
        with open(self.path, 'rb') as f:
            self.fd = f.fileno()
            size = os.fstat(self.fd).st_size
            head = os.pread(self.fd, 100, 0)
            if size < 512 or len(head) < 100:
                raise _NotPlain('shorter than one page')
            page_size = struct.unpack_from('>H', head, 16)[0]
            page_size = 65536 if page_size == 1 else page_size
            if page_size < 512 or page_size & (page_size - 1):
                raise _NotPlain('bad page size')
            self.page_size, self.usable = page_size, page_size - head[20]
            self.n_pages = size // page_size
            last = 0
            try:
                leaves = self._leaves()
                for k in range(0, leaves.size, 2048):
                    u8, base = self._read_pages(leaves[k:k + 2048])
                    data, length, recv_ns, rowid = self._leaf_cells(
                        u8, base, self.usable, topic_ids)
                    if rowid.size and (rowid[0] <= last or (np.diff(rowid) <= 0).any()):
                        raise _NotPlain('rowids out of order')
                    if rowid.size:
                        last = int(rowid[-1])
                        yield _make_piece(u8, data, length, recv_ns, encoding, None), last
            except (IndexError, ValueError) as err:
                raise _NotPlain(str(err)) from None

    def _page(self, page: int) -> np.ndarray:
        if not 2 <= page <= self.n_pages:
            raise _NotPlain('page number out of range')
        raw = os.pread(self.fd, self.page_size, (page - 1) * self.page_size)
        if len(raw) < self.page_size:
            raise _NotPlain('file shorter than its pages')
        return np.frombuffer(raw, np.uint8)

    def _read_pages(self, pages: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Read pages (runs of consecutive numbers at once): (bytes, offset of each page)."""
        if pages.min() < 2 or pages.max() > self.n_pages:
            raise _NotPlain('page number out of range')
        breaks = np.flatnonzero(np.diff(pages) != 1) + 1
        parts = []
        for run in np.split(pages, breaks):
            n = run.size * self.page_size
            raw = os.pread(self.fd, n, (int(run[0]) - 1) * self.page_size)
            if len(raw) < n:
                raise _NotPlain('file shorter than its pages')
            parts.append(raw)
        u8 = np.frombuffer(b''.join(parts), np.uint8)
        base = np.arange(pages.size, dtype=np.int64) * self.page_size
        if (u8[base] != 0x0D).any():
            raise _NotPlain('a leaf is not a table leaf page')
        return u8, base

    def _leaves(self) -> np.ndarray:
        """Page numbers of the table's leaf pages in key order (all at one depth)."""
        level = np.array([self.root], np.int64)
        for _ in range(20):
            kind = self._page(int(level[0]))[0]
            if kind == 0x0D:
                return level
            if kind != 0x05 or level.size > self.n_pages:
                raise _NotPlain('not a table B-tree')
            children = [self._children(int(page)) for page in level.tolist()]
            level = np.concatenate(children)
        raise _NotPlain('B-tree deeper than any real file')

    def _children(self, page: int) -> np.ndarray:
        """Child page numbers of one interior table page, in key order."""
        u8 = self._page(page)
        if u8[0] != 0x05:
            raise _NotPlain(f'page {page} is not an interior table page')
        n_cells = int(u8[3]) << 8 | int(u8[4])
        ptr = 12 + 2 * np.arange(n_cells)
        cells = (u8[ptr].astype(np.int64) << 8) | u8[ptr + 1]
        if n_cells and (cells.max() + 4 > self.page_size or cells.min() < 12):
            raise _NotPlain('cell pointer outside its page')
        children = np.zeros(n_cells + 1, np.int64)
        for i in range(4):
            children[:n_cells] = (children[:n_cells] << 8) | u8[cells + i]
        children[n_cells] = int.from_bytes(bytes(u8[8:12]), 'big')
        return children

    @staticmethod
    def _leaf_cells(u8: np.ndarray, base: np.ndarray, usable: int,
                    topic_ids: list[int]) -> tuple[np.ndarray, ...]:
        """Return (data offset, data length, timestamp, rowid) of the topic's rows."""
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
        rowid, len2 = _varint(u8, cell + len1)
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
            st_time, st_data, rowid = st_time[mine], st_data[mine], rowid[mine]
        recv_ns = _serial_int(u8, time_pos, st_time)
        data = time_pos + _SERIAL_SIZE[st_time]
        length = (st_data - 12) // 2
        if (data + length != start + size).any():
            raise _NotPlain('record sizes do not add up')
        return data, length, recv_ns, rowid
