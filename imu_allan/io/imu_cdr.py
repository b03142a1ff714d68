"""
The sensor_msgs/Imu wire layout, once: numpy-only decoding.

ROS 2 messages are CDR (4 encapsulation bytes, then ``header.stamp`` sec int32 and
nanosec uint32, ``frame_id`` as uint32 length and bytes, padding to 8, then 37
doubles: orientation (4), its covariance (9), angular_velocity (3), its covariance
(9), linear_acceleration (3), its covariance (9)).  ROS 1 messages carry ``seq``,
``secs``, ``nsecs`` uint32, ``frame_id`` (uint32 length, bytes), then the doubles.
Used by the node (which needs nothing of the bag libraries), the bag readers and the
tests.  Only payloads that fit neither layout go through rosbags' own deserialiser,
imported on demand.  The node's relay writes covariances into these bytes with
:mod:`imu_allan.io.imu_patch`.
"""

import functools
from typing import Any

import numpy as np

from imu_allan.errors import InputError

#: Message type name of sensor_msgs/Imu in ROS 2, and the names it has in ROS 2 and ROS 1.
IMU_MSGTYPE = 'sensor_msgs/msg/Imu'
IMU_MSGTYPES = (IMU_MSGTYPE, 'sensor_msgs/Imu')


_N_DOUBLES_BYTES = 37 * 8


#: Leading fields of a serialised Imu message (CDR: encapsulation bytes; both: frame_id
#: length, read in either byte order).
_HEAD = np.dtype({'names': ['enc0', 'enc1', 'frame_len_le', 'frame_len_be'],
                  'formats': ['u1', 'u1', '<u4', '>u4'], 'offsets': [0, 1, 12, 12],
                  'itemsize': 16})


def read_records(u8: np.ndarray, starts: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """
    Read one structured record at each offset of a byte buffer.

    Parameters
    ----------
    u8 : numpy.ndarray
        (size,) uint8 buffer; every ``starts + dtype.itemsize`` must fit in it.
    starts : numpy.ndarray
        (n,) int64 byte offsets.
    dtype : numpy.dtype
        Record layout.

    Returns
    -------
    numpy.ndarray
        (n,) records: a zero-copy strided view when the offsets are equally spaced
        (messages of one length back to back), otherwise a gathered copy.

    """
    n = starts.size
    if n == 1 or (n > 1 and starts[1] - starts[0] >= dtype.itemsize
                  and (np.diff(starts) == starts[1] - starts[0]).all()):
        step = int(starts[1] - starts[0]) if n > 1 else dtype.itemsize
        return np.ndarray((n,), dtype, buffer=u8, offset=int(starts[0]), strides=(step,))
    return gather_bytes(u8, starts, dtype.itemsize).view(dtype).reshape(n)


def gather_bytes(u8: np.ndarray, starts: np.ndarray, nbytes: int) -> np.ndarray:
    """
    Copy ``nbytes`` bytes at each offset of a byte buffer into an (n, nbytes) array.

    A void-typed view with a one-byte stride makes every offset one item, so numpy
    copies whole runs instead of indexing byte by byte (several times faster).
    """
    if u8.size < nbytes:
        return u8[np.asarray(starts)[:, None] + np.arange(nbytes)]   # IndexError, as numpy
    items = np.ndarray((u8.size - nbytes + 1,), np.dtype((np.void, nbytes)), buffer=u8,
                       offset=0, strides=(1,))
    return items[starts].view(np.uint8).reshape(-1, nbytes)


def _fields_dtype(doubles_offset: int, big: bool, ros1: bool, itemsize: int,
                  packed: bool) -> np.dtype:
    """
    Return the dtype of the decoded fields of one Imu message.

    Parameters
    ----------
    doubles_offset : int
        Offset of orientation.x inside the payload [bytes].
    big : bool
        Big-endian CDR.
    ros1 : bool
        ROS 1 (unsigned seconds).
    itemsize : int
        Record size [bytes] (the payload length for strided views).
    packed : bool
        Layout of the 56 gathered bytes (stamp, angular_velocity, linear_acceleration)
        instead of the payload itself.

    Returns
    -------
    numpy.dtype
        Fields sec, nanosec, angular_velocity (3,), linear_acceleration (3,).

    """
    e = '>' if big else '<'
    offsets = [0, 4, 8, 32] if packed else [4, 8, doubles_offset + 104, doubles_offset + 200]
    return np.dtype({'names': ['sec', 'nanosec', 'angular_velocity', 'linear_acceleration'],
                     'formats': [e + ('u4' if ros1 else 'i4'), e + 'u4', (e + 'f8', (3,)),
                                 (e + 'f8', (3,))],
                     'offsets': offsets, 'itemsize': itemsize})


@functools.lru_cache(maxsize=2)
def _typestore(ros1: bool) -> Any:
    """Return rosbags' type store, built once (building it is slow)."""
    from rosbags.typesys import get_typestore, Stores

    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_JAZZY)


