"""Joint Likelihood Filter measurement process (004 §5.2, Fig. 16 'JLF' column).

N joint samples are drawn, one component per target from its Kalman prediction; for each
joint sample and camera the visually distinct front-to-back orderings are enumerated (only
pairs of targets whose image boxes overlap in that camera need an order, 004 §5.2.1), the
masked joint likelihood (nearer targets hide farther ones, 004 §5.2.2) is evaluated for them,
and the best joint sample with its best orderings becomes the joint measurement.

The joint likelihood is a callable ``joint_score(joint_states (R, K, 6), orders (R, C, K))
-> (R,)`` (in the product ``MeasurementModel.joint(..., orders=...)``), ``orders[r, c]`` the
target indices front to back in camera c. It is a sum of per-camera terms, each depending
only on that camera's order, so the best ordering is searched camera by camera against a
reference (the geometric order): sum_c |D_c| evaluations per joint sample instead of
prod_c |D_c|.
"""
from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from mbtrack_ros.core.association.kalman import AssociationError
from mbtrack_ros.core.association.sampling import clean_loglik, posture_loglik, sample_states
from mbtrack_ros.core.camera import Camera
from mbtrack_ros.core.state import SIT, STATE_DIM, X, Y

__all__ = ['JLFResult', 'JointScoreFn', 'best_orders', 'distinct_orders', 'geometric_orders',
           'jlf_measurement', 'overlaps', 'refine_joint', 'silhouette_boxes']

JointScoreFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``joint_score(joint_states (R, K, 6), orders (R, C, K)) -> (R,)`` log-likelihood."""

_N_RIM = 8  # points on each rim of the bounding cylinder


@dataclass(frozen=True)
class JLFResult:
    """The joint measurement of one JLF step.

    Attributes:
        states: (K, 6) the best joint sample (its positions are the measurements).
        orders: (C, K) its best front-to-back order per camera.
        loglik: joint log-likelihood of ``states`` under ``orders``.
        evaluations: number of joint likelihood evaluations (rows) spent.
        posture_loglik: (K, 2) per target, the best joint log-likelihood of a joint sample
            with that target standing / sitting (-inf if not sampled).
    """

    states: np.ndarray
    orders: np.ndarray
    loglik: float
    evaluations: int
    posture_loglik: np.ndarray


def silhouette_boxes(joint_states: np.ndarray, camera: Camera, heights: np.ndarray,
                     widths: np.ndarray) -> np.ndarray:
    """Image boxes of the people's bounding cylinders, clipped to the image.

    Args:
        joint_states: (N, K, 6) states.
        camera: the camera.
        heights, widths: (K,) body height and width (cylinder diameter), metres.
    Returns:
        (N, K, 4) float64 ``x0, y0, x1, y1`` pixels; NaN rows where the person is behind the
        camera or outside the image.
    """
    js = np.asarray(joint_states, dtype=np.float64)
    n, k = js.shape[:2]
    heights = np.broadcast_to(np.asarray(heights, dtype=np.float64), (k,))
    radii = 0.5 * np.broadcast_to(np.asarray(widths, dtype=np.float64), (k,))
    ang = np.linspace(0.0, 2.0 * np.pi, _N_RIM, endpoint=False)
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)  # (8, 2)
    pts = np.empty((n, k, 2, _N_RIM, 3))
    pts[..., :2] = js[:, :, None, None, :2] + radii[None, :, None, None, None] * ring
    pts[:, :, 0, :, 2] = 0.0
    pts[:, :, 1, :, 2] = heights[None, :, None]
    pix = camera.project(pts.reshape(n, k, 2 * _N_RIM, 3))  # (N, K, 16, 2)
    with np.errstate(invalid='ignore'):
        lo = pix.min(axis=2)  # NaN if any point is behind the camera
        hi = pix.max(axis=2)
        box = np.concatenate([np.maximum(lo, -0.5), np.minimum(hi, [camera.width - 0.5,
                                                                    camera.height - 0.5])],
                             axis=-1)
        empty = ~((box[..., 2] > box[..., 0]) & (box[..., 3] > box[..., 1]))
    box[empty] = np.nan
    return box


def overlaps(boxes: np.ndarray) -> np.ndarray:
    """(..., K, K) bool: boxes (..., K, 4) of two different targets intersect (NaN: never)."""
    b = np.asarray(boxes, dtype=np.float64)
    with np.errstate(invalid='ignore'):
        ov = ((b[..., :, None, 0] < b[..., None, :, 2]) & (b[..., None, :, 0] < b[..., :, None, 2])
              & (b[..., :, None, 1] < b[..., None, :, 3])
              & (b[..., None, :, 1] < b[..., :, None, 3]))
    k = b.shape[-2]
    return ov & ~np.eye(k, dtype=bool)


class _OrderTable:
    """All K! permutations and, per pair i < j, whether i is in front of j."""

    def __init__(self, k: int) -> None:
        if k > 7:
            raise AssociationError(f'depth-order enumeration supports at most 7 targets, got {k}')
        self.perms = np.array(list(itertools.permutations(range(k))), dtype=np.intp)
        rank = np.argsort(self.perms, axis=1)  # rank[p, t] = position of t in permutation p
        self.iu, self.ju = np.triu_indices(k, 1)
        self.front = rank[:, self.iu] < rank[:, self.ju]  # (K!, n_pairs)
        self.cache: dict[bytes, np.ndarray] = {}

    def distinct(self, pair_mask: np.ndarray) -> np.ndarray:
        """Indices into ``perms`` of one representative per visually distinct class."""
        key = np.packbits(pair_mask).tobytes()
        found = self.cache.get(key)
        if found is None:
            _, first = np.unique(self.front[:, pair_mask], axis=0, return_index=True)
            found = np.sort(first)
            self.cache[key] = found
        return found

    def signature(self, perm: np.ndarray, pair_mask: np.ndarray) -> np.ndarray:
        rank = np.argsort(perm)
        return (rank[self.iu] < rank[self.ju])[pair_mask]


def distinct_orders(overlap: np.ndarray) -> np.ndarray:
    """Visually distinct front-to-back orders of K targets given their (K, K) overlaps.

    Orders that differ only in the relative order of non-overlapping targets give identical
    masks and are represented once (004 §5.2.1). Returns (D, K) int permutations.
    """
    overlap = np.asarray(overlap, dtype=bool)
    table = _OrderTable(overlap.shape[0])
    mask = overlap[table.iu, table.ju] | overlap[table.ju, table.iu]
    return table.perms[table.distinct(mask)]


def geometric_orders(joint_states: np.ndarray, cameras: Sequence[Camera],
                     heights: np.ndarray) -> np.ndarray:
    """(N, C, K) front-to-back orders by distance of each body centre to each camera."""
    js = np.asarray(joint_states, dtype=np.float64)
    centre = np.concatenate([js[..., :2], np.broadcast_to(
        0.5 * np.asarray(heights, dtype=np.float64), js.shape[:2])[..., None]], axis=-1)
    return np.stack([np.argsort(cam.distance(centre), axis=1, kind='stable')
                     for cam in cameras], axis=1)


def best_orders(joint_states: np.ndarray, joint_score: JointScoreFn,
                cameras: Sequence[Camera], heights: np.ndarray, widths: np.ndarray, *,
                active: Sequence[bool] | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Most likely visually distinct order per joint sample and camera (004 §5.2.1).

    Args:
        joint_states: (N, K, 6) joint samples.
        joint_score: masked joint log-likelihood callable (module docstring).
        cameras: the C cameras, in the order of the ``orders`` axis.
        heights, widths: (K,) body sizes, metres (for the overlap test).
        active: per camera, whether it has an image this frame (inactive cameras keep the
            geometric order and cost no evaluations); default all.
    Returns:
        (orders (N, C, K), loglik (N,) under those orders, number of evaluated rows).
    """
    js = np.asarray(joint_states, dtype=np.float64)
    if js.ndim != 3 or js.shape[2] != STATE_DIM:
        raise AssociationError(f'joint states must be (N, K, 6), got {js.shape}')
    n, k = js.shape[:2]
    n_cam = len(cameras)
    ref = geometric_orders(js, cameras, heights)  # (N, C, K)
    table = _OrderTable(k)
    rows_n: list[int] = [*range(n)]
    rows_orders: list[np.ndarray] = [ref[i] for i in range(n)]
    variant_of: list[tuple[int, int, np.ndarray]] = []  # (sample, camera, order)
    if active is None:
        active = [True] * n_cam
    if len(active) != n_cam:
        raise AssociationError(f'{len(active)} activity flags for {n_cam} cameras')
    if k > 1:
        for c, cam in enumerate(cameras):
            if not active[c]:
                continue
            ov = overlaps(silhouette_boxes(js, cam, heights, widths))  # (N, K, K)
            pair_masks = ov[:, table.iu, table.ju] | ov[:, table.ju, table.iu]
            for i in np.flatnonzero(pair_masks.any(axis=1)):
                mask = pair_masks[i]
                ref_sig = table.signature(ref[i, c], mask)
                for p in table.distinct(mask):
                    # 004 §5.2.1: one representative per visually distinct order class
                    if np.array_equal(table.front[p][mask], ref_sig):
                        continue  # same masks as the reference order
                    orders = ref[i].copy()
                    orders[c] = table.perms[p]
                    rows_n.append(i)
                    rows_orders.append(orders)
                    variant_of.append((i, c, table.perms[p]))
    all_orders = np.stack(rows_orders)
    values = clean_loglik(joint_score(js[np.asarray(rows_n)], all_orders), len(rows_n))
    base = values[:n]
    best = ref.copy()
    gain = np.zeros((n, n_cam))
    for r, (i, c, perm) in enumerate(variant_of):
        delta = values[n + r] - base[i]
        if delta > gain[i, c]:
            gain[i, c] = delta
            best[i, c] = perm
    changed = np.flatnonzero((best != ref).any(axis=(1, 2)))
    loglik = base.copy()
    evaluations = len(rows_n)
    if changed.size:  # exact value under the combined best orders
        loglik[changed] = clean_loglik(joint_score(js[changed], best[changed]), changed.size)
        evaluations += changed.size
    return best, loglik, evaluations


