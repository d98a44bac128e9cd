"""The ``mbtrack`` command line: one subcommand per module in :mod:`mbtrack_ros.commands`."""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from collections.abc import Sequence
from typing import NoReturn

from mbtrack_ros import __version__

__all__ = ['build_parser', 'main']

# Subcommand modules, in the order `mbtrack --help` lists them.
SUBCOMMANDS = ('demo', 'synth', 'replay', 'eval', 'bench', 'import_video', 'experiments',
               'evaluate', 'calibrate', 'synth_board')


def build_parser(only: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``mbtrack`` parser with every subcommand, or with those named in ``only`` (module
    names): ``main`` imports just the subcommand it runs (the others' imports cost
    ~0.1 s of a replay's start-up)."""
    parser = argparse.ArgumentParser(
        prog='mbtrack',
        description='Multi-camera people tracking with the Hybrid Joint-Separable particle '
                    'filter: make recordings, replay them through the tracker, score the '
                    'tracks.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND')
    for name in SUBCOMMANDS:
        if only is not None and name not in only:
            continue
        try:
            module = importlib.import_module(f'mbtrack_ros.commands.{name}')
        except ModuleNotFoundError as err:
            if err.name == f'mbtrack_ros.commands.{name}':
                continue  # subcommand not part of this build
            raise
        sub = module.add_parser(subparsers)
        sub.error = _one_line_error(sub.prog)
        sub.set_defaults(_run=module.run, _error=sub.error)
    return parser


def _one_line_error(prog: str):
    """argparse's error hook for a subcommand: one line on stderr, exit code 2."""
    def error(message: str) -> None:
        print(f'{prog}: error: {message}', file=sys.stderr)
        raise SystemExit(2)
    return error


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``mbtrack``; returns the exit code.

    As the ``mbtrack`` command (``argv`` None), a subcommand that sets the parser default
    ``_quick_exit`` (replay: every file it wrote is closed, its writer process has ended)
    ends the process as soon as it returns, without the interpreter's tear-down of numba,
    LLVM, OpenCV and the rest, which costs a fraction of a second per run."""
    words = list(sys.argv[1:] if argv is None else argv)
    command = next((w for w in words if not w.startswith('-')), '').replace('-', '_')
    parser = build_parser(only=(command,) if command in SUBCOMMANDS else None)
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # reported by the subcommand, in its own one-line form
        getattr(args, '_error', parser.error)(f'unrecognized arguments: {" ".join(unknown)}')
    if not getattr(args, '_run', None):
        parser.print_help()
        return 2
    try:
        code = int(args._run(args) or 0)
    except KeyboardInterrupt:
        print('mbtrack: interrupted', file=sys.stderr)
        return 130
    if argv is None and getattr(args, '_quick_exit', False):
        _quick_exit(code)
    return code


def _quick_exit(code: int) -> NoReturn:
    """End the process with ``code`` now: flush the standard streams and the logging
    handlers, then ``os._exit`` (no tear-down of the imported modules)."""
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == '__main__':
    sys.exit(main())
