"""Detection scores of the births of `detection_eval.py run` outputs, against the ground truth.

Usage: birth_scores.py [--threshold T] OUT REC [OUT REC ...]

Each birth decision (`events.json`) is labelled by the ground truth of its frame:
*new* (a person within 0.5 m whom no track of the frame before was within 0.5 m of),
*tracked* (that person already had a track within 0.5 m) or *nobody* (no person within
0.5 m). Printed: the score quartiles per label, how many of each had a track within the
identity check's radius (the decision's ``near`` list, 1 m) and scored below T, for a few T;
then the identity switches (`switch_classes`) whose new track came from such a weak birth
beside a track, per switch class (section "Weak births beside a track", seventeenth
session, of docs/detection.md).
"""
import sys
from collections import Counter, defaultdict

import numpy as np

from _eval import detection_eval as de
from _eval import pairs as run_pairs

THRESHOLDS = (2.0, 2.5, 3.0, 3.5, 4.0)


def births(out, rec):
    """(frame, new id, score, distance of the nearest track in ``near``, label) of each
    birth decision of one run."""
    tracks, truth, events, _ = de._load(out, rec)
    shown = defaultdict(list)
    for t in tracks:
        shown[t.frame].append((t.x, t.y))
    people = defaultdict(list)
    for r in truth:
        people[r.frame].append((r.x, r.y))
    # the i-th birth decision of a frame made the i-th new id of that frame (ids grow;
    # a reused id is not new and comes from a 'reuse' decision)
    new_ids, seen = defaultdict(list), set()
    for e in events:
        if e['kind'] == 'birth' and e['id'] not in seen:
            seen.add(e['id'])
            new_ids[e['frame']].append(e['id'])
    found = []
    for e in events:
        if e['kind'] != 'decision' or e.get('action') != 'birth':
            continue
        f, xy = e['frame'], np.asarray(e['xy'])
        born = new_ids[f].pop(0) if new_ids[f] else None
        near = min((n[1] for n in e.get('near', [])), default=np.inf)
        here = np.asarray(people.get(f, []), float).reshape(-1, 2)
        label = 'nobody'
        if len(here):
            d = np.hypot(*(here - xy).T)
            if d.min() <= 0.5:
                person = here[d.argmin()]
                prev = np.asarray(shown.get(f - 1, []), float).reshape(-1, 2)
                taken = len(prev) and np.hypot(*(prev - person).T).min() < 0.5
                label = 'tracked' if taken else 'new'
        found.append((f, born, float(e['score']), float(near), label))
    return found


def main() -> None:
    args = sys.argv[1:]
    threshold = 3.0
    if args[:1] == ['--threshold']:
        threshold, args = float(args[1]), args[2:]
    sys.argv = [sys.argv[0]] + args
    pairs = run_pairs(__doc__.splitlines()[2].removeprefix('Usage: '))
    rows = {out: births(out, rec) for out, rec in pairs}
    every = [r for rs in rows.values() for r in rs]
    print(f'{len(every)} births on {len(pairs)} runs')
    for label in ('new', 'tracked', 'nobody'):
        sel = [r for r in every if r[4] == label]
        if not sel:
            continue
        s = np.array([r[2] for r in sel])
        beside = sum(r[3] < np.inf for r in sel)
        print(f'{label}: {len(sel)}, score quartiles '
              f'{" / ".join(f"{q:.2f}" for q in np.percentile(s, [25, 50, 75]))}, '
              f'{beside} with a track within 1 m; below T beside a track: '
              + ', '.join(f'T {t}: {sum(r[2] < t and r[3] < np.inf for r in sel)}'
                          for t in THRESHOLDS))
    switches = Counter()
    total = 0
    for out, rec in pairs:
        weak = {r[1] for r in rows[out] if r[2] < threshold and r[3] < np.inf}
        for s in de.switch_classes(out, rec):
            total += 1
            switches[(s['new'] in weak, s['kind'].split(' (')[0])] += 1
    print(f'{total} identity switches; of them with the new track born from a detection '
          f'scoring below {threshold} beside a track: '
          f'{sum(v for (w, _), v in switches.items() if w)}')
    for (w, kind), v in sorted(switches.items()):
        if w:
            print(f'  {kind}: {v}')


if __name__ == '__main__':
    main()
