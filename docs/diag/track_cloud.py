"""Per frame from FIRST to LAST, each named track's model size (height, width), its
estimate, the weighted spread of its particles in y, their weighted mean velocity and its
existence, beside the ground-truth places of the people with the same ids. Steps the
tracker as ``detection_eval.py run`` does (same seed); the clouds from
``_eval.weighted_cloud``.

usage: .venv/bin/python docs/diag/track_cloud.py REC SEED TRACK[,TRACK...] FIRST LAST
"""
import sys
from pathlib import Path

import numpy as np

from _eval import places, tracked_frames, weighted_cloud
from mbtrack_ros.core.state import VX, VY, X, Y

if len(sys.argv) != 6:
    sys.exit('usage: track_cloud.py REC SEED TRACK[,TRACK...] FIRST LAST')
rec, seed = Path(sys.argv[1]), int(sys.argv[2])
tids = {int(t) for t in sys.argv[3].split(',')}
first, last = int(sys.argv[4]), int(sys.argv[5])
people = places(rec)
for fs, result, tracker in tracked_frames(rec, seed, last):
    if fs.index < first:
        continue
    flt = tracker.filter
    here = people.get(fs.index, {})
    for track in result.tracks:
        tid = track.track_id
        if tid not in tids or tid not in flt.track_ids():
            continue
        cloud, w, model = weighted_cloud(tracker, tid)
        y_mean = float(w @ cloud[:, Y])
        y_spread = float(np.sqrt(w @ (cloud[:, Y] - y_mean) ** 2))
        person = (f'person ({here[tid][0]:.2f}, {here[tid][1]:.2f})' if tid in here
                  else 'person -')
        print(f'{fs.index} track {tid}: h {model.height:.2f} w {model.width:.2f}, '
              f'at ({track.mean[X]:.2f}, {track.mean[Y]:.2f}), sd(y) {y_spread:.2f}, '
              f'v ({w @ cloud[:, VX]:.2f}, {w @ cloud[:, VY]:.2f}), '
              f'existence {track.existence:.3f}; {person}')
