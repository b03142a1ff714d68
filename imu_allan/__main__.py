"""Entry point for ``python -m imu_allan``."""

import sys

try:
    from imu_allan.cli import entry
except KeyboardInterrupt:       # a Ctrl-C in the first instant: the same line as later
    print('imu-allan: interrupted', file=sys.stderr)
    sys.exit(130)

entry()
