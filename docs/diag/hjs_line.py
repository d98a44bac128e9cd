"""At the given frames, what the tracker's own measurement model (the HJS likelihood of
000 Eq. 19 with occlusion by the other tracks' clouds, the coverage term, the exits) says
per camera and summed along the line from a track's mean (0) to a ground-truth person
(1), from LOW (default -0.5) to 1.5: the track's particles are replaced by nine states on
that line (the track's mean otherwise), the other tracks keep their clouds and weights.
Printed against the value at the step nearest 0. Steps the tracker as
``detection_eval.py run`` does (same seed); the tree's code decides (run it from a
worktree with a variant to see the variant's).

usage: .venv/bin/python docs/diag/hjs_line.py REC SEED TRACK PERSON FRAME[,FRAME...] [LOW]
"""
import sys
from pathlib import Path

import numpy as np

from _eval import places, tracked_frames, with_track_replaced
from mbtrack_ros.core.state import X, Y

if len(sys.argv) not in (6, 7):
    sys.exit('usage: hjs_line.py REC SEED TRACK PERSON FRAME[,FRAME...] [LOW]')
rec, seed, tid, pid = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
frames = sorted(int(f) for f in sys.argv[5].split(','))
people = places(rec)
steps = np.linspace(float(sys.argv[6]) if len(sys.argv) == 7 else -0.5, 1.5, 9)
for fs, result, tracker in tracked_frames(rec, seed, frames[-1]):
    if fs.index not in frames:
        continue
    track = next(t for t in result.tracks if t.track_id == tid)
    person = people[fs.index][pid]
    mm = tracker.measurement
    line = np.repeat(track.mean[None].astype(np.float64), len(steps), 0)
    line[:, X] = track.mean[X] + steps * (person[0] - track.mean[X])
    line[:, Y] = track.mean[Y] + steps * (person[1] - track.mean[Y])
    clouds, logw, models, k = with_track_replaced(tracker, tid, line)
    ids = tracker.filter.track_ids()
    zero = int(np.argmin(np.abs(steps)))
    print(f'frame {fs.index}: track {tid} at ({track.mean[X]:.2f}, {track.mean[Y]:.2f}), '
          f'person {pid} at ({person[0]:.2f}, {person[1]:.2f}); steps {steps.round(2)}; '
          f'other tracks {[i for i in ids if i != tid]}')
    images = dict(mm._images)
    try:
        for name in sorted(images):
            mm._images = {name: images[name]}
            ll = mm.hjs(clouds, logw, models, log_weights=True).loglik[k]
            print(f'  {name}: {np.round(ll - ll[zero], 1)}')
    finally:
        mm._images = images
    ll = mm.hjs(clouds, logw, models, log_weights=True).loglik[k]
    print(f'  all : {np.round(ll - ll[zero], 1)}')
