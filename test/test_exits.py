"""Exits: walkable rectangles beyond a door (RoomCalibration.exits), the motion model's
reflection in floor + exits, and the release of a track that walked out (Releaser.exited)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mbtrack_ros.core.camera import CalibrationError, RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.detector import Detector, DetectorConfig
from mbtrack_ros.core.detection.release import ReleaseConfig, Releaser
from mbtrack_ros.core.dynamics import DynamicsError, MotionConfig, predict
from mbtrack_ros.synth.presets import Preset

FORMER_EXIT_MARGIN = 0.3   # m: a smaller ReleaseConfig.exit_margin than the default
from mbtrack_ros.synth.room import default_room, make_calibration

from conftest import make_room

FLOOR = (0.0, 0.0, 6.0, 5.0)                 # conftest.make_room's floor
EXIT_N = (4.0, 5.0, 5.0, 6.5)                # beyond the north edge
EXIT_W = (-1.0, 2.0, 0.0, 3.0)               # beyond the west edge


def _bounce(p: float, v: float, lo: float, hi: float,
            stop: bool) -> tuple[float, float]:
    """Reflection at the walls lo, hi one bounce at a time (the plain reference); with
    ``stop`` (``MotionConfig.wall_stops``) a position outside loses its velocity."""
    if stop and (p < lo or p > hi):
        v = 0.0
    while p < lo or p > hi:
        p, v = (2 * lo - p, -v) if p < lo else (2 * hi - p, -v)
    return p, v


def _inside(x: float, y: float, rect) -> bool:
    return rect[0] <= x <= rect[2] and rect[1] <= y <= rect[3]


def _reference_walk(start: np.ndarray, moved: np.ndarray, floor, exits,
                    stop: bool) -> np.ndarray:
    """Positions (and velocities) after the move, particle by particle: kept when they land
    in the floor or an exit, else reflected in the rectangle they started from."""
    out = moved.copy()
    for i in range(len(out)):
        x, y = out[i, 0], out[i, 1]
        if any(_inside(x, y, r) for r in (floor, *exits)):
            continue
        home = next((r for r in (floor, *exits) if _inside(*start[i, :2], r)), floor)
        out[i, 0], out[i, 2] = _bounce(x, out[i, 2], home[0], home[2], stop)
        out[i, 1], out[i, 3] = _bounce(y, out[i, 3], home[1], home[3], stop)
    return out


@pytest.mark.parametrize('seed', range(4))
def test_reflection_in_floor_and_exits_equals_the_plain_reference(seed):
    """Noise-free constant-velocity moves (so the move itself is known) from the floor,
    from the exits and from outside every rectangle, with steps up to several metres;
    even seeds with a stopping wall (the default), odd ones with bounces."""
    rng = np.random.default_rng(seed)
    n = 6000
    p = np.zeros((n, 6))
    starts = [FLOOR, EXIT_N, EXIT_W, (-2.0, -2.0, 8.0, 8.0)]
    which = rng.integers(0, len(starts), n)
    for k, r in enumerate(starts):
        m = which == k
        p[m, 0] = rng.uniform(r[0], r[2], m.sum())
        p[m, 1] = rng.uniform(r[1], r[3], m.sum())
    p[:, 2:4] = rng.normal(0.0, 1.5, (n, 2)) * rng.choice([0.3, 1.0, 4.0], (n, 1))
    stop = seed % 2 == 0
    cfg = MotionConfig(velocity_noise=0.0, position_noise=0.0, orientation_noise=0.0,
                       sit_flip_rate=0.0, max_speed=100.0, wall_stops=stop)
    out = predict(p, 1.0, cfg, rng, floor=FLOOR, exits=(EXIT_N, EXIT_W))
    free = p.copy()
    free[:, :2] += free[:, 2:4]
    expected = _reference_walk(p, free, FLOOR, (EXIT_N, EXIT_W), stop)
    np.testing.assert_allclose(out[:, :2], expected[:, :2], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(out[:, 2:4], expected[:, 2:4])
    inside = [any(_inside(x, y, r) for r in (FLOOR, EXIT_N, EXIT_W)) for x, y in out[:, :2]]
    assert all(inside)
    # particles do walk into the exits, and come back out of them
    from_floor = which == 0
    in_exit = np.array([_inside(x, y, EXIT_N) for x, y in out[:, :2]])
    assert (from_floor & in_exit).sum() > 3
    from_exit = which == 1
    assert (from_exit & np.array([_inside(x, y, FLOOR) for x, y in out[:, :2]])).sum() > 10
    # without exits the same moves stay on the floor (today's reflection)
    only = predict(p, 1.0, cfg, rng, floor=FLOOR)
    assert all(_inside(x, y, FLOOR) for x, y in only[:, :2])


def test_floor_only_reflection_is_unchanged_by_an_empty_exit_list():
    rng = np.random.default_rng(3)
    p = np.c_[rng.uniform(-1, 7, (200, 2)), rng.normal(0, 2, (200, 2)), np.zeros((200, 2))]
    a = predict(p, 0.5, MotionConfig(), np.random.default_rng(1), floor=FLOOR)
    b = predict(p, 0.5, MotionConfig(), np.random.default_rng(1), floor=FLOOR, exits=())
    np.testing.assert_array_equal(a, b)
    with pytest.raises(DynamicsError, match='floor'):
        predict(p, 0.5, MotionConfig(), rng, exits=(EXIT_N,))
    with pytest.raises(DynamicsError):
        predict(p, 0.5, MotionConfig(), rng, floor=FLOOR, exits=((1.0, 2.0),))


# -- calibration ----------------------------------------------------------------------------
def test_exits_round_trip_and_default(tmp_path):
    room = make_room()
    assert room.exits == ()
    room.save(tmp_path / 'plain.yaml')
    assert 'exits' not in (tmp_path / 'plain.yaml').read_text()   # old files unchanged
    with_exits = replace(room, exits=(EXIT_N, [-1, 2, 0, 3]))
    with_exits.save(tmp_path / 'c.yaml')
    back = RoomCalibration.load(tmp_path / 'c.yaml')
    assert back.exits == (EXIT_N, EXIT_W)
    assert back.floor == room.floor


@pytest.mark.parametrize('rect, message', [
    ((4.0, 5.0, 4.0, 6.0), 'empty'),                 # no width
    ((4.0, 6.0, 5.0, 5.5), 'empty'),                 # y_max < y_min
    ((4.0, 4.5, 5.0, 6.0), 'overlaps the floor'),
    ((1.0, 1.0, 2.0, 2.0), 'overlaps the floor'),    # inside the floor
    ((4.0, 5.2, 5.0, 6.0), 'does not share a border'),
    ((6.0, 5.0, 7.0, 6.0), 'does not share a border'),   # touches a corner only
    ((1.0, 2.0), 'x_min, y_min, x_max, y_max'),
])
def test_a_bad_exit_is_refused_with_one_line(tmp_path, rect, message):
    room = make_room()
    with pytest.raises(CalibrationError, match=message) as err:
        replace(room, exits=(rect,))
    assert '\n' not in str(err.value)
    doc = room.to_dict()
    doc['exits'] = [list(rect)]
    with pytest.raises(CalibrationError, match=message):
        RoomCalibration.from_dict(doc)
    doc['exits'] = 'north'
    with pytest.raises(CalibrationError, match='exits must be a list'):
        RoomCalibration.from_dict(doc)


def test_exit_depth_is_the_distance_from_the_floor_inside_exits_only():
    room = replace(make_room(), exits=(EXIT_N, EXIT_W))
    xy = np.array([[4.5, 5.3], [4.5, 4.0], [3.0, 5.5], [-0.4, 2.5], [5.0, 6.5], [4.5, 5.0]])
    depth = room.exit_depth(xy)
    np.testing.assert_allclose(depth[[0, 3, 4, 5]], [0.3, 0.4, 1.5, 0.0])
    assert np.isnan(depth[[1, 2]]).all()
    assert np.isnan(make_room().exit_depth(xy)).all()


# -- synth room, detection grid, release --------------------------------------------------
def test_synth_calibration_has_the_door_exit_and_the_detector_grid_stays_out_of_it():
    room = default_room()
    calib = make_calibration(room, width=160, height=120)
    (ex,) = calib.exits
    # the door's x span, from the walkable floor's edge through the wall into the corridor
    assert ex == (room.door[0], room.walkable[3], room.door[1], room.depth + 1.2)
    margin = ReleaseConfig().exit_margin
    for zones in ('floor', 'entry'):
        det = Detector(calib, DetectorConfig(zones=zones))
        depth = calib.exit_depth(det.coarse_xy)
        # no hypothesis where a new track would be released at once
        assert not (depth > margin).any()
        x0, y0, x1, y1 = det._bounds()                 # the fine search's bounds too
        assert calib.exit_depth(np.array([[0.5 * (ex[0] + ex[2]), y1]]))[0] <= margin
    assert RoomCalibration.from_dict(calib.to_dict()).exits == calib.exits


def test_releaser_ends_tracks_beyond_the_exit_margin_only():
    room = replace(make_room(), exits=(EXIT_N,))
    rel = Releaser(room, ReleaseConfig(exit_margin=0.4))
    xy = [[4.5, 5.3], [4.5, 5.45], [4.5, 4.9], [3.0, 5.0], [4.9, 6.4]]
    assert rel.exited([1, 2, 3, 4, 5], xy) == [2, 5]
    assert Releaser(make_room()).exited([1, 2], xy[:2]) == []    # no exits: never
    with pytest.raises(DetectionError):
        rel.exited([1], xy)
    with pytest.raises(DetectionError, match='exit_margin'):
        ReleaseConfig(exit_margin=-0.1)


def _leaver(crowd):
    """One person comes in from the corridor, stands in the room, walks out again (the
    clear-room way of leaving: to the door, a pause, 1.3 m into the corridor, gone)."""
    cx, depth = crowd.room.door_centre
    w = crowd.add((cx, depth + 1.6), behaviour='room', theta=-0.5 * np.pi, height=1.75,
                  leave_time=1e9)
    w.in_door = True
    w.tasks = [['pause', 0.8], ['goto', np.array([cx, 3.3]), 0.9, 'door'], ['pause', 0.5],
               ['goto', np.array([cx, depth - 0.7]), 0.9], ['pause', 0.5],
               ['goto', np.array([cx, depth + 1.3]), 0.9, 'door'], ['gone']]


@pytest.mark.parametrize('ceiling', [True, False])
@pytest.mark.parametrize('rules', ['exit', 'default'])
def test_a_person_who_walks_out_is_released_within_1_5_s(ceiling, rules):
    """A short synth recording: the track is released within 1.5 s of the ground truth's
    last row (the person crossing the wall). ``exit``: the doorway rule off and the exit
    margin at 0.3 m; with the ceiling camera the track
    follows the person through the door and the exit rule releases it (without exits the
    person, visible in the corridor, held it at the floor edge). Without the ceiling camera (seed 4) the track loses the person at the door and
    the support timeout ends it first. ``default``: the doorway rule ends the track before
    it reaches today's exit margin, 0.6 m (test_release_doorway)."""
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig
    from mbtrack_ros.synth import Synthesizer

    synth = Synthesizer(Preset('leaver', 'one person leaves', 200, None, _leaver), seed=4,
                        width=320, height=240, ceiling=ceiling)
    assert synth.calibration.exits
    tracker = Tracker(synth.calibration, TrackerConfig(detection=True, seed=0))
    if rules == 'exit':
        tracker.detection.releaser = Releaser(synth.calibration, replace(
            tracker.detection.releaser.config, doorway_band=0.0, exit_margin=FORMER_EXIT_MARGIN))
    exited = []
    original = tracker.detection.releaser.exited

    def logged(ids, xy):
        out = original(ids, xy)
        exited.extend(out)
        return out

    tracker.detection.releaser.exited = logged
    last_truth = ended = None
    born = set()
    for frame in synth:
        if frame.ground_truth:
            last_truth = frame.index
        res = tracker.step(frame.stamp_ns, frame.images)
        born |= {t.track_id for t in res.tracks}
        if res.released and ended is None and last_truth is not None:
            ended = frame.index
    assert len(born) == 1 and last_truth is not None
    assert ended is not None and 0 <= (ended - last_truth) / synth.fps <= 1.5
    if ceiling and rules == 'exit':
        assert exited == sorted(born)
    assert tracker.track_ids == []


