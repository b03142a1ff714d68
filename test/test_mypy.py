"""mypy over the package (settings in setup.cfg [mypy])."""

from mypy import api
import pytest

from conftest import REPO


@pytest.mark.linter
def test_mypy():
    out, err, rc = api.run(['--config-file', str(REPO / 'setup.cfg'), '--no-incremental',
                            '--cache-dir', '/dev/null', str(REPO / 'imu_allan')])
    assert rc == 0, out + err
