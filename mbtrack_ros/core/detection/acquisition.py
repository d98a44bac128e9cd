"""Appearance-model acquisition of a newly detected person (003 §4.1).

On detection, the shape model is rendered at the detected configuration in every side
camera; the part histograms of each view where the new person is unoccluded become key
views of its :class:`~mbtrack_ros.core.appearance.PersonModel`, annotated with the relative
viewing angle, together with the detected height and width. Occlusion is judged from the
other tracks' rendered silhouettes that are *closer* to the camera than the new person.
A detection that no camera sees unoccluded is not acquired (yet): the caller retries on a
later frame. The histogram extraction itself is the appearance module's
(:func:`~mbtrack_ros.core.appearance.model_from_images`).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from mbtrack_ros.core.appearance import AppearanceError, PersonModel, model_from_images
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.detector import Detection, is_ceiling
from mbtrack_ros.core.shape import BodyShape, rasterize

__all__ = ['AcquisitionConfig', 'acquire', 'occluders']


@dataclass(frozen=True)
class AcquisitionConfig:
    """Parameters of the model acquisition.

    Attributes:
        min_visible: a camera gives a key view only if at least this fraction of the
            person's silhouette is inside the image and not hidden by closer tracks.
        use_ceiling: also take key views from top-down cameras (off: 003 §5 uses the
            ceiling camera for detection and release only).
        min_views: key views needed to acquire the model.
    """

    min_visible: float = 0.7
    use_ceiling: bool = False
    min_views: int = 1

    def __post_init__(self) -> None:
        if not 0.0 < self.min_visible <= 1.0:
            raise DetectionError(f'min_visible must be in (0, 1], got {self.min_visible}')
        if self.min_views < 1:
            raise DetectionError('min_views must be >= 1')


def occluders(calibration: RoomCalibration, state: np.ndarray, others: np.ndarray,
              shapes: Sequence[BodyShape], camera: str, *, shape: BodyShape) -> np.ndarray:
    """(H, W) bool pixels of camera ``camera`` hidden by other people closer than ``state``.

    Args:
        state: (6,) the new person's state; ``shape`` its body model.
        others: (K, 6) states of the current tracks; ``shapes`` their K body models.
    """
    cam = calibration.cameras[camera]
    out = np.zeros((cam.height, cam.width), bool)
    others = np.asarray(others, dtype=np.float64).reshape(-1, 6)
    if others.shape[0] == 0:
        return out
    if len(shapes) != others.shape[0]:
        raise DetectionError(f'{len(shapes)} shapes for {others.shape[0]} tracks')
    me = rasterize(cam, np.asarray(state, np.float64)[None], shape)
    sil = rasterize(cam, others, list(shapes))
    for k in range(others.shape[0]):
        if sil.distance[k] < me.distance[0]:
            out |= sil.mask(k) > 0
    return out


def acquire(detection: Detection, images: Mapping[str, np.ndarray],
            calibration: RoomCalibration, *, others: np.ndarray | None = None,
            other_shapes: Sequence[BodyShape] = (), config: AcquisitionConfig | None = None
            ) -> PersonModel | None:
    """Person model of a detection from the current frame set, or None if no camera
    sees it unoccluded (003 §4.1: key views from all unoccluded views).

    Args:
        detection: the detected configuration (state, height, width).
        images: camera -> (H, W, 3) uint8 RGB image of the detection frame.
        calibration: the room.
        others: (K, 6) states of the current tracks, ``other_shapes`` their body models.
    """
    cfg = config or AcquisitionConfig()
    others = np.zeros((0, 6)) if others is None else np.asarray(others, np.float64)
    shape = BodyShape(height=detection.height, width=detection.width)
    names = [n for n in images if n in calibration.cameras
             and (cfg.use_ceiling or not is_ceiling(calibration.cameras[n]))]
    occluded = {n: occluders(calibration, detection.state, others, other_shapes, n,
                             shape=shape) for n in names}
    try:
        model = model_from_images({n: images[n] for n in names}, calibration,
                                  detection.state, detection.height, detection.width,
                                  occluded=occluded, min_visible=cfg.min_visible,
                                  chair_height=shape.chair_height)
    except AppearanceError as err:
        raise DetectionError(f'model acquisition failed: {err}') from err
    if model.view_angles.size < cfg.min_views:
        return None
    return model
