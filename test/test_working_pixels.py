"""``TrackerConfig.working_pixels`` (the tracker works on images of about that many
pixels): validated, read by the node's parameter map and ``mbtrack replay``; the cameras are
scaled to match, every image is resized once per step, the pixel lengths follow the working
size, and tracking does not depend on the input size (the same room rendered at 320x240 and
640x480 tracks alike)."""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import pytest

from mbtrack_ros.core import camera as camera_module
from mbtrack_ros.core.detection.manager import AutoDetectionConfig
from mbtrack_ros.core.initiation import initial_tracks, plan_key_views
from mbtrack_ros.core.tracker import (
    REFERENCE_PIXELS, Tracker, TrackerConfig, TrackerError, length_scale)
from mbtrack_ros.synth.generator import Synthesizer

from conftest import make_room


@pytest.mark.parametrize('bad', [0, 100, -5, 76800.0, float('nan'), True, '76800', None])
def test_bad_working_pixels_are_rejected_in_one_line(bad):
    with pytest.raises(TrackerError, match='working_pixels must be an integer >=') as err:
        TrackerConfig(working_pixels=bad)
    assert '\n' not in str(err.value)


def test_replay_reads_the_scale_from_params_and_option(tmp_path, capsys):
    from mbtrack_ros.commands import replay

    parser = argparse.ArgumentParser()
    replay.add_parser(parser.add_subparsers())
    params = tmp_path / 'node.yaml'
    params.write_text('tracker_node:\n  ros__parameters:\n    tracker:\n'
                      '      working_pixels: 19200\n')

    def config(*extra: str) -> TrackerConfig:
        return replay._config(parser.parse_args(['replay', 'REC', '--out', str(tmp_path),
                                                 *extra]))

    assert config().working_pixels == REFERENCE_PIXELS
    assert config('--params', str(params)).working_pixels == 19200
    assert config('--params', str(params), '--working-pixels', '30000').working_pixels == 30000
    rec = tmp_path / 'rec'
    rec.mkdir()
    room = tmp_path / 'room.yaml'
    make_room().save(room)
    args = parser.parse_args(['replay', str(rec), '--out', str(tmp_path / 'o'),
                              '--config', str(room), '--working-pixels', '20'])
    assert replay.run(args) == 2
    err = capsys.readouterr().err.strip()
    assert 'working_pixels must be an integer >= 4800, got 20' in err and '\n' not in err


def test_node_parameter_map_has_the_scale():
    pytest.importorskip('rclpy')
    from mbtrack_ros.nodes.params import GLOBAL_PARAMETERS, TRACKER_PARAMETERS

    assert TRACKER_PARAMETERS['tracker.working_pixels'] == ('working_pixels', int)
    assert GLOBAL_PARAMETERS['tracker.working_pixels'][0] == REFERENCE_PIXELS


def test_calibration_scaled_by_projects_to_the_resized_pixels():
    room = make_room(160, 120)
    half = room.scaled_by(0.5)
    points = np.array([[1.0, 1.5, 0.0], [2.5, 3.0, 1.7], [0.5, 3.5, 1.0]])
    for name, cam in room.cameras.items():
        small = half.cameras[name]
        assert (small.width, small.height) == (80, 60)
        # pixel centres at integer coordinates: u' = (u + 0.5) s - 0.5
        np.testing.assert_allclose(small.project(points),
                                   (cam.project(points) + 0.5) * 0.5 - 0.5, atol=1e-9)
    assert room.scaled_by(1.0).cameras['cam0'].width == 160
    odd = room.scaled_by(0.75)
    assert (odd.cameras['cam0'].width, odd.cameras['cam0'].height) == (120, 90)


def test_camera_fit_is_the_block_mean_at_half_size():
    cam = make_room(8, 6).cameras['cam0']
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (12, 16, 3), dtype=np.uint8)
    fitted = cam.fit(image)
    blocks = image.reshape(6, 2, 8, 2, 3).astype(np.float64).mean(axis=(1, 3))
    assert fitted.shape == (6, 8, 3)
    assert np.abs(fitted.astype(np.float64) - blocks).max() <= 0.5 + 1e-9
    same = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    assert cam.fit(same) is same  # already at the size: no copy, no resize


