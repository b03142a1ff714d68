"""
Command line interface ``imu-allan`` (also ``python -m imu_allan``).

Each sub-command lives in its own ``cli_<name>.py`` module exposing
``add_parser(subparsers)`` and ``run(args) -> int``.  Contract (docs/contracts.md): with
``--format json`` stdout carries exactly one JSON document, logs go to stderr, and
errors end with a non-zero exit and one clear line on stderr, never a traceback; with
``--format json`` a failure's document is ``{"error": ..., "exit_code": ...}``.  A
command that returns a non-zero code has written its document itself.  Ctrl-C ends any
command with the line ``imu-allan: interrupted`` and exit code 130.
"""

import argparse
import importlib
import signal
import sys

from imu_allan import __version__
from imu_allan.errors import InputError
from imu_allan.pipeline.workers import one_blas_thread

SUBCOMMANDS = ('adev', 'analyze', 'simulate', 'diagnose', 'fleet', 'demo', 'plan', 'node')
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
    'node': ('node', 'watch and command a running node (status, watch, result, save ...)'),
}


class _UsageError(Exception):
    """A command line argparse refuses: (the line to print, argparse's message)."""


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors come back to :func:`main` (sub-parsers inherit it)."""

    def error(self, message):
        self.print_usage(sys.stderr)
        raise _UsageError(f'{self.prog}: error: {message}', message)


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
    parser = _Parser(
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


def wants_json(argv: list) -> bool:
    """
    Tell whether a command line asks for ``--format json`` (read before it is parsed).

    Parameters
    ----------
    argv : list of str
        The arguments; ``--format json``, ``--format=json`` and argparse's
        abbreviations (``--form json``) count.

    Returns
    -------
    bool
        True when the last ``--format`` given is ``json``.

    """
    fmt = None
    for k, arg in enumerate(argv):
        name, eq, value = arg.partition('=')
        if len(name) > 3 and '--format'.startswith(name):
            fmt = value if eq else (argv[k + 1] if k + 1 < len(argv) else None)
        elif arg == '--':
            break
    return fmt == 'json'


def _fail(line: str, message: str, code: int, json_out: bool) -> int:
    """
    Report a failure: one line on stderr and, for ``--format json``, one JSON object.

    The object, ``{"error": message, "exit_code": code}``, is all of stdout, so a pipe
    into ``jq`` reads the failure instead of an empty document.
    """
    print(line, file=sys.stderr)
    if json_out:
        import json
        try:
            json.dump({'error': message, 'exit_code': code}, sys.stdout)
            sys.stdout.write('\n')
            sys.stdout.flush()
        except (BrokenPipeError, ValueError):   # the reader is gone, or stdout closed
            pass
    return code


def main(argv=None) -> int:
    """Run the CLI; return the process exit code."""
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    json_out = wants_json(argv)
    one_blas_thread()       # before the command's module loads numpy
    try:
        args = build_parser(argv).parse_args(argv)
        json_out = getattr(args, 'format', None) == 'json'
        code = int(args.run(args) or 0)
    except _UsageError as exc:
        line, message = exc.args
        return _fail(line, message, 2, json_out)
    except InputError as exc:
        # NotEnoughStillData: 3
        return _fail(f'imu-allan: error: {exc}', str(exc), getattr(exc, 'exit_code', 2),
                     json_out)
    except KeyboardInterrupt:
        # A second Ctrl-C (a terminal's, to the whole group) while the workers stop
        # would end the process by the signal instead of exit 130.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        workers = sys.modules.get('imu_allan.pipeline.workers')   # its server, if started
        if workers is not None:
            workers.stop_workers()
        return _fail('imu-allan: interrupted', 'interrupted', 130, json_out)
    except BrokenPipeError:
        return 1
    return code


def entry() -> None:
    """Run the CLI as the ``imu-allan`` program (console script, ``python -m imu_allan``)."""
    sys.exit(main())


if __name__ == '__main__':
    entry()
