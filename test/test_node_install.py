"""The node as a ROS user starts it: integer values for doubles, ROS_HOME, real rclpy."""

import os
import random

os.environ.setdefault('ROS_DOMAIN_ID', str(random.Random().randint(101, 200)))

import pytest  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from imu_allan.ros.node import ImuAllanNode  # noqa: E402, I100
from imu_allan.ros.params import as_declared_type, default_output_dir  # noqa: E402


def _node(args: list, **kwargs) -> tuple:
    ctx = Context()
    rclpy.init(args=['--ros-args', *args], context=ctx)
    try:
        return ImuAllanNode(context=ctx, **kwargs), ctx
    except BaseException:
        rclpy.try_shutdown(context=ctx)
        raise


def _close(node, ctx) -> None:
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def test_integers_for_double_parameters_on_the_command_line(tmp_path):
    node, ctx = _node(['-p', 'min_duration_s:=600', '-p', 'covering_tau_max_s:=30',
                       '-p', f'output_dir:={tmp_path}'])
    try:
        for name, value in (('min_duration_s', 600.0), ('covering_tau_max_s', 30.0)):
            param = node.get_parameter(name)
            assert param.type_ == Parameter.Type.DOUBLE and param.value == value, name
            assert node.values[name] == value and isinstance(node.values[name], float)
    finally:
        _close(node, ctx)


def test_integers_for_doubles_in_a_parameter_file_and_in_overrides(tmp_path):
    params = tmp_path / 'params.yaml'
    params.write_text('imu_allan:\n  ros__parameters:\n    publish_period_s: 5\n'
                      f"    output_dir: '{tmp_path}'\n")
    node, ctx = _node(['--params-file', str(params)],
                      parameter_overrides=[Parameter('progress_period_s', value=20)])
    try:
        assert node.get_parameter('publish_period_s').value == 5.0
        assert node.get_parameter('progress_period_s').value == 20.0
        assert node.get_parameter('qos_depth').type_ == Parameter.Type.INTEGER
    finally:
        _close(node, ctx)


def test_a_wrong_type_is_still_refused():
    assert as_declared_type('qos_depth', 2.5) == 2.5          # not rounded
    assert as_declared_type('min_duration_s', True) is True   # a bool is not a number
    assert as_declared_type('min_duration_s', 600) == 600.0


def test_the_default_save_directory_follows_ros_home(tmp_path, monkeypatch):
    home = tmp_path / 'ros_home'
    assert default_output_dir('ns/imu_allan', {'ROS_HOME': str(home)}) == \
        home / 'imu_allan' / 'ns' / 'imu_allan'
    assert default_output_dir('imu_allan', {}) == \
        default_output_dir('imu_allan', {'ROS_HOME': os.path.expanduser('~/.ros')})
    monkeypatch.setenv('ROS_HOME', str(home))
    node, ctx = _node(['-r', '__ns:=/left'])
    try:
        assert node.output_dir == home / 'imu_allan' / 'left' / 'imu_allan'
    finally:
        _close(node, ctx)


@pytest.mark.parametrize('value', ['0.5', "'long'"])
def test_bad_values_still_get_a_clear_error(value):
    from imu_allan.errors import InputError
    with pytest.raises(InputError, match='covering_tau_max_s'):
        _node(['-p', f'covering_tau_max_s:={value}'])
