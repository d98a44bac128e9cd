"""Detection features, grid detector, acquisition and release (003 §4)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mbtrack_ros.core.appearance import quantize
from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.acquisition import acquire
from mbtrack_ros.core.detection.manager import AutoDetectionConfig
from mbtrack_ros.core.detection.background import BackgroundBank, BackgroundConfig
from mbtrack_ros.core.detection.detector import (
    Detection, Detector, DetectorConfig, FrameEvidence, _vetoes, is_ceiling)
from mbtrack_ros.core.detection.features import (
    EdgeMap, ForegroundIntegral, Spans, colour_symmetry, contour_loglik, contour_loglik_spans,
    outline, span_counts, span_coverage)
from mbtrack_ros.core.detection.likeness import AppearanceRatio
from mbtrack_ros.core.detection.release import ReleaseConfig, Releaser, blob_coverage
from mbtrack_ros.core.shape import TORSO, BodyShape, rasterize, render_labels

W, H = 160, 120
FPS = 15
SKIN, SHIRT, TROUSERS = (215, 175, 145), (30, 70, 190), (45, 45, 50)


def make_room(ceiling: bool = True) -> RoomCalibration:
    """6 x 5 m room, four upper-corner cameras and optionally a ceiling camera."""
    cams = {}
    for k, (x, y) in enumerate([(0.1, 0.1), (5.9, 0.1), (5.9, 4.9), (0.1, 4.9)]):
        R, t = look_at((x, y, 2.6), (3.0, 2.5, 0.8))
        cams[f'cam{k}'] = Camera(f'cam{k}', W, H, [[90, 0, 79.5], [0, 90, 59.5], [0, 0, 1]],
                                 [-0.1, 0.01, 0, 0, 0], R, t)
    if ceiling:
        R, t = look_at((3.0, 2.5, 2.75), (3.0, 2.5, 0.0), up=(0, 1, 0))
        cams['cam4'] = Camera('cam4', W, H, [[60, 0, 79.5], [0, 60, 59.5], [0, 0, 1]],
                              [0] * 5, R, t)
    return RoomCalibration(cams, (0.3, 0.3, 5.7, 4.7), entry_zones=((4.0, 4.1, 5.3, 4.9),))


def backgrounds(calib: RoomCalibration) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(99)
    out = {}
    for n in calib.cameras:
        base = rng.integers(60, 190, size=(8, 10, 3)).astype(np.uint8)
        out[n] = cv2.resize(base, (W, H), interpolation=cv2.INTER_CUBIC)
    return out


def paint(calib, bgs, people, rng, screen=None):
    """Images with people painted far to near; ``screen`` = colour of a wall screen."""
    out = {}
    for n, cam in calib.cameras.items():
        img = bgs[n].astype(np.int16) + rng.integers(-3, 4, bgs[n].shape)
        if screen is not None:
            corners = np.array([[5.99, 1.6, 0.9], [5.99, 3.4, 0.9], [5.99, 3.4, 2.0],
                                [5.99, 1.6, 2.0]])
            if np.all(cam.depth(corners) > 0.1):
                poly = np.round(cam.project(corners)).astype(np.int32)
                tmp = np.zeros((H, W), np.uint8)
                cv2.fillConvexPoly(tmp, poly, 1)
                img[tmp > 0] = screen
        order = sorted(people, key=lambda p: -cam.distance(np.r_[p[0][:2], 0.9]))
        for state, shape, colours in order:
            if is_ceiling(cam):  # seen from above: a blob (head, shoulders) around the feet
                ring = np.linspace(0, 2 * np.pi, 16, endpoint=False)
                pts = [np.c_[state[0] + 0.25 * np.cos(ring), state[1] + 0.25 * np.sin(ring),
                             np.full(16, z)] for z in (0.0, shape.height)]
                hull = cv2.convexHull(np.round(cam.project(np.concatenate(pts))).astype(
                    np.int32))
                tmp = np.zeros((H, W), np.uint8)
                cv2.fillConvexPoly(tmp, hull, 1)
                img[tmp > 0] = colours[1]
                continue
            lab = render_labels(cam, state, shape)
            for part in (1, 2, 3):
                img[lab == part] = colours[part - 1]
        out[n] = np.clip(img, 0, 255).astype(np.uint8)
    return out


def person(x, y, theta=0.3, h=1.8, w=0.5, colours=(SKIN, SHIRT, TROUSERS)):
    return (np.array([x, y, 0, 0, theta, 0.0]), BodyShape(h, w), colours)


# -- features -----------------------------------------------------------------------------
def test_coverage_equals_pixel_count_and_painted_fraction():
    rng = np.random.default_rng(0)
    calib = make_room()
    cam = calib.cameras['cam1']
    states = np.zeros((12, 6))
    states[:, :2] = rng.uniform([0.5, 0.5], [5.5, 4.5], (12, 2))
    states[:, 4] = rng.uniform(0, np.pi, 12)
    states[::3, 5] = 1.0
    sil = rasterize(cam, states, BodyShape(1.7, 0.5))
    fg = rng.random((H, W)) < 0.4
    unknown = np.zeros((H, W), bool)
    unknown[:, :50] = True
    cov, known, area = ForegroundIntegral(fg, unknown).coverage(sil)
    for i in range(len(states)):
        m = sil.mask(i) > 0
        assert area[i] == m.sum()
        if m.sum():
            k = m & ~unknown
            assert known[i] == pytest.approx(k.sum() / m.sum())
            if k.sum():
                assert cov[i] == pytest.approx((fg & k).sum() / k.sum())
    # a foreground blob painted over the torso of one silhouette: coverage = torso share
    i = int(np.argmax(area))
    blob = sil.mask(i) == TORSO
    c, _, _ = ForegroundIntegral(blob).coverage(sil)
    assert c[i] == pytest.approx(sil.part_area[i, TORSO - 1] / sil.area[i])
    assert 0.2 < c[i] < 0.8


def test_span_counts_equal_the_prefix_sums():
    """span_counts / span_coverage (a walk over the spans' pixels) give exactly the counts
    and coverages of ForegroundIntegral (row prefix sums): silhouettes partly outside the
    image, overlapping parts, empty silhouettes, with and without unknown pixels, and
    hand-made spans beyond the image's rows and columns."""
    rng = np.random.default_rng(4)
    calib = make_room()
    for case in range(12):
        cam = calib.cameras[sorted(calib.cameras)[case % len(calib.cameras)]]
        n = int(rng.integers(1, 9))
        states = np.zeros((n, 6))
        states[:, :2] = rng.uniform([-2.0, -2.0], [8.0, 7.0], (n, 2))
        states[:, 4] = rng.uniform(-np.pi, np.pi, n)
        states[:, 5] = rng.random(n) < 0.3
        sil = rasterize(cam, states, BodyShape(1.75, 0.5))
        fg = rng.random((H, W)) < rng.uniform(0.1, 0.9)
        for unknown in (None, rng.random((H, W)) < 0.3):
            ref = ForegroundIntegral(fg, unknown)
            for got, want in zip(span_counts(fg, sil, unknown), ref.counts(sil)):
                np.testing.assert_array_equal(got, want)
            for got, want in zip(span_coverage(fg, sil, unknown), ref.coverage(sil)):
                np.testing.assert_array_equal(got, want)
    odd = Spans(np.array([-1, 0, 5, H, 7], np.int32), np.array([-5, 3, W - 2, 0, 9], np.int32),
                np.array([4, 3, W + 9, 4, 9], np.int32), np.ones(5, np.int8),
                np.array([0, 2, 2, 5], np.int64))
    fg = rng.random((H, W)) < 0.5
    for got, want in zip(span_counts(fg, odd), ForegroundIntegral(fg).counts(odd)):
        np.testing.assert_array_equal(got, want)
    assert span_counts(fg, odd)[2][2] == 2 + 0 + 0  # clipped to the image, empty span


def test_spans_from_masks_roundtrip():
    lab = np.zeros((20, 30), np.int8)
    lab[2:5, 10:14] = 1
    lab[5:15, 8:18] = 2
    lab[15:19, 9:17] = 3
    sp = Spans.from_masks([lab > 0], [lab])
    assert sp.count == 1
    back = np.zeros_like(lab)
    for r, a, b, p in zip(sp.row, sp.x0, sp.x1, sp.part):
        back[r, a:b] = p
    np.testing.assert_array_equal(back, lab)


def test_outline_normals_of_a_rectangle():
    m = np.zeros((40, 40), bool)
    m[10:30, 12:25] = True
    o = outline(Spans.from_masks([m]), 40, 40)
    left = o.x == 12
    right = o.x == 24
    assert np.allclose(o.nx[left & (o.y > 10) & (o.y < 29)], -1.0)
    assert np.allclose(o.nx[right & (o.y > 10) & (o.y < 29)], 1.0)
    top = (o.y == 10) & ~left & ~right
    assert top.sum() == 11 and np.allclose(o.ny[top], -1.0)
    assert len(o.x) == 2 * 20 + 2 * 11


def painted_person_edges(calib, name, state, shape):
    cam = calib.cameras[name]
    img = np.full((H, W, 3), 120, np.uint8)
    lab = render_labels(cam, state, shape)
    img[lab > 0] = (30, 30, 200)
    return EdgeMap.from_image(img, lab > 0), img


def test_contour_kernel_equals_reference_and_prefers_the_aligned_hypothesis():
    calib = make_room()
    name = 'cam0'
    cam = calib.cameras[name]
    shape = BodyShape(1.8, 0.5)
    true = np.array([2.5, 2.5, 0, 0, 0.4, 0])
    edges, _ = painted_person_edges(calib, name, true, shape)
    rng = np.random.default_rng(1)
    states = np.tile(true, (30, 1))
    states[1:, :2] += rng.normal(0, 0.3, (29, 2))
    states[5:10, 5] = 1.0
    sil = rasterize(cam, states, shape)
    width = (sil.bbox[:, 2] - sil.bbox[:, 0]).astype(float)
    ref, ref_len = contour_loglik(edges, outline(sil, H, W), width)
    fast, fast_len = contour_loglik_spans(edges, sil, width)
    np.testing.assert_allclose(fast, ref, atol=1e-12)
    np.testing.assert_array_equal(fast_len, ref_len)
    # aligned: all outline pixels on edges with matching normals -> close to the best 0.5
    assert fast[0] > 0.2
    shifted = true.copy()
    shifted[0] += 0.3
    sil2 = rasterize(cam, np.stack([true, shifted]), shape)
    w2 = (sil2.bbox[:, 2] - sil2.bbox[:, 0]).astype(float)
    ll, _ = contour_loglik_spans(edges, sil2, w2)
    assert ll[0] > ll[1] + 0.3
    assert np.all((fast >= -1.0) & (fast <= 0.5))


def test_colour_symmetry_symmetric_vs_asymmetric_torso():
    calib = make_room()
    cam = calib.cameras['cam0']
    state = np.array([2.5, 2.5, 0, 0, 0.0, 0])
    shape = BodyShape(1.8, 0.5)
    sil = rasterize(cam, state[None], shape)
    lab = sil.mask(0)
    sym = np.full((H, W, 3), 100, np.uint8)
    sym[lab == TORSO] = (200, 40, 40)
    asym = sym.copy()
    cols = np.nonzero(lab == TORSO)[1]
    mid = 0.5 * (cols.min() + cols.max())
    left = (lab == TORSO) & (np.arange(W)[None, :] < mid)
    asym[left] = (40, 200, 40)
    d_sym = colour_symmetry(sym, sil)[0]
    d_asym = colour_symmetry(asym, sil)[0]
    assert d_sym < 0.1
    assert d_asym > 1.5
    with pytest.raises(DetectionError):
        colour_symmetry(sym, sil, levels=3)


# -- detector -----------------------------------------------------------------------------
def run_detector(calib, frames, *, config=None, track_xy=None, empty=None):
    """Feed frames through background + detector; returns (frame index, detections).

    The background is bootstrapped from the first 5 frames, or from ``empty`` frames.
    """
    det = Detector(calib, config or DetectorConfig())
    bank = BackgroundBank(BackgroundConfig(bootstrap_frames=5, bootstrap_stride=1))
    if empty is not None:
        bank.bootstrap({n: [f[n] for f in empty] for n in calib.cameras})
    found = []
    for k, images in enumerate(frames):
        fg = bank.apply(images)
        if not fg:
            continue
        ev = {n: FrameEvidence(images[n], fg[n], motion=bank.models[n].recent_motion())
              for n in fg}
        for d in det.step(ev, track_xy=track_xy):
            found.append((k, d))
    return found


def test_detector_finds_painted_people_within_the_bound():
    rng = np.random.default_rng(2)
    calib = make_room()
    bgs = backgrounds(calib)
    a = person(2.2, 3.1, h=1.8)
    b = person(4.3, 1.6, h=1.65, colours=(SKIN, (180, 40, 40), (60, 60, 140)))
    frames = [paint(calib, bgs, [], rng) for _ in range(5)]
    frames += [paint(calib, bgs, [a, b], rng) for _ in range(6)]
    found = run_detector(calib, frames)
    first = min(k for k, _ in found)
    assert (first - 5) / FPS <= 0.5 - 1e-9          # confirmed within half a second
    at_first = [d for k, d in found if k == first]
    assert len(at_first) == 2                         # two simultaneous entries, NMS
    for truth in (a, b):
        d = min(at_first, key=lambda d: np.linalg.norm(d.xy - truth[0][:2]))
        assert np.linalg.norm(d.xy - truth[0][:2]) <= 0.15
        assert abs(d.height - truth[1].height) <= 0.15
        assert d.state[5] == 0.0
        assert len(d.coverage) >= 2 and min(d.coverage.values()) > 0.5


def _empty_room_detector(seed: int, confirm_frames: int):
    """(rng, room, background images, a bank bootstrapped on them, a Detector confirming
    after ``confirm_frames``) of the painted empty room."""
    calib = make_room()
    bgs = backgrounds(calib)
    bank = BackgroundBank()
    bank.bootstrap({n: [bgs[n]] for n in calib.cameras})
    return (np.random.default_rng(seed), calib, bgs, bank,
            Detector(calib, DetectorConfig(confirm_frames=confirm_frames)))


def _detect_frame(det, bank, calib, bgs, people, rng, k: int) -> list:
    """Frame ``k`` (at FPS) of ``people`` painted into the room, through the background
    ``bank`` into ``det``; returns the detections it confirmed."""
    images = paint(calib, bgs, people, rng)
    fg = bank.apply(images)
    ev = {n: FrameEvidence(images[n], fg[n]) for n in fg}
    return det.step(ev, stamp_ns=int(round(k * 1e9 / FPS)))


def test_confirmed_detection_gets_the_walking_velocity_and_direction():
    rng, calib, bgs, bank, det = _empty_room_detector(9, 5)
    found = []
    for k in range(8):
        p = person(1.8 - 0.08 * k, 1.5 + 0.04 * k, theta=0.0)   # 1.34 m/s at 153 degrees
        found += _detect_frame(det, bank, calib, bgs, [p], rng, k)
        if found:
            break
    assert found
    d = found[0]
    v = d.state[2:4]
    assert np.hypot(*v) == pytest.approx(np.hypot(1.2, 0.6), abs=0.4)
    expected = np.arctan2(0.6, -1.2)
    assert abs(np.angle(np.exp(1j * (d.state[4] - expected)))) < 0.4


@pytest.mark.parametrize('speed', [0.0, 1.2])
def test_a_walking_detection_found_sitting_is_refined_standing(monkeypatch, speed):
    """A person walking at 1.2 m/s whose best per-frame hypothesis is a sitting body (as
    a walker's spread legs can make it) is confirmed standing, near the painted height and
    place, with the walking velocity kept; one standing still stays as found (sitting)."""
    rng, calib, bgs, bank, det = _empty_room_detector(4, 3)
    refine = Detector._refine
    calls = []

    def sitting_first(self, evidence, centre, track_xy, *, standing=False):
        calls.append(standing)
        d = refine(self, evidence, centre, track_xy, standing=standing)
        if d is not None and not standing:   # the per-frame search finds a sitting 1.9 m
            d.state[5], d.height = 1.0, 1.9
        return d

    monkeypatch.setattr(Detector, '_refine', sitting_first)
    found, truth = [], None
    for k in range(6):
        truth = person(2.0, 3.2 - speed / FPS * k, theta=-np.pi / 2, h=1.7)
        found += _detect_frame(det, bank, calib, bgs, [truth], rng, k)
        if found:
            break
    assert len(found) == 1
    d = found[0]
    if speed == 0.0:
        assert d.state[5] == 1.0 and d.height == 1.9 and True not in calls
        return
    assert calls[-1] is True
    assert d.state[5] == 0.0 and abs(d.height - 1.7) <= 0.1
    assert np.linalg.norm(d.xy - truth[0][:2]) <= 0.15
    assert d.state[2:4] == pytest.approx([0.0, -speed], abs=0.4)
    assert len(d.history) == 3 and d.frames == 3


@pytest.mark.parametrize('xs, speed', [((4.45, 4.8, 4.75), None), ((4.45, 4.5, 4.55), 0.75)])
def test_a_detection_whose_places_jumped_gets_no_velocity(xs, speed):
    """Confirming places 0.3 m apart in two frames (2.25 m/s, above ``max_speed``) are a
    jump between places, not a walk: velocity and orientation stay as found. A walk of
    0.05 m per frame gives its velocity (15 frames/s) and direction."""
    det = Detection(state=np.array([xs[-1], 4.7, 0.0, 0.0, 1.0, 0.0]), height=1.7,
                    width=0.5, score=4.0,
                    history=[(int(round(k * 1e9 / FPS)), x, 4.7) for k, x in enumerate(xs)])
    Detector(make_room(), DetectorConfig())._velocity(det)
    if speed is None:
        assert det.state[2:5].tolist() == [0.0, 0.0, 1.0]
    else:
        assert det.state[2:4] == pytest.approx([speed, 0.0], abs=1e-6)
        assert det.state[4] == pytest.approx(0.0)


def test_detector_excludes_tracked_neighbourhood():
    rng = np.random.default_rng(3)
    calib = make_room()
    bgs = backgrounds(calib)
    a = person(2.2, 3.1)
    frames = [paint(calib, bgs, [], rng) for _ in range(5)]
    frames += [paint(calib, bgs, [a], rng) for _ in range(6)]
    assert run_detector(calib, frames, track_xy=np.array([[2.25, 3.0]])) == []


def test_detector_ignores_a_motionless_ghost():
    """Someone present while the background was bootstrapped leaves a person-shaped
    foreground "ghost" in every camera; it never moves and is not detected."""
    rng = np.random.default_rng(7)
    calib = make_room()
    bgs = backgrounds(calib)
    a = person(2.2, 3.1)
    boot = [paint(calib, bgs, [a], rng) for _ in range(3)]
    boot += [paint(calib, bgs, [], rng) for _ in range(2)]
    frames = [paint(calib, bgs, [], rng) for _ in range(8)]
    assert run_detector(calib, frames, empty=boot) == []
    # without the motion requirement the ghost would be taken for a person
    cfg = DetectorConfig(min_motion=0.0)
    found = run_detector(calib, frames, empty=boot, config=cfg)
    assert found and np.linalg.norm(found[0][1].xy - a[0][:2]) < 0.2


def test_detector_ignores_flickering_screen_and_empty_room():
    rng = np.random.default_rng(4)
    calib = make_room()
    bgs = backgrounds(calib)
    frames = []
    for k in range(45):                              # 3 s of a screen changing slides
        colour = tuple(int(v) for v in rng.integers(0, 255, 3)) if k % 7 < 4 else (20, 20, 20)
        frames.append(paint(calib, bgs, [], rng, screen=colour))
    assert run_detector(calib, frames) == []


def test_detector_without_ceiling_camera_and_config_errors():
    rng = np.random.default_rng(5)
    calib = make_room(ceiling=False)
    assert not any(is_ceiling(c) for c in calib.cameras.values())
    assert is_ceiling(make_room().cameras['cam4'])
    bgs = backgrounds(calib)
    a = person(3.0, 2.0)
    frames = [paint(calib, bgs, [], rng) for _ in range(5)]
    frames += [paint(calib, bgs, [a], rng) for _ in range(4)]
    found = run_detector(calib, frames)
    assert found and np.linalg.norm(found[0][1].xy - a[0][:2]) <= 0.15
    with pytest.raises(DetectionError, match='zones'):
        DetectorConfig(zones='room')
    with pytest.raises(DetectionError):
        DetectorConfig(fine_spacing=0.0)
    with pytest.raises(DetectionError, match='depth_range'):
        DetectorConfig(depth_range=-0.1)


def test_veto_with_the_weakest_view_excused_equals_a_loop_over_hypotheses():
    rng = np.random.default_rng(11)
    covs = rng.uniform(0.0, 0.6, (5, 400))
    covs[rng.random(covs.shape) < 0.3] = np.nan              # cameras that do not see it
    side = np.array([True, True, True, True, False])          # cam4: a ceiling camera
    excusable = rng.random(400) < 0.5
    vetoed, counted = _vetoes(covs, side, 0.15, excusable, 3)
    for j in range(400):
        seeing = [c for c in range(5) if np.isfinite(covs[c, j])]
        excused = None
        if excusable[j] and len(seeing) >= 3 and any(side[c] for c in seeing):
            excused = min((c for c in seeing if side[c]), key=lambda c: covs[c, j])
        kept = [c for c in seeing if c != excused]
        assert list(np.flatnonzero(counted[:, j])) == kept
        assert vetoed[j] == any(covs[c, j] < 0.15 for c in kept)
    assert (vetoed != _vetoes(covs, side, 0.15, np.zeros(400, bool), 3)[0]).any()


def _camouflaged_walker(calib, bgs, rng, start, weak):
    """Frames of a person walking 0.6 m/s in -y from ``start`` who, in camera ``weak``,
    shows nothing but the head (the rest as the background behind)."""
    frames = [paint(calib, bgs, [], rng) for _ in range(5)]
    for k in range(12):
        walker = person(start[0], start[1] - 0.04 * k, theta=-np.pi / 2)
        images = paint(calib, bgs, [walker], rng)
        images[weak] = paint(calib, bgs, [], rng)[weak]
        lab = render_labels(calib.cameras[weak], walker[0], walker[1])
        images[weak][lab == 1] = SKIN
        frames.append(images)
    return frames


def test_a_person_in_the_doorway_hidden_in_one_camera_is_detected_by_the_others():
    """h-enter: in the doorway one camera may see little of a person (dark clothes against
    the corridor, a background model that learnt them beyond the open door); its veto
    must not hide them from the other three. Off the entry zones, and within
    ``excuse_radius`` of a track, the veto stays. Opt-in (``excuse_weakest``): on the 18
    clear-room runs it cost mean MOTA."""
    rng = np.random.default_rng(12)
    calib = make_room(ceiling=False)
    bgs = backgrounds(calib)
    frames = _camouflaged_walker(calib, bgs, rng, (4.6, 4.8), 'cam0')
    excuse = DetectorConfig(excuse_weakest=True)
    found = run_detector(calib, frames, config=excuse)
    assert found and np.linalg.norm(found[0][1].xy - np.array([4.6, 4.8 - 0.04 * (
        found[0][0] - 5)])) <= 0.2
    assert found[0][1].coverage['cam0'] < 0.15                # the weak view, excused
    assert (found[0][0] - 5) / FPS <= 0.5 - 1e-9
    assert run_detector(calib, frames) == []                   # the default: vetoed
    # beside a tracked person (0.8 m) the weak camera still vetoes: not alone in the doorway
    assert run_detector(calib, frames, track_xy=np.array([[3.8, 4.6]]), config=excuse) == []
    assert run_detector(calib, frames, track_xy=np.array([[3.8, 4.6]]),
                        config=DetectorConfig(excuse_weakest=True, excuse_radius=0.7))
    # the same person in the middle of the room: the weak camera still vetoes
    middle = _camouflaged_walker(calib, bgs, rng, (2.6, 2.8), 'cam0')
    assert run_detector(calib, middle, config=excuse) == []
    shown = [paint(calib, bgs, [], rng) for _ in range(5)] + [
        paint(calib, bgs, [person(2.6, 2.8 - 0.04 * k, theta=-np.pi / 2)], rng)
        for k in range(12)]
    assert run_detector(calib, shown)                          # found when seen by all


def _two_camera_room() -> RoomCalibration:
    """The painted room with two opposite corner cameras only (cam0, cam2)."""
    full = make_room(ceiling=False)
    return RoomCalibration({n: full.cameras[n] for n in ('cam0', 'cam2')}, full.floor,
                           entry_zones=full.entry_zones)


def _behind_a_track(calib, rng, background):
    """Frames of a tracked person standing at (2.0, 1.8) and a walker behind him as cam0
    sees it, and per frame the cameras' track masks (the tracked person rendered 0.8 m
    wide): in cam0 the walker is mostly covered by the track. ``background``: the
    cameras' empty-room images, the first 5 frames (for the background bootstrap)."""
    a = person(2.0, 1.8, theta=0.7, colours=(SKIN, (180, 40, 40), (60, 60, 140)))
    walk = [person(3.2 + 0.05 * k, 2.9 - 0.03 * k, theta=-0.5) for k in range(10)]
    frames = [paint(calib, background, [], rng) for _ in range(5)]
    frames += [paint(calib, background, [a, w], rng) for w in walk]
    tracks = {n: render_labels(c, a[0], BodyShape(1.9, 0.8)) > 0
              for n, c in calib.cameras.items()}
    return a, walk, frames, tracks


def test_a_walker_hidden_by_a_track_in_one_of_two_cameras_is_found_by_the_other():
    """Two cameras; in cam0 a new person walks behind a tracked one (most of his
    silhouette is the track's, so cam0 cannot tell): cam0 neither supports nor refutes
    him, and cam2 alone confirms him (within 0.25 m) while he is hidden, not only once
    both cameras see him."""
    calib = _two_camera_room()
    rng = np.random.default_rng(5)
    a, walk, frames, tracks = _behind_a_track(calib, rng, backgrounds(calib))
    det = Detector(calib, DetectorConfig())
    bank = BackgroundBank(BackgroundConfig(bootstrap_frames=5, bootstrap_stride=1))
    found = []
    for k, images in enumerate(frames):
        fg = bank.apply(images)
        if not fg:
            continue
        ev = {n: FrameEvidence(images[n], fg[n], tracks=tracks[n],
                               motion=bank.models[n].recent_motion()) for n in fg}
        found += [(k, d) for d in det.step(ev, track_xy=a[0][None, :2])]
    assert found
    k, d = found[0]
    assert k <= 9                      # while cam0 cannot see him
    assert set(d.coverage) == {'cam2'}
    assert np.linalg.norm(d.xy - walk[k - 5][0][:2]) <= 0.25


@pytest.mark.parametrize('shows', ['person', 'background'])
def test_a_camera_hides_a_place_only_if_what_it_sees_of_it_is_not_background(shows):
    """A camera in which tracks cover most of a hypothesis counts towards ``min_views``
    only when the part it does see is foreground; where that part is background it sees
    the place empty, and the other camera alone is not enough (brute force over the
    pixels of the hypothesis)."""
    calib = _two_camera_room()
    det = Detector(calib, DetectorConfig())
    state = np.array([3.3, 2.84, 0.0, 0.0, -0.5, 0.0])
    shape = BodyShape(1.75, 0.5)
    track = np.array([2.0, 1.8, 0.0, 0.0, 0.7, 0.0])
    ev = {}
    for n, cam in calib.cameras.items():
        sil = render_labels(cam, state, shape) > 0
        tr = (render_labels(cam, track, BodyShape(1.9, 0.8)) > 0) if n == 'cam0' \
            else np.zeros_like(sil)
        fg = sil.copy() if (n == 'cam2' or shows == 'person') else np.zeros_like(sil)
        ev[n] = FrameEvidence(np.zeros(sil.shape + (3,), np.uint8), fg, tracks=tr)
        if n == 'cam0':
            area, known = sil.sum(), (sil & ~tr).sum()
            assert known < det.config.min_known * area          # cam0: hidden
            assert known >= det._min_area(cam)                  # but sees a part
            seen_fg = (fg & sil & ~tr).sum() / known
    score, views, _ = det._score(ev, state[None], np.array([1.75]), np.array([0.5]),
                                 full=False)
    assert views[0] == 1
    hidden = not seen_fg < det.config.veto_coverage
    assert np.isfinite(score[0]) == hidden == (shows == 'person')


@pytest.mark.parametrize('name', ['cam0', 'cam2'])
def test_refinement_searches_the_depth_along_a_line_of_sight(name):
    """A search started 0.6 m from a person along one camera's line of sight through him
    (the depth that view cannot tell, farther than the fine window reaches) ends at the
    person: the refinement also tests the places on the cameras' lines of sight, and it
    ends within the fine spacing of the best of the places on that line tested one by one
    (brute force over the line, 5 cm apart)."""
    calib = _two_camera_room()
    det = Detector(calib, DetectorConfig(sitting=False))
    truth = np.array([3.1, 2.3])
    state = np.array([*truth, 0.0, 0.0, 0.0, 0.0])
    images = paint(calib, backgrounds(calib), [person(*truth, theta=0.0, h=1.75, w=0.5)],
                   np.random.default_rng(3))
    ev = {n: FrameEvidence(images[n], render_labels(c, state, BodyShape(1.75, 0.5)) > 0)
          for n, c in calib.cameras.items()}
    u = truth - calib.cameras[name].center[:2]
    u /= np.linalg.norm(u)
    assert 0.6 > det.config.fine_radius + det.config.fine_spacing
    found = det._refine(ev, truth + 0.6 * u, np.zeros((0, 2)))
    assert found is not None
    assert np.linalg.norm(found.xy - truth) <= 0.1
    line = truth + np.arange(-0.6, 0.61, 0.05)[:, None] * u[None]
    states = np.zeros((len(line), 6))
    states[:, :2] = line
    brute, _, _ = det._score(ev, states, np.full(len(line), 1.75), np.full(len(line), 0.5),
                             full=True)
    best = line[int(np.argmax(brute))]
    assert np.linalg.norm(best - truth) <= 0.1
    assert np.linalg.norm(found.xy - best) <= det.config.fine_spacing + 1e-9


def test_line_places_beside_a_track_compare_only_when_no_more_hidden():
    """``Detector._comparable``: a place farther than ``beside_radius`` from every track
    always compares with the window's best; one beside a track only when in no camera
    more of its silhouette is covered by tracks than of the best's (brute force over the
    rendered masks; the tracks' mask is a track's silhouette and a random patch)."""
    rng = np.random.default_rng(12)
    calib = _two_camera_room()
    det = Detector(calib, DetectorConfig(), beside_radius=1.0)
    track = np.array([3.0, 2.5, 0.0, 0.0, 0.0, 0.0])
    best = np.array([3.65, 3.05, 0.0, 0.0, 0.0, 0.0])     # behind the track in cam0
    states = np.zeros((40, 6))
    states[:, :2] = rng.uniform([1.0, 0.8], [5.0, 4.2], (40, 2))
    shape = BodyShape(1.75, 0.5)
    ev, tracks = {}, {}
    for n, cam in calib.cameras.items():
        tracks[n] = render_labels(cam, track, BodyShape(1.9, 0.8)) > 0
        tracks[n][rng.integers(0, H - 20):, :rng.integers(20, W)] |= n == 'cam2'
        ev[n] = FrameEvidence(np.zeros((H, W, 3), np.uint8), np.zeros((H, W), bool),
                              tracks=tracks[n])

    def known(n, state):
        m = render_labels(calib.cameras[n], state, shape) > 0
        return (m & ~tracks[n]).sum() / m.sum() if m.sum() else 1.0

    got = det._comparable(ev, best, states, track[None, :2], 1.75, 0.5)
    want = [np.hypot(*(s[:2] - track[:2])) > 1.0
            or all(known(n, s) >= known(n, best) for n in calib.cameras) for s in states]
    np.testing.assert_array_equal(got, want)
    assert 0 < got.sum() < len(got) and not all(
        np.hypot(*(s[:2] - track[:2])) > 1.0 for s in states[got])


# -- acquisition and release -------------------------------------------------------------
def test_acquisition_uses_unoccluded_views_only():
    rng = np.random.default_rng(6)
    calib = make_room()
    bgs = backgrounds(calib)
    a = person(3.0, 2.5)
    images = paint(calib, bgs, [a], rng)
    det = Detection(state=a[0].copy(), height=1.8, width=0.5, score=1.0)
    model = acquire(det, images, calib)
    assert model is not None and model.height == 1.8
    assert 2 <= model.view_angles.size <= 4           # the side cameras, not the ceiling
    torso = model.histograms[:, TORSO - 1]
    shirt_bin = (SHIRT[0] >> 5) * 64 + (SHIRT[1] >> 5) * 8 + (SHIRT[2] >> 5)
    assert np.all(torso[:, shirt_bin] > 0.8)
    # tall wide people right in front of the new one in every side camera: no key view
    others = []
    for n, cam in calib.cameras.items():
        if is_ceiling(cam):
            continue
        toward = cam.center[:2] - a[0][:2]
        toward /= np.linalg.norm(toward)
        others.append(np.r_[a[0][:2] + 0.7 * toward, 0, 0, 0, 0])
    shapes = [BodyShape(2.1, 1.0)] * len(others)
    assert acquire(det, images, calib, others=np.array(others), other_shapes=shapes) is None


def test_release_after_the_configured_time():
    calib = make_room()
    cam = calib.cameras['cam4']
    rel = Releaser(calib, ReleaseConfig(timeout=1.0))
    states = np.array([[2.0, 2.0, 0, 0, 0, 0], [4.0, 3.0, 0, 0, 0, 0]])
    sil = rasterize(cam, states, BodyShape())
    fg_both = (sil.mask(0) > 0) | (sil.mask(1) > 0)
    fg_one = sil.mask(1) > 0
    image = np.zeros((H, W, 3), np.uint8)
    ended_at = {}
    for k in range(40):
        fg = fg_both if k < 10 else fg_one             # track 1 loses support at frame 10
        ev = {'cam4': FrameEvidence(image, fg)}
        supported, coverage = rel.support(ev, {'cam4': sil})
        assert coverage['cam4'].shape == (2,)
        for tid in rel.update(int(round(k * 1e9 / FPS)), [1, 2], supported):
            ended_at.setdefault(tid, k)
    assert 2 not in ended_at
    assert ended_at[1] == 10 + int(np.ceil(1.0 * FPS))  # exactly after 1 s unsupported
    with pytest.raises(DetectionError):
        rel.update(0, [1], [True, False])



def test_a_supported_frame_or_two_does_not_restart_a_spare_tracks_release_time():
    """A track spare during its unsupported time keeps that time through supported frames
    until they last recover_time: spare on most frames with one or two supported ones in
    between, it ends; unsupported but never spare (a person the foreground loses now and
    then), or with recover_time 0, every supported frame restarts it; a track supported
    long enough is kept. Marks per frame: s spare, - unsupported, + supported."""
    calib = make_room()

    def ends(pattern: str, recover: float) -> int | None:
        rel = Releaser(calib, ReleaseConfig(timeout=1.0, recover_time=recover))
        for k, mark in enumerate(pattern):
            if rel.update(int(round(k * 1e9 / FPS)), [1], [mark == '+'],
                          spare=[mark == 's']):
                return k
        return None

    blips = 's' * 12 + '++' + 's' * 12 + '+' + 's' * 12      # 0.8 s spare, 0.13 s good, ...
    assert ends(blips, 0.2) == 15                        # 1 s after the first spare frame
    assert ends(blips, 0.0) is None                       # each blip restarted it before
    assert ends(blips.replace('s', '-'), 0.2) is None     # not spare: the former rule
    assert ends('-' * 5 + 's' + '-' * 6 + '++' + '-' * 5, 0.2) == 15   # one spare frame
    recovered = 's' * 12 + '++++' + 's' * 12               # 4 good frames: 0.2 s in a row
    assert ends(recovered, 0.2) is None
    assert ends('s' * 20, 0.2) == 15
    for bad in (-0.1, np.inf, np.nan):
        with pytest.raises(DetectionError, match='recover_time'):
            ReleaseConfig(recover_time=bad)
    with pytest.raises(DetectionError, match='spare'):
        Releaser(calib).update(0, [1, 2], [True, True], spare=[False])

def test_blob_coverage_supports_a_person_right_below_the_ceiling_camera():
    calib = make_room()
    cam = calib.cameras['cam4']
    below = cam.center[:2]
    xy = np.array([below, below + [1.0, 0.5]])
    # the body outline degenerates right below the camera, the cylinder blob does not
    assert rasterize(cam, np.r_[below, 0, 0, 0, 0][None], BodyShape()).area[0] < 20
    full = np.ones((H, W), bool)
    cov, area = blob_coverage(cam, full, xy, np.array([1.75, 1.75]))
    assert np.all(area > 50) and np.allclose(cov, 1.0)
    half = np.zeros((H, W), bool)
    half[:, :int(round(cam.project(np.r_[below, 0.0])[0]))] = True
    cov, _ = blob_coverage(cam, half, xy[:1], np.array([1.75]))
    assert 0.35 < cov[0] < 0.65
    rel = Releaser(calib)
    sil = rasterize(cam, np.c_[xy, np.zeros((2, 4))], BodyShape())
    ev = {'cam4': FrameEvidence(np.zeros((H, W, 3), np.uint8), full)}
    supported, _ = rel.support(ev, {'cam4': sil}, np.c_[xy, np.zeros((2, 4))],
                               np.array([1.75, 1.75]))
    assert supported.all()


def test_duplicate_tracks_release_the_younger_after_the_merge_time():
    rel = Releaser(make_room(), ReleaseConfig(merge_radius=0.35, merge_time=0.5))
    out = {}
    for k in range(20):
        stamp = int(round(k * 1e9 / FPS))
        xy = np.array([[2.0, 2.0], [2.2 if k >= 3 else 3.0, 2.0], [4.0, 4.0]])
        for tid in rel.duplicates(stamp, [1, 7, 3], xy):
            out.setdefault(tid, k)
    assert out == {7: 3 + int(np.ceil(0.5 * FPS))}     # shadowing since frame 3
    assert rel.duplicates(0, [1, 2], np.array([[0.0, 0.0], [1.0, 0.0]])) == []


def test_duplicate_tracks_release_the_one_reported_for_the_shorter_time():
    """With the stamps since which each track has been reported without a break, the pair's
    track hidden (or born) last is released: here the older id 1, hidden at frame 2 while
    track 7 (born at frame 0) was reported; equal stamps fall back to the larger id."""
    rel = Releaser(make_room(), ReleaseConfig(merge_radius=0.35, merge_time=0.5))
    hidden_at = int(round(2 * 1e9 / FPS))
    out = {}
    for k in range(20):
        stamp = int(round(k * 1e9 / FPS))
        xy = np.array([[2.0, 2.0], [2.2, 2.0], [4.0, 4.0]])
        for tid in rel.duplicates(stamp, [1, 7, 3], xy, shown_since=[hidden_at, 0, 0]):
            out.setdefault(tid, k)
    assert out == {1: int(np.ceil(0.5 * FPS))}
    rel = Releaser(make_room(), ReleaseConfig(merge_radius=0.35, merge_time=0.0))
    assert rel.duplicates(0, [1, 7], np.zeros((2, 2)), shown_since=[5, 5]) == [7]
    with pytest.raises(DetectionError):
        rel.duplicates(0, [1, 7], np.zeros((2, 2)), shown_since=[5])
    # a judge of the pair overrules the rule; when it abstains (None) the rule holds
    asked = []
    assert rel.duplicates(0, [1, 7], np.zeros((2, 2)), shown_since=[5, 5],
                          prefer=lambda a, b: asked.append((a, b)) or 7) == [1]
    assert asked == [(1, 7)]
    assert rel.duplicates(0, [1, 7], np.zeros((2, 2)), shown_since=[5, 5],
                          prefer=lambda a, b: None) == [7]


def test_auto_detection_tracks_with_side_cameras_and_rejects_bad_images():
    from mbtrack_ros.core.detection.manager import AutoDetection

    calib = make_room()
    auto = AutoDetection(calib)
    bgs = backgrounds(calib)
    assert set(auto.tracking_images(bgs)) == {'cam0', 'cam1', 'cam2', 'cam3'}
    only_ceiling = {'cam4': bgs['cam4']}
    assert set(auto.tracking_images(only_ceiling)) == {'cam4'}
    auto.bootstrap({n: [bgs[n]] for n in calib.cameras})
    bad = dict(bgs)
    bad['cam1'] = bgs['cam1'][:60]
    with pytest.raises(DetectionError, match='cam1'):
        auto.step(0, bad, [], {})


# -- tracker integration -----------------------------------------------------------------
YELLOW = (SKIN, (200, 190, 40), (150, 40, 120))     # clothes of somebody who looks different


def _detecting_tracker(calib, bgs, seed, **config):
    """A Tracker with automatic detection, background bootstrapped from ``bgs``."""
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig

    tracker = Tracker(calib, TrackerConfig(detection=True, particles=50, seed=seed, **config),
                      rng=np.random.default_rng(seed))
    tracker.detection.bootstrap({n: [bgs[n]] for n in calib.cameras})
    return tracker


def _painted_room_tracker(seed, **detection):
    """The painted room (with ceiling camera), its backgrounds and a detecting tracker of
    tracker seed ``seed`` with these ``AutoDetectionConfig`` fields."""
    from dataclasses import replace

    calib = make_room()
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=seed)
    tracker.detection.config = replace(tracker.detection.config, **detection)
    return calib, bgs, tracker


