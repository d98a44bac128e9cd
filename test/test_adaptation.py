"""Slow, occlusion-aware appearance adaptation (core/detection/adaptation.py,
PersonModel.add_view / adapt)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mbtrack_ros.core.appearance import (
    N_BINS, AppearanceError, PersonModel, model_from_images, part_histograms, quantize,
    relative_angle)
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.adaptation import AdaptationConfig, adapt_models, observe
from mbtrack_ros.core.shape import rasterize
from mbtrack_ros.core.state import THETA, X, Y

from test_detection import FPS, _detecting_tracker, backgrounds, make_room, paint, person

RED = ((215, 175, 145), (200, 40, 40), (45, 45, 50))


def _hists(rng, n=1):
    h = rng.random((n, 3, N_BINS)) ** 4
    return h / h.sum(axis=-1, keepdims=True)


def test_add_view_blends_by_rate_and_rate_half_is_the_average():
    rng = np.random.default_rng(0)
    old, new = _hists(rng, 2)
    for rate in (0.05, 0.5):
        m = PersonModel(1.8, 0.5, view_angles=[0.2], histograms=old.copy())
        m.add_view(0.3, new, rate=rate)
        assert m.view_angles.size == 1
        expected = (1 - rate) * old + rate * new
        np.testing.assert_allclose(m.histograms[0], expected / expected.sum(-1, keepdims=True),
                                   atol=1e-12)
        assert m.view_angles[0] == pytest.approx(0.2 + rate * 0.1)
    # the acquisition's merge (default rate): the plain average, as before the rate existed
    m = PersonModel(1.8, 0.5, view_angles=[0.2], histograms=old.copy())
    m.add_view(0.3, new)
    np.testing.assert_array_equal(m.histograms[0], 0.5 * (old + new))
    with pytest.raises(AppearanceError, match='rate'):
        m.add_view(0.3, new, rate=0.0)


def test_adapt_blends_a_near_view_and_adds_a_new_angle_from_the_interpolation():
    rng = np.random.default_rng(1)
    front, back, seen = _hists(rng, 3)
    m = PersonModel(1.8, 0.5, view_angles=[0.0, np.pi - 0.01], histograms=np.stack([front,
                                                                                      back]))
    side = np.pi / 2
    start = m.interpolate(np.array([side]))[0]
    assert m.adapt(side, seen, 0.1) is True                  # no key view within 20 deg
    assert m.view_angles.size == 3 and m.view_angles[2] == pytest.approx(side)
    np.testing.assert_allclose(m.histograms[2], 0.9 * start + 0.1 * seen, atol=1e-12)
    before = m.histograms[0].copy()
    assert m.adapt(0.1, seen, 0.1) is False                  # within 20 deg of the front
    assert m.view_angles.size == 3
    np.testing.assert_allclose(m.histograms[0], 0.9 * before + 0.1 * seen, atol=1e-12)


def _scene(people, seed=3):
    calib = make_room(ceiling=False)
    images = paint(calib, backgrounds(calib), people, np.random.default_rng(seed))
    return calib, images, {n: quantize(im) for n, im in images.items()}


def _state(p):
    return p[0].copy()


def test_observe_equals_part_histograms_on_the_unoccluded_pixels():
    near, far = person(2.0, 1.5), person(4.0, 3.5, colours=RED)
    calib, _, bins = _scene([near, far])
    means = np.stack([_state(near), _state(far)])
    models = [PersonModel(1.8, 0.5, view_angles=[0.0], histograms=_hists(
        np.random.default_rng(k))) for k in range(2)]
    for name, cam in calib.cameras.items():
        sil = rasterize(cam, means, [near[1], far[1]])
        for k in range(2):
            seen = observe(bins[name], sil, k, name, calib, means, [1, 2], models)
            if seen is None:
                continue
            other = 1 - k
            occluded = (sil.mask(other) > 0) & (sil.distance[other] < sil.distance[k])
            counts = part_histograms(bins[name], sil, k, (~occluded).astype(float),
                                     normalize=False)
            np.testing.assert_allclose(seen.hists * counts.sum(1)[:, None], counts, atol=1e-9)
            assert seen.free == pytest.approx(counts.sum() / sil.full_area[k])
            # foreground only: the histograms of the free foreground pixels, same free share
            fg = np.zeros(bins[name].shape, bool)
            fg[:, ::2] = True
            only = observe(bins[name], sil, k, name, calib, means, [1, 2], models,
                           foreground=fg)
            counts = part_histograms(bins[name], sil, k, (~occluded & fg).astype(float),
                                     normalize=False)
            np.testing.assert_allclose(only.hists * counts.sum(1)[:, None], counts, atol=1e-9)
            assert only.free == pytest.approx(seen.free)
            rel = relative_angle(means[k, THETA], cam.viewing_angle(means[k, [X, Y]]))
            assert seen.angle == pytest.approx(float(rel))


def _adapt(people, track_people, model_colours, config, visibility=1.0, stale=0.0):
    """adapt_models on the painted scene of ``people`` for tracks at the states of
    ``track_people`` whose models were acquired from a painting in ``model_colours`` (one
    per track; ``stale``: that share of each histogram replaced by a flat one), all
    eligible. Returns (models before, models after, records)."""
    calib, images, bins = _scene(people)
    models = []
    for p, colours in zip(track_people, model_colours):
        lone = person(p[0][0], p[0][1], theta=p[0][4], colours=colours)
        _, own_images, _ = _scene([lone], seed=5)
        m = model_from_images(own_images, calib, lone[0], 1.8, 0.5)
        m.histograms = (1 - stale) * m.histograms + stale / N_BINS
        models.append(m)
    before = [PersonModel(m.height, m.width, m.view_angles.copy(), m.histograms.copy())
              for m in models]
    means = np.stack([_state(p) for p in track_people])
    sils = {n: rasterize(c, means, [p[1] for p in track_people])
            for n, c in calib.cameras.items()}
    vis = [{n: visibility for n in calib.cameras} for _ in track_people]
    records = adapt_models(config, calib, bins, sils, means, list(range(1, len(means) + 1)),
                           models, np.ones(len(means), bool), vis)
    return before, models, records


def test_a_clear_view_moves_the_model_toward_the_observation_by_the_rate():
    alone = person(2.5, 2.0, theta=0.4)
    config = AdaptationConfig(rate=0.05)
    before, after, records = _adapt([alone], [alone], [alone[2]], config, stale=0.3)
    assert records and all(r['action'] in ('blend', 'new view') for r in records)
    assert all(0.05 < r['distance'] <= config.max_distance for r in records)
    # the straightforward version: replay the accepted observations on a copy
    calib, _, bins = _scene([alone])
    means = _state(alone)[None]
    replay = before[0]
    for r in records:
        cam = calib.cameras[r['camera']]
        sil = rasterize(cam, means, alone[1])
        counts = part_histograms(bins[r['camera']], sil, 0, normalize=False)
        rel = float(relative_angle(means[0, THETA], cam.viewing_angle(means[0, [X, Y]])))
        near = np.min(np.abs((replay.view_angles - rel + np.pi) % (2 * np.pi) - np.pi))
        assert r['distance'] <= config.max_distance
        if near < np.deg2rad(20):
            j = int(np.argmin(np.abs((replay.view_angles - rel + np.pi) % (2 * np.pi) - np.pi)))
            old = replay.histograms[j].copy()
            obs = counts / counts.sum(1, keepdims=True)
            replay.add_view(rel, counts, rate=0.05)
            np.testing.assert_allclose(replay.histograms[j], 0.95 * old + 0.05 * obs,
                                       atol=1e-12)
        else:
            replay.adapt(rel, counts, 0.05)
    np.testing.assert_allclose(after[0].histograms, replay.histograms, atol=1e-12)
    # closer to what the cameras show: the same observations score better afterwards
    again = adapt_models(
        AdaptationConfig(rate=0.05, max_distance=1.0), *_inputs(alone, after[0]))
    assert len(again) == len(records)
    for r0, r1 in zip(records, again):
        assert r1['distance'] < r0['distance']


def _inputs(p, model):
    calib, _, bins = _scene([p])
    means = _state(p)[None]
    sils = {n: rasterize(c, means, p[1]) for n, c in calib.cameras.items()}
    return calib, bins, sils, means, [1], [model], np.ones(1, bool), [
        {n: 1.0 for n in calib.cameras}]


def test_rate_zero_changes_nothing():
    alone = person(2.5, 2.0, theta=0.4)
    before, after, records = _adapt([alone], [alone], [alone[2]], AdaptationConfig(rate=0.0))
    assert records == []
    np.testing.assert_array_equal(after[0].histograms, before[0].histograms)


def test_a_close_neighbour_an_occluder_low_visibility_or_a_stranger_do_not_update():
    config = AdaptationConfig(rate=0.05)
    a, b = person(2.5, 2.0, theta=0.4), person(3.0, 2.3, colours=RED)  # 0.58 m apart
    before, after, records = _adapt([a, b], [a, b], [a[2], b[2]], config)
    assert records == []
    for m0, m1 in zip(before, after):
        np.testing.assert_array_equal(m1.histograms, m0.histograms)
    # without the radius: the camera where the other one stands in front gives nothing
    loose = AdaptationConfig(rate=0.05, neighbour_radius=0.0)
    _, _, records = _adapt([a, b], [a, b], [a[2], b[2]], loose)
    calib = make_room(ceiling=False)
    means = np.stack([_state(a), _state(b)])
    for r in records:
        cam = calib.cameras[r['camera']]
        sil = rasterize(cam, means, [a[1], b[1]])
        k = r['id'] - 1
        hidden = (sil.mask(k) > 0) & (sil.mask(1 - k) > 0)
        if sil.distance[1 - k] < sil.distance[k] and hidden.sum() > 0.1 * sil.full_area[k]:
            pytest.fail(f'track {r["id"]} learnt from {r["camera"]} where it is occluded')
    # a low visibility xi_v: nothing
    before, after, records = _adapt([a], [a], [a[2]], config, visibility=0.5)
    assert records == []
    # a track on a person who does not look like its model: inconsistent, unchanged
    before, after, records = _adapt([a], [a], [RED], config)
    assert records and all(r['action'] == 'inconsistent' for r in records)
    np.testing.assert_array_equal(after[0].histograms, before[0].histograms)


def test_bad_adaptation_config_is_refused():
    for bad in ({'rate': -0.1}, {'rate': 1.5}, {'min_free': 2.0}, {'max_distance': 0.0},
                {'neighbour_radius': -1.0}, {'interval': -1.0}, {'min_travel': -0.5}):
        with pytest.raises(DetectionError, match='adaptation'):
            AdaptationConfig(**bad)


@pytest.mark.parametrize('rate, speed, learns', [(0.0, 0.6, False), (0.2, 0.6, True),
                                                  (0.2, 0.0, False), (None, 0.6, True)])
def test_tracker_adapts_only_when_enabled_and_after_walking(rate, speed, learns):
    """End to end: a person walking (speed m/s) or standing alone; with a rate (None: the
    default, 0.05) the tracker's model (the object the filter's likelihood reads) learns
    once the track has walked ``min_travel`` (a standing one, like a false track on a
    screen, never does), with rate 0 it stays as acquired."""
    rng = np.random.default_rng(8)
    calib = make_room()
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=1, adaptation_rate=rate)
    wired = AdaptationConfig().rate if rate is None else rate
    assert tracker.detection.config.adaptation.rate == wired   # TrackerConfig wires it
    tracker.detection.config = replace(tracker.detection.config, relocate_interval=0.5)
    acquired, actions, learnt = {}, [], {}
    for k in range(45):
        people = [person(1.5 + speed / FPS * k, 2.4, theta=0.0)] if k >= 2 else []
        res = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, people, rng))
        for tid, m in tracker.models.items():
            acquired.setdefault(tid, (m.view_angles.copy(), m.histograms.copy()))
        actions += [a['action'] for a in tracker.detection.adaptations]
        for a in tracker.detection.adaptations:
            if a['action'] != 'inconsistent':
                learnt.setdefault(a['id'], set()).add(k)
    assert res.tracks and tracker.models
    tid, model = next(iter(tracker.models.items()))
    changed = model.histograms.shape != acquired[tid][1].shape \
        or not np.array_equal(model.histograms, acquired[tid][1])
    assert changed == learns
    assert ('blend' in actions or 'new view' in actions) == learns
    interval = tracker.detection.config.adaptation.interval * FPS   # frames
    for frames in learnt.values():     # each track at most once per interval
        assert np.all(np.diff(sorted(frames)) >= interval - 1e-9), frames
    if learns:   # not before it walked min_travel (1 m at 0.6 m/s: 1.7 s, 25 frames)
        assert min(min(f) for f in learnt.values()) >= 2 + 1.0 / speed * FPS
