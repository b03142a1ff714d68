"""
``imu-allan analyze INPUT... [--topic T] [--out DIR] [--format json]``.

Every input (rosbag2 directory, .mcap, .db3, ROS 1 .bag, CSV) is streamed through the
same :class:`~imu_allan.pipeline.Session` the node uses, fitted, and written as a
report; several inputs are analysed in parallel and compared.

The input plumbing (open_input, stream_input, analyze_input) lives in
:mod:`imu_allan.io.inputs`.
"""

import argparse
from concurrent.futures import as_completed
from contextlib import nullcontext
from dataclasses import replace
import json
import math
import os
from pathlib import Path
import statistics
import sys
from typing import TYPE_CHECKING

from imu_allan import AXES
from imu_allan.cli.outdir import prepare_out_dir, remove_if_unused, writing
from imu_allan.core.plan.targets import DEFAULT_PROFILE, profile_targets, PROFILES
from imu_allan.errors import InputError
from imu_allan.pipeline.workers import start_workers, worker_pool

if TYPE_CHECKING:
    from imu_allan.core.noise.unit_check import DeclaredUnits
    from imu_allan.pipeline.hygiene import SessionConfig


def add_input_options(p: argparse.ArgumentParser, frame_id: bool = True) -> None:
    """Add the options of reading an input into a Session (shared with ``diagnose``)."""
    p.add_argument('--topic', help='Imu topic (needed when a bag holds several)')
    if frame_id:
        p.add_argument('--frame-id', metavar='NAME',
                       help='the IMU to read when the Imu topic carries several, told apart '
                            'by header.frame_id (needed then)')
    p.add_argument('--rate', type=float, default=0.0,
                   help='nominal rate in Hz (default: estimated from the stamps)')
    p.add_argument('--on-motion', choices=('warn', 'pause', 'restart'), default='pause',
                   help='what to do with samples where the IMU moved')
    p.add_argument('--warmup-window', type=float, default=None, metavar='SECONDS',
                   help='still time at the start (and after a sensor restart) judged for '
                        'the output settling after power-on; what had not settled is left '
                        'out, with a warning (default 30 min; 0 keeps everything)')
    p.add_argument('--units', default='', metavar='LIST',
                   help='units the input is written in, converted before the analysis: '
                        'gyro=deg/s, accel=g or accel=mg, time=ms|us|ns (a CSV t column, '
                        'or bag stamps read as one count), e.g. gyro=deg/s,accel=g; raw '
                        'counts as the value of one count (gyro=0.05deg/s,accel=3.33mg); '
                        'gyro=rad/s or accel=m/s^2 confirms SI values the unit check '
                        'doubts (default: rad/s, m/s^2 and the time unit of the format)')


def session_config_from_args(args) -> 'SessionConfig':
    """Return the SessionConfig of the options added by :func:`add_input_options`."""
    from imu_allan.core.noise.unit_check import parse_units
    from imu_allan.pipeline.hygiene import SessionConfig
    if not (math.isfinite(args.rate) and args.rate >= 0):
        raise InputError(f'--rate must be a finite number of Hz >= 0 (0: estimated), '
                         f'got {args.rate:g}')
    window = SessionConfig.warmup_window_s if args.warmup_window is None else args.warmup_window
    if not (math.isfinite(window) and window >= 0):
        raise InputError(f'--warmup-window must be a finite number of seconds >= 0, got '
                         f'{window:g}')
    return SessionConfig(rate_hz=args.rate, on_motion=args.on_motion, warmup_window_s=window,
                         units_declared=','.join(parse_units(args.units).declared))


def units_from_args(args) -> 'DeclaredUnits | None':
    """Return the units declared with ``--units`` (None when none was)."""
    from imu_allan.core.noise.unit_check import parse_units
    units = parse_units(args.units)
    return None if units.is_si and not units.declared else units


