"""Per frame from FIRST to LAST, where a track is against a ground-truth person: the
person's place, and for the track (and any track born after FIRST within 1 m of her) its
mean place and velocity, its distance to her, the nearest person and its existence. Steps
the tracker as ``detection_eval.py run`` does (same seed).

usage: .venv/bin/python docs/diag/track_vs_person.py REC SEED TRACK PERSON FIRST LAST
"""
import sys
from pathlib import Path

import numpy as np

from _eval import places, tracked_frames

if len(sys.argv) != 7:
    sys.exit('usage: track_vs_person.py REC SEED TRACK PERSON FIRST LAST')
rec, seed, tid, pid, first, last = (Path(sys.argv[1]), *map(int, sys.argv[2:]))
people = places(rec)
known: set[int] = set()         # tracks alive at FIRST (other than TRACK): not shown
for fs, result, _ in tracked_frames(rec, seed, last):
    here = people.get(fs.index, {})
    if fs.index < first:
        continue
    if fs.index == first:
        known = {t.track_id for t in result.tracks if t.track_id != tid}
    me = here.get(pid)
    cells = []
    for t in result.tracks:
        m = t.mean
        off = float(np.hypot(*(m[:2] - me))) if me is not None else float('nan')
        if t.track_id != tid and (t.track_id in known or not off < 1.0):
            continue
        d = {k: float(np.hypot(*(m[:2] - v))) for k, v in here.items()}
        k = min(d, key=d.get) if d else None
        cells.append(f'track {t.track_id} ({m[0]:.2f}, {m[1]:.2f}) v ({m[2]:+.2f}, '
                     f'{m[3]:+.2f}) {off:.2f} m off, nearest person {k} '
                     f'{d.get(k, float("nan")):.2f} m, existence {t.existence:.2f}')
    where = f'({me[0]:.2f}, {me[1]:.2f})' if me is not None else 'gone'
    print(f'{fs.index} person {pid} {where} | ' + ' | '.join(cells), flush=True)
