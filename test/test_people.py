"""The people cue's fast bootstrap path (seen hypotheses selected once, explaining-away
recounting only the hypotheses it can change, the compiled median) against the
straightforward computation on small cases."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from conftest import make_room
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.background import median_frame
from mbtrack_ros.core.detection.detector import _max_span_width
from mbtrack_ros.core.detection.features import (
    EdgeMap, ForegroundIntegral, colour_symmetry, contour_loglik_spans)
from mbtrack_ros.core.detection.people import PeopleCue, PeopleCueConfig
from mbtrack_ros.synth.generator import Synthesizer


def _frames(room, rng, n_frames: int = 4) -> list[dict[str, np.ndarray]]:
    """Textured static rooms with a few patches of changing noise (motion) per camera."""
    static = {n: cv2.GaussianBlur(rng.integers(0, 256, (c.height, c.width, 3), np.uint8),
                                  (5, 5), 0) for n, c in room.cameras.items()}
    patches = {n: [(int(rng.integers(10, c.height - 50)), int(rng.integers(10, c.width - 30)))
                   for _ in range(3)] for n, c in room.cameras.items()}
    frames = []
    for _ in range(n_frames):
        fs = {}
        for n, im in static.items():
            im = im.copy()
            for y, x in patches[n]:
                im[y:y + 40, x:x + 20] = rng.integers(0, 256, (40, 20, 3), np.uint8)
            fs[n] = im
        frames.append(fs)
    return frames


def _straightforward(cue: PeopleCue, frames) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scores of every hypothesis, then the greedy choice recounting all of them after
    each explained place (the cue before the fast path)."""
    cfg = cue.config
    m, n_or = cue.n_places, len(cfg.orientations)
    total, views = np.zeros(m), np.zeros(m, np.int64)
    moved_by_cam = {}
    for name in cue.cameras:
        cam, sil, image = cue.calibration.cameras[name], cue._sils[name], frames[-1][name]
        con, _ = contour_loglik_spans(EdgeMap.from_image(image), sil, _max_span_width(sil))
        sym = colour_symmetry(image, sil)
        resp = con + cfg.w_symmetry * np.where(np.isfinite(sym), 1.0 - sym, 0.0)
        min_area = cfg.min_area * cam.width * cam.height / (320.0 * 240.0)
        sees = (sil.area >= cfg.min_visible * np.maximum(sil.full_area, 1)) \
            & (sil.area >= min_area)
        resp = np.where(sees, resp, -np.inf).reshape(n_or, m).max(axis=0)
        seen = np.isfinite(resp)
        med = np.median(resp[seen])
        mad = 1.4826 * np.median(np.abs(resp[seen] - med))
        total += np.where(seen, (resp - med) / max(mad, 1e-6), 0.0)
        views += seen
        moved = np.zeros((cam.height, cam.width), np.uint8)
        grey = [cv2.cvtColor(f[name], cv2.COLOR_RGB2GRAY).astype(np.int64) for f in frames]
        for k in range(1, len(frames)):    # changed since the previous or the first frame
            for ref in (grey[k - 1], grey[0]):
                moved |= (np.abs(grey[k] - ref) > cfg.motion_threshold).view(np.uint8)
        moved = cv2.dilate(moved, cue._kernel(cfg.motion_dilation)).astype(bool)
        moved_by_cam[name] = (moved, sees)
    score = np.where(views >= min(cfg.min_views, len(cue.cameras)),
                     total / np.maximum(views, 1), -np.inf)

    def motion_of(moved_by_cam):
        motion = np.full(m, np.inf)
        for name, (moved, sees) in moved_by_cam.items():
            cov, _, _ = ForegroundIntegral(moved).coverage(cue._sils[name])
            cov = np.where(sees, cov, -np.inf).reshape(n_or, m).max(axis=0)
            motion = np.where(np.isfinite(cov), np.minimum(motion, cov), motion)
        return np.where(np.isfinite(motion), motion, 0.0)

    xy = cue.xy[:m]
    ok = np.isfinite(score) & (score >= cfg.min_score)
    chosen: list[int] = []
    while len(chosen) < cfg.max_people:
        motion = motion_of(moved_by_cam)
        cand = ok & (motion >= cfg.min_motion)
        if chosen:
            cand &= np.linalg.norm(xy[:, None] - xy[chosen][None], axis=2).min(axis=1) \
                >= cfg.nms_radius
        if not cand.any():
            break
        chosen.append(int(np.flatnonzero(cand)[np.argmax(motion[cand])]))
        for name, (mv, _) in moved_by_cam.items():
            mv &= ~cue._region(name, xy[chosen[-1]:chosen[-1] + 1], cfg.region_height,
                               cfg.region_width)
    return score, motion_of({n: (mv, s) for n, (mv, s) in moved_by_cam.items()}), \
        xy[chosen]


