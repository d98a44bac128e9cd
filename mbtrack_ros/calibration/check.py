"""Pictures to check a room calibration by eye: per camera its image with the floor grid,
the floor rectangle, entry zones, exits and the other cameras drawn over it, and a top view
of the room with every camera's field of view on the floor.

Colours (BGR): floor grid grey-white every ``GRID_M``, floor rectangle yellow, entry zones
green, exits red, room x axis red and y axis green (1 m from the origin), cameras in one
colour each.
"""
from __future__ import annotations

import cv2
import numpy as np

from mbtrack_ros.core.camera import Camera, RoomCalibration

__all__ = ['GRID_M', 'camera_overlay', 'top_view']

GRID_M = 0.5
_FLOOR = (0, 215, 255)
_ENTRY = (60, 200, 60)
_EXIT = (50, 50, 230)
_PALETTE = ((255, 160, 40), (40, 160, 255), (200, 80, 220), (80, 220, 220), (160, 255, 80),
            (255, 80, 140), (140, 140, 255), (0, 200, 140))


def camera_colour(index: int) -> tuple[int, int, int]:
    return _PALETTE[index % len(_PALETTE)]


def _segment(a: np.ndarray, b: np.ndarray, step: float = 0.05) -> np.ndarray:
    """(K, 3) points every ``step`` metres from a to b (lines bend under lens distortion)."""
    n = max(2, int(np.ceil(np.linalg.norm(b - a) / step)) + 1)
    return a + (b - a) * np.linspace(0.0, 1.0, n)[:, None]


def _polyline(image: np.ndarray, cam: Camera, pts: np.ndarray, colour, thickness: int,
              scale: int) -> None:
    """Draw world points (K, 3) as a polyline, broken where they are behind the camera or far
    outside the image (anti-aliased, ``scale`` = fixed-point sub-pixel factor)."""
    pix = cam.project(pts)
    ok = np.isfinite(pix).all(axis=1) & cam.in_image(pix, margin=0.5 * max(cam.width,
                                                                              cam.height))
    run: list[np.ndarray] = []
    for p, good in zip(pix, ok):
        if good:
            run.append(p)
        elif run:
            _draw_run(image, run, colour, thickness, scale)
            run = []
    if run:
        _draw_run(image, run, colour, thickness, scale)


def _draw_run(image, run, colour, thickness, scale):
    if len(run) < 2:
        return
    pts = np.round((np.array(run) + 0.5) * scale - 0.5).astype(np.int32)
    cv2.polylines(image, [pts.reshape(-1, 1, 2)], False, colour, thickness, cv2.LINE_AA,
                  shift=int(np.log2(scale)))


def _rect_outline(rect) -> list[np.ndarray]:
    x0, y0, x1, y1 = rect
    c = [np.array(p, float) for p in ((x0, y0, 0), (x1, y0, 0), (x1, y1, 0), (x0, y1, 0))]
    return [_segment(c[k], c[(k + 1) % 4]) for k in range(4)]


def camera_overlay(calibration: RoomCalibration, name: str, image: np.ndarray | None
                   ) -> np.ndarray:
    """(H, W, 3) uint8 BGR: camera ``name``'s image (grey when None; resized to the
    calibration's size) with the room drawn over it."""
    cam = calibration.cameras[name]
    if image is None:
        out = np.full((cam.height, cam.width, 3), 60, np.uint8)
    else:
        out = cam.fit(image).copy()
    scale = 8
    thin = max(1, round(max(cam.width, cam.height) / 640))
    x0, y0, x1, y1 = calibration.floor
    for x in np.arange(np.ceil(x0 / GRID_M) * GRID_M, x1 + 1e-9, GRID_M):
        _polyline(out, cam, _segment(np.array([x, y0, 0]), np.array([x, y1, 0])),
                  (230, 230, 230), thin, scale)
    for y in np.arange(np.ceil(y0 / GRID_M) * GRID_M, y1 + 1e-9, GRID_M):
        _polyline(out, cam, _segment(np.array([x0, y, 0]), np.array([x1, y, 0])),
                  (230, 230, 230), thin, scale)
    for seg in _rect_outline(calibration.floor):
        _polyline(out, cam, seg, _FLOOR, 2 * thin, scale)
    for zone in calibration.entry_zones:
        for seg in _rect_outline(zone):
            _polyline(out, cam, seg, _ENTRY, 2 * thin, scale)
    for ex in calibration.exits:
        for seg in _rect_outline(ex):
            _polyline(out, cam, seg, _EXIT, 2 * thin, scale)
    origin = np.zeros(3)
    _polyline(out, cam, _segment(origin, np.array([1.0, 0, 0])), (0, 0, 255), 2 * thin, scale)
    _polyline(out, cam, _segment(origin, np.array([0, 1.0, 0])), (0, 255, 0), 2 * thin, scale)
    font = 0.4 * thin
    for k, (other, oc) in enumerate(calibration.cameras.items()):
        if other == name:
            continue
        c = oc.center
        _polyline(out, cam, _segment(np.array([c[0], c[1], 0.0]), c), camera_colour(k),
                  thin, scale)
        p = cam.project(c[None])[0]
        if np.isfinite(p).all() and cam.in_image(p[None])[0]:
            q = (int(round(p[0])), int(round(p[1])))
            cv2.circle(out, q, 4 * thin, camera_colour(k), -1, cv2.LINE_AA)
            cv2.putText(out, other, (q[0] + 6 * thin, q[1] - 4 * thin),
                        cv2.FONT_HERSHEY_SIMPLEX, font, camera_colour(k), thin, cv2.LINE_AA)
    cv2.putText(out, f'{name}: grid {GRID_M:g} m', (6 * thin, 16 * thin),
                cv2.FONT_HERSHEY_SIMPLEX, font, (255, 255, 255), thin, cv2.LINE_AA)
    return out


