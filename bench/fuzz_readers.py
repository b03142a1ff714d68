"""
The readers' fuzz campaign at scale: more mutated files than ``make test`` runs.

Usage: ``.venv/bin/python bench/fuzz_readers.py [--cases 500] [--seed 1]
[--kinds mcap_zstd ...]``.  Runs :func:`campaign` of test/test_fuzz_readers.py (the
files, mutations, reference readers and outcome classes are described there) with
``--cases`` mutated files per kind, prints the count of outcomes per kind and class as
the Markdown table of docs/limits.md, then every failure (class ``silent`` or
``traceback``) with its kind, mutation and case number.  Exits 1 when there is one.
"""

import argparse
from collections import Counter
from pathlib import Path
import sys
import tempfile
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

import test_fuzz_readers as fuzz  # noqa: E402, I100 - the campaign lives with its test

CLASSES = ('same', 'complete', 'warned', 'more', 'error', 'silent', 'traceback')


def main() -> int:
    """Run the campaign and print its table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--cases', type=int, default=500, help='mutated files per kind')
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--kinds', nargs='+', default=list(fuzz.KINDS), choices=fuzz.KINDS)
    args = parser.parse_args()
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix='imu_allan_fuzz_') as tmp:
        fuzz._folders(Path(tmp), args.kinds)
        result = fuzz.campaign(args.kinds, args.cases, args.seed, Path(tmp))
    total: Counter = Counter()
    print('| input | ' + ' | '.join(CLASSES) + ' |')
    print('|---' * (len(CLASSES) + 1) + '|')
    for kind, counts in result['table'].items():
        total.update(counts)
        print(f'| {kind} | ' + ' | '.join(str(counts.get(c, 0)) for c in CLASSES) + ' |')
    print('| **all** | ' + ' | '.join(f'**{total.get(c, 0)}**' for c in CLASSES) + ' |')
    print(f'{sum(total.values())} mutated files (seed {args.seed}) in '
          f'{time.perf_counter() - start:.0f} s')
    for failure in result['failures']:
        print('FAILURE', *failure)
    return 1 if result['failures'] else 0


if __name__ == '__main__':
    sys.exit(main())
