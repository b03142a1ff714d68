"""ament_flake8 over the package, its tests, benchmarks and launch files."""

import pytest

from conftest import lint


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    rc, out = lint('test_flake8.py')
    assert rc == 0, f'code style errors / warnings:\n{out}'
