"""Belief propagation of the spatial-exclusion MRF against brute-force enumeration."""
from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest

from mbtrack_ros.core.mrf import MRFError, belief_propagation, exclusion_potential


def brute_force_marginals(xy, weights, edges, radius, epsilon):
    """Exact marginals of prod_k w_k(i_k) prod_edges psi by enumerating all combinations."""
    sizes = [len(w) for w in weights]
    marg = [np.zeros(n) for n in sizes]
    for combo in itertools.product(*[range(n) for n in sizes]):
        p = np.prod([weights[k][i] for k, i in enumerate(combo)])
        for h, k in edges:
            d = np.linalg.norm(xy[h][combo[h]] - xy[k][combo[k]])
            p *= 1.0 if d > radius else epsilon
        for k, i in enumerate(combo):
            marg[k][i] += p
    return [m / m.sum() for m in marg]


def random_sets(rng, k_count, n, spread=0.5):
    xy = [rng.normal(0.0, spread, size=(n, 2)) for _ in range(k_count)]
    w = [rng.random(n) + 0.05 for _ in range(k_count)]
    return xy, w


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_bp_exact_for_two_targets(seed):
    rng = np.random.default_rng(seed)
    xy, w = random_sets(rng, 2, 7)
    res = belief_propagation(xy, w, radius=0.4, epsilon=1e-3, theta=1e-9, max_iterations=10)
    exact = brute_force_marginals(xy, [wi / wi.sum() for wi in w], [(0, 1)], 0.4, 1e-3)
    for got, want in zip(res.weights, exact):
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    # the exclusion actually changed the beliefs (otherwise the test would be vacuous)
    assert max(np.abs(res.weights[0] - w[0] / w[0].sum()).max(),
               np.abs(res.weights[1] - w[1] / w[1].sum()).max()) > 1e-3
    # a single edge converges after one informative iteration plus one confirming it
    assert res.converged and res.iterations == 2 and res.kl < 1e-9


@pytest.mark.parametrize('seed', [3, 4])
def test_bp_exact_on_three_target_chain(seed):
    rng = np.random.default_rng(seed)
    xy, w = random_sets(rng, 3, 5, spread=0.4)
    edges = [(0, 1), (1, 2)]
    res = belief_propagation(xy, w, radius=0.4, epsilon=1e-3, theta=1e-12,
                             max_iterations=20, edges=edges)
    exact = brute_force_marginals(xy, [wi / wi.sum() for wi in w], edges, 0.4, 1e-3)
    for got, want in zip(res.weights, exact):
        np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-12)
    assert res.converged and res.iterations < 20
    # the chain's end nodes interact only through the middle one: a loopy (fully connected)
    # run gives different beliefs, so the edge list is really used
    full = belief_propagation(xy, w, radius=0.4, epsilon=1e-3, theta=1e-12,
                              max_iterations=50)
    assert max(np.abs(a - b).max() for a, b in zip(full.weights, res.weights)) > 1e-6


def test_stopping_rule_stops_below_threshold():
    rng = np.random.default_rng(7)
    xy, w = random_sets(rng, 5, 100, spread=0.6)
    res = belief_propagation(xy, w, theta=0.01, max_iterations=30)
    assert res.converged
    assert res.kl < 0.01
    assert 1 <= res.iterations < 30
    for b in res.weights:
        assert b.shape == (100,) and np.all(b > 0)
        assert abs(b.sum() - 1.0) < 1e-12


def test_far_apart_targets_are_unchanged():
    rng = np.random.default_rng(8)
    xy = [rng.normal(0, 0.05, (20, 2)), rng.normal(0, 0.05, (20, 2)) + [3.0, 0.0]]
    w = [rng.random(20) + 0.1, rng.random(20) + 0.1]
    res = belief_propagation(xy, w)
    for got, wi in zip(res.weights, w):
        np.testing.assert_allclose(got, wi / wi.sum(), atol=1e-12)


def test_soft_floor_keeps_beliefs_positive():
    # every particle of target 1 sits on target 0: a hard potential would zero its belief
    xy = [np.zeros((4, 2)), np.full((4, 2), 0.01)]
    w = [np.ones(4), np.ones(4)]
    res = belief_propagation(xy, w, epsilon=1e-3)
    assert all(np.all(np.isfinite(b)) and np.all(b > 0) for b in res.weights)


def test_potential_values():
    a = np.array([[0.0, 0.0], [1.0, 0.0]])
    b = np.array([[0.3, 0.0], [0.0, 0.5]])
    psi = exclusion_potential(a, b, radius=0.4, epsilon=0.01)
    np.testing.assert_array_equal(psi, [[0.01, 1.0], [1.0, 1.0]])


def test_bad_input_raises():
    with pytest.raises(MRFError):
        belief_propagation([np.zeros((3, 2))], [np.ones(4)])
    with pytest.raises(MRFError):
        belief_propagation([np.zeros((3, 2))] * 2, [np.ones(3)] * 2, edges=[(0, 0)])
    with pytest.raises(MRFError):
        belief_propagation([np.zeros((3, 2))] * 2, [np.zeros(3)] * 2)