def _fallback_decode(payload: bytes, ros1: bool) -> tuple[int, list] | None:
    """Decode one odd payload with rosbags; return (stamp_ns, six values) or None."""
    msg: Any
    if len(payload) < _N_DOUBLES_BYTES + 12:
        return None     # shorter than any Imu message: not worth asking rosbags
    try:
        # Inside the try: a robot without rosbags has no fallback, not a lost batch.
        if ros1:
            msg = _typestore(True).deserialize_ros1(payload, IMU_MSGTYPES[0])
        else:
            msg = _typestore(False).deserialize_cdr(payload, IMU_MSGTYPES[0])
        av, la = msg.angular_velocity, msg.linear_acceleration
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        return stamp, [av.x, av.y, av.z, la.x, la.y, la.z]
    except Exception:   # noqa: B902 - any failure means: not a decodable Imu payload
        return None


def _imu_layout(u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray,
                ros1: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Where the doubles of each serialised Imu message start, and in which byte order.

    Returns (n,) int64 offset of orientation.x from the payload start [bytes], (n,)
    bool big-endian, and (n,) bool "this plain layout fits the payload".
    """
    n = starts.size
    has_head = (lengths >= 16) & (starts + 16 <= u8.size)
    if has_head.all():
        head = read_records(u8, starts, _HEAD)
    elif has_head.any():
        # Short payloads read a stand-in head; they are never marked as fitting below.
        head = read_records(u8, np.where(has_head, starts, starts[has_head][0]), _HEAD)
    else:
        head = np.zeros(n, _HEAD)
    frame_len = head['frame_len_le'].astype(np.int64)
    if ros1:
        big = np.zeros(n, bool)
        known = has_head
        doubles_offset = 16 + frame_len
    else:
        # Encapsulation 0x0000 = CDR big-endian, 0x0001 = CDR little-endian.
        big = head['enc1'] == 0
        known = has_head & (head['enc0'] == 0) & (head['enc1'] <= 1)
        if big.any():
            frame_len = np.where(big, head['frame_len_be'], frame_len)
        known &= frame_len >= 1   # a CDR string always carries its NUL
        # The doubles are 8-aligned relative to the end of the 4-byte encapsulation header.
        doubles_offset = 4 + (12 + frame_len + 7) // 8 * 8
    fits = known & (frame_len < lengths) & (doubles_offset + _N_DOUBLES_BYTES <= lengths)
    return doubles_offset, big, fits


def decode_imu_payloads(u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray,
                        encoding: str = 'cdr') -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Decode many serialised sensor_msgs/Imu payloads held in one byte buffer.

    Parameters
    ----------
    u8 : numpy.ndarray
        (size,) uint8 buffer holding the payloads.
    starts : numpy.ndarray
        (n,) int64 offset of each payload in ``u8`` [bytes].
    lengths : numpy.ndarray
        (n,) int64 length of each payload [bytes].
    encoding : {'cdr', 'ros1'}
        ROS 2 CDR (with encapsulation header, either byte order) or ROS 1.

    Returns
    -------
    stamp_ns : numpy.ndarray
        (n,) int64 header.stamp [ns].
    samples : numpy.ndarray
        (n, 6) float64 angular_velocity [rad/s], linear_acceleration [m/s^2] (NaN where
        not decodable).
    ok : numpy.ndarray
        (n,) bool, False for payloads that are not a decodable Imu message.

    """
    ros1 = encoding == 'ros1'
    starts = np.asarray(starts, np.int64)
    lengths = np.asarray(lengths, np.int64)
    n = starts.size
    stamp_ns = np.zeros(n, np.int64)
    samples = np.full((n, 6), np.nan)
    ok = np.zeros(n, bool)
    if n == 0:
        return stamp_ns, samples, ok
    _decode_plain(u8, starts, lengths, ros1, stamp_ns, samples, ok)
    # The message must end with its last double: a damaged frame_id length that still
    # fits the payload would shift every value (CDR may pad to 4 bytes).
    offset, _, _ = _imu_layout(u8, starts, lengths, ros1)
    slack = lengths - offset - _N_DOUBLES_BYTES
    ok &= (slack >= 0) & (slack <= (0 if ros1 else 3))
    for i in np.flatnonzero(~ok).tolist():
        decoded = _fallback_decode(u8[starts[i]:starts[i] + lengths[i]].tobytes(), ros1)
        if decoded is not None:
            stamp_ns[i], samples[i] = decoded
            ok[i] = True
    return stamp_ns, samples, ok


def orientation_unknown(u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray,
                        encoding: str = 'cdr') -> np.ndarray:
    """
    Tell which serialised Imu messages state that they carry no orientation.

    REP 145: ``orientation_covariance[0] = -1`` means the orientation is not estimated
    (raw IMUs, most camera IMUs); robot_localization then takes roll and pitch from its
    own state (docs/outputs.md).

    Parameters
    ----------
    u8, starts, lengths, encoding
        As in :func:`decode_imu_payloads`.

    Returns
    -------
    numpy.ndarray
        (n,) bool, True where ``orientation_covariance[0] == -1``; False where it is not,
        or the payload is not in a plain layout (rosbags' fallback decodes those).

    """
    starts = np.asarray(starts, np.int64)
    lengths = np.asarray(lengths, np.int64)
    unknown = np.zeros(starts.size, bool)
    if not starts.size:
        return unknown
    offset, big, fits = _imu_layout(u8, starts, lengths, encoding == 'ros1')
    # orientation_covariance[0] follows the 4 doubles of the quaternion: byte 32.
    at = np.flatnonzero(fits)
    raw = gather_bytes(u8, starts[at] + offset[at] + 32, 8)
    value = np.where(big[at], raw.view('>f8').ravel(), raw.view('<f8').ravel())
    unknown[at] = value == -1.0
    return unknown


def _decode_plain(u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray, ros1: bool,
                  stamp_ns: np.ndarray, samples: np.ndarray, ok: np.ndarray) -> None:
    """Decode the payloads that fit the plain layout in numpy, into the given arrays."""
    doubles_offset, big, fits = _imu_layout(u8, starts, lengths, ros1)
    # One group per layout (doubles offset, byte order); nearly always a single group.
    key = np.where(fits, doubles_offset * 2 + big, -1)
    everything = bool(fits.all() and (key == key[0]).all())
    keys = [int(key[0])] if everything else np.unique(key[fits]).tolist()
    for k in keys:
        offset, is_big = k // 2, bool(k % 2)
        idx = slice(None) if everything else np.flatnonzero(key == k)
        group = starts[idx]
        steps = np.diff(group)
        if group.size > 1 and steps[0] >= offset + _N_DOUBLES_BYTES and (steps == steps[0]).all():
            # Equally spaced payloads (one length, back to back): a zero-copy strided view.
            fields = read_records(u8, group, _fields_dtype(offset, is_big, ros1,
                                                           offset + _N_DOUBLES_BYTES, False))
        else:
            # Gather only the 56 bytes needed (stamp, angular_velocity, linear_acceleration),
            # as three runs of bytes per message.
            packed = np.empty((group.size, 56), np.uint8)
            packed[:, :8] = gather_bytes(u8, group + 4, 8)
            packed[:, 8:32] = gather_bytes(u8, group + (offset + 104), 24)
            packed[:, 32:] = gather_bytes(u8, group + (offset + 200), 24)
            fields = packed.view(_fields_dtype(offset, is_big, ros1, 56, True)).ravel()
        stamp_ns[idx] = (fields['sec'].astype(np.int64) * 1_000_000_000
                         + fields['nanosec'].astype(np.int64))
        samples[idx, :3] = fields['angular_velocity']
        samples[idx, 3:] = fields['linear_acceleration']
        ok[idx] = True


def decode_imu_cdr(payloads) -> tuple[np.ndarray, np.ndarray]:
    """
    Decode a list of serialised ROS 2 sensor_msgs/msg/Imu messages (CDR) at once.

    Parameters
    ----------
    payloads : sequence of bytes
        n serialised messages, e.g. from an rclpy raw subscription.

    Returns
    -------
    stamp_ns : numpy.ndarray
        (n,) int64 header.stamp [ns].
    samples : numpy.ndarray
        (n, 6) float64 angular_velocity [rad/s], linear_acceleration [m/s^2].

    Raises
    ------
    InputError
        If any payload is not a decodable Imu message (none is returned then).

    """
    if not len(payloads):
        return np.zeros(0, np.int64), np.zeros((0, 6))
    stamp_ns, samples, ok = decode_imu_payloads(*join_payloads(payloads), 'cdr')
    if not ok.all():
        raise InputError(f'{ok.size - np.count_nonzero(ok)} of {ok.size} payloads are not '
                         'CDR sensor_msgs/msg/Imu messages')
    return stamp_ns, samples


def _cdr_doubles_offset(raw: bytes) -> tuple[int, bool] | None:
    """(offset of orientation.x, big-endian) of one plain ROS 2 CDR Imu payload, or None."""
    if len(raw) < 16 or raw[0] != 0 or raw[1] > 1:
        return None
    big = raw[1] == 0
    frame_len = int.from_bytes(raw[12:16], 'big' if big else 'little')
    offset = 4 + (12 + frame_len + 7) // 8 * 8
    if frame_len < 1 or offset + _N_DOUBLES_BYTES > len(raw):
        return None
    return offset, big


def imu_frame_id(raw: bytes) -> str | None:
    """Return header.frame_id of one serialised ROS 2 Imu message, or None if unreadable."""
    layout = _cdr_doubles_offset(raw)
    if layout is None:
        return None
    big = layout[1]
    frame_len = int.from_bytes(raw[12:16], 'big' if big else 'little')
    return raw[16:16 + frame_len - 1].decode('utf-8', errors='replace')


def payload_frames(u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray,
                   encoding: str) -> tuple[list[str], np.ndarray | None]:
    """
    Return header.frame_id of many decodable Imu payloads, as names and an index.

    One topic may carry several IMUs told apart only by their frame_id; the readers
    split by it.  The usual case, one frame_id throughout, costs one gather of the
    name's bytes and one comparison.

    Parameters
    ----------
    u8 : numpy.ndarray
        (size,) uint8 buffer holding the payloads.
    starts : numpy.ndarray
        (n,) int64 offset of each payload in ``u8`` [bytes]; payloads that
        :func:`decode_imu_payloads` accepted (at least 16 bytes each).
    lengths : numpy.ndarray
        (n,) int64 length of each payload [bytes].
    encoding : str
        'ros1' for ROS 1 payloads; anything else is read as CDR.

    Returns
    -------
    names : list of str
        The distinct frame_ids in order of first appearance ([] when n is 0).
    index : numpy.ndarray or None
        (n,) int64 position of each payload's frame_id in ``names``; None when every
        payload has ``names[0]``.

    """
    n = starts.size
    if n == 0:
        return [], None
    starts = np.asarray(starts, np.int64)
    lengths = np.asarray(lengths, np.int64)
    # The usual case: the first message's byte order, frame_id length and name bytes
    # recur in every message (one strided view and one comparison when equally spaced).
    first = int(starts[0])
    size0 = int.from_bytes(u8[first + 12:first + 16].tobytes(),
                           'big' if encoding != 'ros1' and u8[first + 1] == 0 else 'little')
    width = 4 + max(min(size0, int(lengths[0]) - 16), 0)
    if (lengths >= 12 + width).all():
        heads = read_records(u8, starts, _key_dtype(width))
        if all((heads[name] == heads[name][0]).all() for name in heads.dtype.names or ()):
            # A CDR string's length counts its NUL.
            size = max(width - 4 - (encoding != 'ros1'), 0)
            return [u8[first + 16:first + 16 + size].tobytes().decode('utf-8', 'replace')], None
    return payload_frames_slow(u8, starts, lengths, encoding)


@functools.lru_cache(maxsize=16)
def _key_dtype(width: int) -> np.dtype:
    """
    Return the fields that hold a message's byte order and frame_id (length and name).

    Byte 1 (the CDR byte order), then ``width`` bytes from byte 12 as unsigned integers
    of 8, 4, 2 and 1 bytes: compared field by field, far faster than byte strings.
    """
    names, formats, offsets = ['f1'], ['u1'], [1]
    at, end = 12, 12 + width
    for size in (8, 4, 2, 1):
        while end - at >= size:
            names.append(f'f{at}')
            formats.append(f'u{size}')
            offsets.append(at)
            at += size
    return np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                     'itemsize': end})


