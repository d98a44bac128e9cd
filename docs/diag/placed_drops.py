"""The detections dropped because the track their gain would move was born or moved within
``relocate_interval`` ("drop (track N placed recently)"), and the moves ``move_again_gain``
makes of such a track instead ("move N (again)"): for each, the track's gain (nats per
side camera), appearance distance and distance to the detection, how long before it was
placed, and whether the detection's person was the one the track had followed
(``detection_eval.decision_label``); then counts by label and gain band
(docs/detection.md, "A track placed moments ago moved again").

usage: .venv/bin/python docs/diag/placed_drops.py OUT REC [OUT REC ...]
"""
from _eval import detection_eval, pairs, run_context

FPS = detection_eval.FPS
BANDS = (0.0, 2.5, 4.0)             # gain band edges, nats: the thresholds measured

counts: dict[tuple[str, str, str], int] = {}
for out, rec in pairs('placed_drops.py OUT REC [OUT REC ...]'):
    events, detail, frames, people, placed = run_context(out, rec)
    for e in events:
        action = e.get('action', '') if e['kind'] == 'decision' else ''
        again = action.endswith('(again)')
        if not (again or action.endswith('placed recently)')) or not people.get(e['frame']):
            continue
        f = e['frame']
        tid = detection_eval.decision_track(e)
        _, dist, gain, unlike = next(n for n in e['near'] if n[0] == tid)
        before = [f - g for g in placed.get(tid, []) if g < f]
        label = detection_eval.decision_label(detail, frames, people[f], e, tid)
        band = next((f'<= {b:g}' for b in BANDS if gain <= b), f'> {BANDS[-1]:g}')
        kind = 'moved again' if again else 'dropped'
        counts[kind, band, label] = counts.get((kind, band, label), 0) + 1
        print(f"{out.name} frame {f}: {action}, gain {gain:+.2f}, appearance {unlike:.3f}, "
              f"{dist:.2f} m, placed {min(before) / FPS:.2f} s before, score "
              f"{e['score']:.2f}: {label}")
for (kind, band, label), n in sorted(counts.items()):
    print(f'{kind}, gain {band}: {label} {n}')
