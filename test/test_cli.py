"""
The ``imu-allan`` dispatcher: ``--help`` and one command load only what they use.

A ratio or a timing would be a benchmark; what a test can assert for certain is which
modules a run imports (numpy and scipy dominate the start-up time).
"""

import subprocess
import sys

from conftest import REPO

SCRIPT = """
import sys
from imu_allan.cli import main
try:
    main({argv!r})
except SystemExit:
    pass
print(sorted(m for m in ('numpy', 'scipy', 'matplotlib', 'rclpy', 'imu_allan.cli.analyze',
                         'imu_allan.cli.adev') if m in sys.modules))
"""


def _loaded(argv):
    out = subprocess.run([sys.executable, '-c', SCRIPT.format(argv=argv)], cwd=REPO,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1]


def test_help_imports_no_numerics():
    assert _loaded(['--help']) == '[]'


def test_a_command_imports_only_its_own_module():
    loaded = _loaded(['adev', '--help'])
    assert "'imu_allan.cli.adev'" in loaded and 'imu_allan.cli.analyze' not in loaded
    assert 'rclpy' not in loaded and 'matplotlib' not in loaded


def test_every_command_is_listed_in_the_top_level_help():
    out = subprocess.run([sys.executable, '-m', 'imu_allan', '--help'], cwd=REPO,
                         capture_output=True, text=True, timeout=120)
    for command in ('adev', 'analyze', 'simulate', 'csv-to-bag', 'diagnose', 'demo'):
        assert command in out.stdout


def test_demo_finds_its_default_parameter_file():
    # make demo runs without --params: from a clone the file is the repository's config.
    from imu_allan.cli.demo import _params_file

    path = _params_file(None)
    assert path.is_file() and path.name == 'xsens_mti7.yaml'
