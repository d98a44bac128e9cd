"""The bootstrap (standard library only): no package-index address of its own, and a
Python without ensurepip or pip gets one line naming the package to install."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

from mbtrack_ros import bootstrap


def test_the_bootstrap_names_no_package_index_host():
    source = Path(bootstrap.__file__).read_text()
    assert not re.search(r'https?://|pypi\.org|files\.pythonhosted', source)
    assert 'urllib' not in source


def test_without_ensurepip_and_without_pip_the_user_is_told_what_to_install(
        tmp_path, monkeypatch, capsys):
    made = []

    def create(path, *, with_pip, clear):
        made.append(with_pip)
        if with_pip:       # as venv does on a Debian Python without python3-venv
            raise subprocess.CalledProcessError(1, ['ensurepip'])
        (Path(path) / 'bin').mkdir(parents=True)
        (Path(path) / 'bin' / 'python').touch()

    monkeypatch.setattr(bootstrap, 'VENV', tmp_path / 'venv')
    monkeypatch.setattr(bootstrap.venv, 'create', create)
    monkeypatch.setattr(bootstrap, '_has_pip', lambda python: False)
    assert bootstrap.main(['test']) == 2
    assert made == [True, False]
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == ('[bootstrap] this Python has neither ensurepip nor pip: install the '
                       'python3-venv package (sudo apt install python3-venv) and run again')


def test_without_ensurepip_the_system_pip_installs_pip_into_the_environment(
        tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(bootstrap, 'VENV', tmp_path / 'venv')
    monkeypatch.setattr(bootstrap.venv, 'create', lambda path, *, with_pip, clear: None)
    have = {str(bootstrap.sys.executable): True}
    monkeypatch.setattr(bootstrap, '_has_pip', lambda python: have.get(str(python), False))
    monkeypatch.setattr(bootstrap, '_pip_from_system_pip', lambda python: calls.append(python))
    assert bootstrap.ensure_venv() == bootstrap._python()
    assert calls == [bootstrap._python()]


def test_an_unknown_command_prints_the_usage(capsys):
    assert bootstrap.main(['nope']) == 2
    assert 'python3 -m mbtrack_ros.bootstrap demo' in capsys.readouterr().err
