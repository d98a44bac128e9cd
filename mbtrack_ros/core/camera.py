"""Calibrated pinhole cameras with lens distortion, and the room calibration file.

Conventions (documented in README, "Room calibration file"):

* world frame ``room``: metres, floor at z = 0, z up;
* extrinsics world -> camera: ``x_cam = R @ X_world + t`` (OpenCV optical frame:
  x right, y down, z forward);
* intrinsics as in ``sensor_msgs/CameraInfo``: ``K`` (3x3), ``plumb_bob`` distortion
  ``D = [k1, k2, p1, p2, k3]``, image ``width`` x ``height`` in pixels, pixel centres at
  integer coordinates (OpenCV).

This is the only place where 3D points are projected into images; every other module
(renderer, shape model, detection) calls :meth:`Camera.project`.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from mbtrack_ros.core import _kernels

__all__ = ['MAX_FLOOR_SIDE', 'MAX_IMAGE_SIDE', 'MIN_FLOOR_VIEW', 'CalibrationError',
           'Camera', 'RoomCalibration', 'area_shrink', 'block_shrink', 'check_floor_views',
           'look_at', 'yaml_error_line']

#: largest image side a camera may declare, pixels (images larger than this are refused)
MAX_IMAGE_SIDE = 8192
#: largest side of the walkable floor, metres (the detection grids cover the whole floor)
MAX_FLOOR_SIDE = 100.0
#: share of the floor a camera must see (its image of the floor rectangle) to count as a
#: useful view; less gets a warning, a room where no camera sees any of it is refused
MIN_FLOOR_VIEW = 0.03


class CalibrationError(ValueError):
    """A calibration file or value that cannot be used."""


def _as_matrix(value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    if isinstance(value, (str, bytes)):
        raise CalibrationError(f'{what}: expected {int(np.prod(shape))} numbers, '
                               f'got text {value!r:.40}')
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as err:
        raise CalibrationError(f'{what}: expected {int(np.prod(shape))} numbers, '
                               f'got {value!r:.60}') from err
    if array.size != int(np.prod(shape)):
        raise CalibrationError(f'{what}: expected {int(np.prod(shape))} numbers, '
                               f'got {array.size}')
    if not np.all(np.isfinite(array)):
        raise CalibrationError(f'{what}: contains non-finite values')
    return array.reshape(shape)


def _number(value: Any, what: str) -> float:
    """A finite float from a YAML scalar (bool and text refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise CalibrationError(f'{what}: expected a number, got {value!r:.40}')
    try:
        number = float(value)
    except OverflowError as err:
        raise CalibrationError(f'{what}: number out of range') from err
    if not np.isfinite(number):
        raise CalibrationError(f'{what}: must be finite, got {number}')
    return number


def _image_side(value: Any, what: str) -> int:
    """An image side, a whole number of pixels in 1 .. MAX_IMAGE_SIDE."""
    number = _number(value, what)
    if number != round(number) or not 1 <= number <= MAX_IMAGE_SIDE:
        raise CalibrationError(f'{what}: expected a whole number of pixels in 1 .. '
                               f'{MAX_IMAGE_SIDE}, got {value!r:.40}')
    return int(number)


def _rectangle(value: Any, what: str) -> tuple[float, float, float, float]:
    """A non-empty finite ``(x_min, y_min, x_max, y_max)`` rectangle, metres."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple, np.ndarray)) \
            or len(value) != 4:
        raise CalibrationError(f'{what}: expected [x_min, y_min, x_max, y_max], '
                               f'got {value!r:.60}')
    x0, y0, x1, y1 = (_number(v, what) for v in value)
    if not (x1 > x0 and y1 > y0):
        raise CalibrationError(f'{what}: empty rectangle {[x0, y0, x1, y1]}')
    return (x0, y0, x1, y1)


@lru_cache(maxsize=64)
def _area_taps(n_in: int, n_out: int) -> tuple[np.ndarray, np.ndarray]:
    """Area-averaging weights of shrinking ``n_in`` samples to ``n_out`` <= ``n_in``:
    ``(index, weight)`` (n_out, K) int32 / float32, K = ceil(n_in / n_out) + 1. Output
    ``o`` covers the input interval [o s, (o + 1) s), s = n_in / n_out; an input sample
    ``i`` weighs the length of [i, i + 1) inside it, divided by s (weights sum to 1, zero
    weights pad)."""
    s = n_in / n_out
    k = int(np.ceil(s)) + 1
    a = np.arange(n_out, dtype=np.float64)[:, None] * s
    i = np.floor(a).astype(np.int64) + np.arange(k)[None, :]
    overlap = np.minimum(a + s, i + 1) - np.maximum(a, i)
    weight = np.where((overlap > 1e-9) & (i < n_in), overlap / s, 0.0)
    weight /= weight.sum(axis=1, keepdims=True)
    index = np.clip(i, 0, n_in - 1).astype(np.int32)
    index.flags.writeable = weight.flags.writeable = False
    return index, weight.astype(np.float32)


@lru_cache(maxsize=64)
def _column_taps(n_in: int, n_out: int, channels: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_area_taps` of the columns, per element of an interleaved (n_out * channels)
    row: ``(index, weight)`` (K, n_out * channels) into an (n_in * channels) row."""
    index, weight = _area_taps(n_in, n_out)
    c = np.arange(channels)
    cols = (index.T[:, :, None] * channels + c).reshape(index.shape[1], -1).astype(np.int32)
    wts = np.repeat(weight.T, channels, axis=1).astype(np.float32)
    cols.flags.writeable = wts.flags.writeable = False
    return np.ascontiguousarray(cols), np.ascontiguousarray(wts)


def area_shrink(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """``image`` (H, W[, C]) uint8 shrunk to ``width`` x ``height`` (<= W, H) by area
    averaging: each output pixel is the mean of the input over its cell (``_area_taps``;
    OpenCV's ``INTER_AREA`` up to rounding, one grey level). A numba kernel
    (``_kernels.area_shrink``, no GIL) that reads a C-contiguous input in place."""
    src = np.asarray(image)
    grey = src.ndim == 2
    if grey:
        src = src[:, :, None]
    h_in, w_in, channels = src.shape
    if not (0 < width <= w_in and 0 < height <= h_in) or src.dtype != np.uint8:
        raise ValueError(f'area_shrink: cannot shrink a {src.dtype} {w_in}x{h_in} image '
                         f'to {width}x{height}')
    if not src.flags.c_contiguous:
        src = np.ascontiguousarray(src)
    rows, row_w = _area_taps(h_in, height)
    cols, col_w = _column_taps(w_in, width, channels)
    out = np.empty((height, width, channels), np.uint8)
    _kernels.area_shrink(src, rows, row_w, cols, col_w, out)
    return out[:, :, 0] if grey else out


@lru_cache(maxsize=16)
def _rounded_means(n: int) -> np.ndarray:
    """(255 n + 1,) uint8: the mean of ``n`` uint8 values from their sum, rounded half
    up (``(s + n // 2) // n``)."""
    table = ((np.arange(255 * n + 1) + n // 2) // n).astype(np.uint8)
    table.flags.writeable = False
    return table


def block_shrink(image: np.ndarray, kx: int, ky: int) -> np.ndarray:
    """``image`` (H, W[, C]) uint8, H and W multiples of ``ky`` and ``kx``, shrunk to
    (H / ky, W / kx) by the exact area average: each output pixel is the rounded mean of
    its ``ky`` x ``kx`` block (``_kernels.block_mean``, no GIL; reads a C-contiguous
    input in place). Equal to OpenCV's integer-factor ``INTER_AREA`` up to one grey level
    of rounding."""
    src = np.asarray(image)
    grey = src.ndim == 2
    if grey:
        src = src[:, :, None]
    h_in, w_in, channels = src.shape
    if kx < 1 or ky < 1 or h_in % ky or w_in % kx or src.dtype != np.uint8:
        raise ValueError(f'block_shrink: cannot shrink a {src.dtype} {w_in}x{h_in} image by '
                         f'{kx}x{ky} blocks')
    if not src.flags.c_contiguous:
        src = np.ascontiguousarray(src)
    out = np.empty((h_in // ky, w_in // kx, channels), np.uint8)
    _kernels.block_mean(src, ky, kx, _rounded_means(kx * ky), out)
    return out[:, :, 0] if grey else out


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated camera.

    Attributes:
        name: camera name, unique in a room (``cam0``).
        width, height: image size in pixels.
        K: (3, 3) intrinsic matrix.
        dist: (5,) plumb_bob distortion ``[k1, k2, p1, p2, k3]``.
        R: (3, 3) rotation world -> camera.
        t: (3,) translation world -> camera, metres.
        frame_id: the optical frame id written into image headers.
        time_offset: seconds added to this camera's image stamps to give the capture time
            on the rig's common clock (a camera whose clock runs 30 ms late: 0.03); the
            frame-set synchroniser applies it (:mod:`mbtrack_ros.recording.sync`).
    """

    name: str
    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    frame_id: str = ''
    time_offset: float = 0.0

    def __post_init__(self) -> None:
        what = f'camera {self.name}'
        object.__setattr__(self, 'K', _as_matrix(self.K, (3, 3), f'{what}: K'))
        try:
            offset = float(self.time_offset)
        except (TypeError, ValueError):
            offset = float('nan')
        if not (np.isfinite(offset) and abs(offset) <= 10.0):
            raise CalibrationError(f'{what}: time_offset must be a number of seconds within '
                                   f'+-10, got {self.time_offset!r:.40}')
        object.__setattr__(self, 'time_offset', offset)
        dist = np.zeros(5)
        try:
            given = (None if isinstance(self.dist, (str, bytes))
                     else np.asarray(self.dist, dtype=np.float64).ravel())
        except (TypeError, ValueError, OverflowError):
            given = None
        if given is None:
            raise CalibrationError(f'{what}: distortion_coefficients: expected numbers, got '
                                   f'{self.dist!r:.40}')
        if given.size > 5:
            raise CalibrationError(f'{what}: dist: at most 5 plumb_bob coefficients')
        if not np.all(np.isfinite(given)):  # a NaN coefficient projects every point to NaN
            raise CalibrationError(f'{what}: distortion_coefficients: contains non-finite '
                                   'values')
        dist[: given.size] = given
        object.__setattr__(self, 'dist', dist)
        R = _as_matrix(self.R, (3, 3), f'{what}: R')
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
            raise CalibrationError(f'{what}: R is not a rotation matrix')
        object.__setattr__(self, 'R', R)
        object.__setattr__(self, 't', _as_matrix(self.t, (3,), f'{what}: t'))
        object.__setattr__(self, 'width', _image_side(self.width, f'{what}: image_width'))
        object.__setattr__(self, 'height', _image_side(self.height, f'{what}: image_height'))
        if not self.frame_id:
            object.__setattr__(self, 'frame_id', f'{self.name}_optical_frame')
        if self.K[0, 0] <= 0 or self.K[1, 1] <= 0:
            raise CalibrationError(f'{what}: K: focal lengths must be positive')
        # the rotation matrix OpenCV's projectPoints rebuilds from the Rodrigues vector
        # (differs from R in the last bits); project() uses it to give the same pixels
        rvec, _ = cv2.Rodrigues(R)
        object.__setattr__(self, '_projection_rotation', np.ascontiguousarray(
            cv2.Rodrigues(rvec)[0], dtype=np.float64))
        object.__setattr__(self, '_center', -R.T @ self.t)

    # -- geometry -------------------------------------------------------------------------
    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, (3,) metres: ``C = -R^T t``."""
        return self._center.copy()

    @property
    def projection_parameters(self) -> tuple[np.ndarray, ...]:
        """``(rotation, t, K, dist, centre)`` as the numba projection takes them (the rotation
        OpenCV rebuilds from the Rodrigues vector of R)."""
        return self._projection_rotation, self.t, self.K, self.dist, self._center

    @property
    def depth_row(self) -> tuple[np.ndarray, float]:
        """``(R[2], t[2])``: :meth:`depth` is ``points @ R[2] + t[2]`` (for numba kernels)."""
        return np.ascontiguousarray(self.R[2]), float(self.t[2])

    @property
    def focal(self) -> float:
        """Mean focal length in pixels."""
        return float(0.5 * (self.K[0, 0] + self.K[1, 1]))

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) -> camera-frame points (..., 3)."""
        points = np.asarray(points, dtype=np.float64)
        return points @ self.R.T + self.t

    def depth(self, points: np.ndarray) -> np.ndarray:
        """Optical-axis depth z_cam of world points (..., 3) -> (...,), metres."""
        points = np.asarray(points, dtype=np.float64)
        return points @ self.R[2] + self.t[2]

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Euclidean distance of world points (..., 3) to the camera centre, metres.

        This is the camera closeness ``<_u`` used for depth ordering (HJS Eq. 20).
        """
        return np.linalg.norm(np.asarray(points, dtype=np.float64) - self._center, axis=-1)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Project world points (..., 3) to distorted pixel coordinates (..., 2).

        Points behind the camera (z_cam <= 0) get NaN coordinates.
        """
        points = np.asarray(points, dtype=np.float64)
        flat = points.reshape(-1, 3)
        if flat.shape[0] == 0:
            return np.zeros(points.shape[:-1] + (2,))
        pixels = _kernels.project_points(np.ascontiguousarray(flat),
                                         *self.projection_parameters[:4])
        pixels[self.depth(flat) <= 1e-6] = np.nan
        return pixels.reshape(points.shape[:-1] + (2,))

    def normalized_rays(self, pixels: np.ndarray) -> np.ndarray:
        """Undistort pixels (..., 2) to camera-frame ray directions (..., 3) with z = 1.

        OpenCV's fixed-point undistortion is polished by Newton steps on the distortion
        model (finite-difference Jacobian), so that a ray projects back onto its pixel to
        about 1e-6 px also in the corners of wide-angle images, where the fixed point
        stops pixels short."""
        pixels = np.asarray(pixels, dtype=np.float64)
        flat = pixels.reshape(-1, 1, 2)
        if flat.shape[0] == 0:
            return np.zeros(pixels.shape[:-1] + (3,))
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-9)
        if hasattr(cv2, 'undistortPointsIter'):  # OpenCV 4.x spells the iterative variant so
            und = cv2.undistortPointsIter(flat, self.K, self.dist, None, None, criteria)
        else:
            und = cv2.undistortPoints(flat, self.K, self.dist, criteria=criteria)
        und = self._polish(und.reshape(-1, 2), pixels.reshape(-1, 2))
        rays = np.concatenate([und, np.ones((und.shape[0], 1))], axis=1)
        return rays.reshape(pixels.shape[:-1] + (3,))

    def _polish(self, n: np.ndarray, pixels: np.ndarray, iterations: int = 4) -> np.ndarray:
        """Newton steps on normalised image coordinates ``n`` (N, 2) towards distorting onto
        ``pixels`` (N, 2); a step that does not bring a point closer is not taken."""
        eye, zero = np.eye(3), np.zeros(3)

        def distort(xy: np.ndarray) -> np.ndarray:
            pts = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
            return _kernels.project_points(pts, eye, zero, self.K, self.dist)

        eps = 1e-6
        n = n.copy()
        for _ in range(iterations):
            f = distort(n)
            r = f - pixels
            if not np.any(np.abs(r) > 1e-7):
                break
            jx = (distort(n + (eps, 0.0)) - f) / eps
            jy = (distort(n + (0.0, eps)) - f) / eps
            det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
            with np.errstate(divide='ignore', invalid='ignore'):
                dx = (jy[:, 1] * r[:, 0] - jy[:, 0] * r[:, 1]) / det
                dy = (-jx[:, 1] * r[:, 0] + jx[:, 0] * r[:, 1]) / det
            step = np.stack([dx, dy], 1)
            trial = np.where(np.isfinite(step), n - step, n)
            better = np.linalg.norm(distort(trial) - pixels, axis=1) < np.linalg.norm(r, axis=1)
            n = np.where(better[:, None], trial, n)
        return n

    def pixel_rays(self, pixels: np.ndarray) -> np.ndarray:
        """Unit world-frame viewing directions (..., 3) of pixels (..., 2)."""
        rays = self.normalized_rays(pixels) @ self.R  # R^T applied to row vectors
        return rays / np.linalg.norm(rays, axis=-1, keepdims=True)

    def floor_point(self, pixels: np.ndarray, height: float = 0.0) -> np.ndarray:
        """Intersect the rays of pixels (..., 2) with the plane z = height -> (..., 3).

        Rays parallel to the plane or pointing away from it give NaN.
        """
        rays = self.pixel_rays(pixels)
        c = self.center
        with np.errstate(divide='ignore', invalid='ignore'):
            s = (height - c[2]) / rays[..., 2]
        s = np.where(s > 0, s, np.nan)
        return c + rays * s[..., None]

    def viewing_angle(self, xy: np.ndarray) -> np.ndarray:
        """Azimuth (..., ) of the direction from floor points (..., 2) towards the camera.

        A person at ``xy`` with body orientation ``o`` (radians, world frame) is seen by this
        camera under the relative angle ``o - viewing_angle(xy)`` (0 = facing the camera).
        """
        xy = np.asarray(xy, dtype=np.float64)
        c = self._center
        return np.arctan2(c[1] - xy[..., 1], c[0] - xy[..., 0])

    def in_image(self, pixels: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Boolean mask (...,) of pixels (..., 2) inside the image (NaN -> False)."""
        pixels = np.asarray(pixels, dtype=np.float64)
        x, y = pixels[..., 0], pixels[..., 1]
        with np.errstate(invalid='ignore'):
            return ((x >= -0.5 - margin) & (x < self.width - 0.5 + margin)
                    & (y >= -0.5 - margin) & (y < self.height - 0.5 + margin))

    def scaled_by(self, factor: float) -> Camera:
        """This camera with its image resized by ``factor`` (each size rounded to whole
        pixels, at least 1)."""
        return self.scaled(max(1, round(self.width * factor)),
                           max(1, round(self.height * factor)))

    def at_most(self, pixels: int) -> Camera:
        """This camera at the size the tracker works on: when it has more than ``pixels``
        pixels, resized to about ``pixels`` pixels with square pixels (equal focal lengths
        ``fx = fy``), else itself.

        Columns are scaled by ``sx = sqrt(pixels fy / (w h fx))`` and rows by
        ``sy = sqrt(pixels fx / (w h fy))`` (``sx sy w h = pixels`` and ``sx fx = sy fy``;
        a side already coarser than that keeps its size, the other is squared to it), sizes
        rounded. A working pixel spans the same angle across and down whatever the sensor's
        pixel aspect, as the tracker's pixel lengths and areas (kernels, dilations, edge
        lengths, given at 320 x 240) assume. A camera with square pixels is resized by
        ``sqrt(pixels / (w h))`` on both sides."""
        w, h = self.width, self.height
        if w * h <= pixels:
            return self
        aspect = float(self.K[0, 0] / self.K[1, 1])        # fx / fy: pixel aspect
        sx = float(np.sqrt(pixels / (w * h * aspect)))
        sy = float(np.sqrt(pixels * aspect / (w * h)))
        if sx > 1.0:
            sx, sy = 1.0, aspect
        elif sy > 1.0:
            sx, sy = 1.0 / aspect, 1.0
        return self.scaled(max(1, round(w * sx)), max(1, round(h * sy)))

    def scaled(self, width: int, height: int) -> Camera:
        """The same camera with its image resized to ``width`` x ``height`` pixels."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0, 0] *= sx
        K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
        K[1, 1] *= sy
        K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
        return replace(self, width=int(width), height=int(height), K=K)

    def fit(self, image: np.ndarray) -> np.ndarray:
        """``image`` (H, W[, C]) resized to this camera's size (area averaging, the right
        filter for shrinking), or the same array when it already has that size.

        When the input's sides are integer multiples of this size (``kx`` x ``ky`` blocks,
        640x480 or 1280x720 to 320x240) the result is the exact area average, each pixel
        the rounded mean of its block: halved by OpenCV's 2x2 INTER_AREA path while both
        factors are 2 (vectorised), else one pass of :func:`block_shrink` (no GIL).
        Otherwise a pyramid: while half the image (both sides even) is still at least this
        size, it is halved by exact 2x2 block means; the rest is one area shrink of a uint8
        image by :func:`area_shrink` (OpenCV's fractional INTER_AREA up to rounding, one
        grey level, in two thirds of its time and without the GIL); the result is the
        direct area resize up to the rounding of the intermediate images and the block
        borders. An image smaller than this size on a side is enlarged by OpenCV's
        INTER_AREA."""
        size = (self.height, self.width)
        if image.shape[:2] == size:
            return image
        h, w = image.shape[:2]
        if h % self.height == 0 and w % self.width == 0 and image.dtype == np.uint8 \
                and (h // self.height, w // self.width) != (2, 2):
            return block_shrink(image, w // self.width, h // self.height)
        while h % 2 == 0 and w % 2 == 0 and h // 2 >= self.height and w // 2 >= self.width \
                and (h, w) != size:
            h, w = h // 2, w // 2
            image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
        if image.shape[:2] == size:
            return image
        if h >= self.height and w >= self.width and image.dtype == np.uint8:
            return area_shrink(image, self.width, self.height)
        return cv2.resize(image, (self.width, self.height), interpolation=cv2.INTER_AREA)

    @property
    def projection_matrix(self) -> np.ndarray:
        """CameraInfo ``P`` (3, 4) of the (unrectified) camera: ``[K | 0]``."""
        return np.hstack([self.K, np.zeros((3, 1))])

    # -- serialisation --------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The camera as a calibration-file entry (CameraInfo-style keys + extrinsics;
        ``time_offset`` only when not 0)."""
        entry = {
            'camera_name': self.name,
            'frame_id': self.frame_id,
            'image_width': self.width,
            'image_height': self.height,
            'camera_matrix': {'rows': 3, 'cols': 3, 'data': self.K.ravel().tolist()},
            'distortion_model': 'plumb_bob',
            'distortion_coefficients': {'rows': 1, 'cols': 5, 'data': self.dist.tolist()},
            'rectification_matrix': {'rows': 3, 'cols': 3, 'data': np.eye(3).ravel().tolist()},
            'projection_matrix': {
                'rows': 3, 'cols': 4, 'data': self.projection_matrix.ravel().tolist()},
            'extrinsics': {
                'rotation': self.R.ravel().tolist(),
                'translation': self.t.tolist(),
            },
        }
        if self.time_offset:
            entry['time_offset'] = self.time_offset
        return entry

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any]) -> Camera:
        """Build a camera from a calibration-file entry; raises :class:`CalibrationError`."""
        if not isinstance(entry, Mapping):
            raise CalibrationError(f'camera entry is not a mapping: {entry!r:.40}')
        name = str(entry.get('camera_name', '?'))
        what = f'camera {name}'

        def get(mapping: Mapping[str, Any], key: str) -> Any:
            if key not in mapping:
                raise CalibrationError(f'{what}: misses key {key!r}')
            return mapping[key]

        def data(key: str) -> Any:
            value = get(entry, key)
            return get(value, 'data') if isinstance(value, Mapping) else value

        if 'camera_name' not in entry:
            raise CalibrationError("camera entry misses key 'camera_name'")
        model = entry.get('distortion_model', 'plumb_bob')
        if model not in ('plumb_bob', 'rational_polynomial') and model:
            raise CalibrationError(f'{what}: distortion_model: unsupported model {model!r:.40}')
        dist = data('distortion_coefficients')
        if isinstance(dist, (str, bytes)) or not isinstance(dist, (list, tuple)):
            raise CalibrationError(f'{what}: distortion_coefficients: expected a list of '
                                   f'numbers, got {dist!r:.40}')
        dist = _as_matrix(dist, (len(dist),), f'{what}: distortion_coefficients')
        if np.any(dist[5:] != 0):
            raise CalibrationError(f'{what}: distortion_coefficients: only plumb_bob '
                                   '[k1, k2, p1, p2, k3] is supported')
        ext = get(entry, 'extrinsics')
        if not isinstance(ext, Mapping):
            raise CalibrationError(f'{what}: extrinsics: expected a mapping with rotation '
                                   'and translation')
        return cls(name=name, width=get(entry, 'image_width'),
                   height=get(entry, 'image_height'), K=data('camera_matrix'), dist=dist[:5],
                   R=get(ext, 'rotation'), t=get(ext, 'translation'),
                   frame_id=str(entry.get('frame_id', '') or ''),
                   time_offset=entry.get('time_offset', 0.0))


def look_at(eye: Iterable[float], target: Iterable[float],
            up: Iterable[float] = (0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """World->camera ``(R, t)`` for an optical frame at ``eye`` looking at ``target``."""
    eye = np.asarray(eye, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - eye
    forward /= np.linalg.norm(forward)
    up = np.asarray(up, dtype=np.float64)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:  # looking straight down: pick any right vector
        right = np.cross(forward, np.array([0.0, 1.0, 0.0]))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    return R, -R @ eye


def _in_rect(xy: np.ndarray, rect: tuple[float, float, float, float]) -> np.ndarray:
    """(K,) True for floor points (K, 2) inside the closed rectangle
    ``(x_min, y_min, x_max, y_max)``."""
    x0, y0, x1, y1 = rect
    return (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)


def distance_to_rect(xy: np.ndarray, rect: tuple[float, float, float, float]
                     ) -> np.ndarray:
    """(K,) distance (metres) of floor points (K, 2) from a closed rectangle
    ``(x_min, y_min, x_max, y_max)``; 0 inside it."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    x0, y0, x1, y1 = rect
    dx = np.maximum.reduce([x0 - xy[:, 0], xy[:, 0] - x1, np.zeros(len(xy))])
    dy = np.maximum.reduce([y0 - xy[:, 1], xy[:, 1] - y1, np.zeros(len(xy))])
    return np.hypot(dx, dy)


def _exit_side(floor: tuple[float, float, float, float],
               rect: tuple[float, float, float, float]) -> tuple[int, int]:
    """Which side of the floor an exit lies beyond: ``(axis, sign)``, axis 0 for x and 1
    for y, sign +1 beyond the maximum and -1 beyond the minimum."""
    fx0, fy0, fx1, fy1 = floor
    ex0, ey0, ex1, ey1 = rect
    if ey0 >= fy1:
        return 1, 1
    if ey1 <= fy0:
        return 1, -1
    return (0, 1) if ex0 >= fx1 else (0, -1)


def _check_exit(rect: Any, floor: tuple[float, float, float, float]
                ) -> tuple[float, float, float, float]:
    """An exit rectangle as 4 floats; it must be non-empty, outside the floor and share a
    piece of the floor's border (else no track could walk into it)."""
    try:
        x0, y0, x1, y1 = (float(v) for v in rect)
    except (TypeError, ValueError) as err:
        raise CalibrationError(
            f'exit must be [x_min, y_min, x_max, y_max], got {rect!r}') from err
    if not (np.isfinite([x0, y0, x1, y1]).all() and x1 > x0 and y1 > y0):
        raise CalibrationError(f'exit bounds are empty: {rect!r}')
    fx0, fy0, fx1, fy1 = floor
    overlap_x = min(x1, fx1) - max(x0, fx0)
    overlap_y = min(y1, fy1) - max(y0, fy0)
    if overlap_x > 0 and overlap_y > 0:
        raise CalibrationError(f'exit {[x0, y0, x1, y1]} overlaps the floor {list(floor)}')
    if not ((overlap_x > 0 and overlap_y == 0) or (overlap_y > 0 and overlap_x == 0)):
        raise CalibrationError(f'exit {[x0, y0, x1, y1]} does not share a border with the '
                               f'floor {list(floor)}')
    return (x0, y0, x1, y1)


@dataclass(frozen=True, eq=False)
class RoomCalibration:
    """All cameras of a room plus the floor area people can walk on.

    Attributes:
        cameras: cameras by name, in file order.
        floor: ``(x_min, y_min, x_max, y_max)`` of the walkable floor, metres.
        frame_id: the world frame id (default ``room``).
        entry_zones: optional floor rectangles ``(x_min, y_min, x_max, y_max)`` where people
            enter (detection may be restricted to them).
        exits: optional rectangles ``(x_min, y_min, x_max, y_max)`` outside the floor, each
            sharing a piece of the floor's border (beyond a door), through which people
            leave: the motion model lets tracks follow a person into them and a track whose
            estimate is deep enough inside one is released at once (``ReleaseConfig
            .exit_margin``). None: tracks stay on the floor.
    """

    cameras: dict[str, Camera]
    floor: tuple[float, float, float, float]
    frame_id: str = 'room'
    entry_zones: tuple[tuple[float, float, float, float], ...] = field(default_factory=tuple)
    exits: tuple[tuple[float, float, float, float], ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if not self.cameras:
            raise CalibrationError('a room needs at least one camera')
        try:
            x0, y0, x1, y1 = _rectangle(self.floor, 'floor')
        except CalibrationError as err:
            raise CalibrationError(f'floor bounds are empty or not numbers: {err}') from err
        if max(x1 - x0, y1 - y0) > MAX_FLOOR_SIDE:
            raise CalibrationError(f'floor: {x1 - x0:.6g} x {y1 - y0:.6g} m exceeds the '
                                   f'largest floor side {MAX_FLOOR_SIDE:g} m')
        object.__setattr__(self, 'floor', (x0, y0, x1, y1))
        object.__setattr__(self, 'entry_zones', tuple(
            _rectangle(z, f'entry_zones[{i}]') for i, z in enumerate(self.entry_zones)))
        object.__setattr__(self, 'exits', tuple(_check_exit(e, self.floor) for e in self.exits))

    def exit_depth(self, xy: np.ndarray) -> np.ndarray:
        """(K,) distance (metres) from the floor rectangle of floor points (K, 2) that lie
        inside an exit; NaN for points in no exit."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        depth = np.full(len(xy), np.nan)
        if not self.exits:
            return depth
        inside = np.zeros(len(xy), bool)
        for rect in self.exits:
            inside |= _in_rect(xy, rect)
        depth[inside] = distance_to_rect(xy[inside], self.floor)
        return depth

    def _on_door_wall(self, camera: str, exit_rect: tuple[float, float, float, float]
                      ) -> bool:
        """True when ``camera``'s centre is on the exit's side of the floor border they
        share: it hangs on the wall with the door and looks at the exit from behind it."""
        axis, sign = _exit_side(self.floor, exit_rect)
        border = self.floor[axis + 2] if sign > 0 else self.floor[axis]
        return bool(sign * (self.cameras[camera].center[axis] - border) >= 0.0)

    def exit_hidden(self, camera: str, xy: np.ndarray) -> np.ndarray:
        """(K,) True for floor points (K, 2) inside an exit that ``camera`` cannot see: the
        camera hangs on the wall with the door (``_on_door_wall``) and the point is level
        with the camera or beyond it, across the border the exit shares with the floor.
        The camera's position stands for the wall: the strip of the exit between the
        floor's edge and the wall is still in the room, in front of the camera."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        hidden = np.zeros(len(xy), bool)
        centre = self.cameras[camera].center[:2]
        for rect in self.exits:
            if self._on_door_wall(camera, rect):
                axis, sign = _exit_side(self.floor, rect)
                beyond = sign * (xy[:, axis] - centre[axis]) >= 0.0
                hidden |= _in_rect(xy, rect) & beyond
        return hidden

    def doorway_witnesses(self, xy: np.ndarray, band: float) -> dict[str, np.ndarray]:
        """Per camera, (K,) True for the floor points (K, 2) in front of a door - inside an
        exit, or on the floor less than ``band`` metres from the border piece the exit
        shares with it - that the camera watches from the door's wall
        (``_on_door_wall``). These cameras see the doorway but not the corridor behind
        it; any other camera's view of the doorway also shows the exit, where a person
        who just left may still walk. Cameras with no such point are left out."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        out: dict[str, np.ndarray] = {}
        for rect in self.exits:
            # the exit grown by the band across the border it shares with the floor
            axis, sign = _exit_side(self.floor, rect)
            front = list(rect)
            if sign > 0:
                front[axis] = self.floor[axis + 2] - band
            else:
                front[axis + 2] = self.floor[axis] + band
            inside = _in_rect(xy, tuple(front))
            if not inside.any():
                continue
            for name in self.cameras:
                if self._on_door_wall(name, rect):
                    out[name] = out.get(name, np.zeros(len(xy), bool)) | inside
        return out

    def in_entry_zone(self, xy: np.ndarray) -> np.ndarray:
        """(K,) True for floor points (K, 2) inside any of the ``entry_zones``."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        inside = np.zeros(len(xy), bool)
        for rect in self.entry_zones:
            inside |= _in_rect(xy, rect)
        return inside

    @property
    def names(self) -> list[str]:
        return list(self.cameras)

    def subset(self, names: Iterable[str]) -> RoomCalibration:
        """The same room with only the named cameras, in the given order."""
        names = list(names)
        missing = [n for n in names if n not in self.cameras]
        if missing:
            raise CalibrationError(
                f'unknown camera(s) {", ".join(missing)}; known: {", ".join(self.cameras)}')
        return replace(self, cameras={n: self.cameras[n] for n in names})

    def scaled(self, width: int, height: int) -> RoomCalibration:
        """All cameras resized to the same image size."""
        return replace(self, cameras={n: c.scaled(width, height)
                                      for n, c in self.cameras.items()})

    def scaled_by(self, factor: float) -> RoomCalibration:
        """Every camera with its image resized by ``factor`` (each size rounded to whole
        pixels); the room itself is unchanged."""
        return replace(self, cameras={n: c.scaled_by(factor) for n, c in self.cameras.items()})

    def to_dict(self) -> dict[str, Any]:
        x0, y0, x1, y1 = self.floor
        return {
            'format': 'mbtrack_ros/room_calibration',
            'version': 1,
            'frame_id': self.frame_id,
            'floor': {'x_min': x0, 'y_min': y0, 'x_max': x1, 'y_max': y1},
            'entry_zones': [list(z) for z in self.entry_zones],
            **({'exits': [list(e) for e in self.exits]} if self.exits else {}),
            'cameras': [c.to_dict() for c in self.cameras.values()],
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> RoomCalibration:
        if not isinstance(doc, Mapping) or 'cameras' not in doc:
            raise CalibrationError('not a room calibration (no "cameras" list)')
        if not doc['cameras']:
            raise CalibrationError('a room needs at least one camera')
        if not isinstance(doc['cameras'], list):
            raise CalibrationError('cameras: expected a list of camera entries')
        cams = [Camera.from_dict(entry) for entry in doc['cameras']]
        f = doc.get('floor')
        if not isinstance(f, Mapping):
            raise CalibrationError('floor: expected a mapping x_min, y_min, x_max, y_max')
        missing = [k for k in ('x_min', 'y_min', 'x_max', 'y_max') if k not in f]
        if missing:
            raise CalibrationError(f'floor: misses key {missing[0]!r}')
        floor = tuple(_number(f[k], f'floor: {k}') for k in ('x_min', 'y_min', 'x_max',
                                                             'y_max'))
        names = [c.name for c in cams]
        if len(set(names)) != len(names):
            raise CalibrationError(f'duplicate camera names in {names}')
        zones = doc.get('entry_zones', []) or []
        if not isinstance(zones, list):
            raise CalibrationError(f'entry_zones: expected a list of [x_min, y_min, x_max, '
                                   f'y_max], got {zones!r:.40}')
        zones = tuple(_rectangle(z, f'entry_zones[{i}]') for i, z in enumerate(zones))
        exits = doc.get('exits', []) or []
        if not isinstance(exits, list):
            raise CalibrationError(f'exits must be a list of [x_min, y_min, x_max, y_max], '
                                   f'got {exits!r}')
        return cls(cameras={c.name: c for c in cams}, floor=floor,
                   frame_id=str(doc.get('frame_id', 'room')), entry_zones=zones,
                   exits=tuple(exits))

    def save(self, path: str | Path) -> None:
        """Write the calibration as YAML."""
        Path(path).write_text(
            '# mbtrack_ros room calibration: metres, floor z = 0, z up;\n'
            '# extrinsics map world to camera: x_cam = R X + t (R row-major).\n'
            + yaml.safe_dump(self.to_dict(), sort_keys=False), encoding='utf-8')

    @classmethod
    def load(cls, path: str | Path) -> RoomCalibration:
        """Read a calibration YAML; raises :class:`CalibrationError` with a one-line reason."""
        path = Path(path)
        try:
            doc = yaml.safe_load(path.read_text(encoding='utf-8'))
        except OSError as err:
            raise CalibrationError(f'cannot read calibration {path}: {err.strerror}') from err
        except UnicodeDecodeError as err:
            raise CalibrationError(f'{path}: not a text file (not UTF-8 at byte '
                                   f'{err.start})') from err
        except yaml.YAMLError as err:
            raise CalibrationError(f'{path} is not valid YAML: {yaml_error_line(err)}') \
                from err
        try:
            return cls.from_dict(doc)
        except CalibrationError as err:
            raise CalibrationError(f'{path}: {err}') from err

    def floor_views(self, samples: int = 41) -> dict[str, float]:
        """Share of the floor rectangle each camera sees, in [0, 1] by camera name.

        The floor is sampled on a ``samples`` x ``samples`` grid at z = 0; a sample is seen
        when it lies in front of the camera and projects inside its image.
        """
        x0, y0, x1, y1 = self.floor
        gx, gy = np.meshgrid(np.linspace(x0, x1, samples), np.linspace(y0, y1, samples))
        points = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
        return {name: float(np.mean(cam.in_image(cam.project(points))))
                for name, cam in self.cameras.items()}


def yaml_error_line(err: Exception) -> str:
    """One line for a YAML parser error: the problem and where (line, column)."""
    problem = getattr(err, 'problem', None) or str(err).strip().splitlines()[0]
    mark = getattr(err, 'problem_mark', None)
    where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark is not None else ''
    return f'{problem}{where}'


def check_floor_views(calibration: RoomCalibration, source: str = '') -> list[str]:
    """The floor-view check of a calibration: one warning per camera that sees less than
    :data:`MIN_FLOOR_VIEW` of the floor (:meth:`RoomCalibration.floor_views`); raises
    :class:`CalibrationError` when no camera sees any of it (nothing could be tracked).
    ``source`` (the file) prefixes every message."""
    prefix = f'{source}: ' if source else ''
    views = calibration.floor_views()
    if not any(share > 0.0 for share in views.values()):
        raise CalibrationError(f'{prefix}no camera sees the floor {list(calibration.floor)} '
                               '(check the extrinsics: R maps world to camera, z up)')
    return [f'{prefix}camera {name}: sees {100 * share:.1f} % of the floor (less than '
            f'{100 * MIN_FLOOR_VIEW:.0f} %); check its extrinsics'
            for name, share in views.items() if share < MIN_FLOOR_VIEW]
