"""
imu_allan: Allan-variance characterisation of IMU noise for ROS 2.

Layers (one direction of imports): adapters (node, bag readers, CLI, plots) ->
pipeline -> core (numpy/scipy only; no ROS import anywhere in the core).
"""

__version__ = '0.1.0'

#: Axis names in contract order (docs/contracts.md): rad/s for gyro, m/s^2 for accel.
AXES = ('gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z')
GYRO_AXES = AXES[:3]
ACCEL_AXES = AXES[3:]
#: SI unit of each axis' samples (REP 103/145).
AXIS_UNITS = {a: ('rad/s' if a.startswith('gyro') else 'm/s^2') for a in AXES}
