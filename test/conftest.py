"""Shared fixtures: a small calibrated room that needs no data files."""
from __future__ import annotations

import numpy as np
import pytest

from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at


def make_room(width: int = 160, height: int = 120, n_cameras: int = 2) -> RoomCalibration:
    """A 6 x 5 m room with corner cameras 2.6 m high looking at its centre."""
    corners = [(0.1, 0.1), (5.9, 4.9), (5.9, 0.1), (0.1, 4.9)]
    f = 0.9 * width
    cams = {}
    for i, (x, y) in enumerate(corners[:n_cameras]):
        R, t = look_at((x, y, 2.6), (3.0, 2.5, 0.9))
        cams[f'cam{i}'] = Camera(f'cam{i}', width, height,
                                 [[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]],
                                 [-0.12, 0.02, 0.0, 0.0, 0.0], R, t)
    return RoomCalibration(cams, (0.0, 0.0, 6.0, 5.0), entry_zones=((0.0, 2.0, 0.6, 3.0),))


@pytest.fixture
def room() -> RoomCalibration:
    return make_room()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)
