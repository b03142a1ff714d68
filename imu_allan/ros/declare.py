"""
How the node declares its parameters to rclpy: descriptors and declared types.

The parameter table itself (names, types, defaults, ranges, the docs table) is
:mod:`imu_allan.ros.params`, which needs no rclpy; this module turns it into rclpy's
descriptors (a range, read-only for the parameters that shape the session) and makes
``ros2 param set ... 600`` (an integer) a double where the parameter is one.
"""

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.parameter import Parameter

from imu_allan.ros.params import as_declared_type

#: Parameters that shape the session: fixed while it runs (change them and ~/reset).
SESSION_PARAMS = {'rate_hz', 'qos_depth', 'qos_reliability', 'max_buffer_messages',
                  'output_dir', 'resume', 'publish_imu_with_covariance',
                  'initial_covariance_file', 'diagnose_raw_samples', 'temperature_topic'}


def descriptor(p) -> ParameterDescriptor:
    """Return the rclpy descriptor of a parameter of the table (its range, read-only)."""
    d = ParameterDescriptor(description=f'{p.description} [{p.unit}]' if p.unit
                            else p.description,
                            read_only=p.name in SESSION_PARAMS)
    if p.value_type is float and p.limits:
        d.floating_point_range = [FloatingPointRange(from_value=float(p.limits[0]),
                                                     to_value=float(p.limits[1]), step=0.0)]
    elif p.value_type is int and p.limits:
        d.integer_range = [IntegerRange(from_value=int(p.limits[0]),
                                        to_value=int(p.limits[1]), step=1)]
    elif p.value_type is str and p.limits:
        d.additional_constraints = 'one of: ' + ', '.join(p.limits)
    return d


def as_declared_types(params: list) -> list:
    """Return the parameters to set, an integer for a double parameter made a float."""
    out = []
    for p in params:
        value = as_declared_type(p.name, p.value)
        out.append(p if value is p.value else Parameter(p.name, value=value))
    return out
