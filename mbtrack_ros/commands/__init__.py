"""Subcommands of ``mbtrack``: each module has ``add_parser(subparsers)`` and ``run(args)``."""
from __future__ import annotations

import sys

__all__ = ['one_line_error']


def one_line_error(prog: str):
    """argparse's error hook for a (sub)command: one line on stderr, exit code 2."""
    def error(message: str) -> None:
        print(f'{prog}: error: {message}', file=sys.stderr)
        raise SystemExit(2)
    return error
