"""
``imu-allan fleet INPUT... --store DIR [--manifest F] [--scheduler ADDR] [--report DIR]``.

Characterises many recordings (a fleet's nightly static bags) on Dask: every input runs
through the same pipeline as ``imu-allan analyze``; results are appended to a Parquet
store keyed by IMU, recording start and content; the report compares each IMU with its
siblings and with its own history (:mod:`imu_allan.fleet`).  ``--report-only`` writes
the report of the store without analysing anything.  Needs the ``fleet`` extra.
"""

import argparse
import json
from pathlib import Path
import sys

from imu_allan.cli.analyze import add_input_options, session_config_from_args
from imu_allan.errors import InputError


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the sub-command."""
    p = subparsers.add_parser(
        'fleet', help='characterise many IMUs on Dask; flag changes and outliers',
        description='Analyse many static recordings (globs, directories, a manifest) on a '
                    'Dask cluster, keep every result in a Parquet store, and report the '
                    'spread of each IMU model and every IMU whose N, B or K moved.')
    p.add_argument('inputs', nargs='*', metavar='INPUT',
                   help='bags, CSV files, globs or directories (searched recursively)')
    p.add_argument('--store', type=Path, required=True, help='fleet store directory')
    p.add_argument('--manifest', type=Path,
                   help='CSV or YAML with path, imu_id and optionally model per input')
    p.add_argument('--id-pattern', metavar='REGEX',
                   help='IMU id from each path: the (?P<imu>...) group or the first one '
                        "(default: the bag's topic@frame_id)")
    p.add_argument('--model', default='default', help='IMU model of inputs without one')
    add_input_options(p, frame_id=False)   # one IMU per bag; its id is topic@frame_id
    p.add_argument('--scheduler', metavar='ADDRESS',
                   help='Dask scheduler (tcp://host:8786); default: a local cluster')
    p.add_argument('--workers', type=int, default=0,
                   help='worker processes of the local cluster (default: the cores)')
    p.add_argument('--memory-limit', default='auto', help='memory per local worker')
    p.add_argument('--retry-failed', action='store_true',
                   help='analyse inputs stored as failed again')
    p.add_argument('--report', type=Path, help='write the fleet report here')
    p.add_argument('--report-only', action='store_true', help='only write the report')
    p.add_argument('--no-plot', action='store_true', help='report without figures')
    p.add_argument('--format', choices=('text', 'json'), default='text')
    p.set_defaults(run=run)
    return p


def run(args) -> int:
    """Analyse the inputs not yet in the store, then report; print a summary."""
    from imu_allan.fleet.inputs import fleet_inputs
    from imu_allan.fleet.report import fleet_summary, json_finite, write_fleet_report
    from imu_allan.fleet.store import FleetStore

    store = FleetStore(args.store)
    summary = None
    if not args.report_only:
        from imu_allan.fleet.run import connect, run_fleet

        inputs = fleet_inputs(args.inputs, args.manifest, args.id_pattern, args.model)
        config = session_config_from_args(args)
        client, cluster = connect(args.scheduler, args.workers or None, args.memory_limit)
        print(f'imu-allan: fleet: {len(inputs)} inputs on {client.scheduler.address}',
              file=sys.stderr)

        def progress(key, status, rows):
            what = rows[0]['imu_id'] or rows[0]['path']
            note = '' if status == 'ok' else f': {rows[0]["reason"]}'
            print(f'imu-allan: fleet: {status} {what} ({Path(rows[0]["path"]).name}){note}',
                  file=sys.stderr)
        try:
            summary = run_fleet(inputs, store, client, config, args.topic,
                                args.retry_failed, on_record=progress)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    rows = store.rows()
    files = write_fleet_report(rows, args.report, plot=not args.no_plot) \
        if args.report else []
    views = fleet_summary(rows) if rows else None
    if args.format == 'json':
        doc = {'run': summary._asdict() if summary else None, 'views': views,
               'files': [str(f) for f in files]}
        json.dump(json_finite(doc), sys.stdout, indent=1, allow_nan=False)
        print()
        return 0
    if summary is not None:
        rate = summary.n_messages / summary.cpu_s if summary.cpu_s else 0.0
        print(f'{summary.n_ok} analysed, {summary.n_failed} failed, {summary.n_skipped} '
              f'already in the store, {summary.n_duplicates} duplicates; '
              f'{summary.wall_s:.1f} s wall, {summary.cpu_s:.1f} CPU s '
              f'({rate / 1e6:.2f} M messages per CPU second)')
    if views is None:
        raise InputError(f'the store {args.store} holds no results yet')
    for c in views['changes']:
        print(f'CHANGED  {c["imu_id"]} {c["axis"]} {c["param"]} x{c["ratio"]:.2f} '
              f'on {c["start"]} (z {c["z"]:.1f})')
    for o in views['outliers']:
        print(f'OUTLIER  {o["imu_id"]} {o["axis"]} {o["param"]} {o["value"]:.3g} vs fleet '
              f'{o["fleet_median"]:.3g} (z {o["z"]:.1f})')
    for f in views['failures']:
        print(f'FAILED   {f["path"]}: {f["reason"]}')
    if files:
        print(f'report: {args.report / "fleet_report.md"}')
    return 0
