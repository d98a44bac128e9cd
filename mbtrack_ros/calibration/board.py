"""Calibration boards: the ``--board`` syntax, corner detection, floor poses, printable sheets.

Board syntax: ``charuco:COLS:ROWS:SQUARE_M:MARKER_M:DICT[:FIRST_ID]`` (a ChArUco board of
COLS x ROWS squares, ArUco markers of dictionary DICT numbered from FIRST_ID, default 0, so
that several boards on one floor carry distinct ids) or ``chessboard:COLS:ROWS:SQUARE_M``
(COLS x ROWS squares).

Board frame: OpenCV's. ChArUco: origin at the outer corner of the board's first square, x
along its rows of squares, y along its columns, z into the board; its inner corners are at
``(i * SQUARE_M, j * SQUARE_M, 0)``, i = 1..COLS-1, j = 1..ROWS-1. Chessboard: origin at the
first inner corner (the first object point), same axes. A board lying flat on the floor
face up has z pointing into the floor; the room frame has the same origin and x axis and z up,
so the room's y is the board's -y. ``BoardPose(x, y, yaw)`` places the board's origin at
room ``(x, y)`` with its x axis ``yaw`` degrees from the room's x axis (counter-clockwise
seen from above).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from mbtrack_ros.calibration.errors import CalibrateError

__all__ = ['Board', 'BoardPose', 'Detection', 'parse_board', 'parse_pose', 'printable_sheets']

_EXAMPLE = 'charuco:5:4:0.25:0.19:DICT_4X4_50 or chessboard:9:6:0.05'


@dataclass(frozen=True)
class BoardPose:
    """Where a board lies on the floor: its origin at room ``(x, y)`` metres, its x axis
    ``yaw`` degrees counter-clockwise from the room's x axis."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def matrix(self) -> tuple[np.ndarray, np.ndarray]:
        """``(R, t)`` board frame -> room frame: ``X_room = R @ X_board + t``; R (3, 3),
        t (3,) metres. R = Rz(yaw) @ diag(1, -1, -1) (board z into the floor, room z up)."""
        c, s = math.cos(math.radians(self.yaw)), math.sin(math.radians(self.yaw))
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return Rz @ np.diag([1.0, -1.0, -1.0]), np.array([self.x, self.y, 0.0])


def parse_pose(text: str) -> BoardPose:
    """``X,Y,YAW`` (metres, metres, degrees) -> :class:`BoardPose`."""
    try:
        values = [float(v) for v in str(text).split(',')]
    except ValueError as err:
        raise CalibrateError(f'--board-pose expects X,Y,YAW (metres, metres, degrees), '
                             f'got {text!r}') from err
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise CalibrateError(f'--board-pose expects three numbers X,Y,YAW (metres, metres, '
                             f'degrees), got {text!r}')
    return BoardPose(*values)


@dataclass(frozen=True)
class Detection:
    """Board corners found in one image.

    Attributes:
        ids: (N,) int corner ids (index into :attr:`Board.corners`).
        pixels: (N, 2) float64 sub-pixel corner positions (OpenCV pixel convention).
    """

    ids: np.ndarray
    pixels: np.ndarray

    def __len__(self) -> int:
        return int(self.ids.size)


