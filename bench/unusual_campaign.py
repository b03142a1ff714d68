r"""
The campaign of valid-but-unusual inputs: run ``imu-allan analyze`` on each, judge it.

Usage (from the repository)::

    nice -n 5 .venv/bin/python bench/unusual_campaign.py --seed 1 --rounds 4 --node 2

Every case of :func:`unusual.cases` (``--rounds`` draws of each class, ``--classes``)
is written to a temporary folder and analysed by ``imu-allan analyze INPUT [--frame-id
NAME | --topic T] --no-plot --no-plan --format json --jobs 1`` in this process
(:func:`imu_allan.cli.main`, stdout and stderr captured, any exception that escapes it
caught).  The outcome is one of

* ``ok``: analysed, no warning beyond the ones every short clean record has
  (:data:`ROUTINE`), and the figures hold (below);
* ``warned``: analysed with another warning, and every figure that misses its truth
  is named by a warning with a word of the case's cause;
* ``refused``: exit 2 or 3 with one line ``imu-allan: error: ...``;

and the failures

* ``SILENT LOSS``: fewer messages used than the truth or the reference library gives
  (``hygiene.n_read``, ``n_used`` below 99 % of ``n_read``) with no new warning, or a
  case whose data is partly gone (a missing split file) analysed without a warning
  naming that;
* ``WRONG RESULT``: a figure off its truth with no warning naming the cause: N of an
  axis whose 95 % interval, widened by :data:`N_TOL` either way, excludes the
  simulated N (an upper bound: below it by that much); the rate off by more than 2 %
  or the span by more than 5 %; more messages than the source has;
* ``TRACEBACK``: any exception out of ``main``, a traceback on stderr, or an error of
  more than one line;
* ``UNEXPECTED``: an outcome the case does not allow (a usable input refused; two
  sources or two topics analysed without being chosen; an axis of zeros or integer
  counts analysed without a word about them).

``--node`` rounds of the node situations of bench/unusual_node.py (SIGTERM during a
fit, sim time without a clock) add a row ``node``.

Printed: the Markdown table of docs/limits.md (counts per class and outcome), then
every failure with its figures.  Exits 1 when there is one.
"""

import argparse
from collections import Counter
import contextlib
import io
import json
import math
import os
from pathlib import Path
import sys
import tempfile
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
# This checkout's package first, then bench/ for unusual.
sys.path[:0] = [str(Path(__file__).resolve().parents[1]), str(Path(__file__).resolve().parent)]
import unusual  # noqa: E402, I100

AXES = ('gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z')
OUTCOMES = ('ok', 'warned', 'refused', 'SILENT LOSS', 'WRONG RESULT', 'TRACEBACK',
            'UNEXPECTED')
FAILURES = OUTCOMES[3:]
#: Warnings every short clean record has: they name no input problem.
ROUTINE = ('record too short',)
#: Widening of a reported N interval either way before the truth counts as outside it:
#: a clean 2 min record's 95 % interval of N is about +-2 % and misses the truth in one
#: axis of 20 by chance; the faults the campaign is for are factors of 0.2 to 2.
N_TOL = 1.1
#: Rate and span within these shares of the truth.
RATE_TOL, SPAN_TOL = 0.02, 0.05


def analyze(path: Path, args: list, out: Path) -> tuple:
    """Run ``imu-allan analyze`` in this process; return (code, stdout, stderr, exception)."""
    from imu_allan.cli import main
    stdout, stderr = io.StringIO(), io.StringIO()
    exc = None
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            code = main(['analyze', str(path), *args, '--out', str(out), '--no-plot',
                         '--no-plan', '--format', 'json', '--jobs', '1'])
        except BaseException as err:  # noqa: B902 - whatever escapes main is the finding
            code, exc = -1, f'{type(err).__name__}: {err}'
    return code, stdout.getvalue(), stderr.getvalue(), exc


def _names(text: str, words: tuple) -> bool:
    text = text.lower()
    return any(w in text for w in words)