@pytest.mark.parametrize('size', [(1280, 720), (1920, 1080), (1280, 960), (1000, 750)])
def test_camera_fit_pyramid_is_close_to_the_direct_area_resize(size):
    """``Camera.fit`` halves by 2x2 block means while the half is still at least the
    working size, then area-resizes the rest: within a few grey levels of OpenCV's direct
    area resize on a smooth picture (the same filter up to rounding and block borders)."""
    w, h = size
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    image = np.stack([127 + 100 * np.sin(xx / 41.0) * np.cos(yy / 33.0),
                      127 + 90 * np.cos((xx + yy) / 57.0), 60 + 0.1 * xx], -1)
    image = np.clip(image, 0, 255).astype(np.uint8)
    cam = make_room(8, 6).cameras['cam0'].scaled(w, h).at_most(76800)
    got = cam.fit(image)
    want = cv2.resize(image, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
    assert got.shape == want.shape == (cam.height, cam.width, 3)
    diff = np.abs(got.astype(np.float64) - want)
    assert diff.mean() < 1.0 and diff.max() <= 4


def test_camera_fit_at_half_size_is_the_direct_area_resize():
    """A power-of-two-fraction size (640x480 to 320x240) is one exact halving: the
    direct area resize, bit for bit, on any picture."""
    cam = make_room(8, 6).cameras['cam0'].scaled(640, 480).at_most(76800)
    image = np.random.default_rng(4).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    np.testing.assert_array_equal(cam.fit(image), cv2.resize(image, (320, 240),
                                                             interpolation=cv2.INTER_AREA))


def test_working_size_of_cameras_of_any_size():
    config = TrackerConfig()
    for (w, h) in [(320, 240), (640, 480), (1280, 720), (1920, 1080), (752, 480)]:
        cam = config.working_calibration(make_room(w, h)).cameras['cam0']
        assert abs(cam.width * cam.height - REFERENCE_PIXELS) < 0.01 * REFERENCE_PIXELS
        assert abs(cam.width / cam.height - w / h) < 0.01
        assert length_scale(config.working_calibration(make_room(w, h))) == \
            pytest.approx(1.0, abs=0.01)
    small = config.working_calibration(make_room(160, 120))
    assert small.cameras['cam0'].width == 160       # never enlarged
    assert length_scale(small) == 0.5
    more = TrackerConfig(working_pixels=4 * REFERENCE_PIXELS).working_calibration(
        make_room(1280, 960))
    assert (more.cameras['cam0'].width, more.cameras['cam0'].height) == (640, 480)


def test_pixel_lengths_scale_and_scale_one_changes_nothing():
    plain = TrackerConfig().detection_config()
    assert plain == AutoDetectionConfig(detector=plain.detector, release=plain.release)
    assert plain.background == AutoDetectionConfig().background
    half = TrackerConfig().detection_config(0.5)
    bg, people, det = half.background, half.background.people, half.detector
    assert bg.mask_dilation == 3 and bg.open_size == 3 and bg.close_size == 3
    assert (people.motion_dilation, people.dilation, people.edge_min_pixels) == (1, 2, 6)
    assert (det.edge_min_pixels, det.edge_neighbourhood) == (6, 4)
    # areas are scaled where they are used (given at 320x240): unchanged in the config
    assert det.min_area == plain.detector.min_area
    assert half.release == plain.release
    quarter = TrackerConfig().detection_config(0.25).background
    assert quarter.open_size == 1 and quarter.close_size == 3  # radius 1 -> 0, 2 -> 1
    room = make_room(640, 480)
    full = Tracker(room, TrackerConfig(working_pixels=4 * REFERENCE_PIXELS))
    small = Tracker(room, TrackerConfig(working_pixels=REFERENCE_PIXELS // 4))
    assert full.measurement.config.min_visible_pixels == 80  # an area: s^2
    assert small.measurement.config.min_visible_pixels == 5
    assert small.calibration.cameras['cam0'].width == 160
    assert full.calibration.cameras['cam0'] is room.cameras['cam0']


def test_every_image_is_resized_once_per_step(monkeypatch):
    synth = Synthesizer('clear-room-short', seed=1, frames=4, width=160, height=120)
    tracker = Tracker(synth.calibration, TrackerConfig(working_pixels=80 * 60,
                                                       detection=True, particles=20, seed=0))
    calls = []
    resize = cv2.resize

    def counting(image, size, *args, **kwargs):
        calls.append((image.shape[:2], tuple(size)))
        return resize(image, size, *args, **kwargs)

    monkeypatch.setattr(camera_module.cv2, 'resize', counting)
    seen = []
    set_images = tracker.measurement.set_images
    monkeypatch.setattr(tracker.measurement, 'set_images',
                        lambda images: (seen.append({n: im.shape for n, im in images.items()}),
                                        set_images(images))[1])
    frames = list(synth)
    for frame in frames:
        tracker.step(frame.stamp_ns, frame.images)
    n_cams = len(synth.calibration.cameras)
    frame_resizes = [c for c in calls if c[0] == (120, 160)]
    assert len(frame_resizes) == n_cams * len(frames)
    assert all(size == (80, 60) for _, size in frame_resizes)
    assert seen and all(shape[:2] == (60, 80) for step in seen for shape in step.values())


def _track(synth_frames, calibration, starts,
           pixels: int) -> dict[tuple[int, int], np.ndarray]:
    """(frame, person) -> tracked floor position, tracks started from ground truth."""
    tracker = Tracker(calibration, TrackerConfig(working_pixels=pixels, particles=100, seed=0))
    pending, person_of, out = list(starts), {}, {}
    for frame in synth_frames:
        while pending and pending[0].frame <= frame.index:
            init = pending.pop(0)
            person_of[tracker.add_track(init.model, init.state, init.stamp_ns)] = init.person_id
        result = tracker.step(frame.stamp_ns, frame.images)
        for t in result.tracks:
            out[frame.index, person_of[t.track_id]] = np.asarray(t.mean[:2])
    return out


def test_half_size_tracks_within_a_few_centimetres_of_full_size():
    synth = Synthesizer('clear-room-short', seed=1, frames=30)  # 320x240
    frames = list(synth)
    truth = [r for f in frames for r in f.ground_truth]
    calibration = synth.calibration
    plan = plan_key_views(calibration, truth)
    needed = {v.frame for views in plan.values() for v in views}
    key_images = {f.index: f.images for f in frames if f.index in needed}
    starts = sorted(initial_tracks(calibration, truth, key_images, plan, skip_missing=True),
                    key=lambda s: s.frame)
    assert starts
    full = _track(frames, calibration, starts, REFERENCE_PIXELS)
    half = _track(frames, calibration, starts, REFERENCE_PIXELS // 4)
    gt = {(r.frame, r.person_id): np.array([r.x, r.y]) for r in truth}
    keys = sorted(set(full) & set(half) & set(gt))
    assert len(keys) > 20
    apart = np.array([np.linalg.norm(full[k] - half[k]) for k in keys])
    err_full = np.array([np.linalg.norm(full[k] - gt[k]) for k in keys])
    err_half = np.array([np.linalg.norm(half[k] - gt[k]) for k in keys])
    assert np.median(apart) < 0.06
    assert err_half.mean() < err_full.mean() + 0.03


def test_every_node_parameter_is_in_the_ros_interface_table():
    """docs/ros_interface.md lists each parameter the node declares, with its default."""
    pytest.importorskip('rclpy')
    from mbtrack_ros.nodes.params import GLOBAL_PARAMETERS

    text = (Path(__file__).resolve().parents[1] / 'docs' / 'ros_interface.md').read_text(
        encoding='utf-8')
    rows = {line.split('|')[1].strip().strip('`'): line.split('|')[3].strip()
            for line in text.splitlines() if line.startswith('| `')}
    for name, (default, _, _) in GLOBAL_PARAMETERS.items():
        assert name in rows, name
        shown = rows[name].strip('`')
        if isinstance(default, bool):
            assert shown == str(default).lower(), name
        elif isinstance(default, (int, float)):
            assert float(shown) == default, name


def test_node_defaults_are_the_trackers_defaults():
    """Every tracker setting the node reads has the default of TrackerConfig (or, where
    TrackerConfig leaves it to the detection pipeline with None, of that pipeline): the
    node and `mbtrack replay` without --params track alike."""
    pytest.importorskip('rclpy')
    from mbtrack_ros.nodes.params import GLOBAL_PARAMETERS, TRACKER_PARAMETERS

    config = TrackerConfig()
    pipeline = config.detection_config()
    left_to_pipeline = {'detection_threshold': pipeline.detector.threshold,
                        'spare_support': pipeline.release.spare_support,
                        'release_recover_time': pipeline.release.recover_time,
                        'beside_threshold': pipeline.beside_threshold,
                        'reuse_time': pipeline.reuse_time,
                        'adaptation_rate': pipeline.adaptation.rate}
    for key, (field, _) in TRACKER_PARAMETERS.items():
        owner = config.motion if field.startswith('motion.') else config
        ours = getattr(owner, field.removeprefix('motion.'))
        if ours is None:
            ours = left_to_pipeline[field]
        assert GLOBAL_PARAMETERS[key][0] == ours, key


def test_same_room_at_twice_the_resolution_tracks_alike():
    """Working-resolution invariance: a room rendered at 320x240 and at 640x480 (default
    working_pixels: both tracked at 320x240) tracks as accurately."""
    errors = []
    for width, height in ((320, 240), (640, 480)):
        synth = Synthesizer('clear-room-short', seed=2, frames=20, width=width, height=height)
        calibration = synth.calibration
        frames = list(synth)
        truth = [r for f in frames for r in f.ground_truth]
        plan = plan_key_views(calibration, truth)
        needed = {v.frame for views in plan.values() for v in views}
        key_images = {f.index: f.images for f in frames if f.index in needed}
        starts = sorted(initial_tracks(calibration, truth, key_images, plan,
                                       skip_missing=True), key=lambda s: s.frame)
        out = _track(frames, calibration, starts, REFERENCE_PIXELS)
        gt = {(r.frame, r.person_id): np.array([r.x, r.y]) for r in truth}
        keys = sorted(set(out) & set(gt))
        assert len(keys) > 20
        errors.append(np.mean([np.linalg.norm(out[k] - gt[k]) for k in keys]))
    assert errors[1] < errors[0] + 0.03 and errors[1] < 0.1, errors


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'mono8', 'bgra8'])
def test_raw_images_decoded_at_the_working_size_equal_decode_then_fit(encoding):
    """``decode_raw(..., to=cam)`` resizes the message's own pixels (padded rows too) and
    converts the colours on the small image: the image of a full decode then ``Camera.fit``,
    bit for bit, never aliasing the message; at the working size already, a copy."""
    from mbtrack_ros.recording.images import CHANNELS, decode_raw

    cam = make_room(8, 6).cameras['cam0'].scaled(640, 480).at_most(76800)
    rng = np.random.default_rng(5)
    for w, h in ((640, 480), (320, 240)):
        ch = CHANNELS[encoding]
        step = w * ch + 6                                     # padded rows
        data = rng.integers(0, 256, step * h, dtype=np.uint8)
        full = decode_raw(encoding, h, w, step, data)
        got = decode_raw(encoding, h, w, step, data, to=cam)
        assert got.shape == (240, 320, 3)
        np.testing.assert_array_equal(got, cam.fit(full))
        assert not np.shares_memory(got, data)


def test_jpeg_decoded_at_a_reduced_scale_is_close_to_decode_then_fit():
    """A 1280x720 JPEG for a 370x208 working camera is decoded at 1/2 (640x360 is still
    larger; 1/4 would not be), then resized: within a few grey levels of the full decode
    resized, on a smooth picture; a size the reductions cannot keep (1/2 of 700 < 370 wide)
    is decoded in full."""
    from mbtrack_ros.recording.images import decode_compressed, encode_compressed

    yy, xx = np.mgrid[0:720, 0:1280].astype(np.float64)
    image = np.stack([127 + 100 * np.sin(xx / 41.0) * np.cos(yy / 33.0),
                      127 + 90 * np.cos((xx + yy) / 57.0), 60 + 0.1 * xx], -1)
    image = np.clip(image, 0, 255).astype(np.uint8)
    fmt, data = encode_compressed(image, 'jpeg')
    cam = make_room(1280, 720).cameras['cam0'].at_most(76800)      # square pixels
    assert (cam.width, cam.height) == (370, 208)
    decoded = cv2.imdecode(np.frombuffer(bytes(data), np.uint8), cv2.IMREAD_REDUCED_COLOR_2)
    assert decoded.shape[:2] == (360, 640)
    got = decode_compressed(fmt, data, to=cam)
    want = cam.fit(decode_compressed(fmt, data))
    assert got.shape == want.shape == (208, 370, 3)
    diff = np.abs(got.astype(np.float64) - want)
    assert diff.mean() < 1.0 and diff.max() <= 8
    small = make_room(8, 6).cameras['cam0'].scaled(700, 525).at_most(76800)
    fmt, data = encode_compressed(cv2.resize(image, (700, 525)), 'jpeg')
    np.testing.assert_array_equal(decode_compressed(fmt, data, to=small),
                                  small.fit(decode_compressed(fmt, data)))
