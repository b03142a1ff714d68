"""
Each consumer file loads with its consumer's own parser, with the names and types it reads.

VINS-Fusion and OpenVINS read their YAML with OpenCV's cv::FileStorage (cv2 here, the
same parser); robot_localization gets its parameters from rcl's parameter-file loading
(rclpy here), and only the names ROS 2 robot_localization declares are used.
"""

import math

from numpy.testing import assert_allclose
import pytest
import yaml

from imu_allan import ACCEL_AXES, AXES, GYRO_AXES
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.outputs.covering import cover_axes
from imu_allan.core.outputs.exports import robot_localization_yaml
from imu_allan.core.outputs.vio import openvins_yaml, vins_yaml

cv2 = pytest.importorskip('cv2', reason='opencv-python-headless (requirements-dev.txt)')

RATE_HZ = 200.0
HORIZON_S = (1.0 / RATE_HZ, 100.0)
N = {'gyro_x': 1.0e-4, 'gyro_y': 1.5e-4, 'gyro_z': 1.2e-4,
     'accel_x': 6.0e-4, 'accel_y': 8.0e-4, 'accel_z': 7.0e-4}
K = {'gyro_x': 2e-6, 'gyro_y': 3e-6, 'gyro_z': 2.5e-6,
     'accel_x': 1e-5, 'accel_y': 1.2e-5, 'accel_z': 9e-6}

#: What ROS 2 robot_localization declares for IMU input ``imu0`` and their types
#: (cra-ros-pkg/robot_localization, branch ros2, commit
#: 1cb953379378d13b3e0935ed73d0c7407bd80543, src/ros_filter.cpp, RosFilter::loadParams
#: and loadUpdateConfig): name -> rcl parameter type.
RL_IMU_PARAMS = {
    'imu0': 'string',
    'imu0_differential': 'bool',
    'imu0_relative': 'bool',
    'imu0_pose_rejection_threshold': 'double',
    'imu0_twist_rejection_threshold': 'double',
    'imu0_linear_acceleration_rejection_threshold': 'double',
    'imu0_remove_gravitational_acceleration': 'bool',
    'imu0_queue_size': 'integer',
    'imu0_config': 'bool_array',
}
#: The node-wide names the same file declares (same source and commit).
RL_GLOBAL_PARAMS = {
    'print_diagnostics', 'gravitational_acceleration', 'debug', 'debug_out_file',
    'map_frame', 'odom_frame', 'base_link_frame', 'base_link_frame_output', 'world_frame',
    'tf_prefix', 'publish_tf', 'publish_acceleration', 'permit_corrected_publication',
    'transform_time_offset', 'transform_timeout', 'frequency', 'predict_to_current_time',
    'sensor_timeout', 'two_d_mode', 'smooth_lagged_data', 'history_length',
    'reset_on_time_jump', 'use_control', 'control_timeout', 'control_config',
    'acceleration_limits', 'acceleration_gains', 'deceleration_limits', 'deceleration_gains',
    'dynamic_process_noise_covariance', 'initial_state', 'disabled_at_startup',
    'process_noise_covariance', 'initial_estimate_covariance'}
#: OpenVINS reads these under imu0 (rpng/open_vins commit
#: 69488123ed9362dd44b6f28e7f4680abbff1442b: ov_msckf/src/core/VioManagerOptions.h,
#: ov_msckf/src/state/StateOptions.h, ov_msckf/src/ros/ROS2Visualizer.cpp), with the
#: FileStorage node type its parser needs.
OPENVINS_IMU0 = {
    'accelerometer_noise_density': 'real', 'accelerometer_random_walk': 'real',
    'gyroscope_noise_density': 'real', 'gyroscope_random_walk': 'real',
    'rostopic': 'string', 'model': 'string',
    'Tw': 'matrix', 'R_IMUtoGYRO': 'matrix', 'Ta': 'matrix', 'R_IMUtoACC': 'matrix',
    'Tg': 'matrix'}


def _sources():
    return {a: AxisNoise(N=N[a], B=3 * N[a] / math.sqrt(20.0), T_B=20.0, K=K[a]) for a in AXES}


