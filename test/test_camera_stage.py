"""The per-camera stage (camera_node's core) and the fusion node's received foreground give
the tracks of one process, up to the one-frame latency of the masked background update."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from mbtrack_ros.core.detection.background import BackgroundModel
from mbtrack_ros.core.detection.camera_stage import (
    CameraStage, pack_masks, unpack_masks)
from mbtrack_ros.core.tracker import Tracker, TrackerConfig

FRAMES = 30


@pytest.fixture(scope='module')
def recording(tmp_path_factory) -> Path:
    from mbtrack_ros.synth.generator import generate
    return generate('clear-room-short', tmp_path_factory.mktemp('rec') / 'room', seed=100,
                    frames=FRAMES, width=160, height=120)


def test_pack_unpack_masks_round_trip(rng):
    planes = [rng.random((7, 9)) < 0.5 for _ in range(3)]
    packed = pack_masks(*planes)
    assert packed.dtype == np.uint8
    for a, b in zip(unpack_masks(packed), planes):
        np.testing.assert_array_equal(a, b)


def test_stage_is_the_background_model_with_the_given_exclusion(room, rng):
    """Brute force: a stage's foreground and presence are a plain BackgroundModel's fed the
    same frames and exclusions in the order of one process."""
    cam = room.cameras['cam0']
    stage = CameraStage(cam)
    ref = BackgroundModel(stage.config, name='cam0')
    base = rng.integers(0, 255, (cam.height, cam.width, 3), dtype=np.uint8)
    for k in range(12):
        image = base.copy()
        image[40:80, 10 + 5 * k:40 + 5 * k] = 255 - image[40:80, 10 + 5 * k:40 + 5 * k]
        exclude = np.zeros(image.shape[:2], bool)
        exclude[30:90, 5 * k:50 + 5 * k] = True
        stage.set_exclusion(exclude)
        got = stage.process(image)
        fg = ref.apply(image, exclude=exclude)
        if fg is None:
            assert got.foreground is None
            continue
        np.testing.assert_array_equal(got.foreground, fg)
        np.testing.assert_array_equal(got.presence, ref.presence())
        assert got.foreground.any()


@pytest.mark.parametrize('pipeline', [False, True])
def test_fusion_gives_the_tracks_of_one_process(recording, pipeline):
    """Camera stages + a fusion tracker vs. one tracker on a room with people from its first
    frame (the bootstrap's people cue goes through the fusion node). Measured at 160x120:
    the same ids on every frame but at most three (releases a frame or two apart: both
    release the tracks of the two people walking at the end), positions
    within 14 cm on one frame (13 cm with ``pipeline_search``), mostly millimetres: the
    particle filter amplifies the update's one-frame latency. With ``pipeline_search`` the
    search of a frame set reads its own masks while the next set is received."""
    from mbtrack_ros.evaluation.fusion import fusion_vs_single

    got = fusion_vs_single(recording, TrackerConfig(detection=True, seed=7,
                                                    pipeline_search=pipeline))
    tracked, same_ids, gaps = got.tracked, got.same_ids, got.gaps
    assert got.frames == FRAMES
    assert tracked >= 10   # people were tracked: the comparison says something
    assert same_ids >= FRAMES - 3
    # measured: max 132 mm (one frame, 86 mm the next), with pipeline_search one frame at
    # 126 mm (the gaps start at 0 and grow as the filter carries the update's differences
    # on, then shrink as both follow the same person)
    assert max(gaps) < 0.15 and np.median(gaps) < 0.01


def test_stage_works_at_the_trackers_scale(room, rng):
    """With working_pixels the stage resizes once, to the size of the tracker's cameras."""
    pixels = room.cameras['cam0'].width * room.cameras['cam0'].height // 4
    tracker = Tracker(room, TrackerConfig(detection=True, working_pixels=pixels))
    stage = CameraStage(room.cameras['cam0'], tracker.detection.config.background,
                        working_pixels=pixels)
    image = rng.integers(0, 255, (room.cameras['cam0'].height, room.cameras['cam0'].width, 3),
                         dtype=np.uint8)
    want = tracker.calibration.cameras['cam0']
    got = stage.process(image)
    assert got.image.shape == (want.height, want.width, 3)
    np.testing.assert_array_equal(got.image, want.fit(image))
    assert stage.camera.K.tolist() == want.K.tolist()


def test_fusion_bench_tracks_in_one_process_as_replay_does(recording, tmp_path):
    """``mbtrack bench --fusion``'s one-process run is ``mbtrack replay REC --seed S``:
    the same tracker configuration and frame-set synchroniser give the same track rows."""
    from mbtrack_ros.cli import main
    from mbtrack_ros.commands.replay import sync_options
    from mbtrack_ros.core.camera import RoomCalibration
    from mbtrack_ros.evaluation.fusion import fusion_vs_single
    from mbtrack_ros.recording.csvfiles import read_tracks

    assert main(['replay', str(recording), '--out', str(tmp_path), '--seed', '7']) == 0
    replayed = read_tracks(tmp_path / 'tracks.csv')
    config = TrackerConfig.from_dict({'seed': 7, 'detection': True})
    calibration = RoomCalibration.load(recording / 'calibration.yaml')
    got = fusion_vs_single(recording, config, sync_options(recording, calibration))
    single = got.rows['single']
    assert len(replayed) >= 10 and len(single) == len(replayed)
    for a, b in zip(single, replayed):
        assert (a.stamp_ns, a.track_id) == (b.stamp_ns, b.track_id)
        assert abs(a.x - b.x) < 1e-3 and abs(a.y - b.y) < 1e-3


def test_fusion_bench_refuses_a_bad_jpeg_quality(capsys):
    from mbtrack_ros.cli import main
    assert main(['bench', '--fusion', 'clear-room-short', '--fusion-jpeg', '0']) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        'mbtrack bench: error: --fusion-jpeg must be 1-100, got 0']