def _set_relocate_radius(tracker, metres):
    """Give the tracker's detection a ``relocate_radius`` (the release config's
    ``spare_radius``; the releaser itself keeps its own)."""
    from dataclasses import replace

    cfg = tracker.detection.config
    tracker.detection.config = replace(cfg, release=replace(cfg.release, spare_radius=metres))
    assert tracker.detection.config.relocate_radius == metres


def test_coverage_gain_gives_the_filter_this_frame_foreground():
    """With a ``coverage_gain`` the filter's coverage term gets the foreground masks that
    the same frame set's background step produced (joined from the worker before the
    filter), its possible-person pixels as undecided at the release's ``min_coverage``,
    and the person is still found and tracked."""
    calib, bgs, tracker = _painted_room_tracker(1)
    assert tracker.measurement.config.coverage_gain == 2.0     # the likelihood's default
    frames = [paint(calib, bgs, [person(1.5 + 0.05 * k, 2.8, theta=0.0)] if k >= 3 else [],
                    np.random.default_rng(k)) for k in range(10)]
    extracted, given = [], []
    apply, set_foreground = tracker.detection.background.apply, tracker.measurement.set_foreground

    def recording_apply(images, **kwargs):
        extracted.append(apply(images, **kwargs))
        return extracted[-1]

    def recording_set_foreground(masks, gain=None, **kwargs):
        assert callable(masks)          # joined by the filter when it needs them
        given.append((masks(), gain))
        undecided = kwargs['undecided']()
        assert kwargs['neutral'] == tracker.detection.config.release.min_coverage
        for name, mask in undecided.items():
            possible = tracker.detection.background.models[name].possible_foreground_as_tested
            assert (mask is None and not possible.any()) or (mask == possible).all()
        set_foreground(masks, gain, **kwargs)

    tracker.detection.background.apply = recording_apply
    tracker.measurement.set_foreground = recording_set_foreground
    tracked = []
    for k, images in enumerate(frames):
        tracked.append(len(tracker.step(int(round(k * 1e9 / FPS)), images).tracks))
    assert len(given) == len(extracted) == len(frames)
    for (masks, gain), fg in zip(given, extracted):
        assert gain is None and masks.keys() == fg.keys() and fg   # the config's gain
        for name in fg:
            np.testing.assert_array_equal(masks[name], fg[name])
    assert any(extracted[-1][n].any() for n in extracted[-1])   # the person is foreground
    assert tracked[-1] == 1 and tracked[2] == 0


