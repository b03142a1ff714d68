"""
``imu-allan node``: watch and command a running imu_allan node, without a ROS install.

The same words as the node's log: ``status`` prints its latest progress or results,
``watch`` every new one until Ctrl-C, ``result`` its result.json (the ``~/result``
topic); ``save``, ``reset`` and ``diagnose`` call its services.  Over rclpy from the
venv (``make demo`` installs it), in the ROS_DOMAIN_ID of the environment.
"""

import argparse
import json
from pathlib import Path
import sys

from imu_allan.atomic import write_atomic
from imu_allan.errors import InputError

ACTIONS = {'status': "print the node's latest progress or results (~/noise_parameters)",
           'watch': 'print every new progress or result report until Ctrl-C',
           'result': "print the node's result.json (~/result), or write it with --out",
           'save': 'write the result files now (the node keeps collecting)',
           'reset': 'discard the data and start over',
           'diagnose': 'run the diagnosis in the background (result on ~/diagnosis)'}


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register the sub-command."""
    p = subparsers.add_parser(
        'node', help='watch and command a running node (status, watch, result, save ...)',
        description=__doc__.split('\n\n')[1],
        epilog='\n'.join(f'  {k:9s} {v}' for k, v in ACTIONS.items()),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('action', choices=tuple(ACTIONS), help='what to do (below)')
    p.add_argument('--node', default='/imu_allan',
                   help="the node's name with its namespace (default /imu_allan)")
    p.add_argument('--timeout', type=float, default=10.0,
                   help='seconds to wait for the node to answer [s]')
    p.add_argument('--out', type=Path, default=None,
                   help='with result: write result.json here instead of stdout')
    p.add_argument('--format', choices=('text', 'json'), default='text',
                   help='json: one JSON document on stdout')
    p.set_defaults(run=run)
    return p


def _status_lines(statuses) -> list[str]:
    """One line per status: the node's own message, named by its axis or part."""
    return [f'{s.name.rsplit(": ", 1)[-1]}: {s.message}' for s in statuses]


def run(args) -> int:
    """Run the action; return the exit code (1 when a service reports failure)."""
    if args.timeout <= 0:
        raise InputError('--timeout must be positive [s]')
    from imu_allan.ros.client import NodeClient

    with NodeClient(args.node, args.timeout) as client:
        if args.action in ('status', 'watch'):
            def show(statuses) -> None:
                if args.format == 'json':     # watch: one document per line
                    print(json.dumps([s.__dict__ for s in statuses]), flush=True)
                else:
                    print('\n'.join(_status_lines(statuses)), flush=True)
            if args.action == 'status':
                show(client.statuses())
            else:
                client.watch(show)
            return 0
        if args.action == 'result':
            text = client.result_json()
            if args.out is not None:
                write_atomic(args.out, lambda f: f.write(text), mode='w')
                print(f'imu-allan: wrote {args.out}', file=sys.stderr)
            else:
                sys.stdout.write(text)
            return 0
        ok, message = client.call(args.action)
    if args.format == 'json':
        print(json.dumps({'success': ok, 'message': message}))
    else:
        print(message)
    if not ok:
        print(f'imu-allan: {args.node}/{args.action} failed: {message}', file=sys.stderr)
    return 0 if ok else 1