def test_fast_places_equal_the_straightforward_greedy_choice():
    room = make_room(n_cameras=3)
    rng = np.random.default_rng(5)
    # low thresholds: many candidates, several explaining-away rounds
    cue = PeopleCue(room, PeopleCueConfig(spacing=0.25, min_views=2, min_motion=0.01,
                                          min_score=-1.0, max_people=5, nms_radius=0.5,
                                          refine_radius=0.0,        # the greedy choice
                                          min_still_score=np.inf))  # of moving places only
    frames = _frames(room, rng)
    score, _, places = _straightforward(cue, frames)
    _, fast_score, _ = cue.score(frames)
    np.testing.assert_array_equal(fast_score, score)
    fast = cue.places(frames)
    assert len(places) >= 3                  # the greedy loop really ran several rounds
    np.testing.assert_array_equal(fast, places)


def _refined_straightforward(cue: PeopleCue, frames, greedy: np.ndarray) -> np.ndarray:
    """Each greedy place moved as PeopleCue._refine documents, every hypothesis recounted
    from its own mask."""
    cfg = cue.config
    m, n_or = cue.n_places, len(cfg.orientations)
    xy = cue.xy[:m]
    _, score, _ = cue.score(frames)
    ok = np.isfinite(score) & (score >= cfg.min_score)
    moved = cue._evidence(frames)[2]
    out = []
    for k, place in enumerate(greedy):
        others = np.delete(greedy, k, axis=0)
        motion = np.full(m, np.inf)
        for name, mv in moved.items():
            sil, seen = cue._sils[name], cue._seen[name]
            free = mv & ~cue._region(name, others, cfg.height, cfg.width, 0)
            cov = np.full(n_or * m, -np.inf)
            for h in seen.index:
                body = sil.mask(int(h)) > 0
                cov[h] = free[body].sum() / body.sum()
            cov = cov.reshape(n_or, m).max(axis=0)
            motion = np.where(np.isfinite(cov), np.minimum(motion, cov), motion)
        motion = np.where(np.isfinite(motion), motion, 0.0)
        near = ok & (np.linalg.norm(xy - place, axis=1) <= cfg.refine_radius)
        top = near & (motion >= cfg.min_motion) \
            & (motion >= cfg.refine_share * motion[near].max())
        new = xy[np.flatnonzero(top)[np.argmax(score[top])]] if top.any() else place
        kept = np.array(out + list(greedy[k + 1:])).reshape(-1, 2)
        if len(kept) and np.linalg.norm(kept - new, axis=1).min() < cfg.nms_radius:
            new = place
        out.append(new)
    return np.array(out)


def test_refined_places_equal_the_straightforward_refinement():
    room = make_room(n_cameras=3)
    frames = _frames(room, np.random.default_rng(5))
    kw = dict(spacing=0.25, min_views=2, min_motion=0.01, min_score=-1.0, max_people=5,
              nms_radius=0.5, min_still_score=np.inf)     # moving places only
    greedy = PeopleCue(room, PeopleCueConfig(**kw, refine_radius=0.0)).places(frames)
    cue = PeopleCue(room, PeopleCueConfig(**kw, refine_radius=0.6))
    refined = cue.places(frames)
    np.testing.assert_allclose(refined, _refined_straightforward(cue, frames, greedy))
    assert len(refined) >= 3 and (np.abs(refined - greedy) > 1e-9).any()  # some moved


def test_refined_places_stand_on_the_people_of_a_synth_bootstrap():
    """The first six frames of ``mbtrack synth clear-room --seed 10``: two people, one
    mostly behind the other's region in one camera (the explaining-away leaves him to the
    still-person stage); the greedy choice puts the moving one 0.17 m off, the refinement
    on his outline 3 cm; the still one's clear outline makes up for the floor the other
    hides behind him (``still_evidence``), found on the grid (0.1 m)."""
    synth = Synthesizer('clear-room', seed=10, frames=6)
    rendered = list(synth)
    frames = [f.images for f in rendered]
    truth = np.array([[g.x, g.y] for g in rendered[-1].ground_truth])
    assert len(truth) == 2

    def worst(config: PeopleCueConfig) -> float:
        places = PeopleCue(synth.calibration, config).places(frames)
        assert len(places) >= 1
        return max(np.linalg.norm(truth - p, axis=1).min() for p in places)

    moving = dict(min_still_score=np.inf)
    assert worst(PeopleCueConfig(refine_radius=0.0, **moving)) > 0.15
    assert worst(PeopleCueConfig(**moving)) < 0.08
    both = PeopleCue(synth.calibration, PeopleCueConfig()).places(frames)
    assert len(both) == 2
    assert np.linalg.norm(truth[:, None] - both[None], axis=2).min(axis=1).max() < 0.15


