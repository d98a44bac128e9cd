"""The algorithm core and the recording layer import no ROS client library."""
from __future__ import annotations

import pkgutil
import subprocess
import sys

import mbtrack_ros.core


def test_core_and_recording_do_not_import_rclpy():
    core = [f'mbtrack_ros.core.{m.name}' for m in pkgutil.walk_packages(
        mbtrack_ros.core.__path__) if not m.name.startswith('_')]
    modules = core + ['mbtrack_ros.recording.bag', 'mbtrack_ros.recording.csvfiles']
    code = ('import sys\n' + ''.join(f'import {m}\n' for m in modules)
            + "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
            "('rclpy', 'sensor_msgs', 'geometry_msgs', 'std_msgs', 'visualization_msgs'))\n"
            "print(','.join(bad)); sys.exit(1 if bad else 0)\n")
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert result.returncode == 0, f'ROS modules imported by the core: {result.stdout}' \
                                   f'{result.stderr[-2000:]}'


def _imported_after(code: str, prefixes: tuple[str, ...]) -> list[str]:
    check = (code + '\nimport sys\n'
             f'print(",".join(sorted(m for m in sys.modules if m.startswith({prefixes!r}))))\n')
    result = subprocess.run([sys.executable, '-c', check], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-2000:]
    return [m for m in result.stdout.strip().split(',') if m]


def test_replay_start_up_imports_neither_rclpy_nor_scipy_spatial(tmp_path):
    """``mbtrack replay`` starts without rclpy (its tracks.mcap writer runs in a child
    process; ``--params`` reads the node's parameter map from a rclpy-free module) and
    without scipy.spatial (0.3 s of imports for one distance function)."""
    from pathlib import Path
    params = Path(__file__).resolve().parent.parent / 'config' / 'clear_room_offline.yaml'
    code = ('from mbtrack_ros.cli import build_parser\n'
            'from mbtrack_ros.commands import replay\n'
            f'args = build_parser().parse_args(["replay", "B", "--out", "O", "--params", '
            f'{str(params)!r}])\n'
            'config = replay._config(args)\n'
            'assert config.working_pixels == 19200 and config.particles == 50, config\n')
    assert _imported_after(code, ('rclpy', 'scipy.spatial', 'sensor_msgs')) == []


def test_output_writer_child_imports_no_numba(tmp_path):
    """The writer process of ``mbtrack replay`` builds ``OutputBagWriter`` from a pickled
    factory; that costs its imports (~0.4 s) but not numba's and the tracker's (~1.5 s)."""
    code = ('import functools, pickle\n'
            'from mbtrack_ros.commands.output_writer import output_bag_writer\n'
            f'factory = pickle.loads(pickle.dumps(functools.partial(output_bag_writer, '
            f'{str(tmp_path / "tracks.mcap")!r}, ["cam0", "cam1"], "room")))\n'
            'factory().close()\n')
    assert _imported_after(code, ('numba', 'mbtrack_ros.core.camera',
                                  'mbtrack_ros.core.tracker', 'scipy')) == []
    assert (tmp_path / 'tracks.mcap' / 'metadata.yaml').exists()
