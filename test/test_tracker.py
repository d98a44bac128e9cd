"""Tracker bookkeeping: ids, time base, results, configuration errors."""
from __future__ import annotations

import numpy as np
import pytest

from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.core.dynamics import MotionConfig
from mbtrack_ros.core.filters import available_filters
from mbtrack_ros.core.state import FrameResult, TrackEstimate
from mbtrack_ros.core.tracker import Tracker, TrackerConfig, TrackerError


class _Result:
    def __init__(self, loglik, n_cams):
        self.loglik = loglik
        self.visible_fraction = np.full((len(loglik), n_cams), 0.75)


class StandIn:
    """Gaussian log-likelihood around fixed floor positions (one per track, in order)."""

    def __init__(self, truth):
        self.truth = truth
        self.images_seen = 0

    def set_images(self, images):
        self.images_seen += 1

    def _ll(self, particles):
        return [-((p[:, :2] - self.truth[k % len(self.truth)]) ** 2).sum(1) / 0.02
                for k, p in enumerate(particles)]

    def hjs(self, particles, weights, models):
        return _Result(self._ll(particles), 2)

    def separable(self, particles, models):
        return _Result(self._ll(particles), 2)

    def joint(self, jp, models):
        return sum(self._ll([jp[:, k] for k in range(jp.shape[1])]))


class Model:
    height = 1.8


def room() -> RoomCalibration:
    cams = {}
    for name, eye in (('cam0', (0.0, 0.0, 2.5)), ('cam1', (4.0, 0.0, 2.5))):
        R, t = look_at(eye, (2.0, 2.0, 1.0))
        cams[name] = Camera(name=name, width=80, height=60,
                            K=[[60, 0, 39.5], [0, 60, 29.5], [0, 0, 1]], dist=[], R=R, t=t)
    return RoomCalibration(cameras=cams, floor=(0.0, 0.0, 4.0, 4.0))


def make(algorithm='hjs', truth=((1.0, 1.0), (3.0, 3.0)), **kw):
    cfg = TrackerConfig(algorithm=algorithm, particles=50, joint_particles=500, seed=1, **kw)
    return Tracker(room(), cfg, measurement=StandIn([np.array(t) for t in truth]))


@pytest.mark.parametrize('algorithm', ['hjs', 'hjs-groups', 'separable', 'joint'])
def test_ids_increase_and_are_never_reused(algorithm):
    tr = make(algorithm)
    a = tr.add_track(Model(), [1, 1, 0, 0, 0, 0], 0)
    b = tr.add_track(Model(), [3, 3, 0, 0, 0, 0], 0)
    assert (a, b) == (1, 2)
    tr.step(100_000_000, {})
    tr.remove_track(a)
    c = tr.add_track(Model(), [1, 1, 0, 0, 0, 0], 100_000_000)
    assert c == 3 and tr.track_ids == [2, 3]
    tr.reset()
    assert tr.track_ids == []
    assert tr.add_track(Model(), [1, 1, 0, 0, 0, 0], 0) == 4
    with pytest.raises(TrackerError):
        tr.remove_track(1)


def test_models_follow_the_live_tracks():
    tr = make()
    first, second = Model(), Model()
    a = tr.add_track(first, [1, 1, 0, 0, 0, 0], 0)
    b = tr.add_track(second, [3, 3, 0, 0, 0, 0], 0)
    assert tr.models == {a: first, b: second}
    tr.remove_track(a)
    models = tr.models
    assert models == {b: second}
    models.clear()  # a copy: the tracker's own mapping is untouched
    assert tr.models == {b: second}


def test_stamps_going_backwards_raise():
    tr = make()
    tr.add_track(Model(), [1, 1, 0, 0, 0, 0], 1_000)
    tr.step(2_000, {})
    tr.step(2_000, {})  # same stamp: dt = 0 is allowed
    with pytest.raises(TrackerError, match='before the previous frame'):
        tr.step(1_999, {})
    tr.reset()
    tr.step(5, {})  # after a reset any stamp is accepted


