"""Foreign calibration readers (OpenCV style, camera_info + extrinsics, Qualisys) on real data."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import make_room
from mbtrack_ros.core.camera import CalibrationError, RoomCalibration
from mbtrack_ros.recording.calibration_io import (
    UP_AXES, read_calibration, read_camera_info, read_camera_info_calibration,
    read_opencv_calibration, read_qualisys_calibration, reexpress_world, world_rotation)
from mbtrack_ros.recording.video import read_trc, trc_to_room

DATA = Path(__file__).resolve().parents[1] / 'mbtrack_ros' / 'data' / 'real_clip'
CAMS = ('cam01', 'cam02', 'cam03', 'cam04')
CAMERA_INFO = {c: DATA / 'camera_info' / f'{c}.yaml' for c in CAMS}

# Hand-checked positions of two reference keypoints in reference_projection_frame50.png
# (top row = single-person clip, each camera a 272 x 480 tile, i.e. the 1088 x 1920 images
# at 1/4 scale). Read once by viewing 16x enlarged 20 x 20 px crops around each red dot with a
# pixel grid; the dot centre is the middle of its ~5 px red disc (refined to the centroid of
# its pure-red pixels). Coordinates are within the camera's own tile, png pixels.
PNG_SCALE = (272, 480)
PNG_FRAME = 50  # TRC data row 50 (Frame# 51) = video frame 50, 0-based
PNG_POINTS = {
    'cam01': {'Head': (205.8, 136.4), 'LKnee': (116.9, 249.9)},
    'cam02': {'Head': (186.8, 128.5), 'LKnee': (130.5, 240.5)},
    'cam03': {'Head': (49.0, 143.0), 'LKnee': (116.9, 245.0)},
    'cam04': {'Head': (48.5, 156.5), 'LKnee': (149.8, 246.4)},
}


def readers() -> dict[str, RoomCalibration]:
    return {
        'qualisys': read_qualisys_calibration(DATA / 'Calib.qca.txt'),
        'opencv': read_opencv_calibration(DATA / 'calibration_opencv.json'),
        'camera-info': read_camera_info_calibration(CAMERA_INFO, DATA / 'calibration_opencv.json'),
    }


@pytest.fixture(scope='module')
def keypoints() -> tuple[tuple[str, ...], np.ndarray]:
    trc = read_trc(DATA / 'single_0-100.trc')
    return trc.markers, trc_to_room(trc.points[PNG_FRAME])  # (M, 3) room frame


@pytest.mark.parametrize('reader', ['qualisys', 'opencv', 'camera-info'])
def test_reference_keypoints_project_onto_hand_checked_pixels(reader, keypoints):
    markers, world = keypoints
    room = readers()[reader]
    assert room.names == list(CAMS)
    for name, points in PNG_POINTS.items():
        cam = room.cameras[name].scaled(*PNG_SCALE)
        for marker, expected in points.items():
            pixel = cam.project(world[markers.index(marker)])
            err = np.linalg.norm(pixel - np.asarray(expected))
            assert err < 3.0, f'{reader} {name} {marker}: {pixel} vs {expected} ({err:.2f} px)'


def test_reference_frame_is_z_up_with_floor_near_zero(keypoints):
    markers, world = keypoints
    head = world[markers.index('Head'), 2]
    foot = min(world[markers.index(m), 2] for m in markers if 'Toe' in m or 'Heel' in m)
    assert 1.4 < head < 2.0 and -0.05 < foot < 0.3  # standing on a ~10 cm treadmill


def test_qualisys_and_opencv_json_agree(rng):
    rooms = readers()
    q, o = rooms['qualisys'], rooms['opencv']
    points = rng.uniform([-3, -2, 0], [2.5, 2, 2], (200, 3))
    for name in CAMS:
        a, b = q.cameras[name], o.cameras[name]
        assert (a.width, a.height) == (b.width, b.height) == (1088, 1920)
        np.testing.assert_allclose(a.K, b.K, atol=1e-9)
        np.testing.assert_allclose(a.R, b.R, atol=1e-12)
        np.testing.assert_allclose(a.t, b.t, atol=1e-9)
        np.testing.assert_allclose(a.dist, b.dist, atol=1e-12)
        np.testing.assert_allclose(a.project(points), b.project(points), atol=1e-6)
    # the Qualisys <transform x y z> is the camera centre in mm
    doc = json.loads((DATA / 'calibration_opencv.json').read_text())
    for name in CAMS:
        np.testing.assert_allclose(q.cameras[name].center, doc[name]['centre_world_m'],
                                   atol=1e-9)


def test_camera_info_reader_fields():
    info = read_camera_info(CAMERA_INFO['cam03'])
    doc = json.loads((DATA / 'calibration_opencv.json').read_text())['cam03']
    assert (info.name, info.width, info.height) == ('cam03', 1088, 1920)
    np.testing.assert_allclose(info.K, doc['K'])
    np.testing.assert_allclose(info.dist[:4], doc['dist'])


def test_opencv_filestorage_and_pose2sim_toml_variants(tmp_path):
    ref = read_opencv_calibration(DATA / 'calibration_opencv.json')
    fs_path = tmp_path / 'rig.yml'
    fs = cv2.FileStorage(str(fs_path), cv2.FILE_STORAGE_WRITE)
    for name, cam in ref.cameras.items():
        fs.startWriteStruct(name, cv2.FileNode_MAP)
        fs.write('K', cam.K)
        fs.write('dist', cam.dist[:4].reshape(1, 4))
        fs.write('R', cv2.Rodrigues(cam.R)[0])  # Rodrigues vector form
        fs.write('t', cam.t.reshape(3, 1))
        fs.write('image_size', np.array([[cam.width, cam.height]], dtype=np.float64))
        fs.endWriteStruct()
    fs.release()
    toml_path = tmp_path / 'Calib.toml'
    lines = []
    for name, cam in ref.cameras.items():
        rvec = cv2.Rodrigues(cam.R)[0].ravel()
        lines += [f'[{name}]', f'name = "{name}"', f'size = [{cam.width}.0, {cam.height}.0]',
                  f'matrix = {cam.K.tolist()}', f'distortions = {cam.dist[:4].tolist()}',
                  f'rotation = {rvec.tolist()}', f'translation = {cam.t.tolist()}',
                  'fisheye = false', '']
    toml_path.write_text('\n'.join(lines))
    points = np.array([[-1.4, 0.0, 0.9], [0.5, 1.0, 0.0], [-2.0, -1.0, 1.7]])
    for room in (read_opencv_calibration(fs_path), read_calibration(toml_path)):
        assert room.names == ref.names
        for name in ref.names:
            np.testing.assert_allclose(room.cameras[name].project(points),
                                       ref.cameras[name].project(points), atol=1e-6)


def test_camera_info_with_extrinsics_mapping():
    ref = read_opencv_calibration(DATA / 'calibration_opencv.json')
    poses = {n: (c.R, c.t) for n, c in ref.cameras.items()}
    room = read_camera_info_calibration(list(CAMERA_INFO.values()), poses)  # named by file
    for name in CAMS:
        np.testing.assert_allclose(room.cameras[name].K, ref.cameras[name].K)
        np.testing.assert_allclose(room.cameras[name].t, ref.cameras[name].t)
    assert 'pair' in _one_line_error(lambda: read_camera_info_calibration(
        CAMERA_INFO, {n: (c.R,) for n, c in ref.cameras.items()}))


def test_auto_format_detection():
    assert read_calibration(DATA / 'Calib.qca.txt').names == list(CAMS)
    room = read_calibration(DATA / 'calibration_opencv.json', 'camera-info',
                            camera_info=CAMERA_INFO)
    assert room.names == list(CAMS)


@pytest.mark.parametrize('up_axis', UP_AXES)
def test_world_rotation_is_proper_and_lifts_the_up_axis(up_axis):
    A = world_rotation(up_axis)
    np.testing.assert_allclose(A @ A.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(A) == pytest.approx(1.0)
    up = np.zeros(3)
    up['xyz'.index(up_axis[-1])] = -1.0 if up_axis.startswith('-') else 1.0
    np.testing.assert_allclose(A @ up, [0.0, 0.0, 1.0])


def test_trc_convention_matches_world_rotation():
    # TRC files are Y up and the room is (X, Y, Z) = (trc Z, trc X, trc Y)
    np.testing.assert_allclose(trc_to_room(np.array([1.0, 2.0, 3.0])), [3.0, 1.0, 2.0])


@pytest.mark.parametrize('up_axis', UP_AXES)
def test_reexpress_world_recovers_a_z_up_room(up_axis, rng):
    room = make_room(n_cameras=3)
    floor_offset = 0.37
    A = world_rotation(up_axis)
    # the same rig described in a source frame where X_room = A X_src - offset e_z
    src_cams = {}
    for name, cam in room.cameras.items():
        R = cam.R @ A
        src_cams[name] = cam.__class__(name, cam.width, cam.height, cam.K, cam.dist, R,
                                       cam.t - floor_offset * cam.R[:, 2])
    src = RoomCalibration(src_cams, (-10, -10, 10, 10))
    back = reexpress_world(src, up_axis=up_axis, floor_offset=floor_offset, floor=room.floor)
    room_points = rng.uniform([0, 0, 0], [6, 5, 2], (50, 3))
    src_points = (room_points + [0.0, 0.0, floor_offset]) @ A  # A^T (X + offset e_z)
    for name, cam in room.cameras.items():
        np.testing.assert_allclose(back.cameras[name].R, cam.R, atol=1e-12)
        np.testing.assert_allclose(back.cameras[name].t, cam.t, atol=1e-12)
        np.testing.assert_allclose(src.cameras[name].project(src_points),
                                   cam.project(room_points), atol=1e-6)
    assert back.floor == room.floor


def _one_line_error(call) -> str:
    with pytest.raises(CalibrationError) as info:
        call()
    message = str(info.value)
    assert message and '\n' not in message
    return message


def test_malformed_files_raise_one_line_errors(tmp_path):
    qca = (DATA / 'Calib.qca.txt').read_text()
    broken = tmp_path / 'broken.qca.txt'
    broken.write_text(qca.replace(' r22=', ' rXX='))
    assert 'r22' in _one_line_error(lambda: read_qualisys_calibration(broken))
    notxml = tmp_path / 'x.qca.txt'
    notxml.write_text('<calibration><cameras>')
    assert 'Qualisys' in _one_line_error(lambda: read_qualisys_calibration(notxml))
    nonrot = tmp_path / 'nonrot.qca.txt'
    nonrot.write_text(qca.replace('r11="0.5536380477336265"', 'r11="0.9"'))
    assert 'rotation' in _one_line_error(lambda: read_qualisys_calibration(nonrot))
    assert 'does not exist' in _one_line_error(
        lambda: read_qualisys_calibration(tmp_path / 'missing.qca.txt'))

    doc = json.loads((DATA / 'calibration_opencv.json').read_text())
    del doc['cam02']['K']
    nok = tmp_path / 'nok.json'
    nok.write_text(json.dumps(doc))
    assert 'cam02' in _one_line_error(lambda: read_opencv_calibration(nok))
    garbage = tmp_path / 'garbage.json'
    garbage.write_text('{"cam01": [1, 2')
    _one_line_error(lambda: read_opencv_calibration(garbage))
    doc = json.loads((DATA / 'calibration_opencv.json').read_text())
    doc['cam01']['t'] = [1.0, 2.0]
    short = tmp_path / 'short.json'
    short.write_text(json.dumps(doc))
    assert 'cam01' in _one_line_error(lambda: read_opencv_calibration(short))

    info = tmp_path / 'info.yaml'
    info.write_text('image_width: 640\ncamera_name: c\n')
    assert 'image_height' in _one_line_error(lambda: read_camera_info(info))
    assert 'cam09' in _one_line_error(lambda: read_camera_info_calibration(
        {'cam09': CAMERA_INFO['cam01']}, DATA / 'calibration_opencv.json'))
    assert 'up_axis' in _one_line_error(
        lambda: read_opencv_calibration(DATA / 'calibration_opencv.json', up_axis='w'))
