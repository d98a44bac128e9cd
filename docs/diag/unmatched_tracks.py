"""The tracks reported longest while matched to nobody (eleventh session).

Usage: unmatched_tracks.py OUT REC [N]

Rows of OUT/tracks.csv that the CLEAR-MOT matching pairs with no ground-truth person
(false positives), grouped by track: the N tracks with the most such rows, with their
first and last unmatched frame and place.
"""
import sys
from pathlib import Path

from _eval import detection_eval as de

if len(sys.argv) not in (3, 4):
    sys.exit('usage: unmatched_tracks.py OUT REC [N]')
out, rec = Path(sys.argv[1]), Path(sys.argv[2])
tracks, truth, _, _ = de._load(out, rec)
d, frames = de._matching(tracks, truth)
matched = {(int(f), int(t)) for f, t in zip(frames, d.track_id) if t >= 0}
alone: dict[int, list] = {}
for r in tracks:
    if (r.frame, r.track_id) not in matched:
        alone.setdefault(r.track_id, []).append(r)
for tid, rows in sorted(alone.items(), key=lambda kv: -len(kv[1]))[:int(sys.argv[3]) if
                                                                   len(sys.argv) > 3 else 5]:
    a, b = rows[0], rows[-1]
    print(f'track {tid}: {len(rows)} unmatched rows, frames {a.frame}-{b.frame}, from '
          f'({a.x:.2f}, {a.y:.2f}) to ({b.x:.2f}, {b.y:.2f})')
