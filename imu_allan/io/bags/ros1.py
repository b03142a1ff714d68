"""
ROS 1 bags (format 2.0), through rosbags' reader.

Part of :mod:`imu_allan.io.bag_reader`.
"""

import heapq
from io import BytesIO
import os
from pathlib import Path
from typing import Iterator

import numpy as np

from imu_allan.errors import InputError
from imu_allan.io.bags.base import _FETCH_ROWS, _make_piece, Backend, Piece, Topic
from imu_allan.io.imu_cdr import join_payloads


class _Ros1Backend(Backend):
    """ROS 1 bag (format 2.0) through rosbags' reader; payloads decoded in batches."""

    storage = 'ros1'

    def __init__(self, path: Path, warnings: list[str]) -> None:
        super().__init__(path, warnings)
        from rosbags.rosbag1 import Reader

        try:
            self.reader = Reader(path)
            self.reader.open()
        except Exception as err:   # noqa: B902 - rosbags raises AssertionError, KeyError ...
            text = str(err).splitlines()[0] if str(err) else type(err).__name__
            raise InputError(f'{path}: unreadable ROS 1 bag ({text}); a bag cut short needs '
                             '`rosbag reindex`') from None

    def topics(self) -> list[Topic]:
        """Return one entry per topic and type, with ROS 1 type names (sensor_msgs/Imu)."""
        found: dict[tuple[str, str], Topic] = {}
        for conn in self.reader.connections:
            msgtype = conn.msgtype.replace('/msg/', '/')
            old = found.get((conn.topic, msgtype))
            if old is not None:
                found[conn.topic, msgtype] = old._replace(
                    n_messages=(old.n_messages or 0) + conn.msgcount)
            else:
                found[conn.topic, msgtype] = Topic(conn.topic, msgtype, conn.msgcount, 'ros1')
        return list(found.values())

    def pieces(self, topic: Topic) -> Iterator[Piece]:
        """
        Yield the topic's messages in time order, decoded in batches.

        The index is walked as rosbags' ``Reader.messages`` walks it, but a chunk that
        fails (does not decompress, holds no message record where the index points) is
        skipped with its remaining messages, and the read goes on with the next chunk.
        Relied on, all public attributes of rosbags' rosbag1 ``Reader``: ``indexes``
        (connection id -> time-sorted entries with ``time``, ``chunk_pos``, ``offset``),
        ``chunks`` (chunk_pos -> ``datapos``, ``datasize``, ``decompressor``) and ``bio``
        (the open file); records are parsed with the module's ``Header``, ``RecordType``,
        ``read_uint32`` and ``read_bytes``.
        """
        from rosbags.rosbag1.reader import Header, read_bytes, read_uint32, RecordType

        reader = self.reader
        bio = reader.bio
        assert bio is not None   # opened in __init__
        conn_ids = {c.id for c in reader.connections if c.topic == topic.name
                    and c.msgtype.replace('/msg/', '/') == topic.msgtype}
        indexes = [reader.indexes[conn_id] for conn_id in sorted(conn_ids)]
        damaged: dict[int, str] = {}    # chunk_pos -> first line of its error
        n_skipped = 0
        chunk_pos, chunk = -1, BytesIO()
        recv: list[int] = []
        payloads: list[bytes] = []
        for entry in heapq.merge(*indexes):
            if entry.chunk_pos in damaged:
                n_skipped += 1
                continue
            try:
                if entry.chunk_pos != chunk_pos:
                    info = reader.chunks[entry.chunk_pos]
                    bio.seek(info.datapos)
                    chunk_pos, chunk = entry.chunk_pos, BytesIO(
                        info.decompressor(read_bytes(bio, info.datasize)))
                chunk.seek(entry.offset)
                header = Header.read(chunk)
                while header.get_uint8('op') == RecordType.CONNECTION:
                    chunk.seek(read_uint32(chunk), os.SEEK_CUR)
                    header = Header.read(chunk)
                if (header.get_uint8('op') != RecordType.MSGDATA or header.get_time('time')
                        != entry.time or header.get_uint32('conn') not in conn_ids):
                    raise ValueError('no message record of the topic where the index points')
                payloads.append(read_bytes(chunk, read_uint32(chunk)))
            except Exception as err:   # noqa: B902 - bz2, lz4, rosbags raise their own
                text = str(err).strip()
                damaged[entry.chunk_pos] = text.splitlines()[0] if text else type(err).__name__
                n_skipped += 1
                continue
            recv.append(entry.time)
            if len(payloads) >= _FETCH_ROWS:
                yield _make_piece(*join_payloads(payloads), np.array(recv, np.int64), 'ros1', None)
                recv, payloads = [], []
        if payloads:
            yield _make_piece(*join_payloads(payloads), np.array(recv, np.int64), 'ros1', None)
        if damaged:
            self.warnings.append(
                f'{self.path}: {len(damaged)} damaged chunk(s) in the ROS 1 bag skipped '
                f'({next(iter(damaged.values()))}); {n_skipped} messages of {topic.name} '
                'in them not read')

    def close(self) -> None:
        """Close the bag."""
        self.reader.close()
