"""Visibility, existence and state of one track, every 5 frames (eleventh session).

Usage: track_visibility.py REC SEED TRACK FIRST LAST [MRF_RADIUS]

Steps the tracker with automatic detection as ``detection_eval.py run`` does (same
configuration, same seed) and prints, from frame FIRST to LAST, the track's mean state
(x, y, vx, vy, theta, sitting probability), existence, posterior visibility xi_v per
camera and the HJS visible fraction w* per camera (docs/detection.md, "Fresh recordings,
the suite and the exclusion radius": a sitting person reported invisible everywhere).
"""
import sys
from pathlib import Path

import numpy as np

from _eval import tracked_frames

rec = Path(sys.argv[1])
seed, track_id, first, last = (int(v) for v in sys.argv[2:6])
radius = {'mrf_radius': float(sys.argv[6])} if len(sys.argv) > 6 else {}
for fs, res, _ in tracked_frames(rec, seed, last, **radius):
    if fs.index >= first and fs.index % 5 == 0:
        for t in res.tracks:
            if t.track_id == track_id:
                print(fs.index, np.round(t.mean, 2), f'existence {t.existence:.2f}',
                      'xi_v', {k: round(v, 2) for k, v in t.visibility.items()},
                      'w*', {k: round(v, 2) for k, v in t.visible_fraction.items()})
