"""Entry point for ``python -m imu_allan``."""

import sys

from imu_allan.cli import main

sys.exit(main())