def add_target_option(p: argparse.ArgumentParser) -> None:
    """Add ``--profile`` and ``--target P=WIDTH`` (shared with ``plan``)."""
    p.add_argument('--profile', choices=tuple(PROFILES), default=DEFAULT_PROFILE,
                   help='precision targets by use: vio (= kalibr: N +-10 %%, K +-50 %%), '
                        'ekf (N +-10 %%, B and K +-25 %%), full (N, B +-10 %%, every other '
                        'term +-25 %%; the default)')
    p.add_argument('--target', action='append', default=[], metavar='P=WIDTH',
                   help='target relative 95 %% half-width of a parameter, over the '
                        "profile's, e.g. N=0.05 or K=25%% (B=none: no target)")


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the sub-command."""
    p = subparsers.add_parser(
        'analyze', help='characterise the IMU noise of bags or CSV files',
        description='Analyse rosbag2 (sqlite3/MCAP), ROS 1 bags or CSV files of a static '
                    'IMU: Allan deviation, fitted N, B, K, T_B with 95 % intervals, '
                    'Kalibr imu.yaml, Kalman Q/R, robot_localization covariances, plots.')
    p.add_argument('inputs', nargs='+', metavar='INPUT', help='bag directory, .mcap, .db3, '
                   '.bag or .csv[.gz] (t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z'
                   '[,temperature])')
    add_input_options(p)
    p.add_argument('--temperature-topic', metavar='TOPIC',
                   help='sensor_msgs/Temperature topic of a bag (default: its only one); '
                        'a CSV gives a temperature column')
    p.add_argument('--out', type=Path, default=Path('imu_allan_out'),
                   help='output directory (one sub-directory per input when several)')
    p.add_argument('--format', choices=('text', 'json'), default='text')
    p.add_argument('--no-plot', action='store_true', help='skip the PNG/SVG figures')
    p.add_argument('--jobs', type=int, default=0,
                   help='parallel inputs, or for one input the processes searching its '
                        'axes (default: the number of cores, at most 2 for one input)')
    p.add_argument('--cover-tau-max', type=float, default=100.0, metavar='SECONDS',
                   help='longest averaging time the covering white + random-walk pair of '
                        'the VINS and OpenVINS files must bound (default 100 s; a VIO '
                        'window is seconds, a GNSS outage minutes)')
    add_target_option(p)
    p.add_argument('--no-plan', action='store_true',
                   help='skip the precision plan (record length to each target)')
    p.set_defaults(run=run)
    return p


def _job(args):
    """Analyse and report one input in a worker; errors come back as one line."""
    path, topic, frame_id, config, out, plot, units, tau_max_s, plan, temp_topic = args
    from imu_allan.io.inputs import analyze_input
    from imu_allan.io.report import write_outputs
    try:
        result, seconds = analyze_input(path, topic, config, quiet=True, units=units,
                                        frame_id=frame_id, temperature_topic=temp_topic,
                                        plan=plan is not None, plan_targets=plan)
        result = replace(result, covering_tau_max_s=tau_max_s)
        with writing(out):
            files = write_outputs(result, out, plot=plot)
    except InputError as exc:
        return None, str(exc), [], 0.0
    except Exception as exc:  # noqa: B902 - one line per failed input, the others go on
        return None, f'{path}: unexpected {type(exc).__name__}: {exc}', [], 0.0
    return result, None, [str(f) for f in files], seconds


def spread_table(results: list, labels: list) -> tuple:
    """
    Run-to-run spread of N, B, K, T_B per axis (markdown table and JSON).

    Parameters
    ----------
    results : list of AnalysisResult
        One per input.
    labels : list of str
        Their names (the columns of the per-run table).

    Returns
    -------
    markdown : str
        One row per axis and parameter: every run's value, then mean, standard
        deviation, CV, min, max and the number of runs with an estimate.
    data : dict
        ``{axis: {P: {'mean', 'std', 'cv', 'min', 'max', 'values', 'unit'}}}``; values
        in SI, None where a run gives no estimate (an upper bound or not identified).

    """
    import numpy as np
    from imu_allan.core.fit.result import json_num  # scipy: not on the one-input path

    head = ['axis', 'param', 'unit'] + list(labels) + ['mean', 'std', 'CV %', 'min', 'max',
                                                       'n']
    rows = ['| ' + ' | '.join(head) + ' |', '|' + ' --- |' * len(head)]
    data: dict[str, dict] = {}
    for axis in AXES:
        data[axis] = {}
        for sym in ('N', 'B', 'K', 'T_B'):
            per_run, unit = [], ''
            for r in results:
                fit = r.fits.get(axis)
                p = fit.optimised.get(sym) if fit else None
                ok = p is not None and p.kind == 'estimate' and math.isfinite(p.value)
                per_run.append(p.value if ok and p is not None else None)
                unit = unit or (p.unit if p is not None else '')
            vals = np.array([v for v in per_run if v is not None])
            if not vals.size:
                continue
            # statistics.stdev is exact for equal values (numpy's mean of n equal
            # floats need not equal them, leaving a 1e-20 'spread').
            std = float(statistics.stdev(vals.tolist())) if vals.size > 1 else float('nan')
            mean = float(vals.mean())
            entry = {'mean': mean, 'std': json_num(std), 'cv': json_num(std / mean),
                     'min': float(vals.min()), 'max': float(vals.max()), 'values': per_run,
                     'unit': unit}
            data[axis][sym] = entry
            cells = [axis, sym, unit] + [('-' if v is None else f'{v:.4g}') for v in per_run]
            cells += [f'{mean:.4g}', f'{std:.3g}', f'{100 * std / mean:.1f}',
                      f'{entry["min"]:.4g}', f'{entry["max"]:.4g}', str(vals.size)]
            rows.append('| ' + ' | '.join(cells) + ' |')
    return '\n'.join(rows) + '\n', data


def _finite(obj):
    """Replace NaN and inf by None everywhere (strict JSON)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def _run_several(jobs: list, n_workers: int) -> list:
    """Analyse several inputs (in parallel when n_workers > 1), with a progress line."""
    from imu_allan.io.progress import Progress
    outcomes = [None] * len(jobs)
    if n_workers == 1:
        with Progress('inputs', len(jobs), unit='inputs') as bar:
            bar.update(0, stage='analysed')
            for k, job in enumerate(jobs):
                outcomes[k] = _job(job)
                bar.update(k + 1)
        return outcomes
    pool = worker_pool(n_workers)
    if pool is None:
        return _run_several(jobs, 1)
    with pool:
        # Submit (the workers fork) before the progress thread starts: forking a
        # multi-threaded process can deadlock the child.
        futures = {pool.submit(_job, job): k for k, job in enumerate(jobs)}
        with Progress('inputs', len(jobs), unit='inputs') as bar:
            bar.update(0, stage='analysed')
            for done, future in enumerate(as_completed(futures), 1):
                outcomes[futures[future]] = future.result()
                bar.update(done)
    return outcomes


