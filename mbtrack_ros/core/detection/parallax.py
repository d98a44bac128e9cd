"""Floor-plane parallax: what stands on the floor, from one multi-view frame set.

Every camera sees the floor; a floor point seen by two cameras has one colour in both
(the floor is a plane: the pixel of a floor point in camera b follows from its pixel in
camera a by the plane's homography, with the cameras' distortion). A pixel of camera a
whose ray meets an object standing on the floor shows that object, while the other
cameras see, at the floor point behind it, the floor: the two disagree. This is the
plane + parallax background of Ivanov, Bobick and Liu ("Fast lighting independent
background subtraction", IJCV 37(2), 2000): the empty scene's geometry, not its past
frames, predicts what each pixel would show without the object, so a person who has
never moved is foreground from the first frame.

:class:`FloorParallax` gives, per camera, the pixels whose floor point (inside the
walkable floor) the other cameras show differently, and the pixels where the test applies
at all (the others: walls and ceiling behind, a floor point fewer than two other cameras
see). The difference is robust to a one-pixel calibration error (the colour must lie
outside the range of the other camera's 3x3 neighbourhood) and to the cameras' different
exposure (a per-channel gain, the median of the pixels' ratios over the floor both see).
At least half of the other cameras that see the floor point must disagree, and a pixel is
tested only where two or more see it, so that a person in front of the floor point in
one of them (an occlusion, not a disagreement) does not count; where only one other
camera can see the floor point at all (always in a two-camera room) that one is asked,
and the occlusion it cannot tell from a disagreement is left to the caller.
:class:`~.people.PeopleCue` uses it for the people who stand still while the background
is bootstrapped.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from mbtrack_ros.core.camera import RoomCalibration

__all__ = ['FloorParallax', 'ParallaxEvidence']


class FloorParallax:
    """Per-camera floor-parallax masks of a room (the geometry is computed once).

    Args:
        calibration: the room (its cameras and walkable floor rectangle).
        cameras: the cameras to test and compare (default all).
        threshold: colour difference, 8-bit grey levels (largest over the channels, after
            the gain), above which two views of a floor point disagree.
    """

    def __init__(self, calibration: RoomCalibration, cameras: Sequence[str] | None = None,
                 *, threshold: float = 20.0) -> None:
        self.calibration = calibration
        self.cameras = list(calibration.cameras if cameras is None else cameras)
        self.threshold = float(threshold)
        x0, y0, x1, y1 = calibration.floor
        # per ordered pair (a, b): where camera b sees the floor point of each pixel of a
        self._maps: dict[str, list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]] = {}
        self._floor: dict[str, np.ndarray] = {}
        for a in self.cameras:
            ca = calibration.cameras[a]
            u, v = np.meshgrid(np.arange(ca.width) + 0.5, np.arange(ca.height) + 0.5)
            pts = ca.floor_point(np.stack([u, v], axis=-1))          # (H, W, 3) metres
            on = np.all(np.isfinite(pts), axis=-1)
            px, py = pts[..., 0], pts[..., 1]
            with np.errstate(invalid='ignore'):
                on &= (px >= x0) & (px <= x1) & (py >= y0) & (py <= y1)
            self._floor[a] = on
            pairs = []
            for b in self.cameras:
                if b == a:
                    continue
                cb = calibration.cameras[b]
                q = cb.project(np.where(on[..., None], pts, 0.0).reshape(-1, 3))
                q = q.reshape(ca.height, ca.width, 2)
                sees = on & cb.in_image(q, margin=1.0) & (cb.depth(pts.reshape(-1, 3))
                                                           .reshape(on.shape) > 0)
                if not sees.any():
                    continue
                m = np.where(sees[..., None], q - 0.5, -10.0).astype(np.float32)
                pairs.append((b, m[..., 0].copy(), m[..., 1].copy(), sees))
            self._maps[a] = pairs

    def differences(self, images: Mapping[str, np.ndarray]) -> dict[str, ParallaxEvidence]:
        """Per camera of ``images`` (camera -> (H, W, 3) uint8, the calibration's size)
        and per other camera that sees its floor, how differently that camera shows each
        pixel's floor point (:class:`ParallaxEvidence`)."""
        out = {}
        kernel = np.ones((3, 3), np.uint8)
        for a in self.cameras:
            if a not in images:
                continue
            ia = images[a].astype(np.float32)
            others, diffs, seen, maps = [], [], [], []
            for b, mx, my, sees in self._maps[a]:
                if b not in images:
                    continue
                wb = cv2.remap(images[b], mx, my, cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_REPLICATE).astype(np.float32)
                # exposure: per-channel gain, the median of the pixels' ratios over the
                # shared floor (an object or an occlusion is a minority of them)
                wb *= np.median(ia[sees] / np.maximum(wb[sees], 1.0), axis=0)
                lo, hi = cv2.erode(wb, kernel), cv2.dilate(wb, kernel)
                diffs.append(np.maximum(np.maximum(ia - hi, lo - ia), 0.0).max(axis=-1))
                seen.append(sees)
                others.append(b)
                maps.append((mx, my))
            if others:
                out[a] = ParallaxEvidence(others, np.stack(diffs), np.stack(seen), maps)
        return out

    def decide(self, evidence: ParallaxEvidence,
               hidden: Mapping[str, np.ndarray] | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """``(disagree, known)``, two (H, W) bool masks of one camera: the pixels whose
        floor point at least half of the other cameras that see it show differently
        (difference above ``threshold``), and the pixels where that was tested: those
        whose floor point at least two other cameras see, or the one other camera that
        sees it at all (``seen`` before ``hidden``: the test asks what the room's
        cameras can answer). With one, a person here and one hiding the floor point from
        it there look alike; the caller tells them apart (:class:`~.people.PeopleCue`
        requires the views to agree place by place). ``hidden``
        (camera -> (H, W) bool, e.g. people's silhouettes) are pixels of the other
        cameras that show something in front of the floor: no evidence about it."""
        seen = evidence.seen.copy()
        for k, b in enumerate(evidence.others):
            if hidden is not None and b in hidden and hidden[b].any():
                mx, my = evidence.maps[k]
                hit = cv2.remap(hidden[b].astype(np.uint8), mx, my, cv2.INTER_NEAREST,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
                seen[k] &= hit == 0
        count = seen.sum(axis=0)
        known = (count >= np.minimum(2, evidence.seen.sum(axis=0))) & (count >= 1)
        # the lower median over the cameras that see the floor point: at least half of
        # them show it differently (an occlusion in one of two is no disagreement)
        ranked = np.sort(np.where(seen, evidence.diff, np.inf), axis=0)
        lower = np.take_along_axis(ranked, np.maximum(count - 1, 0)[None] // 2, axis=0)[0]
        return known & (lower > self.threshold), known

    def masks(self, images: Mapping[str, np.ndarray],
              hidden: Mapping[str, np.ndarray] | None = None
              ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """:meth:`decide` for every camera of ``images``."""
        return {a: self.decide(ev, hidden) for a, ev in self.differences(images).items()}


@dataclass(frozen=True)
class ParallaxEvidence:
    """One camera's comparisons with the others (K of them).

    Attributes:
        others: the K other cameras' names.
        diff: (K, H, W) float32 colour difference of each pixel from the other camera's
            view of its floor point, grey levels (0 within that view's 3x3 range).
        seen: (K, H, W) bool, the other camera sees the pixel's floor point.
        maps: K (x, y) pairs of (H, W) float32 pixel coordinates of the floor points in
            the other cameras (``cv2.remap`` maps).
    """

    others: list[str]
    diff: np.ndarray
    seen: np.ndarray
    maps: list[tuple[np.ndarray, np.ndarray]]