def test_every_person_of_a_full_room_is_found_not_a_fixed_number():
    """Eight people walking in a 4 x 3.2 m area of the synth room from the first frame:
    the cue marks all eight, each 0.3 m or closer; the nms spacing, not a count, bounds
    the places (a cap of six leaves two people to be found once the background is
    learnt)."""
    from mbtrack_ros.synth.presets import Preset

    def populate(crowd) -> None:
        for _ in range(8):
            crowd.add(tuple(crowd.random_free_point(min_gap=1.0)), behaviour='area',
                      area=(3.0, 2.5, 2.0, 1.6, 0.0), speed_range=(0.8, 1.0))

    synth = Synthesizer(Preset('eight', 'eight walking', 6, None, populate), seed=1,
                        frames=6)
    rendered = list(synth)
    frames = [f.images for f in rendered]
    truth = np.array([[g.x, g.y] for g in rendered[-1].ground_truth])
    assert len(truth) == 8
    places = PeopleCue(synth.calibration).places(frames)
    assert len(places) == 8
    assert np.linalg.norm(truth[:, None] - places[None], axis=2).min(axis=1).max() < 0.3
    capped = PeopleCue(synth.calibration, PeopleCueConfig(max_people=6)).places(frames)
    assert len(capped) == 6
    with pytest.raises(DetectionError, match='max_people'):
        PeopleCueConfig(max_people=-1)


def test_seen_hypotheses_boxes_hold_their_spans():
    """The explaining-away update skips hypotheses by box: every span must lie inside."""
    cue = PeopleCue(make_room(n_cameras=2), PeopleCueConfig(spacing=0.3))
    for name in cue.cameras:
        seen = cue._seen[name]
        owner = np.repeat(np.arange(len(seen.index)), np.diff(seen.spans.offsets))
        box = seen.bbox[owner]
        assert len(seen.index) > 0
        assert np.all((seen.spans.row >= box[:, 1]) & (seen.spans.row < box[:, 3]))
        assert np.all((seen.spans.x0 >= box[:, 0]) & (seen.spans.x1 <= box[:, 2]))


def test_median_frame_equals_numpy_median():
    rng = np.random.default_rng(2)
    for n in (1, 2, 5, 6):
        frames = [rng.integers(0, 256, (7, 9, 3)).astype(np.float32) for _ in range(n)]
        frames[0][0, 0] = frames[-1][0, 0]                          # ties
        if n == 5:
            frames.append(frames[0].copy())                         # a repeated frame
        ref = np.median(np.stack(frames), axis=0).astype(np.float32)
        out = median_frame(frames)
        assert out.dtype == np.float32 and out.shape == ref.shape
        np.testing.assert_array_equal(out, ref)
    noninteger = [rng.normal(size=(4, 5, 3)).astype(np.float32) for _ in range(4)]
    np.testing.assert_array_equal(median_frame(noninteger),
                                  np.median(np.stack(noninteger), axis=0).astype(np.float32))


def _edge_frames(cam, shifts: list[float]) -> list[np.ndarray]:
    """Frames of camera ``cam``'s size with a vertical step edge from dark blue to yellow
    (luminance 58 to 191; a colour change, not a shadow) at column 60 + shift,
    area-sampled: the pixel the edge crosses mixes the two colours by the covered share
    (what a lens and a sensor, or an area resize, make of a sharp edge)."""
    cols = np.arange(cam.width, dtype=np.float64)
    left, right = np.array([40.0, 40.0, 200.0]), np.array([230.0, 200.0, 40.0])
    frames = []
    for s in shifts:
        cover = np.clip(cols + 1.0 - (60.0 + s), 0.0, 1.0)[:, None]  # share right of it
        row = np.round(left * (1.0 - cover) + right * cover).astype(np.uint8)
        frames.append(np.ascontiguousarray(np.repeat(row[None], cam.height, 0)))
    return frames


def test_slow_sub_pixel_motion_accumulates_into_moved_pixels():
    """An edge of luminance contrast 133 moving 0.1 px per frame changes its pixel by 13
    grey levels a frame (below the motion threshold, 20), 66 over the six frames: the cue
    counts the pixel as moved (change since the first frame); per-frame differences alone
    would not. A still edge, and a still image, move nothing."""
    room = make_room(n_cameras=1)
    cue = PeopleCue(room, PeopleCueConfig())
    cam = room.cameras['cam0']
    name = 'cam0'
    slow = [{name: f} for f in _edge_frames(cam, [0.1 * k for k in range(6)])]
    grey = [cv2.cvtColor(f[name], cv2.COLOR_RGB2GRAY).astype(int) for f in slow]
    steps = [np.abs(b - a).max() for a, b in zip(grey[:-1], grey[1:])]
    assert max(steps) <= cue.config.motion_threshold                  # no step alone moves
    moved = cue._moved(name, slow)
    assert moved[:, 60].all() and moved.sum() == cam.height         # the column it crossed
    still = [{name: f} for f in _edge_frames(cam, [0.0] * 6)]
    assert not cue._moved(name, still).any()
    # a fast swing back and forth: seen between consecutive frames
    swing = [{name: f} for f in _edge_frames(cam, [0.0, 3.0, 0.0, 3.0, 0.0, 0.0])]
    assert cue._moved(name, swing)[:, 60:63].all()
