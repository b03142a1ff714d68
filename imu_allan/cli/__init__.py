"""
Command line interface ``imu-allan`` (also ``python -m imu_allan``).

Each sub-command lives in its own ``cli_<name>.py`` module exposing
``add_parser(subparsers)`` and ``run(args) -> int``.  Contract (docs/contracts.md): with
``--format json`` stdout carries exactly one JSON document, logs go to stderr, and
errors end with a non-zero exit and one clear line on stderr, never a traceback.
"""

import argparse
import importlib
import sys

from imu_allan import __version__
from imu_allan.errors import InputError
from imu_allan.pipeline.workers import one_blas_thread

SUBCOMMANDS = ('adev', 'analyze', 'simulate', 'diagnose', 'fleet', 'demo', 'plan')
#: Every command: (module in SUBCOMMANDS, one-line help).  Only the module of the command
#: that runs is imported, so ``imu-allan --help`` loads neither numpy nor scipy.
COMMANDS = {
    'adev': ('adev', 'Allan deviation of CSV columns, with confidence bounds'),
    'analyze': ('analyze', 'characterise the IMU noise of bags or CSV files'),
    'simulate': ('simulate', 'simulate an IMU record from a noise-parameter YAML'),
    'csv-to-bag': ('simulate', 'convert a CSV IMU log into a bag of sensor_msgs/Imu'),
    'diagnose': ('diagnose', 'find what the noise model misses (simulation vs measurement)'),
    'fleet': ('fleet', 'characterise many IMUs on Dask; flag changes and outliers'),
    'demo': ('demo', 'run the node on a simulated IMU (make demo)'),
    'plan': ('plan', 'how long to record: expected interval widths and time to targets'),
}


def build_parser(argv=None) -> argparse.ArgumentParser:
    """
    Build the top-level parser; only the chosen command's module fills in its options.

    Parameters
    ----------
    argv : list of str, optional
        The arguments about to be parsed (default ``sys.argv[1:]``): the first one that
        names a command selects the module to import.

    Returns
    -------
    argparse.ArgumentParser
        The parser.

    """
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    chosen = next((a for a in argv if a in COMMANDS), None)
    wanted = COMMANDS[chosen][0] if chosen else None
    parser = argparse.ArgumentParser(
        prog='imu-allan',
        description='Allan-variance characterisation of IMU noise (N, B, K, T_B).')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name in SUBCOMMANDS:
        if name == wanted:
            importlib.import_module(f'imu_allan.cli.{name}').add_parser(sub)
            continue
        for command, (module, text) in COMMANDS.items():
            if module == name:
                sub.add_parser(command, help=text, add_help=False)
    return parser


def main(argv=None) -> int:
    """Run the CLI; return the process exit code."""
    one_blas_thread()       # before the command's module loads numpy
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except InputError as exc:
        print(f'imu-allan: error: {exc}', file=sys.stderr)
        return getattr(exc, 'exit_code', 2)     # NotEnoughStillData: 3
    except KeyboardInterrupt:
        print('imu-allan: interrupted', file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 1


def entry() -> None:
    """Run the CLI as the ``imu-allan`` program (console script, ``python -m imu_allan``)."""
    sys.exit(main())


if __name__ == '__main__':
    entry()