def payload_frames_slow(u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray,
                        encoding: str) -> tuple[list[str], np.ndarray | None]:
    """Return what :func:`payload_frames` returns, message by message (several frames)."""
    n = starts.size
    raw = gather_bytes(u8, starts + 12, 4)
    size = raw.copy().view('<u4').reshape(n).astype(np.int64)
    if encoding != 'ros1':
        # Encapsulation 0x0000 is big-endian CDR; the CDR length counts the NUL.
        big = u8[starts + 1] == 0
        if big.any():
            size = np.where(big, raw.copy().view('>u4').reshape(n).astype(np.int64), size)
        size = size - 1
    size = np.clip(size, 0, np.maximum(lengths - 16, 0))
    first = int(size[0])
    if (size == first).all():
        if first == 0:
            return [''], None
        rows = gather_bytes(u8, starts + 16, first)
        if (rows == rows[0]).all():
            return [rows[0].tobytes().decode('utf-8', errors='replace')], None
    names: dict[str, int] = {}
    index = np.empty(n, np.int64)
    for length in np.unique(size).tolist():
        at = np.flatnonzero(size == length)
        if length == 0:
            index[at] = names.setdefault('', len(names))
            continue
        rows = gather_bytes(u8, starts[at] + 16, length).view(np.dtype((np.void, length)))
        distinct, inverse = np.unique(rows.reshape(-1), return_inverse=True)
        codes = np.array([names.setdefault(bytes(d).decode('utf-8', errors='replace'),
                                           len(names)) for d in distinct], np.int64)
        index[at] = codes[inverse.reshape(-1)]
    # Names in order of first appearance, so a locked-on source is the first one seen.
    order = np.argsort(np.unique(index, return_index=True)[1])    # codes by first use
    ranked = np.empty(order.size, np.int64)
    ranked[order] = np.arange(order.size)
    by_code = list(names)
    return [by_code[k] for k in order.tolist()], ranked[index]


def join_payloads(payloads) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenate byte strings; return (buffer uint8, (n,) starts, (n,) lengths)."""
    lengths = np.fromiter(map(len, payloads), np.int64, len(payloads))
    starts = np.zeros(lengths.size, np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    return np.frombuffer(b''.join(payloads), np.uint8), starts, lengths


def imu_msgdef() -> tuple[str, str]:
    """Return (ros2msg definition text, RIHS01 hash) of sensor_msgs/msg/Imu (Jazzy)."""
    from rosbags.typesys import get_typestore, Stores

    store = get_typestore(Stores.ROS2_JAZZY)
    text, _ = store.generate_msgdef(IMU_MSGTYPE, ros_version=2)
    return text, store.hash_rihs01(IMU_MSGTYPE)
