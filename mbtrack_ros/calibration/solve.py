"""Intrinsics from views of a board held in front of a camera; extrinsics from boards lying on
the floor at known poses, refined together.

Intrinsics: Zhang's method as ``cv2.calibrateCamera`` implements it (plumb_bob with k3 = 0)
on a well-spread subset of the views (greedy farthest-point selection over where the board
is in the image, how large and how tilted it is).

Extrinsics: per camera a planar PnP (IPPE, then Levenberg-Marquardt) on all board corners it
sees (photometrically refined, :mod:`.align`), in room coordinates; when boards other than
the first are seen, one bundle adjustment (``scipy.optimize.least_squares``) over every
camera pose and every such board's floor pose ``(x, y, yaw)``: reprojection residuals in
units of ``CORNER_SIGMA_PX`` plus the given board poses as measurements (``POSE_SIGMA_M``,
``POSE_SIGMA_DEG``). The first board defines the room frame and is not moved.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares

from mbtrack_ros.calibration.board import Board, BoardPose, Detection
from mbtrack_ros.calibration.errors import CalibrateError
from mbtrack_ros.core.camera import Camera

__all__ = ['CORNER_SIGMA_PX', 'MIN_CORNERS', 'MIN_VIEWS', 'CameraPose', 'FloorObservation',
           'Intrinsics', 'calibrate_intrinsics', 'solve_extrinsics', 'select_views',
           'viewing_direction']

MIN_CORNERS = 6        # corners a view needs to count (ChArUco; a chessboard has all)
MIN_VIEWS = 8          # usable views the intrinsics need
MAX_VIEWS = 30         # views the intrinsics use at most
CORNER_SIGMA_PX = 0.3  # corner localisation noise assumed by the bundle adjustment, pixels
POSE_SIGMA_M = 0.05    # accuracy of a board pose measured with a tape, metres
POSE_SIGMA_DEG = 2.0   # and its yaw, degrees


@dataclass(frozen=True)
class Intrinsics:
    """One camera's intrinsics: K (3, 3), dist (5,) plumb_bob, RMS reprojection error in
    pixels over the ``views`` used (of ``usable`` views with the board)."""

    name: str
    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray
    rms: float
    views: int
    usable: int


def _spread_features(board: Board, det: Detection, width: int, height: int) -> np.ndarray:
    """(5,) where the board is in the image: centre (2, fractions of the image), size (square
    root of the projected board's area over the image area) and tilt (log ratios of the
    projected board's opposite edges)."""
    obj = board.corners[det.ids][:, :2]
    H, _ = cv2.findHomography(obj, det.pixels)
    quad = cv2.perspectiveTransform(board.outline[None, :, :2], H)[0]
    centre = quad.mean(axis=0) / (width, height)
    area = abs(cv2.contourArea(quad.astype(np.float32)))
    size = math.sqrt(area / (width * height))
    edge = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
    tilt = np.log(np.maximum(edge[[0, 1]], 1e-6) / np.maximum(edge[[2, 3]], 1e-6))
    return np.concatenate([centre, [size], 0.5 * tilt])


def _usable(board: Board, det: Detection) -> bool:
    """At least MIN_CORNERS corners that do not lie on one line."""
    if len(det) < MIN_CORNERS:
        return False
    obj = board.corners[det.ids][:, :2]
    return bool(np.linalg.matrix_rank(obj - obj.mean(axis=0), tol=1e-3 * board.square) == 2)


def select_views(features: np.ndarray, count: int) -> list[int]:
    """Indices of ``count`` rows of ``features`` (N, F) spread out as far as possible: greedy
    farthest-point selection starting from the row nearest the mean."""
    n = len(features)
    if n <= count:
        return list(range(n))
    first = int(np.argmin(np.linalg.norm(features - features.mean(axis=0), axis=1)))
    chosen = [first]
    dist = np.linalg.norm(features - features[first], axis=1)
    while len(chosen) < count:
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(features - features[k], axis=1))
    return sorted(chosen)