def run(args) -> int:
    """Analyse every input; write reports; print a summary or one JSON document."""
    if args.jobs < 0:
        raise InputError(f'--jobs must be >= 0, got {args.jobs}')
    config = session_config_from_args(args)    # bad values: one line, before the work
    units = units_from_args(args)
    paths = [Path(p) for p in args.inputs]
    plot = not args.no_plot
    workers = args.jobs or min(2, os.cpu_count() or 1)
    if len(paths) == 1 and workers > 1 and paths[0].exists():
        # The server of the workers that search the axes and draw the figures imports
        # scipy and matplotlib on the other core while this process imports the readers
        # below and reads the input.
        start_workers(('imu_allan.io.plot_preload',) if plot else ())
    from imu_allan.io.inputs import check_path
    for p in paths:
        check_path(p)
    # Before the work: an --out that cannot take the outputs is one line now, not a
    # traceback after the analysis.
    created = prepare_out_dir(args.out, len(paths))
    try:
        code = _run(args, config, units, paths, plot, workers)
    except BaseException:
        remove_if_unused(args.out, created)
        raise
    if code:
        remove_if_unused(args.out, created)
    return code


def _run(args, config, units, paths: list, plot: bool, workers: int) -> int:
    from imu_allan.io.inputs import analyze_input
    from imu_allan.io.progress import Progress
    several = len(paths) > 1
    stems = _unique_stems(paths)
    outs = [(args.out / s) if several else args.out for s in stems]
    if not (math.isfinite(args.cover_tau_max) and args.cover_tau_max > 0):
        raise InputError(f'--cover-tau-max must be a positive number of seconds, got '
                         f'{args.cover_tau_max}')
    plan = None if args.no_plan else profile_targets(args.profile, args.target)
    jobs = [(p, args.topic, args.frame_id, config, o, plot, units, args.cover_tau_max, plan,
             args.temperature_topic) for p, o in zip(paths, outs)]
    if several:
        n_workers = max(1, args.jobs or min(len(jobs), os.cpu_count() or 1))
        outcomes = _run_several(jobs, n_workers)
    else:
        # One input: its six axes are searched on the cores (several inputs: one each).
        result, seconds = analyze_input(paths[0], args.topic, config, workers=workers,
                                        units=units, frame_id=args.frame_id,
                                        temperature_topic=args.temperature_topic,
                                        plan=plan is not None, plan_targets=plan)
        result = replace(result, covering_tau_max_s=args.cover_tau_max)
        from imu_allan.io.report import write_outputs   # scipy: imported while reading
        with Progress(paths[0].name) as bar, writing(outs[0]), \
                (worker_pool(min(workers, 2) if plot else 1) or nullcontext()) as pool:
            bar.set_stage('writing the report of')
            files = write_outputs(result, outs[0], plot=plot, pool=pool)
        outcomes = [(result, None, [str(f) for f in files], seconds)]
    failed = [err for (_, err, _, _) in outcomes if err]
    good = [(p, s, o) for p, s, o in zip(paths, stems, outcomes) if o[0] is not None]
    if not good and len(failed) == 1:
        raise InputError(failed[0])
    for err in failed:
        print(f'imu-allan: error: {err}', file=sys.stderr)
    if not good:
        raise InputError(f'none of the {len(paths)} inputs could be analysed (errors above)')
    comparison = None
    if len(good) > 1:
        with writing(args.out):
            comparison = _compare(good, args.out, plot=not args.no_plot)
    if args.format == 'json':
        docs = []
        for p, _, (result, _, files, seconds) in good:
            doc = result.to_json()
            doc['input'] = str(p)
            doc['files'] = files
            doc['elapsed_s'] = seconds
            docs.append(doc)
        out = docs[0] if not several else {'results': docs, 'comparison': comparison,
                                           'errors': failed}
        json.dump(_finite(out), sys.stdout, allow_nan=False)
        sys.stdout.write('\n')
    else:
        from imu_allan.io.report import ekf_advice
        for p, _, (result, _, files, seconds) in good:
            print(f'== {p}  ({result.n_samples:,} samples, {result.duration_s / 3600:.2f} h '
                  f'at {result.rate_hz:.2f} Hz, analysed in {seconds:.1f} s)')
            for line in result.summary_lines():
                print('  ' + line)
            for axis, axis_plan in result.plans.items():
                print(f'  {axis} plan: {axis_plan.progress_line()}')
            for w in result.warnings:
                print(f'  warning: {w}')
            if ekf_advice(result):
                print(f'  {ekf_advice(result)}')
            print(f'  files: {Path(files[0]).parent}/ ({", ".join(Path(f).name for f in files)})')
        if comparison:
            print('\n' + (args.out / 'comparison.md').read_text())
    return 2 if failed else 0


