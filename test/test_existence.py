"""Visibility/existence auxiliary processes (001 Eq. 12-30)."""
from __future__ import annotations

import itertools

import cv2
import numpy as np
import pytest
from scipy.special import logsumexp

from mbtrack_ros.core.appearance import (
    model_from_images, quantize, relative_angle, single_target_loglik)
from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.core.detection.release import ReleaseConfig
from mbtrack_ros.core.existence import (
    AuxiliaryConfig, ExistenceError, TrackAuxiliary, binary_step, coverage_log_ratio,
    mixture_loglik, predictive_loglik, transition)
from mbtrack_ros.core.shape import BodyShape, rasterize, render_labels
from mbtrack_ros.core.state import THETA, X, Y


def test_transition_is_stochastic_and_frame_rate_consistent():
    A1 = transition(0.6, 0.3, 0.1)
    np.testing.assert_allclose(A1.sum(axis=1), 1.0)
    assert np.all(A1 >= 0)
    # continuous-time chain: two steps of dt equal one step of 2 dt
    np.testing.assert_allclose(A1 @ A1, transition(0.6, 0.3, 0.2), atol=1e-12)
    # over one second the switch probability of a chain that cannot come back is p
    np.testing.assert_allclose(transition(0.0, 0.3, 1.0)[1, 0], 0.3)
    np.testing.assert_allclose(transition(0.6, 0.3, 0.0), np.eye(2))
    with pytest.raises(ExistenceError):
        transition(1.0, 0.1, 0.1)
    with pytest.raises(ExistenceError):
        transition(0.1, 0.1, -1.0)


def test_binary_step_equals_brute_force_forward_filter():
    """001 Eq. 16 recursion vs explicit enumeration of all binary paths."""
    rng = np.random.default_rng(0)
    A = transition(0.4, 0.2, 0.1)
    xi0 = 0.7
    T = 5
    ll = rng.normal(size=(T, 2)) * 2.0
    xi = xi0
    for t in range(T):
        xi, _ = binary_step(xi, A, ll[t, 0], ll[t, 1])
    num = np.zeros(2)
    for path in itertools.product((0, 1), repeat=T + 1):
        p = xi0 if path[0] == 1 else 1.0 - xi0
        for t in range(T):
            p *= A[path[t], path[t + 1]] * np.exp(ll[t, path[t + 1]])
        num[path[-1]] += p
    assert xi == pytest.approx(num[1] / num.sum(), rel=1e-10)


def test_binary_step_keeps_prior_without_information():
    A = transition(0.4, 0.2, 0.5)
    xi, prior = binary_step(0.9, A, -np.inf, -np.inf)
    assert xi == prior == pytest.approx(0.1 * A[0, 1] + 0.9 * A[1, 1])
    xi, _ = binary_step(0.9, A, np.nan, 0.0)   # NaN -> -inf: only state 1 possible
    assert xi == 1.0


def test_predictive_and_mixture_loglik_against_direct_sums():
    rng = np.random.default_rng(1)
    ll = rng.normal(size=20) - 50.0
    lw = rng.normal(size=20)
    w = np.exp(lw) / np.exp(lw).sum()
    assert predictive_loglik(ll, lw) == pytest.approx(np.log(np.sum(w * np.exp(ll + 50.0)))
                                                      - 50.0)
    assert predictive_loglik(ll) == pytest.approx(logsumexp(ll) - np.log(20))
    lv = rng.normal(size=(4, 3))
    lh = rng.normal(size=3)
    pv = np.array([0.2, 0.5, 1.0])
    direct = np.log(pv * np.exp(lv) + (1 - pv) * np.exp(lh)).sum(axis=1)
    np.testing.assert_allclose(mixture_loglik(lv, lh, pv), direct)
    with pytest.raises(ExistenceError):
        predictive_loglik(np.zeros(0))
    with pytest.raises(ExistenceError):
        mixture_loglik(lv, lh[:2], pv)


def test_existence_rises_while_supported_and_falls_after():
    aux = TrackAuxiliary(AuxiliaryConfig(initial_existence=0.5))
    dt = 1.0 / 15
    rng = np.random.default_rng(2)
    history = []
    for k in range(60):
        supported = k < 30
        cov = {c: float(np.clip((0.85 if supported else 0.03) + rng.normal(0, 0.05), 0, 1))
               for c in ('cam0', 'cam1', 'cam2')}
        aux.update(dt, loglik_visible={}, loglik_hidden={}, coverage=cov)
        history.append(aux.existence)
    assert max(history[:30]) > 0.9 and history[29] > 0.9
    assert history[-1] < 0.1
    # it falls within a second of losing the support
    assert min(history[30:45]) < 0.1


def test_existence_ignores_cameras_where_the_track_is_hidden():
    aux = TrackAuxiliary(AuxiliaryConfig(initial_existence=0.9))
    for _ in range(15):
        aux.update(1 / 15, loglik_visible={}, loglik_hidden={},
                   coverage={'cam0': 0.0, 'cam1': 0.9},
                   visible_fraction={'cam0': 0.0, 'cam1': 1.0})
    assert aux.existence > 0.9


