"""mypy over the package (settings in setup.cfg [mypy]; the command: conftest.LINTERS)."""

import pytest

from conftest import lint


@pytest.mark.linter
def test_mypy():
    rc, out = lint('test_mypy.py')
    assert rc == 0, out
