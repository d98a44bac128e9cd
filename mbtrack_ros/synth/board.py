"""Rendered calibration-board images (``mbtrack synth-board``): a printed board lying on the
synthetic room's floor as each camera sees it, and a board held in front of one camera at
random poses, for testing ``mbtrack calibrate`` against the true calibration.

Rays come from :meth:`Camera.pixel_rays` (lens distortion included), so the pictures follow
the project's camera model exactly. Each pixel near a board averages ``supersample``^2 rays
(box filter) through the board's texture (bilinear at 0.5 mm), the way a sensor integrates
light over its pixel; the room behind it is :class:`CameraView`'s static rendering.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from mbtrack_ros.calibration.align import sample_bilinear
from mbtrack_ros.calibration.board import Board, BoardPose
from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.synth.errors import SynthError
from mbtrack_ros.synth.room import FLOOR, CameraView, Room, default_room, make_calibration

__all__ = ['floor_images', 'intrinsics_images', 'intrinsics_poses',
           'render_boards', 'rig_calibration', 'write_board_images']

_TEXTURE_PPM = 2000.0   # board texture resolution, pixels per metre
_MARGIN = 0.04          # white paper around the squares, metres
_PAPER, _INK = 0.85, 0.06  # reflectances of the paper and the print


def rig_calibration(width: int, height: int, *, camera_height: float | None = None,
                    ceiling: bool = True) -> RoomCalibration:
    """The synthetic room's calibration (:func:`make_calibration`) at ``width`` x ``height``,
    with the four corner cameras moved to ``camera_height`` metres (same floor position,
    looking at the same point) when given."""
    calib = make_calibration(default_room(), width=width, height=height, ceiling=ceiling)
    if camera_height is None:
        return calib
    room = default_room()
    target = (0.5 * room.width, 0.5 * room.depth, 0.8)
    cams = {}
    for name, cam in calib.cameras.items():
        if name == 'cam4':
            cams[name] = cam
            continue
        c = cam.center
        R, t = look_at((c[0], c[1], camera_height), target)
        cams[name] = replace(cam, R=R, t=t)
    return replace(calib, cameras=cams)


def _texture(board: Board) -> np.ndarray:
    return board.image(_TEXTURE_PPM, _MARGIN).astype(np.float32) / 255.0


def _board_hits(camera: Camera, pixels: np.ndarray, R: np.ndarray, t: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Board-frame points (N, 2) and ray lengths (N,) where the rays of ``pixels`` (N, 2)
    meet the board plane ``X = R p + t`` (NaN when they do not)."""
    rays = camera.pixel_rays(pixels)
    C = camera.center
    n = R[:, 2]
    with np.errstate(divide='ignore', invalid='ignore'):
        s = (n @ (t - C)) / (rays @ n)
    s = np.where(s > 1e-6, s, np.nan)
    p = (C + rays * s[:, None] - t) @ R  # R^T (X - t) for row vectors
    return p[:, :2], s


def render_boards(camera: Camera, placements: Sequence[tuple[Board, np.ndarray, np.ndarray]],
                  *, background: np.ndarray | None = None, depth: np.ndarray | None = None,
                  light: float = 230.0, supersample: int = 3, noise: float = 2.0,
                  rng: np.random.Generator | None = None) -> np.ndarray:
    """Render boards into one camera image.

    Args:
        camera: the camera.
        placements: ``(board, R, t)`` per board, board frame -> world ``X = R p + t``.
        background: (H, W, 3) float radiance 0..255 behind the boards (grey 120 if None).
        depth: (H, W) distance of the background surface along each ray, metres; a board
            is drawn only where it is nearer (None: everywhere).
        light: radiance of a perfectly white board, 0..255.
        supersample: rays per pixel side near a board.
        noise: Gaussian sensor noise, grey levels (sigma).
        rng: generator for the noise.

    Returns:
        (H, W, 3) uint8 RGB image.
    """
    H, W = camera.height, camera.width
    image = (np.full((H, W, 3), 120.0) if background is None
             else np.asarray(background, np.float64).copy())
    grid = np.stack(np.meshgrid(np.arange(W, dtype=np.float64),
                                np.arange(H, dtype=np.float64)), axis=-1).reshape(-1, 2)
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
    sub = np.stack(np.meshgrid(offsets, offsets), axis=-1).reshape(-1, 2)  # (S, 2)
    for board, R, t in placements:
        tex = _texture(board)
        x0, y0 = board.outline[0, :2]
        lo = np.array([x0 - _MARGIN, y0 - _MARGIN])
        hi = lo + np.array([tex.shape[1], tex.shape[0]]) / _TEXTURE_PPM
        xy, _ = _board_hits(camera, grid, R, t)  # where to look closer
        pad = 0.1 * board.square
        near = np.all((xy > lo - pad) & (xy < hi + pad), axis=1)
        near = cv2.dilate(near.reshape(H, W).astype(np.uint8), np.ones((5, 5), np.uint8))
        index = np.flatnonzero(near.ravel())
        if index.size == 0:
            continue
        pts = (grid[index][:, None, :] + sub[None]).reshape(-1, 2)
        xy, s = _board_hits(camera, pts, R, t)
        inside = np.all((xy >= lo) & (xy <= hi), axis=1)
        if depth is not None:
            inside &= s < np.repeat(depth.reshape(-1)[index], len(sub)) + 1e-3
        # texture pixel (u, v) of board point (x, y): pixel centres at integers
        uv = ((np.nan_to_num(xy) - lo) * _TEXTURE_PPM - 0.5).astype(np.float32)
        refl = sample_bilinear(tex, uv)
        value = light * (_INK + (_PAPER - _INK) * refl)
        bg = np.repeat(image.reshape(-1, 3)[index], len(sub), axis=0)
        mixed = np.where(inside[:, None], value[:, None], bg)
        image.reshape(-1, 3)[index] = mixed.reshape(len(index), len(sub), 3).mean(axis=1)
    if noise > 0:
        rng = rng if rng is not None else np.random.default_rng(0)
        image += rng.normal(0.0, noise, image.shape)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def floor_images(calibration: RoomCalibration,
                 boards: Sequence[tuple[Board, BoardPose]], *, room: Room | None = None,
                 rng: np.random.Generator | None = None, supersample: int = 3,
                 room_background: bool = True) -> dict[str, np.ndarray]:
    """Per camera, the (H, W, 3) uint8 RGB picture of the synthetic room with the boards lying
    on its floor at their poses (boards hidden behind furniture are hidden); with
    ``room_background`` False the boards lie on a plain grey floor (faster)."""
    room = room or default_room()
    rng = rng if rng is not None else np.random.default_rng(0)
    placements = [(b, *p.matrix()) for b, p in boards]
    out = {}
    for name, cam in calibration.cameras.items():
        if not room_background:
            out[name] = render_boards(cam, placements, rng=rng, supersample=supersample)
            continue
        view = CameraView.build(cam, room)
        floor_depth = np.where(view.surface == FLOOR, view.depth + 0.01, 0.0)
        out[name] = render_boards(cam, placements, background=view.radiance,
                                  depth=floor_depth, rng=rng, supersample=supersample)
    return out


