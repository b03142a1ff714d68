"""ament_pep257 (numpydoc-friendly pydocstyle) over the package and its tests."""

from ament_pep257.main import main
import pytest

from conftest import REPO

CHECKED = ['imu_allan', 'test', 'bench', 'launch', 'examples']


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    paths = [str(REPO / p) for p in CHECKED if (REPO / p).exists()]
    rc = main(argv=paths)
    assert rc == 0, 'Found code style errors / warnings'
