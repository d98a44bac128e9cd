"""Hostile input (issue 55, rows D1-D17): each defect a user or an attacker could trigger,
with the behaviour promised instead: one line and exit code 2 in a command, a throttled
warning and a count in the node, bounded work and memory per message."""
from __future__ import annotations

import os

import numpy as np
import pytest
import yaml

from conftest import make_room
from mbtrack_ros.cli import main
from mbtrack_ros.core.camera import (
    MAX_FLOOR_SIDE, CalibrationError, Camera, RoomCalibration, look_at)
from mbtrack_ros.recording.calibration_io import load_calibration


def _one_error_line(capsys, prog: str = 'mbtrack replay') -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f'{prog}: error: '), err
    assert 'Traceback' not in err[0]
    return err[0]


@pytest.fixture
def calib_doc() -> dict:
    return make_room().to_dict()


def _write(tmp_path, doc, name='room.yaml'):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False) if not isinstance(doc, str) else doc)
    return path


def _replay_with(tmp_path, config, *extra):
    bag = tmp_path / 'bag'
    bag.mkdir(exist_ok=True)
    return main(['replay', str(bag), '--config', str(config), '--out', str(tmp_path / 'o'),
                 *extra])


# -- D1: files that are not UTF-8 -------------------------------------------------------------

def test_d1_binary_calibration_and_params_are_one_line_errors(tmp_path, capsys, calib_doc):
    junk = tmp_path / 'junk.yaml'
    junk.write_bytes(bytes(range(128, 256)) * 4)
    assert _replay_with(tmp_path, junk) == 2
    line = _one_error_line(capsys)
    assert str(junk) in line and 'UTF-8' in line
    good = _write(tmp_path, calib_doc)
    assert _replay_with(tmp_path, good, '--params', str(junk)) == 2
    line = _one_error_line(capsys)
    assert str(junk) in line and 'UTF-8' in line
    with pytest.raises(CalibrationError, match='UTF-8'):
        load_calibration(junk, 'room')


# -- D2: wrong types and absurd ranges ----------------------------------------------------------

def _mutate(doc: dict, where: str, value) -> dict:
    cam = doc['cameras'][0]
    if where == 'image_width':
        cam['image_width'] = value
    elif where == 'distortion_coefficients':
        cam['distortion_coefficients']['data'] = value
    elif where == 'entry_zones':
        doc['entry_zones'] = value
    elif where == 'x_max':
        doc['floor']['x_max'] = value
    elif where == 'camera_matrix':
        cam['camera_matrix']['data'] = value
    elif where == 'translation':
        cam['extrinsics']['translation'] = value
    return doc


@pytest.mark.parametrize('where, value, needle', [
    ('image_width', 'abc', 'camera cam0: image_width'),
    ('image_width', 1e9, 'camera cam0: image_width'),
    ('image_width', 10 ** 400, 'camera cam0: image_width'),
    ('distortion_coefficients', ['a', 'b', 0, 0, 0], 'camera cam0: distortion_coefficients'),
    ('distortion_coefficients', 'text', 'camera cam0: distortion_coefficients'),
    ('entry_zones', [['a', 0, 1, 1]], 'entry_zones[0]'),
    ('entry_zones', [[0.0, 1.0]], 'entry_zones[0]'),
    ('entry_zones', 'everywhere', 'entry_zones'),
    ('x_max', float('inf'), 'floor'),
    ('x_max', 1e6, 'floor'),
    ('x_max', 'far', 'floor: x_max'),
    ('camera_matrix', [1, 2, 3], 'camera cam0: K'),
    ('translation', [[1, 2], [3]], 'camera cam0: t'),
])
def test_d2_wrong_types_and_ranges_are_one_line_errors(tmp_path, capsys, calib_doc, where,
                                                        value, needle):
    path = _write(tmp_path, _mutate(calib_doc, where, value))
    assert _replay_with(tmp_path, path) == 2
    line = _one_error_line(capsys)
    assert str(path) in line and needle in line


def test_d2_floor_side_is_capped():
    room = make_room()
    with pytest.raises(CalibrationError, match='largest floor side'):
        RoomCalibration(room.cameras, (0.0, 0.0, MAX_FLOOR_SIDE + 1.0, 5.0))


# -- D3: non-finite distortion --------------------------------------------------------------------

@pytest.mark.parametrize('bad', [float('nan'), float('inf')])
def test_d3_non_finite_distortion_refused(tmp_path, capsys, calib_doc, bad):
    calib_doc['cameras'][1]['distortion_coefficients']['data'][0] = bad
    path = _write(tmp_path, calib_doc)
    assert _replay_with(tmp_path, path) == 2
    line = _one_error_line(capsys)
    assert 'camera cam1: distortion_coefficients' in line and 'non-finite' in line
    room = make_room()
    cam = room.cameras['cam0']
    with pytest.raises(CalibrationError, match='non-finite'):
        Camera('x', 160, 120, cam.K, [bad, 0, 0, 0, 0], cam.R, cam.t)


# -- D14: YAML syntax errors ------------------------------------------------------------------

def test_d14_yaml_syntax_error_is_one_line(tmp_path, capsys):
    path = _write(tmp_path, 'cameras: [\n  - camera_name: cam0\n    bad: : :\nfloor: {')
    assert _replay_with(tmp_path, path) == 2
    line = _one_error_line(capsys)
    assert 'not valid YAML' in line and 'line' in line


# -- D17: cameras that cannot see the floor -----------------------------------------------------

def _looking_up(room: RoomCalibration, names) -> RoomCalibration:
    cams = dict(room.cameras)
    for name in names:
        cam = cams[name]
        R, t = look_at(cam.center, cam.center + np.array([0.01, 0.0, 5.0]))
        cams[name] = Camera(name, cam.width, cam.height, cam.K, cam.dist, R, t)
    return RoomCalibration(cams, room.floor, entry_zones=room.entry_zones)


def test_d17_camera_blind_to_the_floor_warns_and_all_blind_refused(tmp_path, capsys):
    room = make_room()
    views = room.floor_views()
    assert all(v > 0.2 for v in views.values())
    one = tmp_path / 'one.yaml'
    _looking_up(room, ['cam1']).save(one)
    warnings = []
    load_calibration(one, 'room', warn=warnings.append)
    assert len(warnings) == 1 and 'camera cam1' in warnings[0] and str(one) in warnings[0]
    both = tmp_path / 'both.yaml'
    _looking_up(room, ['cam0', 'cam1']).save(both)
    assert _replay_with(tmp_path, both) == 2
    line = _one_error_line(capsys)
    assert 'no camera sees the floor' in line and str(both) in line
    # the node refuses it too (one line through ParamsError)
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    from mbtrack_ros.nodes.params import ParamsError
    from mbtrack_ros.nodes.tracker_node import TrackerNode
    import rclpy
    from rclpy.context import Context
    ctx = Context()
    rclpy.init(context=ctx)
    try:
        for path, needle in ((both, 'no camera sees the floor'),):
            with pytest.raises(ParamsError, match=needle):
                TrackerNode(cli_args=['--ros-args', '-p', f'calibration_file:={path}',
                                      '-p', 'warm_up:=false'], context=ctx)
        junk = tmp_path / 'junk.yaml'
        junk.write_bytes(bytes(range(128, 256)))
        with pytest.raises(ParamsError, match='UTF-8'):  # D1 in the node
            TrackerNode(cli_args=['--ros-args', '-p', f'calibration_file:={junk}',
                                  '-p', 'warm_up:=false'], context=ctx)
    finally:
        rclpy.try_shutdown(context=ctx)
