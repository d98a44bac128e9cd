"""Body shape model: projection, s(o), sitting pose and the span rasteriser."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mbtrack_ros.core.camera import Camera, look_at
from mbtrack_ros.core.shape import (HEAD, LEGS, TORSO, BodyShape, ShapeError, rasterize,
                                    render_labels, silhouette_outline, width_scale)
from mbtrack_ros.core.state import SIT, THETA, X, Y


def _camera(eye=(0.0, -4.0, 1.4), target=(0.0, 0.0, 0.9), size=(160, 120),
            focal=120.0, dist=(0.0,) * 5) -> Camera:
    w, h = size
    R, t = look_at(eye, target)
    K = [[focal, 0, (w - 1) / 2], [0, focal, (h - 1) / 2], [0, 0, 1]]
    return Camera('cam', w, h, K, np.asarray(dist), R, t)


def _state(x=0.0, y=0.0, theta=0.0, sit=0.0) -> np.ndarray:
    s = np.zeros(6)
    s[[X, Y, THETA, SIT]] = (x, y, theta, sit)
    return s


def _facing(cam: Camera, x=0.0, y=0.0) -> float:
    return float(cam.viewing_angle(np.array([x, y])))


def test_standing_silhouette_covers_foot_and_head():
    cam = _camera()
    shape = BodyShape(height=1.8, width=0.5)
    lab = render_labels(cam, _state(0.3, 0.2), shape)
    foot = cam.project(np.array([0.3, 0.2, 0.05]))
    head = cam.project(np.array([0.3, 0.2, 1.75]))
    torso = cam.project(np.array([0.3, 0.2, 1.2]))
    assert lab[int(round(foot[1])), int(round(foot[0]))] == LEGS
    assert lab[int(round(head[1])), int(round(head[0]))] == HEAD
    assert lab[int(round(torso[1])), int(round(torso[0]))] == TORSO
    ys, _ = np.nonzero(lab)
    # vertical extent spans the projected feet .. head top (within a pixel)
    top = cam.project(np.array([0.3, 0.2, 1.8]))[1]
    bottom = cam.project(np.array([0.3, 0.2, 0.0]))[1]
    assert abs(ys.min() - top) <= 1.0 and abs(ys.max() - bottom) <= 1.0
    # parts are stacked: head above torso above legs
    mean_row = [np.nonzero(lab == q)[0].mean() for q in (HEAD, TORSO, LEGS)]
    assert mean_row[0] < mean_row[1] < mean_row[2]


def test_width_scale_narrows_profile_at_90_degrees():
    assert width_scale(np.array([0.0, np.pi / 2, np.pi]))[1] == pytest.approx(0.7)
    cam = _camera(size=(320, 240), focal=260.0)
    facing = _facing(cam)
    states = np.stack([_state(theta=facing), _state(theta=facing + np.pi / 2)])
    left, right, _, valid, _ = silhouette_outline(cam, states, BodyShape())
    assert valid.all()
    w = np.linalg.norm(right - left, axis=2)                 # (2, P) outline widths
    np.testing.assert_allclose(w[1], 0.7 * w[0], rtol=1e-9)
    # and in the raster: shoulder row is ~0.7 as wide
    sil = rasterize(cam, states, BodyShape())
    assert sil.area[1] == pytest.approx(0.7 * sil.area[0], rel=0.06)


def test_sitting_silhouette_is_shorter_and_has_no_legs():
    cam = _camera()
    shape = BodyShape(height=1.75)
    sil = rasterize(cam, np.stack([_state(), _state(sit=1.0)]), shape)
    h_stand = sil.bbox[0, 3] - sil.bbox[0, 1]
    h_sit = sil.bbox[1, 3] - sil.bbox[1, 1]
    assert h_sit < 0.7 * h_stand
    assert sil.part_area[1, LEGS - 1] == 0 and sil.part_area[0, LEGS - 1] > 0
    assert sil.part_area[1, TORSO - 1] > 0 and sil.part_area[1, HEAD - 1] > 0
    # the seated head top is at chair height + upper body height
    top = cam.project(np.array([0.0, 0.0, 0.45 + (1 - 0.47) * 1.75]))[1]
    assert abs(sil.bbox[1, 1] - top) <= 1.0


def test_raster_matches_fillpoly_and_parts_are_disjoint():
    rng = np.random.default_rng(0)
    cam = _camera(size=(320, 240), focal=400.0, dist=(-0.1, 0.02, 0, 0, 0))
    n = 12
    states = np.zeros((n, 6))
    states[:, X] = rng.uniform(-1.0, 1.0, n)
    states[:, Y] = rng.uniform(-1.0, 1.5, n)
    states[:, THETA] = rng.uniform(-np.pi, np.pi, n)
    states[::3, SIT] = 1.0
    shape = BodyShape(height=1.7, width=0.55)
    left, right, seg_part, valid, _ = silhouette_outline(cam, states, shape)
    sil = rasterize(cam, states, shape)
    for i in range(n):
        ref = np.zeros((cam.height, cam.width), np.uint8)
        for j in range(seg_part.shape[1]):
            if seg_part[i, j] == 0:
                continue
            quad = np.array([left[i, j], right[i, j], right[i, j + 1], left[i, j + 1]])
            cv2.fillPoly(ref, [np.round(quad * 16).astype(np.int32)], 1, shift=4)
        cover = np.zeros((cam.height, cam.width), np.int32)
        sl = sil.spans(i)
        for r, a, b in zip(sil.row[sl], sil.x0[sl], sil.x1[sl]):
            cover[r, a:b] += 1
        assert cover.max() == 1                              # no pixel claimed twice
        mine = cover > 0
        assert mine.sum() == sil.area[i]
        # cv2.fillPoly also fills pixels whose centres lie on the boundary: a little larger
        assert 0 <= ref.sum() - mine.sum() <= 0.08 * ref.sum()
        assert (mine & (ref == 0)).sum() <= 0.01 * mine.sum()
        exact = sum(cv2.contourArea(np.array(
            [left[i, j], right[i, j], right[i, j + 1], left[i, j + 1]], np.float32))
            for j in range(seg_part.shape[1]) if seg_part[i, j])
        if sil.full_area[i] == sil.area[i]:                  # not clipped: analytic area
            assert abs(mine.sum() - exact) <= 0.015 * exact
        iou = (mine & (ref > 0)).sum() / (mine | (ref > 0)).sum()
        assert iou > 0.9
        assert sil.part_area[i].sum() == sil.area[i]
        ys, xs = np.nonzero(mine)
        np.testing.assert_array_equal(sil.bbox[i], [xs.min(), ys.min(), xs.max() + 1,
                                                    ys.max() + 1])


def test_batch_equals_single_rasterisation_and_sizes_per_particle():
    rng = np.random.default_rng(1)
    cam = _camera()
    n = 6
    states = np.zeros((n, 6))
    states[:, X] = rng.uniform(-1.0, 1.0, n)
    states[:, THETA] = rng.uniform(-np.pi, np.pi, n)
    heights = rng.uniform(1.5, 1.9, n)
    widths = rng.uniform(0.4, 0.6, n)
    batch = rasterize(cam, states, BodyShape(), heights=heights, widths=widths)
    listed = rasterize(cam, states, [BodyShape(height=h, width=w)
                                     for h, w in zip(heights, widths)])
    np.testing.assert_array_equal(batch.x0, listed.x0)
    for i in range(n):
        one = rasterize(cam, states[i], BodyShape(height=heights[i], width=widths[i]))
        np.testing.assert_array_equal(batch.mask(i), one.mask(0))
        assert batch.distance[i] == pytest.approx(one.distance[0])
    # taller people have larger silhouettes at the same place
    two = rasterize(cam, np.stack([states[0]] * 2), BodyShape(), heights=[1.5, 1.9])
    assert two.area[1] > two.area[0]


def test_clipping_behind_camera_and_outside():
    cam = _camera()
    states = np.stack([_state(0.0, 0.0), _state(0.0, -6.0), _state(40.0, 0.0),
                       _state(1.2, -2.0)])
    sil = rasterize(cam, states, BodyShape())
    assert sil.area[0] > 0
    assert sil.area[1] == 0 and np.isinf(sil.distance[1])     # behind the camera
    assert sil.area[2] == 0 and sil.full_area[2] > 0          # outside the image
    assert 0 < sil.area[3] < sil.full_area[3]                  # partly outside
    assert sil.full_area[0] == sil.area[0]
    assert np.all((sil.row >= 0) & (sil.row < cam.height))
    assert np.all((sil.x0 >= 0) & (sil.x1 <= cam.width) & (sil.x0 < sil.x1))
    np.testing.assert_array_equal(np.diff(sil.offsets) > 0, sil.area > 0)
    # camera distance of the body centre orders particles front to back
    near = rasterize(cam, np.stack([_state(0, -1), _state(0, 1)]), BodyShape())
    assert near.distance[0] < near.distance[1]


def test_row_step_and_errors():
    cam = _camera()
    full = rasterize(cam, _state(), BodyShape())
    half = rasterize(cam, _state(), BodyShape(), row_step=3)
    assert np.all(half.row % 3 == 0)
    assert half.area[0] == pytest.approx(full.area[0] / 3, rel=0.1)
    with pytest.raises(ShapeError):
        BodyShape(height=-1.0)
    with pytest.raises(ShapeError):
        rasterize(cam, np.zeros((3, 4)), BodyShape())
    with pytest.raises(ShapeError):
        rasterize(cam, np.zeros((2, 6)), [BodyShape()])
    with pytest.raises(ShapeError):
        rasterize(cam, _state(), BodyShape(), row_step=0)


def test_per_particle_sizes_are_checked_and_broadcast():
    """Heights/widths given per particle ((n,) arrays, a (1,) array, a scalar or the shapes'
    sizes) give the same silhouettes; zero, negative, NaN or infinite sizes and arrays of
    the wrong length are refused."""
    cam = _camera()
    states = np.repeat(_state().reshape(1, -1), 3, axis=0)
    states[:, 0] += [0.0, 0.4, 0.8]
    ref = rasterize(cam, states, [BodyShape(1.6, 0.45)] * 3)
    for h, w in ((np.full(3, 1.6), np.full(3, 0.45)), (np.array([1.6]), 0.45),
                 (1.6, [0.45, 0.45, 0.45])):
        got = rasterize(cam, states, BodyShape(), heights=h, widths=w)
        for name in ('row', 'x0', 'x1', 'part', 'offsets', 'area'):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    for bad in (np.array([1.6, 0.0, 1.6]), np.array([1.6, -1.0, 1.6]),
                np.array([1.6, np.nan, 1.6]), np.array([np.inf, 1.6, 1.6]), np.full(2, 1.6)):
        with pytest.raises((ShapeError, ValueError)):
            rasterize(cam, states, BodyShape(), heights=bad)
        with pytest.raises((ShapeError, ValueError)):
            rasterize(cam, states, BodyShape(), widths=bad)


def test_fused_outline_matches_projection_then_outline(rng):
    """silhouette_outline's one-pass kernel against the straightforward composition:
    Camera.project of the axis ends, then the outline of each particle with width_scale of
    the relative orientation, and Camera.distance of the body centre: segment parts and
    validity exact, coordinates and distances to the last bit or two (on CPUs with AVX-512
    NumPy's arctan2, used for the viewing angle, is a SIMD routine that differs from the C
    library's in the last bit for ~7 % of inputs)."""
    from mbtrack_ros.core import _kernels
    R, t = look_at((0.3, -3.0, 2.5), (0.5, 1.0, 0.8))
    cams = [_camera(), Camera('d', 160, 120, [[110, 0, 79.3], [0, 104, 60.6], [0, 0, 1]],
                              [-0.21, 0.04, 0.001, -0.0007, 0.012], R, t)]
    n = 4000
    states = np.zeros((n, 6))
    states[:, :2] = rng.uniform(-5, 5, (n, 2))          # some behind / beside the cameras
    states[:, THETA] = rng.uniform(-4, 4, n)
    states[:, SIT] = rng.random(n) < 0.3
    heights = rng.uniform(1.5, 1.9, n)
    widths = rng.uniform(0.4, 0.6, n)
    shape = BodyShape()
    for cam in cams:
        got = silhouette_outline(cam, states, shape, heights=heights, widths=widths)
        sitting = states[:, SIT] >= 0.5
        zb = np.where(sitting, shape.chair_height, 0.0)
        zt = np.where(sitting, shape.chair_height + (1.0 - shape.hip_fraction) * heights,
                      heights)
        ends = np.stack([np.stack([states[:, X], states[:, Y], zb], 1),
                         np.stack([states[:, X], states[:, Y], zt], 1)], 1)
        scale = width_scale(states[:, THETA] - cam.viewing_angle(states[:, :2]))
        end_px, depth = cam.project(ends), cam.depth(ends)
        npts = shape.fractions.size
        left, right = np.zeros((n, npts, 2)), np.zeros((n, npts, 2))
        seg_part = np.empty((n, npts - 1), np.int8)
        valid = np.array([_kernels._outline_one(
            i, *end_px[i, 0], *end_px[i, 1], *depth[i], bool(sitting[i]), shape.fractions,
            shape.half_widths, shape.segment_parts, shape.hip_fraction, widths[i], scale[i],
            cam.K[0, 0], cam.K[1, 1], left, right, seg_part) for i in range(n)])
        centre = np.stack([states[:, X], states[:, Y], 0.5 * (zb + zt)], axis=1)
        ref = (left, right, seg_part, valid, np.where(valid, cam.distance(centre), np.inf))
        assert 0 < got[3].sum() < n
        for a, b in zip(got, ref):
            if np.issubdtype(np.asarray(b).dtype, np.floating):
                np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9)
            else:
                assert np.array_equal(a, b)


