"""``mbtrack import-video``: the small real clip round trip and the errors users make."""
from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from mbtrack_ros.cli import main
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.recording.bag import RecordingReader
from mbtrack_ros.recording.calibration_io import read_opencv_calibration
from mbtrack_ros.recording.video import (
    EPOCH_NS, VideoImportError, fit_camera, import_videos, read_trc, trc_to_room)

DATA = Path(__file__).resolve().parents[1] / 'mbtrack_ros' / 'data' / 'real_clip'
CAMS = ('cam01', 'cam02', 'cam03', 'cam04')
VIDEOS = [str(DATA / 'videos' / f'{c}.avi') for c in CAMS]
CLIP_FIRST = 45  # the copied videos are frames 45..54 of the original (README there)
CALIB = str(DATA / 'calibration_opencv.json')


def decoded(path: str, width: int | None = None, height: int | None = None) -> list[np.ndarray]:
    """All frames of a video as RGB, resized independently of the code under test."""
    cap = cv2.VideoCapture(path)
    out = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        if width is not None:
            bgr = cv2.resize(bgr, (width, height), interpolation=cv2.INTER_AREA)
        out.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    cap.release()
    return out


def write_video(path: Path, frames: int, width: int, height: int, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), 60.0, (width, height))
    for _ in range(frames):
        writer.write(rng.integers(0, 256, (height, width, 3), dtype=np.uint8))
    writer.release()
    return str(path)


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(['import-video', *argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_round_trip_small_real_clip(tmp_path, capsys):
    out = tmp_path / 'rec'
    code, stdout, err = run_cli(capsys, str(out), '--calibration', CALIB, '--width', '136',
                                '--floor=-3,-2,2,2',
                                '--reference', str(DATA / 'single_0-100.trc'),
                                '--reference-offset', str(CLIP_FIRST), *VIDEOS)
    assert code == 0, err
    assert '10 frame sets x 4 cameras' in stdout
    # the 272x480 videos are a pure 1/4 scale of the 1088x1920 calibration: noted, not refused
    assert err.count('same aspect ratio') == 4
    expected = {c: decoded(v, 136, 240) for c, v in zip(CAMS, VIDEOS)}
    with RecordingReader(out) as reader:
        assert reader.cameras == list(CAMS)
        sets = list(reader.frames())
        bag_truth = reader.ground_truth()
    assert len(sets) == 10 and len(bag_truth) == 10
    for fs in sets:
        assert fs.stamp_ns == EPOCH_NS + round(fs.index * 1e9 / 60)
        for cam in CAMS:
            np.testing.assert_array_equal(fs.images[cam], expected[cam][fs.index])

    room = RoomCalibration.load(out / 'calibration.yaml')
    assert room.floor == (-3.0, -2.0, 2.0, 2.0)
    full = read_opencv_calibration(CALIB)
    trc = read_trc(DATA / 'single_0-100.trc')
    head = trc_to_room(trc.points[50, trc.markers.index('Head')])
    for cam in CAMS:
        assert (room.cameras[cam].width, room.cameras[cam].height) == (136, 240)
        # pixel-centre convention: u_small = (u_full + 0.5) * 136 / 1088 - 0.5
        np.testing.assert_allclose(room.cameras[cam].project(head),
                                   (full.cameras[cam].project(head) + 0.5) / 8 - 0.5,
                                   atol=1e-6)
    meta = yaml.safe_load((out / 'recording.yaml').read_text())
    assert meta['frames'] == 10 and meta['fps'] == 60 and meta['cameras'] == list(CAMS)
    assert meta['width'] == 136 and meta['height'] == 240 and meta['epoch_ns'] == EPOCH_NS

    with (out / 'ground_truth.csv').open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 10
    world = trc_to_room(trc.points)
    hip = 0.5 * (world[:, trc.markers.index('RHip')] + world[:, trc.markers.index('LHip')])
    for i, row in enumerate(rows):
        assert int(row['frame']) == i and int(row['person_id']) == 1
        assert float(row['x']) == pytest.approx(hip[CLIP_FIRST + i, 0], abs=1e-4)
        assert float(row['y']) == pytest.approx(hip[CLIP_FIRST + i, 1], abs=1e-4)
        assert float(row['z_head']) == pytest.approx(
            world[CLIP_FIRST + i, trc.markers.index('Head'), 2], abs=1e-4)
        assert row['visible_cameras'] == ';'.join(CAMS)


def test_named_videos_subset_and_start_offset(tmp_path, capsys):
    out = tmp_path / 'rec'
    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, '--start-offset',
                           'cam03=2', '--shortest', f'cam03={VIDEOS[2]}', f'cam01={VIDEOS[0]}')
    assert code == 0, err
    assert 'frame counts differ' in err
    cam01, cam03 = decoded(VIDEOS[0]), decoded(VIDEOS[2])
    with RecordingReader(out) as reader:
        assert sorted(reader.cameras) == ['cam01', 'cam03']
        sets = list(reader.frames())
    assert len(sets) == 8  # cam03 has 10 - 2 frames left
    for fs in sets:
        np.testing.assert_array_equal(fs.images['cam01'], cam01[fs.index])
        np.testing.assert_array_equal(fs.images['cam03'], cam03[fs.index + 2])
    assert RoomCalibration.load(out / 'calibration.yaml').names == ['cam01', 'cam03']


def test_fit_camera_policy():
    cam = read_opencv_calibration(CALIB).cameras['cam01']
    same, note = fit_camera(cam, 1088, 1920)
    assert same is cam and note is None
    half, note = fit_camera(cam, 544, 960)
    assert 'same aspect ratio' in note and half.K[0, 0] == pytest.approx(cam.K[0, 0] / 2)
    with pytest.raises(VideoImportError, match='aspect ratio differs'):
        fit_camera(cam, 1080, 1920)
    stretched, note = fit_camera(cam, 1080, 1920, fit_size=True)
    assert 'stretched' in note
    assert stretched.K[0, 0] == pytest.approx(cam.K[0, 0] * 1080 / 1088)
    assert stretched.K[1, 1] == pytest.approx(cam.K[1, 1])


def assert_one_line_error(code: int, err: str, *needles: str) -> None:
    assert code == 2
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith('mbtrack import-video: error: ')
    for needle in needles:
        assert needle in lines[0]


def test_bad_inputs_exit_2_with_one_line(tmp_path, capsys):
    out = tmp_path / 'rec'
    missing = str(tmp_path / 'nope.avi')
    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, *VIDEOS[:3], missing)
    assert_one_line_error(code, err, 'nope.avi', 'does not exist')

    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, f'cam01={VIDEOS[0]}',
                           f'camX={VIDEOS[1]}')
    assert_one_line_error(code, err, 'camX', 'cam01, cam02, cam03, cam04')

    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, *VIDEOS[:3])
    assert_one_line_error(code, err, '3 video(s) for 4')

    short = write_video(tmp_path / 'short.avi', 6, 272, 480)
    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, *VIDEOS[:3], short)
    assert_one_line_error(code, err, 'frame counts differ', 'cam04: 6', '--shortest')

    narrow = write_video(tmp_path / 'narrow.avi', 10, 200, 480)
    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, *VIDEOS[:3], narrow)
    assert_one_line_error(code, err, 'cam04', '200x480', '1088x1920', '--fit-size')

    code, _, err = run_cli(capsys, str(out), '--calibration', str(tmp_path / 'none.json'),
                           *VIDEOS)
    assert_one_line_error(code, err, 'none.json')

    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, '--start-offset',
                           'cam02=x', *VIDEOS)
    assert_one_line_error(code, err, 'cam02=x')
    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, '--floor', '1,2,3', *VIDEOS)
    assert_one_line_error(code, err, '--floor')
    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, '--floor', '1,2,0,3',
                           *VIDEOS)
    assert_one_line_error(code, err, 'floor bounds are empty')
    assert not out.exists()  # nothing written on any refusal

    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, '--fit-size', '--frames',
                           '2', *VIDEOS[:3], narrow)
    assert code == 0, err
    assert 'stretched' in err
    code, _, err = run_cli(capsys, str(out), '--calibration', CALIB, *VIDEOS)
    assert_one_line_error(code, err, 'not an empty directory')


