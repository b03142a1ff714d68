"""
``imu-allan diagnose INPUT [--topic T] [--base-model LIST] [--out DIR] [--format json]``.

Streams the input through the same :class:`~imu_allan.pipeline.Session` as
``analyze`` (the input-opening code of :mod:`imu_allan.cli.analyze` is reused), keeps a
bounded block-averaged copy of the samples for the periodogram check, and runs
:func:`imu_allan.core.diagnose.diagnose_session`.  Writes ``diagnose.json``,
``diagnose_table.md`` (the paper's table 3: gap before and after) and one figure per
axis (``diagnose_<axis>.png``) to ``--out``.
"""

import argparse
import json
from pathlib import Path
import sys

from imu_allan.cli.analyze import add_input_options, session_config_from_args, units_from_args
from imu_allan.cli.outdir import prepare_out_dir, remove_if_unused, writing
from imu_allan.core.diagnose.engine import base_terms, DEFAULT_BASE, diagnose_session, EFFECTS
from imu_allan.core.diagnose.replicas import N_REPLICAS
from imu_allan.errors import InputError
from imu_allan.io.inputs import open_input, raw_tap, stream_input
from imu_allan.io.progress import Progress
from imu_allan.pipeline.hygiene import SessionConfig


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the sub-command."""
    p = subparsers.add_parser(
        'diagnose', help='find what the noise model misses (simulation vs measurement)',
        description='Fit the base noise model per axis, simulate it, compare its Allan '
                    'deviation with the measured one, name the missing effect (' +
                    ', '.join(EFFECTS) + '), add it, and repeat until consistent.')
    p.add_argument('input', metavar='INPUT', type=Path,
                   help='bag directory, .mcap, .db3, .bag or .csv[.gz]')
    add_input_options(p)
    p.add_argument('--base-model', default=','.join(DEFAULT_BASE),
                   help='comma-separated base-model terms (default %(default)s: the '
                        "paper's white noise, Gauss-Markov bias instability, random walk; "
                        'the old name gauss_markov is read as bias_instability)')
    p.add_argument('--out', type=Path, default=Path('imu_allan_diagnose'),
                   help='output directory')
    p.add_argument('--format', choices=('text', 'json'), default='text')
    p.add_argument('--replicas', type=int, default=N_REPLICAS,
                   help='simulated replicas per model (default %(default)s)')
    p.add_argument('--seed', type=int, default=0, help='seed of the simulation')
    p.add_argument('--no-plot', action='store_true', help='skip the figures')
    p.set_defaults(run=run)
    return p


def _base_model(text: str) -> tuple:
    names = tuple(n.strip() for n in text.split(',') if n.strip())
    if not names:
        raise InputError('--base-model needs at least one term')
    try:
        return base_terms(names)
    except InputError as exc:
        raise InputError(f'--base-model: {exc}') from None


def diagnose_input(path: Path, topic: str | None, config: SessionConfig, base_model,
                   n_replicas: int = N_REPLICAS, seed: int = 0, quiet: bool = False,
                   units=None, frame_id: str | None = None):
    """
    Stream one input through a Session with a raw copy and diagnose it.

    Returns
    -------
    imu_allan.core.diagnose.DiagnoseResult
        The diagnosis.

    """
    def warn(text):
        if not quiet:
            print(f'imu-allan: warning: {path.name}: {text}', file=sys.stderr)

    keep_raw, keeper = raw_tap()

    with open_input(path, topic, units, frame_id) as source, \
            Progress(path.name, source.n_messages) as progress:
        session = stream_input(source, config, on_warning=warn, progress=progress,
                               tap=keep_raw)
        progress.set_stage('diagnosing')
        for text in source.warnings:
            warn(text)
        if session.stats.n_received == 0:
            raise InputError(f'{path}: no Imu samples in the input')
        if not quiet:
            print(f'imu-allan: diagnosing {session.stats.n_used:,} samples '
                  f'({n_replicas} simulated replicas per model) ...', file=sys.stderr)
        result = diagnose_session(session, keeper, base_model=base_model, seed=seed,
                                  n_replicas=n_replicas, source=source.label)
    if result is None:
        raise InputError(f'{path}: too few usable samples ({session.stats.n_used}) '
                         'for any Allan deviation')
    return result


def write_diagnosis_files(result, out: Path, plot: bool = True) -> list:
    """Write diagnose.json, diagnose_table.md and the per-axis figures; return the paths."""
    out.mkdir(parents=True, exist_ok=True)
    files = []
    doc = result.to_json()
    path = out / 'diagnose.json'
    path.write_text(json.dumps(doc, indent=1, allow_nan=False) + '\n')
    files.append(path)
    path = out / 'diagnose_table.md'
    path.write_text('# Gap between simulated and measured Allan deviation\n\n'
                    'gap = RMS over tau of (ln ADEV_meas - ln ADEV_sim) / s(tau); '
                    '~1 = consistent\n\n' + result.table_markdown() + '\n'
                    + '\n'.join(result.summary_lines()) + '\n')
    files.append(path)
    if plot:
        from imu_allan.io.plot import plot_diagnosis
        for axis, d in result.axes.items():
            if d is not None:
                files.append(plot_diagnosis(d, out / f'diagnose_{axis}.png'))
    return files


def run(args) -> int:
    """Diagnose the input; write the outputs; print the summary or one JSON document."""
    base = _base_model(args.base_model)
    if args.replicas < 1:
        raise InputError(f'--replicas must be >= 1, got {args.replicas}')
    if not args.input.exists():
        raise InputError(f'{args.input}: no such file or directory')
    config = session_config_from_args(args)
    units_from_args(args)                   # a bad --units: one line, before the work
    created = prepare_out_dir(args.out)     # before the minutes of the diagnosis
    try:
        return _run(args, config, base)
    except BaseException:
        remove_if_unused(args.out, created)
        raise


def _run(args, config: SessionConfig, base: tuple) -> int:
    result = diagnose_input(args.input, args.topic, config, base, args.replicas, args.seed,
                            quiet=args.format == 'json', units=units_from_args(args),
                            frame_id=args.frame_id)
    if all(d is None for d in result.axes.values()):
        raise InputError(f'{args.input}: no axis could be diagnosed (frozen, constant or too '
                         f'short: {result.n_samples} samples)')
    with writing(args.out):
        files = write_diagnosis_files(result, args.out, plot=not args.no_plot)
    if args.format == 'json':
        doc = result.to_json()
        doc['files'] = [str(f) for f in files]
        json.dump(doc, sys.stdout, allow_nan=False)
        sys.stdout.write('\n')
    else:
        print(f'== {args.input}  ({result.n_samples:,} samples, '
              f'{result.duration_s / 3600:.2f} h at {result.rate_hz:.2f} Hz)')
        for line in result.summary_lines():
            print('  ' + line)
        print()
        print(result.table_markdown())
        for w in result.warnings:
            print(f'  warning: {w}')
        print(f'  files: {args.out}/ ({", ".join(Path(f).name for f in files)})')
    return 0
