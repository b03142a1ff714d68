"""Shared fixtures: the read-only real recordings in ../shared, when present."""

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / 'shared'


@pytest.fixture
def shared_dir() -> Path:
    """Return ../shared, or skip the test cleanly when it is absent."""
    if not (SHARED / 'realdata').is_dir() or not (SHARED / 'refdata').is_dir():
        pytest.skip('../shared (real recordings and reference data) is not present')
    return SHARED
