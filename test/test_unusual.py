"""
Valid-but-unusual inputs against their truth: a small seeded set of the campaign.

``bench/unusual.py`` generates the inputs (several IMUs on one topic, other channels,
split bags, odd stamp clocks, rates, values) with their truth, and
``bench/unusual_campaign.py`` runs ``imu-allan analyze`` on each and judges the outcome
(ok, warned, refused with one line; the failures silent loss, wrong result, traceback,
unexpected).  Here two cases of each class of seed 2026 run, on records half as long
(about 35 s of CPU); the bench runs every class four times (docs/limits.md has its
table).
"""

import json
import sys

import numpy as np
import pytest

from conftest import REPO  # noqa: I100
sys.path.insert(0, str(REPO / 'bench'))
import unusual  # noqa: E402, I100, I201
import unusual_campaign as camp  # noqa: E402, I100

SEED = 2026
#: Cases per class run here (the first ones the seed draws), and their record length
#: as a share of the bench's (1 min at 100 Hz instead of 2).
PER_CLASS, LENGTH = 2, 0.5


def _small() -> list:
    by_class: dict = {}
    for case in unusual.cases(SEED, 1, length=LENGTH):
        by_class.setdefault(case.klass, []).append(case)
    return [c for k in unusual.CLASSES for c in by_class[k][:PER_CLASS]]


@pytest.mark.parametrize('case', _small(), ids=lambda c: c.name)
def test_an_unusual_input_is_analysed_right_or_warned_or_refused(case, tmp_path):
    outcome, note = camp.run_case(case, tmp_path / 'case')
    assert outcome not in camp.FAILURES, note
    assert outcome in case.allow


def test_cases_are_seeded_and_cover_every_class():
    a, b = unusual.cases(SEED, 2), unusual.cases(SEED, 2)
    assert [c.name for c in a] == [c.name for c in b]
    assert {c.klass for c in a} == set(unusual.CLASSES)
    assert len({c.name for c in a}) == len(a)
    assert [c.name for c in unusual.cases(SEED + 1, 2)] != [c.name for c in a]


def test_the_reference_counts_each_source_and_file(tmp_path):
    case = next(c for c in unusual.cases(SEED, 1, length=LENGTH) if '_pick_' in c.name)
    path = case.build(tmp_path)
    assert unusual.reference_count(path, case.topic, case.frame) == case.n_truth
    k = int(case.name[0])
    assert unusual.reference_count(path, case.topic) == k * case.n_truth, case.name
    assert unusual.reference_count(path, '/other') == 0


def _doc(n_read=12000, n_used=12000, n_gx=1.5e-4, warnings=()) -> str:
    axes = {a: {'params': {'N': {'value': v, 'ci95': [v * 0.98, v * 1.02],
                                 'kind': 'estimate'}}}
            for a, v in zip(camp.AXES, [n_gx] + unusual.truth_n()[1:])}
    return json.dumps({'warnings': list(warnings), 'sample_rate_hz': 100.0,
                       'duration_s': 120.0, 'axes': axes,
                       'hygiene': {'n_read': n_read, 'n_used': n_used}})


def test_the_judge_can_fail():
    case = unusual.Case('c', 'values', lambda f: f, unusual.truth_n(), 100.0, 120.0, 12000,
                        cause=('clip',))
    assert camp.judge(case, None, (0, _doc(), '', None), 12000)[0] == 'ok'
    assert camp.judge(case, None, (0, _doc(n_gx=3e-4), '', None), 12000)[0] == 'WRONG RESULT'
    named = ['gyro_x is clipped: ...']
    assert camp.judge(case, None, (0, _doc(n_gx=3e-4, warnings=named), '', None),
                      12000)[0] == 'warned'
    other = ['accel_z is clipped: ...']
    assert camp.judge(case, None, (0, _doc(n_gx=3e-4, warnings=other), '', None),
                      12000)[0] == 'WRONG RESULT'
    assert camp.judge(case, None, (0, _doc(n_read=11000), '', None), 12000)[0] == \
        'SILENT LOSS'
    assert camp.judge(case, None, (0, _doc(n_used=11000), '', None), 12000)[0] == \
        'SILENT LOSS'
    assert camp.judge(case, None, (0, _doc(), '', None), 13000)[0] == 'SILENT LOSS'
    assert camp.judge(case, None, (-1, '', '', 'ValueError: x'), 12000)[0] == 'TRACEBACK'
    error = json.dumps({'error': 'a\nb', 'exit_code': 2})
    assert camp.judge(case, None, (2, error, 'imu-allan: error: a\nb', None),
                      12000)[0] == 'TRACEBACK'
    error = json.dumps({'error': 'bad', 'exit_code': 2})
    assert camp.judge(case, None, (2, error, 'imu-allan: error: bad', None),
                      12000)[0] == 'UNEXPECTED'
    refusable = unusual.Case('c', 'values', lambda f: f, [None] * 6, 100.0, 120.0, 12000,
                             allow=('refused',), cause=('frame_id',))
    assert camp.judge(refusable, None, (2, error, 'imu-allan: error: bad', None),
                      12000)[0] == 'refused'
    assert camp.judge(refusable, None, (0, _doc(), '', None), 12000)[0] == 'UNEXPECTED'
    lost = unusual.Case('c', 'split', lambda f: f, unusual.truth_n(), 100.0, 120.0, 12000,
                        allow=('warned',), cause=('missing',), loss=True)
    assert camp.judge(lost, None, (0, _doc(warnings=['gap of 2 s']), '', None),
                      12000)[0] == 'SILENT LOSS'


def test_a_two_source_case_truth_is_the_chosen_source():
    case = next(c for c in unusual.cases(SEED, 1, length=LENGTH) if '_pick_' in c.name)
    k = unusual.FRAMES.index(case.frame)
    np.testing.assert_allclose(case.n_axes, unusual.truth_n(1.0 + 2.0 * k), rtol=0)
