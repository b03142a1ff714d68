"""ament_flake8 over the package, its tests, benchmarks and launch files."""

from ament_flake8.main import main_with_errors
import pytest

from conftest import REPO

CHECKED = ['imu_allan', 'test', 'bench', 'launch', 'examples', 'setup.py']


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    paths = [str(REPO / p) for p in CHECKED if (REPO / p).exists()]
    rc, errors = main_with_errors(argv=['--config', str(REPO / 'test' / 'ament_flake8.ini')]
                                  + paths)
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
