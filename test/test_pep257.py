"""ament_pep257 (numpydoc-friendly pydocstyle) over the package and its tests."""

import pytest

from conftest import lint


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    rc, out = lint('test_pep257.py')
    assert rc == 0, f'code style errors / warnings:\n{out}'
