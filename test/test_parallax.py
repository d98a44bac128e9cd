"""Floor parallax (plane + parallax background): a person standing on the floor disagrees
with the floor the other cameras see behind him; the empty floor agrees, whatever the
cameras' exposure; a person who never moves is a place of the people cue."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from conftest import make_room
from mbtrack_ros.core.detection.parallax import FloorParallax, ParallaxEvidence
from mbtrack_ros.core.detection.detector import _states
from mbtrack_ros.core.detection.people import (
    REFUTE_SHARE, STILL_ACCEPT, STILL_MAKE_UP, PeopleCue, PeopleCueConfig, still_evidence)
from mbtrack_ros.core.shape import BodyShape, rasterize

POST = (3.0, 2.5)          # where a person stands, metres


def _floor_colour(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(..., 3) a tiled, graded floor: 0.5 m tiles of two greys, a slow colour ramp."""
    tile = ((np.floor(x / 0.5) + np.floor(y / 0.5)) % 2).astype(np.float64)
    base = 70.0 + 50.0 * tile
    return np.stack([base + 10.0 * x, base + 8.0 * y, base - 5.0 * x], axis=-1)


def _render(room, *, post: bool, gains: dict[str, float] | None = None
            ) -> dict[str, np.ndarray]:
    """Per camera an (H, W, 3) uint8 image of the floor (walls a flat grey) with, if
    ``post``, a person standing at ``POST``: the silhouette of the tracker's body shape
    (003 §2.1) painted per part (skin head, blue torso, dark legs) over the floor."""
    paint = {1: (210.0, 170.0, 140.0), 2: (40.0, 60.0, 190.0), 3: (50.0, 40.0, 40.0)}
    out = {}
    for name, cam in room.cameras.items():
        u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
        p = cam.floor_point(np.stack([u, v], axis=-1))
        x0, y0, x1, y1 = room.floor
        on = np.all(np.isfinite(p), axis=-1)
        with np.errstate(invalid='ignore'):
            on &= (p[..., 0] >= x0) & (p[..., 0] <= x1) & (p[..., 1] >= y0) & (p[..., 1] <= y1)
        img = np.where(on[..., None], _floor_colour(np.nan_to_num(p[..., 0]),
                                                    np.nan_to_num(p[..., 1])), 128.0)
        if post:
            parts = rasterize(cam, _states(np.array([POST])), BodyShape()).mask(0)
            for part, colour in paint.items():
                img[parts == part] = colour
        img = img * (gains or {}).get(name, 1.0)
        out[name] = np.clip(img, 0, 255).astype(np.uint8)
    return out


def _post_masks(room) -> dict[str, np.ndarray]:
    empty, full = _render(room, post=False), _render(room, post=True)
    return {n: np.any(empty[n] != full[n], axis=-1) for n in room.cameras}