def _compare(good: list, out: Path, plot: bool) -> dict:
    """Write comparison.md (spread table) and the comparison plot; return the JSON part."""
    labels = [stem for _, stem, _ in good]
    results = [o[0] for _, _, o in good]
    table, data = spread_table(results, labels)
    out.mkdir(parents=True, exist_ok=True)
    text = ('# Run-to-run spread of the optimised fit\n\n'
            'Per-run values are the estimates of each input ("-": only an upper bound or not '
            'identified); mean, std (n - 1), CV, min, max over the runs with an estimate. '
            'SI units.\n\n' + table)
    (out / 'comparison.md').write_text(text)
    files = [str(out / 'comparison.md')]
    if plot:
        from imu_allan.io.plot import plot_comparison
        files += [str(f) for f in plot_comparison(results, labels, out / 'comparison')]
    return {'labels': labels, 'spread': data, 'files': files}


def _stem(path: Path) -> str:
    name = path.name
    for suffix in ('.gz', '.csv', '.txt', '.mcap', '.db3', '.bag'):
        name = name.removesuffix(suffix)
    return name or 'input'


def _unique_stems(paths: list) -> list:
    """Output sub-directory names: the inputs' stems, numbered where they clash."""
    stems = [_stem(p) for p in paths]
    seen: dict[str, int] = {}
    out = []
    for s in stems:
        seen[s] = seen.get(s, 0) + 1
        out.append(s if stems.count(s) == 1 else f'{s}_{seen[s]}')
    return out
