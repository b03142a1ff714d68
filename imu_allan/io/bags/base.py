"""
What every storage reader shares: block and topic types, the decoded-piece builder.

Part of :mod:`imu_allan.io.bag_reader` (see its docstring for the layouts and speed).
"""

import os
from pathlib import Path
from typing import Callable, Iterator, NamedTuple

import numpy as np

from imu_allan.io.imu_cdr import (decode_imu_payloads, join_payloads, orientation_unknown,
                                  payload_frames)

#: Messages per ImuBlock unless asked otherwise.
DEFAULT_BLOCK_SIZE = 65536

_FETCH_ROWS = 32768
#: The first bytes of an MCAP file (its magic).
MCAP_MAGIC = b'\x89MCAP0\r\n'

PathLike = str | os.PathLike


class TopicInfo(NamedTuple):
    """One topic of a bag: name, message type, message count (None when unknown)."""

    topic: str
    msgtype: str
    n_messages: int | None


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


class Topic(NamedTuple):
    """Internal topic record; encoding is 'cdr', 'ros1' or what the bag names."""

    name: str
    msgtype: str
    n_messages: int | None
    encoding: str


class Piece(NamedTuple):
    """
    Decoded messages of one fetch or chunk, plus how many were dropped.

    ``frames`` are the header.frame_ids met (in order of first appearance) and
    ``frame`` the (n,) int64 position of each message's in it, None when all have
    ``frames[0]`` (pieces cut from one source carry neither).
    """

    recv_ns: np.ndarray
    stamp_ns: np.ndarray
    samples: np.ndarray
    n_bad: int
    frames: tuple[str, ...] = ()
    frame: np.ndarray | None = None
    #: (n,) bool, True where orientation_covariance[0] = -1 (no orientation, REP 145);
    #: None where not read.
    unoriented: np.ndarray | None = None


# --------------------------------------------------------------------------------------
# Vectorised decoding
# --------------------------------------------------------------------------------------


#: Header of an MCAP Message record: opcode, record length, channel id, log_time.
def _make_piece(u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray, recv_ns: np.ndarray,
                encoding: str, decompress: Callable[[bytes], bytes] | None) -> Piece:
    """Decode payloads into a Piece, dropping undecodable ones."""
    if decompress is not None:
        # rosbag2 'message' compression: every payload is its own zstd frame.
        # A frame that does not decompress becomes an empty, undecodable payload.
        payloads = [_safely(decompress, u8[s:s + n].tobytes())
                    for s, n in zip(starts.tolist(), lengths.tolist())]
        u8, starts, lengths = join_payloads(payloads)
    stamp_ns, samples, ok = decode_imu_payloads(u8, starts, lengths, encoding)
    n_bad = int(ok.size - np.count_nonzero(ok))
    unoriented = orientation_unknown(u8, starts, lengths, encoding)
    if n_bad:
        good = np.flatnonzero(ok)
        names, frame = payload_frames(u8, starts[good], lengths[good], encoding)
        return Piece(recv_ns[ok], stamp_ns[ok], samples[ok], n_bad, tuple(names), frame,
                     unoriented[ok])
    names, frame = payload_frames(u8, starts, lengths, encoding)
    return Piece(recv_ns, stamp_ns, samples, 0, tuple(names), frame, unoriented)


def _safely(decompress: Callable[[bytes], bytes], data: bytes) -> bytes:
    try:
        return decompress(data)
    except Exception:   # noqa: B902 - zstd and friends raise their own error types
        return b''


class Backend:
    """Common interface of the storage readers."""

    storage = ''

    def __init__(self, path: Path, warnings: list[str],
                 decompress: Callable[[bytes], bytes] | None = None) -> None:
        self.path = path
        self.warnings = warnings
        self.decompress = decompress  # per-message decompression of rosbag2, or None

    def topics(self) -> list[Topic]:
        """Return every topic with its type, count (or None) and encoding."""
        raise NotImplementedError

    def count(self, topic: Topic) -> int | None:
        """Return the number of messages of a topic (may read the bag; None: unknown)."""
        return topic.n_messages

    def pieces(self, topic: Topic) -> Iterator[Piece]:
        """Yield decoded Imu messages of a topic in the bag's order."""
        raise NotImplementedError

    def extent(self) -> tuple[int | None, int | None, int | None]:
        """
        Return the file's first and last receive time [ns] and its message count.

        All topics together; each is None where the storage cannot tell without
        reading the messages.  Split bags order their files by it and recognise a file
        that repeats another.
        """
        return None, None, None

    def close(self) -> None:
        """Release files."""
