"""
MCAP record layout and the walk over the records of one decompressed chunk.

Part of :mod:`imu_allan.io.bag_reader` (MCAP specification, https://mcap.dev/spec).
"""

import struct
from typing import Callable

import numpy as np

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL = 0x01, 0x02, 0x03, 0x04
_OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX, _OP_DATA_END = 0x05, 0x06, 0x07, 0x0F
_MCAP_MESSAGE = np.dtype({'names': ['op', 'length', 'channel', 'log_time'],
                          'formats': ['u1', '<u8', '<u2', '<u8'], 'offsets': [0, 1, 9, 15],
                          'itemsize': 31})


def walk(raw: bytes, on_record: Callable[[int, bytes, int], None]) -> np.ndarray:
    """
    Return (k,) int64 offsets of the Message records in decompressed chunk data.

    Runs of equally long messages (one topic recorded alone) are stepped over with
    one vectorised check instead of one Python iteration per record.  Schema and
    Channel records met on the way go to ``on_record(opcode, raw, body offset)``.
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
                on_record(op, raw, pos + 9)
            pos += stride
            continue
        # Check growing windows of the records that would follow at this stride (a
        # strided view, no copy): long runs cost a few numpy calls, short ones
        # (interleaved topics) only a small window.
        run, k, window = 1, (end - pos) // stride, 64
        while length >= 22 and run < k:
            n = min(k, run + window) - run
            heads = np.ndarray((n,), _MCAP_MESSAGE, buffer=u8, offset=pos + stride * run,
                               strides=(stride,))
            same = (heads['op'] == _OP_MESSAGE) & (heads['length'] == length)
            if not same.all():
                run += int(np.argmin(same))
                break
            run += n
            window *= 16
        runs.append(pos + stride * np.arange(run, dtype=np.int64))
        pos += stride * run
    return np.concatenate(runs) if runs else np.zeros(0, np.int64)