def test_fusion_with_jpeg_images_tracks_the_same_people(recording):
    """JPEG-coded working images (camera_node image_format jpeg) change the appearance
    likelihood and the detection's edges a little: the fusion tracks change, their MOTA
    stays within 10 points of raw images' (measured at 160x120: 58.3 / 53.3 %)."""
    from mbtrack_ros.evaluation.clear_mot import clear_mot
    from mbtrack_ros.evaluation.fusion import fusion_vs_single
    from mbtrack_ros.recording.csvfiles import read_ground_truth

    truth = read_ground_truth(recording / 'ground_truth.csv')
    config = TrackerConfig(detection=True, seed=7)
    raw = fusion_vs_single(recording, config)
    jpeg = fusion_vs_single(recording, config, jpeg_quality=90)
    assert raw.rows['single'] == jpeg.rows['single']     # the one process is untouched
    assert raw.rows['fusion'] != jpeg.rows['fusion']     # the images did change
    a, b = (clear_mot(r.rows['fusion'], truth).mota for r in (raw, jpeg))
    assert a > 0.3 and abs(a - b) < 0.1


def test_stage_scores_particles_as_the_tracker_does(room, rng):
    """Brute force: a camera stage's scores of a request (CameraStage.score) are the
    tracker's own for that camera (MeasurementModel.hjs on the same image and masks, the
    possible foreground undecided), bit for bit, and a tracker handed the stage's scores
    (set_scorers) gives the same log-likelihoods and visible fractions."""
    from mbtrack_ros.core.appearance import PersonModel
    from mbtrack_ros.core.detection.camera_stage import CameraFrame
    from mbtrack_ros.core.likelihood import LikelihoodConfig, MeasurementModel

    cam = room.cameras['cam0']
    image = rng.integers(0, 255, (cam.height, cam.width, 3), dtype=np.uint8)
    fg = np.zeros((cam.height, cam.width), bool)
    fg[20:100, 30:90] = True
    possible = np.zeros_like(fg)
    possible[20:50, 30:60] = True
    models = [PersonModel(1.75, 0.5, view_angles=[0.0, np.pi],
                          histograms=rng.random((2, 3, 512))),
              PersonModel(1.6, 0.45, view_angles=[0.0], histograms=rng.random((1, 3, 512)))]
    particles = [np.column_stack([rng.uniform(1, 3, (40, 2)), rng.normal(0, 0.3, (40, 2)),
                                  rng.uniform(-3, 3, 40), np.zeros(40)]) for _ in models]
    weights = [rng.random(40) for _ in models]

    def model(scorers=None):
        m = MeasurementModel(room, LikelihoodConfig(threads=1))
        m.set_images({'cam0': image})
        m.set_foreground({'cam0': fg}, undecided={'cam0': possible}, neutral=0.3)
        if scorers:
            m.set_scorers(scorers)
        return m

    requests, replies = [], []
    stage = CameraStage(cam)
    stage.last = CameraFrame(image, fg, possible, fg)

    def score(request):
        requests.append(request)
        replies.append(stage.score(request))
        return lambda: replies[-1]

    local = model().hjs(particles, weights, models)
    tracker = model({'cam0': score})
    remote = tracker.hjs(particles, weights, models)
    assert len(replies) == 1 and np.isfinite(replies[0].cover).sum() > 20
    for a, b in zip(local.loglik, remote.loglik):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(local.visible_fraction, remote.visible_fraction)
    assert local.loglik[0].std() > 0    # the scores say something
    # the next frame set: the key views go only once; a restarted stage, which lacks
    # them, answers None (the tracker scores the camera itself) and gets them next time
    tracker.set_images({'cam0': image})
    tracker.set_foreground({'cam0': fg}, undecided={'cam0': possible}, neutral=0.3)
    again = tracker.hjs(particles, weights, models)
    assert requests[0].key_targets.tolist() == [0, 1] and len(requests[1].key_targets) == 0
    stage = CameraStage(cam)
    stage.last = CameraFrame(image, fg, possible, fg)
    for k in range(2):
        tracker.set_images({'cam0': image})
        tracker.set_foreground({'cam0': fg}, undecided={'cam0': possible}, neutral=0.3)
        restarted = tracker.hjs(particles, weights, models)
        for a, b, c in zip(local.loglik, again.loglik, restarted.loglik):
            np.testing.assert_array_equal(a, b)
            np.testing.assert_array_equal(a, c)
    assert len(requests[2].key_targets) == 0 and replies[2] is None
    assert requests[3].key_targets.tolist() == [0, 1] and replies[3] is not None
    # one model's key views change: only they are sent again
    models[1].histograms = rng.random((1, 3, 512))
    local = model().hjs(particles, weights, models)
    for k in range(2):
        tracker.set_images({'cam0': image})
        tracker.set_foreground({'cam0': fg}, undecided={'cam0': possible}, neutral=0.3)
        changed = tracker.hjs(particles, weights, models)
        for a, b in zip(local.loglik, changed.loglik):
            np.testing.assert_array_equal(a, b)
    assert requests[4].key_targets.tolist() == [1] and len(requests[5].key_targets) == 0
    # a stage with no frame answers None: the tracker scores the camera itself
    idle = CameraStage(cam)
    fallback = model({'cam0': lambda r: lambda: idle.score(r)}).hjs(particles, weights,
                                                                    models)
    for a, b in zip(local.loglik, fallback.loglik):
        np.testing.assert_array_equal(a, b)


