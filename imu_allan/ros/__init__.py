"""
The ROS 2 adapter.

The live node and its parameter table.
"""

from imu_allan.pipeline.workers import one_blas_thread

# The node's entry point imports this package before numpy: OpenBLAS reads the setting
# when it loads.
one_blas_thread()
