"""
``imu-allan analyze INPUT... [--topic T] [--out DIR] [--format json]``.

Every input (rosbag2 directory, .mcap, .db3, ROS 1 .bag, CSV) is streamed through the
same :class:`~imu_allan.pipeline.Session` the node uses, fitted, and written as a
report; several inputs are analysed in parallel and compared.
"""

import argparse
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
import json
import math
import os
from pathlib import Path
import sys
import time

import numpy as np

from imu_allan import AXES
from imu_allan.analysis import analyze
from imu_allan.errors import InputError
from imu_allan.pipeline import Session, SessionConfig

CSV_SUFFIXES = ('.csv', '.csv.gz', '.txt', '.txt.gz')


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the sub-command."""
    p = subparsers.add_parser(
        'analyze', help='characterise the IMU noise of bags or CSV files',
        description='Analyse rosbag2 (sqlite3/MCAP), ROS 1 bags or CSV files of a static '
                    'IMU: Allan deviation, fitted N, B, K, T_B with 95 %% intervals, '
                    'Kalibr imu.yaml, Kalman Q/R, robot_localization covariances, plots.')
    p.add_argument('inputs', nargs='+', metavar='INPUT', help='bag directory, .mcap, .db3, '
                   '.bag or .csv[.gz] (t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z)')
    p.add_argument('--topic', help='Imu topic (needed when a bag holds several)')
    p.add_argument('--out', type=Path, default=Path('imu_allan_out'),
                   help='output directory (one sub-directory per input when several)')
    p.add_argument('--format', choices=('text', 'json'), default='text')
    p.add_argument('--rate', type=float, default=0.0,
                   help='nominal rate in Hz (default: estimated from the stamps)')
    p.add_argument('--on-motion', choices=('warn', 'pause', 'restart'), default='pause',
                   help='what to do with samples where the IMU moved')
    p.add_argument('--no-plot', action='store_true', help='skip the PNG/SVG figures')
    p.add_argument('--jobs', type=int, default=0,
                   help='parallel inputs (default: the number of cores)')
    p.set_defaults(run=run)
    return p


class _Progress:
    """A one-line progress indicator on stderr, shown when the work takes a while."""

    def __init__(self, label: str, total: int | None):
        self.label, self.total = label, total
        self.start = time.monotonic()
        self.last = 0.0
        self.tty = sys.stderr.isatty()

    def update(self, done: int) -> None:
        now = time.monotonic()
        if now - self.start < 2.0 or now - self.last < (0.2 if self.tty else 5.0):
            return
        self.last = now
        rate = done / (now - self.start)
        pct = f'{100.0 * done / self.total:5.1f}% ' if self.total else ''
        line = f'{self.label}: {pct}{done:,} messages, {rate / 1e6:.2f} M msg/s'
        print(('\r' + line) if self.tty else line, end='' if self.tty else '\n',
              file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.tty and self.last:
            print(file=sys.stderr)


def iter_blocks(path: Path, topic: str | None):
    """
    Yield (stamp_ns (n,), samples (n, 6)) blocks of an input, and its total if known.

    Returns a tuple (label, total_messages or None, generator, warnings list).
    """
    name = path.name.lower()
    if not path.exists():
        raise InputError(f'{path}: no such file or directory')
    if name.endswith(CSV_SUFFIXES):
        from imu_allan.csv_io import read_csv
        data = read_csv(path, columns=list(AXES))
        if data.t_s is None:
            raise InputError(f'{path}: a t column (seconds) is needed for analyze')
        stamp_ns = np.round(np.asarray(data.t_s, dtype=np.float64) * 1e9).astype(np.int64)

        def gen():
            step = 200_000
            for k in range(0, stamp_ns.size, step):
                yield stamp_ns[k:k + step], data.samples[k:k + step]
        return str(path), stamp_ns.size, gen(), []
    from imu_allan.bag_reader import open_imu
    source = open_imu(path, topic)
    gen = ((b.stamp_ns, b.samples) for b in source.blocks())
    return f'{path} {source.topic}', source.n_messages, gen, source.warnings


def analyze_input(path: Path, topic: str | None, config: SessionConfig, quiet: bool = False):
    """Stream one input through a Session and fit it; return (AnalysisResult, seconds)."""
    start = time.monotonic()
    warnings = []

    def warn(text):
        warnings.append(text)
        if not quiet:
            print(f'imu-allan: warning: {path.name}: {text}', file=sys.stderr)

    label, total, blocks, reader_warnings = iter_blocks(path, topic)
    session = Session(config, on_warning=warn)
    progress = _Progress(f'reading {path.name}', total)
    done = 0
    for stamp_ns, samples in blocks:
        session.add(stamp_ns, samples)
        done += stamp_ns.size
        progress.update(done)
    session.flush()
    progress.close()
    for text in reader_warnings:
        warn(text)
    if session.stats.n_received == 0:
        raise InputError(f'{path}: no Imu samples in the input')
    result = analyze(session, source=label)
    if result is None:
        raise InputError(f'{path}: too few usable samples ({session.stats.n_used}) '
                         'for any Allan deviation')
    if reader_warnings:
        result = replace(result, warnings=tuple(reader_warnings) + result.warnings)
    return result, time.monotonic() - start


def _job(args):
    path, topic, config, out, plot = args
    from imu_allan.report import write_outputs
    try:
        result, seconds = analyze_input(path, topic, config, quiet=True)
    except InputError as exc:
        return None, str(exc), [], 0.0
    files = write_outputs(result, out, plot=plot)
    return result, None, [str(f) for f in files], seconds


def spread_table(results: list, labels: list) -> tuple[str, dict]:
    """
    Run-to-run spread of N, B, K, T_B per axis (markdown table and JSON).

    Returns
    -------
    markdown : str
        One row per axis and parameter: mean, standard deviation, CV, min, max.
    data : dict
        ``{axis: {P: {'mean', 'std', 'cv', 'min', 'max', 'values'}}}``.

    """
    rows = ['| axis | param | mean | std | CV % | min | max | n |',
            '| --- | --- | --- | --- | --- | --- | --- | --- |']
    data = {}
    for axis in AXES:
        data[axis] = {}
        for sym in ('N', 'B', 'K', 'T_B'):
            vals = []
            for r in results:
                fit = r.fits.get(axis)
                p = fit.optimised.get(sym) if fit else None
                if p is not None and p.kind == 'estimate' and math.isfinite(p.value):
                    vals.append(p.value)
            if not vals:
                continue
            v = np.array(vals)
            std = float(v.std(ddof=1)) if v.size > 1 else float('nan')
            entry = {'mean': float(v.mean()), 'std': std, 'cv': std / float(v.mean()),
                     'min': float(v.min()), 'max': float(v.max()), 'values': vals}
            data[axis][sym] = entry
            rows.append(f'| {axis} | {sym} | {entry["mean"]:.4g} | {std:.3g} | '
                        f'{100 * entry["cv"]:.1f} | {entry["min"]:.4g} | {entry["max"]:.4g} | '
                        f'{v.size} |')
    return '\n'.join(rows) + '\n', data


def run(args) -> int:
    """Analyse every input; write reports; print a summary or one JSON document."""
    paths = [Path(p) for p in args.inputs]
    for p in paths:
        if not p.exists():
            raise InputError(f'{p}: no such file or directory')
    config = SessionConfig(rate_hz=args.rate, on_motion=args.on_motion)
    several = len(paths) > 1
    outs = [(args.out / _stem(p)) if several else args.out for p in paths]
    jobs = [(p, args.topic, config, o, not args.no_plot) for p, o in zip(paths, outs)]
    n_workers = args.jobs or min(len(jobs), os.cpu_count() or 1)
    if several and n_workers > 1:
        with ProcessPoolExecutor(max_workers=n_workers) as pool:
            outcomes = list(pool.map(_job, jobs))
    elif several:
        outcomes = [_job(j) for j in jobs]
    else:
        from imu_allan.report import write_outputs
        result, seconds = analyze_input(paths[0], args.topic, config)
        files = write_outputs(result, outs[0], plot=not args.no_plot)
        outcomes = [(result, None, [str(f) for f in files], seconds)]
    failed = [(p, err) for p, (_, err, _, _) in zip(paths, outcomes) if err]
    for p, err in failed:
        print(f'imu-allan: error: {err}', file=sys.stderr)
    good = [(p, o) for p, o in zip(paths, outcomes) if o[0] is not None]
    if not good:
        return 2
    comparison = None
    if several and len(good) > 1:
        from imu_allan.plot import plot_comparison
        labels = [_stem(p) for p, _ in good]
        results = [o[0] for _, o in good]
        table, data = spread_table(results, labels)
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / 'comparison.md').write_text(
            '# Run-to-run spread (optimised fit)\n\n' + table)
        files = [] if args.no_plot else [str(f) for f in plot_comparison(
            results, labels, args.out / 'comparison')]
        comparison = {'spread': data, 'files': [str(args.out / 'comparison.md')] + files}
    if args.format == 'json':
        docs = []
        for p, (result, _, files, seconds) in good:
            doc = result.to_json()
            doc['files'] = files
            doc['elapsed_s'] = seconds
            docs.append(doc)
        out = docs[0] if not several else {'results': docs, 'comparison': comparison,
                                           'errors': [e for _, e in failed]}
        json.dump(out, sys.stdout, allow_nan=False)
        sys.stdout.write('\n')
    else:
        for p, (result, _, files, seconds) in good:
            print(f'== {p}  ({result.n_samples:,} samples, {result.duration_s / 3600:.2f} h '
                  f'at {result.rate_hz:.2f} Hz, analysed in {seconds:.1f} s)')
            for line in result.summary_lines():
                print('  ' + line)
            for w in result.warnings:
                print(f'  warning: {w}')
            print(f'  files: {Path(files[0]).parent}/ ({", ".join(Path(f).name for f in files)})')
        if comparison:
            print('\n' + (args.out / 'comparison.md').read_text())
    return 2 if failed else 0


def _stem(path: Path) -> str:
    name = path.name
    for suffix in ('.gz', '.csv', '.txt', '.mcap', '.db3', '.bag'):
        name = name.removesuffix(suffix)
    return name or 'input'
