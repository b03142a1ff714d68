"""
ROS 1 bags (format 2.0), through rosbags' reader.

Part of :mod:`imu_allan.io.bag_reader`.
"""

from pathlib import Path
from typing import Iterator

import numpy as np

from imu_allan.errors import InputError
from imu_allan.io.bags.base import _Backend, _FETCH_ROWS, _make_piece, _Piece, _Topic
from imu_allan.io.imu_cdr import _join


class _Ros1Backend(_Backend):
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

    def topics(self) -> list[_Topic]:
        """Return one entry per topic, with ROS 1 type names (sensor_msgs/Imu)."""
        found: dict[str, _Topic] = {}
        for conn in self.reader.connections:
            msgtype = conn.msgtype.replace('/msg/', '/')
            if conn.topic in found:
                old = found[conn.topic]
                found[conn.topic] = old._replace(n_messages=(old.n_messages or 0) + conn.msgcount)
            else:
                found[conn.topic] = _Topic(conn.topic, msgtype, conn.msgcount, 'ros1')
        return list(found.values())

    def pieces(self, topic: _Topic) -> Iterator[_Piece]:
        """Yield the topic's messages in time order, decoded in batches."""
        conns = [c for c in self.reader.connections if c.topic == topic.name]
        recv: list[int] = []
        payloads: list[bytes] = []
        try:
            for _, stamp, raw in self.reader.messages(connections=conns):
                recv.append(stamp)
                payloads.append(raw)
                if len(payloads) >= _FETCH_ROWS:
                    yield _make_piece(*_join(payloads), np.array(recv, np.int64), 'ros1', None)
                    recv, payloads = [], []
        except Exception as err:   # noqa: B902 - rosbags raises AssertionError, KeyError ...
            text = str(err).splitlines()[0] if str(err) else type(err).__name__
            self.warnings.append(f'{self.path}: damaged ROS 1 bag ({text}); read stopped')
        if payloads:
            yield _make_piece(*_join(payloads), np.array(recv, np.int64), 'ros1', None)

    def close(self) -> None:
        """Close the bag."""
        self.reader.close()
