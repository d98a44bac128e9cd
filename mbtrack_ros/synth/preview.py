"""Contact sheet of a recording: all camera views of one frame with people drawn on them."""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import cv2
import numpy as np

from mbtrack_ros.core.camera import CalibrationError, Camera, RoomCalibration
from mbtrack_ros.recording.csvfiles import CsvFormatError, GroundTruthRow, read_ground_truth
from mbtrack_ros.synth.errors import SynthError

__all__ = ['contact_sheet', 'draw_people']

_GT_COLOUR = (40, 230, 40)      # RGB, ground truth: green
_TRACK_COLOUR = (255, 40, 220)  # RGB, tracks: magenta


def _id_colour(k: int) -> tuple[int, int, int]:
    hue = (k * 47) % 180
    bgr = cv2.cvtColor(np.uint8([[[hue, 200, 255]]]), cv2.COLOR_HSV2RGB)[0, 0]
    return tuple(int(c) for c in bgr)


def draw_people(image: np.ndarray, camera: Camera, scale: float,
                ground_truth: Iterable[GroundTruthRow] = (),
                tracks: Sequence[tuple[int, float, float, float]] | None = None) -> None:
    """Draw people on an RGB image (in place) that is ``scale`` times the camera size.

    Ground truth: a line from the projected floor point to the head, a disc at the floor
    point, a circle at the head and the id. Tracks ``(track_id, x, y, height)``: a square at
    the floor point, a diamond at the head height and ``T<id>``.
    """
    def px(point: np.ndarray) -> tuple[int, int] | None:
        uv = camera.project(point)
        if not np.all(np.isfinite(uv)) or not camera.in_image(uv, margin=50):
            return None
        return int(round((uv[0] + 0.5) * scale - 0.5)), int(round((uv[1] + 0.5) * scale - 0.5))

    font = cv2.FONT_HERSHEY_SIMPLEX
    for row in ground_truth:
        foot = px(np.array([row.x, row.y, 0.0]))
        head = px(np.array([row.x, row.y, row.z_head]))
        colour = _id_colour(row.person_id)
        if foot and head:
            cv2.line(image, foot, head, colour, 1, cv2.LINE_AA)
        if foot:
            cv2.circle(image, foot, 4, _GT_COLOUR, -1, cv2.LINE_AA)
        if head:
            cv2.circle(image, head, 5, colour, 2, cv2.LINE_AA)
            label = f'{row.person_id}' + ('s' if row.sitting else '')
            cv2.putText(image, label, (head[0] + 6, head[1] - 4), font, 0.45, (0, 0, 0), 3,
                        cv2.LINE_AA)
            cv2.putText(image, label, (head[0] + 6, head[1] - 4), font, 0.45, colour, 1,
                        cv2.LINE_AA)
    for track_id, x, y, height in tracks or ():
        foot = px(np.array([x, y, 0.0]))
        head = px(np.array([x, y, height]))
        if foot:
            cv2.rectangle(image, (foot[0] - 5, foot[1] - 5), (foot[0] + 5, foot[1] + 5),
                          _TRACK_COLOUR, 2)
        if head:
            pts = np.array([[head[0], head[1] - 6], [head[0] + 6, head[1]],
                            [head[0], head[1] + 6], [head[0] - 6, head[1]]], np.int32)
            cv2.polylines(image, [pts], True, _TRACK_COLOUR, 2, cv2.LINE_AA)
            cv2.putText(image, f'T{track_id}', (head[0] - 30, head[1] + 16), font, 0.45,
                        _TRACK_COLOUR, 1, cv2.LINE_AA)
        if foot and head:
            cv2.line(image, foot, head, _TRACK_COLOUR, 1, cv2.LINE_4)


def contact_sheet(recording_dir: str | Path, frame_index: int, out_png: str | Path, *,
                  tracks: Sequence[tuple[int, float, float, float]] | None = None,
                  columns: int = 3) -> Path:
    """Write a PNG grid of all camera views of frame ``frame_index`` of a recording.

    Ground-truth people (``ground_truth.csv``) are drawn in every view, and the optional
    ``tracks`` (``(track_id, x, y, height)`` in metres) in another style. Images narrower
    than 400 px are shown twice as large. Returns the PNG path.
    """
    from mbtrack_ros.recording.bag import BagError, RecordingReader

    recording_dir = Path(recording_dir)
    try:
        calib = RoomCalibration.load(recording_dir / 'calibration.yaml')
        gt_path = recording_dir / 'ground_truth.csv'
        gt = [r for r in read_ground_truth(gt_path) if r.frame == frame_index] \
            if gt_path.exists() else []
    except (CalibrationError, CsvFormatError) as err:
        raise SynthError(str(err)) from err
    if frame_index < 0:
        raise SynthError(f'frame index must be >= 0, got {frame_index}')
    images = None
    try:
        with RecordingReader(recording_dir) as reader:
            for fs in reader.frames():
                if fs.index == frame_index:
                    images = fs.images
                    break
    except BagError as err:
        raise SynthError(f'cannot read {recording_dir}: {err}') from err
    if images is None:
        raise SynthError(f'{recording_dir} has no frame {frame_index}')
    tiles = []
    for name, cam in calib.cameras.items():
        image = images.get(name)
        if image is None:
            image = np.zeros((cam.height, cam.width, 3), np.uint8)
        scale = 2.0 if cam.width < 400 else 1.0
        tile = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
        draw_people(tile, cam, scale, gt, tracks)
        cv2.putText(tile, f'{name}  frame {frame_index}', (6, 18), cv2.FONT_HERSHEY_SIMPLEX,
                    0.5, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(tile)
    h = max(t.shape[0] for t in tiles)
    w = max(t.shape[1] for t in tiles)
    cols = max(1, min(columns, len(tiles)))
    rows = -(-len(tiles) // cols)
    sheet = np.full((rows * h, cols * w, 3), 30, np.uint8)
    for k, tile in enumerate(tiles):
        r, c = divmod(k, cols)
        sheet[r * h:r * h + tile.shape[0], c * w:c * w + tile.shape[1]] = tile
    out_png = Path(out_png)
    if not cv2.imwrite(str(out_png), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR)):
        raise SynthError(f'cannot write {out_png}')
    return out_png
