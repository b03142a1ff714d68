"""
Imported by the workers' fork server: matplotlib and its font loaded once.

Every worker forked from the server then draws its figure at once instead of
importing matplotlib and loading its font first (see
:func:`imu_allan.pipeline.workers.start_workers`).
"""

from imu_allan.io.plot import warm_fonts

warm_fonts()
