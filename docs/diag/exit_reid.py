"""Exit releases against the ground truth, and what a re-activation would have done
(h-reid, docs/detection.md "Exit releases at the door").

    .venv/bin/python docs/diag/exit_reid.py detail OUT REC [OUT REC ...]
    .venv/bin/python docs/diag/exit_reid.py replay GRACE_S RADIUS_M OUT REC [OUT REC ...]
    .venv/bin/python docs/diag/exit_reid.py rescues OUT REC [OUT REC ...]

``detail``: per exit release (``detection_eval.py exits``' classes premature / left /
nobody) the track's last reported places, its person's ground-truth place and motion,
the other people and reported tracks within 1 m, the track's age, and the births in the
second after it (where, how far, whose person).
``replay``: offline, on existing outputs, the rule "a birth within GRACE_S seconds of an
exit release and within RADIUS_M of the released track's last reported place inside the
room takes the released id": per exit release class, how many births would take the id
and whether the born track's person is the released track's person (same) or not.
``rescues``: each decision of the exit rescue (events ``exit_check`` of a run with
``AutoDetectionConfig.exit_rescue``) with the class of its track's person as ``exits``
gives it (premature: still in the room, left, nobody) and, for a rescue, the person the
track was matched to in the 15 frames after it (same / other / nobody), its door-wall
coverage and where it was put against that person.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from detection_eval import FPS, FLOOR, _load, _matching, end_class  # noqa: E402


def _person_of(d, frames, track_id: int, first: int, last: int) -> int:
    """The person a track was matched to most in frames [first, last] (-1: none)."""
    sel = (d.track_id == track_id) & (frames >= first) & (frames <= last) & (d.person_id >= 0)
    return int(np.bincount(d.person_id[sel]).argmax()) if sel.any() else -1


def _exits(out: Path, rec: Path):
    tracks, truth, events, _ = _load(out, rec)
    d, frames = _matching(tracks, truth)
    present = {(r.frame, r.person_id) for r in truth}
    where = {(r.frame, r.person_id): (r.x, r.y) for r in truth}
    gt: dict[int, list] = {}
    for r in truth:
        gt.setdefault(r.frame, []).append(r)
    rows: dict[int, list] = {}
    for t in tracks:
        rows.setdefault(t.track_id, []).append(t)
    at: dict[int, list] = {}
    for t in tracks:
        at.setdefault(t.frame, []).append(t)
    born: dict[int, list[int]] = {}
    for e in events:
        if e['kind'] == 'birth':
            born.setdefault(e['id'], []).append(e['frame'])
    births = sorted((f, tid) for tid, fs in born.items() for f in fs)
    for e in events:
        if e['kind'] != 'end' or e['reason'] != 'exit':
            continue
        f, tid = e['frame'], e['id']
        kind, p = end_class(d, frames, present, tid, f)
        mine = [t for t in rows.get(tid, []) if t.frame <= f]
        inside = [t for t in mine if t.y <= FLOOR[3]]
        last_in = inside[-1] if inside else (mine[-1] if mine else None)
        start = max([g for g in born.get(tid, []) if g <= f], default=0)
        yield {'out': out, 'frame': f, 'id': tid, 'kind': kind, 'person': p,
               'track': mine[-8:], 'last_in': last_in, 'age': (f - start) / FPS,
               'where': where, 'gt': gt, 'at': at, 'births': births, 'd': d,
               'frames': frames, 'rows': rows}


def detail(pairs) -> None:
    stats: dict[str, list] = {}
    for out, rec in pairs:
        for x in _exits(out, rec):
            f, p = x['frame'], x['person']
            a, b = x['where'].get((f - 6, p)), x['where'].get((f, p))
            last = x['track'][-1] if x['track'] else None
            if a is not None and b is not None and last is not None:
                # the nearest other reported track to the person in the frame before, and
                # whether the released estimate lies beyond it as seen from it, outwards
                # (the clear-room door is on the floor's y_max edge: outwards is +y)
                near = [(np.hypot(t.x - b[0], t.y - b[1]), t) for t in x['at'].get(f - 1, [])
                        if t.track_id != x['id']]
                gap, other = min(near, key=lambda n: n[0]) if near else (np.inf, None)
                push = np.nan
                if other is not None and gap < 0.8:
                    v = np.array([last.x - other.x, last.y - other.y])
                    push = v[1] / max(np.linalg.norm(v), 1e-9)
                stats.setdefault(x['kind'], []).append(
                    (x['age'], (b[1] - a[1]) * FPS / 6, np.hypot(last.x - b[0], last.y - b[1]),
                     last.x - b[0], b[1], gap, push))
            print(f"{out.name} track {x['id']} exit@{f} {x['kind']} person {p}, "
                  f"track age {x['age']:.1f} s")
            print('  track y: ' + ' '.join(f'{t.frame}:({t.x:.2f},{t.y:.2f})'
                                           for t in x['track']))
            if p >= 0:
                pos = [(g, x['where'][(g, p)]) for g in range(f - 6, f + 8)
                       if (g, p) in x['where']]
                print('  person: ' + ' '.join(f'{g}:({a:.2f},{b:.2f})' for g, (a, b) in pos))
                me = x['where'].get((f, p))
                if me is not None:
                    others = [(r.person_id, np.hypot(r.x - me[0], r.y - me[1]), r.x, r.y)
                              for r in x['gt'].get(f, []) if r.person_id != p]
                    near = [o for o in others if o[1] < 1.0]
                    print('  others within 1 m: ' + ', '.join(
                        f'p{o[0]} {o[1]:.2f} m ({o[2]:.2f},{o[3]:.2f})' for o in near))
                    tr = [(t.track_id, np.hypot(t.x - me[0], t.y - me[1]), t.x, t.y)
                          for t in x['at'].get(f - 1, []) if t.track_id != x['id']]
                    print('  tracks within 1 m at f-1: ' + ', '.join(
                        f'{t[0]} {t[1]:.2f} m ({t[2]:.2f},{t[3]:.2f})' for t in tr if t[1] < 1))
            for g, tid in x['births']:
                if f <= g <= f + int(FPS):
                    r0 = x['rows'].get(tid)
                    r0 = next((t for t in r0 if t.frame >= g), None) if r0 else None
                    q = _person_of(x['d'], x['frames'], tid, g, g + 15)
                    li = x['last_in']
                    dist = np.hypot(r0.x - li.x, r0.y - li.y) if (r0 and li) else np.nan
                    print(f'  birth {tid}@{g}: person {q}, '
                          + (f'at ({r0.x:.2f},{r0.y:.2f}), {dist:.2f} m from the last '
                             f'place in the room' if r0 else 'never reported'))


    for kind, v in sorted(stats.items()):
        v = np.array(v)
        q = lambda c: ' / '.join(f'{t:.2f}' for t in np.percentile(v[:, c], [25, 50, 75]))  # noqa: E731
        print(f'{kind} ({len(v)}), quartiles: track age {q(0)} s; person moving {q(1)} m/s in y '
              f'(< 0: into the room); last reported estimate {q(2)} m from the person, '
              f'x offset {q(3)} m; person y {q(4)} m; moving out (> 0.1 m/s) '
              f'{int(np.sum(v[:, 1] > 0.1))}, into the room (< -0.1 m/s) '
              f'{int(np.sum(v[:, 1] < -0.1))}; another track within 0.8 m of the person '
              f'{int(np.sum(v[:, 5] < 0.8))}, with the released estimate beyond it outwards '
              f'(cosine with +y > 0.7) {int(np.sum(v[:, 6] > 0.7))}')


def replay(grace: float, radius: float, pairs) -> None:
    counts: dict[tuple[str, str], int] = {}
    for out, rec in pairs:
        for x in _exits(out, rec):
            f, li = x['frame'], x['last_in']
            got = 'none'
            if li is not None:
                for g, tid in x['births']:
                    if not f <= g <= f + grace * FPS:
                        continue
                    r0 = next((t for t in x['rows'].get(tid, []) if t.frame >= g), None)
                    if r0 is None or np.hypot(r0.x - li.x, r0.y - li.y) > radius:
                        continue
                    q = _person_of(x['d'], x['frames'], tid, g, g + 15)
                    got = 'same' if q == x['person'] and q >= 0 else \
                        'nobody' if q < 0 else 'other'
                    print(f"{out.name} track {x['id']} exit@{f} {x['kind']} -> birth "
                          f"{tid}@{g} ({got})")
                    break
            counts[(x['kind'], got)] = counts.get((x['kind'], got), 0) + 1
    for k in sorted(counts):
        print(f'{k[0]:10s} birth taken: {k[1]:7s} {counts[k]}')


def rescues(pairs) -> None:
    counts: dict[tuple[str, str], int] = {}
    for out, rec in pairs:
        tracks, truth, events, _ = _load(out, rec)
        d, frames = _matching(tracks, truth)
        present = {(r.frame, r.person_id) for r in truth}
        where = {(r.frame, r.person_id): (r.x, r.y) for r in truth}
        for e in events:
            if e['kind'] != 'exit_check':
                continue
            f, tid = e['frame'], e['id']
            kind, p = end_class(d, frames, present, tid, f)
            after = 'released'
            off = np.nan
            if e['rescued']:
                q = _person_of(d, frames, tid, f + 1, f + 15)
                after = 'nobody' if q < 0 else 'same' if q == p else 'other'
                if p >= 0 and (f, p) in where:
                    off = float(np.hypot(*(np.array(e['place']) - where[(f, p)])))
            counts[(kind, after)] = counts.get((kind, after), 0) + 1
            print(f"{out.name} track {tid} exit@{f} {kind} (person {p}): door-wall coverage "
                  f"{e['coverage']:.2f}, {'rescued -> ' + after if e['rescued'] else 'released'}"
                  + (f', put {off:.2f} m from the person' if np.isfinite(off) else ''))
    for k in sorted(counts):
        print(f'{k[0]:10s} {k[1]:9s} {counts[k]}')


def main(argv: list[str]) -> None:
    if argv[0] == 'rescues':
        rest = argv[1:]
        rescues([(Path(rest[i]), Path(rest[i + 1])) for i in range(0, len(rest), 2)])
    elif argv[0] == 'detail':
        rest = argv[1:]
        detail([(Path(rest[i]), Path(rest[i + 1])) for i in range(0, len(rest), 2)])
    else:
        grace, radius, rest = float(argv[1]), float(argv[2]), argv[3:]
        replay(grace, radius, [(Path(rest[i]), Path(rest[i + 1]))
                               for i in range(0, len(rest), 2)])


if __name__ == '__main__':
    main(sys.argv[1:])