def test_visibility_cap_bounds_the_appearance_evidence_against_existence():
    """All cameras rejecting the appearance model of a track believed visible: with the
    cap the existence log-odds drop by exactly n * weight * log(1 - cap)."""
    cams = ('cam0', 'cam1', 'cam2', 'cam3')
    lv = {c: -40.0 for c in cams}
    lh = {c: -8.7 for c in cams}
    drops = {}
    for cap in (0.7, 1.0):
        cfg = AuxiliaryConfig(initial_existence=0.5, initial_visibility=0.999,
                              visibility_cap=cap)
        aux = TrackAuxiliary(cfg)
        aux.update(0.0, loglik_visible=lv, loglik_hidden=lh)
        drops[cap] = np.log(aux.existence / (1 - aux.existence))
    assert drops[0.7] == pytest.approx(4 * 0.3 * np.log(0.3), rel=1e-6)
    assert drops[1.0] == pytest.approx(4 * 0.3 * np.log(0.001), rel=1e-3)


# -- visibility on rendered images ------------------------------------------------------
def _room() -> RoomCalibration:
    cams = {}
    for k, (x, y) in enumerate([(0.1, 0.1), (5.9, 0.1)]):
        R, t = look_at((x, y, 2.6), (3.0, 2.5, 0.8))
        cams[f'cam{k}'] = Camera(f'cam{k}', 160, 120, [[90, 0, 79.5], [0, 90, 59.5],
                                                        [0, 0, 1]], [0] * 5, R, t)
    return RoomCalibration(cams, (0.3, 0.3, 5.7, 4.7))


def _paint(calib, people, rng):
    out = {}
    for n, cam in calib.cameras.items():
        base = np.random.default_rng(7).integers(60, 190, (6, 8, 3)).astype(np.uint8)
        img = cv2.resize(base, (cam.width, cam.height), interpolation=cv2.INTER_CUBIC)
        img = img.astype(np.int16) + rng.integers(-3, 4, img.shape)
        order = sorted(people, key=lambda p: -cam.distance(np.r_[p[0][:2], 0.9]))
        for state, shape, colours in order:        # painter's algorithm: far to near
            lab = render_labels(cam, state, shape)
            for part in (1, 2, 3):
                img[lab == part] = colours[part - 1]
        out[n] = np.clip(img, 0, 255).astype(np.uint8)
    return out


def test_visibility_drops_during_full_occlusion_and_recovers():
    rng = np.random.default_rng(3)
    calib = _room()
    shape = BodyShape(1.75, 0.5)
    target = np.array([3.0, 2.5, 0, 0, 0, 0])
    me = (target, shape, [(210, 170, 140), (30, 60, 190), (40, 40, 40)])
    model = model_from_images(_paint(calib, [me], rng), calib, target, 1.75, 0.5)
    # an occluder between cam0 and the target, hiding it completely in cam0 only
    c0 = calib.cameras['cam0'].center
    toward = (c0[:2] - target[:2]) / np.linalg.norm(c0[:2] - target[:2])
    occ_state = np.r_[target[:2] + 0.9 * toward, 0, 0, 0, 0]
    occluder = (occ_state, BodyShape(1.95, 0.8), [(120, 200, 90), (200, 120, 30),
                                                   (150, 150, 20)])
    aux = TrackAuxiliary(AuxiliaryConfig())
    hidden = -0.5 ** 2 / (2 * 0.12 ** 2)
    particles = target + np.c_[rng.normal(0, 0.03, (20, 2)), np.zeros((20, 4))]
    vis = []
    for k in range(45):
        occluded = 15 <= k < 30
        images = _paint(calib, [me, occluder] if occluded else [me], rng)
        lv, lh = {}, {}
        for n, cam in calib.cameras.items():
            sil = rasterize(cam, particles, shape)
            rel = relative_angle(particles[:, THETA], cam.viewing_angle(particles[:, [X, Y]]))
            ll = single_target_loglik(quantize(images[n]), sil, model.interpolate(rel))
            lv[n], lh[n] = predictive_loglik(ll), hidden
        aux.update(1 / 15, loglik_visible=lv, loglik_hidden=lh)
        vis.append((aux.visibility['cam0'], aux.visibility['cam1']))
    vis = np.array(vis)
    assert vis[14, 0] > 0.9                        # seen before the occlusion
    assert vis[29, 0] < 0.5 and vis[20:30, 0].max() < 0.5   # hidden in cam0
    assert vis[15:30, 1].min() > 0.9               # still seen in cam1
    assert vis[44, 0] > 0.9                        # recovered


