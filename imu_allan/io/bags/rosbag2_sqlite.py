"""
rosbag2 sqlite3 storage: the messages table read from its B-tree pages, or by SQL.

The schema, the counts, the read by SQL and around damaged pages live here; the fast
read of the table's pages straight from the file is :mod:`imu_allan.io.bags.sqlite_pages`.
Part of :mod:`imu_allan.io.bag_reader`.
"""

from pathlib import Path
import shutil
import sqlite3
import tempfile
from typing import Callable, Iterator
from urllib.parse import quote

import numpy as np
import yaml

from imu_allan.errors import InputError
from imu_allan.io.bags.base import _FETCH_ROWS, _make_piece, Backend, Piece, Topic
from imu_allan.io.bags.sqlite_pages import NotPlain, SqlitePages
from imu_allan.io.imu_cdr import join_payloads


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
        :class:`SqlitePages`); from the first row that path cannot vouch for (a
        write-ahead log next to the file, overflow pages of the wanted topic, an unusual
        schema, any inconsistency) on, the rest is read with SQL.
        """
        after = 0
        if self.decompress is None:
            try:
                pages = SqlitePages(self.db_path, self.conn)
                ids = self.ids[topic.name, topic.msgtype]
                for piece, last_rowid in pages.pieces(ids, topic.encoding):
                    after = last_rowid
                    yield piece
                return
            except (NotPlain, OSError):
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
