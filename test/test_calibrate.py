"""``mbtrack calibrate``: boards, detection on rendered images, intrinsics, floor extrinsics
with joint refinement, the check pictures and the one-line refusals of bad input."""
from __future__ import annotations

import itertools
from dataclasses import replace

import cv2
import numpy as np
import pytest

from mbtrack_ros.calibration.board import BoardPose, parse_board, printable_sheets
from mbtrack_ros.calibration.errors import CalibrateError
from mbtrack_ros.calibration.solve import (FloorObservation, select_views, solve_extrinsics,
                                           viewing_direction)
from mbtrack_ros.cli import main
from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.synth.board import floor_images, intrinsics_images, render_boards

BOARD = 'charuco:5:4:0.25:0.19:DICT_4X4_50'
BIG = 'charuco:5:4:0.4:0.3:DICT_4X4_50'  # 2 x 1.6 m: resolved by 480 x 360 corner cameras


def _rotation_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(Ra @ Rb.T) - 1) / 2, -1, 1))))


def _camera(name: str, eye, target, *, width=320, height=240, f=175.0,
            dist=(-0.16, 0.025, 0.0, 0.0, 0.0)) -> Camera:
    R, t = look_at(eye, target)
    K = [[f * width / 320, 0, (width - 1) / 2 + 1.0], [0, f * width / 320, (height - 1) / 2 - 0.5],
         [0, 0, 1]]
    return Camera(name, width, height, K, dist, R, t)


def _room(width=320, height=240) -> RoomCalibration:
    cams = {'cam0': _camera('cam0', (0.1, 0.1, 2.5), (3.0, 2.5, 0.8), width=width,
                            height=height),
            'cam2': _camera('cam2', (5.9, 4.9, 2.5), (3.0, 2.5, 0.8), width=width,
                            height=height, f=181.0)}
    return RoomCalibration(cams, floor=(0.3, 0.3, 5.7, 4.7))


# -- boards ---------------------------------------------------------------------------------
def test_board_parsing_and_refusals():
    b = parse_board(BOARD)
    assert (b.cols, b.rows, b.square, b.marker) == (5, 4, 0.25, 0.19)
    assert b.corners.shape == (12, 3) and np.allclose(b.corners[0], (0.25, 0.25, 0))
    assert list(parse_board('charuco:5:4:0.25:0.19:DICT_4X4_50:10').marker_ids) == \
        list(range(10, 20))
    assert np.allclose(parse_board('chessboard:9:6:0.05').corners[0], 0)
    for bad, word in (('charuco:5:4:0.25:0.19:DICT_4X4_5O', 'dictionary'),
                      ('charuco:5:4:0.25:0.3:DICT_4X4_50', 'marker'),
                      ('charuco:5:4:0.25:0.19:DICT_4X4_50:45', 'do not fit'),
                      ('checker:5:4:0.25', 'expected'), ('chessboard:2:5:0.1', '3 x 3')):
        with pytest.raises(CalibrateError, match=word):
            parse_board(bad)


def test_board_pose_convention():
    """Board x along room x rotated by yaw, board y = room -y, board z into the floor."""
    R, t = BoardPose(1.0, 2.0, 90.0).matrix()
    assert np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(R @ [1, 0, 0], [0, 1, 0])       # x axis turned 90 deg
    assert np.allclose(R @ [0, 1, 0], [1, 0, 0])       # board y = room -y, turned
    assert np.allclose(R @ [0, 0, 1], [0, 0, -1])      # into the floor
    assert np.allclose(t, [1, 2, 0])


def test_printed_board_is_detected_in_full(tmp_path):
    board = parse_board(BOARD)
    [(label, image)] = printable_sheets(parse_board('charuco:5:4:0.03:0.022:DICT_4X4_50'), 150)
    assert label == ''
    det = parse_board('charuco:5:4:0.03:0.022:DICT_4X4_50').detect(image)
    assert sorted(det.ids) == list(range(12))
    sheets = printable_sheets(board, 40)  # 1.25 x 1 m: several A4 sheets
    assert len(sheets) > 1 and sheets[0][0] == 'r1c1'
    assert main(['calibrate', 'board', BOARD, str(tmp_path / 'b.png'), '--dpi', '40']) == 0
    assert len(list(tmp_path.glob('b_r*c*.png'))) == len(sheets)


