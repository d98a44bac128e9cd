"""A window of one run near the door: per frame from FIRST to LAST (every STEP), the
ground-truth people and the reported tracks with x > X0 and y > Y0 (a track's existence
when below 0.99), then the run's events in the window other than appearance adaptation.
With OUT/probe.csv (``release_probe.py``), each track's release view in those frames too:
supported (+) or not (-), spare (s) and its exclusive support, hidden tracks included.

usage: .venv/bin/python docs/diag/door_window.py OUT REC FIRST LAST X0 Y0 [STEP]
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import detection_eval  # noqa: E402
from _eval import context  # noqa: E402

if len(sys.argv) not in (7, 8):
    sys.exit('usage: door_window.py OUT REC FIRST LAST X0 Y0 [STEP]')
out, rec = Path(sys.argv[1]), Path(sys.argv[2])
first, last = int(sys.argv[3]), int(sys.argv[4])
x0, y0 = float(sys.argv[5]), float(sys.argv[6])
step = int(sys.argv[7]) if len(sys.argv) == 8 else 1
tracks, truth, events, _ = detection_eval._load(out, rec)
people = context(tracks, truth, events)[3]            # ground-truth rows by frame
shown: dict[int, list] = {}
for t in tracks:
    shown.setdefault(t.frame, []).append(t)
for f in range(first, last + 1, step):
    here = sorted((r for r in people.get(f, []) if r.x > x0 and r.y > y0),
                  key=lambda r: r.person_id)
    mine = sorted((t for t in shown.get(f, []) if t.x > x0 and t.y > y0),
                  key=lambda t: t.track_id)
    print(f, ' '.join(f'P{r.person_id}({r.x:.2f},{r.y:.2f})' for r in here), '|',
          ' '.join(f'T{t.track_id}({t.x:.2f},{t.y:.2f}'
                   + ('' if t.existence >= 0.99 else f' e{t.existence:.2f}') + ')'
                   for t in mine))
for e in events:
    if first <= e.get('frame', -1) <= last and e['kind'] != 'adapt':
        print(e)
if (out / 'probe.csv').exists():
    probe = np.genfromtxt(out / 'probe.csv', delimiter=',', names=True)
    s0 = min(r.stamp_ns for r in truth)
    frame = np.round((probe['stamp_ns'] - s0) / (1e9 / detection_eval.FPS)).astype(int)
    inside = (frame >= first) & (frame <= last) & (probe['x'] > x0) & (probe['y'] > y0)
    for tid in sorted(set(probe['track_id'][inside].astype(int))):
        rows = np.flatnonzero(inside & (probe['track_id'] == tid))
        marks = ' '.join(f"{frame[k]}{'+' if probe['supported'][k] else '-'}"
                         f"{'s' if probe['spare'][k] else ''}{probe['exclusive'][k]:.2f}"
                         for k in rows)
        spare = int(np.sum(probe['spare'][rows]))
        print(f'track {tid}: spare on {spare} of {len(rows)} probe rows; {marks}')
