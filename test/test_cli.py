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


def test_a_subcommand_imports_only_its_own_module():
    """``mbtrack replay ...`` builds the parser of replay alone (the other subcommands'
    imports would only slow its start-up); an unknown word still gets the full parser."""
    import subprocess
    import sys
    code = ('import sys\nfrom mbtrack_ros.cli import main\n'
            'try:\n    main(["replay", "--no-such-option"])\nexcept SystemExit:\n    pass\n'
            'print(",".join(sorted(m for m in sys.modules '
            'if m.startswith("mbtrack_ros.commands."))))\n')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-2000:]
    loaded = set(result.stdout.split()[-1].split(','))
    assert 'mbtrack_ros.commands.replay' in loaded
    assert not loaded & {f'mbtrack_ros.commands.{n}' for n in SUBCOMMANDS if n != 'replay'}
    with pytest.raises(SystemExit) as info:
        main(['no-such-command'])
    assert info.value.code == 2