def test_coverage_gain_is_checked_and_handed_to_the_likelihood():
    from mbtrack_ros.core.likelihood import LikelihoodConfig, LikelihoodError
    from mbtrack_ros.core.tracker import TrackerConfig, TrackerError

    assert TrackerConfig(coverage_gain=1.5).likelihood_config().coverage_gain == 1.5
    assert TrackerConfig().likelihood_config().coverage_gain == \
        LikelihoodConfig().coverage_gain
    for bad in (-0.1, float('nan'), float('inf')):
        with pytest.raises(LikelihoodError, match='coverage_gain'):
            LikelihoodConfig(coverage_gain=bad)
        with pytest.raises(TrackerError, match='coverage_gain'):
            TrackerConfig(coverage_gain=bad)
    with pytest.raises(TrackerError, match='coverage_gain'):
        TrackerConfig(coverage_gain=True)


def test_tracker_detects_tracks_and_releases_a_painted_person():
    """End to end with the real tracker: born within 0.5 s, released within 1.5 s."""
    rng = np.random.default_rng(8)
    calib = make_room()
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=1)
    enter, leave, total = 3, 30, 60
    born = ended = None
    existence = []
    for k in range(total):
        x = 2.0 + 0.05 * k                       # walking at 0.75 m/s
        people = [person(x, 2.8, theta=0.0)] if enter <= k < leave else []
        stamp = int(round(k * 1e9 / FPS))
        res = tracker.step(stamp, paint(calib, bgs, people, rng))
        if born is None and res.tracks:
            born = k
            assert len(res.tracks) == 1
            assert abs(res.tracks[0].mean[0] - x) < 0.3
        if res.tracks:
            t = res.tracks[0]
            existence.append(t.existence)
            assert set(t.visibility) <= set(calib.cameras)
        if res.released and ended is None:
            ended = k
    assert born is not None and (born - enter) / FPS <= 0.5
    assert ended is not None and 0 < (ended - leave) / FPS <= 1.5
    assert max(existence) > 0.9
    assert tracker.track_ids == []


