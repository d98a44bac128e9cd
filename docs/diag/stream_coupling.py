"""How far a change at one place of the room reaches: two runs of the tracker, the second
with one extra track started at FRAME at (X, Y), far from everyone (it has no person and
is released about a second later).

Usage: stream_coupling.py REC SEED FRAME X Y [LAST]

Steps the tracker as ``detection_eval.py run`` does up to frame LAST (default: the whole
recording) and prints, every 100 frames after FRAME, how many of the tracks of both runs
(the extra one left out; ids after it shifted back by one) have the same ids and means
within 1 mm, how many differ, and the ids only one run has. With one random generator shared by all tracks, the extra
track's draws shifted every other track's; with one stream per track only the tracks the
extra one meets (through the likelihood, the exclusion prior or the detection) can move.
"""
import sys
from pathlib import Path

import numpy as np

from _eval import tracked_frames

rec, seed, frame = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
place = np.array([float(sys.argv[4]), float(sys.argv[5])])
last = int(sys.argv[6]) if len(sys.argv) > 6 else 10 ** 9


def means(extra: bool) -> tuple[dict[int, dict[int, np.ndarray]], int | None]:
    out: dict[int, dict[int, np.ndarray]] = {}
    added = None
    for fs, result, tracker in tracked_frames(rec, seed, last):
        if extra and fs.index == frame:
            model = next(iter(tracker.models.values()))
            added = tracker.add_track(model, np.r_[place, 0.0, 0.0, 0.0, 0.0], fs.stamp_ns)
        out[fs.index] = {t.track_id: t.mean[:2].copy() for t in result.tracks}
    return out, added


plain, _ = means(False)
other, added = means(True)
print(f'{rec.name} seed {seed}: extra track {added} at {place} from frame {frame}')
for f in sorted(plain):
    if f <= frame or (f - frame) % 100 and f != max(plain):
        continue
    a = plain[f]
    # the extra track took an id: the second run's later ids are one higher
    b = {k - (k > added): v for k, v in other.get(f, {}).items() if k != added}
    common = sorted(set(a) & set(b))
    same = sum(np.abs(a[k] - b[k]).max() < 1e-3 for k in common)
    only = sorted(set(a) ^ set(b))
    print(f'frame {f}: {same} same, {len(common) - same} moved, ids in one run only {only}')
