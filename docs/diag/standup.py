"""One track's particles around a person's stand-up (thirteenth session).

Usage: standup.py REC SEED FIRST LAST TRACK:PERSON

Steps the tracker as ``detection_eval.py run`` does (same config, same seed) up to frame
LAST and prints, from frame FIRST on, the person's ground-truth place and sitting flag,
the track's weighted mean place and velocity, its probability of sitting, the distance of
its mean to the person, and the weight of its particles within 0.1 m of the person and
within 0.15 m seated / standing.
"""
import csv
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _eval import tracked_frames, weighted_cloud  # noqa: E402

from mbtrack_ros.core.state import SIT, VX, VY, X, Y  # noqa: E402

rec = Path(sys.argv[1])
seed, first, last = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
tid, pid = (int(v) for v in sys.argv[5].split(':'))
gt = {}
for r in csv.DictReader(open(rec / 'ground_truth.csv')):
    gt[int(r['frame']), int(r['person_id'])] = (float(r['x']), float(r['y']), r['sitting'])
for fs, _, tracker in tracked_frames(rec, seed, last):
    if fs.index < first or tid not in tracker.filter.track_ids() or (fs.index, pid) not in gt:
        continue
    particles, w, _ = weighted_cloud(tracker, tid)
    gx, gy, sitting = gt[fs.index, pid]
    d = np.hypot(particles[:, X] - gx, particles[:, Y] - gy)
    mean = w @ particles
    seated = particles[:, SIT] >= 0.5
    print(f'{fs.index} person ({gx:.2f}, {gy:.2f}) sitting {sitting} | track '
          f'({mean[X]:.2f}, {mean[Y]:.2f}) v ({mean[VX]:+.2f}, {mean[VY]:+.2f}) '
          f'p(sit) {w @ seated:.2f} d mean {np.hypot(mean[X] - gx, mean[Y] - gy):.2f} | '
          f'w(d < 0.1) {w[d < 0.1].sum():.2f} seated {w[(d < 0.15) & seated].sum():.2f} '
          f'standing {w[(d < 0.15) & ~seated].sum():.2f} (d < 0.15)', flush=True)