def intrinsics_poses(camera: Camera, board: Board, count: int, *,
                     rng: np.random.Generator | None = None
                     ) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` random poses ``(R, t)`` (board frame -> camera frame) of ``board`` held in
    front of ``camera``: the board's centre on the ray of a random pixel of the image's
    central 80 %, at the distance where it fills 35-70 % of the image width, tilted 5 to 45
    degrees about a random axis in its plane and rolled up to 30 degrees."""
    rng = rng if rng is not None else np.random.default_rng(0)
    cam = replace(camera, R=np.eye(3), t=np.zeros(3))
    w, h = board.size
    centre = board.outline[0] + np.array([0.5 * w, 0.5 * h, 0.0])
    poses = []
    for _ in range(count):
        fill = rng.uniform(0.35, 0.7)
        d = cam.focal * w / (fill * cam.width)
        u, v = rng.uniform(0.1, 0.9) * cam.width, rng.uniform(0.1, 0.9) * cam.height
        ray = cam.normalized_rays(np.array([[u, v]]))[0]
        position = ray / np.linalg.norm(ray) * d
        axis = rng.normal(size=2)
        axis = np.array([*(axis / np.linalg.norm(axis)), 0.0])
        tilt, _ = cv2.Rodrigues(axis * np.radians(rng.uniform(5.0, 45.0)))
        roll, _ = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(rng.uniform(-30, 30))]))
        R = tilt @ roll
        poses.append((R, position - R @ centre))
    return poses


def intrinsics_images(camera: Camera, board: Board, count: int, *,
                      rng: np.random.Generator | None = None, supersample: int = 3
                      ) -> list[np.ndarray]:
    """``count`` (H, W, 3) uint8 pictures of ``board`` held in front of ``camera`` (its
    intrinsics; its pose is irrelevant) at :func:`intrinsics_poses`, on grey backgrounds."""
    rng = rng if rng is not None else np.random.default_rng(0)
    cam = replace(camera, R=np.eye(3), t=np.zeros(3))
    images = []
    for R, t in intrinsics_poses(camera, board, count, rng=rng):
        background = np.full((cam.height, cam.width, 3), rng.uniform(60, 140))
        images.append(render_boards(cam, [(board, R, t)], background=background, rng=rng,
                                    supersample=supersample))
    return images


def write_board_images(outdir: str | Path, calibration: RoomCalibration,
                       boards: Sequence[tuple[Board, BoardPose]], *, intrinsics_views: int = 0,
                       seed: int = 0, supersample: int = 3) -> dict[str, Path]:
    """Write ``OUTDIR/calibration.yaml`` (the true calibration), ``OUTDIR/floor/NAME.png`` per
    camera and, with ``intrinsics_views`` > 0, ``OUTDIR/intrinsics/NAME/NNN.png``. Returns the
    written paths by role."""
    out = Path(outdir)
    if out.exists() and any(out.iterdir()):
        raise SynthError(f'{out} exists and is not empty')
    rng = np.random.default_rng(seed)
    (out / 'floor').mkdir(parents=True, exist_ok=True)
    calibration.save(out / 'calibration.yaml')
    for name, img in floor_images(calibration, boards, rng=rng,
                                  supersample=supersample).items():
        cv2.imwrite(str(out / 'floor' / f'{name}.png'), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    if intrinsics_views > 0:
        board = boards[0][0]
        for name, cam in calibration.cameras.items():
            folder = out / 'intrinsics' / name
            folder.mkdir(parents=True, exist_ok=True)
            for k, img in enumerate(intrinsics_images(cam, board, intrinsics_views, rng=rng,
                                                      supersample=supersample)):
                cv2.imwrite(str(folder / f'{k:03d}.png'), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    return {'calibration': out / 'calibration.yaml', 'floor': out / 'floor',
            'intrinsics': out / 'intrinsics'}
