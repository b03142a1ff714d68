"""
Read sensor_msgs/Imu from bags fast: rosbag2 (sqlite3 or MCAP), single files, ROS 1.

Inputs: a rosbag2 directory (metadata.yaml of any version, or none: the storage
files are read directly), a single ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag``.
Time comes from ``header.stamp`` (docs/contracts.md); the bag's receive time is kept too.

Speed: decoding one message at a time in Python would take minutes for a long
recording (docs/benchmarks.md).  Here raw serialised payloads are
located in bulk (sqlite: the messages table's B-tree pages parsed straight from the
file, with SQL in rowid order from the first row that path cannot vouch for; MCAP:
whole chunks, CRC-checked, walked record by record) and decoded with numpy structured
dtypes, one call per group of messages.  Files are read with
plain reads, never mapped, so a file that shrinks while it is read cannot crash the
process.  Whatever is lost (damaged chunks or pages, undecodable payloads) is counted
against the bag's own count and warned about (``ImuSource.n_lost``); messages come in
header-stamp order even where chunks overlap in time.

The layout of a ROS 2 CDR sensor_msgs/msg/Imu: 4-byte encapsulation header,
``stamp.sec`` int32, ``stamp.nanosec`` uint32, ``frame_id`` (uint32 length including
the NUL, bytes), padding to 8 bytes (counted after the encapsulation header), then 37
doubles: orientation 4,
orientation_covariance 9, angular_velocity 3, its covariance 9,
linear_acceleration 3, its covariance 9.  ROS 1 is packed little-endian:
``seq``, ``secs``, ``nsecs`` uint32, ``frame_id`` (uint32 length, bytes), doubles.
A payload must end with its last double (CDR: up to 3 bytes of padding).  Big-endian
CDR is decoded too; any payload that fits neither layout goes through rosbags' own
deserialiser (default Jazzy / Noetic type stores), or is skipped with
a warning.
"""

from pathlib import Path
from typing import Iterator

import numpy as np

from imu_allan.errors import InputError
from imu_allan.io.bags.base import (Backend, DEFAULT_BLOCK_SIZE, ImuBlock, PathLike, Piece,
                                    Topic, TopicInfo)
from imu_allan.io.bags.rosbag2_dir import open_backend
from imu_allan.io.imu_cdr import IMU_MSGTYPES

#: Topics named in an error message before 'and N more'.
_MAX_LISTED = 8
__all__ = ['DEFAULT_BLOCK_SIZE', 'ImuBlock', 'ImuSource', 'list_imu_topics', 'list_topics',
           'open_imu', 'TopicInfo']


def _is_imu(topic: Topic) -> bool:
    return topic.msgtype in IMU_MSGTYPES


def _describe(topics: list[Topic]) -> str:
    """List topics for an error message: '/a (type, 10 messages), ...'."""
    parts = []
    for topic in topics[:_MAX_LISTED]:
        count = topic.n_messages
        parts.append(f'{topic.name} ({topic.msgtype}'
                     + ('' if count is None else f', {count} messages') + ')')
    if len(topics) > _MAX_LISTED:
        parts.append(f'and {len(topics) - _MAX_LISTED} more')
    return ', '.join(parts) if parts else 'none'


def list_topics(path: PathLike) -> list[TopicInfo]:
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
    backend = _guarded_open(path, [])
    try:
        return [TopicInfo(t.name, t.msgtype, backend.count(t)) for t in backend.topics()]
    finally:
        backend.close()


def list_imu_topics(path: PathLike) -> list[TopicInfo]:
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
    backend = _guarded_open(path, [])
    try:
        return [TopicInfo(t.name, t.msgtype, backend.count(t))
                for t in backend.topics() if _is_imu(t)]
    finally:
        backend.close()


