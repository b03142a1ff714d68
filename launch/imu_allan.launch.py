"""
Launch imu_allan_node with config/imu_allan.yaml and a remappable Imu topic.

Two IMUs on one robot: launch it twice with different namespaces
(``namespace:=left imu_topic:=/left/imu/data``); each node then keeps its own
output directory, topics and diagnostic names.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    config = os.path.join(get_package_share_directory('imu_allan'), 'config', 'imu_allan.yaml')
    arguments = [
        ('imu_topic', '/imu/data', 'sensor_msgs/Imu topic of the stationary IMU'),
        ('params_file', config, 'Parameter file (see config/imu_allan.yaml)'),
        ('namespace', '', 'Namespace of the node (one per IMU)'),
        ('use_sim_time', 'false', 'Use /clock (bag playback with --clock)'),
        ('resume', 'false', 'Continue from the checkpoint in output_dir'),
        ('publish_imu_with_covariance', 'false',
         'Republish each Imu message on ~/imu_with_covariance with the Allan covariances'),
        ('log_level', 'info', 'Logging level: debug, info, warn, error'),
    ]
    return LaunchDescription([
        *[DeclareLaunchArgument(name, default_value=default, description=text)
          for name, default, text in arguments],
        Node(
            package='imu_allan',
            executable='imu_allan_node',
            name='imu_allan',
            namespace=LaunchConfiguration('namespace'),
            output='screen',
            parameters=[LaunchConfiguration('params_file'), {
                'use_sim_time': ParameterValue(LaunchConfiguration('use_sim_time'),
                                               value_type=bool),
                'resume': ParameterValue(LaunchConfiguration('resume'), value_type=bool),
                'publish_imu_with_covariance': ParameterValue(
                    LaunchConfiguration('publish_imu_with_covariance'), value_type=bool)}],
            remappings=[('imu', LaunchConfiguration('imu_topic'))],
            arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')],
        ),
    ])
