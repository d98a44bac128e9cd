"""At one frame, the HJS terms of one camera for a track put at places on a line: the
track's particles are replaced by states at x = X and y from Y0 to Y1 (N places; the
track's mean otherwise), the other tracks keep their clouds and weights, and for each
camera the foreground term fc (000 Eq. 33 with Eq. 26), the background term bc (Eq. 40)
and the visible mass sum(w*) of each place are printed (``MeasurementModel.hjs_debug``),
then the tracker's summed log-likelihood against the first place. Steps the tracker as
``detection_eval.py run`` does (same seed); the clouds as ``hjs_line.py`` builds them
(``_eval.with_track_replaced``).

usage: .venv/bin/python docs/diag/hjs_terms.py REC SEED TRACK FRAME X Y0 Y1 [N]
"""
import sys
from pathlib import Path

import numpy as np

from _eval import tracked_frames, with_track_replaced
from mbtrack_ros.core.state import X, Y

if len(sys.argv) not in (8, 9):
    sys.exit('usage: hjs_terms.py REC SEED TRACK FRAME X Y0 Y1 [N]')
rec, seed, tid, frame = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
x = float(sys.argv[5])
ys = np.linspace(float(sys.argv[6]), float(sys.argv[7]), int(sys.argv[8]) if len(sys.argv) == 9
                 else 6)
for fs, result, tracker in tracked_frames(rec, seed, frame):
    if fs.index != frame:
        continue
    mm = tracker.measurement
    track = next(t for t in result.tracks if t.track_id == tid)
    line = np.repeat(track.mean[None].astype(np.float64), len(ys), 0)
    line[:, X], line[:, Y] = x, ys
    clouds, logw, models, k = with_track_replaced(tracker, tid, line)
    weights = [np.exp(w - w.max()) for w in logw]
    print(f'frame {frame}: track {tid} at ({track.mean[X]:.2f}, {track.mean[Y]:.2f}); '
          f'places x {x:.2f}, y {np.round(ys, 2)}')
    for name in mm.camera_names:
        dbg = mm.hjs_debug(name, clouds, weights, models)
        mine = dbg.target == k
        print(f'  {name}: fc {np.round(dbg.fc[mine], 3)} bc {np.round(dbg.bc[mine], 3)} '
              f'sum(w*) {np.round(dbg.visible[mine], 1)}')
    total = mm.hjs(clouds, logw, models, log_weights=True).loglik[k]
    print(f'  log-likelihood, all cameras: {np.round(total - total[0], 1)}')
