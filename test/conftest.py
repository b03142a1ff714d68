"""
Shared fixtures: a still IMU, the tests' start stamp, the real recordings in ../shared.

Test files import the plain ones (``from conftest import REPO, still_imu, T0_NS``).
"""

import importlib.util
import os
from pathlib import Path
import subprocess
import sys
import tempfile

# As the CLI and the node do before numpy loads (imu_allan.pipeline.workers.one_blas_thread):
# the tests that compare an in-process analysis with a CLI run compare the same sums.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402
import pytest  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / 'shared'
#: Start of the tests' synthetic records [ns] (2023-11-14, a plausible ROS stamp).
T0_NS = 1_700_000_000_000_000_000
#: White-noise sd per sample of :func:`still_imu` [rad/s, m/s^2], gyro then accel.
STILL_SIGMA = (1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2)

#: Test files that import pip-only extras at module level (no rosdep key for Ubuntu
#: 24.04; package.xml leaves them out, docs/node.md says how to install them): without
#: the extras they are not collected, and the pytest header names them.
EXTRAS = {'test_bag_reader.py': ('rosbags', 'mcap'), 'test_bag_writer.py': ('rosbags', 'mcap'),
          'test_cli_analyze.py': ('rosbags', 'mcap'), 'test_cli_simulate.py': ('rosbags',),
          'test_imu_patch.py': ('rosbags',),
          'test_fleet.py': ('dask', 'pyarrow')}
MISSING = {f: [m for m in mods if importlib.util.find_spec(m) is None]
           for f, mods in EXTRAS.items()}
collect_ignore = [f for f, missing in MISSING.items() if missing]


def pytest_report_header(config):
    """Name the test files left out for missing pip extras."""
    return [f'imu_allan: skipped {f} (pip extras missing: {", ".join(MISSING[f])})'
            for f in collect_ignore]


def _existing(*names: str) -> list:
    return [n for n in names if (REPO / n).exists()]


_CHECKED = ('imu_allan', 'test', 'bench', 'launch', 'examples')
#: The linters' commands (``python -m ...`` from the repository), by the test file that
#: reads each.  In one pytest process each starts in the background once its test is
#: selected, and their minute of one core overlaps the tests.
LINTERS = {
    'test_mypy.py': ['mypy', '--config-file', 'setup.cfg', '--no-incremental',
                     '--cache-dir', os.devnull, 'imu_allan'],
    'test_flake8.py': ['ament_flake8.main', '--config', 'test/ament_flake8.ini',
                       *_existing(*_CHECKED, 'setup.py')],
    'test_pep257.py': ['ament_pep257.main', *_existing(*_CHECKED)],
}
_LINTING: dict = {}


def _start_linter(name: str) -> None:
    out = tempfile.TemporaryFile()
    proc = subprocess.Popen([sys.executable, '-m', *LINTERS[name]], cwd=REPO, stdout=out,
                            stderr=subprocess.STDOUT)
    _LINTING[name] = (proc, out)


#: Test files whose nodes talk over DDS with timers and discovery that a loaded core
#: slows past their waits: marked ``ros_graph``, and `make test` runs them alone after
#: the others ran on two xdist workers.
ROS_GRAPH = ('test_node.py', 'test_node_plan.py', 'test_node_install.py')
#: Test files with module-scoped fixtures (fleet runs, analysed records, a colcon
#: build): one xdist group each, so a worker builds each once; the tests of the
#: session's ADIS16405 run 1 are one group too.  The rest go to either worker.
SHARED_FIXTURES = frozenset(p.name for p in Path(__file__).parent.glob('test_*.py')
                            if "scope='module'" in p.read_text())


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(session, config, items):
    """Mark :data:`ROS_GRAPH` and the xdist groups (before ``-m`` selects)."""
    for item in items:
        name = Path(str(item.path)).name
        if name in ROS_GRAPH:
            item.add_marker(pytest.mark.ros_graph)
        group = ('adis_run1' if 'adis_run1' in getattr(item, 'fixturenames', ())
                 else name if name in SHARED_FIXTURES else None)
        if group:
            item.add_marker(pytest.mark.xdist_group(group))


def pytest_collection_finish(session):
    """Start the linters whose tests were selected (see :data:`LINTERS`)."""
    if os.environ.get('PYTEST_XDIST_WORKER'):
        return      # each worker collects every test: a linter starts when its test runs
    for name in sorted({Path(str(item.path)).name for item in session.items} & set(LINTERS)):
        if name not in _LINTING:
            _start_linter(name)


def pytest_unconfigure(config):
    """Stop a linter whose test did not read it (an interrupted run)."""
    for proc, _ in _LINTING.values():
        proc.kill()


def lint(name: str) -> tuple[int, str]:
    """Return the exit code and output of a linter of :data:`LINTERS` (waits for it)."""
    if name not in _LINTING:
        _start_linter(name)
    proc, out = _LINTING.pop(name)
    rc = proc.wait()
    out.seek(0)
    return rc, out.read().decode(errors='replace')


@pytest.fixture
def shared_dir() -> Path:
    """Return ../shared, or skip the test cleanly when it is absent."""
    if not (SHARED / 'realdata').is_dir() or not (SHARED / 'refdata').is_dir():
        pytest.skip('../shared (real recordings and reference data) is not present')
    return SHARED


@pytest.fixture(scope='session')
def adis_run1():
    """
    Return ADIS16405 run 1 analysed as ``imu-allan analyze`` does, once per test session.

    The docs' figures (test_docs) and the node's path (test_live) compare with it; skips
    when ../shared is absent.
    """
    path = SHARED / 'realdata' / 'adis16405' / 'adis16405_run1.csv.gz'
    if not path.is_file():
        pytest.skip('../shared (real recordings and reference data) is not present')
    from imu_allan.io.inputs import analyze_input
    from imu_allan.pipeline.hygiene import SessionConfig

    # Two worker processes for the axes' searches, as the CLI runs on two cores (the same
    # numbers: test_pipeline.py::test_axes_searched_in_worker_processes_give_the_same_result).
    return analyze_input(path, None, SessionConfig(), quiet=True, progress=False,
                         workers=2)[0]


def still_imu(n: int, seed: int = 0, rate_hz: float = 100.0) -> tuple:
    """
    Return a still IMU: white noise of sd STILL_SIGMA, gravity on accel_z.

    Parameters
    ----------
    n : int
        Samples.
    seed : int
        Seed of ``np.random.default_rng``.
    rate_hz : float
        Sample rate [Hz]; stamps are exact multiples of the period from T0_NS.

    Returns
    -------
    stamp_ns : numpy.ndarray
        (n,) int64 [ns].
    samples : numpy.ndarray
        (n, 6) float64 [rad/s, m/s^2], axes as ``imu_allan.AXES``.

    """
    rng = np.random.default_rng(seed)
    samples = rng.normal(0.0, STILL_SIGMA, (n, 6))
    samples[:, 5] += 9.80665
    return T0_NS + np.round(np.arange(n) * 1e9 / rate_hz).astype(np.int64), samples


def white_rw_offset(n: int, n_axes: int, seed: int) -> np.ndarray:
    """White + random-walk rate noise on top of per-axis offsets, shape (n, n_axes)."""
    rng = np.random.default_rng(seed)
    offsets = np.array([9.81, -0.3, 0.02, 1e3, 0.0, -9.81])[:n_axes]
    white = rng.standard_normal((n, n_axes)) * 1e-3
    walk = np.cumsum(rng.standard_normal((n, n_axes)), axis=0) * 1e-6
    return offsets + white + walk
