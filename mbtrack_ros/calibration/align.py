"""Photometric refinement of a board's pose: the board's known picture, seen through the
calibrated camera, aligned with the image over every pixel of the board.

Corner detectors look at a few pixels around each corner; on a board across the room a
ChArUco corner has its markers two or three pixels away and its position is biased by a few
tenths of a pixel. With the intrinsics known, the board's picture predicts every pixel it
covers: ``I(p) = a + b * T(pi^-1(p; R, t))`` with T the board's reflectance (blurred to the
pixel footprint and averaged over 3 x 3 rays per pixel), pi^-1 the ray of pixel p met with
the board plane, and the illumination (an offset a and a gain b varying linearly over the
board) fitted in closed form at every step (variable projection); at most 8000 of the
board's pixels, evenly spread.
The 6 pose parameters minimise the robust (soft-L1, 8 grey levels) sum of squared
differences (``scipy.optimize.least_squares``), coarse (texture blurred 3x) then fine. The
refined pose gives back the corners' pixels, which then enter the PnP and the bundle
adjustment like detected corners.
"""
from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
from scipy.optimize import least_squares

from mbtrack_ros.calibration.board import Board
from mbtrack_ros.core.camera import Camera

__all__ = ['refine_corners']

_TEXTURE_PPM = 1000.0  # board reflectance map, pixels per metre
_MAX_SHIFT_PX = 1.5    # refined corners further than this (RMS) from the detected: rejected
_MAX_PIXELS = 8000     # board pixels used at most


def sample_bilinear(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples (N,) of a (h, w) float32 texture at pixel positions (N, 2)."""
    n = len(uv)
    rows = -(-n // 4096)
    maps = np.zeros((rows * 4096, 2), np.float32)
    maps[:n] = uv
    maps = maps.reshape(rows, 4096, 2)
    out = cv2.remap(texture, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1)[:n]


def refine_corners(gray: np.ndarray, camera: Camera, board: Board, ids: np.ndarray,
                   pixels: np.ndarray) -> np.ndarray:
    """Corner pixels (N, 2) of ``ids`` re-derived from the board pose aligned photometrically
    with ``gray`` (H, W) through ``camera`` (intrinsics used, pose ignored); the detected
    ``pixels`` when there are too few corners, the board covers under 200 pixels, or the
    alignment moves the corners more than 1.5 px RMS."""
    if len(ids) < 4:
        return pixels
    cam = replace(camera, R=np.eye(3), t=np.zeros(3))
    obj = board.corners[ids]
    ok, rvec, tvec = cv2.solvePnP(obj, pixels, cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return pixels
    rvec, tvec = cv2.solvePnPRefineLM(obj, pixels, cam.K, cam.dist, rvec, tvec)
    outline = cam.project(_pose_points(board.outline, rvec, tvec))
    if not np.isfinite(outline).all():
        return pixels
    mask = np.zeros(gray.shape, np.uint8)
    cv2.fillPoly(mask, [np.round(outline).astype(np.int32).reshape(-1, 1, 2)], 1)
    mask = cv2.erode(mask, np.ones((5, 5), np.uint8))
    ys, xs = np.nonzero(mask)
    if len(xs) < 200:
        return pixels
    if len(xs) > _MAX_PIXELS:  # a regular subset is as informative and bounds the work
        keep = np.linspace(0, len(xs) - 1, _MAX_PIXELS).astype(int)
        ys, xs = ys[keep], xs[keep]
    image = gray[ys, xs].astype(np.float64)
    offsets = (np.arange(3) + 0.5) / 3 - 0.5
    sub = np.stack(np.meshgrid(offsets, offsets), -1).reshape(-1, 2)
    grid = np.stack([xs, ys], 1).astype(np.float64)
    rays = cam.pixel_rays((grid[:, None, :] + sub[None]).reshape(-1, 2))
    depth = float(np.linalg.norm(tvec))
    metres_per_sample = depth / cam.focal / 3.0
    base = board.image(_TEXTURE_PPM, 0.0).astype(np.float32) / 255.0
    origin = board.outline[0, :2]

    # illumination a + b T varying linearly over the board: I = a + T (b0 + b1 u + b2 v)
    u = (xs - xs.mean()) / max(float(np.ptp(xs)), 1.0)
    v = (ys - ys.mean()) / max(float(np.ptp(ys)), 1.0)

    def residuals(x, texture):
        R, _ = cv2.Rodrigues(x[:3])
        t = x[3:]
        normal = R[:, 2]
        with np.errstate(divide='ignore', invalid='ignore'):
            s = (normal @ t) / (rays @ normal)
        xy = ((rays * s[:, None] - t) @ R)[:, :2]
        uv = (np.nan_to_num(xy) - origin) * _TEXTURE_PPM - 0.5
        model = sample_bilinear(texture, uv.astype(np.float32)).reshape(len(grid), -1).mean(axis=1)
        A = np.stack([np.ones_like(model), model, model * u, model * v], 1)
        coef, *_ = np.linalg.lstsq(A, image, rcond=None)
        return A @ coef - image

    x = np.concatenate([np.ravel(rvec), np.ravel(tvec)])
    for blur in (3.0, 1.0):
        sigma = max(0.5, blur * 0.5 * metres_per_sample * _TEXTURE_PPM)
        texture = cv2.GaussianBlur(base, (0, 0), sigma)
        sol = least_squares(residuals, x, args=(texture,), method='trf', loss='soft_l1',
                            f_scale=8.0, diff_step=1e-6, max_nfev=30)
        x = sol.x
    refined = cam.project(_pose_points(obj, x[:3], x[3:]))
    if not np.isfinite(refined).all() or \
            np.sqrt(np.mean(np.sum((refined - pixels) ** 2, axis=1))) > _MAX_SHIFT_PX:
        return pixels
    return refined


def _pose_points(points: np.ndarray, rvec, tvec) -> np.ndarray:
    """Board points (N, 3) in the camera frame for a board -> camera pose."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3))
    return points @ R.T + np.asarray(tvec, np.float64).reshape(3)