@dataclass(frozen=True)
class Board:
    """A calibration board parsed from its ``--board`` text.

    Attributes:
        kind: ``'charuco'`` or ``'chessboard'``.
        cols, rows: number of squares along x and y.
        square: square side, metres.
        marker: ArUco marker side, metres (ChArUco only, else 0).
        dictionary: ArUco dictionary name (ChArUco only, else '').
        first_id: id of the board's first marker (ChArUco only).
        text: the spec it was parsed from.
    """

    kind: str
    cols: int
    rows: int
    square: float
    marker: float = 0.0
    dictionary: str = ''
    first_id: int = 0
    text: str = ''

    # -- geometry --------------------------------------------------------------------------
    @property
    def size(self) -> tuple[float, float]:
        """``(width, height)`` of the squares' area, metres."""
        return self.cols * self.square, self.rows * self.square

    @property
    def corners(self) -> np.ndarray:
        """(N, 3) float64 inner-corner positions in the board frame, metres, in OpenCV's
        order (row by row, x fastest); N = (COLS - 1) * (ROWS - 1)."""
        j, i = np.mgrid[1:self.rows, 1:self.cols]
        xy = np.stack([i.ravel(), j.ravel()], axis=1) * self.square
        if self.kind == 'chessboard':
            xy -= self.square
        return np.concatenate([xy, np.zeros((len(xy), 1))], axis=1).astype(np.float64)

    @property
    def outline(self) -> np.ndarray:
        """(4, 3) corners of the squares' area in the board frame, metres."""
        w, h = self.size
        o = -self.square if self.kind == 'chessboard' else 0.0
        return np.array([[o, o, 0], [o + w, o, 0], [o + w, o + h, 0], [o, o + h, 0]], float)

    @property
    def marker_ids(self) -> np.ndarray:
        """(M,) ids of the board's ArUco markers (empty for a chessboard)."""
        if self.kind != 'charuco':
            return np.zeros(0, int)
        return np.arange(self.first_id, self.first_id + (self.cols * self.rows) // 2)

    # -- OpenCV objects --------------------------------------------------------------------
    def _dictionary(self):
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))

    def opencv_board(self):
        """The ``cv2.aruco.CharucoBoard`` (ChArUco only)."""
        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square, self.marker,
                                      self._dictionary(), self.marker_ids.astype(np.int32))

    def image(self, px_per_m: float, margin_m: float = 0.0) -> np.ndarray:
        """(H, W) uint8 picture of the board at ``px_per_m`` pixels per metre with a white
        margin of ``margin_m`` metres; board-frame point ``(x, y)`` is at pixel
        ``((x - x0 + margin_m) * px_per_m - 0.5, ...)`` with ``(x0, y0)`` the outline's first
        corner (pixel centres at integers)."""
        w, h = self.size
        W, H = round(w * px_per_m), round(h * px_per_m)
        if self.kind == 'charuco':
            squares = self.opencv_board().generateImage((W, H), marginSize=0, borderBits=1)
        else:
            u = (np.arange(W) + 0.5) / px_per_m // self.square
            v = (np.arange(H) + 0.5) / px_per_m // self.square
            squares = np.where((u[None, :] + v[:, None]) % 2 == 0, 0, 255).astype(np.uint8)
        m = round(margin_m * px_per_m)
        return cv2.copyMakeBorder(squares, m, m, m, m, cv2.BORDER_CONSTANT, value=255)

    # -- detection ---------------------------------------------------------------------------
    def detect(self, gray: np.ndarray, *, far: bool = False) -> Detection:
        """Find the board's inner corners in a (H, W) uint8 image; empty when not found.

        ChArUco: ``cv2.aruco.CharucoDetector`` (markers, then corners interpolated between
        them and refined to sub-pixel); small images are searched at twice their size so
        that markers of a few pixels per bit are still decoded. ``far`` (a board seen from
        across the room, squares of a few tens of pixels): the corners are then refined on
        the checker edges away from the markers (:meth:`_refine_masked`). Chessboard:
        ``findChessboardCornersSB`` (all corners or none)."""
        if self.kind == 'charuco':
            scale = 2 if max(gray.shape) < 1600 else 1
            work = cv2.resize(gray, None, fx=scale, fy=scale,
                              interpolation=cv2.INTER_CUBIC) if scale > 1 else gray
            params = cv2.aruco.DetectorParameters()
            params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
            charuco = cv2.aruco.CharucoParameters()
            charuco.minMarkers = 1
            detector = cv2.aruco.CharucoDetector(self.opencv_board(), charuco, params)
            corners, ids, _, _ = detector.detectBoard(work)
            if ids is None or len(ids) == 0:
                return Detection(np.zeros(0, int), np.zeros((0, 2)))
            pixels = (corners.reshape(-1, 2).astype(np.float64) + 0.5) / scale - 0.5
            ids = ids.ravel().astype(int)
            if far:
                pixels = self._refine_masked(gray, ids, _refine(gray, pixels))
            return Detection(ids, pixels)
        found, corners = cv2.findChessboardCornersSB(
            gray, (self.cols - 1, self.rows - 1), flags=cv2.CALIB_CB_ACCURACY)
        if not found:
            return Detection(np.zeros(0, int), np.zeros((0, 2)))
        return Detection(np.arange(len(corners)), corners.reshape(-1, 2).astype(np.float64))

    def _refine_masked(self, gray: np.ndarray, ids: np.ndarray, pixels: np.ndarray,
                       rounds: int = 2, reach: float = 0.6, min_near: int = 4,
                       max_radius: int = 8, marker_gap_px: float = 2.5) -> np.ndarray:
        """ChArUco corners (N, 2) refined on the checker edges alone.

        OpenCV's ``cornerSubPix`` weighs every gradient in its window; near a ChArUco
        corner the markers' edges lie a few pixels away and bias it by up to half a pixel
        on small boards. Here each corner solves the same gradient-orthogonality equations
        (the corner q satisfies ``sum g g^T (q - p) = 0`` over pixels p with gradient g) over
        the pixels whose board position, through a homography fitted to the neighbouring
        corners, lies within 0.6 squares of the corner but at least 1.5 pixels away from every
        marker; a weak pull towards the previous estimate keeps directions without such
        pixels where they were."""
        if len(ids) < 4:
            return pixels
        img = gray.astype(np.float32)
        gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3) / 8.0
        gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3) / 8.0
        obj = self.corners[ids][:, :2]
        n_cols = self.cols - 1
        grid = np.stack([ids % n_cols, ids // n_cols], axis=1)
        off = 0.5 * (self.square - self.marker)
        H_img, W_img = gray.shape
        out = pixels.copy()
        for _ in range(rounds):
            H_all, _ = cv2.findHomography(obj, out)
            new = out.copy()
            for k in range(len(ids)):
                near = np.all(np.abs(grid - grid[k]) <= 1, axis=1)
                H = H_all
                if near.sum() < min_near:
                    continue
                if near.sum() >= 4 and np.linalg.matrix_rank(
                        obj[near] - obj[near].mean(axis=0), tol=1e-6) == 2:
                    H_loc, _ = cv2.findHomography(obj[near], out[near])
                    H = H_loc if H_loc is not None else H_all
                if H is None:
                    continue
                # pixels per metre around the corner, from the homography's local scale
                d = cv2.perspectiveTransform(
                    np.array([[obj[k], obj[k] + (self.square, 0), obj[k] + (0, self.square)]]),
                    H)[0]
                px_per_m = max(np.linalg.norm(d[1] - d[0]), np.linalg.norm(d[2] - d[0])) \
                    / self.square
                radius = int(np.clip(np.ceil(reach * self.square * px_per_m), 2, max_radius))
                cx, cy = int(round(out[k, 0])), int(round(out[k, 1]))
                x0, x1 = max(cx - radius, 1), min(cx + radius, W_img - 2)
                y0, y1 = max(cy - radius, 1), min(cy + radius, H_img - 2)
                if x1 - x0 < radius or y1 - y0 < radius:
                    continue  # too little of the window inside the image
                ys, xs = np.mgrid[y0:y1 + 1, x0:x1 + 1]
                p = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
                b = cv2.perspectiveTransform(p[None], np.linalg.inv(H))[0] - obj[k]
                margin = marker_gap_px / px_per_m
                keep = ((np.abs(b) < reach * self.square).all(axis=1)
                        & ((np.abs(b[:, 0]) < off - margin) | (np.abs(b[:, 1]) < off - margin)))
                if keep.sum() < 4:
                    continue
                g = np.stack([gx[ys, xs].ravel(), gy[ys, xs].ravel()], axis=1)[keep]
                pk = p[keep]
                A = np.einsum('ni,nj->ij', g, g)
                rhs = np.einsum('ni,nj,nj->i', g, g, pk)
                lam = 1e-3 * np.trace(A)
                q = np.linalg.solve(A + lam * np.eye(2), rhs + lam * out[k])
                if np.linalg.norm(q - out[k]) < 0.25 * radius:
                    new[k] = q
            out = new
        return out


def _refine(gray: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Sub-pixel corner refinement (``cornerSubPix``) with a window that fits the image."""
    if len(pixels) == 0:
        return pixels
    pts = pixels.astype(np.float32).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    if len(pixels) > 1:
        d = np.linalg.norm(pixels[:, None] - pixels[None], axis=-1)
        d[d == 0] = np.inf
        spacing = float(np.min(d))
    else:
        spacing = 12.0
    half = int(np.clip(spacing / 4.0, 2, 6))
    cv2.cornerSubPix(gray, pts, (half, half), (-1, -1), criteria)
    return pts.reshape(-1, 2).astype(np.float64)


def parse_board(text: str) -> Board:
    """Parse ``--board`` text (see the module docstring); raises :class:`CalibrateError`."""
    parts = str(text).strip().split(':')
    kind = parts[0].lower()
    try:
        if kind == 'charuco' and len(parts) in (6, 7):
            cols, rows = int(parts[1]), int(parts[2])
            square, marker = float(parts[3]), float(parts[4])
            dictionary = parts[5].upper()
            first_id = int(parts[6]) if len(parts) == 7 else 0
        elif kind == 'chessboard' and len(parts) == 4:
            cols, rows, square = int(parts[1]), int(parts[2]), float(parts[3])
            marker, dictionary, first_id = 0.0, '', 0
        else:
            raise ValueError
    except ValueError as err:
        raise CalibrateError(f'board {text!r}: expected {_EXAMPLE}') from err
    if cols < 3 or rows < 3:
        raise CalibrateError(f'board {text!r}: needs at least 3 x 3 squares')
    if not (0 < square < 10) or not math.isfinite(square):
        raise CalibrateError(f'board {text!r}: square side must be in metres, 0 < s < 10')
    if kind == 'charuco':
        if not (0 < marker < square):
            raise CalibrateError(f'board {text!r}: marker side must be smaller than the square')
        if not dictionary.startswith('DICT_') or not hasattr(cv2.aruco, dictionary):
            known = ', '.join(n for n in dir(cv2.aruco) if n.startswith('DICT_4X4')
                              or n.startswith('DICT_5X5'))
            raise CalibrateError(f'board {text!r}: unknown ArUco dictionary {parts[5]!r} '
                                 f'(e.g. {known})')
        size = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)).bytesList
        n_markers = (cols * rows) // 2
        if first_id < 0 or first_id + n_markers > size.shape[0]:
            raise CalibrateError(f'board {text!r}: markers {first_id}..'
                                 f'{first_id + n_markers - 1} do not fit {dictionary} '
                                 f'({size.shape[0]} markers)')
    return Board(kind, cols, rows, square, marker, dictionary, first_id, str(text).strip())


# A4 paper, portrait, metres, and the unprinted margin of an office printer
_SHEET = (0.210, 0.297)
_SHEET_MARGIN = 0.01


def printable_sheets(board: Board, dpi: float, *, split: bool = True
                     ) -> list[tuple[str, np.ndarray]]:
    """The board at true size for printing at ``dpi``: one image when it fits an A4 sheet,
    else A4 tiles (row-major) whose printable areas butt together, each labelled with its
    place (``r1c2``) in its margin. Returns ``[(label, (H, W) uint8)]``, label '' for a single
    image (with a white margin of one quarter square; always when ``split`` is False)."""
    if not (20 <= dpi <= 1200):
        raise CalibrateError(f'--dpi must be within 20..1200, got {dpi}')
    ppm = dpi / 0.0254
    w, h = board.size
    margin = 0.25 * board.square
    if not split or (w + 2 * margin <= _SHEET[0] and h + 2 * margin <= _SHEET[1]) or \
            (w + 2 * margin <= _SHEET[1] and h + 2 * margin <= _SHEET[0]):
        return [('', board.image(ppm, margin))]
    full = board.image(ppm, margin)
    if full.size > 400e6:
        raise CalibrateError(f'board {board.text!r} at {dpi:g} dpi would be '
                             f'{full.shape[1]}x{full.shape[0]} pixels: lower --dpi')
    landscape = w > h
    sheet_w, sheet_h = (_SHEET[1], _SHEET[0]) if landscape else _SHEET
    tile_w = round((sheet_w - 2 * _SHEET_MARGIN) * ppm)
    tile_h = round((sheet_h - 2 * _SHEET_MARGIN) * ppm)
    m = round(_SHEET_MARGIN * ppm)
    H, W = full.shape
    sheets = []
    for r, y0 in enumerate(range(0, H, tile_h)):
        for c, x0 in enumerate(range(0, W, tile_w)):
            tile = np.full((tile_h + 2 * m, tile_w + 2 * m), 255, np.uint8)
            part = full[y0:y0 + tile_h, x0:x0 + tile_w]
            tile[m:m + part.shape[0], m:m + part.shape[1]] = part
            label = f'r{r + 1}c{c + 1}'
            cv2.putText(tile, f'{label}  {board.text}', (m, max(12, m - 4)),
                        cv2.FONT_HERSHEY_SIMPLEX, max(0.3, m / 60.0), 0, 1, cv2.LINE_AA)
            sheets.append((label, tile))
    return sheets


def write_png(path: Path, image: np.ndarray) -> None:
    """Write a PNG atomically (to a temporary name, then renamed)."""
    tmp = path.with_name(f'.{path.name}.part.png')
    if not cv2.imwrite(str(tmp), image):
        raise CalibrateError(f'cannot write {path}')
    tmp.replace(path)