# -- rendering and detection ---------------------------------------------------------------
def test_rendered_corners_match_the_camera_model():
    """Corners detected in a rendered picture lie where Camera.project puts them."""
    board = parse_board(BOARD)
    cam = _camera('c', (0.3, -0.6, 1.6), (0.6, 0.5, 0.0))
    R, t = BoardPose(0.0, 1.0, 0.0).matrix()
    image = render_boards(cam, [(board, R, t)], rng=np.random.default_rng(1))
    det = board.detect(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY))
    assert len(det) == 12
    truth = cam.project(board.corners[det.ids] @ R.T + t)
    assert np.sqrt(np.mean(np.sum((det.pixels - truth) ** 2, axis=1))) < 0.15


def test_select_views_is_within_twice_the_best_spread():
    """Greedy farthest-point selection vs brute force over all subsets: its smallest pairwise
    distance is at least half the best possible (the greedy 2-approximation)."""
    rng = np.random.default_rng(3)
    for _ in range(5):
        feats = rng.uniform(size=(9, 3))
        chosen = select_views(feats, 4)
        assert len(set(chosen)) == 4

        def spread(idx):
            return min(np.linalg.norm(feats[a] - feats[b]) for a, b in
                       itertools.combinations(idx, 2))
        best = max(spread(c) for c in itertools.combinations(range(9), 4))
        assert spread(chosen) >= 0.5 * best - 1e-12


# -- intrinsics -----------------------------------------------------------------------------
def test_intrinsics_from_rendered_views(tmp_path, capsys):
    cam = _camera('cam0', (0, 0, 0), (0, 0, 1))
    board = parse_board(BOARD)
    views = intrinsics_images(cam, board, 10, rng=np.random.default_rng(5), supersample=2)
    folder = tmp_path / 'views'
    folder.mkdir()
    for k, img in enumerate(views):
        cv2.imwrite(str(folder / f'{k:02d}.png'), img)
    out = tmp_path / 'intr.yaml'
    assert main(['calibrate', 'intrinsics', str(out), '--board', BOARD,
                 f'cam0={folder}']) == 0
    import yaml
    entry = yaml.safe_load(out.read_text())['cameras'][0]
    K = np.reshape(entry['camera_matrix']['data'], (3, 3))
    assert abs(K[0, 0] / cam.K[0, 0] - 1) < 0.02 and abs(K[1, 1] / cam.K[1, 1] - 1) < 0.02
    assert entry['rms_px'] < 0.5
    # too few views: one line naming the camera, nothing written
    out2 = tmp_path / 'few.yaml'
    few = tmp_path / 'few'
    few.mkdir()
    for k in range(3):
        cv2.imwrite(str(few / f'{k}.png'), views[k])
    capsys.readouterr()
    assert main(['calibrate', 'intrinsics', str(out2), '--board', BOARD, f'cam0={few}']) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and 'cam0: 3 of 3 images' in err and '8 are needed' in err
    assert not out2.exists()


