"""Layers of the ``~/debug/<camera>/occlusion`` image: occlusion maps and silhouettes.

Shows what the HJS filter sees (000 Fig. 4): each track's silhouette, rendered with the body
shape model (:mod:`mbtrack_ros.core.shape`) at its posterior mean, and the occlusion map w*
of 000 Eq. 34 on it: the probability that a pixel of a person is hidden by the people in
front, from their weighted particles. Debug only: computed when someone subscribes.
"""
from __future__ import annotations

import numpy as np

from mbtrack_ros.core.camera import Camera
from mbtrack_ros.core.shape import BodyShape, ShapeError, rasterize
from mbtrack_ros.core.state import FrameResult, TrackEstimate, X, Y

__all__ = ['coverage_map', 'occlusion_layers']


def coverage_map(camera: Camera, states: np.ndarray, weights: np.ndarray,
                 shape: BodyShape) -> np.ndarray:
    """Weighted silhouette coverage ``sum_i w_i [u in silhouette_i]`` -> (H, W) float32."""
    h, w = camera.height, camera.width
    if states.shape[0] == 0:
        return np.zeros((h, w), np.float32)
    sil = rasterize(camera, states, shape)
    # span weights, then a difference image summed along rows (no per-pixel loop)
    owner = np.repeat(np.arange(len(sil)), np.diff(sil.offsets))
    span_w = np.asarray(weights, dtype=np.float64)[owner]
    diff = np.zeros((h, w + 1))
    np.add.at(diff, (sil.row, sil.x0), span_w)
    np.add.at(diff, (sil.row, sil.x1), -span_w)
    out = np.cumsum(diff, axis=1)[:, :w]
    if sil.row_step > 1:  # fill skipped rows from the sampled row above
        rows = (np.arange(h) // sil.row_step) * sil.row_step
        out = out[rows]
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def _subsample(track: TrackEstimate, max_particles: int) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``max_particles`` particles picked evenly along the weight CDF (equal weights)."""
    if track.particles is None or track.weights is None or len(track.particles) == 0:
        return np.asarray(track.mean, dtype=np.float64)[None], np.ones(1)
    w = np.asarray(track.weights, dtype=np.float64)
    cdf = np.cumsum(w / w.sum())
    m = min(max_particles, len(w))
    idx = np.minimum(np.searchsorted(cdf, (np.arange(m) + 0.5) / m), len(w) - 1)
    return np.asarray(track.particles)[idx], np.full(m, 1.0 / m)


def occlusion_layers(tracker, camera: Camera, result: FrameResult, *,
                     max_particles: int = 24) -> tuple[np.ndarray | None,
                                                       dict[int, np.ndarray]]:
    """Occlusion map and per-track silhouettes of one camera.

    Args:
        tracker: the running tracker (unused for now; reserved for the measurement model's own
            occlusion maps).
        camera: the camera.
        result: the frame's tracker output (particles used when present).
        max_particles: particles per track used for the soft coverage maps.

    Returns:
        ``(occlusion, silhouettes)``: (H, W) float32 in [0, 1], the w* value (000 Eq. 34)
        on each track's silhouette (max over tracks), or None without tracks; and track id
        -> (H, W) bool silhouette at the posterior mean.
    """
    del tracker
    if not result.tracks:
        return None, {}
    order = sorted(result.tracks, key=lambda t: float(camera.distance(
        np.array([t.mean[X], t.mean[Y], 0.5 * _height(t)]))))
    occ = np.zeros((camera.height, camera.width), np.float32)
    silhouettes: dict[int, np.ndarray] = {}
    visible_free = np.ones_like(occ)  # prod over nearer targets of (1 - coverage)
    for t in order:  # nearest first
        try:
            shape = BodyShape(height=_height(t))
            mean_sil = rasterize(camera, np.asarray(t.mean, dtype=np.float64)[None], shape)
            mask = mean_sil.mask(0) > 0
            states, weights = _subsample(t, max_particles)
            cov = coverage_map(camera, states, weights, shape)
        except ShapeError:
            continue
        silhouettes[t.track_id] = mask
        w_star = 1.0 - visible_free  # 000 Eq. 34: occluded by someone nearer
        occ = np.maximum(occ, np.where(mask, w_star, 0.0).astype(np.float32))
        visible_free *= 1.0 - cov
    return occ, silhouettes


def _height(t: TrackEstimate) -> float:
    h = float(t.height)
    return h if np.isfinite(h) and h > 0 else 1.75