def field_of_view(cam: Camera, *, max_range: float = 15.0, samples: int = 40) -> np.ndarray:
    """(K, 2) floor polygon (metres) seen by ``cam``: the image border's rays meet with the
    floor, cut at ``max_range`` metres from the camera (rays above the horizon end there)."""
    W, H = cam.width, cam.height
    u = np.linspace(-0.5, W - 0.5, samples)
    v = np.linspace(-0.5, H - 0.5, samples)
    border = np.concatenate([np.stack([u, np.full_like(u, -0.5)], 1),
                             np.stack([np.full_like(v, W - 0.5), v], 1),
                             np.stack([u[::-1], np.full_like(u, H - 0.5)], 1),
                             np.stack([np.full_like(v, -0.5), v[::-1]], 1)])
    rays = cam.pixel_rays(border)
    c = cam.center
    with np.errstate(divide='ignore', invalid='ignore'):
        s = -c[2] / rays[:, 2]
    s = np.where((s > 0) & np.isfinite(s), s, np.inf)
    flat = np.linalg.norm(rays[:, :2], axis=1)
    s = np.minimum(s, max_range / np.maximum(flat, 1e-9))
    return (c + rays * s[:, None])[:, :2]


def top_view(calibration: RoomCalibration, *, px_per_m: float = 100.0, margin: float = 1.0
             ) -> np.ndarray:
    """(H, W, 3) uint8 BGR top view: floor, grid, zones, exits, each camera's position,
    optical axis and field of view on the floor (translucent)."""
    pts = [np.array(calibration.floor).reshape(2, 2)]
    pts += [np.array(e).reshape(2, 2) for e in calibration.exits]
    pts += [c.center[None, :2] for c in calibration.cameras.values()]
    lo = np.min(np.concatenate(pts), axis=0) - margin
    hi = np.max(np.concatenate(pts), axis=0) + margin
    W, H = (np.ceil((hi - lo) * px_per_m)).astype(int)

    def px(xy: np.ndarray) -> np.ndarray:  # room y up -> image rows down
        xy = np.asarray(xy, float).reshape(-1, 2)
        return np.stack([(xy[:, 0] - lo[0]) * px_per_m,
                         (hi[1] - xy[:, 1]) * px_per_m], 1).round().astype(np.int32)

    out = np.full((H, W, 3), 250, np.uint8)
    x0, y0, x1, y1 = calibration.floor
    cv2.rectangle(out, tuple(px([x0, y1])[0]), tuple(px([x1, y0])[0]), (225, 225, 225), -1)
    for k, (name, cam) in enumerate(calibration.cameras.items()):
        layer = out.copy()
        poly = field_of_view(cam, max_range=float(np.linalg.norm(hi - lo)))
        cv2.fillPoly(layer, [px(poly).reshape(-1, 1, 2)], camera_colour(k), cv2.LINE_AA)
        out = cv2.addWeighted(layer, 0.18, out, 0.82, 0.0)
        cv2.polylines(out, [px(poly).reshape(-1, 1, 2)], True, camera_colour(k), 1,
                      cv2.LINE_AA)
    for x in np.arange(np.ceil(x0 / GRID_M) * GRID_M, x1 + 1e-9, GRID_M):
        cv2.line(out, tuple(px([x, y0])[0]), tuple(px([x, y1])[0]), (190, 190, 190), 1)
    for y in np.arange(np.ceil(y0 / GRID_M) * GRID_M, y1 + 1e-9, GRID_M):
        cv2.line(out, tuple(px([x0, y])[0]), tuple(px([x1, y])[0]), (190, 190, 190), 1)
    cv2.rectangle(out, tuple(px([x0, y1])[0]), tuple(px([x1, y0])[0]), (0, 160, 200), 2)
    for zone, colour in [(z, _ENTRY) for z in calibration.entry_zones] + \
            [(e, _EXIT) for e in calibration.exits]:
        a, b = px([zone[0], zone[3]])[0], px([zone[2], zone[1]])[0]
        cv2.rectangle(out, tuple(a), tuple(b), colour, 2)
    o = px([0.0, 0.0])[0]
    cv2.arrowedLine(out, tuple(o), tuple(px([1.0, 0.0])[0]), (0, 0, 255), 2, tipLength=0.1)
    cv2.arrowedLine(out, tuple(o), tuple(px([0.0, 1.0])[0]), (0, 160, 0), 2, tipLength=0.1)
    for k, (name, cam) in enumerate(calibration.cameras.items()):
        c = cam.center
        p = px(c[:2])[0]
        axis = cam.R[2]
        tip = px(c[:2] + 0.6 * axis[:2] / max(np.linalg.norm(axis[:2]), 1e-9)
                 * min(1.0, np.linalg.norm(axis[:2]) * 3))[0]
        cv2.arrowedLine(out, tuple(p), tuple(tip), camera_colour(k), 2, cv2.LINE_AA,
                        tipLength=0.25)
        cv2.circle(out, tuple(p), 6, camera_colour(k), -1, cv2.LINE_AA)
        cv2.putText(out, f'{name} {c[2]:.2f} m', (int(p[0]) + 8, int(p[1]) - 8),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, (40, 40, 40), 1, cv2.LINE_AA)
    cv2.putText(out, f'top view, grid {GRID_M:g} m, x right, y up', (8, 18),
                cv2.FONT_HERSHEY_SIMPLEX, 0.45, (40, 40, 40), 1, cv2.LINE_AA)
    return out