def test_paint_blobs_marks_the_blob_only_where_the_outline_degenerates():
    from mbtrack_ros.core.detection.release import paint_blobs

    calib = make_room()
    cam = calib.cameras['cam4']
    xy = np.array([cam.center[:2], cam.center[:2] + [2.0, 1.0]])   # below / far off
    heights = np.array([1.8, 1.8])
    full = np.ones((H, W), bool)
    _, area = blob_coverage(cam, full, xy, heights)
    each = []
    for k in range(2):
        m = np.zeros((H, W), bool)
        paint_blobs(m, cam, xy[k:k + 1], heights[:1])
        assert m.sum() == area[k]                      # the same hull as blob_coverage
        each.append(m)
    outline = rasterize(cam, np.c_[xy, np.zeros((2, 4))], BodyShape(),
                        heights=heights).area
    assert outline[0] < 0.25 * area[0] and outline[1] >= 0.25 * area[1]
    chosen = np.zeros((H, W), bool)
    paint_blobs(chosen, cam, xy, heights, outline_area=outline)
    assert np.array_equal(chosen, each[0])             # the far person keeps his outline


def test_a_person_standing_below_the_ceiling_camera_is_not_learnt_into_its_background():
    """The ceiling camera alone decides the release, and the body outline degenerates right
    below it: the model update must still leave the tracked person out (cylinder blob in
    the exclusion mask), else the person fades into the background and the track ends."""
    from mbtrack_ros.core.detection.release import blob_coverage

    rng = np.random.default_rng(3)
    calib = make_room()
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=2)
    cam = calib.cameras['cam4']
    below = cam.center[:2]
    ids = set()
    for k in range(150):                          # 10 s standing still
        stamp = int(round(k * 1e9 / FPS))
        images = paint(calib, bgs, [person(*below)], rng)
        res = tracker.step(stamp, images)
        ids |= {t.track_id for t in res.tracks}
        assert not res.released, f'track released at frame {k}'
        if k >= 20:
            assert len(res.tracks) == 1, f'frame {k}: {len(res.tracks)} tracks'
    # the ceiling camera still sees the person as foreground after 10 s
    fg = tracker.detection.background.models['cam4'].foreground(images['cam4'])
    cov, _ = blob_coverage(cam, fg, below[None], np.array([1.8]))
    assert cov[0] > 0.3
    assert len(ids) == 1


def test_detector_refines_a_fixed_budget_with_pending_candidates_first(monkeypatch):
    """Refinement cost is bounded per frame; candidates being confirmed are not starved."""
    rng = np.random.default_rng(5)
    calib = make_room()
    bgs = backgrounds(calib)
    crowd = [person(1.5, 1.5), person(4.5, 1.5, colours=(SKIN, (180, 40, 40), (60, 60, 140))),
             person(1.5, 3.6, colours=(SKIN, (40, 150, 60), TROUSERS)),
             person(4.4, 3.5, colours=(SKIN, (200, 200, 60), (90, 50, 20)))]
    frames = [paint(calib, bgs, [], rng) for _ in range(5)]
    frames += [paint(calib, bgs, crowd, rng) for _ in range(4)]
    calls = []
    original = Detector._refine

    def counting(self, *args, **kwargs):
        calls[-1] += 1
        return original(self, *args, **kwargs)

    original_detect = Detector.detect

    def detect(self, *args, **kwargs):
        calls.append(0)
        return original_detect(self, *args, **kwargs)

    monkeypatch.setattr(Detector, '_refine', counting)
    monkeypatch.setattr(Detector, 'detect', detect)
    found = run_detector(calib, frames, config=DetectorConfig(max_candidates=2))
    assert calls and max(calls) == 2                   # 4 people, budget 2 per frame
    first = [d for k, d in found if k == 5 + 2]        # confirmed on the 3rd frame
    assert len(first) == 2                             # the same two kept being refined
    for d in first:
        assert min(np.linalg.norm(d.xy - p[0][:2]) for p in crowd) < 0.2


def _track_painted(tracker, calib, bgs, rng, frames, people_at):
    """Step the tracker over painted frames; returns the per-frame results."""
    out = []
    for k in range(frames):
        stamp = int(round(k * 1e9 / FPS))
        out.append(tracker.step(stamp, paint(calib, bgs, people_at(k), rng)))
    return out


def _no_hidden_moves(monkeypatch):
    """Patch :class:`AutoDetection` so that no hidden track is moved onto a detection (the
    scene is about the appearance gain alone)."""
    from mbtrack_ros.core.detection.manager import AutoDetection

    monkeypatch.setattr(AutoDetection, '_hidden_hypothesis', lambda self, *a, **k: None)


def _walker(k):
    """One person walking along y = 2.6 m, 0.3 m/s."""
    return [person(2.0 + 0.02 * k, 2.6, theta=0.0)]


def _drifted_walker(frames, before_drift=None):
    """:func:`_walker` tracked as track 1 for ``frames`` frames, then track 1 put 0.8 m
    beside the person (``before_drift(tracker)`` runs just before). Returns the tracker and
    ``step(k)``, which steps frame k and returns (result, the decisions' actions). The
    reach is off: these tests are about the detector's identity check, and 0.8 m is
    within what the reach (0.5 m rings, a silhouette's width) would bring back by itself."""
    from dataclasses import replace

    rng = np.random.default_rng(3)
    calib = make_room()
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=2)
    tracker.detection.config = replace(tracker.detection.config, reach_radius=0.0)
    res = _track_painted(tracker, calib, bgs, rng, frames, _walker)
    assert tracker.track_ids == [1]
    if before_drift is not None:
        before_drift(tracker)
    state = res[-1].tracks[0].mean.copy()
    state[1] += 0.8
    tracker.relocate_track(1, state)

    def step(k):
        r = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, _walker(k), rng))
        return r, [d['action'] for d in tracker.detection.decisions]
    return tracker, step


def test_tracker_moves_a_drifted_track_back_instead_of_a_second_birth():
    """A track 0.8 m off its person: the person is re-detected beside it; the track's own
    appearance model explains the detection better than its place, so the track is moved
    (same id) and no second track is born on the person."""
    # tracked for 36 frames (> relocate_interval), then its particles put 0.8 m beside
    tracker, step = _drifted_walker(36)
    ids, last = set(), None
    for k in range(36, 56):
        r, _ = step(k)
        ids |= {t.track_id for t in r.tracks}
        last = (k, r)
    assert ids == {1} and tracker.track_ids == [1]        # never a second track
    k, r = last
    assert np.hypot(r.tracks[0].mean[0] - (2.0 + 0.02 * k), r.tracks[0].mean[1] - 2.6) < 0.25


def test_tracker_births_a_different_person_beside_a_tracked_one():
    """A differently dressed person who appears 0.7 m beside a tracked person is born as a
    new track; the tracked person keeps id 1 and its place."""
    rng = np.random.default_rng(4)
    calib = make_room()
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=3)
    a = person(2.5, 2.5, theta=0.0)
    b = lambda k: person(2.5 + 0.02 * (k - 8), 3.2, theta=0.0,        # noqa: E731
                         colours=(SKIN, (200, 40, 40), (200, 200, 200)))
    res = _track_painted(tracker, calib, bgs, rng, 20,
                         lambda k: [a] if k < 8 else [a, b(k)])
    assert tracker.track_ids == [1, 2]
    final = {t.track_id: t.mean[:2] for t in res[-1].tracks}
    assert np.linalg.norm(final[1] - [2.5, 2.5]) < 0.25
    assert np.linalg.norm(final[2] - b(19)[0][:2]) < 0.25


def test_bench_detection_reports_times_and_tracks_five_people_without_births():
    """`mbtrack bench` detection part on a tiny scene: every scene is timed, the five
    tracked people stay five tracks (no birth beside them), people entering are found."""
    from mbtrack_ros.commands.bench_detection import bench_detection, print_detection

    r = bench_detection(frames=2, size=(160, 120))
    summary = print_detection(r)
    for key in ('entering_5cams', 'entering_4cams', 'tracked_5cams', 'tracked_4cams',
                'empty_5cams'):
        assert r[key]['frames'] == 2 and r[key]['detect']['median_ms'] > 0
    assert r['tracked_4cams']['cameras'] == 4 and r['tracked_5cams']['cameras'] == 5
    for tag in ('4cams', '5cams'):
        assert r[f'tracked_{tag}']['tracks_mean'] == 5.0
        assert r[f'tracked_{tag}']['births'] == 0
        assert r[f'entering_{tag}']['detections'] >= 2      # confirmed on the 3rd frame
    assert summary['pipeline_4cams_fps'] > 0


def test_a_track_born_recently_is_moved_again_by_a_positive_gain_and_no_twin_is_born():
    """Within ``relocate_interval`` of a track's birth a detection is not born beside it:
    the young track's model explains its person's detection better than its own place
    (a positive gain), so it is moved onto its person, once (and nothing is born)."""
    tracker, step = _drifted_walker(8)  # drift 0.5 s after the birth
    actions = []
    for k in range(8, 20):
        actions += step(k)[1]
    assert tracker.track_ids == [1]
    assert 'birth' not in actions
    moves = [a for a in actions if a.startswith('move')]
    assert moves == ['move 1 (again)'], actions   # back on its person: nothing beside it


def test_deferred_search_gives_the_same_tracks_as_the_full_step():
    """step(search=False) + search() (the node publishes in between) == step()."""
    calib = make_room()
    bgs = backgrounds(calib)
    frames = [paint(calib, bgs, [person(1.5 + 0.05 * k, 2.8, theta=0.0)] if k >= 3 else [],
                    np.random.default_rng(k)) for k in range(14)]
    runs = []
    for deferred in (False, True):
        tracker = _detecting_tracker(calib, bgs, seed=1)
        rows, started = [], []
        for k, images in enumerate(frames):
            res = tracker.step(int(round(k * 1e9 / FPS)), images, search=not deferred)
            rows.append([(t.track_id, *np.round(t.mean[:2], 9)) for t in res.tracks])
            if deferred:
                started += tracker.search()
                assert tracker.search() == []  # one search per step
        runs.append(rows)
        if deferred:
            assert started == [1]
    assert runs[0] == runs[1]
    assert any(runs[1]) and not any(runs[1][:4])  # born after entering, not before


