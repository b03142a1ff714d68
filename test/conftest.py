"""Shared fixtures: the read-only real recordings in ../shared, when present."""

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / 'shared'

#: Test files that import pip-only extras at module level (no rosdep key for Ubuntu
#: 24.04; package.xml leaves them out, docs/node.md says how to install them): without
#: the extras they are not collected, and the pytest header names them.
EXTRAS = {'test_bag_reader.py': ('rosbags', 'mcap'), 'test_bag_writer.py': ('rosbags', 'mcap'),
          'test_cli_analyze.py': ('rosbags', 'mcap'), 'test_cli_simulate.py': ('rosbags',),
          'test_fleet.py': ('dask', 'pyarrow')}
MISSING = {f: [m for m in mods if importlib.util.find_spec(m) is None]
           for f, mods in EXTRAS.items()}
collect_ignore = [f for f, missing in MISSING.items() if missing]


def pytest_report_header(config):
    """Name the test files left out for missing pip extras."""
    return [f'imu_allan: skipped {f} (pip extras missing: {", ".join(MISSING[f])})'
            for f in collect_ignore]


@pytest.fixture
def shared_dir() -> Path:
    """Return ../shared, or skip the test cleanly when it is absent."""
    if not (SHARED / 'realdata').is_dir() or not (SHARED / 'refdata').is_dir():
        pytest.skip('../shared (real recordings and reference data) is not present')
    return SHARED
