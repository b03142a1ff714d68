from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'imu_allan'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'bench']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'), glob('config/*.yaml')),
        (os.path.join('share', package_name, 'launch'), glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'pyyaml'],
    # imu-allan fleet: Dask for the cluster, pyarrow for the Parquet store.
    extras_require={'fleet': ['dask[distributed]>=2024.1', 'pyarrow>=14']},
    zip_safe=False,
    maintainer='imu_allan developers',
    maintainer_email='imu-allan@example.com',
    description='Allan-variance characterisation of IMU noise, live and offline, for ROS 2.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'imu-allan = imu_allan.cli:entry',
            'imu_allan_node = imu_allan.ros.node:main',
        ],
    },
)
