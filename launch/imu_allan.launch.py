"""Launch imu_allan_node with config/imu_allan.yaml and a remappable Imu topic."""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    config = os.path.join(get_package_share_directory('imu_allan'), 'config', 'imu_allan.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('imu_topic', default_value='/imu/data',
                              description='sensor_msgs/Imu topic of the stationary IMU'),
        DeclareLaunchArgument('params_file', default_value=config,
                              description='Parameter file (see config/imu_allan.yaml)'),
        Node(
            package='imu_allan',
            executable='imu_allan_node',
            name='imu_allan',
            output='screen',
            parameters=[LaunchConfiguration('params_file')],
            remappings=[('imu', LaunchConfiguration('imu_topic'))],
        ),
    ])
