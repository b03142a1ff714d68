"""
rosbag2's messages table read straight from the sqlite3 file's B-tree pages.

The fast path of :mod:`imu_allan.io.bags.rosbag2_sqlite`: :class:`SqlitePages` reads
the leaf pages in batches and parses every cell at once with numpy; whatever it cannot
vouch for raises :class:`NotPlain`, and the caller reads the rest by SQL.
"""

import os
from pathlib import Path
import sqlite3
import struct
from typing import Iterator

import numpy as np

from imu_allan.io.bags.base import _make_piece, Piece
from imu_allan.io.imu_cdr import gather_bytes


class NotPlain(Exception):
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
class SqlitePages:
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
    https://www.sqlite.org/fileformat2.html).  Safety: refused (raise NotPlain, the
    caller reads the rest with SQL) for a file with a write-ahead log or hot journal,
    another table layout, wanted rows that spill to overflow pages, rowids that do not
    increase, or any page or cell that does not check out.
    """

    def __init__(self, path: Path, conn: sqlite3.Connection) -> None:
        self.path = path
        for suffix in ('-wal', '-journal'):
            side = path.with_name(path.name + suffix)
            if side.exists() and side.stat().st_size > 0:
                raise NotPlain(f'{side.name} present')
        try:
            columns = [(r[1].lower(), r[2].upper(), r[5]) for r in
                       conn.execute('PRAGMA table_info(messages)').fetchall()]
            row = conn.execute("SELECT rootpage FROM sqlite_master WHERE type = 'table' "
                               "AND name = 'messages'").fetchone()
        except sqlite3.DatabaseError as err:
            raise NotPlain(str(err)) from None
        names = [c[0] for c in columns]
        key = columns[0][1:] if columns else None
        if names != ['id', 'topic_id', 'timestamp', 'data'] or key != ('INTEGER', 1):
            raise NotPlain('not the rosbag2 messages layout')
        self.root = int(row[0])

    def pieces(self, topic_ids: list[int], encoding: str) -> Iterator[tuple[Piece, int]]:
        """Yield (decoded piece, its last rowid) per batch of leaf pages, in rowid order."""
        with open(self.path, 'rb') as f:
            self.fd = f.fileno()
            size = os.fstat(self.fd).st_size
            head = os.pread(self.fd, 100, 0)
            if size < 512 or len(head) < 100:
                raise NotPlain('shorter than one page')
            page_size = struct.unpack_from('>H', head, 16)[0]
            page_size = 65536 if page_size == 1 else page_size
            if page_size < 512 or page_size & (page_size - 1):
                raise NotPlain('bad page size')
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
                        raise NotPlain('rowids out of order')
                    if rowid.size:
                        last = int(rowid[-1])
                        yield _make_piece(u8, data, length, recv_ns, encoding, None), last
            except (IndexError, ValueError) as err:
                raise NotPlain(str(err)) from None

    def _page(self, page: int) -> np.ndarray:
        if not 2 <= page <= self.n_pages:
            raise NotPlain('page number out of range')
        raw = os.pread(self.fd, self.page_size, (page - 1) * self.page_size)
        if len(raw) < self.page_size:
            raise NotPlain('file shorter than its pages')
        return np.frombuffer(raw, np.uint8)

    def _read_pages(self, pages: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Read pages (runs of consecutive numbers at once): (bytes, offset of each page)."""
        if pages.min() < 2 or pages.max() > self.n_pages:
            raise NotPlain('page number out of range')
        breaks = np.flatnonzero(np.diff(pages) != 1) + 1
        parts = []
        for run in np.split(pages, breaks):
            n = run.size * self.page_size
            raw = os.pread(self.fd, n, (int(run[0]) - 1) * self.page_size)
            if len(raw) < n:
                raise NotPlain('file shorter than its pages')
            parts.append(raw)
        u8 = np.frombuffer(b''.join(parts), np.uint8)
        base = np.arange(pages.size, dtype=np.int64) * self.page_size
        if (u8[base] != 0x0D).any():
            raise NotPlain('a leaf is not a table leaf page')
        return u8, base

    def _leaves(self) -> np.ndarray:
        """Page numbers of the table's leaf pages in key order (all at one depth)."""
        level = np.array([self.root], np.int64)
        for _ in range(20):
            kind = self._page(int(level[0]))[0]
            if kind == 0x0D:
                return level
            if kind != 0x05 or level.size > self.n_pages:
                raise NotPlain('not a table B-tree')
            children = [self._children(int(page)) for page in level.tolist()]
            level = np.concatenate(children)
        raise NotPlain('B-tree deeper than any real file')

    def _children(self, page: int) -> np.ndarray:
        """Child page numbers of one interior table page, in key order."""
        u8 = self._page(page)
        if u8[0] != 0x05:
            raise NotPlain(f'page {page} is not an interior table page')
        n_cells = int(u8[3]) << 8 | int(u8[4])
        ptr = 12 + 2 * np.arange(n_cells)
        cells = (u8[ptr].astype(np.int64) << 8) | u8[ptr + 1]
        if n_cells and (cells.max() + 4 > self.page_size or cells.min() < 12):
            raise NotPlain('cell pointer outside its page')
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
            raise NotPlain('cell outside its page')
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
            raise NotPlain('record header shorter than four columns')
        st_id, st_topic, st_time, st_data = serials
        bad_int = (st_topic > 9) | (st_time > 9) | (st_topic == 7) | (st_time == 7)
        if ((st_id != 0) | bad_int | (st_data < 12) | (st_data % 2 == 1)).any():
            raise NotPlain('unexpected column types')
        body = start + header_len
        topic = _serial_int(u8, body, st_topic)
        time_pos = body + _SERIAL_SIZE[st_topic]
        mine = topic == topic_ids[0] if len(topic_ids) == 1 else np.isin(topic, topic_ids)
        # A payload is stored inline (no overflow page) when size <= usable - 35.
        if (size[mine] > usable - 35).any():
            raise NotPlain('messages of the topic spill to overflow pages')
        if not mine.all():
            size, start, time_pos = size[mine], start[mine], time_pos[mine]
            st_time, st_data, rowid = st_time[mine], st_data[mine], rowid[mine]
        recv_ns = _serial_int(u8, time_pos, st_time)
        data = time_pos + _SERIAL_SIZE[st_time]
        length = (st_data - 12) // 2
        if (data + length != start + size).any():
            raise NotPlain('record sizes do not add up')
        return data, length, recv_ns, rowid