@pytest.mark.parametrize('coverage_gain', [0.0, 2.0])
def test_foreground_overlapped_with_the_filter_gives_the_same_tracks_and_background(
        coverage_gain):
    """Tracker.step starts the foreground on the detection's worker before the filter and
    joins it in update(): the same tracks, background models and motion as extracting it
    within update() (without the filter's coverage term, which needs it before update);
    a step that fails in the filter leaves the background as if that frame set had not
    been seen, with the coverage term too."""
    calib = make_room()
    bgs = backgrounds(calib)
    frames = [paint(calib, bgs, [person(1.5 + 0.05 * k, 2.8, theta=0.0)] if k >= 3 else [],
                    np.random.default_rng(k)) for k in range(14)]
    failing = 9
    runs, banks = [], []
    for variant in ('inline', 'overlapped', 'failed')[1 if coverage_gain else 0:]:
        tracker = _detecting_tracker(calib, bgs, seed=1, coverage_gain=coverage_gain)
        if variant == 'inline':
            tracker.detection.start_foreground = lambda images: None
        rows = []
        for k, images in enumerate(frames):
            stamp = int(round(k * 1e9 / FPS))
            if variant == 'failed' and k == failing:
                real = tracker.filter.step

                def broken(*args, **kwargs):
                    raise RuntimeError('filter failed')
                tracker.filter.step = broken
                with pytest.raises(RuntimeError):
                    tracker.step(stamp, images)
                tracker.filter.step = real
                continue
            if variant != 'failed' and k == failing:
                continue  # the frame set the failing run loses
            res = tracker.step(stamp, images)
            rows.append([(t.track_id, *np.round(t.mean[:2], 9), t.existence)
                         for t in res.tracks])
        runs.append(rows)
        banks.append(tracker.detection.background.models)
    assert all(run == runs[0] for run in runs[1:])
    assert any(runs[0])  # someone was tracked
    for name, model in banks[0].items():
        for other in banks[1:]:
            np.testing.assert_array_equal(model.background_ycc, other[name].background_ycc)
            np.testing.assert_array_equal(model.presence(), other[name].presence())


def test_pipelined_search_is_timing_independent_and_starts_people_one_frame_later():
    """pipeline_search: the search of frame t runs on the worker while frame t+1 is
    filtered and its people are added after frame t+1's result. Whatever the threads'
    timing (random sleeps in the worker's part and in the filter) and whether the caller
    runs step() or step(search=False) + search(), the tracks are the same; the person
    appears one frame later than with the serial search; the detector and the acquisition
    run on the worker, the decisions on the tracks (_associate) on the caller's thread."""
    import threading
    import time

    calib = make_room()
    bgs = backgrounds(calib)
    frames = [paint(calib, bgs, [person(1.5 + 0.05 * k, 2.8, theta=0.0)] if k >= 3 else [],
                  np.random.default_rng(k)) for k in range(16)]
    runs, threads = {}, {'find': set(), 'identify': set()}
    for variant in ('serial', 'pipelined', 'pipelined_slow', 'pipelined_deferred'):
        tracker = _detecting_tracker(calib, bgs, seed=1,
                                     pipeline_search=variant != 'serial')
        det = tracker.detection
        if variant == 'pipelined_slow':
            jitter = np.random.default_rng(5)
            find, identify, step = det._find, det._associate, tracker.filter.step

            def slow_find(*args, **kwargs):
                time.sleep(jitter.uniform(0, 0.03))
                threads['find'].add(threading.current_thread().name)
                return find(*args, **kwargs)

            def watched_identify(*args, **kwargs):
                threads['identify'].add(threading.current_thread().name)
                return identify(*args, **kwargs)

            def slow_step(*args, **kwargs):
                time.sleep(jitter.uniform(0, 0.03))
                return step(*args, **kwargs)
            det._find, det._associate, tracker.filter.step = slow_find, watched_identify, \
                slow_step
        rows = []
        for k, images in enumerate(frames):
            deferred = variant == 'pipelined_deferred'
            res = tracker.step(int(round(k * 1e9 / FPS)), images, search=not deferred)
            if deferred:
                tracker.search()
                assert tracker.search() == []  # one search per step
            rows.append([(t.track_id, *np.round(t.mean[:2], 9), t.existence)
                         for t in res.tracks])
        runs[variant] = rows
    assert runs['pipelined'] == runs['pipelined_slow'] == runs['pipelined_deferred']
    first = {v: next(k for k, r in enumerate(rows) if r) for v, rows in runs.items()}
    assert first['pipelined'] == first['serial'] + 1
    assert runs['pipelined'][-1][0][0] == runs['serial'][-1][0][0] == 1
    assert np.hypot(*np.subtract(runs['pipelined'][-1][0][1:3],
                                 runs['serial'][-1][0][1:3])) < 0.25
    assert threads['find'] and threading.main_thread().name not in threads['find']
    assert threads['identify'] == {threading.main_thread().name}


# -- fast paths against their straightforward versions -----------------------------------
def test_prefix_sums_equal_numpy_cumsum():
    rng = np.random.default_rng(4)
    fg = rng.random((H, W)) < 0.3
    unknown = rng.random((H, W)) < 0.2
    for unk in (unknown, None):
        known = np.ones((H, W), bool) if unk is None else ~unk
        integral = ForegroundIntegral(fg, unk)
        np.testing.assert_array_equal(integral._fg[:, 1:], np.cumsum(fg & known, axis=1))
        np.testing.assert_array_equal(integral._known[:, 1:], np.cumsum(known, axis=1))
        assert not integral._fg[:, 0].any() and not integral._known[:, 0].any()


def test_colour_symmetry_equals_numpy_histograms():
    """The kernel (colours merged once per image) equals a plain per-silhouette version."""
    rng = np.random.default_rng(8)
    calib = make_room()
    cam = calib.cameras['cam1']
    states = np.zeros((8, 6))
    states[:, :2] = rng.uniform([1.0, 1.0], [5.0, 4.0], (8, 2))
    states[:, 4] = rng.uniform(0, np.pi, 8)
    sil = rasterize(cam, states, BodyShape(1.8, 0.55))
    image = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    for levels in (2, 4, 8):
        fast = colour_symmetry(image, sil, levels=levels, min_pixels=4)
        q = (image // (256 // levels)).astype(np.int64)
        colour = (q[..., 0] * levels + q[..., 1]) * levels + q[..., 2]
        for i in range(len(states)):
            left, right = [], []
            for s in range(sil.offsets[i], sil.offsets[i + 1]):
                if sil.part[s] != TORSO or not 0 <= sil.row[s] < H:
                    continue
                for x in range(max(sil.x0[s], 0), min(sil.x1[s], W)):
                    side = np.sign(2 * x + 1 - (sil.x0[s] + sil.x1[s]))
                    if side:
                        (left if side < 0 else right).append(colour[sil.row[s], x])
            if min(len(left), len(right)) < 4:
                assert np.isnan(fast[i])
                continue
            hl = np.bincount(left, minlength=levels ** 3) / len(left)
            hr = np.bincount(right, minlength=levels ** 3) / len(right)
            assert fast[i] == pytest.approx(np.abs(hl - hr).sum(), abs=1e-12)
        assert np.isfinite(fast).sum() >= 4


def test_edge_map_equals_full_image_component_validation():
    """Validating edge components inside the edges' bounding box keeps the same edges as the
    connected components of the whole image."""
    rng = np.random.default_rng(2)
    image = cv2.resize(rng.integers(0, 256, (15, 20, 3), dtype=np.uint8), (W, H),
                       interpolation=cv2.INTER_NEAREST)
    fg = np.zeros((H, W), bool)
    fg[30:90, 40:100] = True
    fast = EdgeMap.from_image(image, fg, min_edge_pixels=12)
    gray = cv2.GaussianBlur(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), (3, 3), 0)
    edges = cv2.Canny(gray, 40.0, 120.0, L2gradient=True)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (15, 15))
    edges &= cv2.dilate(fg.astype(np.uint8), k) * 255
    _, labels, stats, _ = cv2.connectedComponentsWithStats((edges > 0).astype(np.uint8),
                                                           connectivity=8)
    keep = stats[:, cv2.CC_STAT_AREA] >= 12
    keep[0] = False
    np.testing.assert_array_equal(fast.edges, keep[labels])
    assert fast.edges.any() and (fast.edges != (edges > 0)).any()   # some were dropped
    dist, _ = cv2.distanceTransformWithLabels(np.where(keep[labels], 0, 1).astype(np.uint8),
                                              cv2.DIST_L2, 5,
                                              labelType=cv2.DIST_LABEL_PIXEL)
    np.testing.assert_array_equal(fast.distance, dist)


def test_selected_silhouettes_equal_separate_rasterisations():
    rng = np.random.default_rng(9)
    cam = make_room().cameras['cam2']
    a = np.zeros((5, 6))
    a[:, :2] = rng.uniform([0.5, 0.5], [5.5, 4.5], (5, 2))
    a[1, 5] = 1.0
    b = np.zeros((3, 6))
    b[:, :2] = rng.uniform([0.5, 0.5], [5.5, 4.5], (3, 2))
    shape = BodyShape(1.75, 0.5)
    ha, hb = np.full(5, 1.7), np.full(3, 2.1)
    both = rasterize(cam, np.concatenate([a, b]), shape, heights=np.concatenate([ha, hb]))
    for part, (states, h) in zip((both.select(0, 5), both.select(5, 8)), ((a, ha), (b, hb))):
        one = rasterize(cam, states, shape, heights=h)
        for f in ('row', 'x0', 'x1', 'part', 'offsets', 'area', 'part_area', 'full_area',
                  'bbox', 'distance'):
            np.testing.assert_array_equal(getattr(part, f), getattr(one, f))


def test_step_reuses_the_filters_colour_bins_and_defers_the_background_update():
    """After step(search=False) the side cameras' evidence holds the measurement model's
    quantised images (no second quantisation) and the background update (with the motion
    the detector needs) is pending until search()."""
    calib = make_room()
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=1)
    checked = 0
    for k in range(12):
        images = paint(calib, bgs, [person(1.5 + 0.05 * k, 2.8, theta=0.0)] if k >= 3
                       else [], np.random.default_rng(k))
        tracker.step(int(round(k * 1e9 / FPS)), images, search=False)
        pending = tracker.detection._pending
        evidence = pending.evidence if pending else {}
        bins = tracker.measurement.frame_bins()
        for name in set(evidence) & set(bins):
            assert evidence[name].bins is bins[name]
            np.testing.assert_array_equal(bins[name], quantize(images[name]))
            checked += 1
        models = tracker.detection.background.models
        if evidence:
            assert all(models[n].pending for n in evidence)
            assert all(ev.motion is None for ev in evidence.values())
        tracker.search()
        assert not any(m.pending for m in models.values())
        assert all(ev.motion is not None for ev in evidence.values())
    assert checked > 0


@pytest.mark.parametrize('hidden_rule', [True, False])
def test_a_hidden_track_beside_a_detection_is_moved_there_instead_of_a_birth(
        monkeypatch, hidden_rule):
    """A track 0.8 m off its person whose existence fell below the report threshold (it lost
    its person): the person's detection moves that track (same id) whatever the appearance
    gain; when no hidden track is found (``_hidden_hypothesis`` patched) a second track is
    born (and released later as a duplicate)."""
    from mbtrack_ros.core.detection.manager import AutoDetection

    def hidden(tracker):
        # the appearance gain can never move a track; track 1 counts as hidden
        monkeypatch.setattr(AutoDetection, '_explains', lambda self, *a: -1e9)
        monkeypatch.setattr(AutoDetection, 'reported', lambda self, tid: False)
        if not hidden_rule:
            _no_hidden_moves(monkeypatch)

    tracker, step = _drifted_walker(36, before_drift=hidden)
    actions = []
    for k in range(36, 50):
        actions += step(k)[1]
    if hidden_rule:
        assert tracker.track_ids == [1] and 'move 1 (hidden)' in actions
        assert 'birth' not in actions
        mean = tracker.filter._particles[1].mean(axis=0)
        assert np.hypot(mean[0] - (2.0 + 0.02 * 49), mean[1] - 2.6) < 0.3
    else:
        assert 'birth' in actions and not any(a.startswith('move') for a in actions)


@pytest.mark.parametrize('reuse_time, place, back, reused', [
    (2.0, (2.5, 2.5), 'same', True), (0.0, (2.5, 2.5), 'same', False),
    (2.0, (4.6, 4.5), 'same', True), (2.0, (4.6, 4.5), 'other', False),
    (2.0, (2.5, 2.5), None, False), (2.0, (2.5, 2.5), 'other', False)])
def test_a_person_re_found_soon_after_the_release_gets_the_released_id(
        reuse_time, place, back, reused):
    """A standing person vanishes (their track is released after the 1 s timeout) and is
    detected again at the same place 0.3 s later: within ``reuse_time`` the new track takes
    the released id, in the entry zone too; with ``reuse_time`` 0, or when somebody who
    looks different stands there (the appearance ratio; in the
    entry zone: a newcomer), a new id is issued. The id ends (``FrameResult.ended``) at the
    release when it cannot come back, ``reuse_time`` after it when nobody took it, never
    when it was taken: an id never returns after it ended."""
    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4, reuse_time=reuse_time)
    stand = [person(*place, theta=0.0)]
    other = [person(*place, theta=0.0, colours=YELLOW)]
    released_at, ids, ended = None, [], {}
    for k in range(75):
        gone = 12 <= k < 12 + 15 + 5 if released_at is None else \
            (k < released_at + 5 or back is None)
        who = stand if released_at is None or back == 'same' else other
        r = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, [] if gone else who,
                                                          rng))
        for tid in r.ended:
            assert tid not in ended, 'an id ends once'
            ended[tid] = k
        if released_at is None and k > 0 and ids[-1] == [1] and not tracker.track_ids:
            released_at = k
        ids.append(sorted(tracker.track_ids))
    assert released_at is not None
    assert ids[-1] == ([1] if reused else [2] if back else [])
    if reused:
        assert 1 not in ended
    elif reuse_time == 0:  # cannot come back: ends at the release
        assert ended[1] == released_at
    else:       # lost for reuse_time, then ended
        assert ended[1] == released_at + round(reuse_time * FPS)
    for tid, k in ended.items():
        assert all(tid not in later for later in ids[k:]), 'an ended id came back'