def refine_joint(states: np.ndarray, orders: np.ndarray, joint_score: JointScoreFn, *,
                 max_evals: int = 80, xtol: float = 0.01) -> tuple[np.ndarray, float]:
    """Powell hill-climbing of all K floor positions with the depth orders fixed (004 §5.2.2).

    Args:
        states: (K, 6) joint sample; orders: (C, K).
    Returns:
        ((K, 6) refined states, log-likelihood); the input if nothing better is found.
    """
    states = np.asarray(states, dtype=np.float64)

    def cost(xy: np.ndarray) -> float:
        trial = states.copy()
        trial[:, [X, Y]] = xy.reshape(-1, 2)
        value = clean_loglik(joint_score(trial[None], orders[None]), 1)[0]
        return 1e300 if not np.isfinite(value) else -float(value)

    x0 = states[:, [X, Y]].ravel()
    start = cost(x0)
    result = minimize(cost, x0, method='Powell',
                      options={'maxfev': int(max_evals), 'xtol': xtol, 'ftol': 1e-6})
    if not np.isfinite(result.fun) or result.fun >= start:
        return states.copy(), -start if start < 1e300 else -np.inf
    refined = states.copy()
    refined[:, [X, Y]] = result.x.reshape(-1, 2)
    return refined, -float(result.fun)


def jlf_measurement(means: np.ndarray, covs: np.ndarray, joint_score: JointScoreFn,
                    cameras: Sequence[Camera], heights: np.ndarray, widths: np.ndarray,
                    rng: np.random.Generator, *, n_samples: int = 50, include_mean: bool = True,
                    active: Sequence[bool] | None = None,
                    refine: bool = False, refine_evals: int = 80, scale: float = 1.0,
                    min_std: float = 0.05, min_speed: float = 0.2,
                    sit_explore: float = 0.0) -> JLFResult:
    """One JLF joint measurement (004 §5.2.1, Fig. 16): sample, order, evaluate, pick best.

    Args:
        means: (K, 6) predicted states; covs: (K, 4, 4) predicted covariances.
        joint_score: masked joint log-likelihood callable.
        cameras, heights, widths: see :func:`best_orders`.
        n_samples: number of joint samples N.
        include_mean: make the first joint sample the prediction itself.
        active: cameras with an image this frame, see :func:`best_orders`.
        refine: Powell on the best joint sample with its orders fixed.
    Returns:
        :class:`JLFResult`.
    """
    means = np.asarray(means, dtype=np.float64)
    if means.ndim != 2 or means.shape[1] != STATE_DIM or len(covs) != means.shape[0]:
        raise AssociationError(f'need means (K, 6) and K covariances, got {means.shape}')
    k = means.shape[0]
    js = np.stack([sample_states(means[t], covs[t], n_samples, rng, scale=scale,
                                 min_std=min_std, min_speed=min_speed,
                                 sit_explore=sit_explore) for t in range(k)],
                  axis=1)  # (N, K, 6), components independent (004 §5.2.1)
    if include_mean:  # the orientation is the same in every sample
        js[0, :, [X, Y]] = means[:, [X, Y]].T
        if sit_explore > 0.0:  # the more probable posture
            js[0, :, SIT] = np.round(means[:, SIT])
    orders, loglik, evaluations = best_orders(js, joint_score, cameras, heights, widths,
                                              active=active)
    i = int(np.argmax(loglik))  # 004 §5.2.1: the most probable joint sample
    posture = np.array([posture_loglik(js[:, t, SIT], loglik) for t in range(k)])
    states, value = js[i].copy(), float(loglik[i])
    if refine and np.isfinite(value):
        states, value = refine_joint(states, orders[i], joint_score, max_evals=refine_evals)
        evaluations += refine_evals
    return JLFResult(states, orders[i], value, evaluations, posture)
