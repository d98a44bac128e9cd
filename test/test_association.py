"""Tests of the data-association baselines (004): Kalman, sampling, PDAF, JPDAF, JLF."""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import pytest

from mbtrack_ros.core.association import jlf, jpdaf, kalman, pdaf, sampling
from mbtrack_ros.core.association.kalman import AssociationError
from mbtrack_ros.core.state import STATE_DIM

R2 = np.diag([0.05 ** 2, 0.05 ** 2])


def _prediction(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    mean = np.array([2.0, 1.5, 0.6, -0.3])
    a = rng.normal(size=(4, 4)) * 0.1
    return mean, a @ a.T + np.diag([0.02, 0.03, 0.1, 0.1])


# -- Kalman filter -------------------------------------------------------------------------
def test_kalman_predict_is_constant_velocity_with_white_acceleration() -> None:
    mean = np.array([1.0, 2.0, 0.5, -1.0])
    m, P = kalman.predict(mean, np.zeros((4, 4)), 0.5, accel_std=2.0, position_std=0.3)
    np.testing.assert_allclose(m, [1.25, 1.5, 0.5, -1.0])
    q = 4.0
    np.testing.assert_allclose(P[0, 0], q * 0.5 ** 3 / 3 + 0.09 * 0.5)
    np.testing.assert_allclose(P[0, 2], q * 0.5 ** 2 / 2)
    np.testing.assert_allclose(P[2, 2], q * 0.5)
    assert P[0, 1] == 0.0 and P[0, 3] == 0.0
    # vectorised over targets equals the loop
    means = np.stack([mean, mean + 1.0])
    covs = np.stack([np.eye(4), 2 * np.eye(4)])
    vm, vP = kalman.predict(means, covs, 0.2, accel_std=1.0)
    for k in range(2):
        lm, lP = kalman.predict(means[k], covs[k], 0.2, accel_std=1.0)
        np.testing.assert_allclose(vm[k], lm)
        np.testing.assert_allclose(vP[k], lP)


def test_kalman_converges_on_noiseless_constant_velocity_data() -> None:
    truth = np.array([0.5, 4.0, 0.8, -0.4])
    mean = np.array([1.5, 3.0, 0.0, 0.0])
    cov = np.diag([1.0, 1.0, 1.0, 1.0])
    dt = 0.1
    for step in range(100):
        truth = kalman.transition_matrix(dt) @ truth
        mean, cov = kalman.predict(mean, cov, dt, accel_std=0.3)
        mean, cov = kalman.update(mean, cov, truth[:2], R2)
    np.testing.assert_allclose(mean, truth, atol=0.02)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert kalman.nees(mean - truth, cov) < 20.0
    assert cov[0, 0] < 0.05 ** 2  # better than one measurement


def test_kalman_rejects_bad_input() -> None:
    with pytest.raises(AssociationError):
        kalman.predict(np.zeros(3), np.eye(3), 0.1, accel_std=1.0)
    with pytest.raises(AssociationError):
        kalman.predict(np.zeros(4), np.eye(4), -1.0, accel_std=1.0)
    with pytest.raises(AssociationError):
        kalman.gate_threshold(1.0)
    with pytest.raises(AssociationError):
        kalman.update(np.zeros(4), np.eye(4), np.zeros(3), R2)


# -- PDAF -----------------------------------------------------------------------------------
@pytest.mark.parametrize('offset', [(0.0, 0.0), (0.05, -0.08)])
def test_pdaf_with_one_measurement_and_no_clutter_is_the_kalman_update(offset) -> None:
    mean, cov = _prediction(np.random.default_rng(3))
    z = mean[:2] + np.asarray(offset)
    km, kP = kalman.update(mean, cov, z, R2)
    for density in (0.0, 1e-12):
        res = pdaf.pdaf_update(mean, cov, z[None], R2, p_detect=1.0, p_gate=0.99,
                               clutter_density=density)
        assert res.beta0 < 1e-9
        np.testing.assert_allclose(res.beta, [1.0], atol=1e-9)
        np.testing.assert_allclose(res.mean, km, atol=1e-9)
        np.testing.assert_allclose(res.cov, kP, atol=1e-9)


@pytest.mark.parametrize('density', [0.0, 0.1, 3.0])
@pytest.mark.parametrize('p_detect', [0.7, 1.0])
def test_pdaf_betas_sum_to_one_and_follow_the_likelihood_ratio(density, p_detect) -> None:
    rng = np.random.default_rng(5)
    mean, cov = _prediction(rng)
    z = mean[:2] + rng.normal(scale=0.15, size=(5, 2))
    z[4] = mean[:2] + 50.0  # far outside the gate
    res = pdaf.pdaf_update(mean, cov, z, R2, p_detect=p_detect, p_gate=0.99,
                           clutter_density=density)
    assert res.beta0 + res.beta.sum() == pytest.approx(1.0)
    assert res.beta[4] == 0.0 and not res.gated[4]
    S = kalman.innovation_covariance(cov, R2)
    g = np.array([np.exp(-0.5 * (zi - mean[:2]) @ np.linalg.solve(S, zi - mean[:2]))
                  for zi in z[:4]])
    inside = res.gated[:4]
    ratio = res.beta[:4][inside] / res.beta[:4][inside][0]
    np.testing.assert_allclose(ratio, g[inside] / g[inside][0], rtol=1e-9)
    # beta_0 against the closed form b / (b + sum e_i) with b = lambda |2 pi S|^0.5 (1-PdPg)/Pd
    b = density * np.sqrt(np.linalg.det(2 * np.pi * S)) * (1 - p_detect * 0.99) / p_detect
    assert res.beta0 == pytest.approx(b / (b + g[inside].sum()), rel=1e-9)
    assert np.all(np.linalg.eigvalsh(res.cov) > 0)
    if density > 0:  # missing-target hypothesis inflates the covariance
        P_c = kalman.update(mean, cov, z[0], R2)[1]
        assert np.trace(res.cov) > np.trace(P_c)


def test_pdaf_without_measurements_keeps_the_prediction() -> None:
    mean, cov = _prediction(np.random.default_rng(1))
    res = pdaf.pdaf_update(mean, cov, np.zeros((0, 2)), R2, p_detect=0.9, p_gate=0.99,
                           clutter_density=0.0)
    assert res.beta0 == 1.0
    np.testing.assert_allclose(res.mean, mean)
    np.testing.assert_allclose(res.cov, cov)
    with pytest.raises(AssociationError):
        pdaf.pdaf_update(mean, cov, np.zeros((2, 2)), R2, p_detect=1.5, p_gate=0.99,
                         clutter_density=0.0)
    with pytest.raises(AssociationError):
        pdaf.pdaf_update(mean, cov, np.full((1, 2), np.nan), R2, p_detect=0.9, p_gate=0.99,
                         clutter_density=0.0)


# -- JPDAF ----------------------------------------------------------------------------------
def _brute_force_jpdaf(means, covs, z, p_detect, p_gate, density):
    """All (M+1)^K assignments with itertools; keep the feasible gated ones."""
    K, M = len(means), len(z)
    gamma = kalman.gate_threshold(p_gate)
    events, weights = [], []
    for a in itertools.product(range(-1, M), repeat=K):
        used = [j for j in a if j >= 0]
        if len(used) != len(set(used)):
            continue  # one measurement for two targets
        w = 1.0
        ok = True
        for t, j in enumerate(a):
            if j < 0:
                w *= density * (1 - p_detect * p_gate)
                continue
            S = covs[t][:2, :2] + R2
            nu = z[j] - means[t][:2]
            d2 = nu @ np.linalg.solve(S, nu)
            if d2 > gamma:
                ok = False
                break
            w *= p_detect * np.exp(-0.5 * d2) / np.sqrt(np.linalg.det(2 * np.pi * S))
        if ok:
            events.append(a)
            weights.append(w)
    weights = np.asarray(weights)
    return events, weights / weights.sum()


@pytest.mark.parametrize('K,M,seed', [(2, 3, 0), (2, 4, 1), (3, 3, 2), (3, 4, 3), (3, 4, 4)])
def test_jpdaf_events_and_marginals_equal_brute_force(K, M, seed) -> None:
    rng = np.random.default_rng(seed)
    means = np.column_stack([rng.uniform(0, 0.6, size=(K, 2)), rng.normal(size=(K, 2))])
    covs = np.stack([np.diag([0.04, 0.04, 0.2, 0.2])] * K)
    z = rng.uniform(-0.1, 0.7, size=(M, 2))
    res = jpdaf.jpdaf_update(means, covs, z, R2, p_detect=0.9, p_gate=0.99,
                             clutter_density=0.5)
    events, probs = _brute_force_jpdaf(means, covs, z, 0.9, 0.99, 0.5)
    assert len(events) > K + 1  # the case is not trivial
    got = {tuple(int(v) for v in e): p for e, p in zip(res.events, res.probabilities)}
    assert set(got) == set(events)
    for e, p in zip(events, probs):
        assert got[e] == pytest.approx(p, rel=1e-9, abs=1e-15)
    # no event assigns one measurement to two targets
    for e in res.events:
        used = e[e >= 0]
        assert len(used) == len(set(used.tolist()))
    beta = np.zeros((K, M))
    beta0 = np.zeros(K)
    for e, p in zip(events, probs):
        for t, j in enumerate(e):
            if j < 0:
                beta0[t] += p
            else:
                beta[t, j] += p
    np.testing.assert_allclose(res.beta, beta, atol=1e-12)
    np.testing.assert_allclose(res.beta0, beta0, atol=1e-12)
    np.testing.assert_allclose(res.beta.sum(axis=1) + res.beta0, 1.0)
    # a measurement's total association probability can not exceed one
    assert np.all(res.beta.sum(axis=0) <= 1.0 + 1e-12)


def test_jpdaf_with_one_target_is_the_pdaf() -> None:
    rng = np.random.default_rng(9)
    mean, cov = _prediction(rng)
    z = mean[:2] + rng.normal(scale=0.1, size=(4, 2))
    single = pdaf.pdaf_update(mean, cov, z, R2, p_detect=0.8, p_gate=0.99,
                              clutter_density=0.3)
    joint = jpdaf.jpdaf_update(mean[None], cov[None], z, R2, p_detect=0.8, p_gate=0.99,
                               clutter_density=0.3)
    np.testing.assert_allclose(joint.beta[0], single.beta, atol=1e-12)
    np.testing.assert_allclose(joint.means[0], single.mean, atol=1e-12)
    np.testing.assert_allclose(joint.covs[0], single.cov, atol=1e-12)


def test_jpdaf_gating_prunes_events() -> None:
    # two well separated targets, each with two nearby measurements
    means = np.array([[0.0, 0.0, 0, 0], [3.0, 0.0, 0, 0]], dtype=float)
    covs = np.stack([np.diag([0.01, 0.01, 0.1, 0.1])] * 2)
    z = np.array([[0.02, 0.0], [-0.03, 0.02], [3.01, 0.0], [2.97, -0.02]])
    res = jpdaf.jpdaf_update(means, covs, z, R2, p_detect=0.9, p_gate=0.99,
                             clutter_density=0.1)
    assert res.gated.tolist() == [[True, True, False, False], [False, False, True, True]]
    assert len(res.events) == 3 * 3  # (1 + 2 gated) per target, no conflicts
    ungated = jpdaf.enumerate_events(np.ones((2, 4), dtype=bool))
    assert len(ungated) == 1 + 4 + 4 + 4 * 3  # both missed, one detected, both detected
    assert np.all(res.beta[0, 2:] == 0) and np.all(res.beta[1, :2] == 0)
    with pytest.raises(AssociationError):
        jpdaf.enumerate_events(np.ones((6, 8), dtype=bool), max_events=1000)


def test_jpdaf_resolves_a_shared_measurement() -> None:
    # two targets both close to measurement 0; measurement 1 only fits target 1: exclusion
    # makes target 0 take measurement 0 and target 1 take measurement 1.
    means = np.array([[0.0, 0.0, 0, 0], [0.1, 0.0, 0, 0]], dtype=float)
    covs = np.stack([np.diag([0.02, 0.02, 0.1, 0.1])] * 2)
    z = np.array([[0.02, 0.0], [0.3, 0.0]])
    res = jpdaf.jpdaf_update(means, covs, z, R2, p_detect=0.95, p_gate=0.999,
                             clutter_density=0.01)
    single = pdaf.pdaf_update(means[1], covs[1], z, R2, p_detect=0.95, p_gate=0.999,
                              clutter_density=0.01)
    assert res.beta[1, 1] > single.beta[1]
    assert res.beta[0, 0] > res.beta[0, 1] and res.beta[1, 1] > res.beta[1, 0]


# -- measurement sampling -------------------------------------------------------------------
def _bump_score(peaks, widths, heights=None):
    peaks = np.atleast_2d(peaks)
    heights = np.zeros(len(peaks)) if heights is None else np.asarray(heights)

    def score(states):
        d2 = ((states[:, None, :2] - peaks[None]) ** 2).sum(axis=2)
        return np.max(heights - 0.5 * d2 / np.asarray(widths) ** 2, axis=1)
    return score


def test_suppress_is_greedy_minimum_separation() -> None:
    rng = np.random.default_rng(2)
    pos = rng.uniform(0, 2, size=(200, 2))
    ll = rng.normal(size=200)
    ll[7] = np.nan
    keep = sampling.suppress(pos, ll, radius=0.3)
    assert 7 not in keep
    d = np.hypot(*(pos[keep][:, None] - pos[keep][None]).transpose(2, 0, 1))
    assert np.all(d[~np.eye(len(keep), dtype=bool)] > 0.3)
    assert np.all(np.diff(ll[keep]) <= 0)
    for i in set(range(200)) - set(keep.tolist()) - {7}:  # each dropped one has a better
        near = keep[np.hypot(*(pos[keep] - pos[i]).T) <= 0.3]  # kept neighbour
        assert near.size and ll[near].max() >= ll[i]
    assert len(sampling.suppress(pos, ll, radius=0.3, max_keep=3)) == 3


def test_measurement_sampling_finds_the_likelihood_peak() -> None:
    rng = np.random.default_rng(0)
    mean = np.array([1.0, 1.0, 0.5, 0.0, 0.3, 0.0])
    cov = np.diag([0.04, 0.04, 0.1, 0.1])
    peak = np.array([1.12, 0.93])
    score = _bump_score(peak, 0.1)
    raw = sampling.measurement_sampling(mean, cov, score, rng, n_samples=100, n_keep=5,
                                        radius=0.05)
    assert 1 <= len(raw.loglik) <= 5 and np.all(np.diff(raw.loglik) <= 0)
    assert np.all(raw.states[:, 4] == 0.0)  # heading of the predicted velocity (+x)
    refined = sampling.measurement_sampling(mean, cov, score, np.random.default_rng(0),
                                            n_samples=100, n_keep=5, radius=0.05, refine=True)
    assert np.linalg.norm(refined.positions[0] - peak) < 0.01
    assert refined.loglik[0] >= raw.loglik[0]
    with pytest.raises(AssociationError):
        sampling.measurement_sampling(mean, cov, lambda s: np.zeros(3), rng, n_samples=10)


def test_joint_measurements_give_one_measurement_per_peak() -> None:
    rng = np.random.default_rng(4)
    peaks = np.array([[1.0, 1.0], [1.6, 1.0]])
    score = _bump_score(peaks, 0.12)
    means = np.array([[1.05, 1.0, 0, 0, 0, 0], [1.5, 1.05, 0, 0, 0, 0]], dtype=float)
    covs = np.stack([np.diag([0.05, 0.05, 0.1, 0.1])] * 2)
    meas = jpdaf.joint_measurements(means, covs, [score, score], rng, n_samples=60,
                                    n_keep=5, separation=0.3, refine=True)
    assert len(meas.loglik) == 2
    d = np.hypot(*(meas.positions[:, None] - peaks[None]).transpose(2, 0, 1))
    assert np.all(d.min(axis=0) < 0.02)


# -- JLF ------------------------------------------------------------------------------------
def test_distinct_orders_only_order_overlapping_pairs() -> None:
    none = np.zeros((3, 3), dtype=bool)
    assert len(jlf.distinct_orders(none)) == 1
    pair = none.copy()
    pair[0, 1] = pair[1, 0] = True
    orders = jlf.distinct_orders(pair)
    assert len(orders) == 2
    assert {tuple(o).index(0) < tuple(o).index(1) for o in orders} == {True, False}
    chain = pair.copy()
    chain[1, 2] = chain[2, 1] = True
    assert len(jlf.distinct_orders(chain)) == 4  # acyclic orientations of a path
    assert len(jlf.distinct_orders(~np.eye(3, dtype=bool))) == 6


class _Painter:
    """A masked joint likelihood built independently of jlf: each person is an image
    rectangle (foot to head, width from depth), painted back to front; the score counts
    pixels whose painted label differs from an observed label image."""

    def __init__(self, cameras, height=1.7, width=0.5):
        self.cameras = cameras
        self.height, self.width = height, width
        self.observed = None
        self.calls = 0

    def rects(self, cam, states):
        foot = np.column_stack([states[:, :2], np.zeros(len(states))])
        head = foot + [0.0, 0.0, self.height]
        u0, u1 = cam.project(foot), cam.project(head)
        half = 0.5 * cam.focal * self.width / cam.depth(foot)
        return np.column_stack([u0[:, 0] - half, u1[:, 1], u0[:, 0] + half, u0[:, 1]])

    def paint(self, cam, states, order):
        v, u = np.mgrid[0:cam.height, 0:cam.width]
        label = np.zeros((cam.height, cam.width), dtype=int)
        rect = self.rects(cam, states)
        for t in order[::-1]:  # back to front
            x0, y0, x1, y1 = rect[t]
            label[(u >= x0) & (u <= x1) & (v >= y0) & (v <= y1)] = t + 1
        return label

    def observe(self, states, orders):
        self.observed = [self.paint(c, states, o) for c, o in zip(self.cameras, orders)]

    def __call__(self, joint_states, orders):
        self.calls += len(joint_states)
        out = np.zeros(len(joint_states))
        for r in range(len(joint_states)):
            for c, cam in enumerate(self.cameras):
                label = self.paint(cam, joint_states[r], orders[r, c])
                out[r] -= 0.01 * np.count_nonzero(label != self.observed[c])
        return out


def _two_in_line(room):
    cams = list(room.cameras.values())
    c0 = cams[0].center[:2]
    d = np.array([3.0, 2.5]) - c0
    d /= np.linalg.norm(d)
    perp = np.array([-d[1], d[0]])
    states = np.zeros((2, STATE_DIM))
    states[0, :2] = c0 + 2.2 * d + 0.12 * perp  # nearer to cam0
    states[1, :2] = c0 + 3.6 * d
    return cams, states


@pytest.mark.parametrize('front', [0, 1])
def test_jlf_picks_the_painted_occluder_in_front(room, front) -> None:
    cams, truth = _two_in_line(room)
    painter = _Painter(cams)
    order0 = np.array([front, 1 - front])
    geometric = jlf.geometric_orders(truth[None], cams, np.full(2, 1.7))[0]
    assert geometric[0].tolist() == [0, 1]  # person 0 is physically nearer to cam0
    observed_orders = geometric.copy()
    observed_orders[0] = order0  # paint person `front` in front in cam0, whatever geometry
    painter.observe(truth, observed_orders)
    boxes = jlf.silhouette_boxes(truth[None], cams[0], np.full(2, 1.7), np.full(2, 0.5))
    assert jlf.overlaps(boxes)[0, 0, 1]
    covs = np.stack([np.diag([0.01, 0.01, 0.1, 0.1])] * 2)
    res = jlf.jlf_measurement(truth, covs, painter, cams, np.full(2, 1.7), np.full(2, 0.5),
                              np.random.default_rng(0), n_samples=8)
    assert res.orders[0].tolist() == order0.tolist()
    np.testing.assert_allclose(res.states[:, :2], truth[:, :2], atol=0.15)


def test_best_orders_equals_brute_force_over_all_permutations(room) -> None:
    cams, truth = _two_in_line(room)
    third = truth[1].copy()
    third[:2] += [0.25, -0.3]
    base = np.vstack([truth, third])  # (3, 6)
    painter = _Painter(cams)
    painter.observe(base, [np.array([2, 0, 1]), np.array([1, 2, 0])])
    rng = np.random.default_rng(6)
    js = base[None] + np.concatenate([rng.normal(scale=0.15, size=(4, 3, 2)),
                                      np.zeros((4, 3, 4))], axis=2)
    heights, widths = np.full(3, 1.7), np.full(3, 0.5)
    orders, loglik, n_eval = jlf.best_orders(js, painter, cams, heights, widths)
    perms = list(itertools.permutations(range(3)))
    for i in range(len(js)):
        combos = list(itertools.product(perms, perms))
        all_orders = np.array(combos)  # (36, 2, 3)
        brute = painter(np.repeat(js[i][None], len(combos), axis=0), all_orders)
        assert loglik[i] == pytest.approx(brute.max())
        assert painter(js[i][None], orders[i][None])[0] == pytest.approx(brute.max())
    assert n_eval < len(js) * 36  # distinct orders only, camera by camera


# -- filters behind the tracker interface (stand-in measurement model) ----------------------
@dataclass
class _Person:
    index: int
    height: float = 1.7
    width: float = 0.5


@dataclass
class _Result:
    loglik: list
    visible_fraction: np.ndarray


class _StandIn:
    """Log-likelihood = Gaussian bump of width 0.15 m around each person's true position
    (in every camera); joint = sum of the components; hjs reports visible fraction 0.5."""

    def __init__(self, n_cameras: int) -> None:
        self.truth = np.zeros((0, 2))
        self.sitting = np.zeros(2)
        self.n_cameras = n_cameras
        self.joint_orders_seen = False

    def set_images(self, images) -> None:
        pass

    def _ll(self, states, model):
        d2 = ((states[..., :2] - self.truth[model.index]) ** 2).sum(axis=-1)
        wrong_posture = np.round(states[..., 5]) != self.sitting[model.index]
        return -0.5 * d2 / 0.15 ** 2 - 4.0 * wrong_posture

    def separable(self, particles, models):
        return _Result([self._ll(p, m) for p, m in zip(particles, models)],
                       np.ones((len(models), self.n_cameras)))

    def hjs(self, particles, weights, models):
        return _Result([self._ll(p, m) for p, m in zip(particles, models)],
                       np.full((len(models), self.n_cameras), 0.5))

    def joint(self, joint_particles, models, *, orders=None):
        assert orders is not None and orders.shape == joint_particles.shape[:1] + (
            self.n_cameras, len(models))
        self.joint_orders_seen = True
        return sum(self._ll(joint_particles[:, k], m) for k, m in enumerate(models))


@pytest.mark.parametrize('algorithm', ['pdaf', 'jpdaf', 'jlf'])
def test_association_filters_track_through_the_tracker(room, algorithm) -> None:
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig
    standin = _StandIn(len(room.cameras))
    tracker = Tracker(room, TrackerConfig(algorithm=algorithm, particles=40, seed=3),
                      measurement=standin)
    assert tracker.filter.name == algorithm
    start = np.array([[1.0, 1.0], [4.5, 3.5]])
    vel = np.array([[0.8, 0.4], [-0.6, -0.2]])
    ids = []
    for k in range(2):
        state = np.zeros(STATE_DIM)
        state[:2] = start[k] + [0.1, -0.1]  # initialised 14 cm off, no velocity
        ids.append(tracker.add_track(_Person(k), state, 0))
    for frame in range(1, 31):
        standin.truth = start + vel * frame * 0.1
        result = tracker.step(int(frame * 1e8), {})
    assert [t.track_id for t in result.tracks] == ids
    for k, est in enumerate(result.tracks):
        assert np.linalg.norm(est.mean[:2] - standin.truth[k]) < 0.1
        assert np.linalg.norm(est.mean[2:4] - vel[k]) < 0.3
        assert est.covariance.shape == (4, 4) and est.particles is None
        assert set(est.visible_fraction.values()) == {0.5}
    assert standin.joint_orders_seen == (algorithm == 'jlf')
    for est in result.tracks:
        assert est.mean[5] < 0.2  # standing
    # person 1 stops and sits down: the sitting probability follows within 10 frames
    standin.sitting[1] = 1.0
    for frame in range(31, 41):
        standin.truth[0] += vel[0] * 0.1
        result = tracker.step(int(frame * 1e8), {})
    assert result.tracks[1].mean[5] > 0.8 and result.tracks[0].mean[5] < 0.2
    assert np.linalg.norm(result.tracks[1].mean[:2] - standin.truth[1]) < 0.15
    tracker.remove_track(ids[0])
    assert tracker.track_ids == ids[1:]


@pytest.mark.parametrize('density', [0.0, 0.4])
def test_pdaf_update_is_the_moment_matched_mixture_of_kalman_updates(density) -> None:
    rng = np.random.default_rng(11)
    mean, cov = _prediction(rng)
    z = mean[:2] + rng.normal(scale=0.12, size=(4, 2))
    res = pdaf.pdaf_update(mean, cov, z, R2, p_detect=0.85, p_gate=0.995,
                           clutter_density=density)
    assert np.all(res.gated)
    comps = [(mean, cov)] + [kalman.update(mean, cov, zi, R2) for zi in z]
    w = np.concatenate([[res.beta0], res.beta])
    mix_mean = sum(wi * m for wi, (m, _) in zip(w, comps))
    mix_cov = sum(wi * (P + np.outer(m - mix_mean, m - mix_mean)) for wi, (m, P) in zip(w, comps))
    np.testing.assert_allclose(res.mean, mix_mean, atol=1e-12)
    np.testing.assert_allclose(res.cov, mix_cov, atol=1e-10)


# -- JLF with the real measurement model on a painted image ---------------------------------
_COLOURS = {0: [(230, 40, 40), (200, 30, 30), (150, 20, 20)],  # person 0: reds per part
            1: [(40, 40, 230), (30, 200, 30), (220, 220, 40)]}  # person 1: blue/green/yellow


def _uniform_model(k: int):
    from mbtrack_ros.core.appearance import PersonModel, quantize
    hists = np.zeros((1, 3, 512))
    for part, rgb in enumerate(_COLOURS[k]):
        hists[0, part, int(quantize(np.array([[rgb]], dtype=np.uint8))[0, 0])] = 1.0
    return PersonModel(height=1.7, width=0.5, view_angles=[0.0], histograms=hists)


@pytest.mark.parametrize('front', [0, 1])
def test_jlf_with_the_measurement_model_picks_the_painted_occluder(room, front) -> None:
    from mbtrack_ros.core.likelihood import LikelihoodConfig, MeasurementModel
    cams, truth = _two_in_line(room)
    mm = MeasurementModel(room, LikelihoodConfig())
    models = [_uniform_model(0), _uniform_model(1)]
    name = cams[0].name
    image = np.full((cams[0].height, cams[0].width, 3), 128, dtype=np.uint8)
    for k in (1 - front, front):  # back to front
        labels = mm.render_labels(name, truth[k], models[k])
        for part in range(3):
            image[labels == part + 1] = _COLOURS[k][part]
    assert np.any(np.all(image == _COLOURS[0][1], axis=2))  # both partly visible
    assert np.any(np.all(image == _COLOURS[1][1], axis=2))
    mm.set_images({name: image})

    def joint_score(js, orders):
        return mm.joint(js, models, orders=orders)

    covs = np.stack([np.diag([0.003, 0.003, 0.1, 0.1])] * 2)
    res = jlf.jlf_measurement(truth, covs, joint_score, cams, np.full(2, 1.7),
                              np.full(2, 0.5), np.random.default_rng(1), n_samples=10)
    assert res.orders[0].tolist() == [front, 1 - front]
    # cam1 has no image: skipping it gives the same answer with fewer evaluations
    lean = jlf.jlf_measurement(truth, covs, joint_score, cams, np.full(2, 1.7),
                               np.full(2, 0.5), np.random.default_rng(1), n_samples=10,
                               active=[True, False])
    assert lean.orders[0].tolist() == [front, 1 - front]
    assert lean.evaluations < res.evaluations
    # the chosen order scores better than the other one for the chosen joint sample
    other = res.orders.copy()
    other[0] = other[0][::-1]
    assert res.loglik > joint_score(res.states[None], other[None])[0]


def test_association_config_validation_and_tracker_defaults() -> None:
    from mbtrack_ros.core.association.filters import AssociationConfig
    from mbtrack_ros.core.tracker import TrackerConfig
    for bad in (dict(p_gate=1.0), dict(p_detect=0.0), dict(samples=0), dict(kept=True),
                dict(clutter_density=-1.0), dict(measurement_std=0.0)):
        with pytest.raises(AssociationError):
            AssociationConfig(**bad)
    cfg = AssociationConfig.from_tracker(TrackerConfig(particles=37), kept=2)
    assert (cfg.samples, cfg.kept) == (37, 2)
    assert cfg.accel_std == TrackerConfig().motion.velocity_noise
    np.testing.assert_allclose(cfg.R, cfg.measurement_std ** 2 * np.eye(2))


def test_sampling_explores_both_postures() -> None:
    mean = np.array([1.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    cov = np.diag([0.01, 0.01, 0.1, 0.1])
    rng = np.random.default_rng(8)
    copied = sampling.sample_states(mean, cov, 2000, rng)
    assert np.all(copied[:, 5] == 0.0)
    explored = sampling.sample_states(mean, cov, 2000, rng, sit_explore=0.1)
    assert set(np.unique(explored[:, 5])) == {0.0, 1.0}
    assert abs(explored[:, 5].mean() - 0.1) < 0.03
    mean[5] = 0.7
    assert abs(sampling.sample_states(mean, cov, 2000, rng, sit_explore=0.1)[:, 5].mean()
               - 0.7) < 0.04
    with pytest.raises(AssociationError):
        sampling.sample_states(mean, cov, 10, rng, sit_explore=0.6)


def test_posture_update_is_a_two_state_bayes_filter() -> None:
    ll = sampling.posture_loglik(np.array([0.0, 1.0, 0.0, 1.0]), np.array([-3.0, -2.0, -1.0,
                                                                           np.nan]))
    np.testing.assert_allclose(ll, [-1.0, -2.0])
    assert sampling.posture_update(0.5, np.array([0.0, np.log(3.0)])) == pytest.approx(0.75)
    assert sampling.posture_update(0.2, np.array([np.log(2.0), 0.0])) == pytest.approx(
        0.2 / (0.2 + 0.8 * 2.0))
    # a posture that was not sampled carries no evidence
    assert sampling.posture_update(0.3, np.array([-1.0, -np.inf])) == pytest.approx(0.3)
    np.testing.assert_allclose(sampling.posture_update(np.array([0.0, 1.0]), np.zeros((2, 2))),
                               [1e-4, 1 - 1e-4])
