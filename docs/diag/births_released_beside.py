"""The births beside a track that the releaser ends as spare or duplicate within SECONDS
after: for each, that track's row of the identity check (id, metres, gain, appearance
distance), its end, and whether the detection's person was the one it had followed
(``detection_eval.decision_label``); then counts by label (docs/detection.md, "A track
shown again moments ago": whether handing the released id to the new track would help).

usage: .venv/bin/python docs/diag/births_released_beside.py SECONDS OUT REC [OUT REC ...]
"""
import sys

from _eval import detection_eval, pairs, run_context

USAGE = 'births_released_beside.py SECONDS OUT REC [OUT REC ...]'
if len(sys.argv) < 2:
    sys.exit(f'usage: {USAGE}')
WINDOW = float(sys.argv.pop(1)) * detection_eval.FPS     # frames

counts: dict[str, int] = {}
for out, rec in pairs(USAGE):
    events, detail, frames, people, _ = run_context(out, rec)
    ends: dict[int, list] = {}          # an id reused after its release ends again
    for e in events:
        if e['kind'] == 'end':
            ends.setdefault(e['id'], []).append(e)
    for e in events:
        if e['kind'] != 'decision' or e['action'] != 'birth' or not people.get(e['frame']):
            continue
        f = e['frame']
        for row in e.get('near', []):
            end = next((x for x in ends.get(int(row[0]), []) if x['frame'] >= f), None)
            if end is None or end['reason'] not in ('spare', 'duplicate') \
                    or not f <= end['frame'] <= f + WINDOW:
                continue
            label = detection_eval.decision_label(detail, frames, people[f], e, int(row[0]))
            counts[label] = counts.get(label, 0) + 1
            print(f"{out.name} frame {f}: birth beside track {row[0]} ({row[1]:.2f} m, gain "
                  f"{row[2]:+.2f}, appearance {row[3]:.3f}), ended {end['reason']} at frame "
                  f"{end['frame']}: {label}")
print(', '.join(f'{label} {n}' for label, n in sorted(counts.items())))
