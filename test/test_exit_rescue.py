"""The exit rescue (AutoDetectionConfig.exit_rescue): a track that the exit rule would release while its person still stands at the door
is moved back onto them with its id; a track whose person walked out is released."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.detector import FrameEvidence
from mbtrack_ros.core.detection.manager import AutoDetection, AutoDetectionConfig
from mbtrack_ros.core.detection.release import Releaser
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.state import TrackEstimate

from test_detection import FPS, _detecting_tracker, backgrounds, make_room, paint, person
from test_exits import FORMER_EXIT_MARGIN

EXIT = (4.2, 4.7, 5.1, 6.2)          # beyond the painted room's north edge (floor y <= 4.7)
AT_DOOR = (4.5, 4.5)                 # a person standing on the floor right at the door
PUSHED = (4.85, 5.1)                 # a track estimate 0.4 m deep in the exit
SHAPE = BodyShape(1.8, 0.5)


def _room():
    """The painted room of test_detection with a door exit on its north wall; cam2 and cam3
    hang on that wall (the doorway rule's witnesses), no ceiling camera."""
    calib = replace(make_room(ceiling=False), exits=(EXIT,))
    assert set(calib.doorway_witnesses(np.array([AT_DOOR]), 0.5)) == {'cam2', 'cam3'}
    return calib


def _state(xy) -> np.ndarray:
    return np.array([xy[0], xy[1], 0.4, 0.6, 0.0, 0.0])


def _scene(calib, people, lit, tracks_xy):
    """(evidence, silhouettes, means, shapes, heads) of tracks at ``tracks_xy``, the
    foreground being the silhouettes of ``people`` in the cameras ``lit``."""
    h, w = 120, 160
    means = np.array([_state(xy) for xy in tracks_xy])
    evidence, sils = {}, {}
    for n, cam in calib.cameras.items():
        fg = np.zeros((h, w), bool)
        if n in lit and people:
            drawn = rasterize(cam, np.array([_state(p) for p in people]), SHAPE)
            fg = np.any([drawn.mask(i) > 0 for i in range(len(people))], axis=0)
        evidence[n] = FrameEvidence(np.zeros((h, w, 3), np.uint8), fg)
        sils[n] = rasterize(cam, means, [SHAPE] * len(means))
    return evidence, sils, means, [SHAPE] * len(means), np.full(len(means), 1.8)


def _rescue(calib, people, lit, tracks_xy, rescue=0.5):
    """``AutoDetection._rescue_exits`` for track 1 at ``tracks_xy[0]`` (other tracks at the
    rest) in the scene of :func:`_scene`. Returns (ids released, the detection, tracks)."""
    det = AutoDetection(calib, AutoDetectionConfig(exit_rescue=rescue, reach_age=0.0))
    det.bootstrap({n: [np.zeros((120, 160, 3), np.uint8)] for n in calib.cameras})
    scene = _scene(calib, people, lit, tracks_xy)
    tracks = [TrackEstimate(track_id=k + 1, mean=m.copy(), covariance=np.eye(4), height=1.8)
              for k, m in enumerate(scene[2])]
    return det._rescue_exits(0, tracks, [1], *scene), det, tracks


def test_a_track_pushed_into_the_exit_beside_its_free_person_is_moved_back():
    calib = _room()
    released, det, tracks = _rescue(calib, [AT_DOOR], calib.cameras, [PUSHED])
    assert released == []
    place = det.reach_moves[1]
    assert np.hypot(*(place - AT_DOOR)) < 0.3, place
    assert calib.exit_depth(place[None])[0] != calib.exit_depth(place[None])[0]  # NaN: floor
    assert np.allclose(tracks[0].mean[:2], place) and np.all(tracks[0].mean[2:4] == 0.0)
    check = det.exit_checks[0]
    assert check['id'] == 1 and check['rescued'] and check['place'] == tuple(place)
    assert check['coverage'] >= 0.5 and check['overall'] > 0.5
    # once per relocate_interval: the same track exiting again 1 s later is released
    again = det._rescue_exits(int(1e9), tracks, [1], *_scene(calib, [AT_DOOR], calib.cameras,
                                                             [PUSHED]))
    assert again == [1]


@pytest.mark.parametrize('case', ['walked out', 'tracked', 'nobody'])
def test_a_track_whose_person_is_gone_or_tracked_is_released(case):
    """Released: the person walked into the corridor (seen by cam0 and cam1 through the
    door, not by the door-wall cameras), or another track covers the person at the door,
    or there is no foreground at all."""
    calib = _room()
    if case == 'walked out':
        out = (4.65, 5.4)
        released, det, _ = _rescue(calib, [out], ('cam0', 'cam1'), [PUSHED])
    elif case == 'tracked':
        released, det, _ = _rescue(calib, [AT_DOOR], calib.cameras, [PUSHED, AT_DOOR])
    else:
        released, det, _ = _rescue(calib, [], calib.cameras, [PUSHED])
    assert released == [1] and 1 not in det.reach_moves
    assert det.exit_checks[0]['rescued'] is False and det.exit_checks[0]['coverage'] < 0.5


def test_bad_exit_rescue_is_refused():
    for bad in (-0.1, 1.5, float('nan')):
        with pytest.raises(DetectionError, match='exit_rescue'):
            AutoDetectionConfig(exit_rescue=bad)


@pytest.mark.parametrize('rescue', [0.5, 0.0])
def test_a_person_standing_at_the_door_keeps_the_id_of_a_track_pushed_into_the_exit(rescue):
    """End to end with the tracker on painted frames: a person standing at the door is
    tracked; the track is then put 0.4 m deep into the exit (where cam2 and cam3 cannot
    judge it and the filter drifts outwards). With the rescue the same
    track is back on the person in the next frames and no other id appears; without it the
    exit rule releases the track (a person re-found would get a new id; this one stands
    still, which the detector's motion test does not confirm)."""
    calib = _room()
    bgs = backgrounds(calib)
    rng = np.random.default_rng(6)
    tracker = _detecting_tracker(calib, bgs, seed=3)
    tracker.detection.config = replace(tracker.detection.config, exit_rescue=rescue)
    # the exit margin the rescue was measured with (PUSHED is 0.4 m deep)
    tracker.detection.releaser = Releaser(
        calib, replace(tracker.detection.releaser.config, exit_margin=FORMER_EXIT_MARGIN))

    def standing(k):
        return [person(*AT_DOOR, theta=-1.2)]
    ids, ended = set(), []
    for k in range(16):
        res = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, standing(k), rng))
        ids |= {t.track_id for t in res.tracks}
    assert tracker.track_ids == [1] and ids == {1}
    tracker.relocate_track(1, np.array([*PUSHED, 0.0, 0.5, -1.2, 0.0]))
    last = None
    for k in range(16, 40):
        res = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, standing(k), rng))
        ids |= {t.track_id for t in res.tracks}
        ended += res.released
        last = res
    if rescue > 0:
        assert ended == [] and ids == {1} and tracker.track_ids == [1]
        assert np.hypot(*(last.tracks[0].mean[:2] - AT_DOOR)) < 0.2
    else:
        assert ended == [1] and 1 not in tracker.track_ids