def _load(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.isOpened(), f'OpenCV FileStorage refuses {name}'
    return fs


def _worst(values: dict, axes) -> float:
    return max(values[a] for a in axes)


def test_vins_file_loads_in_opencv_with_per_step_values(tmp_path):
    src = _sources()
    covers = cover_axes(src, HORIZON_S)
    fs = _load(tmp_path, 'vins_imu.yaml', vins_yaml(src, RATE_HZ, covers, HORIZON_S))
    got = {}
    for key in ('acc_n', 'gyr_n', 'acc_w', 'gyr_w'):
        node = fs.getNode(key)
        assert node.isReal(), key          # parameters.cpp: fsSettings[key] into a double
        got[key] = node.real()
    # integration_base.h: gyr_n = N sqrt(2 rate), gyr_w = K sqrt(rate), covering pair.
    n_c = {a: covers[a].N_cover for a in AXES}
    k_c = {a: covers[a].K_cover for a in AXES}
    assert_allclose(got['gyr_n'], _worst(n_c, GYRO_AXES) * math.sqrt(2 * RATE_HZ), rtol=1e-6)
    assert_allclose(got['acc_n'], _worst(n_c, ACCEL_AXES) * math.sqrt(2 * RATE_HZ), rtol=1e-6)
    assert_allclose(got['gyr_w'], _worst(k_c, GYRO_AXES) * math.sqrt(RATE_HZ), rtol=1e-6)
    assert_allclose(got['acc_w'], _worst(k_c, ACCEL_AXES) * math.sqrt(RATE_HZ), rtol=1e-6)
    # The covering pair is at least the fitted one; the fitted densities are far smaller.
    assert got['gyr_n'] >= 1.5e-4 * math.sqrt(2 * RATE_HZ) * (1 - 1e-9)
    assert got['gyr_w'] > 3e-6 * math.sqrt(RATE_HZ)
    fs.release()


def test_vins_file_without_covers_makes_the_covering_pair_per_step(tmp_path):
    # One rule for every random-walk consumer: without covers given, the file makes the
    # covering pair over the default horizon (the sample period to 100 s).
    covers = cover_axes(_sources(), HORIZON_S)
    fs = _load(tmp_path, 'vins_imu.yaml', vins_yaml(_sources(), RATE_HZ))
    assert_allclose(fs.getNode('gyr_n').real(),
                    max(covers[a].N_cover for a in GYRO_AXES) * math.sqrt(2 * RATE_HZ),
                    rtol=1e-6)
    assert_allclose(fs.getNode('acc_w').real(),
                    max(covers[a].K_cover for a in ACCEL_AXES) * math.sqrt(RATE_HZ),
                    rtol=1e-6)
    fs.release()


def test_openvins_file_loads_in_opencv_with_the_imu0_node(tmp_path):
    src = _sources()
    covers = cover_axes(src, HORIZON_S)
    text = openvins_yaml(src, RATE_HZ, '/robot/imu', covers, HORIZON_S)
    assert text.startswith('%YAML:1.0\n')
    fs = _load(tmp_path, 'kalibr_imu_chain.yaml', text)
    imu0 = fs.getNode('imu0')
    assert imu0.isMap()
    for key, kind in OPENVINS_IMU0.items():
        node = imu0.getNode(key)
        assert not node.empty(), key
        if kind == 'real':
            assert node.isReal() and node.real() > 0, key
        elif kind == 'string':
            assert node.isString(), key
        else:   # a 3x3 matrix as a sequence of three sequences of three reals
            assert node.isSeq() and node.size() == 3, key
            for r in range(3):
                row = node.at(r)
                assert row.isSeq() and row.size() == 3, key
                assert all(row.at(c).isReal() for c in range(3)), key
    assert imu0.getNode('rostopic').string() == '/robot/imu'
    assert imu0.getNode('model').string() == 'kalibr'
    assert_allclose(imu0.getNode('update_rate').real(), RATE_HZ)
    # Densities (OpenVINS discretises them itself): the covering pair, worst axis.
    assert_allclose(imu0.getNode('gyroscope_noise_density').real(),
                    max(covers[a].N_cover for a in GYRO_AXES), rtol=1e-6)
    assert_allclose(imu0.getNode('accelerometer_random_walk').real(),
                    max(covers[a].K_cover for a in ACCEL_AXES), rtol=1e-6)
    fs.release()


def _rl_params(tmp_path, text: str) -> dict:
    """Load the fragment as rclpy's parameter-file loader gives it to ekf_filter_node."""
    from rclpy.parameter import parameter_dict_from_yaml_file, parameter_value_to_python
    path = tmp_path / 'ekf_imu.yaml'
    path.write_text(text)
    params = parameter_dict_from_yaml_file(str(path), target_nodes=['ekf_filter_node'])
    return {name: (msg.value.type, parameter_value_to_python(msg.value))
            for name, msg in params.items()}


#: robot_localization's defaults for the IMU parameters (same source): declaring with
#: them fixes each parameter's type, as rclcpp's declare_parameter does there.
RL_DEFAULTS = {'imu0_differential': False, 'imu0_relative': False,
               'imu0_pose_rejection_threshold': 1.7976931348623157e308,
               'imu0_twist_rejection_threshold': 1.7976931348623157e308,
               'imu0_linear_acceleration_rejection_threshold': 1.7976931348623157e308,
               'imu0_remove_gravitational_acceleration': False, 'imu0_queue_size': 10,
               'imu0_config': [False] * 15}


def _declared_by_a_node(tmp_path, text: str) -> dict:
    """Start a node named ekf_filter_node on the file and declare as robot_localization."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    path = tmp_path / 'ekf_params.yaml'
    path.write_text(text)
    ctx = Context()
    rclpy.init(args=['--ros-args', '--params-file', str(path)], context=ctx)
    try:
        node = Node('ekf_filter_node', context=ctx)
        try:
            got = {'imu0': node.declare_parameter('imu0', Parameter.Type.STRING).value}
            for name, default in RL_DEFAULTS.items():   # a wrong type raises here
                got[name] = node.declare_parameter(name, default).value
            return got
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.mark.parametrize('orientation', [True, False])
def test_robot_localization_fragment_uses_only_declared_ros2_names(tmp_path, orientation):
    from rcl_interfaces.msg import ParameterType
    types = {'string': ParameterType.PARAMETER_STRING, 'bool': ParameterType.PARAMETER_BOOL,
             'double': ParameterType.PARAMETER_DOUBLE,
             'integer': ParameterType.PARAMETER_INTEGER,
             'bool_array': ParameterType.PARAMETER_BOOL_ARRAY}
    text = robot_localization_yaml(_sources(), RATE_HZ, '/robot/imu_allan/imu_with_covariance',
                                   orientation=orientation)
    params = _rl_params(tmp_path, text)
    assert params, 'no parameters for /ekf_filter_node'
    for name, (kind, _) in params.items():
        assert name in RL_IMU_PARAMS or name in RL_GLOBAL_PARAMS, \
            f'{name} is not a ROS 2 robot_localization parameter'
        if name in RL_IMU_PARAMS:   # rclcpp refuses a value of another type
            assert kind == types[RL_IMU_PARAMS[name]], name
    values = {k: v for k, (_, v) in params.items()}
    assert values['imu0'] == '/robot/imu_allan/imu_with_covariance'
    assert len(values['imu0_config']) == 15
    assert values['imu0_twist_rejection_threshold'] > 0       # the angular-velocity gate
    rates = values['imu0_config'][9:12]
    accels = values['imu0_config'][12:15]
    assert all(rates) and not any(values['imu0_config'][:9])
    # Gravity removal only where roll/pitch come with the message.
    assert all(accels) == orientation
    assert values['imu0_remove_gravitational_acceleration'] == orientation
    assert ('orientation_covariance[0] != -1' in text) == orientation
    # A node declaring them as robot_localization does takes every value from the file.
    declared = _declared_by_a_node(tmp_path, text)
    for name, value in values.items():
        assert declared[name] == value, name


def test_kalibr_file_is_plain_yaml_with_its_keys_unchanged():
    from imu_allan.core.outputs.exports import kalibr_yaml
    doc = yaml.safe_load(kalibr_yaml(_sources(), RATE_HZ))
    assert set(doc) == {'accelerometer_noise_density', 'accelerometer_random_walk',
                        'gyroscope_noise_density', 'gyroscope_random_walk', 'rostopic',
                        'update_rate'}
    # The covering pair (continuous densities), as the VIO files: never below the
    # reported worst axis.
    covers = cover_axes(_sources(), HORIZON_S)
    assert_allclose(doc['gyroscope_noise_density'],
                    max(covers[a].N_cover for a in GYRO_AXES), rtol=1e-6)
    assert_allclose(doc['accelerometer_random_walk'],
                    max(covers[a].K_cover for a in ACCEL_AXES), rtol=1e-6)
    assert doc['gyroscope_noise_density'] >= 1.1 * 1.5e-4 * (1 - 1e-9)
    assert doc['accelerometer_random_walk'] >= 1.2e-5