# Long because it is one reading of one IMU: its blocks, counts, source choice and the
# warnings they give, so no count is made twice.
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
    n_read : int
        Messages delivered (complete once ``blocks()`` has been consumed).
    n_lost : int or None
        Messages the bag counts that were not delivered (damaged, undecodable);
        None when the bag states no count and damage was met.
    frame_id : str
        header.frame_id of the messages read: the one asked for, else the topic's only
        one ('' before any).
    frame_counts : dict of str to int
        Messages of the topic per header.frame_id (complete once ``blocks()`` has been
        consumed); a topic may carry several IMUs, and one is read.
    n_no_orientation : int
        Messages delivered whose orientation_covariance[0] is -1: they carry no
        orientation (complete once ``blocks()`` has been consumed).

    """

    def __init__(self, path: Path, backend: Backend, topic: Topic,
                 warnings: list[str], frame_id: str | None = None) -> None:
        self.path = path
        self.frame_counts: dict[str, int] = {}
        self._wanted = frame_id
        self.topic = topic.name
        self.msgtype = topic.msgtype
        self.n_messages = topic.n_messages
        self.storage = backend.storage
        self.warnings = warnings
        self.frame_id = ''
        self.n_read = 0
        self.n_lost: int | None = None
        self.n_no_orientation = 0
        self._backend = backend
        self._topic = topic
        self._counts = [0, 0, 0, 0]

    def _warn(self, text: str) -> None:
        if text not in self.warnings:
            self.warnings.append(text)

    def blocks(self, block_size: int = DEFAULT_BLOCK_SIZE) -> Iterator[ImuBlock]:
        """
        Yield the messages in blocks of ``block_size`` (the last one may be shorter).

        Messages come in header-stamp order: overlapping chunks, and log times that
        jitter against the stamps, are merged (see :func:`_in_stamp_order`).  Afterwards
        ``n_read`` holds the messages delivered and ``n_lost`` the messages the bag
        counts but that could not be read (None when the bag states no count).

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
        pending: list[Piece] = []
        n_pending = 0
        self._counts = [0, 0, 0, 0]   # good, undecodable, zero stamps, no orientation
        self.frame_counts = {}
        for piece in _in_stamp_order(self._guarded()):
            pending.append(piece)
            n_pending += piece.recv_ns.size
            while n_pending >= block_size:
                block, rest = _split(pending, block_size)
                pending = [rest] if rest is not None else []
                n_pending -= block_size
                yield block
        if n_pending:
            yield _split(pending, n_pending)[0]
        self._account()

    def _guarded(self) -> Iterator[Piece]:
        """Yield the backend's pieces, counted; a library failure ends the read with a warning."""
        mixed = False
        try:
            for piece in self._backend.pieces(self._topic):
                self._counts[1] += piece.n_bad
                piece = self._one_source(piece)
                mixed = mixed or (self._wanted is None and len(self.frame_counts) > 1)
                if mixed or not piece.recv_ns.size:
                    continue    # several IMUs and none chosen: only counted, for the error
                self._counts[0] += piece.recv_ns.size
                self._counts[2] += int(np.count_nonzero(piece.stamp_ns == 0))
                if piece.unoriented is not None:
                    self._counts[3] += int(np.count_nonzero(piece.unoriented))
                yield piece
        except InputError:
            raise
        except Exception as err:   # noqa: B902 - any library failure: keep what was read
            text = str(err).splitlines()[0] if str(err) else ''
            self._warn(f'{self.path}: reading stopped ({type(err).__name__}: {text}) after '
                       f'{self._counts[0]} messages of {self.topic}')
        if mixed:
            raise InputError(f'{self.path}: {self.topic} carries {len(self.frame_counts)} IMUs '
                             f'(header.frame_id): {self._sources()}; choose one with '
                             '--frame-id NAME')

    def _one_source(self, piece: Piece) -> Piece:
        """
        Count a piece's messages per frame_id; keep those of the IMU read.

        Two IMUs on one topic are two sources: merged, their samples would make one
        IMU of twice the rate and a mixture of both noises.  The IMU read is the one
        asked for, else the first seen (the read stops at a second one).
        """
        if not piece.frames:
            return piece
        if piece.frame is None:
            sizes = [piece.recv_ns.size]
        else:
            sizes = np.bincount(piece.frame, minlength=len(piece.frames)).tolist()
        for name, size in zip(piece.frames, sizes):
            self.frame_counts[name] = self.frame_counts.get(name, 0) + size
        if self._wanted is None and not self.frame_id:
            self.frame_id = piece.frames[0]
        keep = self.frame_id if self._wanted is None else self._wanted
        if piece.frame is None:
            return piece if piece.frames[0] == keep else _take(piece, slice(0, 0))
        if keep not in piece.frames:
            return _take(piece, slice(0, 0))
        return _take(piece, piece.frame == piece.frames.index(keep))

    def _sources(self) -> str:
        """List the frame_ids with their message counts: 'imu_a (12000 messages), ...'."""
        parts = [f'{name or "(empty)"} ({count} messages)'
                 for name, count in list(self.frame_counts.items())[:_MAX_LISTED]]
        if len(self.frame_counts) > _MAX_LISTED:
            parts.append(f'and {len(self.frame_counts) - _MAX_LISTED} more')
        return ', '.join(parts)

    def _account(self) -> None:
        """Compare what was read with the bag's count; warn with the count lost."""
        n_good, n_bad, n_zero, self.n_no_orientation = self._counts
        self.n_read = n_good
        if self._wanted is not None:
            self.frame_id = self._wanted
            others = {name: k for name, k in self.frame_counts.items() if name != self._wanted}
            if not n_good and others:
                raise InputError(f'{self.path}: no message of {self.topic} has frame_id '
                                 f'{self._wanted!r}; it carries {self._sources()}')
            if others:
                self._warn(f'{sum(others.values())} messages of other IMUs on {self.topic} '
                           f'skipped (frame_id {self._wanted!r} read; others: '
                           + ', '.join(f'{name or "(empty)"} ({k})' for name, k in others.items())
                           + ')')
        # Messages of another IMU were read, only not delivered: they are not lost.
        n_other = sum(self.frame_counts.values()) - n_good
        try:
            expected = self._backend.count(self._topic)
        except InputError:
            expected = self.n_messages
        if expected is None:
            self.n_lost = n_bad if n_bad or not self._damaged() else None
        else:
            self.n_lost = max(expected - n_good - n_other, 0)
        if n_bad:
            self._warn(f'{n_bad} messages on {self.topic} are not decodable sensor_msgs/Imu '
                       'and were skipped')
        if self.n_lost and expected is not None:
            self._warn(f'{self.n_lost} of {expected} messages on {self.topic} lost '
                       f'({n_good} read)')
        if n_zero:
            self._warn(f'header.stamp is 0 in {n_zero} of {n_good} messages on {self.topic}: '
                       'the publisher does not fill the header; only recv_ns carries time')
        if not n_good:
            self._warn(f'no readable messages on {self.topic} in {self.path}')

    def _damaged(self) -> bool:
        return any(w.startswith(str(self.path)) for w in self.warnings)

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


