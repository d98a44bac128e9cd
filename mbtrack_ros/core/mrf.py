"""Spatial-exclusion MRF motion prior and belief propagation on particle weights.

000 §III-B and §V-B.1 (Algorithm 1, "predict"): after each target's particles have been
propagated independently (000 Eq. 15), a pairwise MRF ``p(x^h, x^k)`` (000 Eq. 16) corrects
their weights by loopy belief propagation over the particle sets, which stay fixed; only
the weights change (000 Eq. 17-18). The potential implements spatial exclusion,
``delta(|x^h - x^k| > r)`` with r = 0.4 m (000 §VI-A), floored at ``epsilon`` (default 1e-3)
so that a belief can never vanish completely: with a hard 0/1 potential a target whose
particles all lie within r of the other's would get an all-zero belief, and the filter could
not recover from that.

Messages (000 Eq. 17) are normalised to sum one over the receiving particles; beliefs are
000 Eq. 18. Iteration stops when the KL divergence of the new beliefs to the previous ones
(000 Eq. 43; summed over targets) falls below ``theta`` (000 §V-B.1: 0.01) or after
``max_iterations``. The graph is fully connected by default (000 §V-B.1); an explicit edge
list can be given (used by the tests to check exactness on trees).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import math

import numpy as np

__all__ = ['BeliefPropagationResult', 'MRFError', 'belief_propagation',
           'exclusion_potential']


class MRFError(ValueError):
    """Inconsistent particle sets, weights or edges for belief propagation."""


def exclusion_potential(xy_a: np.ndarray, xy_b: np.ndarray, *, radius: float = 0.4,
                        epsilon: float = 1e-3) -> np.ndarray:
    """Pairwise spatial-exclusion potential between two particle sets.

    Args:
        xy_a: (N, 2) floor positions, metres.
        xy_b: (M, 2) floor positions, metres.
        radius: exclusion radius r, metres.
        epsilon: floor of the potential inside the radius.

    Returns:
        (N, M) float64: 1 where the positions are farther apart than ``radius``, else
        ``epsilon``.
    """
    xy_a = np.asarray(xy_a, dtype=np.float64)
    xy_b = np.asarray(xy_b, dtype=np.float64)
    # squared distances of all pairs; the same floating-point operations as scipy's
    # cdist(..., 'sqeuclidean') without importing scipy.spatial (~0.3 s per replay)
    dx = xy_a[:, 0, None] - xy_b[None, :, 0]
    dy = xy_a[:, 1, None] - xy_b[None, :, 1]
    d2 = dx * dx + dy * dy
    # 000 §VI-A: p(x^h, x^k) = delta(|x^h - x^k| > r), soft-floored at epsilon
    return np.where(d2 > radius * radius, 1.0, epsilon)


def _boxes_apart(box_a: tuple[np.ndarray, np.ndarray], box_b: tuple[np.ndarray, np.ndarray],
                 radius: float) -> bool:
    """True if two particle clouds' bounding boxes ``(min (2,), max (2,))`` are farther apart
    than ``radius`` (then every pair is, the potential is constant and the edge carries no
    information)."""
    gap = np.maximum(box_a[0] - box_b[1], box_b[0] - box_a[1])
    gap = np.maximum(gap, 0.0)
    return float(gap @ gap) > radius * radius


@dataclass
class BeliefPropagationResult:
    """Output of :func:`belief_propagation`.

    Attributes:
        weights: per target, (N_k,) beliefs (000 Eq. 18) normalised to sum one.
        iterations: number of message-passing iterations run.
        kl: KL divergence of the last iteration's beliefs to the previous ones (Eq. 43).
        converged: True if ``kl < theta`` was reached before ``max_iterations``.
    """

    weights: list[np.ndarray]
    iterations: int
    kl: float
    converged: bool


def _kl(new: list[np.ndarray], old: list[np.ndarray]) -> float:
    total = 0.0
    for b, a in zip(new, old):
        mask = b > 0
        bm = b[mask]
        total += float((bm * np.log(bm / np.maximum(a[mask], 1e-300))).sum())
    return total


def belief_propagation(xy: Sequence[np.ndarray], prior_weights: Sequence[np.ndarray], *,
                       radius: float = 0.4, epsilon: float = 1e-3, theta: float = 0.01,
                       max_iterations: int = 20,
                       edges: Sequence[tuple[int, int]] | None = None,
                       potentials: dict[tuple[int, int], np.ndarray] | None = None,
                       ) -> BeliefPropagationResult:
    """Loopy BP of the spatial-exclusion MRF over K particle sets (000 Eq. 17-18, 43).

    Args:
        xy: K arrays (N_k, 2) of particle floor positions, metres.
        prior_weights: K arrays (N_k,) of independently propagated prior weights p^-
            (000 Eq. 15), normalised internally.
        radius, epsilon: potential parameters (see :func:`exclusion_potential`).
        theta: KL stopping threshold theta_BP (000 Eq. 43).
        max_iterations: upper bound on iterations.
        edges: undirected pairs ``(h, k)``; default all pairs (fully connected graph).
        potentials: optional precomputed ``{(h, k): (N_h, N_k)}`` potential matrices
            (any other pairwise MRF); missing pairs use :func:`exclusion_potential`.

    Returns:
        :class:`BeliefPropagationResult` with the corrected prior beliefs.
    """
    k_count = len(xy)
    if len(prior_weights) != k_count:
        raise MRFError(f'{k_count} particle sets but {len(prior_weights)} weight arrays')
    if max_iterations < 1:
        raise MRFError(f'max_iterations must be >= 1, got {max_iterations}')
    priors = []
    for k, (pts, w) in enumerate(zip(xy, prior_weights)):
        pts = np.asarray(pts)
        w = np.asarray(w, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] < 2 or w.shape != (pts.shape[0],) or w.size == 0:
            raise MRFError(f'target {k}: positions {pts.shape} and weights {w.shape} '
                           'do not match')
        total = w.sum()
        if not math.isfinite(total) or total <= 0 or (w < 0).any():
            raise MRFError(f'target {k}: prior weights must be >= 0 with a positive sum')
        priors.append(w / total)
    if edges is None:
        edges = [(h, k) for h in range(k_count) for k in range(h + 1, k_count)]
    edge_set = set()
    for h, k in edges:
        if h == k or not (0 <= h < k_count and 0 <= k < k_count):
            raise MRFError(f'bad edge {(h, k)} for {k_count} targets')
        edge_set.add((min(h, k), max(h, k)))
    if not edge_set:
        return BeliefPropagationResult([p.copy() for p in priors], 0, 0.0, True)
    potentials = dict(potentials or {})
    # psi[(h, k)]: (N_h, N_k), both directions share one matrix (the potential is symmetric)
    psi: dict[tuple[int, int], np.ndarray] = {}
    boxes: dict[int, tuple[np.ndarray, np.ndarray]] = {}    # per cloud, computed once

    def box(k: int) -> tuple[np.ndarray, np.ndarray]:
        if k not in boxes:
            pts = np.asarray(xy[k])[:, :2]
            boxes[k] = (pts.min(axis=0), pts.max(axis=0))
        return boxes[k]

    for h, k in sorted(edge_set):
        mat = potentials.get((h, k))
        if mat is None and (k, h) in potentials:
            mat = potentials[(k, h)].T
        if mat is None:
            a, b = np.asarray(xy[h])[:, :2], np.asarray(xy[k])[:, :2]
            if _boxes_apart(box(h), box(k), radius):
                continue  # constant potential: its messages are uniform, drop the edge
            mat = exclusion_potential(a, b, radius=radius, epsilon=epsilon)
        psi[(h, k)] = np.asarray(mat, dtype=np.float64)
    neighbours: list[list[int]] = [[] for _ in range(k_count)]
    for h, k in psi:
        neighbours[h].append(k)
        neighbours[k].append(h)
    # Algorithm 1: initialise messages to 1 (normalised: uniform)
    msgs = {(h, k): np.full(priors[k].size, 1.0 / priors[k].size)
            for h, k in psi} | {(k, h): np.full(priors[h].size, 1.0 / priors[h].size)
                                for h, k in psi}
    beliefs = [p.copy() for p in priors]
    kl = np.inf
    iteration = 0
    for iteration in range(1, max_iterations + 1):
        new_msgs = {}
        for (h, k) in msgs:
            # 000 Eq. 17: m^{h,k}(x^k) = sum_j p(x^h_j, x^k) p^-(x^h_j) prod_{n != k} m^{n,h}
            source = priors[h].copy()
            for n in neighbours[h]:
                if n != k:
                    source *= msgs[(n, h)]
            mat = psi[(h, k)] if h < k else psi[(k, h)].T
            m = source @ mat
            s = m.sum()
            # Algorithm 1: normalise messages to sum one
            new_msgs[(h, k)] = m / s if s > 0 else np.full(m.size, 1.0 / m.size)
        msgs = new_msgs
        new_beliefs = []
        for node in range(k_count):
            # 000 Eq. 18: belief = p^- times the product of incoming messages
            b = priors[node].copy()
            for n in neighbours[node]:
                b *= msgs[(n, node)]
            s = b.sum()
            new_beliefs.append(b / s if s > 0 else priors[node].copy())
        # 000 Eq. 43: KL divergence of subsequent beliefs
        kl = _kl(new_beliefs, beliefs)
        beliefs = new_beliefs
        if kl < theta:
            return BeliefPropagationResult(beliefs, iteration, kl, True)
    return BeliefPropagationResult(beliefs, iteration, kl, False)
