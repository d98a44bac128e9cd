"""Ground-truth rows off the walkable region a tracker follows people on (twenty-third
session).

Usage: off_floor.py REC [REC ...]

Per recording, the ground-truth rows whose place lies outside the calibration's floor and
outside every exit (``RoomCalibration.floor``, ``exits``): a track cannot be there, so such
a person is always at least that far from any track. Prints their count and, per person,
the first and last such row with the largest distance from the region.
docs/detection.md ("The wall beside the door in the synth") runs it on the clear-room
recordings.
"""
import sys
from pathlib import Path

import numpy as np

from mbtrack_ros.core.camera import RoomCalibration, distance_to_rect
from mbtrack_ros.recording.csvfiles import read_ground_truth

if len(sys.argv) < 2:
    sys.exit('usage: off_floor.py REC [REC ...]')


for rec in map(Path, sys.argv[1:]):
    cal = RoomCalibration.load(rec / 'calibration.yaml')
    rows = read_ground_truth(rec / 'ground_truth.csv')
    xy = np.array([[r.x, r.y] for r in rows]).reshape(-1, 2)
    off = np.min([distance_to_rect(xy, r) for r in (cal.floor, *cal.exits)], axis=0)
    people: dict[int, list[tuple[int, float]]] = {}
    for r, d in zip(rows, off):
        if d > 0:
            people.setdefault(r.person_id, []).append((r.frame, float(d)))
    n = int((off > 0).sum())
    print(f'{rec.name}: {n} row{"" if n == 1 else "s"} off the floor and the exits'
          + ''.join(f'; person {p} frames {v[0][0]}-{v[-1][0]} ({len(v)} of them, up to '
                    f'{max(d for _, d in v):.3f} m)' for p, v in sorted(people.items())))
