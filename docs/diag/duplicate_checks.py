"""Each duplicate judgement of ``detection_eval.py run`` (``duplicate_check`` events) against
the ground truth: the person the pair stands on, how many of the 3 s before the merge
each track had followed that person (own) or somebody else, which one the run released;
then how often keeping the better-fitting track when its gain exceeds a margin would
keep the right one. Run it on outputs of ``--detection duplicate_margin=1e9`` (judged,
never overruled: the rule's own decisions). Last, the pairs by whom the two tracks stand on
now (the persons matched to each over the 4 frames to the judgement): two people or one,
with the exclusive support of the track to be released (``duplicate_own_support``; events
written before it have none).

usage: .venv/bin/python docs/diag/duplicate_checks.py OUT REC [OUT REC ...]
"""
import numpy as np

from _eval import detection_eval, pairs

rows = []
for out, rec in pairs('duplicate_checks.py OUT REC [OUT REC ...]'):
    tracks, truth, events, _ = detection_eval._load(out, rec)
    detail, frames = detection_eval._matching(tracks, truth)
    ends = {(e['frame'], e['id']) for e in events
            if e['kind'] == 'end' and e['reason'] == 'duplicate'}
    for e in (e for e in events if e['kind'] == 'duplicate_check'):
        f, (a, b) = e['frame'], e['ids']
        now = (frames >= f - 3) & (frames <= f) & np.isin(detail.track_id, [a, b])
        persons = list(detail.person_id[now])
        p = max(set(persons), key=persons.count) if persons else None
        history = {}
        for t in (a, b):
            before = (detail.track_id == t) & (frames >= f - 60) & (frames < f - 15)
            history[t] = (int(np.sum(detail.person_id[before] == p)) if p is not None else 0,
                          int(np.sum(detail.person_id[before] != p)))
        right = None     # the track that had followed this person clearly longer
        if p is not None and history[a][0] > history[b][0] + 5:
            right = a
        elif p is not None and history[b][0] > history[a][0] + 5:
            right = b
        released = [t for t in (a, b) if (f, t) in ends]
        on = []         # the person each track stands on now (None: matched to nobody)
        for t in (a, b):
            mine = list(detail.person_id[now & (detail.track_id == t)])
            on.append(max(set(mine), key=mine.count) if mine else None)
        rows.append({'run': out.name, 'frame': f, 'a': a, 'b': b, 'gain': e['gain'],
                     'person': p, 'history': history, 'released': released, 'right': right,
                     'two': None not in on and on[0] != on[1], 'support': e.get('support')})
for r in rows:
    print(f"{r['run']} frame {r['frame']}: tracks {r['a']}, {r['b']} gain {r['gain']:+.2f} "
          f"nats/camera, person {r['person']}, (own, other) frames before {r['history']}, "
          f"released {r['released']}, right to keep {r['right']}, "
          f"{'two people' if r['two'] else 'one person'} now")
known = [r for r in rows if r['right'] is not None and r['released']]
rule = sum(r['released'][0] != r['right'] for r in known)
print(f'{len(rows)} judgements, {len(known)} with a clear history; the rule kept the right '
      f'track {rule} times')
for margin in (0, 1, 3, 5, 8, 12):
    right = good = bad = 0
    for r in known:
        kept = r['b'] if r['released'][0] == r['a'] else r['a']
        keep = (r['a'] if r['gain'] > 0 else r['b']) if abs(r['gain']) > margin else kept
        right += keep == r['right']
        good += keep != kept and keep == r['right']
        bad += keep != kept and keep != r['right']
    print(f'margin {margin}: right {right} of {len(known)} (overruled: {good} right, {bad} wrong)')

first = {}      # each pair's first judgement of a run (a pair kept stays due, judged again)
for r in rows:
    first.setdefault((r['run'], r['a'], r['b']), r)
for two in (True, False):
    sel = [r for r in first.values() if r['two'] == two]
    gone = [r for r in rows if r['two'] == two and r['released']]
    print(f"{'two people' if two else 'one person'}: {len(sel)} pairs, {len(gone)} released")
    for r in sel:
        if r['support'] is not None:
            print(f"  {r['run']} frame {r['frame']}: tracks {r['a']}, {r['b']} exclusive "
                  f"support {r['support']}, released {r['released']}")
