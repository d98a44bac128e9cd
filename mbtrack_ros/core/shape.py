"""3D body shape model of 003 §2.1 (Fig. 1) and its rasterisation into row spans.

A person is a stack of horizontally elongated cone trunks (legs, torso, head) around the
vertical body axis. The model is calibrated by the target height ``h`` and width ``w``
(metres); the outline is a piece-wise linear profile given by a table of
``(height fraction, half-width fraction, part)`` points:

=====================  ===============  =====================  =======
profile point          height / h       half-width / w         part
=====================  ===============  =====================  =======
feet                   0.00             0.28                   legs
knees                  0.28             0.32                   legs
hips                   0.47             0.40                   torso
waist                  0.62             0.36                   torso
shoulders              0.82             0.50                   torso
neck                   0.865            0.16                   head
cheeks                 0.93             0.22                   head
head top               1.00             0.13
=====================  ===============  =====================  =======

The part of a profile point is the part of the segment from it to the next point (legs
from the feet to the hips, torso from the hips to the neck, head from the neck up). A
0.5 m wide person is therefore 0.5 m across the shoulders and 0.4 m across the hips.

Projection (003 §2.1): the foot and head-top points are projected with
:meth:`Camera.project`; the axis points at the profile heights are placed on the image
segment joining them by perspective-correct interpolation (exact for a pinhole camera); the
outline is drawn around the axis, perpendicular to the foot -> head image direction, with
offsets in pixels = half-width (m) * focal / depth of the axis point (the focal length
along the offset's image direction: fx beside an upright axis when the pixels are not square), times
``s(o) = 0.7 + 0.3 |cos o|`` with o the body orientation relative to the camera. Each
segment of the profile is then a convex quadrilateral in the image; a pixel belongs to it
when its centre is inside (half-open edge rules, so neighbouring parts never share a
pixel), which matches the analytic polygon area to about 1 %.

Sitting pose (003 §2.1): the hip centre is put at chair height and the leg trunks are
dropped; the torso and head keep their standing sizes, so the head top is at
``chair_height + (1 - hip fraction) h``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mbtrack_ros.core import _kernels
from mbtrack_ros.core.camera import Camera
from mbtrack_ros.core.state import STATE_DIM, THETA

__all__ = ['HEAD', 'LEGS', 'PART_NAMES', 'TORSO', 'BodyShape', 'ShapeError', 'Silhouettes',
           'rasterize', 'render_labels', 'silhouette_outline', 'width_scale']

HEAD, TORSO, LEGS = 1, 2, 3
PART_NAMES = ('head', 'torso', 'legs')

# (height fraction, half-width fraction of the width, part of the segment above)
_STANDING_PROFILE = (
    (0.00, 0.28, LEGS),
    (0.28, 0.32, LEGS),
    (0.47, 0.40, TORSO),
    (0.62, 0.36, TORSO),
    (0.82, 0.50, TORSO),
    (0.865, 0.16, HEAD),
    (0.93, 0.22, HEAD),
    (1.00, 0.13, 0),
)


class ShapeError(ValueError):
    """Bad input to the shape model (non-positive size, wrong state array)."""


@dataclass(frozen=True)
class BodyShape:
    """Part-based 3D shape of one person (003 §2.1).

    Attributes:
        height: body height h, metres.
        width: body width w (shoulder width), metres.
        chair_height: height of the hip centre when sitting, metres.
        profile: ``(height fraction, half-width fraction, part)`` points, increasing height;
            the part labels the segment from a point to the next one.
        hip_fraction: height fraction of the hip (the lowest point kept when sitting).
    """

    height: float = 1.75
    width: float = 0.5
    chair_height: float = 0.45
    profile: tuple[tuple[float, float, int], ...] = _STANDING_PROFILE
    hip_fraction: float = 0.47

    def __post_init__(self) -> None:
        if not (np.isfinite(self.height) and self.height > 0):
            raise ShapeError(f'body height must be positive, got {self.height}')
        if not (np.isfinite(self.width) and self.width > 0):
            raise ShapeError(f'body width must be positive, got {self.width}')
        fr = [p[0] for p in self.profile]
        if len(fr) < 2 or any(b <= a for a, b in zip(fr, fr[1:])):
            raise ShapeError('profile heights must be strictly increasing (>= 2 points)')
        if not any(abs(f - self.hip_fraction) < 1e-12 for f in fr):
            raise ShapeError(f'hip fraction {self.hip_fraction} is not a profile point')

    @property
    def fractions(self) -> np.ndarray:
        """(P,) profile height fractions."""
        return np.array([p[0] for p in self.profile])

    @property
    def half_widths(self) -> np.ndarray:
        """(P,) profile half-width fractions."""
        return np.array([p[1] for p in self.profile])

    @property
    def segment_parts(self) -> np.ndarray:
        """(P - 1,) int8 part of each profile segment."""
        return np.array([p[2] for p in self.profile[:-1]], dtype=np.int8)


@dataclass
class Silhouettes:
    """Row spans of N rasterised particles in one camera, concatenated.

    Attributes:
        row, x0, x1: (M,) int32 span row and column range ``[x0, x1)``, clipped to the image.
        part: (M,) int8 body part of each span (1 head, 2 torso, 3 legs).
        offsets: (N + 1,) int64, spans of particle i are ``offsets[i]:offsets[i + 1]``.
        area: (N,) int64 pixel area inside the image.
        part_area: (N, 3) int64 pixel area per part (head, torso, legs).
        full_area: (N,) int64 pixel area of the unclipped silhouette (same row sampling).
        bbox: (N, 4) int32 ``x0, y0, x1, y1`` (exclusive) of the spans; zeros if empty.
        distance: (N,) camera distance of the body centre (half height), metres; +inf for
            particles behind the camera.
        width, height: image size in pixels; row_step: row sampling used.
    """

    row: np.ndarray
    x0: np.ndarray
    x1: np.ndarray
    part: np.ndarray
    offsets: np.ndarray
    area: np.ndarray
    part_area: np.ndarray
    full_area: np.ndarray
    bbox: np.ndarray
    distance: np.ndarray
    width: int
    height: int
    row_step: int = 1

    def __len__(self) -> int:
        return int(self.offsets.shape[0] - 1)

    def select(self, start: int, stop: int) -> Silhouettes:
        """The silhouettes of particles ``start:stop`` (views of the arrays, offsets from 0):
        one rasterisation of several particle sets, then one object per set."""
        a, b = int(self.offsets[start]), int(self.offsets[stop])
        return Silhouettes(
            row=self.row[a:b], x0=self.x0[a:b], x1=self.x1[a:b], part=self.part[a:b],
            offsets=self.offsets[start:stop + 1] - a, area=self.area[start:stop],
            part_area=self.part_area[start:stop], full_area=self.full_area[start:stop],
            bbox=self.bbox[start:stop], distance=self.distance[start:stop],
            width=self.width, height=self.height, row_step=self.row_step)

    def spans(self, i: int) -> slice:
        """Slice of the spans of particle i."""
        return slice(int(self.offsets[i]), int(self.offsets[i + 1]))

    def mask(self, i: int) -> np.ndarray:
        """(H, W) int8 part labels of particle i (0 background)."""
        out = np.zeros((self.height, self.width), np.int8)
        _kernels.paint_spans(out, self.row, self.x0, self.x1, self.part,
                             int(self.offsets[i]), int(self.offsets[i + 1]), 0, True)
        return out


def width_scale(rel_angle: np.ndarray) -> np.ndarray:
    """003 §2.1: profile width factor s(o) = 0.7 + 0.3 |cos o| (o relative orientation);
    the kernels' :func:`~mbtrack_ros.core._kernels.width_scale`, for any array shape."""
    rel = np.asarray(rel_angle, dtype=np.float64)
    return _kernels.width_scale(np.ascontiguousarray(rel.reshape(-1))).reshape(rel.shape)


