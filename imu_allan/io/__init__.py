"""
File and message adapters.

CSV, rosbag2 (sqlite3, MCAP) and ROS 1 bag readers, the bag writer, the report files
and plots.  Heavy third-party libraries are imported only by the modules that need them.
"""

#: The ADEV figure's files, adev.<format> (drawn by :mod:`imu_allan.io.plot`).
FIGURE_FORMATS = ('png', 'svg')