def test_frame_result_fields_filled():
    tr = make()
    tr.add_track(Model(), [1.0, 1.0, 0.0, 0.0, 0.0, 0.0], 0)
    tr.add_track(Model(), [3.0, 3.0, 0.0, 0.0, 0.0, 0.0], 0)
    res = None
    for i in range(1, 6):
        res = tr.step(i * 66_666_667, {'cam0': np.zeros((60, 80, 3), np.uint8)})
    assert isinstance(res, FrameResult)
    assert res.stamp_ns == 5 * 66_666_667
    assert [t.track_id for t in res.tracks] == [1, 2]
    for t, truth in zip(res.tracks, ((1.0, 1.0), (3.0, 3.0))):
        assert isinstance(t, TrackEstimate)
        assert t.mean.shape == (6,) and t.covariance.shape == (4, 4)
        assert np.linalg.norm(t.mean[:2] - truth) < 0.15
        assert t.height == 1.8 and t.existence == 1.0
        assert t.visible_fraction == {'cam0': 0.75, 'cam1': 0.75}
        assert t.particles.shape == (50, 6) and t.weights.shape == (50,)
        assert t.weights.sum() == pytest.approx(1.0)
    for stage in ('prepare', 'predict', 'mrf', 'update', 'filter', 'total'):
        assert res.timings[stage] >= 0.0
    assert tr.measurement.images_seen == 5


def test_add_track_extrapolates_to_the_tracker_time():
    cfg = TrackerConfig(particles=20, seed=0, init_position_spread=0.0,
                        init_velocity_spread=0.0)
    tr = Tracker(room(), cfg, measurement=StandIn([np.array([1.0, 1.0])]))
    tr.add_track(Model(), [1.0, 1.0, 0.0, 0.0, 0.0, 0.0], 1_000_000_000)
    tr.step(1_000_000_000, {})
    # a state observed 0.5 s later at x = 2.0 moving at 1 m/s was at x = 1.5 at tracker time
    tr.add_track(Model(), [2.0, 1.0, 1.0, 0.0, 0.0, 0.0], 1_500_000_000)
    parts = tr.filter._particles[2]
    np.testing.assert_allclose(parts[:, 0], 1.5)


def test_same_seed_same_result():
    out = []
    for _ in range(2):
        tr = make()
        tr.add_track(Model(), [1, 1, 0.2, 0, 0, 0], 0)
        tr.add_track(Model(), [3, 3, 0, 0, 0, 0], 0)
        for i in range(1, 4):
            res = tr.step(i * 50_000_000, {})
        out.append(np.array([t.mean for t in res.tracks]))
    np.testing.assert_array_equal(out[0], out[1])


@pytest.mark.parametrize('kw, msg', [
    ({'particles': 0}, 'particles'),
    ({'particles': 2.5}, 'particles'),
    ({'sigma': -1.0}, 'sigma'),
    ({'theta_bp': 0.0}, 'theta_bp'),
    ({'mrf_epsilon': 0.0}, 'mrf_epsilon'),
    ({'mrf_radius': float('nan')}, 'mrf_radius'),
    ({'seed': 'x'}, 'seed'),
    ({'motion': 3}, 'motion'),
    ({'release_time': 0.0}, 'release_time'),
    ({'detection_threshold': float('inf')}, 'detection_threshold'),
    ({'spare_support': 1.5}, 'spare_support'),
    ({'reuse_time': -0.5}, 'reuse_time'),
    ({'reuse_time': float('inf')}, 'reuse_time'),
    ({'coverage_gain': True}, 'coverage_gain'),
    ({'coverage_gain': -0.1}, 'coverage_gain'),
])
def test_config_validation(kw, msg):
    with pytest.raises(TrackerError, match=msg):
        TrackerConfig(**kw)


def test_unknown_algorithm_and_from_dict():
    with pytest.raises(TrackerError, match='unknown algorithm'):
        Tracker(room(), TrackerConfig(algorithm='nope'), measurement=StandIn([np.zeros(2)]))
    assert {'hjs', 'hjs-groups', 'separable', 'joint'} <= set(available_filters())
    cfg = TrackerConfig.from_dict({'particles': 30, 'motion': {'velocity_noise': 0.3}})
    assert cfg.particles == 30 and cfg.motion == MotionConfig(velocity_noise=0.3)
    with pytest.raises(TrackerError, match='unknown key'):
        TrackerConfig.from_dict({'particle': 30})
    with pytest.raises(TrackerError, match='motion'):
        TrackerConfig.from_dict({'motion': {'velocity_noise': -1}})


