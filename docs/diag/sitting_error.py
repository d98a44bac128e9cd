"""Distance of matched tracks to their person, sitting and standing apart (eleventh session).

Usage: sitting_error.py OUT REC [OUT REC ...]

For every person-frame that the CLEAR-MOT matching pairs with a track (runs of
``detection_eval.py run``), the floor distance between the track and the person, split by
the ground truth's ``sitting`` flag: count, median and 90th percentile.
"""

import numpy as np

from _eval import detection_eval as de, pairs

dist: dict[bool, list[float]] = {True: [], False: []}
for out, rec in pairs('sitting_error.py OUT REC [OUT REC ...]'):
    tracks, truth, _, _ = de._load(out, rec)
    d, frames = de._matching(tracks, truth)
    shown = {(t.frame, t.track_id): (t.x, t.y) for t in tracks}
    where = {(r.frame, r.person_id): r for r in truth}
    for f, t, p in zip(frames, d.track_id, d.person_id):
        if t >= 0:
            r = where[(int(f), int(p))]
            x, y = shown[(int(f), int(t))]
            dist[bool(r.sitting)].append(float(np.hypot(x - r.x, y - r.y)))
for sitting, v in dist.items():
    if v:
        print(f'{"sitting" if sitting else "standing"}: {len(v)} person-frames, median '
              f'{np.median(v):.3f} m, 90th percentile {np.percentile(v, 90):.3f} m')
