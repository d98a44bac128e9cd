"""Layers of the ``~/debug/<camera>/occlusion`` image: occlusion maps and silhouettes.

Shows what the HJS filter sees (000 Fig. 4): each track's silhouette at its posterior mean
and, on it, the probability that the pixel is hidden by the other people, i.e. one minus the
occlusion map at infinity of 000 Eq. 34, both computed by the measurement model
(:meth:`MeasurementModel.occlusion_maps`, :meth:`MeasurementModel.render_labels`) from the
tracks' weighted particles. Debug only: the node computes it when someone subscribes.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from mbtrack_ros.core.camera import Camera
from mbtrack_ros.core.shape import BodyShape, ShapeError, render_labels
from mbtrack_ros.core.state import FrameResult, TrackEstimate

__all__ = ['occlusion_layers', 'shadow_layer']


def shadow_layer(tracker, camera: str, rgb: np.ndarray) -> np.ndarray | None:
    """(h, w) bool pixels of ``rgb`` (the camera's image as received) that the shadow model
    (:func:`~mbtrack_ros.core.detection.shadow.shadow_mask`) takes for cast shadows on the
    background, at the tracker's working size; None without a ready background model."""
    from mbtrack_ros.core.detection.illumination import ycc_to_rgb
    from mbtrack_ros.core.detection.shadow import shadow_mask
    from mbtrack_ros.core.tracker import length_scale

    detection = getattr(tracker, 'detection', None)
    model = None if detection is None else detection.background.models.get(camera)
    if model is None or not model.ready:
        return None
    image = tracker.working_images({camera: rgb})[camera]
    if image.shape[:2] != model.shape:
        return None
    gains = getattr(tracker.illumination, 'gains', {}).get(camera)
    if gains is not None:   # the image as the background test saw it
        image = np.clip(image / gains, 0, 255)
    background = np.clip(ycc_to_rgb(model.background_ycc), 0, 255)
    return shadow_mask(image, background, length_scale=length_scale(tracker.calibration))


def _subsample(track: TrackEstimate, max_particles: int) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``max_particles`` particles picked evenly along the weight CDF (equal weights)."""
    if track.particles is None or track.weights is None or len(track.particles) == 0:
        return np.asarray(track.mean, dtype=np.float64)[None], np.ones(1)
    w = np.asarray(track.weights, dtype=np.float64)
    cdf = np.cumsum(w / w.sum())
    m = min(max_particles, len(w))
    idx = np.minimum(np.searchsorted(cdf, (np.arange(m) + 0.5) / m), len(w) - 1)
    return np.asarray(track.particles, dtype=np.float64)[idx], np.full(m, 1.0 / m)


def occlusion_layers(measurement, camera: Camera, result: FrameResult,
                     models: Mapping[int, object], *, max_particles: int = 50,
                     ) -> tuple[np.ndarray | None, dict[int, np.ndarray]]:
    """Occlusion map and per-track silhouettes of one camera.

    Args:
        measurement: the tracker's measurement model (``occlusion_maps``, ``render_labels``);
            without those methods only silhouettes from :mod:`mbtrack_ros.core.shape`.
        camera: the camera.
        result: the frame's tracker output (particles used when present).
        models: track id -> PersonModel of the live tracks.
        max_particles: particles per track used for the occlusion maps.

    Returns:
        ``(occlusion, silhouettes)``: (H, W) float32 in [0, 1], the probability that a pixel
        of a track's silhouette is hidden by the others (max over tracks), or None; and
        track id -> (H, W) bool silhouette at the posterior mean.
    """
    tracks = [t for t in result.tracks if t.track_id in models]
    silhouettes: dict[int, np.ndarray] = {}
    has_maps = hasattr(measurement, 'occlusion_maps') and hasattr(measurement, 'render_labels')
    for t in result.tracks:
        mean = np.asarray(t.mean, dtype=np.float64)
        try:
            if has_maps and t.track_id in models:
                labels = measurement.render_labels(camera.name, mean, models[t.track_id])
            else:
                h = float(t.height) if np.isfinite(t.height) and t.height > 0 else 1.75
                labels = render_labels(camera, mean, BodyShape(height=h))
        except (ShapeError, ValueError):
            continue
        silhouettes[t.track_id] = np.asarray(labels) > 0
    if not has_maps or len(tracks) < 2:
        return None, silhouettes
    picks = [_subsample(t, max_particles) for t in tracks]
    maps = measurement.occlusion_maps(camera.name, [p for p, _ in picks],
                                      [w for _, w in picks],
                                      [models[t.track_id] for t in tracks])
    occ = np.zeros((camera.height, camera.width), np.float32)
    for k, t in enumerate(tracks):
        mask = silhouettes.get(t.track_id)
        if mask is not None:
            # 000 Eq. 34: 1 - w*_inf is the probability that another target hides the pixel
            occ = np.maximum(occ, np.where(mask, 1.0 - maps[k], 0.0).astype(np.float32))
    return occ, silhouettes