# -- extrinsics -----------------------------------------------------------------------------
def test_extrinsics_end_to_end_recovers_the_rig(tmp_path, capsys):
    """Render the board on the floor for two corner cameras, calibrate, compare."""
    truth = _room(480, 360)
    board = parse_board(BIG)
    pose = BoardPose(2.2, 3.1, 0.0)
    images = floor_images(truth, [(board, pose)], room_background=False,
                          rng=np.random.default_rng(2), supersample=2)
    args = []
    for name, img in images.items():
        cv2.imwrite(str(tmp_path / f'{name}.png'), img)
        args.append(f'{name}={tmp_path / f"{name}.png"}')
    truth.save(tmp_path / 'true.yaml')
    out = tmp_path / 'cal.yaml'
    assert main(['calibrate', 'extrinsics', str(out), '--intrinsics', str(tmp_path / 'true.yaml'),
                 '--board', BIG, '--board-pose', '2.2,3.1,0', '--floor', '0.3,0.3,5.7,4.7',
                 '--entry-zone', '4.0,3.8,5.3,4.7', '--exit', '4.2,4.7,5.1,5.9', *args]) == 0
    printed = capsys.readouterr().out
    assert 'height 2.4' in printed or 'height 2.5' in printed
    got = RoomCalibration.load(out)
    assert got.exits == ((4.2, 4.7, 5.1, 5.9),) and got.floor == truth.floor
    for name, cam in truth.cameras.items():
        assert _rotation_deg(got.cameras[name].R, cam.R) < 0.3
        assert np.linalg.norm(got.cameras[name].center - cam.center) < 0.02
    az, dep = viewing_direction(got.cameras['cam0'])
    assert 30 < az < 50 and 15 < dep < 40
    # check pictures of the result
    check = tmp_path / 'check'
    assert main(['calibrate', 'check', str(out), *args, '--out', str(check)]) == 0
    assert sorted(p.name for p in check.iterdir()) == ['cam0.png', 'cam2.png', 'top.png']
    over = cv2.imread(str(check / 'cam0.png'))
    src = cv2.imread(str(tmp_path / 'cam0.png'))
    # the floor rectangle's corner (0.3, 0.3) is drawn where the camera sees it
    u, v = np.round(truth.cameras['cam0'].project(np.array([[5.7, 4.7, 0.0]]))[0]).astype(int)
    assert np.abs(over[v - 2:v + 3, u - 2:u + 3].astype(int)
                  - src[v - 2:v + 3, u - 2:u + 3]).max() > 60


def test_photometric_alignment_beats_the_corner_detector():
    """A board across the room at 480 x 360: the aligned board gives its corners within
    0.05 px of Camera.project, several times closer than the detected corners."""
    from mbtrack_ros.calibration.align import refine_corners
    cam = _room(480, 360).cameras['cam0']
    board = parse_board(BOARD)
    R, t = BoardPose(1.0, 2.2, 20.0).matrix()
    image = render_boards(cam, [(board, R, t)], rng=np.random.default_rng(4))
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    det = board.detect(gray, far=True)
    assert len(det) >= 8
    truth = cam.project(board.corners[det.ids] @ R.T + t)
    refined = refine_corners(gray, cam, board, det.ids, det.pixels)

    def rms(p):
        return float(np.sqrt(np.mean(np.sum((p - truth) ** 2, axis=1))))
    assert rms(refined) < 0.05 and rms(refined) < 0.5 * rms(det.pixels)


def test_joint_refinement_moves_a_mismeasured_board():
    """Exact corner projections, the second board's given pose 4 cm and 1.5 deg off: the
    bundle adjustment finds its true pose and the cameras'; brute-force check of the
    residual at the solution."""
    truth = _room(640, 480)
    b1 = parse_board('charuco:5:4:0.25:0.19:DICT_4X4_50')
    b2 = parse_board('charuco:5:4:0.25:0.19:DICT_4X4_50:10')
    true_poses = [BoardPose(1.5, 2.0, 0.0), BoardPose(3.0, 3.5, 30.0)]
    boards = [(b1, true_poses[0]), (b2, BoardPose(3.03, 3.47, 31.5))]
    obs = {}
    for name, cam in truth.cameras.items():
        obs[name] = []
        for k, (b, _) in enumerate(boards):
            R, t = true_poses[k].matrix()
            ids = np.arange(len(b.corners))
            obs[name].append(FloorObservation(k, ids, cam.project(b.corners @ R.T + t)))
    cams = [replace(c, R=np.eye(3), t=np.zeros(3)) for c in truth.cameras.values()]
    poses, board_poses = solve_extrinsics(cams, boards, obs)
    solved = board_poses[1]
    assert abs(solved.x - 3.0) < 0.004 and abs(solved.y - 3.5) < 0.004
    assert abs(solved.yaw - 30.0) < 0.2
    for p in poses:
        cam = truth.cameras[p.camera.name]
        assert np.linalg.norm(p.camera.center - cam.center) < 0.01
        assert p.rms < 0.2


