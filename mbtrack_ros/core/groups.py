"""Which targets the spatial-exclusion prior couples: the groups of the grouped HJS filter.

The product of marginals of the HJS filter (000 §III) is exact for the exclusion prior of
000 Eq. 16 when no pair of particles of two targets lies within the exclusion radius r: the
potential is then 1 on the whole support of the product and changes nothing. Where two
clouds come within r of each other the potential couples them, and a product of marginals
cannot carry that coupling from one frame to the next (a hidden pair whose clouds diffuse
through each other). :func:`interaction_groups` finds those pairs from the quantity the
model already has, the exclusion radius: the prior mass of the pair's violating joint
states,

    v_hk = sum_i sum_j w^h_i w^k_j [ |x^h_i - x^k_j| <= r ],

and joins targets with v_hk > 0 into groups of at most ``max_size`` targets (the strongest
couplings first), which the grouped filter samples jointly.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ['GroupError', 'interaction_groups', 'violation_mass']


class GroupError(ValueError):
    """Malformed particle clouds or group parameters."""


def violation_mass(xy_a: np.ndarray, w_a: np.ndarray, xy_b: np.ndarray, w_b: np.ndarray,
                   radius: float) -> float:
    """Prior probability (product of the marginals) that two targets are within ``radius``.

    Args:
        xy_a, xy_b: (N_a, 2) and (N_b, 2) particle floor positions, metres.
        w_a, w_b: (N_a,) and (N_b,) non-negative weights (normalised here).
        radius: exclusion radius r, metres (000 Eq. 16).

    Returns:
        ``sum_ij w_a[i] w_b[j] [|xy_a[i] - xy_b[j]| <= radius]`` in [0, 1].
    """
    wa = np.asarray(w_a, np.float64)
    wb = np.asarray(w_b, np.float64)
    sa, sb = wa.sum(), wb.sum()
    if not (sa > 0 and sb > 0):
        raise GroupError('particle weights must have a positive sum')
    d2 = ((np.asarray(xy_a, np.float64)[:, None, :]
           - np.asarray(xy_b, np.float64)[None, :, :]) ** 2).sum(axis=2)
    return float((wa / sa) @ (d2 <= radius * radius) @ (wb / sb))


def interaction_groups(xy: Sequence[np.ndarray], weights: Sequence[np.ndarray],
                       radius: float, max_size: int = 3) -> list[list[int]]:
    """Groups of targets coupled by the exclusion prior (module docstring).

    Args:
        xy: K arrays (N_k, 2) of particle floor positions, metres.
        weights: K arrays (N_k,) of the particles' weights (normalised here).
        radius: exclusion radius r, metres.
        max_size: largest group (bounds the joint likelihood's cost); couplings that would
            make a larger group are left to the product of marginals, weakest first.

    Returns:
        The groups of two or more targets, each a sorted list of target indices, sorted by
        their first index; targets in no group are separable.
    """
    if len(xy) != len(weights):
        raise GroupError(f'{len(xy)} particle sets but {len(weights)} weight arrays')
    if radius < 0 or int(max_size) < 2:
        raise GroupError('radius must be >= 0 and max_size >= 2')
    k_count = len(xy)
    pts = [np.asarray(p, np.float64).reshape(-1, 2) for p in xy]
    # cheap bound first: two clouds whose bounding boxes are farther apart than r cannot couple
    lo = [p.min(axis=0) if len(p) else np.full(2, np.inf) for p in pts]
    hi = [p.max(axis=0) if len(p) else np.full(2, -np.inf) for p in pts]
    pairs = []
    for h in range(k_count):
        for k in range(h + 1, k_count):
            gap = np.maximum(0.0, np.maximum(lo[h] - hi[k], lo[k] - hi[h]))
            if not len(pts[h]) or not len(pts[k]) or float(gap @ gap) > radius * radius:
                continue
            v = violation_mass(pts[h], weights[h], pts[k], weights[k], radius)
            if v > 0:
                pairs.append((-v, h, k))
    parent = list(range(k_count))
    size = [1] * k_count

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for _, h, k in sorted(pairs):
        a, b = root(h), root(k)
        if a != b and size[a] + size[b] <= int(max_size):
            parent[b] = a
            size[a] += size[b]
    members: dict[int, list[int]] = {}
    for k in range(k_count):
        members.setdefault(root(k), []).append(k)
    return sorted((m for m in members.values() if len(m) > 1), key=lambda m: m[0])
