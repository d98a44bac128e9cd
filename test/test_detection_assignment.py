"""The automatic detection's one association step per frame: the optimal assignment of the
confirmed detections to tracks, births and drops (``core.detection.association``)."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from mbtrack_ros.core.detection.association import (
    BIRTH, DROP, PREFER_TRACK, assignment_costs, solve_assignment)
from mbtrack_ros.core.detection.config import AutoDetectionConfig
from mbtrack_ros.core.detection.likeness import AppearanceRatio


def _brute_force(llr: np.ndarray, birth: np.ndarray) -> float:
    """The largest summed log-likelihood ratio over every assignment of the N detections to
    one of: a track (each at most once, inside its gate), a birth or a drop (ratio 0)."""
    n, m = llr.shape
    best = -np.inf
    for choice in itertools.product(range(-2, m), repeat=n):
        used = [c for c in choice if c >= 0]
        if len(used) != len(set(used)):
            continue
        total = 0.0
        for i, c in enumerate(choice):
            if c == BIRTH:
                total += birth[i]
            elif c >= 0:
                if not np.isfinite(llr[i, c]):
                    break
                total += llr[i, c]
        else:
            best = max(best, total)
    return best


def _total(outcome: np.ndarray, llr: np.ndarray, birth: np.ndarray) -> float:
    return float(sum(birth[i] if c == BIRTH else 0.0 if c == DROP else llr[i, c]
                     for i, c in enumerate(outcome)))


@pytest.mark.parametrize('seed', range(60))
def test_the_assignment_is_the_best_of_all_assignments(seed):
    """On random ratio matrices (1-4 detections, 0-4 tracks, a third of the pairs outside
    their gate, births of either sign) the assignment's summed ratio equals the largest
    one found by enumerating every assignment, and it never uses a gated pair or a track
    twice."""
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(1, 5)), int(rng.integers(0, 5))
    llr = rng.normal(0.0, 4.0, size=(n, m))
    llr[rng.random((n, m)) < 0.33] = -np.inf
    birth = rng.normal(0.0, 3.0, size=n)
    outcome = solve_assignment(llr, birth)
    assert outcome.shape == (n,)
    used = [int(c) for c in outcome if c >= 0]
    assert len(used) == len(set(used)), outcome
    assert all(np.isfinite(llr[i, c]) for i, c in enumerate(outcome) if c >= 0), outcome
    assert all(c in (BIRTH, DROP) or 0 <= c < m for c in outcome), outcome
    assert _total(outcome, llr, birth) == pytest.approx(_brute_force(llr, birth), abs=1e-9)


def test_the_cost_matrix_has_one_birth_and_one_drop_column_per_detection():
    """Columns: tracks (-ratio; 1e9 outside the gate), then the births on a diagonal, then
    the drops (0) on a diagonal; every other entry 1e9."""
    llr = np.array([[1.5, -np.inf], [np.nan, -2.0]])
    cost = assignment_costs(llr, np.array([0.5, -1.0]))
    big = 1e9
    np.testing.assert_array_equal(cost, [[-1.5, big, -0.5, big, 0.0, big],
                                         [big, 2.0, big, 1.0, big, 0.0]])
    assert solve_assignment(np.zeros((0, 3)), np.zeros(0)).shape == (0,)
    np.testing.assert_array_equal(solve_assignment(np.zeros((2, 0)), np.array([1.0, -1.0])),
                                  [BIRTH, DROP])


def test_two_detections_competing_for_one_track_are_settled_by_the_total_ratio():
    """Detection 0 explains track 0 a little better than detection 1 does, but detection 1
    has nothing else (its birth is unlikely) while detection 0 is a likely birth: the
    assignment gives track 0 to detection 1 and a birth to detection 0, which a greedy
    choice in detection order would not."""
    llr = np.array([[5.0], [4.0]])
    birth = np.array([4.5, -1.0])
    np.testing.assert_array_equal(solve_assignment(llr, birth), [BIRTH, 0])


def test_a_scene_decided_by_the_cost_terms_the_way_a_person_would():
    """Four detections, a reported track A, a hidden track H and a lost track L, with the
    ratios built from the configuration's terms (``move_llr``, the appearance ratio of
    two models before any calibration sample, the detection's score against
    ``beside_threshold``):

    - d0, strong, 0.6 m from A, A's model explains it 2 nats better than A's own place:
      A drifted off its person - move A;
    - d1, strong, 1.3 m from where L was released, looking like L (appearance distance
      0.15): L's person re-found - reuse L;
    - d2, strong, far from every track, unlike L: a newcomer - birth;
    - d3, weak (score 1.5), beside A, which explains it worse than its own place: the
      fringe of A's person - drop. H (hidden, its person lost) is 3 m away, outside its
      gate, and takes nothing."""
    cfg = AutoDetectionConfig()
    ratio = AppearanceRatio(cfg.clutter_distance, 0.12).llr
    strong, weak = 6.0, 1.5
    e = np.array([strong - cfg.beside_threshold, strong, strong,
                  weak - cfg.beside_threshold])
    base = np.maximum(e, 0.0) + PREFER_TRACK
    inf = -np.inf
    a_d0 = e[0] + cfg.move_llr(strong, 2.0, ratio(0.6)) + PREFER_TRACK
    a_d3 = e[3] + cfg.move_llr(weak, -1.0, ratio(0.2)) + PREFER_TRACK
    l_d1 = base[1] + max(ratio(0.15), 0.0)
    l_d2 = base[2] + max(ratio(0.7), 0.0)     # 0: unlike, not in L's gate
    assert l_d2 == base[2] and ratio(0.15) > 0
    #                  A     H    L
    llr = np.array([[a_d0, inf, inf],
                    [inf, inf, l_d1],
                    [inf, inf, inf],
                    [a_d3, inf, inf]])
    outcome = solve_assignment(llr, e)
    assert outcome.tolist() == [0, 2, BIRTH, DROP]
    # the same detection 0.2 m nearer A but with A's model explaining it worse than A's
    # own place and looking unlike A: a second person beside A - birth
    llr[0, 0] = e[0] + cfg.move_llr(strong, -1.0, ratio(0.8)) + PREFER_TRACK
    assert solve_assignment(llr, e)[0] == BIRTH
    # a look-alike of A (0.2): a track left behind where its person turned - move A
    llr[0, 0] = e[0] + cfg.move_llr(strong, -1.0, ratio(0.2)) + PREFER_TRACK
    assert solve_assignment(llr, e)[0] == 0


def test_a_lost_track_takes_back_a_person_near_its_place_who_does_not_look_unlike_it():
    """The ratio of a lost track's hypothesis: the place term (:func:`place_llr`, a 2-D
    Gaussian of half the gate's radius against a birth anywhere on the floor) plus the
    appearance ratio of the two models, negative for unlike ones. The place term against
    its closed form (and integrating the Gaussian over a large floor gives 1: a density);
    then a person re-found 0.3 m from where a track was lost moments ago is its person
    even with models a little beyond the clutter distance apart (0.53: two views of one
    person), not somebody dressed otherwise (0.75), and not at the gate's edge with
    that distance."""
    from mbtrack_ros.core.detection.association import place_llr

    ratio = AppearanceRatio(AutoDetectionConfig().clutter_distance, 0.12).llr
    area, gate = 30.0, 1.6
    sd = gate / 2
    for d in (0.0, 0.3, 1.0, gate):
        want = np.log(area / (2 * np.pi * sd ** 2)) - d ** 2 / (2 * sd ** 2)
        assert place_llr(d, gate, area) == pytest.approx(want)
    xs = np.linspace(-6, 6, 601)
    g = np.exp([[place_llr(np.hypot(x, y), gate, area) for x in xs] for y in xs]) / area
    assert g.sum() * (xs[1] - xs[0]) ** 2 == pytest.approx(1.0, rel=1e-3)

    def lost(metres, unlike):
        return place_llr(metres, gate, area) + ratio(unlike)

    birth = np.array([2.0, 2.0, 2.0])
    base = np.maximum(birth, 0.0) + PREFER_TRACK
    for u, metres, reused in ((0.53, 0.3, True), (0.75, 0.3, False), (0.53, gate, False)):
        value = lost(metres, u)
        llr = np.array([[base[0] + value if value > 0 else -np.inf]])
        outcome = solve_assignment(llr, birth[:1])
        assert (outcome[0] == 0) == reused, (u, metres, value)
