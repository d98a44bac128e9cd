"""The ``mbtrack`` command line: one subcommand per module in :mod:`mbtrack_ros.commands`."""
from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from mbtrack_ros import __version__

__all__ = ['build_parser', 'main']

# Subcommand modules, in the order `mbtrack --help` lists them.
SUBCOMMANDS = ('demo', 'synth', 'replay', 'eval', 'bench', 'import_video', 'experiments')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='mbtrack',
        description='Multi-camera people tracking with the Hybrid Joint-Separable particle '
                    'filter: make recordings, replay them through the tracker, score the '
                    'tracks.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND')
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f'mbtrack_ros.commands.{name}')
        except ModuleNotFoundError as err:
            if err.name == f'mbtrack_ros.commands.{name}':
                continue  # subcommand not part of this build
            raise
        sub = module.add_parser(subparsers)
        sub.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``mbtrack``; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, '_run', None):
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print('mbtrack: interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