def test_cameras_on_the_door_wall_cannot_see_into_the_exit():
    """Beyond the wall (the cameras' y, 4.9 m) the exit is hidden from the cameras on the
    door's wall; its strip between the floor's edge (4.7 m) and the wall is not."""
    calib = make_calibration(default_room(), width=160, height=120)
    xy = np.array([[4.6, 5.3], [4.3, 6.0], [4.6, 4.5], [2.0, 2.0], [4.6, 4.85], [4.6, 4.95]])
    assert calib.floor[3] < 4.85 < calib.cameras['cam2'].center[1] == pytest.approx(4.9)
    for name, cam in calib.cameras.items():
        hidden = calib.exit_hidden(name, xy)
        behind = cam.center[1] >= calib.floor[3]          # on the north wall, like the door
        assert hidden.tolist() == [behind, behind, False, False, False, behind], name
    assert {n for n in calib.names if calib.exit_hidden(n, xy[:1])[0]} == {'cam2', 'cam3'}
    assert not make_room().exit_hidden('cam0', xy).any()        # no exits


def test_hidden_exit_particles_score_their_targets_mean_in_that_camera():
    """The likelihood of particles a camera cannot see in the exit is the prior-weighted
    mean of the target's other particles in that camera (a loop over targets here); the
    others keep their values; cameras that see the exit are unchanged."""
    from mbtrack_ros.core.appearance import PersonModel
    from mbtrack_ros.core.likelihood import MeasurementModel
    from mbtrack_ros.synth import Synthesizer

    synth = Synthesizer(Preset('leaver', 'one person leaves', 1, None, _leaver), seed=4,
                        width=160, height=120)
    frame = next(iter(synth))
    calib = synth.calibration
    rng = np.random.default_rng(5)
    hists = rng.random((1, 3, 512)) ** 4
    hists /= hists.sum(axis=2, keepdims=True)
    models = [PersonModel(1.75, 0.5, [0.0], hists)]
    parts = []
    for _ in range(2):
        p = np.zeros((40, 6))
        p[:, 0] = rng.uniform(4.3, 5.0, 40)
        p[:, 1] = rng.uniform(4.2, 5.8, 40)
        parts.append(p)
    models = models * 2
    for name in calib.names:
        with_exit = MeasurementModel(calib.subset([name]))
        plain = MeasurementModel(replace(calib.subset([name]), exits=()))
        for m in (with_exit, plain):
            m.set_images({name: frame.images[name]})
        got = with_exit.separable(parts, models).loglik
        ref = plain.separable(parts, models).loglik
        for p, g, r in zip(parts, got, ref):
            hidden = calib.exit_hidden(name, p[:, :2])
            np.testing.assert_array_equal(g[~hidden], r[~hidden])
            if hidden.any():
                np.testing.assert_allclose(g[hidden], np.mean(r[~hidden]), rtol=1e-12)
            assert hidden.any() == (name in ('cam2', 'cam3'))


