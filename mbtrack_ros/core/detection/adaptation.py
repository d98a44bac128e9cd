"""Slow, occlusion-aware adaptation of the tracks' appearance models during tracking.

A :class:`~mbtrack_ros.core.appearance.PersonModel` is acquired once, from the cameras that
saw the newcomer unoccluded (003 §4.1); the sides it turns later are interpolated from the
two nearest key views (003 Eq. 1-2). The papers leave updating it to future work. Here a
confirmed track's model learns from a camera only where the view is unambiguous:

- the track is reported, its existence is high, it has walked some distance since it was
  first seen (a false track on a static thing has not) and no other track stands within a
  floor radius (in a group a model would learn its neighbours);
- in that camera its visibility ``xi_v`` (001) is high and the silhouettes of the tracks
  closer to the camera leave most of its silhouette free and inside the image;
- the part histograms seen at its estimate are already close to what the model expects at
  that relative angle (003 Eq. 3-4, part areas as weights), and closer than any other
  track's model: a track sitting on the wrong person does not learn them.

The observation is then blended slowly into the nearest key view, or starts a new key view
for an angle the model lacks (:meth:`PersonModel.adapt`). The models are the tracker's own
objects (the filter's likelihood stacks their key views each frame set), so the change is
seen from the next frame set on.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from mbtrack_ros.core import _kernels
from mbtrack_ros.core.appearance import (
    PersonModel, bhattacharyya_distance_sq, part_histograms, relative_angle)
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.shape import Silhouettes
from mbtrack_ros.core.state import THETA, X, Y

__all__ = ['AdaptationConfig', 'Observation', 'adapt_models', 'observe']


@dataclass(frozen=True)
class AdaptationConfig:
    """Parameters of the appearance adaptation.

    Attributes:
        rate: blending rate alpha per accepted observation, dimensionless in [0, 1]: the
            share of the new observation in the model (0 disables the adaptation; 0.05 =
            a memory of about 20 accepted observations).
        min_free: fraction of the track's full silhouette that must be inside the image and
            not covered by closer tracks' silhouettes.
        min_visibility: visibility probability ``xi_v`` (001 §3.1) the track needs in the
            camera.
        min_existence: existence probability (001 §3.2) the track needs.
        neighbour_radius: no other track within this floor distance, metres.
        max_distance: largest area-weighted squared Bhattacharyya distance (003 Eq. 3-4)
            between the observed and the expected part histograms.
        foreground_only: learn only from the silhouette's foreground pixels (the
            estimate's silhouette also covers some background beside the person).
        interval: seconds between two adaptations of one track (slow, and cheap).
        min_travel: metres the track's estimate must have been from where it was first
            seen: a false track on something static (a changing screen, a bootstrap
            ghost) would otherwise learn its changes and keep itself alive.
    """

    rate: float = 0.05
    min_free: float = 0.9
    min_visibility: float = 0.9
    min_existence: float = 0.9
    neighbour_radius: float = 0.8
    max_distance: float = 0.3
    foreground_only: bool = True
    interval: float = 0.5
    min_travel: float = 1.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.rate <= 1.0:
            raise DetectionError(f'adaptation rate must be in [0, 1], got {self.rate}')
        for name in ('min_free', 'min_visibility', 'min_existence'):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise DetectionError(f'adaptation {name} must be in [0, 1]')
        if not (self.neighbour_radius >= 0 and 0.0 < self.max_distance <= 1.0
                and self.interval >= 0 and self.min_travel >= 0):
            raise DetectionError('adaptation neighbour_radius, interval and min_travel '
                                 'must be >= 0 and max_distance in (0, 1]')


@dataclass
class Observation:
    """One track seen in one camera: its part histograms (3, 512), relative angle, the
    free fraction of its silhouette and the distances (003 Eq. 3) to its own model and to
    the nearest other track's model."""

    track_id: int
    camera: str
    angle: float
    hists: np.ndarray
    free: float
    distance: float
    other_distance: float


def weighted_distance(observed: np.ndarray, pixels: np.ndarray, expected: np.ndarray
                      ) -> np.ndarray:
    """003 Eq. 3's ``sum_p a_p d^2_p / sum_p a_p``: observed parts (3, 512) with pixel
    counts ``pixels`` (3,) against expected part histograms (..., 3, 512)."""
    d2 = bhattacharyya_distance_sq(observed, expected)          # (..., 3), 003 Eq. 4
    total = float(pixels.sum())
    return (d2 * pixels).sum(axis=-1) / total if total > 0 else np.full(d2.shape[:-1], 1.0)


