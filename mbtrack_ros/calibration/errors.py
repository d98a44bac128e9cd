"""Errors of :mod:`mbtrack_ros.calibration`."""
from __future__ import annotations

__all__ = ['CalibrateError']


class CalibrateError(ValueError):
    """Input the calibration cannot use; the message is one line naming the camera (when there
    is one) and what to do."""
