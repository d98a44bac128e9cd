"""HJS, separable and joint likelihoods against brute-force evaluations on tiny images."""
from __future__ import annotations

import itertools
import threading
import time

import cv2
import numpy as np
import pytest

from mbtrack_ros.core.appearance import (PersonModel, bhattacharyya_distance_sq, quantize,
                                         relative_angle)
from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.core.likelihood import LikelihoodConfig, LikelihoodError, MeasurementModel
from mbtrack_ros.core.shape import BodyShape, silhouette_outline
from mbtrack_ros.core.state import THETA, X, Y

D_OCC = 0.15


def _camera(name: str, eye, target=(0.0, 0.0, 0.9), size=(40, 30), focal=50.0) -> Camera:
    w, h = size
    R, t = look_at(eye, target)
    K = [[focal, 0, (w - 1) / 2], [0, focal, (h - 1) / 2], [0, 0, 1]]
    return Camera(name, w, h, K, np.zeros(5), R, t)


def _room(*cams: Camera) -> RoomCalibration:
    return RoomCalibration({c.name: c for c in cams}, (-3.0, -3.0, 3.0, 3.0))


def _random_image(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    # blocky colours so that histograms are neither flat nor single-bin
    small = rng.integers(0, 256, (h // 3 + 1, w // 3 + 1, 3), dtype=np.uint8)
    return np.repeat(np.repeat(small, 3, axis=0), 3, axis=1)[:h, :w].copy()


def _random_model(rng: np.random.Generator, height: float) -> PersonModel:
    hists = rng.random((2, 3, 512)) ** 4
    return PersonModel(height, 0.5, [0.0, np.pi / 2], hists)


def _random_particles(rng, centre, n):
    p = np.zeros((n, 6))
    p[:, X] = centre[0] + rng.uniform(-0.35, 0.35, n)
    p[:, Y] = centre[1] + rng.uniform(-0.35, 0.35, n)
    p[:, THETA] = rng.uniform(-np.pi, np.pi, n)
    return p


def _F(bins, labels, w, model_hist, d_occ=D_OCC):
    """000 Eq. 26 / 33 directly: w-weighted part histograms vs model, penalty d_occ."""
    area = float((labels > 0).sum())
    num = 0.0
    alpha_tot = 0.0
    for q in range(3):
        sel = labels == q + 1
        hist = np.bincount(bins[sel], weights=w[sel], minlength=512)
        alpha = hist.sum()
        if alpha > 0:
            num += alpha * float(bhattacharyya_distance_sq(hist / alpha, model_hist[q]))
        alpha_tot += alpha
    return (num + (area - alpha_tot) * d_occ) / area


def _brute_w_star(masks, dist, prior, target, p, exclude):
    """000 Eq. 32: prior-weighted average of the binary visibility mask of particle p
    over all joint configurations of the targets not in ``exclude`` (and not p's)."""
    k = target[p]
    others = [h for h in sorted(set(target.tolist())) if h != k and h not in exclude]
    lists = [np.flatnonzero(target == h) for h in others]
    w = np.zeros(masks[p].shape)
    for combo in itertools.product(*lists):
        pr = np.prod([prior[j] for j in combo]) if combo else 1.0
        vis = masks[p].copy()
        for j in combo:
            if dist[j] < dist[p]:
                vis &= ~masks[j]
        w += pr * vis
    return w


@pytest.mark.parametrize('n_targets,n_particles,seed,zeros', [
    (2, 4, 0, 0), (3, 3, 1, 0), (3, 5, 2, 0), (3, 5, 4, 3),
    (3, (2, 6, 3), 5, 2)])     # unequal particle counts per target
def test_hjs_incremental_equals_brute_force(n_targets, n_particles, seed, zeros):
    counts = n_particles if isinstance(n_particles, tuple) else (n_particles,) * n_targets
    rng = np.random.default_rng(seed)
    cam = _camera('cam', (0.0, -3.5, 1.2))
    mm = MeasurementModel(_room(cam), LikelihoodConfig(d_occ=D_OCC))
    image = _random_image(rng, cam.height, cam.width)
    mm.set_images({'cam': image})
    bins = quantize(image)
    models = [_random_model(rng, 1.6 + 0.1 * k) for k in range(n_targets)]
    particles = [_random_particles(rng, (0.3 * k - 0.3, 0.4 * k), counts[k])
                 for k in range(n_targets)]
    weights = [rng.random(counts[k]) + 0.05 for k in range(n_targets)]
    for j in range(zeros):                                   # particles with zero prior
        weights[j % n_targets][j // n_targets] = 0.0
    dbg = mm.hjs_debug('cam', particles, weights, models)
    sil = dbg.silhouettes
    labels = [sil.mask(p) for p in range(len(sil))]
    masks = [lab > 0 for lab in labels]
    assert all(m.sum() > 30 for m in masks)                 # all particles in view
    dist = sil.distance
    target, prior = dbg.target, dbg.prior
    np.testing.assert_allclose(np.bincount(target, prior), 1.0)
    overlaps = 0
    states = np.concatenate(particles)
    rel = relative_angle(states[:, THETA], cam.viewing_angle(states[:, :2]))
    model_hists = [models[target[p]].interpolate(rel[p:p + 1])[0] for p in range(len(sil))]
    for p in range(len(sil)):
        k = target[p]
        # (a) occlusion map w* (Eq. 32 by enumeration == Eq. 34 incremental)
        w = _brute_w_star(masks, dist, prior, target, p, exclude=())
        np.testing.assert_allclose(dbg.w_star[p], w, atol=1e-9, rtol=0)
        overlaps += int(np.any(w[masks[p]] < 1))
        # (b) foreground term, Eq. 33 evaluated at the brute-force w*
        assert dbg.fc[p] == pytest.approx(_F(bins, labels[p], w, model_hists[p]), abs=1e-9)
        # (c) background term, Eq. 36-38 directly
        bc = 0.0
        for j in range(len(sil)):
            if target[j] == k or not dist[j] < dist[p]:
                continue
            r = (masks[j] & masks[p]).sum() / masks[j].sum()        # Eq. 37
            if r == 0:
                continue
            w_hat = _brute_w_star(masks, dist, prior, target, j, exclude=(k,))
            bc += prior[j] * r * _F(bins, labels[j], w_hat, model_hists[j])
        assert dbg.bc[p] == pytest.approx(bc, abs=1e-9)
    assert overlaps >= 2                                     # the case really has occlusions
    assert np.any(dbg.bc > 0)


def test_hjs_loglik_combines_fc_bc_and_a_camera_says_nothing_of_what_it_does_not_see():
    """000 Eq. 19 from fc and bc. A particle the camera does not see gets the prior-weighted
    mean of its target's seen particles (0, the best score, would draw tracks out of the
    view); a target the camera sees less than ``min_inside_share`` of gets 0 on every
    particle (brute force per target)."""
    rng = np.random.default_rng(5)
    cam = _camera('cam', (0.0, -3.5, 1.2))
    mm = MeasurementModel(_room(cam), LikelihoodConfig(sigma=0.1, d_occ=D_OCC,
                                                       min_visible_pixels=1))
    mm.set_images({'cam': _random_image(rng, cam.height, cam.width)})
    models = [_random_model(rng, 1.7) for _ in range(3)]
    particles = [_random_particles(rng, (0.0, 0.0), 4), _random_particles(rng, (0.2, 0.5), 4),
                 _random_particles(rng, (-0.2, 0.3), 4)]
    particles[1][0, X] = 50.0                                # far outside the view
    particles[2][:3, X] = 50.0                               # mostly outside: says nothing
    weights = [np.ones(4), np.array([1.0, 2.0, 1.0, 1.0]), np.ones(4)]
    res = mm.hjs(particles, weights, models)
    dbg = mm.hjs_debug('cam', particles, weights, models)
    raw = -(dbg.fc + dbg.bc) / (2 * 0.1 ** 2)
    sil = dbg.silhouettes
    seen = sil.area > 0
    assert seen.tolist() == [True] * 4 + [False] + [True] * 3 + [False] * 3 + [True]
    expect = raw.copy()
    for k in range(3):
        sel = dbg.target == k
        share = np.sum(dbg.prior[sel] * np.where(seen[sel], sil.area[sel] / sil.full_area[sel],
                                                 0.0))
        mean = np.sum((dbg.prior * raw)[sel & seen]) / np.sum(dbg.prior[sel & seen])
        expect[sel & ~seen] = mean
        if (share < mm.config.min_inside_share
                or res.visible_fraction[k, 0] < mm.config.min_visible_share):
            expect[sel] = 0.0
    np.testing.assert_allclose(np.concatenate(res.loglik), expect, atol=1e-12)
    assert res.loglik[1][0] < 0.0 and res.loglik[1][0] < np.max(res.loglik[1][1:])
    assert np.all(res.loglik[2] == 0.0) and np.all(res.loglik[0] < 0.0)
    assert np.all(dbg.w_star[dbg.silhouettes.area == 0] == 0.0)
    assert res.visible_fraction.shape == (3, 1)
    assert np.all((res.visible_fraction >= 0) & (res.visible_fraction <= 1))
    # visible fraction: prior-weighted mean of sum(w*) / silhouette area (0 out of view)
    sil = dbg.silhouettes
    frac = np.where(sil.full_area > 0, dbg.visible / np.maximum(sil.full_area, 1), 0.0)
    for k in range(3):
        sel = dbg.target == k
        assert res.visible_fraction[k, 0] == pytest.approx(np.sum(dbg.prior[sel] * frac[sel]))
    assert res.visible_fraction.min() < 0.99                 # the overlap is seen
    # an empty particle set is allowed and yields an empty result
    empty = mm.hjs([particles[0], np.zeros((0, 6))], [weights[0], np.zeros(0)], models[:2])
    assert empty.loglik[1].shape == (0,)


def test_a_camera_in_which_a_target_is_hidden_says_nothing_about_it():
    """A target the camera hides behind a nearer one (prior-expected visible fraction
    below ``min_visible_share``) gets 0 on every particle from that camera: the occlusion
    penalty and the nearer target's background term would otherwise still rank its places
    The other targets' scores do not change, and with the threshold at 0 the hidden
    target gets the plain Eq. 19 scores of ``hjs_debug``."""
    rng = np.random.default_rng(11)
    cam = _camera('cam', (0.0, -3.5, 1.2))
    image = _random_image(rng, cam.height, cam.width)
    models = [_random_model(rng, 1.7) for _ in range(3)]

    def near(centre, n=5):
        p = np.zeros((n, 6))
        p[:, X] = centre[0] + rng.uniform(-0.03, 0.03, n)
        p[:, Y] = centre[1] + rng.uniform(-0.03, 0.03, n)
        p[:, THETA] = rng.uniform(-np.pi, np.pi, n)
        return p

    # target 0 in front, target 1 straight behind it, target 2 half behind it
    particles = [near((0.0, -0.5)), near((0.0, 1.5)), near((0.25, 1.5))]
    weights = [rng.random(5) + 0.1 for _ in range(3)]
    results = {}
    for share in (0.0, 0.1):
        mm = MeasurementModel(_room(cam), LikelihoodConfig(
            sigma=0.1, d_occ=D_OCC, min_visible_pixels=1, min_visible_share=share))
        mm.set_images({'cam': image})
        results[share] = (mm.hjs(particles, weights, models),
                          mm.hjs_debug('cam', particles, weights, models))
    quiet, _ = results[0.1]
    scored, dbg = results[0.0]
    visible = quiet.visible_fraction[:, 0]
    assert visible[1] < 0.1 <= visible[2] < 0.9 and visible[0] > 0.99   # the case is real
    np.testing.assert_array_equal(quiet.visible_fraction, scored.visible_fraction)
    raw = -(dbg.fc + dbg.bc) / (2 * 0.1 ** 2)
    for k in range(3):
        sel = dbg.target == k
        np.testing.assert_allclose(scored.loglik[k], raw[sel], atol=1e-12)
        if k == 1:
            assert np.all(quiet.loglik[k] == 0.0)
            assert np.all(scored.loglik[k] < 0.0) and np.ptp(scored.loglik[k]) > 0
        else:
            np.testing.assert_array_equal(quiet.loglik[k], scored.loglik[k])
            assert np.all(quiet.loglik[k] < 0.0)


def test_hjs_without_overlap_equals_separable():
    rng = np.random.default_rng(3)
    cam = _camera('cam', (0.0, -6.0, 1.3), size=(160, 40), focal=60.0)
    mm = MeasurementModel(_room(cam))
    mm.set_images({'cam': _random_image(rng, cam.height, cam.width)})
    models = [_random_model(rng, 1.7) for _ in range(2)]
    particles = [_random_particles(rng, (-3.0, 0.0), 4), _random_particles(rng, (3.0, 0.0), 4)]
    hjs = mm.hjs(particles, [rng.random(4) + 0.1 for _ in range(2)], models)
    sep = mm.separable(particles, models)
    for a, b in zip(hjs.loglik, sep.loglik):
        np.testing.assert_allclose(a, b, atol=1e-12)
        assert np.all(a < 0)
    np.testing.assert_allclose(hjs.visible_fraction, 1.0)


def _two_cameras():
    return (_camera('front', (0.0, -4.0, 1.3), size=(48, 36), focal=55.0),
            _camera('side', (4.0, 0.5, 1.3), size=(48, 36), focal=55.0))


def test_joint_single_target_equals_separable():
    rng = np.random.default_rng(7)
    cams = _two_cameras()
    mm = MeasurementModel(_room(*cams))
    mm.set_images({c.name: _random_image(rng, c.height, c.width) for c in cams})
    model = _random_model(rng, 1.75)
    parts = _random_particles(rng, (0.0, 0.0), 6)
    joint = mm.joint(parts[:, None, :], [model])
    sep = mm.separable([parts], [model]).loglik[0]
    np.testing.assert_allclose(joint, sep, atol=1e-12)
    assert np.all(joint < 0)


def test_joint_non_overlapping_is_sum_of_singles():
    rng = np.random.default_rng(8)
    cam = _camera('cam', (0.0, -6.0, 1.3), size=(160, 40), focal=60.0)
    mm = MeasurementModel(_room(cam))
    mm.set_images({'cam': _random_image(rng, cam.height, cam.width)})
    models = [_random_model(rng, 1.7), _random_model(rng, 1.6)]
    a = _random_particles(rng, (-3.0, 0.0), 5)
    b = _random_particles(rng, (3.0, 0.0), 5)
    joint = mm.joint(np.stack([a, b], axis=1), models)
    sep = mm.separable([a, b], models).loglik
    np.testing.assert_allclose(joint, sep[0] + sep[1], atol=1e-12)


def test_joint_explicit_order_swaps_occluder():
    rng = np.random.default_rng(9)
    cam = _camera('cam', (0.0, -3.5, 1.2))
    cfg = LikelihoodConfig(d_occ=0.4, min_visible_pixels=1)
    mm = MeasurementModel(_room(cam), cfg)
    image = _random_image(rng, cam.height, cam.width)
    mm.set_images({'cam': image})
    bins = quantize(image)
    models = [_random_model(rng, 1.7), _random_model(rng, 1.7)]
    sample = np.zeros((1, 2, 6))
    sample[0, 0, [X, Y]] = (0.0, 0.0)                        # nearer the camera
    sample[0, 1, [X, Y]] = (0.15, 1.0)                       # behind, partly hidden
    lab = [mm.render_labels('cam', sample[0, k], models[k]) for k in range(2)]
    m0, m1 = lab[0] > 0, lab[1] > 0
    assert (m0 & m1).sum() > 10 and (m1 & ~m0).sum() > 10
    rel = relative_angle(sample[0, :, THETA], cam.viewing_angle(sample[0, :, :2]))
    hists = [models[k].interpolate(rel[k:k + 1])[0] for k in range(2)]
    s2 = 2 * cfg.sigma ** 2

    def expected(front: int) -> float:
        back = 1 - front
        vis_back = (~(lab[front] > 0)).astype(float)
        return -(_F(bins, lab[front], np.ones(m0.shape), hists[front], cfg.d_occ)
                 + _F(bins, lab[back], vis_back, hists[back], cfg.d_occ)) / s2

    default = mm.joint(sample, models)[0]
    assert default == pytest.approx(expected(0), abs=1e-12)   # depth order: target 0 front
    order_swapped = np.array([[[1, 0]]])
    swapped = mm.joint(sample, models, orders=order_swapped)[0]
    assert swapped == pytest.approx(expected(1), abs=1e-12)
    assert swapped != pytest.approx(default, abs=1e-6)
    same = mm.joint(sample, models, orders=np.array([[[0, 1]]]))[0]
    assert same == pytest.approx(default, abs=1e-12)
    with pytest.raises(LikelihoodError):
        mm.joint(sample, models, orders=np.array([[[0, 0]]]))


def _paint(cams, states, models, colours, background=(90, 90, 90)):
    """Synthetic images: each person's part quads filled with cv2.fillPoly in flat colours
    (independent of the span rasteriser), far to near."""
    images = {}
    for cam in cams:
        img = np.empty((cam.height, cam.width, 3), np.uint8)
        img[:] = background
        order = np.argsort([-cam.distance(np.array([s[X], s[Y], 0.9])) for s in states])
        for k in order:
            left, right, seg_part, _, _ = silhouette_outline(
                cam, states[k:k + 1], BodyShape(height=models[k].height,
                                                width=models[k].width))
            for j in range(seg_part.shape[1]):
                if seg_part[0, j]:
                    quad = np.array([left[0, j], right[0, j], right[0, j + 1], left[0, j + 1]])
                    cv2.fillPoly(img, [np.round(quad * 16).astype(np.int32)],
                                 colours[k][seg_part[0, j] - 1], shift=4)
        images[cam.name] = img
    return images


def _flat_model(colours, height):
    hists = np.zeros((1, 3, 512))
    for q, (r, g, b) in enumerate(colours):
        hists[0, q, (r >> 5) * 64 + (g >> 5) * 8 + (b >> 5)] = 1.0
    return PersonModel(height, 0.5, [0.0], hists)


def test_correct_particle_scores_higher_than_displaced():
    cams = _two_cameras()
    mm = MeasurementModel(_room(*cams), LikelihoodConfig(min_visible_pixels=5))
    colours = [((230, 190, 160), (200, 30, 30), (30, 30, 200)),
               ((230, 190, 160), (30, 200, 30), (220, 220, 20))]
    models = [_flat_model(colours[0], 1.75), _flat_model(colours[1], 1.65)]
    truth = np.zeros((2, 6))
    truth[0, [X, Y]] = (0.0, 0.0)
    truth[1, [X, Y]] = (0.2, 0.9)
    mm.set_images(_paint(cams, truth, models, colours))
    shifts = np.array([[0, 0], [0.3, 0], [-0.3, 0], [0, 0.3], [0.2, -0.2]])
    parts = []
    for k in range(2):
        p = np.repeat(truth[k:k + 1], len(shifts), axis=0)
        p[:, [X, Y]] += shifts
        parts.append(p)
    hjs = mm.hjs(parts, [np.ones(len(shifts))] * 2, models)
    sep = mm.separable(parts, models)
    for res in (hjs, sep):
        for k in range(2):
            assert np.argmax(res.loglik[k]) == 0
            assert np.all(res.loglik[k][1:] < res.loglik[k][0] - 1.0)
    joint = mm.joint(np.stack(parts, axis=1), models)
    assert np.argmax(joint) == 0


def test_occlusion_maps_match_prior_coverage():
    rng = np.random.default_rng(11)
    cam = _camera('cam', (0.0, -3.5, 1.2))
    mm = MeasurementModel(_room(cam))
    models = [_random_model(rng, 1.7) for _ in range(3)]
    particles = [_random_particles(rng, (0.3 * k, 0.3 * k), 4) for k in range(3)]
    weights = [rng.random(4) + 0.1 for _ in range(3)]
    maps = mm.occlusion_maps('cam', particles, weights, models)
    assert maps.shape == (3, cam.height, cam.width) and maps.dtype == np.float32
    cover = []
    for k in range(3):
        w = weights[k] / weights[k].sum()
        c = np.zeros((cam.height, cam.width))
        for j in range(4):
            c += w[j] * (mm.render_labels('cam', particles[k][j], models[k]) > 0)
        cover.append(1.0 - c)
    for k in range(3):
        expect = np.prod([cover[h] for h in range(3) if h != k], axis=0)
        np.testing.assert_allclose(maps[k], expect, atol=1e-6)
    assert np.min(maps) < 0.9


def test_missing_camera_is_skipped_and_bad_images_rejected():
    rng = np.random.default_rng(12)
    cams = _two_cameras()
    mm = MeasurementModel(_room(*cams))
    images = {c.name: _random_image(rng, c.height, c.width) for c in cams}
    model = _random_model(rng, 1.7)
    parts = _random_particles(rng, (0.0, 0.0), 5)
    mm.set_images(images)
    both = mm.separable([parts], [model]).loglik[0]
    singles = []
    for c in cams:
        mm.set_images({c.name: images[c.name]})
        res = mm.separable([parts], [model])
        singles.append(res.loglik[0])
        other = [i for i, n in enumerate(mm.camera_names) if n != c.name][0]
        assert res.visible_fraction[0, other] == 0.0
    np.testing.assert_allclose(both, singles[0] + singles[1], atol=1e-12)
    with pytest.raises(LikelihoodError, match='expected'):
        mm.set_images({'front': np.zeros((10, 10, 3), np.uint8)})
    with pytest.raises(LikelihoodError, match='unknown camera'):
        mm.set_images({'nope': images['front']})
    with pytest.raises(LikelihoodError):
        mm.hjs([parts], [np.full(5, np.nan)], [model])
    with pytest.raises(LikelihoodError):
        mm.hjs([parts[:, :4]], [np.ones(5)], [model])


def test_subsample_uses_every_kth_row():
    rng = np.random.default_rng(13)
    cam = _camera('cam', (0.0, -4.0, 1.3), size=(60, 45), focal=45.0)
    model = _random_model(rng, 1.7)
    parts = _random_particles(rng, (0.0, 0.0), 4)
    image = _random_image(rng, cam.height, cam.width)
    full = MeasurementModel(_room(cam))
    half = MeasurementModel(_room(cam), LikelihoodConfig(subsample=2))
    for m in (full, half):
        m.set_images({'cam': image})
    sil = half.silhouettes('cam', parts, model)
    assert np.all(sil.row % 2 == 0)
    a = full.separable([parts], [model]).loglik[0]
    b = half.separable([parts], [model]).loglik[0]
    assert not np.allclose(a, b)
    assert np.all(np.abs(a - b) < 0.5 * np.abs(a) + 1.0)    # an approximation, same scale


def test_threads_and_joint_chunks_do_not_change_results():
    rng = np.random.default_rng(14)
    cams = _two_cameras()
    images = {c.name: _random_image(rng, c.height, c.width) for c in cams}
    models = [_random_model(rng, 1.7), _random_model(rng, 1.6)]
    parts = [_random_particles(rng, (0.0, 0.0), 7), _random_particles(rng, (0.2, 0.4), 7)]
    weights = [rng.random(7) + 0.1 for _ in range(2)]
    out = []
    for threads in (1, 2):
        mm = MeasurementModel(_room(*cams), LikelihoodConfig(threads=threads))
        mm.set_images(images)
        out.append((mm.hjs(parts, weights, models), mm.joint(np.stack(parts, axis=1), models)))
    for a, b in zip(out[0][0].loglik, out[1][0].loglik):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(out[0][0].visible_fraction, out[1][0].visible_fraction)
    # the threads take the cameras by their last cost: reversed order, same results
    mm._camera_cost = {cams[0].name: 0.0, cams[1].name: 1.0}
    again = mm.hjs(parts, weights, models)
    for a, b in zip(out[0][0].loglik, again.loglik):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(out[0][0].visible_fraction, again.visible_fraction)
    np.testing.assert_array_equal(out[0][1], out[1][1])
    mm.JOINT_CHUNK = 4                                       # 2 joint samples per chunk
    np.testing.assert_allclose(mm.joint(np.stack(parts, axis=1), models), out[0][1],
                               atol=1e-12)


def test_reused_workspaces_equal_fresh_ones_and_are_left_zero():
    """The image buffers of the HJS update are kept between calls (grown to the largest
    image and target count): a model evaluated again and again, with fewer targets than
    its buffers hold and two image sizes, gives exactly the results of a fresh model."""
    rng = np.random.default_rng(15)
    cams = _two_cameras()
    small = _camera('small', (0.5, -3.0, 1.2), size=(30, 20), focal=40.0)
    room = _room(*cams, small)
    images = {c.name: _random_image(rng, c.height, c.width) for c in (*cams, small)}
    reused = MeasurementModel(room, LikelihoodConfig(threads=1))
    reused.set_images(images)
    for trial, n_targets in enumerate((3, 2, 3, 1, 2)):
        models = [_random_model(rng, 1.6 + 0.1 * k) for k in range(n_targets)]
        parts = [_random_particles(rng, (0.25 * k - 0.2, 0.3 * k), 6)
                 for k in range(n_targets)]
        weights = [rng.random(6) + 0.05 for _ in range(n_targets)]
        fresh = MeasurementModel(room, LikelihoodConfig(threads=1))
        fresh.set_images(images)
        a = reused.hjs(parts, weights, models)
        b = fresh.hjs(parts, weights, models)
        for la, lb in zip(a.loglik, b.loglik):
            np.testing.assert_array_equal(la, lb)
        np.testing.assert_array_equal(a.visible_fraction, b.visible_fraction)
        if trial == 0:
            assert any(np.any(np.abs(la) > 0) for la in a.loglik)
    # the kept buffers are back at zero (m_fg and b_bg; w* is scratch)
    (mfg, bbg, _), = reused._workspaces._free
    assert mfg.shape[0] >= 6 and not np.any(mfg) and not np.any(bbg)


def _stagewise(mm: MeasurementModel, particles, weights, models, separable: bool):
    """The update as separate steps (the path before the one-call camera update):
    Python rasterisation, key-view weights, a stable argsort, hjs_camera with fresh
    buffers, then 000 Eq. 19, what the camera says of targets it sees little of (target by
    target) and the visible fractions in numpy."""
    from mbtrack_ros.core import _kernels
    from mbtrack_ros.core.appearance import key_view_stack, view_weights
    states = np.concatenate(particles)
    target = np.repeat(np.arange(len(particles)), [len(p) for p in particles])
    prior = np.concatenate([w / w.sum() for w in weights])
    key = key_view_stack(models)
    cfg = mm.config
    loglik = np.zeros(len(states))
    visible = np.zeros((len(models), len(mm.camera_names)))
    for c, name in enumerate(mm.camera_names):
        cam = mm.calibration.cameras[name]
        sil = mm.silhouettes(name, states, [models[k] for k in target])
        va, vb, wa = (v[0] for v in view_weights([cam], states, target, models))
        fc, bc, vis = _kernels.hjs_camera(
            mm.bins(name), sil.row, sil.x0, sil.x1, sil.part, sil.offsets, sil.area,
            sil.bbox, np.argsort(sil.distance, kind='stable'), target, prior, key, va, vb,
            wa, len(models), cfg.d_occ, separable, np.zeros(0),
            np.zeros(len(states) + 1, np.int64))
        one = -(fc + bc) / (2.0 * cfg.sigma ** 2)
        seen = (sil.area > 0) & (sil.area * sil.row_step >= cfg.min_visible_pixels)
        frac = np.where(sil.full_area > 0, vis / np.maximum(sil.full_area, 1), 0.0)
        visible[:, c] = np.bincount(target, weights=prior * np.clip(frac, 0, 1),
                                    minlength=len(models))
        for k in range(len(models)):                 # what the camera says of each target
            sel = target == k
            share = np.sum(prior[sel] * np.where(seen[sel], np.minimum(
                sil.area[sel] / np.maximum(sil.full_area[sel], 1), 1.0), 0.0)) / prior[sel].sum()
            if share < cfg.min_inside_share or visible[k, c] < cfg.min_visible_share:
                one[sel] = 0.0
            elif np.any(sel & ~seen):
                one[sel & ~seen] = (np.sum((prior * one)[sel & seen])
                                    / np.sum(prior[sel & seen]) if np.any(sel & seen) else 0.0)
        loglik += one
    return loglik, visible


@pytest.mark.parametrize('seed,subsample,threads', [(20, 1, 1), (21, 2, 2), (22, 1, 2)])
def test_one_call_camera_update_equals_stagewise_path(seed, subsample, threads):
    """``hjs`` / ``separable`` run each camera as one numba call (update_camera): bit for
    bit the results of the steps done one by one, with sitting particles, particles out of
    view and behind a camera, a distorted camera and several key views."""
    rng = np.random.default_rng(seed)
    R, t = look_at((-3.5, 2.0, 2.2), (0.0, 0.0, 0.8))
    bent = Camera('bent', 44, 34, [[50, 0, 21.7], [0, 48, 16.2], [0, 0, 1]],
                  [-0.2, 0.05, 0.002, -0.001, 0.01], R, t)
    cams = (*_two_cameras(), bent)
    mm = MeasurementModel(_room(*cams), LikelihoodConfig(subsample=subsample, threads=threads,
                                                         min_visible_pixels=15))
    mm.set_images({c.name: _random_image(rng, c.height, c.width) for c in cams})
    for trial in range(4):
        n_targets = 1 + trial % 4
        models = [PersonModel(1.55 + 0.1 * k, 0.45 + 0.05 * k,
                              rng.uniform(-np.pi, np.pi, 1 + (k + trial) % 3),
                              rng.random((1 + (k + trial) % 3, 3, 512)) ** 4)
                  for k in range(n_targets)]
        particles = [_random_particles(rng, rng.uniform(-0.6, 0.6, 2), 5 + k)
                     for k in range(n_targets)]
        for p in particles:
            p[:, 5] = rng.random(len(p)) < 0.3                     # some sitting
        particles[0][0, X] = 40.0                                   # out of every view
        particles[-1][-1, :2] = (4.5, 0.5)                          # behind 'side'
        weights = [rng.random(len(p)) + 0.05 for p in particles]
        for separable in (False, True):
            res = (mm.separable(particles, models) if separable
                   else mm.hjs(particles, weights, models))
            loglik, visible = _stagewise(mm, particles,
                                         [np.ones(len(p)) for p in particles] if separable
                                         else weights, models, separable)
            np.testing.assert_array_equal(np.concatenate(res.loglik), loglik)
            np.testing.assert_array_equal(res.visible_fraction, visible)
            assert np.count_nonzero(loglik) > len(loglik) // 2


def test_camera_threads_keep_item_order_and_raise_errors():
    """The calling thread works through the cameras with the pool's threads: results come
    back in item order whichever thread ran them, and an error in any thread reaches the
    caller."""
    mm = MeasurementModel(_room(*_two_cameras()), LikelihoodConfig(threads=3))
    seen = set()

    def slow_square(i: int) -> int:
        seen.add(threading.current_thread().name)
        time.sleep(0.002 * (i % 3))
        return i * i

    for _ in range(3):
        assert mm._map(slow_square, list(range(11))) == [i * i for i in range(11)]
    assert len(seen) >= 2                                    # the pool took part

    def fail_on_7(i: int) -> int:
        if i == 7:
            raise LikelihoodError('camera 7 failed')
        return i

    with pytest.raises(LikelihoodError, match='camera 7'):
        mm._map(fail_on_7, list(range(11)))
    assert mm._map(slow_square, [2, 3]) == [4, 9]            # still usable afterwards
    mm.close()


def test_prior_list_equals_target_by_target_normalisation():
    """The one-pass normalisation of equal-sized linear weights gives the numbers of
    _normalised_priors per target, and its errors (the fallback's)."""
    from mbtrack_ros.core.likelihood import (
        LikelihoodError, _normalised_prior_list, _normalised_priors)
    rng = np.random.default_rng(4)
    for _ in range(100):
        k, n = int(rng.integers(1, 6)), int(rng.integers(1, 90))
        parts = [np.zeros((n, 6)) for _ in range(k)]
        weights = [rng.random(n) * 10.0 ** rng.uniform(-300, 300) for _ in range(k)]
        for got, (j, w) in zip(_normalised_prior_list(weights, parts, False),
                               enumerate(weights)):
            np.testing.assert_array_equal(got, _normalised_priors(w, n, j, False))
        logs = [np.log(w) for w in weights]
        for got, (j, w) in zip(_normalised_prior_list(logs, parts, True), enumerate(logs)):
            np.testing.assert_array_equal(got, _normalised_priors(w, n, j, True))
    parts = [np.zeros((3, 6)), np.zeros((3, 6))]
    with pytest.raises(LikelihoodError, match='target 1: weights must be finite'):
        _normalised_prior_list([np.ones(3), np.array([1.0, np.nan, 1.0])], parts, False)
    with pytest.raises(LikelihoodError, match='target 0: weights sum to zero'):
        _normalised_prior_list([np.zeros(3), np.ones(3)], parts, False)
    with pytest.raises(LikelihoodError, match='target 1: 2 weights for 3 particles'):
        _normalised_prior_list([np.ones(3), np.ones(2)], parts, False)


def _brute_term(mm, camera, states, model, mask, prior, neutral=0.5, undecided=None):
    """The coverage term's ``f`` of each state (N,) in one camera, pixel by pixel: every
    silhouette pixel adds ``F_u - neutral`` (an undecided pixel 0), the sum is divided by
    the prior-weighted mean silhouette area (pixels in the image) and ``neutral`` added; a
    silhouette outside the image gets the prior-weighted mean of the others' ``f``."""
    bodies = [mm.render_labels(camera, s, model) > 0 for s in states]
    und = np.zeros(mask.shape, bool) if undecided is None else undecided
    area = np.array([b.sum() for b in bodies], float)
    excess = np.array([((b & mask & ~und).sum() - neutral * (b & ~und).sum()) for b in bodies])
    inside = area > 0
    ref = np.sum(prior[inside] * area[inside]) / np.sum(prior[inside])
    f = np.where(inside, neutral + excess / ref, np.nan)
    f[~inside] = np.sum(prior[inside] * f[inside]) / np.sum(prior[inside])
    return f


@pytest.mark.parametrize('separable', [False, True])
def test_coverage_term_adds_gain_times_brute_force_coverage(separable):
    rng = np.random.default_rng(21)
    cams = _two_cameras()
    mm = MeasurementModel(_room(*cams), LikelihoodConfig(min_visible_pixels=1))
    images = {c.name: _random_image(rng, c.height, c.width) for c in cams}
    masks = {c.name: rng.random((c.height, c.width)) < 0.4 for c in cams}
    masks['front'][:, :20] = True              # coverage varies between the particles
    models = [_random_model(rng, 1.7) for _ in range(2)]
    particles = [_random_particles(rng, (0.0, 0.0), 5), _random_particles(rng, (0.3, 0.6), 5)]
    particles[1][0, X] = 50.0                  # outside both views
    weights = [rng.random(5) + 0.1 for _ in range(2)]

    def evaluate():
        if separable:
            return mm.separable(particles, models).loglik
        return mm.hjs(particles, weights, models).loglik

    mm.set_images(images)
    plain = evaluate()
    gain = 1.5
    mm.set_foreground(masks, gain)
    with_term = evaluate()
    for k in range(2):
        prior = np.full(5, 0.2) if separable else weights[k] / weights[k].sum()
        term = np.zeros(5)
        for cam in cams:
            term += gain * _brute_term(mm, cam.name, particles[k], models[k],
                                       masks[cam.name], prior)
        np.testing.assert_allclose(with_term[k] - plain[k], term, atol=1e-9)
        assert np.ptp(term) > 0.1                  # the term tells the particles apart
    mm.set_images(images)                          # a new frame clears the masks
    for a, b in zip(evaluate(), plain):
        np.testing.assert_allclose(a, b, atol=1e-12)


@pytest.mark.parametrize('separable', [False, True])
def test_undecided_pixels_count_as_the_neutral_coverage_in_the_term(separable):
    """With undecided background pixels, each counts as ``neutral`` in the particle's
    coverage, whatever its mask value: it adds nothing to the foreground excess
    ``fg - neutral x area`` (pixel by pixel); a particle on undecided pixels alone gets
    ``gain x neutral``."""
    rng = np.random.default_rng(23)
    cams = _two_cameras()
    mm = MeasurementModel(_room(*cams), LikelihoodConfig(min_visible_pixels=1))
    images = {c.name: _random_image(rng, c.height, c.width) for c in cams}
    masks = {c.name: rng.random((c.height, c.width)) < 0.4 for c in cams}
    undecided = {c.name: np.zeros((c.height, c.width), bool) for c in cams}
    undecided['front'][:, :24] = True          # a bootstrap region, all of it foreground
    masks['front'][:, :24] = True
    undecided['side'] = None                   # all decided there
    models = [_random_model(rng, 1.7)]
    particles = [_random_particles(rng, (0.0, 0.0), 6)]
    weights = [rng.random(6) + 0.1]
    gain, neutral = 1.5, 0.3

    def evaluate():
        if separable:
            return mm.separable(particles, models).loglik[0]
        return mm.hjs(particles, weights, models).loglik[0]

    mm.set_images(images)
    plain = evaluate()
    mm.set_images(images)
    mm.set_foreground(masks, gain, undecided=lambda: undecided, neutral=neutral)
    with_term = evaluate()
    prior = np.full(6, 1.0 / 6) if separable else weights[0] / weights[0].sum()
    term = np.zeros(6)
    shares = []
    for cam in cams:
        und = undecided[cam.name]
        term += gain * _brute_term(mm, cam.name, particles[0], models[0], masks[cam.name],
                                   prior, neutral, und)
        for state in particles[0]:
            body = mm.render_labels(cam.name, state, models[0]) > 0
            if body.any() and und is not None:
                shares.append((body & und).sum() / body.sum())
    assert max(shares) > 0.3 and min(shares) < 0.1    # some particles on undecided pixels
    np.testing.assert_allclose(with_term - plain, term, atol=1e-9)
    with pytest.raises(LikelihoodError, match='neutral coverage'):
        mm.set_foreground(masks, gain, neutral=1.5)
    mm.set_images(images)
    with pytest.raises(LikelihoodError, match='undecided-pixel mask'):
        mm.set_foreground(masks, gain, undecided={'front': np.zeros((2, 2), bool)})


def test_coverage_term_prefers_the_foreground_over_a_look_alike_background():
    """A person and a painted look-alike of her on the wall behind: colour alone cannot
    tell them apart, the foreground can."""
    cams = _two_cameras()
    mm = MeasurementModel(_room(*cams), LikelihoodConfig(min_visible_pixels=5))
    colours = [((230, 190, 160), (200, 30, 30), (30, 30, 200))] * 2
    models = [_flat_model(colours[0], 1.75)] * 2
    places = np.zeros((2, 6))
    places[1, [X, Y]] = (1.2, 1.0)                  # the look-alike, apart from her
    mm.set_images(_paint(cams, places, models, colours))
    masks = {c.name: mm.render_labels(c.name, places[0], models[0]) > 0 for c in cams}
    parts = [places.copy()]                         # one track, a particle on each
    plain = mm.hjs(parts, [np.ones(2)], models[:1]).loglik[0]
    assert abs(plain[0] - plain[1]) < 0.5
    mm.set_foreground(masks, 2.0)
    scored = mm.hjs(parts, [np.ones(2)], models[:1]).loglik[0]
    assert scored[0] > scored[1] + 3.0              # 2 cameras x gain 2 x (1 - 0)


def test_a_place_along_the_line_of_sight_inside_the_blob_loses_to_the_person():
    """Farther along a camera's line of sight a body's image is smaller and lies inside the
    person's blob: its foreground fraction is as high as the person's own, so colour and a
    plain coverage fraction cannot tell the depth. Counted per pixel, the foreground it
    leaves unexplained weighs against it; nearer, the larger silhouette covers background
    and loses too."""
    cam = _camera('front', (0.0, -4.0, 1.3), size=(96, 72), focal=110.0)
    mm = MeasurementModel(_room(cam), LikelihoodConfig(min_visible_pixels=5))
    colours = [((230, 190, 160), (200, 30, 30), (30, 30, 200))]
    model = _flat_model(colours[0], 1.75)
    places = np.zeros((3, 6))
    places[1, Y] = 0.7                               # 0.7 m farther along the sight line
    places[2, Y] = -0.7                              # 0.7 m nearer
    person = mm.render_labels('front', places[0], model) > 0
    farther = mm.render_labels('front', places[1], model) > 0
    assert (farther & person).sum() == farther.sum() < 0.8 * person.sum()
    gain = 2.0
    mm.set_images({'front': np.full((72, 96, 3), 90, np.uint8)})   # no colour evidence
    mm.set_foreground({'front': person}, gain)
    scored = mm.hjs([places], [np.ones(3)], [model]).loglik[0]
    expected = gain * _brute_term(mm, 'front', places, model, person, np.full(3, 1 / 3))
    np.testing.assert_allclose(scored - scored[0], expected - expected[0], atol=1e-9)
    # a plain fraction scores the farther place as the person's (all of it is foreground);
    # counted per pixel the blob it leaves unexplained tells them apart, and the nearer
    # place covers background
    assert scored[0] - scored[1] > 0.1 * gain and scored[0] - scored[2] > 0.1 * gain


def test_a_particle_on_the_person_beats_one_on_a_guessed_blob():
    """The online bootstrap gives a possible person's pixels the value foreground before the
    background there is known; a track placed a little off its person at the start sits on
    that blob. Counted as observed foreground the blob holds the track as firmly as the
    person does (colour alike); counted as undecided (the neutral coverage) the particle
    on the person wins by ``gain (1 - neutral)`` per camera."""
    cams = _two_cameras()
    mm = MeasurementModel(_room(*cams), LikelihoodConfig(min_visible_pixels=5))
    colours = [((230, 190, 160), (200, 30, 30), (30, 30, 200))] * 2
    models = [_flat_model(colours[0], 1.75)] * 2
    places = np.zeros((2, 6))
    places[1, [X, Y]] = (1.2, 1.0)                  # the blob, where she stood
    images = _paint(cams, places, models, colours)  # a look-alike there: colour is no help
    person = {c.name: mm.render_labels(c.name, places[0], models[0]) > 0 for c in cams}
    blob = {c.name: mm.render_labels(c.name, places[1], models[0]) > 0 for c in cams}
    masks = {n: person[n] | blob[n] for n in person}
    parts = [places.copy()]                         # one track, a particle on each
    gain, neutral = 2.0, 0.3
    mm.set_images(images)
    mm.set_foreground(masks, gain)
    held = mm.hjs(parts, [np.ones(2)], models[:1]).loglik[0]
    assert abs(held[0] - held[1]) < 0.5             # the blob holds it like the person
    mm.set_images(images)
    mm.set_foreground(masks, gain, undecided={n: blob[n] & ~person[n] for n in blob},
                      neutral=neutral)
    freed = mm.hjs(parts, [np.ones(2)], models[:1]).loglik[0]
    assert freed[0] - freed[1] > 0.8 * len(cams) * gain * (1.0 - neutral)


def test_coverage_masks_and_gain_are_checked():
    cams = _two_cameras()
    mm = MeasurementModel(_room(*cams))
    rng = np.random.default_rng(2)
    mm.set_images({c.name: _random_image(rng, c.height, c.width) for c in cams})
    with pytest.raises(LikelihoodError, match='foreground mask'):
        mm.set_foreground({'front': np.zeros((3, 3), bool)}, 1.0)
    for gain in (-1.0, float('nan'), float('inf')):
        with pytest.raises(LikelihoodError, match='coverage gain'):
            mm.set_foreground({}, gain)
    models = [_random_model(rng, 1.7)]
    particles = [_random_particles(rng, (0.0, 0.0), 4)]
    plain = mm.hjs(particles, [np.ones(4)], models).loglik[0]
    mm.set_foreground({'nowhere': np.zeros((3, 3), bool)}, 1.0)   # unknown camera: no term
    np.testing.assert_array_equal(mm.hjs(particles, [np.ones(4)], models).loglik[0], plain)
    mm.set_foreground({'front': np.ones((36, 48), bool)}, 1.0)    # front fully covered
    np.testing.assert_allclose(mm.hjs(particles, [np.ones(4)], models).loglik[0], plain
                               + _brute_term(mm, 'front', particles[0], models[0],
                                             np.ones((36, 48), bool), np.full(4, 0.25)))


def test_coverage_masks_from_a_callable_are_fetched_once_and_give_the_same_term():
    rng = np.random.default_rng(4)
    cams = _two_cameras()
    mm = MeasurementModel(_room(*cams), LikelihoodConfig(threads=2))
    images = {c.name: _random_image(rng, c.height, c.width) for c in cams}
    masks = {c.name: rng.random((c.height, c.width)) < 0.5 for c in cams}
    models = [_random_model(rng, 1.7)]
    particles = [_random_particles(rng, (0.0, 0.0), 6)]
    mm.set_images(images)
    mm.set_foreground(masks, 2.0)
    direct = mm.hjs(particles, [np.ones(6)], models).loglik[0]
    calls = []

    def source():
        calls.append(1)
        return masks

    mm.set_images(images)
    mm.set_foreground(source, 2.0)
    assert calls == []                         # not before a camera needs them
    np.testing.assert_array_equal(mm.hjs(particles, [np.ones(6)], models).loglik[0], direct)
    assert calls == [1]                        # once for both camera threads
    mm.set_images(images)
    mm.set_foreground(source, 0.0)             # gain 0: never fetched
    mm.hjs(particles, [np.ones(6)], models)
    assert calls == [1]
    bad = {c.name: np.zeros((2, 2), bool) for c in cams}
    mm.set_images(images)
    mm.set_foreground(lambda: bad, 1.0)
    with pytest.raises(LikelihoodError, match='foreground mask'):
        mm.hjs(particles, [np.ones(6)], models)


def _painted_scene(colours_a, colours_b, paint_a_as=None):
    """A hand-made two-person scene: camera, image and one-hot models. Person A stands in
    front of person B and hides part of B; every part is painted in one colour over a grey
    background (A over B); ``paint_a_as`` paints A in other colours than its model."""
    cam = _camera('cam', (0.0, -3.5, 1.6), size=(80, 60), focal=90.0)
    mm = MeasurementModel(_room(cam), LikelihoodConfig(sigma=0.1, d_occ=D_OCC,
                                                       min_visible_pixels=1))
    states = np.zeros((2, 6))
    states[0, :2] = (0.15, -0.8)                  # A, nearer the camera
    states[1, :2] = (0.0, 0.6)                    # B, partly behind A
    image = np.full((60, 80, 3), 128, np.uint8)
    bins_of = []
    models = []
    for colours in (colours_a, colours_b):
        px = np.array(colours, np.uint8).reshape(3, 1, 1, 3)
        bins_of.append([int(quantize(px[q])[0, 0]) for q in range(3)])
        hists = np.zeros((1, 3, 512))
        for q in range(3):
            hists[0, q, bins_of[-1][q]] = 1.0
        models.append(PersonModel(1.75, 0.5, [0.0], hists))
    labels = [mm.render_labels('cam', states[k], models[k]) for k in range(2)]
    painted = [colours_a if paint_a_as is None else paint_a_as, colours_b]
    for k in (1, 0):                              # far first: A is painted over B
        for q in range(3):
            image[labels[k] == q + 1] = painted[k][q]
    mm.set_images({'cam': image})
    return mm, states, models, labels, image


def test_hand_made_two_person_scene_foreground_term_is_d_occ_times_the_hidden_share():
    """000 Eq. 26 on a scene whose visible parts match their one-hot models exactly (d =
    0): the front person scores 0; the person behind scores d_occ times the share of the
    silhouette the front one hides (beta / (alpha + beta)), computed from the rendered
    masks; nobody is in front of A, and A's own evidence is perfect, so both background
    terms (Eq. 40) are 0."""
    a = [[200, 170, 140], [200, 30, 30], [30, 30, 140]]
    b = [[90, 60, 40], [30, 180, 30], [40, 40, 40]]
    mm, states, models, labels, _ = _painted_scene(a, b)
    dbg = mm.hjs_debug('cam', [states[:1], states[1:]], [np.ones(1), np.ones(1)], models)
    mask_a, mask_b = labels[0] > 0, labels[1] > 0
    hidden = (mask_a & mask_b).sum() / mask_b.sum()
    assert 0.1 < hidden < 0.9                                   # the case is real
    assert dbg.fc[0] == pytest.approx(0.0, abs=1e-12)
    assert dbg.fc[1] == pytest.approx(D_OCC * hidden, abs=1e-12)
    np.testing.assert_array_equal(dbg.w_star[1][mask_b], (~mask_a)[mask_b])
    assert dbg.bc[0] == 0.0 and dbg.bc[1] == pytest.approx(0.0, abs=1e-12)


def test_hand_made_two_person_scene_background_term_is_the_occluders_evidence():
    """000 Eq. 36-40: with A painted in other colours than its model, a hypothesis of B
    behind A carries A's evidence over the share of A it overlaps: bc_B = r(A, B) F(A)
    with r of Eq. 37 (overlap / A's area) and F(A) A's foreground term with nobody in
    front of it (Eq. 33 with w = 1, brute force); a B far beside A carries none of it
    (the pixels outside every silhouette are the background layer g(∅) of Eq. 20, not
    scored)."""
    a = [[200, 170, 140], [200, 30, 30], [30, 30, 140]]
    b = [[90, 60, 40], [30, 180, 30], [40, 40, 40]]
    mm, states, models, labels, image = _painted_scene(
        a, b, paint_a_as=[[200, 170, 140], [30, 30, 200], [30, 30, 140]])
    beside = states[1:].copy()
    beside[0, :2] = (1.4, 0.6)
    dbg = mm.hjs_debug('cam', [states[:1], np.concatenate([states[1:], beside])],
                       [np.ones(1), np.ones(2)], models)
    mask_a, mask_b = labels[0] > 0, labels[1] > 0
    f_a = _F(quantize(image), labels[0], np.ones(mask_a.shape), models[0].histograms[0])
    assert f_a > 0.1 and dbg.fc[0] == pytest.approx(f_a, abs=1e-12)
    r = (mask_a & mask_b).sum() / mask_a.sum()                  # Eq. 37
    assert r > 0.1
    assert dbg.bc[1] == pytest.approx(r * f_a, abs=1e-12)
    beside_mask = mm.render_labels('cam', beside[0], models[1]) > 0
    assert not (beside_mask & mask_a).any() and dbg.bc[2] == 0.0


def test_hjs_marginal_equals_the_product_belief_expectation_over_all_nine_joint_states():
    """000 Eq. 22-23 and 36-38 by enumeration: two targets with three particles each, their
    clouds interleaved in depth (the incremental near-to-far visit meets both targets in
    turn). For every one of the 3 x 3 joint states the joint log-likelihood is built
    from binary visibility masks (Eq. 20, 26); the HJS marginal of particle i of target k
    is its expectation under the other target's prior, restricted to the visual cone of
    x^k (Eq. 36-37): sum_j q(j) [F_k(wbar_ij) + [x^h_j nearer] r(x^h_j, x^k_i) F_h(x^h_j)].
    With one colour over the image, each part's d of Eq. 26 does not depend on which of its
    pixels are visible, F is linear in w and the first-order step of Eq. 31 is exact, so
    the code's fc + bc, its log-likelihoods (Eq. 19) and its normalised weights all equal
    the enumeration. The full joint likelihood (``MeasurementModel.joint``, checked against
    the same enumeration) adds what the cone leaves out: the evidence of the target
    behind x^k (the charge for hiding it) and of the front target outside x^k's cone."""
    cam = _camera('cam', (0.0, -3.5, 1.2))
    sigma = 0.12
    mm = MeasurementModel(_room(cam), LikelihoodConfig(
        sigma=sigma, d_occ=D_OCC, min_visible_pixels=1, min_inside_share=0.0,
        min_visible_share=0.0))
    image = np.zeros((cam.height, cam.width, 3), np.uint8)
    image[:] = (150, 90, 60)
    mm.set_images({'cam': image})
    bins = quantize(image)
    rng = np.random.default_rng(3)
    models = [_random_model(rng, 1.65), _random_model(rng, 1.8)]
    particles = [np.zeros((3, 6)), np.zeros((3, 6))]
    particles[0][:, X] = [-0.05, 0.1, -0.15]
    particles[0][:, Y] = [-0.6, 0.3, 1.1]
    particles[1][:, X] = [0.15, -0.1, 0.05]
    particles[1][:, Y] = [-0.2, 0.7, 1.5]
    particles[0][:, THETA] = [0.3, -1.0, 2.0]
    particles[1][:, THETA] = [1.2, 0.1, -2.5]
    priors = [np.array([0.5, 0.3, 0.2]), np.array([0.2, 0.45, 0.35])]

    states = np.concatenate(particles)
    rel = relative_angle(states[:, THETA], cam.viewing_angle(states[:, :2]))
    hists = [models[k].interpolate(rel[3 * k:3 * k + 3]) for k in range(2)]
    labels = [[mm.render_labels('cam', particles[k][i], models[k]) for i in range(3)]
              for k in range(2)]
    dist = [[float(cam.distance(np.r_[particles[k][i, :2], models[k].height / 2]))
             for i in range(3)] for k in range(2)]
    assert all(lab.sum() > 30 for row in labels for lab in row)        # all in view

    def F(k, i, w):
        return _F(bins, labels[k][i], w, hists[k][i])

    ones = np.ones((cam.height, cam.width))
    cone = np.zeros((2, 3))         # HJS marginal by enumeration (reduced observation space)
    full = np.zeros((2, 3))         # marginal of the full joint log-likelihood (Eq. 22)
    joint_states = np.zeros((9, 2, 6))
    joint_l = np.zeros(9)
    front_back = set()
    for n, (i, j) in enumerate(itertools.product(range(3), range(3))):
        joint_states[n] = particles[0][i], particles[1][j]
        idx = ((0, i), (1, j))
        masks = [labels[k][p] > 0 for k, p in idx]
        near = 0 if dist[0][i] < dist[1][j] else 1
        far = 1 - near
        front_back.add(near)
        w = [ones, ones]
        w[far] = (~masks[near]).astype(float)                      # Eq. 28
        f = [F(k, p, w[k]) for k, p in idx]
        joint_l[n] = f[0] + f[1]                                    # Eq. 21
        r = (masks[near] & masks[far]).sum() / masks[near].sum()    # Eq. 37
        for k, p in idx:
            h = 1 - k
            q = priors[h][idx[h][1]]
            full[k, p] += q * joint_l[n]
            cone[k, p] += q * (f[k] + (r * f[h] if k == far else 0.0))
    assert front_back == {0, 1}                       # each target is in front somewhere

    # the code's joint likelihood is the enumerated one
    np.testing.assert_allclose(mm.joint(joint_states, models), -joint_l / (2 * sigma ** 2),
                               rtol=1e-12)
    # HJS fc + bc (incremental, Algorithm 1) against the enumeration
    dbg = mm.hjs_debug('cam', particles, priors, models)
    np.testing.assert_allclose(dbg.fc + dbg.bc, cone.ravel(), rtol=0, atol=1e-12)
    assert np.any(dbg.bc > 0) and np.any((dbg.bc == 0) & (dbg.fc > 0))
    # Eq. 19 and the normalised weights
    loglik = mm.hjs(particles, priors, models).loglik
    for k in range(2):
        want = -cone[k] / (2 * sigma ** 2)
        np.testing.assert_allclose(loglik[k], want, rtol=1e-12)
        got_w = np.exp(loglik[k] - loglik[k].max())
        want_w = np.exp(want - want.max())
        np.testing.assert_allclose(got_w / got_w.sum(), want_w / want_w.sum(), rtol=1e-9)
    # what the cone restriction leaves out of the full joint marginal: not zero here
    assert np.abs(full - cone).max() > 0.01
