"""Entry point for ``python -m imu_allan``."""

from imu_allan.cli import entry

entry()