def _about(warning: str, axis: str) -> bool:
    """Tell whether a warning is about an axis: names it, its sensor alone, or no sensor."""
    w = warning.lower()
    if axis in w:
        return True
    if 'gyro' not in w and 'accel' not in w:
        return True
    return axis.split('_')[0] in w and not any(a in w for a in AXES)


def _n_misses(entry: dict, truth: float) -> str:
    """Return how a reported N misses its truth ('' when it does not)."""
    p = entry.get('params', {}).get('N')
    if not p or p.get('value') is None:
        return ''
    value = p['value']
    lo, hi = p.get('ci95') or (None, None)
    kind = p['kind']
    if kind == 'estimate':
        lo, hi = (value if lo is None else lo), (math.inf if hi is None else hi)
    elif kind == 'upper_bound':
        lo, hi = 0.0, value
    elif kind == 'lower_bound':
        lo, hi = value, math.inf
    else:
        return ''
    if lo / N_TOL <= truth <= hi * N_TOL:
        return ''
    return f'N {value:.3g} [{lo:.3g}, {hi:.3g}] ({kind}) vs truth {truth:.3g}'


def judge(case: 'unusual.Case', path: Path, ran: tuple, n_ref: int) -> tuple:
    """Return (outcome, note) of one case's run (the module docstring's rules)."""
    code, stdout, stderr, exc = ran
    if exc is not None or 'Traceback (most recent call last)' in stderr:
        return 'TRACEBACK', exc or stderr[-400:]
    if code != 0:
        errors = [ln for ln in stderr.splitlines() if ln.startswith('imu-allan: error:')]
        try:
            message = json.loads(stdout)['error']
        except (ValueError, KeyError, TypeError):
            return 'TRACEBACK', f'exit {code} without its JSON document: {stderr[-300:]}'
        if '\n' in message or len(errors) != 1:
            return 'TRACEBACK', f'an error of several lines: {message!r}'
        if 'refused' in case.allow:
            return 'refused', message
        return 'UNEXPECTED', f'refused: {message}'
    doc = json.loads(stdout)
    new = [w for w in doc['warnings'] if not _names(w, ROUTINE)]
    named = [w for w in new if _names(w, case.cause)]
    hyg = doc['hygiene']
    n_read, n_used = hyg['n_read'], hyg['n_used']
    notes = []
    if n_read is not None and n_read < max(case.n_truth, n_ref) and not new:
        return 'SILENT LOSS', f'read {n_read}, truth {case.n_truth}, reference {n_ref}'
    if n_used < 0.99 * (n_read or n_used) and not new:
        return 'SILENT LOSS', f'used {n_used} of {n_read} read'
    if n_read is not None and n_read > case.n_truth and not new:
        notes.append(f'read {n_read} of a source of {case.n_truth}')
    rate, span = doc['sample_rate_hz'], doc['duration_s']
    if abs(rate / case.rate_hz - 1) > RATE_TOL and not named:
        notes.append(f'rate {rate:.6g} Hz vs {case.rate_hz:g}')
    if abs(span / case.duration_s - 1) > SPAN_TOL and not named:
        notes.append(f'span {span:.6g} s vs {case.duration_s:.6g}')
    for axis, truth in zip(AXES, case.n_axes):
        miss = '' if truth is None else _n_misses(doc['axes'].get(axis, {}), truth)
        if miss and not any(_about(w, axis) for w in named):
            notes.append(f'{axis} {miss}')
    if notes:
        return 'WRONG RESULT', '; '.join(notes) + f' (warnings: {new})'
    outcome = 'warned' if new else 'ok'
    if 'ok' not in case.allow and not named:
        outcome = 'ok'      # its warnings are not about this case's cause
    if outcome in case.allow:
        return outcome, '; '.join(new)[:300]
    if case.loss:
        return 'SILENT LOSS', f'no warning naming {case.cause} (warnings: {new})'
    return 'UNEXPECTED', f'{outcome} where {case.allow} (warnings: {new})'


