"""
Covariances written into serialised sensor_msgs/Imu messages (ROS 2 CDR), in place.

The node's ``~/imu_with_covariance`` relay republishes each message with the noise
model's covariances (:mod:`imu_allan.ros.relay`): :class:`CovariancePatch` writes them
into one message's bytes, :func:`set_imu_covariances_cdr` into many at once; both find
the fields by the wire layout :mod:`imu_allan.io.imu_cdr` reads, so no Python message is
built per sample.
"""

import numpy as np

from imu_allan.io.imu_cdr import _cdr_doubles_offset, _imu_layout, join_payloads


def set_imu_covariances_cdr(payloads, angular_velocity_covariance,
                            linear_acceleration_covariance) -> list[bytes | None]:
    """
    Copy serialised ROS 2 sensor_msgs/msg/Imu messages (CDR) with new covariances.

    The two 3x3 covariances are written straight into the bytes, so republishing
    costs no Python message per sample.

    Parameters
    ----------
    payloads : sequence of bytes
        n serialised messages, e.g. from an rclpy raw subscription.
    angular_velocity_covariance : array_like
        (9,) row-major 3x3 covariance [(rad/s)^2].
    linear_acceleration_covariance : array_like
        (9,) row-major 3x3 covariance [(m/s^2)^2].

    Returns
    -------
    list
        n patched payloads (bytes); None where the payload is not in the plain CDR
        layout (the caller deserialises those).

    """
    if not len(payloads):
        return []
    u8, starts, lengths = join_payloads(payloads)
    u8 = u8.copy()  # writable
    offset, big, fits = _imu_layout(u8, starts, lengths, False)
    # The covariances follow orientation (4 doubles), its covariance (9) and
    # angular_velocity (3), then linear_acceleration (3): byte 128 and 224 of the doubles.
    for field_at, cov in ((128, angular_velocity_covariance),
                          (224, linear_acceleration_covariance)):
        for is_big in (False, True):
            sel = np.flatnonzero(fits & (big == is_big))
            if sel.size:
                data = np.frombuffer(np.asarray(cov, '>f8' if is_big else '<f8').tobytes(),
                                     np.uint8)
                u8[(starts[sel] + offset[sel] + field_at)[:, None] + np.arange(72)] = data
    joined = u8.tobytes()
    return [joined[a:a + n] if ok else None
            for a, n, ok in zip(starts.tolist(), lengths.tolist(), fits.tolist())]


class CovariancePatch:
    """
    Write two fixed covariances into single serialised Imu messages (ROS 2 CDR).

    The per-message path of the node's relay: the byte strings of both fields are
    prepared once per covariance update, so a message costs a few slices (about a
    microsecond), with the same result as :func:`set_imu_covariances_cdr`.

    Parameters
    ----------
    angular_velocity_covariance, linear_acceleration_covariance : array_like
        (9,) row-major 3x3 covariances [(rad/s)^2], [(m/s^2)^2].

    """

    def __init__(self, angular_velocity_covariance, linear_acceleration_covariance):
        fields = [np.asarray(c, np.float64).reshape(9) for c in
                  (angular_velocity_covariance, linear_acceleration_covariance)]
        self._bytes = {big: [f.astype('>f8' if big else '<f8').tobytes() for f in fields]
                       for big in (False, True)}

    def __call__(self, raw: bytes) -> bytes | None:
        """Return the patched copy of ``raw``, or None for an unusual layout."""
        layout = _cdr_doubles_offset(raw)
        if layout is None:
            return None
        at, big = layout
        gyro, accel = self._bytes[big]
        return b''.join((raw[:at + 128], gyro, raw[at + 200:at + 224], accel,
                         raw[at + 296:]))
