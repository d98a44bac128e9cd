"""Identity switches near a track left in a floor box matched to nobody (twenty-second
session).

Usage: stale_box.py X0 Y0 X1 Y1 OUT REC [OUT REC ...]

For each identity switch of the runs (``detection_eval.switch_classes``) the tracks that
were reported inside the box [X0, X1] x [Y0, Y1] (metres) while matched to no
ground-truth person on at least 8 of the 75 frames (5 s) before it; then how many
switches had one. docs/detection.md ("Catching up", "Where stale tracks stay") runs it on
the floor's corner east of the clear-room door: 5.1 4.2 5.7 4.75.
"""
import sys

from _eval import detection_eval as de
from _eval import pairs

WINDOW, MIN_FRAMES = 75, 8
usage = 'stale_box.py X0 Y0 X1 Y1 OUT REC [OUT REC ...]'
try:
    x0, y0, x1, y1 = (float(v) for v in sys.argv[1:5])
except ValueError:
    sys.exit(f'usage: {usage}')
del sys.argv[1:5]
total = near = 0
for out, rec in pairs(usage):
    tracks, truth, _, _ = de._load(out, rec)
    d, frames = de._matching(tracks, truth)
    matched = {(int(f), int(t)) for f, t in zip(frames, d.track_id) if t >= 0}
    stale: dict[int, list[int]] = {}     # track id -> frames reported in the box, unmatched
    for t in tracks:
        if x0 <= t.x <= x1 and y0 <= t.y <= y1 and (t.frame, t.track_id) not in matched:
            stale.setdefault(t.track_id, []).append(t.frame)
    for s in de.switch_classes(out, rec):
        total += 1
        f = s['frame']
        who = [tid for tid, fs in stale.items()
               if sum(f - WINDOW <= g <= f for g in fs) >= MIN_FRAMES]
        if who:
            near += 1
            print(f"{out.name} person {s['person']} f{f}: {s['old']} -> {s['new']} "
                  f"{s['kind']}; stale in the box: {', '.join(map(str, who))}")
print(f'{near} of {total} switches with a track >= {MIN_FRAMES} frames unmatched in the '
      f'box in the {WINDOW / de.FPS:.0f} s before')