def run_case(case: 'unusual.Case', folder: Path) -> tuple:
    """Write, count with the reference library, analyse and judge one case."""
    folder.mkdir(parents=True)
    try:
        path = case.build(folder)
        n_ref = unusual.reference_count(path, case.topic, case.frame)
    except Exception as err:  # noqa: B902 - a case that cannot be written is a bench bug
        return 'TRACEBACK', f'writing the case: {type(err).__name__}: {err}'
    return judge(case, path, analyze(path, case.args, folder / 'out'), n_ref)


def campaign(seed: int, rounds: int, classes, folder: Path, log=None) -> dict:
    """Run every case; return {'table': {class: Counter}, 'failures': [...], 'cases': n}."""
    table: dict = {k: Counter() for k in classes}
    failures = []
    all_cases = unusual.cases(seed, rounds, classes)
    for k, case in enumerate(all_cases):
        start = time.monotonic()
        outcome, note = run_case(case, folder / f'case_{k}')
        table[case.klass][outcome] += 1
        if outcome in FAILURES:
            failures.append((case.klass, case.name, outcome, note))
        if log is not None:
            print(f'{case.klass:9s} {case.name:45s} {outcome:12s} '
                  f'{time.monotonic() - start:5.1f} s  {note[:160]}', file=log, flush=True)
    return {'table': table, 'failures': failures, 'cases': len(all_cases)}


def node_campaign(rounds: int, seed: int, folder: Path, result: dict, log=None) -> None:
    """Run the node situations of bench/unusual_node.py; add a 'node' row to a result."""
    import unusual_node
    counts: Counter = Counter()
    for k, (kind, case_seed) in enumerate(unusual_node.node_cases(rounds, seed)):
        start = time.monotonic()
        try:
            outcome, note = unusual_node.node_case(kind, case_seed, folder / f'node_{k}')
        except Exception as err:  # noqa: B902 - the bench's own failure, said as one
            outcome, note = 'TRACEBACK', f'the bench: {type(err).__name__}: {err}'
        counts[outcome] += 1
        if outcome in FAILURES:
            result['failures'].append(('node', f'{kind}_{case_seed}', outcome, note))
        if log is not None:
            print(f'{"node":9s} {kind + "_" + str(case_seed):45s} {outcome:12s} '
                  f'{time.monotonic() - start:5.1f} s  {note[:160]}', file=log, flush=True)
    result['table']['node'] = counts
    result['cases'] += sum(counts.values())


def markdown(table: dict) -> str:
    """Return the table of counts per class and outcome as Markdown."""
    total: Counter = Counter()
    lines = ['| class | ' + ' | '.join(OUTCOMES) + ' |', '|---' * (len(OUTCOMES) + 1) + '|']
    for klass, counts in table.items():
        total.update(counts)
        lines.append(f'| {klass} | ' + ' | '.join(str(counts.get(c, 0)) for c in OUTCOMES)
                     + ' |')
    lines.append('| **all** | ' + ' | '.join(f'**{total.get(c, 0)}**' for c in OUTCOMES)
                 + ' |')
    return '\n'.join(lines)


def main() -> int:
    """Run the campaign and print its table and failures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--rounds', type=int, default=4, help='draws of each class')
    parser.add_argument('--classes', nargs='+', default=list(unusual.CLASSES),
                        choices=unusual.CLASSES)
    parser.add_argument('--node', type=int, default=2, metavar='ROUNDS',
                        help='draws of each node situation (bench/unusual_node.py; 0: none)')
    parser.add_argument('--quiet', action='store_true', help='no line per case on stderr')
    args = parser.parse_args()
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix='imu_allan_unusual_') as tmp:
        log = None if args.quiet else sys.stderr
        result = campaign(args.seed, args.rounds, args.classes, Path(tmp), log=log)
        if args.node:
            node_campaign(args.node, args.seed, Path(tmp), result, log=log)
    print(markdown(result['table']))
    print(f'{result["cases"]} cases (seed {args.seed}, {args.rounds} rounds, {args.node} of the '
          f'node) in '
          f'{time.monotonic() - start:.0f} s')
    for failure in result['failures']:
        print('FAILURE', *failure)
    return 1 if result['failures'] else 0


if __name__ == '__main__':
    sys.exit(main())
