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
