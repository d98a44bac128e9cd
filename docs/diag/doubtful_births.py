"""The reported tracks of doubtful existence beside births: for each birth (and each drop
beside a young look-alike, the other outcome `reuse_hidden` can change), the tracks
reported in that frame within ``reuse_radius`` of the detection whose existence (tracks.csv)
is below LEVEL, with their distance, existence and appearance distance (when the identity
check compared them), labelled by whether the detection's person was the one the track had
followed (``detection_eval.decision_label``); then counts by existence band and label
(docs/detection.md, "A track shown again moments ago").

usage: .venv/bin/python docs/diag/doubtful_births.py LEVEL OUT REC [OUT REC ...]
"""
import sys

import numpy as np
from _eval import context, detection_eval, pairs

from mbtrack_ros.core.detection.manager import AutoDetectionConfig

USAGE = 'doubtful_births.py LEVEL OUT REC [OUT REC ...]'
if len(sys.argv) < 2:
    sys.exit(f'usage: {USAGE}')
LEVEL = float(sys.argv.pop(1))
RADIUS = AutoDetectionConfig().reuse_radius
BAND = AutoDetectionConfig().reuse_doubtful     # counts split at the default level

counts: dict[tuple[str, str], int] = {}
for out, rec in pairs(USAGE):
    tracks, truth, events, _ = detection_eval._load(out, rec)     # loaded once
    events, detail, frames, people, _ = context(tracks, truth, events)
    shown: dict[int, list] = {}
    for t in tracks:
        shown.setdefault(t.frame, []).append(t)
    for e in events:
        action = e.get('action', '') if e['kind'] == 'decision' else ''
        if not (action == 'birth' or action.startswith('drop (young')) \
                or not people.get(e['frame']):
            continue
        f = e['frame']
        compared = {int(n[0]): n for n in e.get('near', [])}
        for t in shown.get(f, []):
            metres = float(np.hypot(t.x - e['xy'][0], t.y - e['xy'][1]))
            if metres > RADIUS or not t.existence < LEVEL:
                continue
            label = detection_eval.decision_label(detail, frames, people[f], e, t.track_id)
            band = f'< {BAND:g}' if t.existence < BAND else f'>= {BAND:g}'
            counts[band, label] = counts.get((band, label), 0) + 1
            unlike = compared[t.track_id][3] if t.track_id in compared else None
            print(f"{out.name} frame {f}: {action}, score {e['score']:.2f}; track "
                  f"{t.track_id} {metres:.2f} m, existence {t.existence:.3f}, appearance "
                  f"{'not compared' if unlike is None else f'{unlike:.3f}'}: {label}")
for (band, label), n in sorted(counts.items()):
    print(f'existence {band}: {label} {n}')