@pytest.mark.parametrize('reuse_time', [AutoDetectionConfig().reuse_time, 2.0])
def test_a_person_re_found_2_5_s_after_the_release_keeps_her_id_by_default(reuse_time):
    """A person whose track was released is detected again at the same place 2.5 s
    later (on clear-room a person who stood up from her chair was re-found 2.4-2.9 s after
    her track's release): the default
    ``reuse_time`` (3 s) gives her the released id back; with the former 2 s the id has
    ended and a new one is issued."""
    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4, reuse_time=reuse_time)
    stand = [person(2.5, 2.5, theta=0.0)]
    gap = round(2.5 * FPS)
    released_at, ids = None, []
    for k in range(120):
        gone = 12 <= k if released_at is None else k < released_at + gap
        tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, [] if gone else stand,
                                                      rng))
        if released_at is None and k > 0 and ids[-1] == [1] and not tracker.track_ids:
            released_at = k
        ids.append(sorted(tracker.track_ids))
    assert released_at is not None and released_at + gap < 110
    assert ids[-1] == ([1] if reuse_time >= 2.5 else [2]), (reuse_time, ids[-1])


@pytest.mark.parametrize('relocate_radius, reused', [(None, True), (0.5, False)])
def test_a_person_re_found_1_3_m_from_her_released_track_keeps_her_id_by_default(
        relocate_radius, reused):
    """A person's track is released where she stood, and she is detected again 1.3 m
    away (a track left behind a person who turned is released and she is found again a
    few frames later): the default ``reuse_radius`` (1 m ``relocate_radius`` + 0.5 m/s for
    the 1 s release timeout) gives her the released id back; with a ``relocate_radius``
    (the release's ``spare_radius``) of 0.5 m (a reuse radius of 1 m) a new id is
    issued."""
    assert AutoDetectionConfig().reuse_radius == 1.5
    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4)
    if relocate_radius is not None:
        _set_relocate_radius(tracker, relocate_radius)
    stand, moved = [person(2.3, 2.5, theta=0.0)], [person(3.6, 2.5, theta=0.0)]
    released_at, ids = None, []
    for k in range(75):
        if released_at is None:
            who = [] if k >= 12 else stand
        else:
            who = [] if k < released_at + 5 else moved
        tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, who, rng))
        if released_at is None and k > 0 and ids[-1] == [1] and not tracker.track_ids:
            released_at = k
        ids.append(sorted(tracker.track_ids))
    assert released_at is not None and released_at + 5 < 60
    assert ids[-1] == ([1] if reused else [2]), (relocate_radius, ids[-1])


@pytest.mark.parametrize('margin', [AutoDetectionConfig().duplicate_margin, float('inf')])
def test_of_two_tracks_on_one_person_the_one_whose_model_fits_stays(margin):
    """Track 1 follows a person in blue, track 2 a person in yellow; the person in blue
    leaves and, at the same frame, track 1 jumps onto the person in yellow (a track that
    stayed behind when its person walked out and took over somebody else's). After the
    merge time one of the two is released: with ``duplicate_margin`` the one whose model
    does not explain the yellow person (1, although reported for longer); without it the
    shorter reported one (2), which leaves the yellow person with the wrong id."""
    rng = np.random.default_rng(3)
    calib, bgs, tracker = _painted_room_tracker(2, duplicate_margin=margin)
    det = tracker.detection
    blue = person(2.0, 2.4, theta=0.0)
    yellow = person(4.0, 3.0, theta=0.0, colours=YELLOW)
    released, jump, checks = {}, 30, []
    for k in range(60):
        if k == jump:
            assert tracker.track_ids == [1, 2]      # 1 on blue, 2 on yellow
            tracker.relocate_track(1, yellow[0])
        people = ([blue] if k < jump else []) + ([yellow] if k >= 8 else [])
        r = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, people, rng))
        for tid in r.released:
            released.setdefault(tid, k)
        checks += det.duplicate_checks
    assert released == ({1: jump + round(0.5 * FPS)} if np.isfinite(margin)
                        else {2: jump + round(0.5 * FPS)})
    assert tracker.track_ids == ([2] if np.isfinite(margin) else [1])
    if np.isfinite(margin):     # judged once: track 2's model fits by far
        assert len(checks) == 1 and checks[0]['ids'] == (1, 2) and checks[0]['keep'] == 2
        assert checks[0]['gain'] < -margin and checks[0]['cameras'] >= 2
    else:
        assert checks == []
    for bad in (-1.0, float('nan')):
        with pytest.raises(DetectionError, match='duplicate_margin'):
            AutoDetectionConfig(duplicate_margin=bad)

def test_detection_every_kth_frame_set_holds_existence_in_between(monkeypatch):
    """``detection_every=3``: the detection pipeline runs on frame sets 0, 3, 6, ... only;
    the frame sets between report the tracks with the last existence and visibility, and
    the painted person is still found and released."""
    from mbtrack_ros.core.detection.manager import AutoDetection
    from mbtrack_ros.core.existence import AuxiliaryConfig
    from mbtrack_ros.core.tracker import TrackerConfig, TrackerError

    for bad in (0, -2, 1.5, True):
        with pytest.raises(TrackerError, match='detection_every'):
            TrackerConfig(detection_every=bad)
    calls: list[int] = []
    plain = AutoDetection.update

    def counted(self, stamp_ns, *a, **k):
        calls.append(int(stamp_ns))
        return plain(self, stamp_ns, *a, **k)

    monkeypatch.setattr(AutoDetection, 'update', counted)
    rng = np.random.default_rng(8)
    calib = make_room()
    bgs = backgrounds(calib)
    every = 3
    tracker = _detecting_tracker(calib, bgs, seed=1, detection_every=every)
    enter, leave, total = 3, 30, 66
    stamps, born, ended, held = [], None, None, 0
    last: dict[int, tuple[float, dict]] = {}
    for k in range(total):
        x = 2.0 + 0.05 * k
        people = [person(x, 2.8, theta=0.0)] if enter <= k < leave else []
        stamp = int(round(k * 1e9 / FPS))
        stamps.append(stamp)
        res = tracker.step(stamp, paint(calib, bgs, people, rng))
        if born is None and res.tracks:
            born = k
        for t in res.tracks:
            if k % every:  # skipped: the values of the last detection frame set
                before = last.get(t.track_id, (AuxiliaryConfig().initial_existence, {}))
                assert (t.existence, t.visibility) == before  # (or those of a new track)
                held += 1
            last[t.track_id] = (t.existence, dict(t.visibility))
        if res.released:
            assert k % every == 0  # releases happen on detection frame sets only
            ended = k if ended is None else ended
    assert calls == stamps[::every]
    assert held > 10
    assert born is not None and (born - enter) / FPS <= 0.5 + (every - 1) * 2 / FPS
    assert ended is not None and 0 < (ended - leave) / FPS <= 1.5 + (every - 1) / FPS
    assert tracker.track_ids == []
    tracker.reset()  # the count restarts: the next frame set runs the detection
    calls.clear()
    tracker.step(stamps[-1] + 10 ** 9, bgs)
    assert len(calls) == 1


def _pinned_existence(reach_radius, frames=14, ghost=False, spare_rule=True,
                      exclusion=True, reach_age=0.0, off=0.5):
    """A person walking at 0.9 m/s along y = 2.6 m, tracked as track 1 for 16 frames;
    then, frame by frame, track 1 is put back ``off`` metres behind them before the step (a
    track that fell behind a person who started walking) or, with ``ghost``, a second track
    with track 1's model is kept ``off`` beside the person while track 1 follows them.
    Returns the existence per later frame of the pinned track (NaN: released).
    ``spare_rule=False``: no spare tracks (release ``spare_support`` 0);
    ``exclusion=False``: the detector's (and the reach's) exclusion radius 0; the track is
    about 1 s old (``reach_age`` 0 by default)."""
    from dataclasses import replace

    rng = np.random.default_rng(5)
    calib = make_room(ceiling=False)       # the corner cameras alone decide existence
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=4)
    det = tracker.detection
    det.config = replace(det.config, reach_radius=reach_radius, reach_age=reach_age)
    if not exclusion:
        det.config = replace(det.config, detector=replace(det.config.detector,
                                                          exclusion_radius=0.0))
    if not spare_rule:
        det.releaser = Releaser(calib, replace(det.releaser.config, spare_support=0.0))

    def walker(k):
        return [person(1.5 + 0.06 * k, 2.6, theta=0.0)]
    res = _track_painted(tracker, calib, bgs, rng, 16, walker)
    assert tracker.track_ids == [1] and res[-1].tracks[0].existence > 0.9
    pinned = 1
    if ghost:
        state = res[-1].tracks[0].mean.copy()
        state[1] += off
        pinned = tracker.add_track(tracker._models[1], state, int(round(15 * 1e9 / FPS)))
    out = []
    for k in range(16, 16 + frames):
        x = 1.5 + 0.06 * k
        if pinned in tracker.track_ids:
            state = np.array([x - off, 2.6, 0.0, 0.0, 0.0, 0.0]) if not ghost else \
                np.array([x - 0.06, 2.6 + off, 0.9, 0.0, 0.0, 0.0])
            tracker.relocate_track(pinned, state)
        tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, walker(k), rng))
        aux = det.aux.get(pinned)
        out.append(aux.existence if aux is not None and pinned in tracker.track_ids
                   else np.nan)
    return np.array(out)


def test_a_track_lagging_its_walking_person_stays_reported_by_its_reach():
    """A track kept 0.4 m behind its walking person: the coverage of its silhouette falls
    and, judged at its mean only, its existence drops below the report threshold (it would
    be hidden, the person shielded from the detector, and re-born under a new id after
    its release); with the reach (the best place within 0.5 m counts) it stays reported."""
    lagging = _pinned_existence(0.5)
    assert np.all(lagging >= 0.5), lagging
    at_mean = _pinned_existence(0.0)
    assert np.nanmin(at_mean) < 0.5, at_mean
    young = _pinned_existence(0.5, reach_age=2.0)     # a track of 1 s has no reach yet
    assert np.nanmin(young) < 0.5, young


@pytest.mark.parametrize('guard', ['all', 'pixels', 'spare', 'none'])
def test_the_reach_does_not_keep_a_track_alive_on_another_tracked_person(
        monkeypatch, guard):
    """A second track kept 0.44 m beside a tracked person (its own silhouette there covers
    less than the support coverage of the person): its reach counts only foreground
    that the other track's silhouette does not cover ('pixels'), a spare track (release
    rule) has no reach ('spare'), and no place of the reach lies within the detector's
    exclusion radius of another track (part of 'all'; alone it is not enough: a place just
    outside the radius covers the person's support coverage). 'pixels' or 'spare' alone
    keeps the ghost's existence from the person beside it, so that it falls below the
    report threshold; with none of them the person keeps it reported."""
    from mbtrack_ros.core.detection import deleter

    if guard not in ('all', 'pixels'):   # the other track's pixels not set aside
        counts = deleter.span_counts
        monkeypatch.setattr(deleter, 'span_counts',
                            lambda fg, spans, unknown=None: counts(fg, spans))
    ghost = _pinned_existence(0.5, ghost=True, spare_rule=guard in ('all', 'spare'),
                              exclusion=guard in ('all', 'radius'), off=0.44)
    if guard != 'none':
        assert np.nanmin(ghost) < 0.5, ghost
    else:
        assert np.all(ghost[:6] >= 0.5), ghost


def test_a_lagging_track_is_moved_to_the_place_its_reach_found():
    """A track put 0.45 m behind its walking person once is restarted where its reach
    found the person and is within 0.2 m of them two frames later."""
    from dataclasses import replace

    rng = np.random.default_rng(5)
    calib = make_room(ceiling=False)
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=4)
    tracker.detection.config = replace(tracker.detection.config, reach_age=0.0)

    def walker(k):
        return [person(1.5 + 0.06 * k, 2.6, theta=0.0)]
    _track_painted(tracker, calib, bgs, rng, 16, walker)
    assert tracker.track_ids == [1]
    tracker.relocate_track(1, np.array([1.5 + 0.06 * 15 - 0.45, 2.6, 0.0, 0.0, 0.0, 0.0]))
    moved = []
    for k in (16, 17):
        res = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, walker(k), rng))
        moved.append(1 in tracker.detection.reach_moves)
    lag = 1.5 + 0.06 * 17 - res.tracks[0].mean[0]
    assert tracker.track_ids == [1]
    assert moved[0] and abs(lag) < 0.2, lag


