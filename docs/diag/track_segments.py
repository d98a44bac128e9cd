"""Which person each named track was matched to (CLEAR MOT), frame span by frame span, and
its birth and end events: how a track moved from person to person.

usage: .venv/bin/python docs/diag/track_segments.py OUT REC TRACK [TRACK ...]
(OUT: a ``detection_eval.py run`` output, REC: its recording)
"""
import sys
from pathlib import Path

from _eval import detection_eval

if len(sys.argv) < 4:
    sys.exit(__doc__.strip().splitlines()[-2])
out, rec = Path(sys.argv[1]), Path(sys.argv[2])
tracks, truth, events, _ = detection_eval._load(out, rec)
detail, frames = detection_eval._matching(tracks, truth)
for tid in map(int, sys.argv[3:]):
    sel = detail.track_id == tid
    spans: list[list[int]] = []      # [first frame, last frame, person]
    for f, p in sorted(zip(frames[sel], detail.person_id[sel])):
        if spans and spans[-1][2] == p and f - spans[-1][1] <= 2:
            spans[-1][1] = f
        else:
            spans.append([int(f), int(f), int(p)])
    shown = sorted(t.frame for t in tracks if t.track_id == tid)
    print(f'track {tid}: reported {shown[0] if shown else "-"}-{shown[-1] if shown else "-"}; '
          + ', '.join(f'{a}-{b}: person {p}' for a, b, p in spans))
    for e in events:
        if e.get('id') == tid and e['kind'] in ('birth', 'end'):
            print(f"    {e['kind']} at {e['frame']}" + (f" ({e['reason']})" if 'reason' in e else ''))