def test_bad_state_rejected():
    tr = make()
    with pytest.raises(TrackerError):
        tr.add_track(Model(), [1.0, 2.0], 0)
    with pytest.raises(TrackerError):
        tr.add_track(Model(), [np.inf, 2.0, 0, 0, 0, 0], 0)


# -- ground-truth initiation -------------------------------------------------------------------
def test_initial_state_and_height():
    from mbtrack_ros.core.initiation import PersonTruth, body_height, initial_state

    rows = [PersonTruth(f, f * 100_000_000, 7, 1.0 + 0.05 * f, 2.0, 1.7) for f in range(5)]
    s = initial_state(rows, 0)
    np.testing.assert_allclose(s[:4], [1.0, 2.0, 0.5, 0.0])
    assert s[4] == pytest.approx(0.0)  # walking along +x
    s_last = initial_state(rows, 4)  # the last row looks back
    np.testing.assert_allclose(s_last[2:4], [0.5, 0.0])
    assert body_height(rows) == pytest.approx(1.7)
    sitting = [PersonTruth(0, 0, 1, 0.0, 0.0, 0.45 + 0.53 * 1.8, True)]
    assert body_height(sitting) == pytest.approx(1.8)


def test_key_views_skip_occluded_frames():
    from mbtrack_ros.core.initiation import PersonTruth, plan_key_views

    cal = room()
    cam0 = cal.cameras['cam0'].center
    ray = np.array([2.0, 2.0]) - cam0[:2]
    ray /= np.linalg.norm(ray)
    rows = []
    for f in range(6):
        far = cam0[:2] + 3.2 * ray
        # person 2 stands in front of person 1 (on the same cam0 ray) in frames 0-2 only
        near = cam0[:2] + (2.0 if f < 3 else 1.0) * ray + (0 if f < 3 else 1.2) * np.array(
            [-ray[1], ray[0]])
        rows.append(PersonTruth(f, f * 66_666_667, 1, far[0], far[1], 1.7))
        rows.append(PersonTruth(f, f * 66_666_667, 2, near[0], near[1], 1.8))
    plan = plan_key_views(cal, rows, min_area=20)
    views1 = [(v.frame, v.camera) for v in plan[1]]
    assert views1, 'person 1 is visible in frames 3-5'
    assert all(f >= 3 for f, cam in views1 if cam == 'cam0')
    assert any(f < 3 for f, cam in [(v.frame, v.camera) for v in plan[2]])


@pytest.mark.parametrize('algorithm', ['hjs', 'separable'])
def test_a_track_draws_are_its_own(algorithm):
    """Each track has its own random stream: whether a third track, far from the others,
    is born before them (taking id 1), lives, ends or is born later leaves the particles
    of the tracks at (1, 1) and (3, 3) bit for bit as they are; the same seed gives the
    same run, another seed another one."""
    near, far, other = np.array([1.0, 1.0]), np.array([3.0, 3.0]), np.array([1.0, 3.2])

    def run(third: str, seed: int = 1):
        cfg = TrackerConfig(algorithm=algorithm, particles=50, seed=seed)
        order = [other, near, far] if third == 'first' else [near, far, other]
        tr = Tracker(room(), cfg, measurement=StandIn(order))
        if third == 'first':
            tr.add_track(Model(), [*other, 0, 0, 0, 0], 0)
        ids = [tr.add_track(Model(), [*xy, 0, 0, 0, 0], 0) for xy in (near, far)]
        if third in ('ends', 'lives'):
            extra = tr.add_track(Model(), [*other, 0, 0, 0, 0], 0)
        out = None
        for k in range(1, 7):
            if k == 3 and third == 'ends':
                tr.remove_track(extra)
            if k == 3 and third == 'born':
                tr.add_track(Model(), [*other, 0, 0, 0, 0], k * 100_000_000)
            out = {t.track_id: t for t in tr.step(k * 100_000_000, {}).tracks}
        return [out[t] for t in ids]

    alone = run('none')
    for third in ('first', 'lives', 'ends', 'born'):
        for mine, theirs in zip(run(third), alone):
            np.testing.assert_array_equal(mine.particles, theirs.particles)
            np.testing.assert_array_equal(mine.weights, theirs.weights)
    np.testing.assert_array_equal(run('none')[0].particles, alone[0].particles)
    assert not np.array_equal(run('none', seed=2)[0].particles, alone[0].particles)