def test_no_birth_deeper_into_an_exit_than_half_the_body_depth():
    """A confirmed detection whose centre is deeper inside an exit than half its body's
    depth (its width seen from the side, 0.7 of it) starts no track (its body is wholly
    past the floor's edge: its person is in the doorway or beyond); one just inside the
    exit does, a wider body deeper."""
    from mbtrack_ros.core.appearance import PersonModel
    from mbtrack_ros.core.detection.detector import Detection, FrameEvidence
    from mbtrack_ros.core.detection.manager import AutoDetection, _Found, _Pending

    calib = make_calibration(default_room(), width=160, height=120)
    auto = AutoDetection(calib)
    # a track born as deep as half the deepest body would not end at once
    assert 0.35 * max(auto.config.detector.widths) < auto.config.release.exit_margin
    image = np.zeros((120, 160, 3), np.uint8)
    evidence = {'cam0': FrameEvidence(image, np.zeros((120, 160), bool))}
    pending = _Pending(0, {'cam0': image}, [], {}, np.zeros((0, 6)), [], evidence, [])
    edge = calib.floor[3]
    found = []
    for depth, width in ((0.1, 0.5), (0.16, 0.5), (0.19, 0.5), (0.4, 0.5), (0.19, 0.6)):
        det = Detection(np.array([4.65, edge + depth, 0.0, 0.0, 0.0, 0.0]), 1.75, width, 1.0)
        found.append((det, PersonModel(1.75, width)))
    births = auto._settle(pending, _Found(found, {'detect_find': 0.0}))
    assert [round(b.state[1] - edge, 3) for b in births] == [0.1, 0.16, 0.19]
    assert births[-1].detection.width == 0.6


