"""Appearance model: quantisation, part histograms, Bhattacharyya, key views."""
from __future__ import annotations

import numpy as np
import pytest

from mbtrack_ros.core.appearance import (AppearanceError, PersonModel,
                                         bhattacharyya_distance_sq, model_distance,
                                         model_from_images,
                                         part_histograms, quantize, relative_angle,
                                         single_target_loglik, view_weights)
from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.core.shape import BodyShape, rasterize, render_labels
from mbtrack_ros.core.state import THETA, X, Y


def _camera(name='cam', eye=(0.0, -4.0, 1.4), size=(120, 90), focal=90.0) -> Camera:
    w, h = size
    R, t = look_at(eye, (0.0, 0.0, 0.9))
    K = [[focal, 0, (w - 1) / 2], [0, focal, (h - 1) / 2], [0, 0, 1]]
    return Camera(name, w, h, K, np.zeros(5), R, t)


def _bin(rgb) -> int:
    r, g, b = rgb
    return (r // 32) * 64 + (g // 32) * 8 + b // 32


def test_quantize_bins():
    img = np.array([[[0, 0, 0], [255, 255, 255], [32, 64, 96], [31, 63, 95]]], np.uint8)
    bins = quantize(img)
    assert bins.dtype == np.int16
    np.testing.assert_array_equal(bins[0], [0, 511, 1 * 64 + 2 * 8 + 3, 0 * 64 + 1 * 8 + 2])
    with pytest.raises(AppearanceError):
        quantize(np.zeros((4, 4), np.uint8))
    with pytest.raises(AppearanceError):
        quantize(np.zeros((4, 4, 3), np.float32))


def test_uniform_patch_histogram_is_one_bin():
    cam = _camera()
    colour = (200, 40, 90)
    img = np.empty((cam.height, cam.width, 3), np.uint8)
    img[:] = colour
    sil = rasterize(cam, np.zeros(6), BodyShape())
    hist = part_histograms(quantize(img), sil, 0)
    assert hist.shape == (3, 512)
    for q in range(3):
        assert hist[q, _bin(colour)] == pytest.approx(1.0)
        assert hist[q].sum() == pytest.approx(1.0)
    raw = part_histograms(quantize(img), sil, 0, normalize=False)
    np.testing.assert_array_equal(raw.sum(axis=1), sil.part_area[0])
    # a weight map scales the mass and can zero out a part
    lab = sil.mask(0)
    wmap = np.where(lab == 3, 0.0, 0.5)
    half = part_histograms(quantize(img), sil, 0, wmap, normalize=False)
    np.testing.assert_allclose(half.sum(axis=1), [0.5 * sil.part_area[0, 0],
                                                  0.5 * sil.part_area[0, 1], 0.0])


def test_part_histograms_of_painted_parts_match_counts():
    rng = np.random.default_rng(0)
    cam = _camera()
    img = rng.integers(0, 256, (cam.height, cam.width, 3), dtype=np.uint8)
    bins = quantize(img)
    state = np.zeros(6)
    state[THETA] = 0.7
    sil = rasterize(cam, state, BodyShape())
    lab = render_labels(cam, state, BodyShape())
    hist = part_histograms(bins, sil, 0, normalize=False)
    for q in range(3):
        expect = np.bincount(bins[lab == q + 1], minlength=512)
        np.testing.assert_array_equal(hist[q], expect)


def test_bhattacharyya_hand_values():
    h = np.zeros(512)
    h[3] = 1.0
    k = np.zeros(512)
    k[7] = 1.0
    m = np.zeros(512)
    m[3] = m[7] = 0.5
    assert bhattacharyya_distance_sq(h, h) == pytest.approx(0.0)
    assert bhattacharyya_distance_sq(h, k) == pytest.approx(1.0)
    assert bhattacharyya_distance_sq(h, m) == pytest.approx(1.0 - np.sqrt(0.5))
    batch = bhattacharyya_distance_sq(np.stack([h, k]), m)
    np.testing.assert_allclose(batch, [1 - np.sqrt(0.5)] * 2)


def test_model_distance_hand_values():
    """Views averaged, then the Bhattacharyya distance per part, averaged over the parts
    both models have seen."""
    def one_bin(*bins):        # (V, 3, 512): view v has all of part p in bins[v][p]
        h = np.zeros((len(bins), 3, 512))
        for v, parts in enumerate(bins):
            for p, b in enumerate(parts):
                if b is not None:
                    h[v, p, b] = 1.0
        return PersonModel(1.75, 0.5, view_angles=np.linspace(0, np.pi, len(bins),
                                                               endpoint=False), histograms=h)

    a = one_bin((1, 2, 3), (1, 2, 5))         # legs: half bin 3, half bin 5 over the views
    assert model_distance(a, a) == pytest.approx(0.0)
    assert model_distance(a, one_bin((7, 8, 9))) == pytest.approx(1.0)
    # head and torso equal, legs 1 - sqrt(0.5) apart (squared): sqrt of it, / 3 parts
    b = one_bin((1, 2, 3))
    assert model_distance(a, b) == pytest.approx(np.sqrt(1 - np.sqrt(0.5)) / 3)
    # a part one model never saw is left out (the head here)
    c = one_bin((None, 2, 3), (None, 2, 5))
    assert model_distance(c, b) == pytest.approx(np.sqrt(1 - np.sqrt(0.5)) / 2)
    assert model_distance(one_bin((None, None, None)), a) == 1.0
    assert model_distance(a, b) == pytest.approx(model_distance(b, a))


def test_interpolation_hand_weights():
    rng = np.random.default_rng(1)
    hists = rng.random((3, 3, 512))
    model = PersonModel(1.7, 0.5, [0.0, np.pi / 2, np.pi], hists)
    norm = hists / hists.sum(axis=2, keepdims=True)
    out = model.interpolate(np.array([np.pi / 6, np.pi / 2, np.deg2rad(-170.0)]))
    # 30 deg: views at 0 (30 deg away) and 90 (60 deg away): weights 2/3, 1/3
    np.testing.assert_allclose(out[0], 2 / 3 * norm[0] + 1 / 3 * norm[1])
    np.testing.assert_allclose(out[1], norm[1])
    # -170 deg is 10 deg from the view at 180 and 100 deg from the view at 90 (wrap-around)
    w = 100 / 110
    np.testing.assert_allclose(out[2], w * norm[2] + (1 - w) * norm[1])
    np.testing.assert_allclose(out.sum(axis=2), 1.0)
    single = PersonModel(1.7, 0.5, [0.3], hists[:1])
    np.testing.assert_allclose(single.interpolate(np.array([2.0, -1.0])), norm[[0, 0]])


def test_missing_part_is_completed_from_nearest_view():
    rng = np.random.default_rng(2)
    hists = rng.random((3, 3, 512))
    hists[0, 2] = 0.0                                    # legs never seen in view 0
    model = PersonModel(1.7, 0.5, [0.0, np.deg2rad(80.0), np.deg2rad(200.0)], hists)
    norm = hists / np.maximum(hists.sum(axis=2, keepdims=True), 1e-300)
    done = model.completed_histograms()
    np.testing.assert_allclose(done[0, 2], norm[1, 2])   # 80 deg is nearer than 200 deg
    np.testing.assert_allclose(done[1:], norm[1:])
    np.testing.assert_array_equal(model.histograms[0, 2], 0.0)   # stored model unchanged
    out = model.interpolate(np.array([np.deg2rad(20.0)]))
    np.testing.assert_allclose(out.sum(axis=2), 1.0)
    np.testing.assert_allclose(out[0, 2], norm[1, 2])


def test_add_view_merges_close_views():
    h0 = np.zeros((3, 512))
    h0[:, 1] = 1.0
    h1 = np.zeros((3, 512))
    h1[:, 2] = 1.0
    model = PersonModel(1.7, 0.5)
    model.add_view(0.0, h0)
    model.add_view(np.deg2rad(10.0), h1)                 # merged: averaged
    assert model.view_angles.size == 1
    assert model.view_angles[0] == pytest.approx(np.deg2rad(5.0))
    np.testing.assert_allclose(model.histograms[0, :, 1:3], 0.5)
    model.add_view(np.deg2rad(90.0), h1)                 # new key view
    assert model.view_angles.size == 2
    with pytest.raises(AppearanceError):
        model.add_view(0.0, np.zeros((2, 512)))
    with pytest.raises(AppearanceError):
        PersonModel(1.7, 0.5).interpolate(np.zeros(1))


def _painted_frame(cams, state, shape, colours):
    images = {}
    for cam in cams:
        img = np.full((cam.height, cam.width, 3), 80, np.uint8)
        lab = render_labels(cam, state, shape)
        for q in range(3):
            img[lab == q + 1] = colours[q]
        images[cam.name] = img
    return images


def test_model_from_images_and_single_target_likelihood():
    cams = [_camera('a', (0.0, -4.0, 1.4)), _camera('b', (4.0, 0.0, 1.4))]
    calib = RoomCalibration({c.name: c for c in cams}, (-3, -3, 3, 3))
    colours = [(230, 190, 160), (200, 30, 30), (30, 30, 200)]
    state = np.zeros(6)
    state[THETA] = 0.0
    shape = BodyShape(height=1.75, width=0.5)
    images = _painted_frame(cams, state, shape, colours)
    model = model_from_images(images, calib, state, 1.75, 0.5)
    assert model.view_angles.size == 2
    expect = [float(np.arctan2(np.sin(state[THETA] - c.viewing_angle(np.zeros(2))),
                               np.cos(state[THETA] - c.viewing_angle(np.zeros(2)))))
              for c in cams]
    np.testing.assert_allclose(np.sort(model.view_angles), np.sort(expect), atol=1e-9)
    for v in range(2):
        for q in range(3):
            assert model.histograms[v, q, _bin(colours[q])] > 0.9
    # an occlusion mask hiding most of the person in camera b drops that view
    occ = {'b': np.ones((cams[1].height, cams[1].width), bool)}
    assert model_from_images(images, calib, state, 1.75, 0.5, occluded=occ).view_angles.size \
        == 1
    # the likelihood (003 Eq. 3) prefers the true position
    shifted = np.zeros((4, 6))
    shifted[:, X] = [0.0, 0.3, -0.3, 0.15]
    shifted[:, Y] = [0.0, 0.0, 0.0, 0.4]
    sil = rasterize(cams[0], shifted, shape)
    rel = shifted[:, THETA] - cams[0].viewing_angle(shifted[:, [X, Y]])
    ll = single_target_loglik(quantize(images['a']), sil, model.interpolate(rel))
    assert np.argmax(ll) == 0 and ll[0] > -0.5
    assert np.all(ll[1:] < ll[0] - 1.0)
    # out of view -> neutral 0
    far = np.zeros((1, 6))
    far[0, X] = 50.0
    sil_far = rasterize(cams[0], far, shape)
    assert single_target_loglik(quantize(images['a']), sil_far,
                                model.interpolate(np.zeros(1)))[0] == 0.0
    with pytest.raises(AppearanceError):
        model_from_images({'zz': images['a']}, calib, state, 1.75, 0.5)
    with pytest.raises(AppearanceError):
        model_from_images(images, calib, np.zeros(3), 1.75, 0.5)


def test_key_view_loglik_equals_interpolated_histograms():
    """Lazy key-view interpolation (key_view_stack + view_weights + key_view_loglik) gives
    the same 003 Eq. 3 values as PersonModel.interpolate + single_target_loglik, for two
    models with different numbers of key views (one with a part missing in a view)."""
    from mbtrack_ros.core.appearance import key_view_loglik, key_view_stack, view_weights
    rng = np.random.default_rng(5)
    cams = [_camera('a'), _camera('b', eye=(4.0, 0.0, 1.4))]
    image = rng.integers(0, 256, size=(cams[0].height, cams[0].width, 3), dtype=np.uint8)
    models = []
    for views in (3, 1):
        m = PersonModel(height=1.75, width=0.5)
        for v in range(views):
            h = rng.random((3, 512)) * (rng.random((3, 512)) < 0.2)
            if views == 3 and v == 1:
                h[2] = 0.0                           # legs not seen in this view
            m.add_view(2.0 * np.pi * v / views - 1.0, h, merge_angle=0.0)
        models.append(m)
    states = np.zeros((10, 6))
    states[:, X] = rng.uniform(-0.5, 0.5, 10)
    states[:, Y] = rng.uniform(-0.5, 0.5, 10)
    states[:, THETA] = rng.uniform(-np.pi, np.pi, 10)
    target = np.array([0, 1] * 5)
    va, vb, wa = view_weights(cams, states, target, models)
    key = key_view_stack(models)
    bins = quantize(image)
    for c, cam in enumerate(cams):
        sil = rasterize(cam, states, BodyShape())
        rel = states[:, THETA] - cam.viewing_angle(states[:, [X, Y]])
        hists = np.stack([models[t].interpolate(rel[i:i + 1])[0]
                          for i, t in enumerate(target)])
        plain = single_target_loglik(bins, sil, hists)
        lazy = key_view_loglik(bins, sil, key, target, va[c], vb[c], wa[c])
        assert np.any(plain < -0.1)
        np.testing.assert_allclose(lazy, plain, rtol=0, atol=1e-12)


def _quantize_numpy(image):
    q = image >> 5
    return (q[..., 0].astype(np.int16) * 64 + q[..., 1].astype(np.int16) * 8
            + q[..., 2].astype(np.int16))


def test_quantize_matches_numpy_version():
    img = np.random.default_rng(4).integers(0, 256, (37, 80, 3), dtype=np.uint8)
    for view in (img, img[:, ::3], img[::-1]):           # contiguous and strided
        got = quantize(view)
        assert got.dtype == np.int16 and got.shape == view.shape[:2]
        np.testing.assert_array_equal(got, _quantize_numpy(view))


def _interpolation_numpy(view_angles, rel):
    """The straightforward version: sort the wrapped distances to all key views."""
    wrap = lambda a: (a + np.pi) % (2.0 * np.pi) - np.pi   # noqa: E731
    if view_angles.size == 1:
        zero = np.zeros(rel.size, np.int64)
        return zero, zero, np.ones(rel.size)
    dist = np.abs(wrap(rel[:, None] - view_angles[None, :]))
    idx = np.argsort(dist, axis=1, kind='stable')[:, :2]
    da = np.take_along_axis(dist, idx[:, :1], axis=1)[:, 0]
    db = np.take_along_axis(dist, idx[:, 1:2], axis=1)[:, 0]
    total = da + db
    wa = np.where(total > 0, db / np.where(total > 0, total, 1.0), 1.0)
    return idx[:, 0], idx[:, 1], wa


def test_interpolation_weights_match_sorting_version():
    rng = np.random.default_rng(5)
    for n_views in (1, 2, 3, 5, 8):
        model = PersonModel(1.7, 0.5, rng.uniform(-np.pi, np.pi, n_views),
                            rng.random((n_views, 3, 512)))
        rel = rng.uniform(-7, 7, 500)
        rel[:20] = model.view_angles[rng.integers(0, n_views, 20)]     # on a key view
        got = model.interpolation_weights(rel)
        for a, b in zip(got, _interpolation_numpy(model.view_angles, rel)):
            np.testing.assert_array_equal(a, b)
    # ties go to the lower index, as a stable sort: 0 is equally far from +-pi/2
    model = PersonModel(1.7, 0.5, [np.pi / 2, 0.3, -np.pi / 2], np.ones((3, 3, 512)))
    va, vb, wa = model.interpolation_weights(np.array([0.0, np.pi]))
    np.testing.assert_array_equal(va, [1, 0])
    np.testing.assert_array_equal(vb, [0, 2])


def test_view_weights_match_per_model_version():
    rng = np.random.default_rng(6)
    cams = [_camera('a'), _camera('b', eye=(3.0, 2.0, 2.5))]
    models = [PersonModel(1.7, 0.5, rng.uniform(-np.pi, np.pi, v), rng.random((v, 3, 512)))
              for v in (1, 4, 2)]
    states = np.zeros((300, 6))
    states[:, :2] = rng.uniform(-2, 2, (300, 2))
    states[:, THETA] = rng.uniform(-np.pi, np.pi, 300)
    target = rng.integers(0, 3, 300)
    va, vb, wa = view_weights(cams, states, target, models)
    for c, cam in enumerate(cams):
        rel = relative_angle(states[:, THETA], cam.viewing_angle(states[:, [X, Y]]))
        for k, m in enumerate(models):
            sel = target == k
            ref = _interpolation_numpy(m.view_angles, rel[sel])
            for got, want in zip((va[c, sel], vb[c, sel], wa[c, sel]), ref):
                np.testing.assert_array_equal(got, want)


def test_completed_histograms_cache_follows_view_changes():
    rng = np.random.default_rng(7)
    hists = rng.random((3, 3, 512))
    hists[1, 2] = 0.0                                   # legs never seen in view 1
    model = PersonModel(1.7, 0.5, [0.0, 1.0, 2.5], hists)
    fresh = lambda m: m._complete()                     # noqa: E731 (uncached)
    first = model.completed_histograms()
    np.testing.assert_array_equal(first, fresh(model))
    np.testing.assert_array_equal(first[1, 2], model.histograms[0, 2])   # from the nearest
    first[:] = 0.0                                       # a returned copy: cache unharmed
    np.testing.assert_array_equal(model.completed_histograms(), fresh(model))
    model.view_angles[0] = -0.8                          # in place: view 2 is now nearer
    np.testing.assert_array_equal(model.completed_histograms()[1, 2],
                                  model.histograms[2, 2])
    model.histograms[2, 2, :] = 0.0                      # in place: donor lost its legs
    model.histograms[2, 2, 5] = 1.0
    np.testing.assert_array_equal(model.completed_histograms(), fresh(model))
    model.add_view(-2.0, rng.random((3, 512)))
    assert model.completed_histograms().shape == (4, 3, 512)
    np.testing.assert_array_equal(model.completed_histograms(), fresh(model))
