"""
Command line interface ``imu-allan`` (also ``python -m imu_allan``).

Each sub-command lives in its own ``cli_<name>.py`` module exposing
``add_parser(subparsers)`` and ``run(args) -> int``.  Contract (DESIGN.md): with
``--format json`` stdout carries exactly one JSON document, logs go to stderr, and
errors end with a non-zero exit and one clear line on stderr, never a traceback.
"""

import argparse
import importlib
import sys

from imu_allan import __version__
from imu_allan.errors import InputError

SUBCOMMANDS = ('adev', 'analyze', 'simulate', 'diagnose', 'demo')


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog='imu-allan',
        description='Allan-variance characterisation of IMU noise (N, B, K, T_B).')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name in SUBCOMMANDS:
        module = importlib.import_module(f'imu_allan.cli.{name}')
        module.add_parser(sub)
    return parser


def main(argv=None) -> int:
    """Run the CLI; return the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except InputError as exc:
        print(f'imu-allan: error: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('imu-allan: interrupted', file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 1


if __name__ == '__main__':
    sys.exit(main())