def test_stage_refuses_a_malformed_score_request(room, rng):
    """A request whose arrays do not fit together is refused with DetectionError before a
    kernel indexes with it; a reply of the wrong shape is refused by the tracker."""
    from dataclasses import replace

    from mbtrack_ros.core.detection import DetectionError
    from mbtrack_ros.core.detection.camera_stage import CameraFrame
    from mbtrack_ros.core.likelihood import (
        CameraRequest, CameraScores, LikelihoodError, MeasurementModel)

    cam = room.cameras['cam0']
    stage = CameraStage(cam)
    stage.last = CameraFrame(rng.integers(0, 255, (cam.height, cam.width, 3), np.uint8))
    good = CameraRequest(np.array([[2.0, 2.0, 0, 0, 0, 0]]), np.zeros(1, np.int64),
                         np.ones(1), np.full(1, 1.7), np.full(1, 0.5), 0.45, np.zeros((1, 1)),
                         np.ones(1, np.int64), rng.random((1, 1, 1536)), False, 0.03, 0.15,
                         1, 20)
    assert stage.score(good).loglik.shape == (1,)
    for bad in (replace(good, target=np.ones(1, np.int64)),           # no target 1
                replace(good, n_views=np.full(1, 2, np.int64)),       # more views than keys
                replace(good, prior=np.ones(2)),
                replace(good, key=np.zeros((1, 1, 7)))):
        with pytest.raises(DetectionError, match='malformed score request'):
            stage.score(bad)
    m = MeasurementModel(room)
    m.set_images({'cam0': stage.last.image})
    m.set_scorers({'cam0': lambda r: lambda: CameraScores.empty(len(r.states) + 1, 1)})
    with pytest.raises(LikelihoodError, match='cam0: camera scores loglik'):
        m.hjs([good.states], [np.ones(1)], [_model(rng)])
    with pytest.raises(LikelihoodError, match='unknown camera'):
        m.set_scorers({'nope': stage.score})