def calibrate_intrinsics(name: str, board: Board, detections: Sequence[Detection],
                         width: int, height: int, *, source: str = '',
                         max_views: int = MAX_VIEWS) -> Intrinsics:
    """Intrinsics of camera ``name`` from the board ``detections`` of its images (one per
    image, empty when the board was not found) of size ``width`` x ``height``.

    Raises :class:`CalibrateError` when fewer than ``MIN_VIEWS`` views are usable."""
    usable = [d for d in detections if _usable(board, d)]
    if len(usable) < MIN_VIEWS:
        raise CalibrateError(
            f'{name}: {len(usable)} of {len(detections)} images of {source or "the source"} '
            f'show the board {board.text} with >= {MIN_CORNERS} corners, {MIN_VIEWS} are '
            f'needed: '
            f'record more views, the board filling a third to two thirds of the image, '
            f'tilted, in every part of the image')
    feats = np.array([_spread_features(board, d, width, height) for d in usable])
    chosen = [usable[k] for k in select_views(feats, max_views)]
    obj = [board.corners[d.ids].astype(np.float32) for d in chosen]
    img = [d.pixels.astype(np.float32).reshape(-1, 1, 2) for d in chosen]
    flags = cv2.CALIB_FIX_K3
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)
    for attempt in range(3):
        try:
            rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(
                obj, img, (width, height), None, None, flags=flags, criteria=criteria)
        except cv2.error as err:
            raise CalibrateError(f'{name}: OpenCV could not calibrate from {len(obj)} views '
                                 f'({str(err).strip().splitlines()[-1]}): record more '
                                 f'varied views') from err
        if attempt == 2:
            break
        # drop corners whose residual exceeds 4 robust sigmas (at least 0.75 px): a corner
        # interpolated from a wrongly decoded or blurred marker; then solve again
        res = [np.linalg.norm(cv2.projectPoints(o, r, t, K, dist)[0].reshape(-1, 2)
                              - i.reshape(-1, 2), axis=1)
               for o, i, r, t in zip(obj, img, rvecs, tvecs)]
        every = np.concatenate(res)
        limit = max(0.75, 4.0 * 1.4826 * float(np.median(every)))
        if not np.any(every > limit):
            break
        keep = [r <= limit for r in res]
        pairs = [(o[k], i[k]) for o, i, k in zip(obj, img, keep) if k.sum() >= MIN_CORNERS]
        if len(pairs) < MIN_VIEWS:
            break
        obj = [p[0] for p in pairs]
        img = [p[1] for p in pairs]
    dist = np.asarray(dist, np.float64).ravel()[:5]
    if not (np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0):
        raise CalibrateError(f'{name}: the calibration diverged: record more varied views')
    return Intrinsics(name, width, height, np.asarray(K, np.float64), dist, float(rms),
                      len(obj), len(usable))


# -- extrinsics ---------------------------------------------------------------------------
@dataclass(frozen=True)
class FloorObservation:
    """Corners of board ``board`` (index into the boards list) seen by one camera:
    ids (N,) and pixels (N, 2) the solver fits (photometrically refined), ``detected``
    (N, 2) as the corner detector found them, averaged over the frames (None: the same as
    ``pixels``); the reported RMS error is against the detected corners."""

    board: int
    ids: np.ndarray
    pixels: np.ndarray
    detected: np.ndarray | None = None


@dataclass
class CameraPose:
    """A camera's solved pose and how well it fits.

    Attributes:
        camera: the camera with its new extrinsics.
        corners: board corners it sees.
        rms: reprojection RMS error of the detected corners, pixels.
        boards: indices of the boards it sees.
    """

    camera: Camera
    corners: int
    rms: float
    boards: list[int] = field(default_factory=list)


def average_detections(detections: Iterable[Detection]) -> tuple[np.ndarray, np.ndarray]:
    """Per corner id, the median pixel over the frames that show it: ``(ids (N,), pixels
    (N, 2))`` sorted by id."""
    by_id: dict[int, list[np.ndarray]] = {}
    for det in detections:
        for i, p in zip(det.ids.tolist(), det.pixels):
            by_id.setdefault(int(i), []).append(p)
    ids = np.array(sorted(by_id), dtype=int)
    pixels = np.array([np.median(by_id[i], axis=0) for i in ids]).reshape(-1, 2)
    return ids, pixels


def _room_points(board: Board, pose: BoardPose, ids: np.ndarray) -> np.ndarray:
    R, t = pose.matrix()
    return board.corners[ids] @ R.T + t


def _project(rvec: np.ndarray, tvec: np.ndarray, camera: Camera, pts: np.ndarray
             ) -> np.ndarray:
    out, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), rvec, tvec, camera.K, camera.dist)
    return out.reshape(-1, 2)


