"""Calibrating a room's cameras against the floor with a printed board (``mbtrack calibrate``).

Pure algorithms on numpy / OpenCV / scipy (no ROS): board specifications and detection
(:mod:`.board`), intrinsics and floor extrinsics (:mod:`.solve`), image sources
(:mod:`.sources`) and the check pictures (:mod:`.check`).
"""
from __future__ import annotations

from mbtrack_ros.calibration.errors import CalibrateError

__all__ = ['CalibrateError']