#: Messages held back for ordering at most; beyond, the oldest go on unmerged.
_MAX_HELD = 1 << 20


def _in_stamp_order(pieces: Iterator[Piece]) -> Iterator[Piece]:
    """
    Yield the messages of consecutive pieces in header-stamp order.

    Each piece is sorted by stamp (stable); messages are held back until a later
    piece's first stamp passes them, so pieces that overlap in time (overlapping MCAP
    chunks, log times that jitter against the stamps) merge without loss.  At most
    ``_MAX_HELD`` messages wait: an isolated far-future stamp cannot hold the rest.
    """
    held: Piece | None = None
    for piece in pieces:
        piece = _sorted(piece)
        if held is None:
            held = piece
            continue
        cut = int(np.searchsorted(held.stamp_ns, piece.stamp_ns[0], 'right'))
        cut = max(cut, held.recv_ns.size + piece.recv_ns.size - _MAX_HELD)
        cut = min(cut, held.recv_ns.size)
        if cut:
            yield _take(held, slice(0, cut))
        rest = _take(held, slice(cut, None))
        held = piece if not rest.recv_ns.size else _sorted(_concat([rest, piece]))
    if held is not None:
        yield held


def _sorted(piece: Piece) -> Piece:
    if piece.stamp_ns.size < 2 or (np.diff(piece.stamp_ns) >= 0).all():
        return piece
    return _take(piece, np.argsort(piece.stamp_ns, kind='stable'))


