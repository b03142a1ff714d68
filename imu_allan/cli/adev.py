"""
``imu-allan adev``: Allan (or Hadamard) deviation of CSV columns with confidence bounds.

Reads a CSV (contract header ``t,gyro_x,...,accel_z``, any header with ``--column``, or a
headerless numeric file with ``--rate``), computes the curve with
:func:`imu_allan.core.allan.allan_curve` and prints a table, or with ``--format json``
exactly one JSON document on stdout: one object per column, or a list of them when
there are several.  Warnings go to stderr.
"""

import argparse
import json
import math
import sys

import numpy as np

from imu_allan import AXIS_UNITS
from imu_allan.core.allan.curve import allan_curve
from imu_allan.core.allan.taus import METHODS, tau_grid, TAU_KINDS
from imu_allan.errors import InputError
from imu_allan.io.csv_io import read_csv

# Time steps further than this from the median step count as irregular.
_IRREGULAR_REL = 0.01
# Share of irregular steps above which a warning is printed.
_IRREGULAR_SHARE = 0.001
# Work (taus x samples) above which '--taus all' warns that it will be slow.
_SLOW_WORK = 2e10


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the ``adev`` sub-command."""
    p = subparsers.add_parser(
        'adev', help='Allan deviation of CSV columns, with confidence bounds',
        description='Overlapping, non-overlapping (octave procedure) or overlapping '
                    'Hadamard deviation of one or more CSV columns, with noise-aware '
                    'chi-square confidence bounds (NIST SP 1065).')
    p.add_argument('file', metavar='FILE', help='CSV file (.csv or .csv.gz)')
    p.add_argument('--rate', type=float, default=None, metavar='HZ',
                   help='sample rate [Hz] (default: from the t column)')
    p.add_argument('--column', action='append', default=None, metavar='NAME',
                   help='column to analyse; repeat for several (default: the six axes, '
                        'or every column besides t)')
    p.add_argument('--taus', default='octave', metavar='SET',
                   help='octave, dense (10 per decade), all, or tau values in seconds '
                        'T1,T2,... (rounded to whole samples); default octave')
    p.add_argument('--method', default='overlapping', choices=METHODS,
                   help='estimator (default overlapping)')
    p.add_argument('--confidence', type=float, default=0.683, metavar='P',
                   help='two-sided confidence level of the bounds (default 0.683)')
    p.add_argument('--format', default='text', choices=('text', 'json'),
                   help='output format (default text)')
    p.set_defaults(run=run)
    return p


def parse_taus(text: str):
    """Return a tau-set name or a list of tau values [s] from the --taus argument."""
    text = text.strip()
    if text in TAU_KINDS:
        return text
    try:
        values = [float(v) for v in text.split(',') if v.strip()]
    except ValueError:
        raise InputError(f'--taus must be octave, dense, all or numbers T1,T2,... in '
                         f'seconds, got {text!r}') from None
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise InputError(f'--taus values must be positive numbers of seconds, got {text!r}')
    return values


def _check_stamps(t_s: np.ndarray, path: str) -> None:
    """Warn on stderr when the time stamps are not evenly spaced."""
    step = np.diff(t_s)
    med = float(np.median(step))
    off = np.abs(step - med) > _IRREGULAR_REL * med
    if off.mean() > _IRREGULAR_SHARE:
        mean_hz = (t_s.size - 1) / float(t_s[-1] - t_s[0])
        print(f'imu-allan: warning: {path}: irregular time stamps ({100 * off.mean():.1f}% '
              f'of steps differ from the median {med:.6g} s by more than '
              f'{100 * _IRREGULAR_REL:g}%, range {step.min():.6g} .. {step.max():.6g} s); '
              f'using the median rate {1 / med:.6g} Hz (mean rate {mean_hz:.6g} Hz; give '
              '--rate to override)', file=sys.stderr)


def _clean(values: np.ndarray) -> list:
    """JSON-safe list: NaN and infinities become null."""
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, float)]


def run(args) -> int:
    """Compute and print the curves; return the exit code."""
    if not 0.0 < args.confidence < 1.0:
        raise InputError(f'--confidence must lie strictly between 0 and 1, '
                         f'got {args.confidence:g}')
    if args.rate is not None and not (math.isfinite(args.rate) and args.rate > 0):
        raise InputError(f'--rate must be a positive number of Hz, got {args.rate:g}')
    taus = parse_taus(args.taus)
    data = read_csv(args.file, columns=args.column, rate_hz=args.rate)
    if args.rate is None and data.t_s is not None:
        _check_stamps(data.t_s, args.file)
    n = data.samples.shape[0]
    if taus == 'all' and tau_grid(n, 'all', args.method).size * float(n) > _SLOW_WORK:
        print(f'imu-allan: warning: --taus all on {n} samples is O(N^2) work and will be '
              'slow; dense (10 per decade) is usually enough', file=sys.stderr)
    curve = allan_curve(data.samples, data.rate_hz, taus=taus, method=args.method,
                        confidence=args.confidence)
    docs = []
    for a, name in enumerate(data.columns):
        docs.append({
            'column': name,
            'method': curve.method,
            'confidence': curve.confidence,
            'rate_hz': curve.rate_hz,
            'tau_s': _clean(curve.tau_s),
            'adev': _clean(curve.adev[:, a]),
            'adev_lo': _clean(curve.adev_lo[:, a]),
            'adev_hi': _clean(curve.adev_hi[:, a]),
            'n': [int(v) for v in curve.n_terms],
            'alpha': [int(v) for v in curve.alpha[:, a]],
            'edf': _clean(curve.edf[:, a]),
        })
    if args.format == 'json':
        json.dump(docs[0] if len(docs) == 1 else docs, sys.stdout, allow_nan=False)
        sys.stdout.write('\n')
        return 0
    label = {'overlapping': 'overlapping Allan', 'nonoverlapping': 'non-overlapping Allan',
             'hadamard': 'overlapping Hadamard'}[curve.method]
    print(f'{args.file}: {n} samples at {curve.rate_hz:.6g} Hz, {label} deviation, '
          f'bounds at {100 * curve.confidence:g}% confidence')
    for doc in docs:
        unit = AXIS_UNITS.get(doc['column'], '')
        print(f'\n{doc["column"]}' + (f' [{unit}]' if unit else ''))
        print(f'{"tau_s":>12} {"n":>10} {"alpha":>5} {"adev_lo":>12} {"adev":>12} '
              f'{"adev_hi":>12}')
        for row in zip(doc['tau_s'], doc['n'], doc['alpha'], doc['adev_lo'], doc['adev'],
                       doc['adev_hi']):
            cells = [f'{v:12.5g}' if v is not None else f'{"-":>12}'
                     for v in (row[3], row[4], row[5])]
            print(f'{row[0]:12.5g} {row[1]:10d} {row[2]:5d} ' + ' '.join(cells))
    return 0
