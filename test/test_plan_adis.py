"""
The planner on a real sensor (skipped without ../shared).

From the first 20 minutes of ADIS16405 run 2, the record length at which N of the two
well-behaved gyros reaches the width the whole 2.78 h run achieved, within a factor of
2.  bench/plan_adis.py runs all six runs and every axis: where the whole run's model has
terms the 20-minute one lacks, the factor of 2 is mostly not met (docs/planning.md).
"""

import sys

from conftest import REPO

sys.path.insert(0, str(REPO / 'bench'))
from plan_adis import compare_run  # noqa: E402, I100


def test_twenty_minutes_predict_the_full_run(shared_dir):
    rows = compare_run(shared_dir / 'realdata' / 'adis16405' / 'adis16405_run2.csv.gz', 20.0,
                       workers=2)
    checked = 0
    for run, axis, p, w_short, w_full, t_pred, t_full, kind, w_pred, caveat, grew in rows:
        if axis not in ('gyro_x', 'gyro_y') or p != 'N':
            continue
        assert kind == 'predicted', (axis, p)
        assert 0.5 <= t_pred / t_full <= 2.0, (axis, p, w_short, w_full, t_pred / 3600)
        assert 0.7 <= w_pred / w_full <= 1.4, (axis, p, w_pred, w_full)
        checked += 1
    assert checked == 2
