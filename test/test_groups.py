"""The groups of the grouped HJS filter: which targets the exclusion prior couples."""
from __future__ import annotations

import numpy as np
import pytest

from mbtrack_ros.core.groups import GroupError, interaction_groups, violation_mass


def _cloud(center, n, spread, rng):
    return np.asarray(center, float) + rng.normal(0.0, spread, size=(n, 2))


def test_violation_mass_is_the_double_sum_over_particle_pairs():
    rng = np.random.default_rng(0)
    a, b = _cloud([0, 0], 7, 0.2, rng), _cloud([0.3, 0], 5, 0.2, rng)
    wa, wb = rng.random(7), rng.random(5)
    brute = 0.0
    for i in range(7):
        for j in range(5):
            if np.hypot(*(a[i] - b[j])) <= 0.4:
                brute += wa[i] / wa.sum() * wb[j] / wb.sum()
    assert violation_mass(a, wa, b, wb, 0.4) == pytest.approx(brute, abs=1e-12)
    assert 0.0 < brute < 1.0


def test_clouds_farther_apart_than_the_radius_are_separable():
    rng = np.random.default_rng(1)
    a, b = _cloud([0, 0], 50, 0.05, rng), _cloud([2.0, 0], 50, 0.05, rng)
    w = np.ones(50)
    assert violation_mass(a, w, b, w, 0.4) == 0.0
    assert interaction_groups([a, b], [w, w], 0.4) == []
    # a single particle within r couples them: the potential is not 1 on the support
    b[0] = a[0] + [0.39, 0.0]
    assert interaction_groups([a, b], [w, w], 0.4) == [[0, 1]]
    # ... unless it has no weight
    wb = w.copy()
    wb[0] = 0.0
    assert interaction_groups([a, b], [w, wb], 0.4) == []


def test_groups_are_capped_keeping_the_strongest_couplings():
    rng = np.random.default_rng(2)
    w = np.ones(80)
    # a chain 0 - 1 - 2: 0 and 1 overlap strongly, 1 and 2 barely
    clouds = [_cloud([0, 0], 80, 0.05, rng), _cloud([0.2, 0], 80, 0.05, rng),
              _cloud([0.65, 0], 80, 0.05, rng)]
    v01 = violation_mass(clouds[0], w, clouds[1], w, 0.4)
    v12 = violation_mass(clouds[1], w, clouds[2], w, 0.4)
    assert v01 > v12 > 0
    assert violation_mass(clouds[0], w, clouds[2], w, 0.4) == 0.0
    assert interaction_groups(clouds, [w] * 3, 0.4, max_size=3) == [[0, 1, 2]]
    assert interaction_groups(clouds, [w] * 3, 0.4, max_size=2) == [[0, 1]]
    # two separate pairs and a loner
    far = [c + [5.0, 0.0] for c in clouds[:2]]
    lone = _cloud([-5, 0], 80, 0.05, rng)
    got = interaction_groups([far[0], lone, clouds[0], far[1], clouds[1]], [w] * 5, 0.4,
                             max_size=2)
    assert got == [[0, 3], [2, 4]]


def test_bad_arguments_are_refused():
    w = np.ones(3)
    pts = np.zeros((3, 2))
    with pytest.raises(GroupError):
        interaction_groups([pts, pts], [w], 0.4)
    with pytest.raises(GroupError):
        interaction_groups([pts, pts], [w, w], 0.4, max_size=1)
    with pytest.raises(GroupError):
        violation_mass(pts, np.zeros(3), pts, w, 0.4)
