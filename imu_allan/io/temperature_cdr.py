"""
The sensor_msgs/msg/Temperature wire layout: the node's temperature, decoded without ROS.

A ROS 2 CDR Temperature is the 4-byte encapsulation header (byte 1: 0 big-endian,
1 little-endian), ``stamp.sec`` int32, ``stamp.nanosec`` uint32, ``frame_id`` (uint32
length including the NUL, bytes), padding to 8 bytes (counted after the encapsulation
header), then ``temperature`` and ``variance`` float64.  Temperature topics are slow,
so each message is decoded alone (:mod:`struct`); one that does not fit is dropped
and counted.
"""

import struct

import numpy as np


def decode_temperatures(raws: list) -> tuple[np.ndarray, np.ndarray, int]:
    """
    Decode serialized sensor_msgs/msg/Temperature messages.

    Parameters
    ----------
    raws : list of bytes
        CDR payloads, encapsulation header included.

    Returns
    -------
    stamp_ns : np.ndarray
        Shape (k,), header stamps [ns] (int64) of the decodable messages.
    temp_c : np.ndarray
        Shape (k,), their temperatures [degC].
    n_bad : int
        Payloads that are no Temperature message (dropped).

    """
    stamps, temps, bad = [], [], 0
    for raw in raws:
        found = _one(bytes(raw))
        if found is None:
            bad += 1
            continue
        stamps.append(found[0])
        temps.append(found[1])
    return np.asarray(stamps, dtype=np.int64), np.asarray(temps, dtype=np.float64), bad


def _one(raw: bytes) -> tuple[int, float] | None:
    """Return (stamp [ns], temperature [degC]) of one payload, or None."""
    if len(raw) < 4 + 12 + 16 or raw[1] not in (0, 1):
        return None
    end = '<' if raw[1] == 1 else '>'
    sec, nanosec, n = struct.unpack_from(end + 'iII', raw, 4)
    at = 4 + 12 + n
    at = 4 + ((at - 4 + 7) // 8) * 8
    if n == 0 or nanosec >= 1_000_000_000 or at + 16 > len(raw):
        return None
    temp, _variance = struct.unpack_from(end + 'dd', raw, at)
    return sec * 1_000_000_000 + nanosec, temp