def test_exclusion_potential_distances_equal_scipy_cdist_bit_for_bit():
    """The pairwise squared distances are computed with numpy (scipy.spatial costs ~0.3 s
    of import per replay); they must be scipy's cdist 'sqeuclidean', bit for bit, so the
    potential's threshold decisions are the same."""
    from scipy.spatial.distance import cdist

    rng = np.random.default_rng(3)
    for _ in range(200):
        n, m = rng.integers(1, 80, size=2)
        a = rng.normal(size=(n, 2)) * rng.uniform(0.01, 5.0)
        b = rng.normal(size=(m, 2)) * rng.uniform(0.01, 5.0) + rng.normal(size=2)
        d2 = cdist(a, b, 'sqeuclidean')
        radius = float(np.sqrt(np.median(d2)))  # about half the pairs on each side
        psi = exclusion_potential(a, b, radius=radius, epsilon=0.01)
        np.testing.assert_array_equal(psi, np.where(d2 > radius * radius, 1.0, 0.01))
        # a radius exactly at a pair's distance: only bit-equal distances agree there
        edge = float(np.sqrt(d2[0, 0]))
        np.testing.assert_array_equal(exclusion_potential(a, b, radius=edge),
                                      np.where(d2 > edge * edge, 1.0, 1e-3))


def brute_force_joint_prior(xy, weights, radius, epsilon):
    """Marginals of the MRF-weighted joint prior of 000 Eq. 16 on a fully connected graph,
    prod_{h<k} psi(x^h, x^k) prod_k p^-(x^k), by enumerating every joint particle."""
    k_count = len(xy)
    edges = [(h, k) for h in range(k_count) for k in range(h + 1, k_count)]
    return brute_force_marginals(xy, [w / w.sum() for w in weights], edges, radius, epsilon)


@pytest.mark.parametrize('seed', [10, 11, 12])
def test_filter_prior_equals_brute_force_joint_prior_for_two_targets(seed):
    """The HJS filter's MRF prior (what HJSFilter hands the likelihood) is the exact
    marginal of the joint prior of 000 Eq. 16 for two targets (a tree: BP is exact)."""
    from mbtrack_ros.core.filters import FilterConfig, HJSFilter

    rng = np.random.default_rng(seed)
    filt = HJSFilter(FilterConfig(particles=4, theta_bp=1e-12, max_bp_iterations=50))
    xy, _ = random_sets(rng, 2, 4, spread=0.3)
    particles = [np.c_[p, np.zeros((4, 4))] for p in xy]
    prior = filt._exclusion_prior([1, 2], particles, [np.full(4, 0.25)] * 2)
    exact = brute_force_joint_prior(xy, [np.ones(4)] * 2, 0.4, 1e-3)
    for got, want in zip(prior, exact):
        np.testing.assert_allclose(got, want, rtol=1e-9)
    assert max(np.abs(p - 0.25).max() for p in prior) > 1e-2   # not vacuous


@pytest.mark.parametrize('seed', [13, 14, 15, 16])
def test_loopy_bp_is_close_to_the_brute_force_joint_prior_for_three_targets(seed):
    """Three targets, fully connected (000 §V-B.1): loopy BP approximates the exact
    marginals of 000 Eq. 16; with people-sized clouds (0.15 m) a third of r apart its
    marginals are within 0.05 of the enumeration (4^3 joint states)."""
    rng = np.random.default_rng(seed)
    centres = np.array([[0.0, 0.0], [0.35, 0.0], [0.15, 0.3]])
    xy = [c + rng.normal(0.0, 0.15, size=(4, 2)) for c in centres]
    w = [rng.random(4) + 0.2 for _ in range(3)]
    res = belief_propagation(xy, w, theta=1e-10, max_iterations=100)
    exact = brute_force_joint_prior(xy, w, 0.4, 1e-3)
    assert max(np.abs(a - b).max() for a, b in zip(res.weights, exact)) < 0.05
    prior = [wi / wi.sum() for wi in w]
    assert max(np.abs(a - b).max() for a, b in zip(exact, prior)) > 0.05   # not vacuous



def test_tracker_exclusion_radius_forbids_only_overlapping_bodies():
    """The tracker's default radius acts below the smallest distance at which two bodies of
    the shape model can stand: their thinnest horizontal extent, the width seen from the
    side (003 §2.1: s(pi/2) = 0.7 times the shoulder width, 0.35 m for the default 0.5 m).
    000's r = 0.4 m lies above it and forbids people standing one behind the other."""
    from mbtrack_ros.core.shape import BodyShape, width_scale
    from mbtrack_ros.core.tracker import TrackerConfig

    thinnest = float(width_scale(np.array([np.pi / 2]))[0]) * BodyShape().width
    assert thinnest == pytest.approx(0.35)
    assert TrackerConfig().mrf_radius <= thinnest


