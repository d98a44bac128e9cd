"""h-rel2, offline on `detection_eval.py run` outputs (with OUT/probe.csv from release_probe.py
where a subcommand reads it). Run from the repository root:

    doorway_ends.py doorway OUT REC [OUT REC ...]   each release by the doorway timeout (events
        flagged "doorway"): premature / left / nobody (as `detection_eval.py exits` judges
        exit releases) and the larger door-wall camera coverage (cam2, cam3) of the track
        in its last 8 probe rows, "held" = rows with coverage >= 0.3
    doorway_ends.py exits OUT REC [OUT REC ...]     exit releases by class and whether the
        door-wall cameras covered the track (>= 0.3) at the release frame
    doorway_ends.py first OUT_A OUT_B               first frame where two runs of one recording
        differ (tracks.csv rows or births / ends), with the ends of both there
    doorway_ends.py creep OUT REC [OUT REC ...]     each premature exit release: frames since
        the track was born or moved, its y and its person's y over the 6 frames before
"""
from __future__ import annotations

import collections
import csv
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import detection_eval as de  # noqa: E402

WALL = ('coverage_cam2', 'coverage_cam3')      # the synth room's cameras on the door's wall


def _judged(out: Path, rec: Path):
    """Ends of OUT with their class (premature / left / nobody), person and probe rows."""
    tracks, truth, events, _ = de._load(out, rec)
    d, frames = de._matching(tracks, truth)
    present = {(r.frame, r.person_id) for r in truth}
    rows = collections.defaultdict(list)
    probe = out / 'probe.csv'
    if probe.exists():
        for r in csv.DictReader(probe.open()):
            rows[int(r['track_id'])].append(r)
    for e in events:
        if e['kind'] != 'end':
            continue
        kind, person = de.end_class(d, frames, present, e['id'], e['frame'])
        yield e, kind, person, rows[e['id']]


def _wall(row) -> float:
    c = [float(row[k]) for k in WALL if row[k] != 'nan']
    return max(c) if c else np.nan


def doorway(pairs) -> None:
    total = collections.Counter()
    for out, rec in pairs:
        for e, kind, _, rows in _judged(out, rec):
            if not e.get('doorway'):
                continue
            last = rows[-8:]
            w = [_wall(r) for r in last]
            held = sum(x >= 0.3 for x in w)
            total[(e['reason'], kind, 'held 8/8' if held == 8 else 'held 1-7/8' if held
                   else 'held 0/8')] += 1
            print(f"{out.name} t{e['id']}@{e['frame']} {e['reason']} {kind}: held {held}/8, "
                  f"spare {sum(r['spare'] == '1' for r in last)}/8, existence "
                  f"{float(last[-1]['existence']):.2f}, y {float(last[-1]['y']):.2f}, wall "
                  + ' '.join(f'{x:.2f}' for x in w))
    for k in sorted(total):
        print(k, total[k])


def exits(pairs) -> None:
    total = collections.Counter()
    for out, rec in pairs:
        for e, kind, _, rows in _judged(out, rec):
            if e['reason'] == 'exit' and rows:
                total[(kind, 'covered' if _wall(rows[-1]) >= 0.3 else 'not covered')] += 1
    for k in sorted(total):
        print(k, total[k])


def creep(pairs) -> None:
    for out, rec in pairs:
        tracks, truth, events, _ = de._load(out, rec)
        person = {(r.frame, r.person_id): r.y for r in truth}
        placed = collections.defaultdict(list)
        for e in events:
            if e['kind'] == 'birth':
                placed[e['id']].append(e['frame'])
            elif e['kind'] == 'decision' and e['action'].startswith('move'):
                placed[int(e['action'].split()[1])].append(e['frame'])
        ys = {(t.track_id, t.frame): t.y for t in tracks}
        for e, kind, p, _ in _judged(out, rec):
            if e['reason'] != 'exit' or kind != 'premature':
                continue
            f = e['frame']
            since = f - max([g for g in placed[e['id']] if g < f], default=0)
            print(f"{out.name} t{e['id']}@{f}: placed {since} frames before; track y "
                  + ' '.join(f"{ys.get((e['id'], g), np.nan):.2f}" for g in range(f - 6, f))
                  + '; person y '
                  + ' '.join(f"{person.get((g, p), np.nan):.2f}" for g in range(f - 6, f)))


def first(a: Path, b: Path) -> None:
    def load(out):
        tr, ev = collections.defaultdict(list), collections.defaultdict(list)
        for r in csv.DictReader((out / 'tracks.csv').open()):
            tr[int(r['frame'])].append((r['track_id'], r['x'], r['y'], r['existence']))
        for e in json.loads((out / 'events.json').read_text()):
            if e['kind'] in ('birth', 'end'):
                ev[e['frame']].append((e['kind'], e['id'], e.get('reason'),
                                       bool(e.get('doorway'))))
        return tr, ev
    (ta, ea), (tb, eb) = load(a), load(b)
    for f in range(max(list(ta) + list(tb) + [0]) + 1):
        if ta.get(f) != tb.get(f) or ea.get(f) != eb.get(f):
            print(f'first difference at frame {f}: {a.name} ends {ea.get(f, [])}, '
                  f'{b.name} ends {eb.get(f, [])}')
            return
    print('identical')


if __name__ == '__main__':
    cmd, args = sys.argv[1], [Path(p) for p in sys.argv[2:]]
    if cmd == 'first':
        first(*args)
    else:
        {'doorway': doorway, 'exits': exits, 'creep': creep}[cmd](list(zip(args[::2], args[1::2])))