def _model(rng):
    from mbtrack_ros.core.appearance import PersonModel
    return PersonModel(1.7, 0.5, view_angles=[0.0], histograms=rng.random((1, 3, 512)))


def test_stage_scoring_leaves_the_fusion_tracks_unchanged(recording):
    """The camera stages scoring the fusion tracker's particles (the default) or the
    fusion tracker scoring them itself: the same fusion tracks, row for row."""
    from mbtrack_ros.evaluation.fusion import fusion_vs_single

    config = TrackerConfig(detection=True, seed=7)
    staged = fusion_vs_single(recording, config)
    itself = fusion_vs_single(recording, config, stage_likelihood=False)
    assert staged.scored > 0 and itself.scored == 0
    assert len(staged.rows['fusion']) >= 10
    assert staged.rows['fusion'] == itself.rows['fusion']
    assert staged.rows['single'] == itself.rows['single']


def test_received_foreground_computes_the_cue_in_the_background_with_the_same_result(
        recording):
    """``background_cue``: the bootstrap's regions and people places are those of the
    synchronous cue, given by a later receive() (the frame sets in between are kept but
    do not change what the cue saw), and receive() does not wait for the cue."""
    from dataclasses import replace

    from mbtrack_ros.core.camera import RoomCalibration
    from mbtrack_ros.core.detection.camera_stage import ReceivedForeground
    from mbtrack_ros.recording.bag import RecordingReader

    calibration = RoomCalibration.load(recording / 'calibration.yaml')
    config = replace(TrackerConfig(), detection=True)
    tracker = Tracker(calibration, config)
    background = tracker.detection.config.background
    banks = [ReceivedForeground(tracker.detection.calibration, background,
                                background_cue=b) for b in (False, True)]
    stages = {n: CameraStage(calibration.cameras[n], background) for n in calibration.names}
    got: list[dict] = [{}, {}]
    with RecordingReader(recording) as reader:
        images = [fs.images for fs in reader.frames()]
    k, frames, started = 0, None, None   # started: the receive() that started the models
    deadline = time.monotonic() + 120.0
    while not got[1] and time.monotonic() < deadline:
        if k < len(images):  # the recording's frames, then its last again while the cue runs
            frames = {n: (s.hold(images[k][n]) if s.awaiting_regions
                          else s.process(images[k][n])) for n, s in stages.items()}
        k += 1
        for bank, out in zip(banks, got):
            out.update(bank.receive(frames))
        if got[0] and started is None:
            started = k
        elif not got[1]:
            time.sleep(0.02)
    assert got[0] and set(got[0]) == set(got[1]) == set(calibration.names)
    assert k > started   # the background cue's answer came with a later call
    for name in calibration.names:
        for a, b in zip(got[0][name], got[1][name]):
            np.testing.assert_array_equal(a, b)
    places = [bank.bootstrap_cue.take_places() for bank in banks]
    assert places[0] is not None and len(places[0])
    np.testing.assert_array_equal(places[0], places[1])