def test_reach_counts_foreground_only_where_no_other_track_is():
    """The reach ring's coverage, side and top-down cameras: a place on an untracked
    person's foreground is covered; the same place is not when another track's silhouette
    (blob) at its mean covers that person, nor when the person's pixels are a possible
    person of the bootstrap (a ghost: the background's not-yet-known foreground); with the
    detector's exclusion radius there is no place near the other track at all; bad
    settings raise."""
    from mbtrack_ros.core.detection.manager import AutoDetection
    from mbtrack_ros.core.detection.release import paint_blobs

    calib = make_room()
    shape = BodyShape(1.8, 0.5)
    person_xy = np.array([2.5, 2.5])
    me = np.array([2.0, 2.5, 0.0, 0.0, 0.0, 0.0])      # the person is 0.5 m in +x of me
    other = np.r_[person_xy, 0.0, 0.0, 0.0, 0.0]       # a track on that person
    covered = {}
    for case in ('free', 'tracked', 'ghost', 'excluded'):
        det = AutoDetection(calib, AutoDetectionConfig(
            reach_radius=0.5,
            detector=DetectorConfig(exclusion_radius=0.5 if case == 'excluded' else 0.0)))
        det.bootstrap({n: [np.zeros((H, W, 3), np.uint8)] for n in calib.cameras})
        means = np.array([me, other]) if case in ('tracked', 'excluded') else me[None]
        evidence, sils = {}, {}
        for n, cam in calib.cameras.items():
            fg = np.zeros((H, W), bool)
            if is_ceiling(cam):
                paint_blobs(fg, cam, person_xy[None], np.array([1.8]))
            else:
                fg |= render_labels(cam, np.r_[person_xy, 0, 0, 0, 0], shape) > 0
            if case == 'ghost':
                det.background.model(n).set_unknown(fg)
            evidence[n] = FrameEvidence(np.zeros((H, W, 3), np.uint8), fg)
            sils[n] = rasterize(cam, means, [shape] * len(means))
        places, rings = det._reach_coverage(0, evidence, sils, means, [shape] * len(means),
                                            np.full(len(means), 1.8))
        if case == 'excluded':
            assert 0 < len(places) == len(rings) < 16  # 16 places, those near the track not
            assert np.linalg.norm(places - person_xy, axis=1).min() > 0.5
            continue
        at = int(np.argmin(np.linalg.norm(places - person_xy, axis=1)))
        assert np.allclose(places[at], person_xy)
        covered[case] = rings[at]
    for n in calib.cameras:
        assert covered['free'][n] > 0.8, (n, covered)
        assert covered['tracked'][n] < 0.1, (n, covered)
        assert covered['ghost'][n] < 0.1, (n, covered)
    for bad in ({'reach_radius': -0.1}, {'reach_age': -1.0}):
        with pytest.raises(DetectionError):
            AutoDetectionConfig(**bad)


@pytest.mark.parametrize('how', ['hidden', 'gain', 'young'])
def test_a_lost_track_that_looks_like_the_person_is_reused_before_another_is_moved(
        monkeypatch, how):
    """Blue's track (1) is released while she is away; yellow's track (2) is either hidden
    (not reported, moved whatever the gain) or left behind when yellow walks off, its
    model's appearance gain at the detection forced to +2 nats (a move by the gain;
    'young': track 2 counts as placed moments ago).
    Blue comes back 0.75 m from track 2: the assignment gives her her lost id back (the
    appearance ratio of her model and blue's lost one is larger than what track 2's
    hypothesis offers; a hidden track offers nothing for somebody who looks unlike it, its
    appearance ratio negative) and track 2 stays."""
    from mbtrack_ros.core.detection.manager import AutoDetection

    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4, reach_radius=0.0)
    if how == 'young':      # the gain's hypothesis, onto a track placed moments ago
        placed = AutoDetection._placed_recently
        monkeypatch.setattr(AutoDetection, '_placed_recently', lambda self, tid, stamp:
                            (tid == 2 and released_at is not None)
                            or placed(self, tid, stamp))
    blue, yellow = person(2.0, 2.5, theta=0.0), person(3.5, 2.5, theta=0.0, colours=YELLOW)
    back = person(2.75, 2.5, theta=0.0)
    released_at, actions, decided = None, [], []
    for k in range(60):
        if released_at is None:
            people = [yellow] if k >= 15 else [blue, yellow]
        else:
            gone = how != 'hidden' and k >= released_at + 2
            people = ([] if k < released_at + 5 else [back]) + ([] if gone else [yellow])
        tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, people, rng))
        actions += [d['action'] for d in tracker.detection.decisions]
        decided += tracker.detection.decisions
        if released_at is None and k > 10 and tracker.track_ids == [2]:
            released_at = k
            actions, decided = [], []
            if how == 'hidden':     # the gain never moves; track 2 is hidden
                monkeypatch.setattr(AutoDetection, '_explains', lambda self, *a: -1e10)
                monkeypatch.setattr(AutoDetection, 'reported', lambda self, tid: tid != 2)
            else:
                monkeypatch.setattr(AutoDetection, '_explains', lambda self, *a: 2.0)
        if released_at is not None and k >= released_at + 12:
            break
    assert released_at is not None
    on_blue = [t for t in tracker.track_ids if np.hypot(
        *(tracker.filter._particles[t].mean(axis=0)[:2] - back[0][:2])) < 0.3]
    moved = 'move 2 (hidden)' if how == 'hidden' else 'move 2'
    reused = 'reuse 1' if how == 'hidden' else 'reuse 1 (not 2)'
    assert reused in actions and moved not in actions, actions
    assert 'drop (track 2 placed recently)' not in actions, actions
    # blue has her id back; track 2, left behind by yellow, may follow the foreground of
    # blue 0.75 m away (its coverage above the support coverage keeps its existence)
    # until the duplicate rule ends one of the two
    assert on_blue == [1] if how == 'hidden' else 1 in on_blue, on_blue
    # the terms that decided it: lost track 1 (metres, appearance distance) nearer blue
    # in appearance than track 2, the track the detection would have moved
    reuse = next(d for d in decided if d['action'] == reused)
    (lost, metres, unlike), = [r for r in reuse['reuse'] if r[0] == 1]
    if how == 'hidden':
        assert reuse['llr'].get('track 2', 0.0) < 0.0 < reuse['llr']['lost 1'], reuse
    else:
        assert reuse['unlike'][0] == 2 and unlike < reuse['unlike'][1], reuse
        assert reuse['llr']['lost 1'] > reuse['llr']['track 2'], reuse
    assert metres <= AutoDetectionConfig().reuse_radius, reuse


@pytest.mark.parametrize('rule, who, moved', [(True, 'same', True), (False, 'same', False),
                                              (True, 'other', False)])
def test_a_hidden_track_1_2_m_away_is_given_back_its_person_when_she_looks_alike(
        monkeypatch, rule, who, moved):
    """Track 1 follows a person in blue; from frame 40 it is hidden (not reported) and she
    stands 1.2 m away, beyond ``relocate_radius``. Her detection moves track 1 there (same
    id), as a lost track's id would be given back within ``reuse_radius``; with a
    ``reuse_radius`` below 1.2 m (``relocate_radius`` 0.5 m), or when the person there is
    dressed differently
    (the appearance ratio of the two models), a new track is born."""
    from mbtrack_ros.core.detection.manager import AutoDetection

    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4, reach_radius=0.0)
    if not rule:
        _set_relocate_radius(tracker, 0.5)
    here = person(2.0, 2.5, theta=0.0)
    there = person(3.2, 2.5, theta=0.0, **({} if who == 'same' else {'colours': YELLOW}))
    actions = []
    for k in range(52):
        if k == 40:
            assert tracker.track_ids == [1]
            monkeypatch.setattr(AutoDetection, 'reported', lambda self, tid: tid != 1)
        tracker.step(int(round(k * 1e9 / FPS)),
                     paint(calib, bgs, [here if k < 40 else there], rng))
        if k >= 40:
            actions += [d['action'] for d in tracker.detection.decisions]
    assert ('move 1 (hidden, far)' in actions) == moved, actions
    assert ('birth' in actions) == (not moved), actions
    mean = tracker.filter._particles[1].mean(axis=0)
    assert (np.hypot(mean[0] - 3.2, mean[1] - 2.5) < 0.3) == moved


@pytest.mark.parametrize('who, moved', [('same', True), ('other', False)])
def test_a_reported_track_of_doubtful_existence_is_given_back_its_person_like_a_hidden_one(
        who, moved):
    """As above, but track 1 stays reported (``existence.report_threshold`` 0) while its
    existence falls once she has stepped 1.2 m away (slowly: a weak coverage evidence,
    ``existence.support_gain`` 0.5, and the top-down camera's blob at the old place still
    covers part of her foreground, so that it is above 0.5 when her detection is
    confirmed). Below ``reuse_doubtful`` (a newborn's existence; 0.97 in
    this scene) it counts as hidden and her detection moves it there ("doubtful, far"); it
    is not taken for a person dressed differently (a new track is born)."""
    assert AutoDetectionConfig().reuse_doubtful == 0.9
    from mbtrack_ros.core.existence import AuxiliaryConfig

    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(
        4, reach_radius=0.0,
        existence=AuxiliaryConfig(report_threshold=0.0, initial_existence=0.97,
                                  support_gain=0.5))
    doubtful = tracker.detection.config.reuse_doubtful
    here = person(2.0, 2.5, theta=0.0)
    there = person(3.2, 2.5, theta=0.0, **({} if who == 'same' else {'colours': YELLOW}))
    actions, existence, far = [], [], []
    for k in range(52):
        if k == 40:
            assert tracker.track_ids == [1]
        tracker.step(int(round(k * 1e9 / FPS)),
                     paint(calib, bgs, [here if k < 40 else there], rng))
        if k >= 40:
            actions += [d['action'] for d in tracker.detection.decisions]
            far += [d['far'] for d in tracker.detection.decisions if 'far' in d]
            existence.append(tracker.detection.aux[1].existence)
    # not reported at the default report_threshold (unless given back its person first)
    assert (min(existence) < 0.5) == (not moved), existence
    assert ('move 1 (doubtful, far)' in actions) == moved, actions
    if moved:   # logged: the track, its distance, appearance distance and existence
        (tid, metres, unlike, exists), = far
        assert tid == 1 and 1.0 < metres < 1.5 and unlike <= 0.55 and exists < doubtful
    assert ('birth' in actions) == (not moved), actions
    mean = tracker.filter._particles[1].mean(axis=0)
    assert (np.hypot(mean[0] - 3.2, mean[1] - 2.5) < 0.3) == moved


def _move_or_birth(monkeypatch, who: str, gain: float, **detection):
    """Track 1 follows a person in blue; from frame 40 she is gone and somebody (``who``:
    'same', the blue person, or 'other', dressed in yellow) stands 0.75 m from the track,
    the appearance gain of track 1's model there forced to ``gain``. Returns the tracker,
    the decisions' actions from frame 40 and the tracks the appearance ratio kept back."""
    from mbtrack_ros.core.detection.manager import AutoDetection

    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4, reach_radius=0.0, **detection)
    _no_hidden_moves(monkeypatch)
    here = person(2.0, 2.5, theta=0.0)
    there = person(2.75, 2.5, theta=0.0, **({} if who == 'same' else {'colours': YELLOW}))
    actions, unalike = [], []
    for k in range(52):
        if k == 40:
            assert tracker.track_ids == [1]
            monkeypatch.setattr(AutoDetection, '_explains', lambda self, *a: gain)
        tracker.step(int(round(k * 1e9 / FPS)),
                     paint(calib, bgs, [here if k < 40 else there], rng))
        if k >= 40:
            actions += [d['action'] for d in tracker.detection.decisions]
            unalike += [d['unalike'] for d in tracker.detection.decisions if 'unalike' in d]
    return tracker, actions, unalike


def _appearance_zero(monkeypatch, distance: float) -> None:
    """Trackers made from now on start their appearance ratio with its zero at
    ``distance`` (the prior of :class:`AppearanceRatio`), the clutter distance unchanged."""
    from mbtrack_ros.core.detection import manager

    monkeypatch.setattr(manager, 'AppearanceRatio',
                        lambda a, sigma: AppearanceRatio(distance, sigma))


def test_the_move_ratio_is_the_gain_and_for_a_strong_detection_the_looks():
    """:meth:`AutoDetectionConfig.move_llr` against its terms written out on a grid of
    scores, gains (nats per side camera) and appearance ratios (nats): the gain, plus for a
    strong detection (``beside_threshold``) the appearance ratio floored at 0. With
    the detection's own ratio (score less ``beside_threshold``) added, a weak detection
    beats its drop only with a gain above its score's shortfall."""
    cfg = AutoDetectionConfig()
    for score in (0.5, cfg.beside_threshold - 0.01, cfg.beside_threshold, 6.0):
        for gain in (-9.0, -6.0, -1.0, 0.0, 0.02, 2.6):
            for looks in (-5.0, -0.1, 0.0, 0.3, 8.7):
                strong = score >= cfg.beside_threshold
                want = gain + (max(looks, 0.0) if strong else 0.0)
                got = cfg.move_llr(score, gain, looks)
                assert got == pytest.approx(want), (score, gain, looks)
                if not strong:      # the move against the drop: gain over the shortfall
                    assert (score - cfg.beside_threshold + got > 0) == (
                        gain > cfg.beside_threshold - score)


def test_every_decision_is_logged_with_its_terms(monkeypatch, caplog):
    """Each confirmed detection's decision is one debug line: the detection's place and
    score, the action, and its terms - per track compared (id, metres, appearance gain in
    nats per side camera, appearance distance), the exclusive support a move would leave,
    the strangers the looks kept back. In the scene of :func:`_move_or_birth` with the
    gain forced to -1: the blue person moves track 1, the stranger in yellow is born."""
    import logging
    import re

    logger = 'mbtrack_ros.core.detection.association'
    for who, action in (('same', 'move 1'), ('other', 'birth')):
        caplog.clear()
        with caplog.at_level(logging.DEBUG, logger=logger):
            _, actions, _ = _move_or_birth(monkeypatch, who, -1.0)
        lines = [r.getMessage() for r in caplog.records if r.name == logger]
        assert len(lines) >= len(actions) > 0 and action in actions, (actions, lines)
        # (the first birth is the blue person's when the room was empty)
        line = next(m for m in lines if f': {action};' in m and 'near=' in m)
        assert re.match(r'detection at \(2\.\d\d, 2\.\d\d\) score \d+\.\d\d: ', line), line
        terms = re.search(r'near=\[\(1, ([\d.]+), (-?[\d.]+), ([\d.]+)\)\]', line)
        assert terms is not None, line
        metres, gain, unlike = map(float, terms.groups())
        assert 0.5 < metres < 1.0 and gain == -1.0
        alike = AppearanceRatio(AutoDetectionConfig().clutter_distance, 0.12).alike_distance()
        assert (unlike <= alike) == (who == 'same'), line
        assert ('support=[(1, ' in line) == (who == 'same'), line
        assert ('unalike=[(1, ' in line) == (who == 'other'), line