def test_a_track_back_from_an_exit_loses_a_duplicate_pair_to_one_that_stayed():
    """A track whose estimate is inside an exit counts as reported since then (its person
    may have left there): back in the room beside an older track of somebody who stayed,
    the duplicate rule releases it, not the other one (with plain ages it would be kept)."""
    from mbtrack_ros.core.detection.manager import AutoDetection
    from mbtrack_ros.core.state import TrackEstimate

    calib = make_calibration(default_room(), width=160, height=120)
    auto = AutoDetection(calib)
    edge = calib.floor[3]
    for tid in (1, 2):
        auto.register(tid, 0)
        auto.aux[tid].existence = 1.0                       # both reported throughout

    def note(stamp: int, y1: float) -> None:
        means = np.array([[4.65, y1, 0, 0, 0, 0], [4.65, edge - 0.6, 0, 0, 0, 0]])
        tracks = [TrackEstimate(i, means[k], np.eye(4), 1.75) for k, i in enumerate((1, 2))]
        auto._note_reporting(stamp, tracks, means, [], {})

    note(10, edge - 0.2)                                    # in the room: nothing changes
    assert auto._shown_since == {1: 0, 2: 0}
    note(20, edge + 0.1)                                    # track 1 steps into the exit
    note(30, edge - 0.5)                                    # and comes back
    assert auto._shown_since == {1: 20, 2: 0}
    rel = auto.releaser
    shown = [auto._shown_since[1], auto._shown_since[2]]
    xy = np.array([[4.65, edge - 0.55], [4.65, edge - 0.6]])
    step = int(rel.config.merge_time * 1e9)
    assert rel.duplicates(0, [1, 2], xy, shown) == []
    assert rel.duplicates(step, [1, 2], xy, shown) == [1]
    ages = Releaser(calib, rel.config)                      # without the exit's stamp
    assert ages.duplicates(0, [1, 2], xy, [0, 0]) == []
    assert ages.duplicates(step, [1, 2], xy, [0, 0]) == [2]