# -- bad input ------------------------------------------------------------------------------
@pytest.mark.parametrize('case', ['no_board', 'bad_dict', 'bad_video', 'unknown_camera',
                                  'too_small'])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, case):
    truth = _room()
    truth.save(tmp_path / 'true.yaml')
    blank = tmp_path / 'blank.png'
    cv2.imwrite(str(blank), np.full((240, 320, 3), 128, np.uint8))
    board, source = BIG, f'cam0={blank}'
    if case == 'bad_dict':
        board = 'charuco:4:3:0.4:0.3:DICT_4x4_5'
    elif case == 'bad_video':
        video = tmp_path / 'broken.mp4'
        video.write_bytes(b'not a video')
        source = f'cam0={video}'
    elif case == 'unknown_camera':
        source = f'cam7={blank}'
    elif case == 'too_small':
        # a small board far away: markers found, too few corners
        small = parse_board('charuco:5:4:0.05:0.038:DICT_4X4_50')
        img = render_boards(truth.cameras['cam0'], [(small, *BoardPose(1.5, 1.5, 0).matrix())],
                            supersample=2)
        cv2.imwrite(str(blank), img)
        board = small.text
    out = tmp_path / 'out.yaml'
    code = main(['calibrate', 'extrinsics', str(out), '--intrinsics', str(tmp_path / 'true.yaml'),
                 '--board', board, source])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count('\n') == 0 and err.startswith('mbtrack calibrate')
    assert 'Traceback' not in err
    if case != 'bad_dict':
        assert ('cam0' in err) or ('cam7' in err)
    assert not out.exists()


def test_calibration_package_imports_no_ros():
    import subprocess
    import sys
    code = ('import sys\nimport mbtrack_ros.calibration.board, mbtrack_ros.calibration.solve, '
            'mbtrack_ros.calibration.check, mbtrack_ros.calibration.sources, '
            'mbtrack_ros.synth.board\n'
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'sensor_msgs'))\n"
            "sys.exit(1 if bad else 0)\n")
    assert subprocess.run([sys.executable, '-c', code]).returncode == 0


def test_boards_from_options_and_yaml(tmp_path):
    import argparse

    from mbtrack_ros.commands.calibrate import _boards
    spec2 = 'charuco:5:4:0.25:0.19:DICT_4X4_50:10'
    boards = _boards(argparse.Namespace(board=[BOARD, spec2], board_pose=['1,2,0', '3,1,90']))
    assert [p for _, p in boards] == [BoardPose(1, 2, 0), BoardPose(3, 1, 90)]
    (tmp_path / 'b.yaml').write_text(f'boards:\n- {{board: "{BOARD}"}}\n'
                                     f'- {{board: "{spec2}", pose: [3, 1, 90]}}\n')
    boards = _boards(argparse.Namespace(board=[str(tmp_path / 'b.yaml')], board_pose=[]))
    assert boards[0][1] == BoardPose() and boards[1][1] == BoardPose(3.0, 1.0, 90.0)
    with pytest.raises(CalibrateError, match='share marker ids'):
        _boards(argparse.Namespace(board=[BOARD, BOARD], board_pose=['0,0,0', '1,1,0']))
    with pytest.raises(CalibrateError, match='--board-pose'):
        _boards(argparse.Namespace(board=[BOARD, spec2], board_pose=[]))


def test_room_action_keeps_what_it_is_not_told(tmp_path, capsys):
    cal = replace(_room(), exits=((4.2, 4.7, 5.1, 5.9),))
    cal.save(tmp_path / 'cal.yaml')
    (tmp_path / 'room.yaml').write_text('entry_zones: [[4.0, 3.8, 5.3, 4.7]]\n')
    out = tmp_path / 'out.yaml'
    assert main(['calibrate', 'room', str(tmp_path / 'cal.yaml'), str(out),
                 '--room', str(tmp_path / 'room.yaml')]) == 0
    got = RoomCalibration.load(out)
    assert got.floor == cal.floor and got.exits == cal.exits
    assert got.entry_zones == ((4.0, 3.8, 5.3, 4.7),)
    assert main(['calibrate', 'room', str(tmp_path / 'cal.yaml'), str(tmp_path / 'bad.yaml'),
                 '--exit', '1,1,2,2']) == 2
    assert 'overlaps the floor' in capsys.readouterr().err
    assert not (tmp_path / 'bad.yaml').exists()