def _hidden_floor(room, name: str, post: dict[str, np.ndarray]) -> np.ndarray:
    """(H, W) bool pixels of camera ``name`` whose floor point another camera sees
    behind the person (within 2 pixels of his silhouette there)."""
    cam = room.cameras[name]
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    p = cam.floor_point(np.stack([u, v], axis=-1))
    hidden = np.zeros((cam.height, cam.width), bool)
    for other, oc in room.cameras.items():
        if other == name:
            continue
        near = cv2.dilate(post[other].astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        q = oc.project(np.nan_to_num(p).reshape(-1, 3)).reshape(cam.height, cam.width, 2)
        inside = np.isfinite(p[..., 0]) & oc.in_image(q)
        q = np.clip(np.nan_to_num(q, nan=-1.0, posinf=-1.0, neginf=-1.0), -1.0, 1e6)
        qi = np.clip(q.astype(int), 0, [oc.width - 1, oc.height - 1])
        hidden |= inside & near[qi[..., 1], qi[..., 0]]
    return hidden


def test_two_cameras_ask_each_other():
    """With one other camera that sees a floor point at all, that one is asked: a two-camera
    room has parallax (the people cue tells a person from one hiding the floor)."""
    room = make_room(n_cameras=2)
    for disagree, known in FloorParallax(room).masks(_render(room, post=True)).values():
        assert known.sum() > 0.2 * known.size and disagree.any()


@pytest.mark.parametrize('n_cameras', [2, 3, 4])
def test_the_empty_floor_agrees_between_cameras_whatever_their_exposure(n_cameras):
    room = make_room(n_cameras=n_cameras)
    gains = {'cam1': 1.25}
    masks = FloorParallax(room).masks(_render(room, post=False, gains=gains))
    for name, (disagree, known) in masks.items():
        assert known.sum() > 0.2 * known.size            # the floor is tested
        assert disagree.sum() <= 0.01 * known.sum(), name


@pytest.mark.parametrize('n_cameras', [2, 3, 4])
def test_an_object_standing_on_the_floor_disagrees_with_the_floor_behind_it(n_cameras):
    room = make_room(n_cameras=n_cameras)
    post = _post_masks(room)
    masks = FloorParallax(room).masks(_render(room, post=True))
    for name, (disagree, known) in masks.items():
        tested = post[name] & known
        assert tested.sum() > 30, name
        assert disagree[tested].mean() >= 0.6, name
        # off the person, only the floor he hides from another camera disagrees
        off = disagree & ~post[name] & ~_hidden_floor(room, name, post)
        assert off.sum() <= 0.01 * known.sum(), name


def test_without_the_gain_a_brighter_camera_would_disagree():
    """The exposure correction is what keeps the floor consistent: a camera 25 % brighter
    differs by far more than the threshold on this floor."""
    room = make_room(n_cameras=2)
    plain = _render(room, post=False)
    bright = _render(room, post=False, gains={'cam1': 1.25})
    diff = np.abs(bright['cam1'].astype(float) - plain['cam1']).max(axis=-1)
    assert np.median(diff) > 20.0


def test_the_people_cue_finds_a_person_who_never_moves_only_with_parallax():
    """Three identical frame sets (no motion at all): the motion stage finds nothing; the
    still-person stage finds the person by the floor parallax of his person-like outline,
    and nothing in the empty room (a tiled floor has person-like edges too)."""
    room = make_room(n_cameras=3)
    kw = dict(spacing=0.2, min_views=2)
    still = [_render(room, post=True)] * 3
    places = PeopleCue(room, PeopleCueConfig(**kw)).places(still)
    assert len(places) == 1
    assert np.linalg.norm(places[0] - POST) <= 0.25
    off = PeopleCue(room, PeopleCueConfig(**kw, min_still_score=np.inf)).places(still)
    assert len(off) == 0
    empty = [_render(room, post=False)] * 3
    assert len(PeopleCue(room, PeopleCueConfig(**kw)).places(empty)) == 0


def test_the_people_cue_finds_a_still_person_with_two_cameras():
    """Two cameras (opposite corners): each asks the other about the floor behind the
    person (no third view exists to need), so the still-person stage finds him; the empty
    room has nobody."""
    room = make_room(n_cameras=2)
    kw = dict(spacing=0.2, min_views=2)
    places = PeopleCue(room, PeopleCueConfig(**kw)).places([_render(room, post=True)] * 3)
    assert len(places) == 1
    assert np.linalg.norm(places[0] - POST) <= 0.25
    empty = [_render(room, post=False)] * 3
    assert len(PeopleCue(room, PeopleCueConfig(**kw)).places(empty)) == 0


@pytest.mark.parametrize('weak', [0.15, 0.3, 0.6])
def test_with_two_testing_views_the_weaker_view_decides(weak):
    """A two-camera room has no third view to refute a phantom of the two-view hull (one
    view's line of sight meets a person in front of the place, the other's the floor
    mostly): the cover of a place two views test is the smaller of their disagreeing
    shares, not the pooled one the larger silhouette would dominate."""
    room = make_room(n_cameras=2)
    cue = PeopleCue(room, PeopleCueConfig(spacing=0.2, min_views=2))
    rng = np.random.default_rng(3)
    shown = {}
    for k, name in enumerate(room.cameras):
        size = (room.cameras[name].height, room.cameras[name].width)
        shown[name] = (rng.random(size) < (1.0 if k == 0 else weak), np.ones(size, bool))
    cover = cue._parallax_cover(shown)
    i = int(np.argmin(np.linalg.norm(cue.xy[:cue.n_places] - POST, axis=1)))
    assert cover[i] == pytest.approx(weak, abs=0.06)
    assert cover[i] < 0.5 * (1.0 + weak) - 0.05        # below the pooled share


def _still_features(room, frames, **kw) -> tuple[float, float, float]:
    """(parallax share, outline z-score) of the best still hypothesis within 0.25 m of
    ``POST`` (nobody explained away), as the still-person stage sees them, and the
    largest outline z-score of a place with a parallax share."""
    cue = PeopleCue(room, PeopleCueConfig(**kw))
    xy, score, _ = cue._evidence(frames)
    par = FloorParallax(room, threshold=cue.config.motion_threshold)
    shown = {n: par.decide(ev) for n, ev in par.differences(frames[-1]).items()}
    cover = cue._parallax_cover(shown)
    near = np.linalg.norm(xy - POST, axis=1) <= 0.25
    best = np.flatnonzero(near)[np.argmax((cover + score)[near])]
    return float(cover[best]), float(score[best]), float(score[cover > 0].max())


def test_a_clear_outline_makes_up_for_a_parallax_share_below_its_threshold():
    """The still person's floor-parallax share just below ``min_parallax`` (as when a
    neighbour hides part of the floor behind him) and an outline half again as clear as
    ``min_still_score``: weighed together he is a person (the parallax threshold alone
    would miss him); with the outline at three quarters of its threshold the two fall short of
    ``STILL_ACCEPT`` and he is not, and the empty room gives nothing with the
    thresholds that find him."""
    room = make_room(n_cameras=3)
    kw = dict(spacing=0.2, min_views=2)
    still = [_render(room, post=True)] * 3
    cover, score, _ = _still_features(room, still, **kw)
    assert 0.0 < cover and score > 0.0
    found = dict(kw, min_parallax=cover / 0.95, min_still_score=score / 1.5)
    places = PeopleCue(room, PeopleCueConfig(**found)).places(still)
    assert len(places) == 1
    assert np.linalg.norm(places[0] - POST) <= 0.25
    weak = dict(kw, min_parallax=cover / 0.95, min_still_score=score / 0.75)
    assert 0.95 + 0.75 < STILL_ACCEPT
    assert len(PeopleCue(room, PeopleCueConfig(**weak)).places(still)) == 0
    empty = [_render(room, post=False)] * 3
    assert len(PeopleCue(room, PeopleCueConfig(**found)).places(empty)) == 0


def test_a_parallax_share_far_above_its_threshold_does_not_make_a_poor_outline_a_person():
    """Objects on the floor whose outlines reach at most 0.4 of ``min_still_score`` (as a
    cabinet's) and a parallax share ten times ``min_parallax``: the share makes up for at
    most half of the outline's threshold (``STILL_MAKE_UP``), so none is a person; with
    the person's outline at 0.6 of the threshold the share makes up the rest."""
    room = make_room(n_cameras=3)
    kw = dict(spacing=0.2, min_views=2)
    still = [_render(room, post=True)] * 3
    cover, score, best = _still_features(room, still, **kw)
    poor = dict(kw, min_parallax=cover / 10.0, min_still_score=best / 0.4)
    assert len(PeopleCue(room, PeopleCueConfig(**poor)).places(still)) == 0
    fair = dict(kw, min_parallax=cover / 10.0, min_still_score=score / 0.6)
    places = PeopleCue(room, PeopleCueConfig(**fair)).places(still)
    assert len(places) >= 1
    assert np.linalg.norm(places[0] - POST) <= 0.25


def test_still_evidence_sums_the_two_evidences_in_units_of_their_thresholds():
    """Brute force over a grid of (share, z-score): each in units of its threshold, at
    most ``STILL_MAKE_UP``, summed; a person at ``STILL_ACCEPT`` or more, never where the
    parallax test does not apply (share 0) or the outline is unseen, nor where either
    evidence is below half its threshold."""
    cover = np.repeat(np.linspace(0.0, 1.0, 11), 9)
    score = np.tile(np.linspace(-1.0, 3.0, 9), 11)
    score[::7] = -np.inf
    got = still_evidence(cover, score, 0.5, 1.0)
    for c, z, g in zip(cover, score, got):
        if c == 0.0 or not np.isfinite(z):
            assert g == -np.inf
        else:
            assert g == pytest.approx(min(c / 0.5, STILL_MAKE_UP) + min(z, STILL_MAKE_UP))
    both = (cover >= 0.5) & (score >= 1.0)
    assert np.all(got[both] >= STILL_ACCEPT)     # both thresholds met: always a person
    assert np.any((got >= STILL_ACCEPT) & ~both)  # one missed, made up by the other
    half = (cover < 0.25) | (score < 0.5)
    assert not np.any(got[half] >= STILL_ACCEPT - 1e-12)


@pytest.mark.parametrize('k', [1, 2, 3, 4])
def test_decide_is_the_lower_median_of_the_cameras_that_see_the_floor_point(k):
    """The vectorised decision against a per-pixel loop: tested where two or more other
    cameras see the floor point, or the only one that can see it at all, disagreeing where
    at least half of them differ by more than the threshold; a camera whose view is
    hidden there does not count."""
    room = make_room(n_cameras=k + 1)
    par = FloorParallax(room)
    rng = np.random.default_rng(k)
    h, w = 6, 7
    others = [f'cam{i}' for i in range(1, k + 1)]
    maps = [(np.tile(np.arange(w, dtype=np.float32), (h, 1)),
             np.tile(np.arange(h, dtype=np.float32)[:, None], (1, w))) for _ in others]
    ev = ParallaxEvidence(others, rng.uniform(0, 40, (k, h, w)).astype(np.float32),
                          rng.random((k, h, w)) < 0.8, maps)
    hidden = {'cam1': rng.random((h, w)) < 0.3}
    disagree, known = par.decide(ev, hidden=hidden)
    for y in range(h):
        for x in range(w):
            d = [ev.diff[j, y, x] for j in range(k)
                 if ev.seen[j, y, x] and not (others[j] == 'cam1' and hidden['cam1'][y, x])]
            can = int(ev.seen[:, y, x].sum())     # before the hidden views
            tested = len(d) >= min(2, can) and len(d) >= 1
            assert known[y, x] == tested
            if tested:
                lower = sorted(d)[(len(d) - 1) // 2]
                assert disagree[y, x] == (lower > par.threshold)
            else:
                assert not disagree[y, x]


def _three_views(seed: int, known=(1.0, 1.0, 1.0), disagree=(1.0, 1.0, 1.0)):
    """A people cue of a 3-camera room and the floor-parallax images of its cameras:
    camera k's pixels tested (the floor seen) with probability ``known[k]``, disagreeing
    with probability ``disagree[k]``."""
    room = make_room(n_cameras=3)
    cue = PeopleCue(room, PeopleCueConfig(spacing=0.2, min_views=2))
    rng = np.random.default_rng(seed)
    shown = {}
    for k, name in enumerate(room.cameras):
        size = (room.cameras[name].height, room.cameras[name].width)
        shown[name] = (rng.random(size) < disagree[k], rng.random(size) < known[k])
    return cue, shown


@pytest.mark.parametrize('n_known, third_share', [(1, 0.0), (2, 0.0), (2, 0.05), (2, 0.2),
                                                  (3, 0.0)])
def test_a_still_place_needs_a_third_view_of_the_floor_behind_it(n_known, third_share):
    """Two views' disagreements also meet where nothing stands (a phantom of the two-view
    visual hull): the parallax cover of a place counts only when two cameras see the floor
    behind a quarter of its silhouette and a third behind a tenth; then it is the pooled
    share of those pixels that disagree (here all of them)."""
    shares = [1.0 if k < n_known else third_share if k == n_known else 0.0
              for k in range(3)]
    cue, shown = _three_views(7, known=shares)
    cover = cue._parallax_cover(shown)
    i = int(np.argmin(np.linalg.norm(cue.xy[:cue.n_places] - POST, axis=1)))
    counted = n_known >= 3 or (n_known == 2 and third_share >= 0.1)
    assert cover[i] == (1.0 if counted else 0.0)


@pytest.mark.parametrize('third_share', [0.0, 0.05, 0.3, 1.0])
def test_a_view_that_sees_the_floor_agree_refutes_a_still_place(third_share):
    """An object stands where it stands in every view: a place whose floor two views
    show differently but a third view, seeing the floor behind more than a tenth of the
    silhouette, shows as the floor (disagreeing on less than ``REFUTE_SHARE`` of what it
    tests) has no parallax cover, however much the two others disagree; a third view
    that disagrees on more keeps the pooled share; a place only two cameras see is tested
    by those two, the weaker deciding (brute force per place and orientation, pixel by
    pixel of the body's core)."""
    cue, shown = _three_views(11, disagree=[1.0, 1.0, third_share])
    cover = cue._parallax_cover(shown)
    n_or, n = len(cue.config.orientations), cue.n_places
    want = np.zeros(n_or * n)
    core = BodyShape(height=cue.config.height, width=cue.config.core_width)
    cores = {name: rasterize(cue.calibration.cameras[name], cue.states, core)
             for name in shown}
    for hyp in range(n_or * n):
        hits = known = 0
        views = refuted = False
        counts = []
        for name, (disagree, kn) in shown.items():
            seen = cue._seen[name]
            w = np.flatnonzero(seen.index == hyp)
            if not len(w):
                counts.append(None)
                continue
            px = [tuple(p) for p in np.argwhere(cores[name].mask(hyp) > 0)]
            h = sum(bool(disagree[r, x] and kn[r, x]) for r, x in px)
            k = sum(bool(kn[r, x]) for r, x in px)
            counts.append((h, k, len(px)))
        seen = [c for c in counts if c is not None]
        tested = [(h, k) for h, k, area in seen if k >= 0.1 * max(area, 1)]
        if sum(k >= 0.25 * max(area, 1) for _, k, area in seen) >= 2 \
                and len(tested) >= min(3, len(seen)) \
                and not any(h < REFUTE_SHARE * k for h, k in tested):
            want[hyp] = sum(h for h, _ in tested) / max(sum(k for _, k in tested), 1)
            if len(tested) < 3:
                want[hyp] = min([want[hyp]] + [h / max(k, 1) for h, k in tested])
    want = want.reshape(n_or, n).max(axis=0)
    np.testing.assert_allclose(cover, want)
    i = int(np.argmin(np.linalg.norm(cue.xy[:cue.n_places] - POST, axis=1)))
    if third_share < REFUTE_SHARE:
        assert cover[i] == 0.0           # the place all three see: refuted
    else:
        assert cover[i] > 0.0
