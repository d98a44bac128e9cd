"""Set up a local virtual environment and run the demo or the tests (standard library only).

Run from a checkout on a machine with nothing but Python >= 3.11::

    python3 -m mbtrack_ros.bootstrap demo      # the tracking demo
    python3 -m mbtrack_ros.bootstrap test      # the test suite (extra args go to pytest)

It creates (or reuses) ``.venv`` beside ``setup.py``, installs the package with everything it
needs from the package index (ROS 2 Jazzy wheels included), and reinstalls only when
``setup.py`` changed; then builds the interface packages of ``interfaces/`` that the
environment lacks (:mod:`mbtrack_ros.interfaces_build`). Packages come from the index pip is
configured with (``pip.conf``, ``PIP_INDEX_URL``); no address is written here. Debian and
Ubuntu ship Python without ``ensurepip`` unless ``python3-venv`` is installed: then the
system's own pip (if any) downloads pip for the environment, and without either the
bootstrap says which package to install.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
import venv
from pathlib import Path

from mbtrack_ros.interfaces_build import ensure_interfaces

ROOT = Path(__file__).resolve().parent.parent
VENV = Path(os.environ.get('MBTRACK_VENV', ROOT / '.venv'))
STAMP = VENV / '.mbtrack-installed'


def _say(message: str) -> None:
    print(f'[bootstrap] {message}', file=sys.stderr, flush=True)


def _python() -> Path:
    return VENV / ('Scripts/python.exe' if os.name == 'nt' else 'bin/python')


class SetupError(Exception):
    """The environment cannot be made on this machine; the message says what to install."""


def _has_pip(python: Path | str) -> bool:
    return subprocess.run([str(python), '-m', 'pip', '--version'],
                          capture_output=True).returncode == 0


def _pip_from_system_pip(python: Path) -> None:
    """Install pip into the environment with the system Python's pip: it downloads the pip
    wheel from its configured index, and the wheel installs itself."""
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, '-m', 'pip', 'download', '--quiet', '--no-deps',
                        '--only-binary=:all:', '--dest', tmp, 'pip'], check=True)
        wheel = next(Path(tmp).glob('pip-*.whl'))
        subprocess.run([str(python), str(wheel / 'pip'), 'install', '--quiet', '--no-index',
                        str(wheel)], check=True)


def ensure_venv() -> Path:
    """Create the virtual environment with a working pip; returns its python."""
    python = _python()
    if python.exists() and _has_pip(python):
        return python
    _say(f'creating virtual environment {VENV}')
    try:
        venv.create(VENV, with_pip=True, clear=True)
    except subprocess.CalledProcessError:
        venv.create(VENV, with_pip=False, clear=True)  # no ensurepip on this Python
    if not _has_pip(python):
        if not _has_pip(sys.executable):
            raise SetupError('this Python has neither ensurepip nor pip: install the '
                             'python3-venv package (sudo apt install python3-venv) and run '
                             'again')
        _say('this Python has no ensurepip: installing pip with the system\'s pip')
        _pip_from_system_pip(python)
    return python


def ensure_installed(python: Path) -> None:
    """Install the package and its dependencies if setup.py changed since the last time."""
    digest = hashlib.sha256((ROOT / 'setup.py').read_bytes()).hexdigest()
    if STAMP.exists() and STAMP.read_text().strip() == digest:
        return
    _say('installing mbtrack_ros and its dependencies (ROS 2 Jazzy wheels, OpenCV, numba, '
         '...); this takes a minute or two the first time')
    subprocess.run([python, '-m', 'pip', 'install', '--quiet', '--upgrade', 'pip'],
                   check=True)
    subprocess.run([python, '-m', 'pip', 'install', '--quiet', '-e', f'{ROOT}[test]'],
                   check=True)
    STAMP.write_text(digest)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in ('demo', 'test', 'shell'):
        print(__doc__, file=sys.stderr)
        return 2
    if sys.version_info < (3, 11):
        _say(f'Python >= 3.11 is needed, this is {sys.version.split()[0]}')
        return 2
    command, rest = argv[0], argv[1:]
    try:
        python = ensure_venv()
        ensure_installed(python)
        ensure_interfaces(python, VENV)
    except SetupError as err:
        _say(str(err))
        return 2
    except (OSError, subprocess.CalledProcessError, StopIteration) as err:
        _say(f'setting up the environment failed: {err}')
        return 1
    if command == 'demo':
        cmd = [str(python), '-m', 'mbtrack_ros.cli', 'demo', *rest]
    elif command == 'test':
        cmd = [str(python), '-m', 'pytest', *(rest or ['-q'])]
    else:
        cmd = [str(python), *rest]
    _say(' '.join(cmd[1:]))
    return subprocess.run(cmd, cwd=ROOT).returncode


if __name__ == '__main__':
    sys.exit(main())
