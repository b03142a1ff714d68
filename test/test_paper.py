"""
The example configs carry the paper's numbers (../shared/paper/TABLES.md, tables 1 and 2).

Skips when ../shared is absent (a clone of the repository alone).
"""

from pathlib import Path
import re

from numpy.testing import assert_allclose
import pytest

from conftest import REPO
from imu_allan import ACCEL_AXES, GYRO_AXES
from imu_allan.core.noise.params import load_params

TABLES = Path(__file__).resolve().parents[2] / 'shared' / 'paper' / 'TABLES.md'
COLUMNS = ('N acc', 'N gyro', 'B acc', 'B gyro', 'K acc', 'K gyro', 'T_B acc', 'T_B gyro')
FILES = {('MTi-7', 2): 'xsens_mti7.yaml', ('C102-F9R', 2): 'ublox_c102_f9r.yaml',
         ('MTi-7', 1): 'xsens_mti7_readoff.yaml', ('C102-F9R', 1): 'ublox_c102_f9r_readoff.yaml'}


def _table(number: int) -> dict:
    """Rows of table ``number`` of TABLES.md: IMU -> {column: value} (SI, X axis)."""
    text = TABLES.read_text()
    section = text.split(f'## Table {number}:')[1].split('\n## ')[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if len(cells) == 9 and re.match(r'^[0-9]', cells[1]):
            rows[cells[0]] = dict(zip(COLUMNS, map(float, cells[1:])))
    return rows


@pytest.mark.skipif(not TABLES.is_file(), reason='../shared/paper/TABLES.md is absent')
@pytest.mark.parametrize('imu,number', sorted(FILES))
def test_configs_carry_the_papers_tables(imu, number):
    row = _table(number)[imu]
    spec = load_params(REPO / 'config' / FILES[(imu, number)])
    # The paper gives the X axis only; every axis of a sensor copies it.
    for axes, kind in ((GYRO_AXES, 'gyro'), (ACCEL_AXES, 'acc')):
        for axis in axes:
            noise = spec.axes[axis]
            got = (noise.N, noise.B, noise.K, noise.T_B)
            want = tuple(row[f'{sym} {kind}'] for sym in ('N', 'B', 'K', 'T_B'))
            assert_allclose(got, want, rtol=1e-12, err_msg=f'{imu} table {number} {axis}')
