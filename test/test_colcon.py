"""
colcon builds the package and puts the executables where ``ros2 run`` looks.

``ros2 run PKG EXE`` resolves ``<prefix>/lib/PKG/EXE`` with the prefix found in the
ament index (AMENT_PREFIX_PATH); this test does that lookup with ament_index_python on
a workspace built by colcon from PyPI, then starts the installed console script.
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

from conftest import REPO


def _package_files() -> list[str]:
    out = subprocess.run(['git', 'ls-files', '--cached', '--others', '--exclude-standard'],
                         cwd=REPO, capture_output=True, text=True, check=True)
    return [f for f in out.stdout.splitlines() if (REPO / f).is_file()]


@pytest.fixture(scope='module')
def workspace(tmp_path_factory) -> Path:
    colcon = shutil.which('colcon', path=str(Path(sys.executable).parent))
    if colcon is None:
        pytest.fail('colcon is missing from the venv: run make test, which installs it')
    ws = tmp_path_factory.mktemp('ws')
    src = ws / 'src' / 'imu_allan'
    for rel in _package_files():
        dst = src / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, dst)
    env = dict(os.environ, PATH=f'{Path(sys.executable).parent}:{os.environ["PATH"]}')
    out = subprocess.run([colcon, 'build', '--event-handlers', 'console_direct-'],
                         cwd=ws, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return ws


def test_executables_where_ros2_run_looks(workspace):
    from ament_index_python.packages import get_package_prefix
    os.environ['AMENT_PREFIX_PATH'] = str(workspace / 'install' / 'imu_allan')
    prefix = Path(get_package_prefix('imu_allan'))
    for exe in ('imu_allan_node', 'imu-allan'):
        path = prefix / 'lib' / 'imu_allan' / exe
        assert path.is_file() and os.access(path, os.X_OK), path
    share = prefix / 'share' / 'imu_allan'
    assert (share / 'package.xml').is_file()
    assert list((share / 'config').glob('*.yaml')), 'config/*.yaml not installed'
    assert list((share / 'launch').glob('*.launch.py')), 'launch file not installed'


def test_installed_cli_runs(workspace):
    prefix = workspace / 'install' / 'imu_allan'
    site = next(prefix.glob('lib/python3*/site-packages'))
    env = dict(os.environ, PYTHONPATH=str(site))
    out = subprocess.run([str(prefix / 'lib' / 'imu_allan' / 'imu-allan'), '--version'],
                         env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith('imu-allan ')