def _initial_pose(camera: Camera, pts: np.ndarray, pixels: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Planar PnP on room points (N, 3) with z = 0: IPPE's two solutions, the one in front
    of the camera with the lower error, refined by Levenberg-Marquardt."""
    obj = pts.astype(np.float64).reshape(-1, 1, 3)
    img = pixels.astype(np.float64).reshape(-1, 1, 2)
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(obj, img, camera.K, camera.dist,
                                                flags=cv2.SOLVEPNP_IPPE)
    best = None
    for rvec, tvec, err in zip(rvecs, tvecs, np.ravel(errs)):
        R, _ = cv2.Rodrigues(rvec)
        if np.all(pts @ R[2] + tvec[2, 0] > 0) and (best is None or err < best[2]):
            best = (rvec, tvec, err)
    if best is None:
        raise CalibrateError(f'{camera.name}: the board corners found cannot come from a '
                             f'board on the floor in front of the camera: check --board '
                             f'and the intrinsics')
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, camera.K, camera.dist, best[0], best[1])
    return rvec.ravel(), tvec.ravel()


def _with_pose(camera: Camera, rvec: np.ndarray, tvec: np.ndarray) -> Camera:
    from dataclasses import replace
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    return replace(camera, R=R, t=np.asarray(tvec, np.float64))


def solve_extrinsics(cameras: Sequence[Camera], boards: Sequence[tuple[Board, BoardPose]],
                     observations: dict[str, list[FloorObservation]]
                     ) -> tuple[list[CameraPose], list[BoardPose]]:
    """Camera poses in the room frame from their floor-board observations.

    Args:
        cameras: cameras with their intrinsics (extrinsics ignored).
        boards: ``(board, pose)``; the first board's pose defines the room frame, the
            others are refined when a camera sees them.
        observations: camera name -> its board observations (each with >= 4 corners).

    Returns:
        ``(poses, board_poses)``: per camera (in ``cameras`` order) its pose and fit, and
        every board's (refined) floor pose.
    """
    rvecs, tvecs = {}, {}
    for cam in cameras:
        obs = observations[cam.name]
        pts = np.concatenate([_room_points(boards[o.board][0], boards[o.board][1], o.ids)
                              for o in obs])
        pix = np.concatenate([o.pixels for o in obs])
        rvecs[cam.name], tvecs[cam.name] = _initial_pose(cam, pts, pix)
    free = sorted({o.board for obs in observations.values() for o in obs} - {0})
    poses = [p for _, p in boards]
    if free:
        rvecs, tvecs, poses = _bundle_adjust(cameras, boards, observations, rvecs, tvecs, free)
    out = []
    for cam in cameras:
        obs = observations[cam.name]
        solved = _with_pose(cam, rvecs[cam.name], tvecs[cam.name])
        pts = np.concatenate([_room_points(boards[o.board][0], poses[o.board], o.ids)
                              for o in obs])
        pix = np.concatenate([o.pixels if o.detected is None else o.detected for o in obs])
        res = _project(rvecs[cam.name], tvecs[cam.name], cam, pts) - pix
        rms = float(np.sqrt(np.mean(np.sum(res ** 2, axis=1))))
        out.append(CameraPose(solved, len(pix), rms, sorted({o.board for o in obs})))
    return out, poses


def _bundle_adjust(cameras, boards, observations, rvecs, tvecs, free):
    """Joint least squares over camera poses (6 each) and the floor poses (3 each) of the
    ``free`` boards; see the module docstring."""
    names = [c.name for c in cameras]
    x0 = np.concatenate([np.concatenate([rvecs[n], tvecs[n]]) for n in names]
                        + [np.array([boards[b][1].x, boards[b][1].y, boards[b][1].yaw])
                           for b in free])
    slot = {b: 6 * len(names) + 3 * k for k, b in enumerate(free)}

    def unpack(x):
        poses = [p for _, p in boards]
        for b, s in slot.items():
            poses[b] = BoardPose(*x[s:s + 3])
        return poses

    def residuals(x):
        poses = unpack(x)
        res = []
        for k, cam in enumerate(cameras):
            for o in observations[cam.name]:
                pts = _room_points(boards[o.board][0], poses[o.board], o.ids)
                proj = _project(x[6 * k:6 * k + 3], x[6 * k + 3:6 * k + 6], cam, pts)
                res.append(((proj - o.pixels) / CORNER_SIGMA_PX).ravel())
        for b, s in slot.items():
            given = boards[b][1]
            res.append(np.array([(x[s] - given.x) / POSE_SIGMA_M,
                                 (x[s + 1] - given.y) / POSE_SIGMA_M,
                                 (x[s + 2] - given.yaw) / POSE_SIGMA_DEG]))
        return np.concatenate(res)

    sol = least_squares(residuals, x0, method='trf', x_scale='jac', loss='soft_l1',
                        f_scale=3.0, max_nfev=200)
    x = sol.x
    for k, n in enumerate(names):
        rvecs[n], tvecs[n] = x[6 * k:6 * k + 3], x[6 * k + 3:6 * k + 6]
    return rvecs, tvecs, unpack(x)


def viewing_direction(camera: Camera) -> tuple[float, float]:
    """``(azimuth, depression)`` of the optical axis in degrees: azimuth counter-clockwise
    from the room's x axis on the floor, depression below the horizontal (90 = straight
    down, negative = looking up)."""
    axis = camera.R[2]  # optical axis in the room frame (third row of R)
    azimuth = math.degrees(math.atan2(axis[1], axis[0]))
    depression = math.degrees(math.asin(float(np.clip(-axis[2], -1.0, 1.0))))
    return azimuth, depression
