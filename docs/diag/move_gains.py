"""The identity check's moves by the appearance gain (not of hidden tracks, not by
``beside_support``) on ``detection_eval.py run`` outputs, each labelled by whether the
detection's person was the one the moved track had followed (``same``) or another
(``other``); then counts by detection score (below / at least ``--score``) and by gain
band (``--gains`` edges), the table of docs/detection.md "Weak moves by their gain";
with ``--support S``, also by the moved track's exclusive support left beside the
detection (below / at least S; recorded in the decisions since ``move_support``: run with
``--detection move_support=2`` to have every move), the table of "Moves of tracks on a
person of their own", and every track the gain would have moved that kept at least S
(the tracks ``move_support`` S keeps back, on runs with that setting), labelled the same way,
with the frames since that track was born or last moved (under ``relocate_interval``, 30
frames at 15 fps, the detection would have been dropped had the check not taken it out).

    .venv/bin/python docs/diag/move_gains.py [--list] [--score 3.0] [--gains 1 1.5 2 3] \
        [--support 0.3] OUT REC [OUT REC ...]
"""
import argparse
import collections
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _eval import detection_eval  # noqa: E402


def moves(out: Path, rec: Path, support: float = np.inf) -> tuple[list[dict], list[dict]]:
    """Each move by the gain of one run (frame, score, gain, distance, support, label as
    ``detection_eval.py decisions`` labels it), and each track the gain would move whose
    recorded support was at least ``support`` (frame, track, support, action, label)."""
    tracks, truth, events, _ = detection_eval._load(out, rec)
    d, frames = detection_eval._matching(tracks, truth)
    gt: dict[int, list] = {}
    for r in truth:
        gt.setdefault(r.frame, []).append(r)
    found, kept = [], []
    placed: dict[int, int] = {}     # track id -> frame of its birth or last move
    for e in events:
        if e['kind'] == 'decision' and gt.get(e['frame']):
            kept += [{'run': out.name, 'frame': e['frame'], 'track': int(t), 'support': v,
                      'action': e['action'],
                      'since': e['frame'] - placed[int(t)] if int(t) in placed else None,
                      'label': detection_eval.decision_label(d, frames, gt[e['frame']], e,
                                                             int(t))}
                     for t, v in e.get('support', []) if v >= support]
        action = e['action'] if e['kind'] == 'decision' else ''
        if e['kind'] == 'birth' or action.startswith('move'):   # hidden and beside too
            placed[int(e['id'] if e['kind'] == 'birth' else action.split()[1])] = e['frame']
        if not action.startswith('move') or '(' in action or not gt.get(e['frame']):
            continue
        tid = int(action.split()[1])
        dist, gain = next(n for n in e['near'] if n[0] == tid)[1:3]
        found.append({'run': out.name, 'frame': e['frame'], 'score': e['score'],
                      'gain': gain, 'distance': dist,
                      'support': dict(e.get('support', [])).get(tid, np.nan),
                      'label': detection_eval.decision_label(d, frames, gt[e['frame']], e,
                                                             tid)})
    return found, kept


def _cell(rows: list[dict]) -> str:
    """'same / other' counts of labelled rows (and the unmatched ones, if any)."""
    c = collections.Counter(r['label'] for r in rows)
    return f"{c['same']} / {c['other']}" + (f" (+{c['unmatched']} unmatched)"
                                            if c['unmatched'] else '')


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--score', type=float, default=3.0)
    p.add_argument('--gains', type=float, nargs='+', default=[1.0, 1.5, 2.0, 3.0])
    p.add_argument('--support', type=float, default=None,
                   help='also count the moves by the exclusive support left to the track')
    p.add_argument('--list', action='store_true', help='print every move')
    p.add_argument('pairs', nargs='+', type=Path)
    args = p.parse_args()
    if len(args.pairs) % 2:
        p.error('give OUT REC pairs')
    rows, kept = [], []
    limit = np.inf if args.support is None else args.support
    for out, rec in zip(args.pairs[::2], args.pairs[1::2]):
        found, high = moves(out, rec, limit)
        rows += found
        kept += high
    if args.list:
        for r in sorted(rows, key=lambda r: (r['score'], r['gain'])):
            print(f"{r['run']:<10} frame {r['frame']:5d} score {r['score']:5.2f} "
                  f"gain {r['gain']:6.2f} distance {r['distance']:.2f} "
                  f"support {r['support']:.3f} {r['label']}")
    edges = [-np.inf] + sorted(args.gains) + [np.inf]
    print(f'| gain | score < {args.score:g}: same / other | score >= {args.score:g}: '
          'same / other |')
    print('| --- | --- | --- |')
    weak = [r for r in rows if r['score'] < args.score]
    strong = [r for r in rows if r['score'] >= args.score]
    for lo, hi in zip(edges[:-1], edges[1:]):
        cells = [_cell([r for r in side if lo <= r['gain'] < hi]) for side in (weak, strong)]
        print(f'| [{lo:g}, {hi:g}) | {cells[0]} | {cells[1]} |')
    if args.support is not None:
        print(f'| support left | score < {args.score:g}: same / other | '
              f'score >= {args.score:g}: same / other |')
        print('| --- | --- | --- |')
        for name, test in ((f'< {args.support:g}', lambda v: v < args.support),
                           (f'>= {args.support:g}', lambda v: v >= args.support),
                           ('not recorded', lambda v: not np.isfinite(v))):
            cells = [_cell([r for r in side if test(r['support'])]) for side in (weak, strong)]
            print(f'| {name} | {cells[0]} | {cells[1]} |')
        for r in kept:
            print(f"{r['run']:<10} frame {r['frame']:5d} track {r['track']} support "
                  f"{r['support']:.3f} ({r['action']}), placed "
                  + (f"{r['since']} frames before" if r['since'] is not None else 'never')
                  + f": {r['label']}")
        c = collections.Counter(r['label'] for r in kept)
        print(f'tracks the gain would move with support >= {args.support:g}: '
              f"{c['same']} same / {c['other']} other / {c['unmatched']} unmatched")
    print(f'{len(rows)} moves')


if __name__ == '__main__':
    main()