def observe(bins: np.ndarray, sil: Silhouettes, k: int, camera_name: str,
            calibration: RoomCalibration, means: np.ndarray, track_ids: Sequence[int],
            models: Sequence[PersonModel | None], max_distance: float = 1.0,
            foreground: np.ndarray | None = None) -> Observation | None:
    """What camera ``camera_name`` shows of track k (rasterised as ``sil``, all tracks at
    their means (K, 6), in the order of ``track_ids`` / ``models``): its part histograms
    on the pixels no closer track's silhouette covers (and, given ``foreground`` (H, W)
    bool, that are foreground), or None when it has no pixels.
    The distance to the nearest other model is computed only when the one to its own is
    at most ``max_distance`` (+inf otherwise, and when there is no other model)."""
    full = float(sil.full_area[k])
    if full <= 0 or sil.area[k] <= 0:
        return None
    occluded = np.zeros((sil.height, sil.width), np.uint8)
    for j in range(len(sil)):
        if j != k and sil.distance[j] < sil.distance[k]:
            _kernels.paint_spans(occluded, sil.row, sil.x0, sil.x1, sil.part,
                                 int(sil.offsets[j]), int(sil.offsets[j + 1]), 1, False)
    free = 1.0 - occluded
    counts = part_histograms(bins, sil, k, free, normalize=False)
    free_pixels = float(counts.sum())
    if foreground is not None:
        counts = part_histograms(bins, sil, k, free * foreground, normalize=False)
    pixels = counts.sum(axis=1)
    if pixels.sum() <= 0:
        return None
    hists = counts / np.maximum(pixels, 1.0)[:, None]
    cam = calibration.cameras[camera_name]
    rel = relative_angle(means[:, THETA], cam.viewing_angle(means[:, [X, Y]]))
    own = float(weighted_distance(hists, pixels, models[k].interpolate(rel[k:k + 1]))[0])
    other = float('inf')
    if own <= max_distance:  # the other models only for an observation that may be learnt
        other = min((float(weighted_distance(hists, pixels,
                                             models[j].interpolate(rel[k:k + 1]))[0])
                     for j in range(len(models))
                     if j != k and models[j] is not None and models[j].view_angles.size),
                    default=float('inf'))
    return Observation(int(track_ids[k]), camera_name, float(rel[k]), hists,
                       free_pixels / full, own, other)


def adapt_models(config: AdaptationConfig, calibration: RoomCalibration,
                 bins: Mapping[str, np.ndarray], sils: Mapping[str, Silhouettes],
                 means: np.ndarray, track_ids: Sequence[int],
                 models: Sequence[PersonModel | None], eligible: np.ndarray,
                 visibility: Sequence[Mapping[str, float]],
                 foreground: Mapping[str, np.ndarray] | None = None) -> list[dict]:
    """Adapt the models of the eligible tracks (K,) bool (reported, existence high, model
    not moved lately: the caller's judgement) in place from the side cameras ``bins`` /
    ``sils`` (all K tracks rasterised at their means (K, 6)); ``visibility[k]``: camera ->
    ``xi_v`` of track k; ``foreground``: camera -> (H, W) bool mask (for
    ``foreground_only``). Returns one record per track and camera looked at (what was
    decided and why), for diagnostics."""
    records: list[dict] = []
    if config.rate <= 0 or not len(track_ids):
        return records
    xy = means[:, [X, Y]]
    gap = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    np.fill_diagonal(gap, np.inf)
    alone = gap.min(axis=1) > config.neighbour_radius if len(xy) > 1 \
        else np.ones(len(xy), bool)
    for k in np.flatnonzero(np.asarray(eligible, bool) & alone):
        model = models[k]
        if model is None or not model.view_angles.size:
            continue
        for name, sil in sils.items():
            if name not in bins or visibility[k].get(name, 0.0) < config.min_visibility:
                continue
            fg = None if foreground is None or not config.foreground_only \
                else foreground.get(name)
            seen = observe(bins[name], sil, int(k), name, calibration, means, track_ids,
                           models, config.max_distance, fg)
            if seen is None or seen.free < config.min_free:
                continue
            record = {'id': seen.track_id, 'camera': name, 'distance': round(seen.distance, 4),
                      'other': round(min(seen.other_distance, 1.0), 4),
                      'free': round(seen.free, 3)}
            if seen.distance > config.max_distance or seen.distance >= seen.other_distance:
                record['action'] = 'inconsistent'
            else:
                added = model.adapt(seen.angle, seen.hists, config.rate)
                record['action'] = 'new view' if added else 'blend'
            records.append(record)
    return records