def _reference_update(aux: TrackAuxiliary, dt, vis, hid, cov, frac, neutral=0.5) -> None:
    """TrackAuxiliary.update written plainly with numpy arrays (the scalar code's reference)."""
    cfg = aux.config
    A_v = transition(cfg.desocclusion, cfg.occlusion, dt)

    def step(xi, A, l0, l1):
        prior = np.array([1.0 - xi, xi]) @ A
        with np.errstate(divide='ignore', invalid='ignore'):
            logp = np.log(prior) + np.array([l0, l1])
        logp = np.where(np.isnan(logp), -np.inf, logp)
        norm = logsumexp(logp)
        if not np.isfinite(norm):
            return prior[1], prior[1]
        return np.exp(logp[1] - norm), prior[1]

    ratio = 0.0
    for cam in vis:
        l1 = -np.inf if np.isnan(vis[cam]) else vis[cam]
        l0 = -np.inf if np.isnan(hid[cam]) else hid[cam]
        xi, prior = step(aux.visibility.get(cam, cfg.initial_visibility), A_v, l0, l1)
        aux.visibility[cam] = xi
        w = np.clip(frac.get(cam, 1.0), 0.0, 1.0)
        if np.isfinite(l0):
            pv = min(prior, cfg.visibility_cap)
            with np.errstate(divide='ignore'):
                ratio += cfg.appearance_weight * w * np.logaddexp(np.log(pv) + l1 - l0,
                                                                  np.log1p(-pv))
    for cam, f in cov.items():
        w = np.clip(frac.get(cam, 1.0), 0.0, 1.0)
        f = np.clip(f, 0.0, 1.0) if np.isfinite(f) else 0.0
        ratio += w * cfg.support_gain * 2.0 * (f - neutral)
    aux.existence, _ = step(aux.existence, transition(cfg.birth, cfg.death, dt), 0.0, ratio)


def test_scalar_update_matches_the_array_reference():
    """The scalar (fast) existence/visibility update equals a plain numpy version, also with
    -inf / NaN likelihoods, empty coverage, certain priors and a visibility cap of 1."""
    rng = np.random.default_rng(3)
    for cap in (0.7, 1.0):
        cfg = AuxiliaryConfig(visibility_cap=cap, initial_visibility=1.0 if cap == 1.0
                              else 0.8)
        fast, ref = TrackAuxiliary(cfg), TrackAuxiliary(cfg)
        for t in range(60):
            cams = ['a', 'b', 'c'][:1 + t % 3]
            vis = {c: float(v) for c, v in zip(cams, rng.normal(-2.0, 3.0, len(cams)))}
            hid = {c: -17.0 for c in cams}
            if t % 7 == 0:
                vis['a'] = -np.inf
            if t % 11 == 0:
                vis[cams[-1]], hid[cams[-1]] = np.nan, np.nan
            cov = {} if t % 5 == 0 else {c: float(v) for c, v in
                                          zip(cams, rng.uniform(-0.1, 1.1, len(cams)))}
            frac = {c: float(v) for c, v in zip(cams, rng.uniform(-0.2, 1.2, len(cams)))}
            dt = 0.0 if t == 4 else 1 / 15
            neutral = (0.5, 0.3, 0.0)[t % 3]
            fast.update(dt, loglik_visible=vis, loglik_hidden=hid, coverage=cov,
                        visible_fraction=frac, neutral_coverage=neutral)
            _reference_update(ref, dt, vis, hid, cov, frac, neutral)
            assert fast.existence == pytest.approx(ref.existence, abs=1e-12)
            for c in ref.visibility:
                assert fast.visibility[c] == pytest.approx(ref.visibility[c], abs=1e-12)
        assert 0.0 < fast.existence < 1.0


def test_coverage_evidence_is_neutral_at_the_support_coverage():
    """The coverage evidence is 0 at the support coverage f_s, positive above, negative
    below: a person seen in part (0.4 of the rendered silhouette covered in both cameras,
    above the release's support threshold) keeps the track for a second, an empty place
    (0.05) loses it; with the crossover of the symmetric exponentials (0.5) the person
    seen in part would be lost too."""
    f_s = ReleaseConfig().min_coverage
    assert 0.0 < f_s < 0.4
    assert coverage_log_ratio({'a': f_s, 'b': f_s}, {}, 4.0, neutral=f_s) == 0.0
    assert coverage_log_ratio({'a': 0.4}, {'a': 0.5}, 4.0, neutral=f_s) \
        == pytest.approx(0.5 * 4.0 * 2.0 * (0.4 - f_s))

    def existence(f: float, neutral: float) -> float:
        aux = TrackAuxiliary(AuxiliaryConfig())
        for _ in range(15):                                   # one second at 15 Hz
            aux.update(1 / 15, loglik_visible={}, loglik_hidden={},
                       coverage={'a': f, 'b': f}, neutral_coverage=neutral)
        return aux.existence

    assert existence(0.4, f_s) > 0.95
    assert existence(0.05, f_s) < 0.05
    assert existence(0.4, 0.5) < 0.05