def _check_states(states: np.ndarray) -> np.ndarray:
    states = np.asarray(states, dtype=np.float64)
    if states.ndim == 1:
        states = states[None]
    if states.ndim != 2 or states.shape[1] != STATE_DIM:
        raise ShapeError(f'states must be (N, {STATE_DIM}), got shape {states.shape}')
    return states


def _per_particle(value: float | np.ndarray | None, default: float, n: int,
                  what: str) -> np.ndarray:
    value = default if value is None else value
    if np.ndim(value) == 0:                   # one size for all (the common case): no scan
        v = float(value)
        if not (math.isfinite(v) and v > 0):
            raise ShapeError(f'{what} must be positive and finite')
        return np.full(n, v)
    arr = np.asarray(value, np.float64)
    # a writable contiguous copy; an (n,) array skips broadcast_to (~30 us of its ~40 us
    # per call, and every rasterisation of per-particle sizes makes two such calls)
    arr = np.array(arr if arr.shape == (n,) else np.broadcast_to(arr, (n,)))
    if not ((arr > 0).all() and np.isfinite(arr).all()):
        raise ShapeError(f'{what} must be positive and finite')
    return arr


def silhouette_outline(camera: Camera, states: np.ndarray, shape: BodyShape, *,
                       heights: np.ndarray | None = None,
                       widths: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Image outline of N particles (003 §2.1).

    Args:
        camera: the camera.
        states: (N, 6) particle states.
        shape: body model (profile table, chair height, default height/width).
        heights, widths: optional (N,) per-particle height/width in metres overriding
            ``shape.height``/``shape.width`` (one call for several targets).

    Returns:
        left, right: (N, P, 2) image points of the outline at the profile heights.
        seg_part: (N, P - 1) int8 segment parts (sitting: legs segments set to 0).
        valid: (N,) bool, all axis points in front of the camera.
        distance: (N,) camera distance of the body centre, metres (+inf if not valid).
    """
    states = _check_states(states)
    n = states.shape[0]
    h = _per_particle(heights, shape.height, n, 'heights')
    w = _per_particle(widths, shape.width, n, 'widths')
    # axis end points: feet (z = 0) and head top (z = h) standing; sitting, the hip at chair
    # height and the head top at chair height + upper body height; legs dropped
    ends, end_depth, sitting = _kernels.axis_ends(
        states, h, float(shape.chair_height), float(shape.hip_fraction), *camera.depth_row)
    # 003 §2.1: project the bottom and top points; the axis points in between lie on the
    # image segment joining them (perspective-correct placement in the kernel, which also
    # drops the leg segments and rescales the profile heights of sitting particles); one
    # numba pass projects the ends (Camera.project), takes s(o) of the orientation relative
    # to the camera (width_scale) and the camera distance of the body centre
    return _kernels.body_outline(
        ends, end_depth, np.ascontiguousarray(states[:, THETA]), sitting, shape.fractions,
        shape.half_widths, shape.segment_parts, float(shape.hip_fraction), w,
        *camera.projection_parameters)


def rasterize(camera: Camera, states: np.ndarray, shape: BodyShape | Sequence[BodyShape], *,
              heights: np.ndarray | None = None, widths: np.ndarray | None = None,
              row_step: int = 1) -> Silhouettes:
    """Rasterise the silhouettes of N particles into clipped row spans (numba).

    Args:
        camera: the camera.
        states: (N, 6) particle states (metres, radians).
        shape: one body model for all particles, or a sequence of N models (same profile
            table; their heights and widths are used).
        heights, widths: optional (N,) metres, per-particle overrides of the model size.
        row_step: keep every ``row_step``-th image row (speed option; areas count kept rows).

    Returns:
        :class:`Silhouettes`; particles behind the camera or outside the image have no spans.
    """
    states = _check_states(states)
    if not isinstance(shape, BodyShape):
        shapes = list(shape)
        if len(shapes) != states.shape[0]:
            raise ShapeError(f'{len(shapes)} shapes for {states.shape[0]} particles')
        if not shapes:
            shape = BodyShape()
        else:
            if any(s.profile != shapes[0].profile for s in shapes):
                raise ShapeError('all shapes of one rasterisation must share the profile')
            heights = np.array([s.height for s in shapes]) if heights is None else heights
            widths = np.array([s.width for s in shapes]) if widths is None else widths
            shape = shapes[0]
    if int(row_step) < 1:
        raise ShapeError(f'row_step must be >= 1, got {row_step}')
    n = states.shape[0]
    h = _per_particle(heights, shape.height, n, 'heights')
    w = _per_particle(widths, shape.width, n, 'widths')
    (row, x0, x1, part, offsets, area, part_area, full_area, bbox,
     distance) = _kernels.silhouettes(
        states, h, w, float(shape.chair_height), shape.fractions, shape.half_widths,
        shape.segment_parts, float(shape.hip_fraction), *camera.depth_row,
        *camera.projection_parameters, camera.width, camera.height,
        int(row_step))
    return Silhouettes(row=row, x0=x0, x1=x1, part=part, offsets=offsets, area=area,
                       part_area=part_area, full_area=full_area, bbox=bbox,
                       distance=distance, width=camera.width, height=camera.height,
                       row_step=int(row_step))


def render_labels(camera: Camera, state: np.ndarray, shape: BodyShape) -> np.ndarray:
    """(H, W) int8 part labels of one state: 0 background, 1 head, 2 torso, 3 legs."""
    sil = rasterize(camera, np.asarray(state, dtype=np.float64).reshape(1, -1), shape)
    return sil.mask(0)