def test_distance_to_rect_equals_the_nearest_of_dense_boundary_points():
    """``distance_to_rect`` (used by ``exit_depth``) against brute force: 0 inside, else the
    distance to the nearest of 4000 points on the rectangle's border (within 2 mm)."""
    from mbtrack_ros.core.camera import distance_to_rect

    rect = (0.5, 1.0, 3.0, 2.5)
    rng = np.random.default_rng(0)
    xy = rng.uniform([-1.0, -0.5], [4.5, 4.0], (300, 2))
    t = np.linspace(0.0, 1.0, 1000)
    border = np.concatenate([np.c_[0.5 + 2.5 * t, np.full_like(t, 1.0)],
                             np.c_[0.5 + 2.5 * t, np.full_like(t, 2.5)],
                             np.c_[np.full_like(t, 0.5), 1.0 + 1.5 * t],
                             np.c_[np.full_like(t, 3.0), 1.0 + 1.5 * t]])
    inside = (xy[:, 0] >= 0.5) & (xy[:, 0] <= 3.0) & (xy[:, 1] >= 1.0) & (xy[:, 1] <= 2.5)
    brute = np.where(inside, 0.0,
                     np.linalg.norm(xy[:, None] - border[None], axis=2).min(axis=1))
    assert inside.any() and (~inside).any()
    np.testing.assert_allclose(distance_to_rect(xy, rect), brute, atol=2e-3)
