from glob import glob
import os

from setuptools import Extension, find_packages, setup

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
    # The core's compiled kernels: plain C called through ctypes (imu_allan/core/native/),
    # so no numpy headers are needed.
    ext_modules=[Extension(f'{package_name}.core.native._native',
                           ['imu_allan/core/native/_native.c'],
                           extra_compile_args=['-O3', '-ffp-contract=off'])],
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