@pytest.mark.parametrize('ceiling', [True, False])
def test_a_person_who_walks_out_is_still_released_within_1_5_s_with_the_rescue(ceiling):
    """test_exits' walk-out clip (one person comes in, stands, leaves through the door)
    with the rescue on: the track ends within 1.5 s of the ground truth's last row and no
    exit decision keeps it (with the ceiling camera the exit rule ends it, the doorway
    rule off as in test_exits; without, the default rules)."""
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig
    from mbtrack_ros.synth import Synthesizer
    from mbtrack_ros.synth.presets import Preset

    from test_exits import _leaver

    synth = Synthesizer(Preset('leaver', 'one person leaves', 200, None, _leaver), seed=4,
                        width=320, height=240, ceiling=ceiling)
    tracker = Tracker(synth.calibration, TrackerConfig(detection=True, seed=0))
    tracker.detection.config = replace(tracker.detection.config, exit_rescue=0.5)
    if ceiling:   # the exit rule, not the doorway rule, ends it (as in test_exits)
        tracker.detection.releaser = Releaser(synth.calibration, replace(
            tracker.detection.releaser.config, doorway_band=0.0,
            exit_margin=FORMER_EXIT_MARGIN))
    last_truth = ended = None
    checks = []
    for frame in synth:
        if frame.ground_truth:
            last_truth = frame.index
        res = tracker.step(frame.stamp_ns, frame.images)
        checks += tracker.detection.exit_checks
        if res.released and ended is None and last_truth is not None:
            ended = frame.index
    assert ended is not None and 0 <= (ended - last_truth) / synth.fps <= 1.5
    assert not any(c['rescued'] for c in checks) and tracker.track_ids == []
    if ceiling:
        assert checks, 'the exit rule did not fire'