def _raster_reference(left, right, seg_part, valid, width, height):
    """Straightforward scan conversion (Python loops): per quad and row, the crossings of
    the edges ``y_top <= y < y_bottom`` parametrised from their sorted end points, pixels
    ``ceil(xl) <= c < ceil(xr)`` clipped to the image; spans, areas and span counts."""
    spans, area, count = [], [], []
    for i in range(left.shape[0]):
        mine = []
        for j in range(left.shape[1] - 1):
            if not valid[i] or seg_part[i, j] == 0:
                continue
            quad = [left[i, j], right[i, j], right[i, j + 1], left[i, j + 1]]
            edges = []
            for a, b in zip(quad, quad[1:] + quad[:1]):
                if a[1] > b[1] or (a[1] == b[1] and a[0] > b[0]):
                    a, b = b, a
                edges.append((a[1], b[1], a[0], (b[0] - a[0]) / (b[1] - a[1])
                              if b[1] > a[1] else 0.0))
            for r in range(int(np.ceil(min(e[0] for e in edges))),
                           int(np.ceil(max(e[1] for e in edges)))):
                xs = [e[2] + (r - e[0]) * e[3] for e in edges if e[0] <= r < e[1]]
                if not xs or not 0 <= r < height:
                    continue
                c0 = max(int(np.ceil(min(xs))), 0)
                c1 = min(int(np.ceil(max(xs))), width)
                if c1 > c0:
                    mine.append((r, c0, c1, seg_part[i, j]))
        spans += mine
        area.append(sum(c1 - c0 for _, c0, c1, _ in mine))
        count.append(len(mine))
    return np.array(spans, np.int64).reshape(-1, 4), np.array(area), np.array(count)