def test_bad_arguments_are_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        main(['import-video', str(tmp_path / 'rec'), '--width', 'wide', *VIDEOS])
    assert info.value.code == 2
    assert_one_line_error(2, capsys.readouterr().err, '--width')
    with pytest.raises(SystemExit) as info:
        main(['import-video', str(tmp_path / 'rec'), *VIDEOS])
    assert_one_line_error(info.value.code, capsys.readouterr().err, '--calibration')


def test_import_videos_refuses_before_writing(tmp_path):
    room = read_opencv_calibration(CALIB)
    with pytest.raises(VideoImportError, match='--frames 11'):
        import_videos(tmp_path / 'rec', room, VIDEOS, max_frames=11)
    assert not (tmp_path / 'rec').exists()


@pytest.mark.parametrize('fmt', ['qualisys', 'camera-info'])
def test_other_calibration_formats_and_compressed(tmp_path, capsys, fmt):
    out = tmp_path / 'rec'
    if fmt == 'qualisys':
        extra = ['--calibration', str(DATA / 'Calib.qca.txt'), '--calibration-format', fmt]
    else:
        extra = ['--calibration', CALIB, '--calibration-format', fmt]
        extra += [f'--camera-info={c}={DATA / "camera_info" / f"{c}.yaml"}' for c in CAMS]
    code, _, err = run_cli(capsys, str(out), *extra, '--frames', '2', '--compressed', *VIDEOS)
    assert code == 0, err
    room = RoomCalibration.load(out / 'calibration.yaml')
    ref = read_opencv_calibration(CALIB).scaled(272, 480)
    for cam in CAMS:
        np.testing.assert_allclose(room.cameras[cam].K, ref.cameras[cam].K, atol=1e-9)
        np.testing.assert_allclose(room.cameras[cam].R, ref.cameras[cam].R, atol=1e-9)
    expected = {c: decoded(v) for c, v in zip(CAMS, VIDEOS)}
    with RecordingReader(out) as reader:
        sets = list(reader.frames())
    assert len(sets) == 2
    for fs in sets:
        for cam in CAMS:  # JPEG in the bag: close, not equal, and not channel-swapped
            diff = np.abs(fs.images[cam].astype(int) - expected[cam][fs.index].astype(int))
            assert diff.mean() < 4.0
