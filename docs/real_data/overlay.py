"""Draw the tracks of some frames into the camera images (one row per frame).

Usage: python docs/real_data/overlay.py RECORDING TRACKS.csv OUT.jpg FRAME [FRAME ...]

Each track is drawn as a vertical 1.7 m segment above its floor position with its id; the
reference (ground_truth.csv of the recording, if any) as a white segment.
"""
from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.recording.bag import RecordingReader
from mbtrack_ros.recording.csvfiles import read_ground_truth, read_tracks

COLOURS = [(255, 60, 60), (60, 200, 60), (60, 120, 255), (255, 200, 0), (255, 0, 255)]


def main(recording: str, tracks_csv: str, out: str, *frames: str) -> None:
    wanted = [int(f) for f in frames]
    room = RoomCalibration.load(Path(recording) / 'calibration.yaml')
    tracks = read_tracks(tracks_csv)
    gt_path = Path(recording) / 'ground_truth.csv'
    truth = read_ground_truth(gt_path) if gt_path.exists() else []
    rows = []
    with RecordingReader(recording) as reader:
        for fs in reader.frames():
            if fs.index not in wanted:
                continue
            tiles = []
            for name in room.names:
                cam = room.cameras[name]
                img = fs.images[name].copy()
                items = [(r.x, r.y, (255, 255, 255), '') for r in truth if r.frame == fs.index]
                items += [(t.x, t.y, COLOURS[(t.track_id - 1) % len(COLOURS)], str(t.track_id))
                          for t in tracks if t.frame == fs.index]
                for x, y, colour, label in items:
                    p = cam.project(np.array([[x, y, 0.0], [x, y, 1.7]]))
                    if not np.all(np.isfinite(p)):
                        continue
                    a, b = tuple(int(v) for v in p[0]), tuple(int(v) for v in p[1])
                    cv2.line(img, a, b, colour, 2 if label else 1)
                    if label:
                        cv2.putText(img, label, b, cv2.FONT_HERSHEY_SIMPLEX, 0.6, colour, 2)
                cv2.putText(img, f'{name} f{fs.index}', (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                            (255, 255, 0), 1)
                tiles.append(cv2.resize(img, (270, 480)))
            rows.append(np.hstack(tiles))
    cv2.imwrite(out, cv2.cvtColor(np.vstack(rows), cv2.COLOR_RGB2BGR),
                [cv2.IMWRITE_JPEG_QUALITY, 75])


if __name__ == '__main__':
    main(*sys.argv[1:])
