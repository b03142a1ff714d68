"""Tests of the sqlite page reader's decoding of varints and integer columns."""

import numpy as np
from numpy.testing import assert_array_equal

from imu_allan.io.bags.sqlite_pages import _serial_int, _SERIAL_SIZE, _varint


def _encode_varint(value: int) -> bytes:
    """Encode a sqlite varint (https://www.sqlite.org/fileformat2.html, section 1.6)."""
    if value >= 1 << 56:
        # Nine bytes: eight groups of 7 bits, then a whole last byte.
        head = value >> 8
        groups = [(head >> (7 * k)) & 0x7F for k in range(7, -1, -1)]
        return bytes(g | 0x80 for g in groups) + bytes([value & 0xFF])
    groups = []
    while True:
        groups.append(value & 0x7F)
        value >>= 7
        if not value:
            break
    groups.reverse()
    return bytes(g | 0x80 for g in groups[:-1]) + bytes(groups[-1:])


def test_varint_of_every_length():
    values = [0, 1, 127, 128, 300, 2 ** 14, 2 ** 21 + 5, 2 ** 35, 2 ** 40, 2 ** 56 - 1,
              2 ** 56, 2 ** 62, 2 ** 63 - 1]
    encoded = [_encode_varint(v) for v in values]
    u8 = np.frombuffer(b''.join(encoded) + bytes(9), np.uint8)
    pos = np.cumsum([0] + [len(e) for e in encoded[:-1]])
    value, length = _varint(u8, pos)
    assert_array_equal(value, values)
    assert_array_equal(length, [len(e) for e in encoded])
    assert max(length) == 9


def test_serial_int_of_every_width_and_sign():
    # Serial types 1-6 are big-endian two's complement of 1, 2, 3, 4, 6 and 8 bytes;
    # 8 and 9 are the constants 0 and 1 (no bytes).
    rng = np.random.default_rng(61)
    cases = []
    for serial, nbytes in ((1, 1), (2, 2), (3, 3), (4, 4), (5, 6), (6, 8)):
        bits = 8 * nbytes
        for v in [-(1 << (bits - 1)), -1, 0, 1, (1 << (bits - 1)) - 1,
                  int(rng.integers(-(1 << min(bits - 1, 62)), 1 << min(bits - 1, 62)))]:
            cases.append((serial, v, v.to_bytes(nbytes, 'big', signed=True)))
    cases += [(8, 0, b''), (9, 1, b'')]
    raw = b''.join(c[2] for c in cases) + bytes(8)
    u8 = np.frombuffer(raw, np.uint8)
    pos = np.cumsum([0] + [len(c[2]) for c in cases[:-1]])
    serial = np.array([c[0] for c in cases], np.int64)
    assert_array_equal(_SERIAL_SIZE[serial], [len(c[2]) for c in cases])
    assert_array_equal(_serial_int(u8, pos, serial), [c[1] for c in cases])
    # One width throughout takes the big-endian view: the same numbers.
    four = [c for c in cases if c[0] == 4]
    u8 = np.frombuffer(b''.join(c[2] for c in four), np.uint8)
    assert_array_equal(_serial_int(u8, np.arange(len(four)) * 4, np.full(len(four), 4)),
                       [c[1] for c in four])