def test_no_birth_for_a_detection_whose_foreground_the_tracks_explain(monkeypatch):
    """The birth's ratio of the association is -inf when the detection, as one more track,
    would have less foreground of its own (exclusive support, ``release.spare_tracks``)
    than the existence's neutral coverage f_s: in the scene of :func:`_move_or_birth` the
    stranger in yellow 0.75 m from track 1 stands mostly on foreground of her own and is
    born; with her exclusive support just below f_s (the fringes of tracked people that
    meet on a phantom of the two-view hull) the same detection is dropped as explained
    by the tracks, and no track is added."""
    from mbtrack_ros.core.detection.manager import AutoDetection
    from mbtrack_ros.core.detection.release import ReleaseConfig

    f_s = ReleaseConfig().min_coverage
    decided = []
    decide = AutoDetection._decide
    monkeypatch.setattr(AutoDetection, '_decide',
                        lambda self, info: (decided.append(info), decide(self, info)))
    tracker, actions, _ = _move_or_birth(monkeypatch, 'other', -1.0)
    born = [d for d in decided if d['action'] == 'birth' and 'near' in d]
    assert born and all(d['own'] >= f_s for d in born), decided
    assert 'drop (explained by the tracks)' not in actions

    real = AutoDetection._exclusive_support

    def covered(self, *args):
        return real(self, *args)[0], f_s - 0.01

    monkeypatch.setattr(AutoDetection, '_exclusive_support', covered)
    tracker, actions, _ = _move_or_birth(monkeypatch, 'other', -1.0)
    assert 'birth' not in actions and 'drop (explained by the tracks)' in actions, actions
    assert tracker.track_ids == [1]


@pytest.mark.parametrize('gate, who, gain, moved', [
    (None, 'other', -1.0, False), (1.0, 'other', -1.0, True), (None, 'same', -1.0, True),
    (None, 'other', 1.0, True)])
def test_a_doubtful_move_needs_the_detection_to_look_like_the_track(
        monkeypatch, gate, who, gain, moved):
    """The scene of :func:`_move_or_birth` with the gain in the doubtful band (-1: the
    track's model explains the detection a little worse than its own estimate). With
    the appearance ratio at its prior (zero at the default ``clutter_distance``) a person
    dressed differently is born as a new track and track 1 stays, while the blue person
    herself still takes track 1 (her model matches); with the prior's zero at 1 the gain
    alone decides and track 1 is moved onto the stranger. A positive gain (+1) is not
    doubtful: the stranger takes track 1 whatever the gate."""
    gate = AutoDetectionConfig().clutter_distance if gate is None else gate
    _appearance_zero(monkeypatch, gate)
    tracker, actions, unalike = _move_or_birth(monkeypatch, who, gain)
    assert ('move 1' in actions) == moved, actions
    assert ('birth' in actions) == (not moved), actions
    assert bool(unalike) == (gate < 1.0 and who == 'other' and gain <= 0), unalike
    # the person there is followed by track 1 when it was moved, by a new track 2 if not
    mean = tracker.filter._particles[1 if moved else 2].mean(axis=0)
    if who == 'same' or not moved:      # (blue's model drifts off the stranger)
        assert np.hypot(mean[0] - 2.75, mean[1] - 2.5) < 0.3, mean
    for bad in (0.0, -0.1, float('nan')):
        with pytest.raises(DetectionError):
            AutoDetectionConfig(clutter_distance=bad)


@pytest.mark.parametrize('who, gain, moved', [
    ('same', -2.0, True), ('other', -2.0, False), ('same', -9.0, False)])
def test_a_look_alike_track_is_moved_by_a_negative_gain_its_looks_make_up(
        monkeypatch, who, gain, moved):
    """The scene of :func:`_move_or_birth` with a negative gain: the blue person takes
    track 1 back when the appearance ratio of her model and the track's
    (:class:`AppearanceRatio`'s prior, at most 8.7 nats) makes up the gain; a
    stranger in yellow is born beside it, and so is she at a gain further down."""
    tracker, actions, _ = _move_or_birth(monkeypatch, who, gain)
    assert ('move 1' in actions) == moved, actions
    assert ('birth' in actions) == (not moved), actions
    mean = tracker.filter._particles[1 if moved else 2].mean(axis=0)
    assert np.hypot(mean[0] - 2.75, mean[1] - 2.5) < 0.3, mean


@pytest.mark.parametrize('gain, actions_wanted', [
    (6.0, ['move 1', 'move 1 (again)', 'drop (track 1 placed recently)']),
    (-1.0, ['move 1', 'drop (track 1 placed recently)'])])
def test_a_track_placed_moments_ago_is_moved_again_by_a_positive_gain_once(
        monkeypatch, gain, actions_wanted):
    """Track 1 follows a person in blue at (2, 2.5); she stands at (2.75, 2.5) from frame
    40, back at (2, 2.5) from frame 50 and at (2.75, 2.5) again from frame 60, the gain of
    track 1's model forced to ``gain``. Her first detection moves track 1; the next comes
    within ``relocate_interval`` of that move and is dropped, unless the gain is positive
    (track 1's model explains her better than its own place): then it is moved again, once -
    the third detection, within the interval of a move made that way, is dropped. (The
    actions are what is asserted. With a negative gain nothing moves track 1 back to her:
    its particles, 0.75 m from her and on empty floor, find her again only by their random
    walk, and when is chance; that run ends as she moves on at frame 60.)"""
    from mbtrack_ros.core.detection.manager import AutoDetection

    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4, reach_radius=0.0)
    _no_hidden_moves(monkeypatch)
    here, there = person(2.0, 2.5, theta=0.0), person(2.75, 2.5, theta=0.0)
    actions = []
    for k in range(70 if gain > 0 else 60):
        if k == 40:
            assert tracker.track_ids == [1]
            monkeypatch.setattr(AutoDetection, '_explains', lambda self, *a: gain)
        who = here if k < 40 or 50 <= k < 60 else there
        tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, [who], rng))
        actions += [d['action'] for d in tracker.detection.decisions if k >= 40]
    # each action once, in this order (a person detected again on the next frames
    # gives the same action again: repeats dropped; a weak detection of her beside the
    # track needs a positive gain, which -1 is not, and is dropped)
    actions = [a for a in actions if a != 'drop (weak beside a track)']
    seen = [a for i, a in enumerate(actions) if a not in actions[:i]]
    assert seen == actions_wanted, actions
    assert tracker.track_ids == [1]


def test_of_two_tracks_a_detection_could_move_the_one_that_looks_like_it_is_moved(
        monkeypatch):
    """Track 1 follows a person in blue, track 2 one in yellow; from frame 40 both are gone
    and the blue person stands 0.75 m from each track. Both tracks may be moved there
    (gains in the doubtful band, the appearance ratio's zero at 1), and track 2's gain is
    the higher
    one (-1 against -2; each gain compares the detection with that track's own place).
    The track whose model is nearer the detection's in appearance is moved: track 1."""
    from mbtrack_ros.core.detection.manager import AutoDetection

    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4, reach_radius=0.0)
    _appearance_zero(monkeypatch, 1.0)
    _no_hidden_moves(monkeypatch)
    blue, yellow = person(2.0, 2.5, theta=0.0), person(3.5, 2.5, theta=0.0, colours=YELLOW)
    there = person(2.75, 2.5, theta=0.0)
    actions, near = [], []
    for k in range(52):
        if k == 40:
            assert tracker.track_ids == [1, 2]
            monkeypatch.setattr(AutoDetection, '_explains',
                                lambda self, ref, track, *a: -2.0 if track[0] < 2.75 else -1.0)
        tracker.step(int(round(k * 1e9 / FPS)),
                     paint(calib, bgs, [blue, yellow] if k < 40 else [there], rng))
        if k >= 40:
            actions += [d['action'] for d in tracker.detection.decisions]
            near += [d['near'] for d in tracker.detection.decisions if 'near' in d]
    assert any(len(n) == 2 for n in near), near         # both tracks were compared
    assert 'move 1' in actions and 'move 2' not in actions, actions


@pytest.mark.parametrize('who, both, born', [('same', False, False), ('same', True, True),
                                             ('other', True, True)])
def test_no_birth_beside_a_young_track_that_looks_like_the_detection(monkeypatch, who, both,
                                                                      born):
    """Track 1 follows a person in blue; from frame 40 it counts as placed moments ago
    (``relocate_interval``) and somebody stands 0.75 m from it, its gain there too low to
    move it. When she went there (not ``both``), the look-alike ('same': blue) is taken
    for track 1's own person, whom a young track lags: her detection is dropped. When
    track 1's person is still where it is (``both``), the track keeps its exclusive
    support and the look-alike is a second person: born, as is somebody dressed in
    yellow ('other')."""
    from mbtrack_ros.core.detection.manager import AutoDetection

    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4, reach_radius=0.0)
    _no_hidden_moves(monkeypatch)
    here = person(2.0, 2.5, theta=0.0)
    there = person(2.75, 2.5, theta=0.0, **({} if who == 'same' else {'colours': YELLOW}))
    placed = AutoDetection._placed_recently
    actions, decided = [], []
    for k in range(52):
        if k == 40:
            assert tracker.track_ids == [1]
            monkeypatch.setattr(AutoDetection, '_explains', lambda self, *a: -10.0)
            monkeypatch.setattr(AutoDetection, '_placed_recently', lambda self, tid, stamp:
                                tid == 1 or placed(self, tid, stamp))
        tracker.step(int(round(k * 1e9 / FPS)),
                     paint(calib, bgs, ([here] if k < 40 or both else [])
                           + ([there] if k >= 40 else []), rng))
        if k >= 40:
            actions += [d['action'] for d in tracker.detection.decisions]
            decided += tracker.detection.decisions
    assert ('birth' in actions) == born, actions
    assert ('drop (young look-alike 1)' in actions) == (not born), actions
    if not born:    # the terms: track 1 compared, its gain (-10) too low to move it
        drop = next(d for d in decided if d['action'] == 'drop (young look-alike 1)')
        assert [n[0] for n in drop['near']] == [1] and drop['near'][0][2] == -10.0, drop
    assert len(tracker.track_ids) == (2 if born else 1), tracker.track_ids


def test_the_appearance_ratio_learns_from_two_tracks_side_by_side(monkeypatch):
    """A person in blue and one in yellow stand 1 m apart (within each other's
    ``reuse_radius``): once their tracks are confident, each is sampled about once a second
    (``CALIBRATION_INTERVAL``): the model acquired again at a track's estimate is nearer its
    own model than the neighbour's, so the learnt ratio (:class:`AppearanceRatio`) says
    "same" for a track's own model and "different" for the neighbour's. Alone, a track
    gives no sample (nobody within its gate to be confused with)."""
    from mbtrack_ros.core.appearance import model_distance
    from mbtrack_ros.core.detection.manager import CALIBRATION_INTERVAL

    rng = np.random.default_rng(5)
    calib, bgs, tracker = _painted_room_tracker(4, reach_radius=0.0)
    blue, yellow = person(2.0, 2.5, theta=0.0), person(3.0, 2.5, theta=0.0, colours=YELLOW)
    frames = 90
    for k in range(frames):
        tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, [blue, yellow], rng))
    ratio = tracker.detection.likeness
    same, different = ratio.counts
    # both tracks confident after the relocate interval: about a sample a second each
    most = 2 * (frames / FPS) / CALIBRATION_INTERVAL
    assert 2 <= same <= most and different == same, ratio.describe()
    m_same, m_diff, _ = ratio.parameters()
    assert m_same < 0.7 * m_diff, ratio.describe()
    models = [tracker.models[t] for t in tracker.track_ids]
    assert len(models) == 2
    assert ratio.llr(0.5 * model_distance(*models)) > 0 > ratio.llr(model_distance(*models))

    alone = _painted_room_tracker(4, reach_radius=0.0)[2]
    for k in range(60):
        alone.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, [blue], rng))
    assert alone.track_ids == [1] and alone.detection.likeness.counts.tolist() == [0, 0]


@pytest.mark.parametrize('ghost_edge_ratio', [1.5, 0.0])
def test_a_person_who_keeps_still_while_untracked_is_found_again(ghost_edge_ratio):
    """She walks in and stops; her track is lost (removed) while she keeps perfectly still.
    No pixel of her moves, so the motion that proves a new person is no ghost is missing;
    her outline is in the frame, not in the background model (the border test of ghost
    detection read the other way), which proves her there: a track is on her again within
    a second. With the border test off (``ghost_edge_ratio`` 0) nothing proves a still
    person, and she stays untracked."""
    from dataclasses import replace

    calib, bgs, tracker = _painted_room_tracker(3)
    cfg = tracker.detection.config       # the detection's border test (the model's own
    tracker.detection.config = replace(  # ghost removal is left as it is)
        cfg, background=replace(cfg.background, ghost_edge_ratio=ghost_edge_ratio))
    rng = np.random.default_rng(11)
    stop = (2.6, 2.5)
    k = 0
    for k in range(40):                          # in at frame 3, still from frame 16
        x = min(1.95 + 0.05 * k, stop[0])
        who = [person(x, stop[1], theta=0.0)] if k >= 3 else []
        tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, who, rng))
    assert len(tracker.track_ids) == 1           # tracked while she walked
    tracker.remove_track(tracker.track_ids[0])   # lost while she keeps still
    found = None
    for k in range(40, 40 + FPS):
        result = tracker.step(int(round(k * 1e9 / FPS)),
                              paint(calib, bgs, [person(*stop, theta=0.0)], rng))
        near = [t for t in result.tracks if np.hypot(*(t.mean[:2] - stop)) < 0.3]
        if near and found is None:
            found = k
    if ghost_edge_ratio > 0:
        assert found is not None and found - 40 <= FPS - 3
    else:
        assert found is None