class _GaussianMeasurement:
    """Stand-in measurement: each target's log-likelihood is a Gaussian of width ``sigma``
    metres around its true floor position."""

    def __init__(self, truth, sigma):
        self.truth, self.sigma = truth, sigma

    def hjs(self, particles, weights, models):
        loglik = [-((p[:, :2] - self.truth[k]) ** 2).sum(axis=1) / (2 * self.sigma ** 2)
                  for k, p in enumerate(particles)]
        return SimpleNamespace(loglik=loglik, visible_fraction=None)


def _estimated_gap(radius, *, gap=0.45, sigma=0.05, seeds=2, steps=40):
    """Mean estimated distance of two HJS tracks of people standing ``gap`` metres apart,
    each measured to ``sigma`` metres (radius None: no MRF)."""
    from mbtrack_ros.core.filters import FilterConfig, HJSFilter

    estimates = []
    truth = [np.zeros(2), np.array([gap, 0.0])]
    measurement = _GaussianMeasurement(truth, sigma)
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        filt = HJSFilter(FilterConfig(particles=100, use_mrf=radius is not None,
                                      mrf_radius=radius or 0.3))
        for k in range(2):
            filt.add(k, object(), np.r_[truth[k], 0, 0, 0, 0], rng)
        for t in range(steps):
            out = filt.step(1 / 15, measurement, {}, rng)
            if t >= 10:
                estimates.append(out[1].mean[0] - out[0].mean[0])
    return float(np.mean(estimates))


def test_exclusion_leaves_well_measured_people_where_they_stand():
    """Two people 0.45 m apart (they can stand so: the model's bodies touch at 0.35 m front
    to back), each located to 5 cm: with the tracker's radius the MRF moves the estimated
    gap by under 5 mm; a potential as wide as the shoulders (0.5 m, the distance at which
    two bodies side by side touch) pushes them apart by centimetres, on the people who
    stand close in a crowd."""
    from mbtrack_ros.core.tracker import TrackerConfig

    free = _estimated_gap(None)
    assert abs(free - 0.45) < 0.005
    assert abs(_estimated_gap(TrackerConfig().mrf_radius) - free) < 0.005
    assert _estimated_gap(0.5) - free > 0.03


def _two_close_walkers(use_mrf, frames=30):
    """A detecting tracker (painted room, 4 side cameras and a ceiling camera) on two
    people walking side by side, 1.2 m apart, then closing in to 0.4 m centre to centre:
    per frame the reported (id, mean, existence, particles), the filter's clouds at the
    end and per frame the means the track management read."""
    from test_detection import FPS, _detecting_tracker, backgrounds, make_room, paint, person

    calib = make_room()
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=3, use_mrf=use_mrf)
    managed = []            # what the track management read, frame by frame
    update = tracker.detection.update

    def reading_update(stamp, images, tracks, models, **kwargs):
        managed.append({t.track_id: t.mean.copy() for t in tracks})
        return update(stamp, images, tracks, models, **kwargs)

    tracker.detection.update = reading_update
    yellow = ((215, 175, 145), (200, 190, 40), (150, 40, 120))
    out = []
    for k in range(frames):
        x, close = 2.0 + 0.04 * k, 0.02 * min(k, 20)
        people = [person(x, 2.0 + close, theta=0.0),
                  person(x, 3.2 - close, theta=0.0, colours=yellow)]
        res = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, people,
                                                           np.random.default_rng(k)))
        out.append([(t.track_id, t.mean.copy(), t.existence, t.particles) for t in res.tracks])
    clouds = {t: tracker.filter.cloud(t)[:2] for t in tracker.filter.track_ids()}
    return out, clouds, managed


def test_the_exclusion_changes_the_reported_estimates_and_not_the_tracks():
    """With automatic detection, two people walking side by side closer than the tracks'
    clouds spread: the MRF (000 Eq. 16-18) moves the reported estimates, and the track
    management, which reads each target's own posterior, decides as without it: the same
    tracks, existence probabilities and particle clouds frame by frame."""
    on, clouds_on, managed_on = _two_close_walkers(True)
    off, clouds_off, managed_off = _two_close_walkers(False)
    assert max(len(f) for f in on) == 2          # both people are tracks
    moved = 0.0
    for a, b in zip(on, off):
        assert [t[0] for t in a] == [t[0] for t in b]
        for (_, mean_a, ex_a, parts_a), (_, mean_b, ex_b, parts_b) in zip(a, b):
            assert ex_a == ex_b
            np.testing.assert_array_equal(parts_a, parts_b)
            moved = max(moved, float(np.abs(mean_a[:2] - mean_b[:2]).max()))
    assert moved > 1e-3                          # the MRF acted on the estimates
    # the track management read the targets' own posteriors, bit for bit as without it
    assert len(managed_on) == len(managed_off) == len(on)
    for a, b in zip(managed_on, managed_off):
        assert a.keys() == b.keys()
        for tid in a:
            np.testing.assert_array_equal(a[tid], b[tid])
    assert clouds_on.keys() == clouds_off.keys()
    for t in clouds_on:
        np.testing.assert_array_equal(clouds_on[t][0], clouds_off[t][0])
        np.testing.assert_array_equal(clouds_on[t][1], clouds_off[t][1])
