"""
The core knows nothing of ROS: it imports with rclpy and the bag libraries unavailable.

Runs in a subprocess whose import machinery refuses every ROS, bag and plotting module,
so a stray import anywhere in the core (even a lazy one at module level) fails here.
"""

import subprocess
import sys

from conftest import REPO

CORE = ('allan', 'analysis', 'accumulator', 'model', 'fit', 'simulate', 'kalman', 'diagnose',
        'noise_params', 'units', 'csv_io', 'pipeline', 'errors', 'node_params')
FORBIDDEN = ('rclpy', 'rosbags', 'mcap', 'sensor_msgs', 'std_msgs', 'std_srvs',
             'diagnostic_msgs', 'builtin_interfaces', 'matplotlib', 'launch')

SCRIPT = f"""
import importlib, importlib.util, sys
FORBIDDEN = {FORBIDDEN!r}

class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in FORBIDDEN:
            raise ImportError('core imported ' + name)
        return None

sys.meta_path.insert(0, Refuse())
for mod in {CORE!r}:
    if importlib.util.find_spec('imu_allan.' + mod) is not None:
        importlib.import_module('imu_allan.' + mod)
print('ok')
"""


def test_core_imports_without_ros():
    out = subprocess.run([sys.executable, '-c', SCRIPT], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'ok'


def test_refusal_really_works():
    # The guard itself must be able to fail: importing rclpy under it is refused.
    script = SCRIPT.replace("print('ok')", 'import rclpy')
    out = subprocess.run([sys.executable, '-c', script], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode != 0 and 'core imported rclpy' in out.stderr
