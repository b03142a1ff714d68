"""Tests of the covariances written into serialised Imu messages, against rosbags."""

import numpy as np
from numpy.testing import assert_array_equal
from rosbags.typesys import get_typestore, Stores

from conftest import T0_NS
from imu_allan.io.bag_writer import serialize_imu
from imu_allan.io.imu_cdr import imu_frame_id
from imu_allan.io.imu_patch import CovariancePatch, set_imu_covariances_cdr

IMU = 'sensor_msgs/msg/Imu'
ROS2 = get_typestore(Stores.ROS2_JAZZY)


def _mixed_cdr(seed: int) -> tuple[list, list]:
    """Six Imu messages, both byte orders, frame ids of 0-5 characters, then garbage."""
    rng = np.random.default_rng(seed)
    msgs = [ROS2.deserialize_cdr(bytes(serialize_imu(np.array([T0_NS + i * 10**7]),
                                                     rng.normal(size=(1, 6)), 'f' * i)[0]), IMU)
            for i in range(6)]
    payloads = [bytes(ROS2.serialize_cdr(m, IMU, little_endian=i % 2 == 0))
                for i, m in enumerate(msgs)]
    payloads.append(b'\x00\x01\x00\x00' + b'\x07' * 10)   # too short to be an Imu
    return msgs, payloads


def test_covariances_are_written_into_the_cdr_bytes():
    msgs, payloads = _mixed_cdr(seed=8)
    gyro, accel = np.arange(9) * 1e-6, np.arange(9, 18) * 1e-3
    patched = set_imu_covariances_cdr(payloads, gyro, accel)
    assert patched[-1] is None and set_imu_covariances_cdr([], gyro, accel) == []
    for raw, msg in zip(patched[:-1], msgs):
        got = ROS2.deserialize_cdr(raw, IMU)
        assert_array_equal(got.angular_velocity_covariance, gyro)
        assert_array_equal(got.linear_acceleration_covariance, accel)
        # Everything else is the original message, byte for byte.
        got.angular_velocity_covariance = msg.angular_velocity_covariance
        got.linear_acceleration_covariance = msg.linear_acceleration_covariance
        assert bytes(ROS2.serialize_cdr(got, IMU, little_endian=raw[1] == 1)) == \
            bytes(ROS2.serialize_cdr(msg, IMU, little_endian=raw[1] == 1))


def test_single_message_patch_and_frame_id_match_the_batch_path():
    # The node's relay patches one message at a time: same bytes as the batch path, in
    # both byte orders and for every frame_id length (padding), None where it cannot.
    msgs, payloads = _mixed_cdr(seed=9)
    gyro, accel = np.arange(9) * 1e-6, np.arange(9, 18) * 1e-3
    patch = CovariancePatch(gyro, accel)
    for raw, batch in zip(payloads, set_imu_covariances_cdr(payloads, gyro, accel)):
        assert patch(raw) == batch
    for raw, msg in zip(payloads[:-1], msgs):
        assert imu_frame_id(raw) == msg.header.frame_id
    assert imu_frame_id(b'\x00\x01') is None and patch(b'') is None