def test_rasterize_quads_matches_straightforward_scan(rng):
    from mbtrack_ros.core import _kernels
    cam = _camera()
    n = 150
    states = np.zeros((n, 6))
    states[:, :2] = rng.uniform(-3, 3, (n, 2))
    states[:, THETA] = rng.uniform(-4, 4, n)
    states[:, SIT] = rng.random(n) < 0.3
    left, right, seg_part, valid, _ = silhouette_outline(cam, states, BodyShape())
    left[:5] = np.round(left[:5])                 # vertices on pixel centres: the edge rules
    right[:5] = np.round(right[:5])
    row, x0, x1, part, offsets, area, *_ = _kernels.rasterize_quads(
        left, right, seg_part, valid, cam.width, cam.height, 1, 10 * cam.height)
    spans, ref_area, ref_count = _raster_reference(left, right, seg_part, valid, cam.width,
                                                   cam.height)
    got = np.column_stack([row, x0, x1, part]).astype(np.int64)
    assert spans.shape[0] > 100 and np.array_equal(got, spans)
    np.testing.assert_array_equal(area, ref_area)
    np.testing.assert_array_equal(np.diff(offsets), ref_count)


@pytest.mark.parametrize('size', [(370, 208), (256, 300)])
def test_silhouettes_keep_their_size_in_an_image_resized_to_another_aspect_ratio(size):
    """A camera whose image is resized to another aspect ratio has non-square pixels
    (fx != fy): a body's silhouette covers the same part of the picture, so its area
    scales with both factors (sx sy) and its widest span with sx, whatever the body's
    orientation (the outline's offsets use the focal length along their direction)."""
    R, t = look_at((0.1, 0.1, 2.6), (3.0, 2.5, 0.8))
    cam = Camera('c', 320, 240, [[175, 0, 159.5], [0, 175, 119.5], [0, 0, 1]],
                 [0.0] * 5, R, t)
    wide = cam.scaled(*size)
    sx, sy = size[0] / 320, size[1] / 240
    states = np.zeros((6, 6))
    states[:, :2] = [[3.0, 2.5], [2.0, 3.5], [4.0, 1.5], [1.5, 1.5], [2.5, 4.0], [4.5, 3.5]]
    states[:, THETA] = np.linspace(0, np.pi, 6)
    a, b = rasterize(cam, states, BodyShape()), rasterize(wide, states, BodyShape())
    assert np.all(a.full_area > 400)
    np.testing.assert_allclose(b.full_area / a.full_area, sx * sy, rtol=0.04)
    for i in range(len(states)):
        span_a = (a.mask(i) > 0).sum(axis=1).max()
        span_b = (b.mask(i) > 0).sum(axis=1).max()
        assert span_b / span_a == pytest.approx(sx, rel=0.08)