def _take(piece: Piece, index) -> Piece:
    unoriented = None if piece.unoriented is None else piece.unoriented[index]
    return Piece(piece.recv_ns[index], piece.stamp_ns[index], piece.samples[index], 0,
                 unoriented=unoriented)


def _concat(pieces: list[Piece]) -> Piece:
    return Piece(np.concatenate([p.recv_ns for p in pieces]),
                 np.concatenate([p.stamp_ns for p in pieces]),
                 np.concatenate([p.samples for p in pieces]), 0)


def _split(pieces: list[Piece], n: int) -> tuple[ImuBlock, Piece | None]:
    """Concatenate pieces and cut the first n messages off as a block."""
    joined = pieces[0] if len(pieces) == 1 else _concat(pieces)
    block = ImuBlock(joined.stamp_ns[:n], joined.recv_ns[:n], joined.samples[:n])
    if joined.recv_ns.size == n:
        return block, None
    return block, Piece(joined.recv_ns[n:], joined.stamp_ns[n:], joined.samples[n:], 0)


def open_imu(path: PathLike, topic: str | None = None,
             frame_id: str | None = None) -> ImuSource:
    """
    Open the sensor_msgs/Imu topic of a bag for reading.

    Parameters
    ----------
    path : str or os.PathLike
        rosbag2 directory (sqlite3 or MCAP; metadata.yaml optional), a single ``.mcap`` or
        ``.db3`` file, or a ROS 1 ``.bag``.
    topic : str, optional
        Topic to read; by default the only Imu topic of the bag.
    frame_id : str, optional
        The IMU to read when the topic carries several (told apart by
        header.frame_id); by default the topic must carry one only.

    Returns
    -------
    ImuSource
        Reader of that topic (close it, or use it as a context manager).

    Raises
    ------
    InputError
        If the bag is missing, unreadable or empty, has no Imu topic, several Imu topics
        and no ``topic``, or ``topic`` is missing or not of type Imu.  Several
        frame_ids on the topic and no ``frame_id`` (or one it does not carry) are an
        InputError of ``blocks()``, raised once the messages are counted.

    """
    warnings: list[str] = []
    backend = _guarded_open(path, warnings)
    try:
        chosen = _choose_topic(Path(path), backend, topic)
        _warn_other_types(Path(path), backend, chosen, warnings)
    except BaseException:
        backend.close()
        raise
    return ImuSource(Path(path), backend, chosen, warnings, frame_id)


def _warn_other_types(path: Path, backend: Backend, chosen: Topic,
                      warnings: list[str]) -> None:
    """Name the messages of other types on the chosen topic, which are not read."""
    for other in backend.topics():
        if other.name == chosen.name and other.msgtype != chosen.msgtype:
            count = backend.count(other)
            warnings.append(f'{path}: {"" if count is None else f"{count} "}messages of type '
                            f'{other.msgtype or "(untyped)"} on {chosen.name} skipped (only '
                            f'{chosen.msgtype} is read)')


def _guarded_open(path: PathLike, warnings: list[str]) -> Backend:
    """Open a bag; any library failure becomes a one-line InputError."""
    try:
        return open_backend(path, warnings)
    except (InputError, MemoryError, KeyboardInterrupt):
        raise
    except Exception as err:   # noqa: B902 - a damaged file can make any library raise
        text = str(err).strip().splitlines()[0] if str(err).strip() else ''
        raise InputError(f'{path}: unreadable bag ({type(err).__name__}: {text})') from None


def _choose_topic(path: Path, backend: Backend, name: str | None) -> Topic:
    topics = backend.topics()
    if not topics:
        raise InputError(f'{path}: empty bag (no topics)')
    imu = [t for t in topics if _is_imu(t)]
    if name is not None:
        wanted = name if name.startswith('/') else '/' + name
        named = [t for t in topics if t.name in (name, wanted)]
        # Other message types may share the name: the Imu one is the topic.
        match = next((t for t in named if _is_imu(t)), named[0] if named else None)
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
    if chosen.n_messages == 0 and backend.count(chosen) == 0:
        total = sum(t.n_messages or 0 for t in topics)
        raise InputError(f'{path}: topic {chosen.name} has no messages'
                         + (' (empty bag)' if not total else ''))
    return chosen
