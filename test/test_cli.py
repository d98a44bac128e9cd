"""The mbtrack command line: every subcommand rejects bad arguments with one line, exit 2."""
from __future__ import annotations

import pytest

from mbtrack_ros.cli import SUBCOMMANDS, build_parser, main

COMMANDS = sorted(name.replace('_', '-') for name in SUBCOMMANDS)


def test_every_subcommand_is_registered():
    text = build_parser().format_help()
    for name in COMMANDS:
        assert name in text


@pytest.mark.parametrize('name', COMMANDS)
def test_bad_option_is_one_line_and_exit_2(name, capsys):
    with pytest.raises(SystemExit) as info:
        main([name, '--no-such-option'])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith(f'mbtrack {name}: error:'), err
