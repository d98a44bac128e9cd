"""Stretches of at least N frames in which a track's appearance fit stayed below T, each
labelled (at its N-th frame) by whom the track was matched to then: its own person (the
first it was matched to), another person, nobody, or not reported (hidden); a letter every
third frame of the stretch (O own, x other, . nobody, h hidden); then the quartiles of all
fits by label. Reads OUT/appearance.csv,
which ``detection_eval.py run`` writes on a tree with variant_lost_fit.patch applied.

usage: .venv/bin/python docs/diag/appearance_fit_runs.py T N OUT REC [OUT REC ...]
"""
import csv
import sys
from pathlib import Path

import numpy as np

from _eval import detection_eval

if len(sys.argv) < 5 or len(sys.argv) % 2 == 0:
    sys.exit(__doc__.strip().splitlines()[-1])
threshold, length = float(sys.argv[1]), int(sys.argv[2])
args = [Path(a) for a in sys.argv[3:]]
letter = {'own': 'O', 'other': 'x', 'none': '.', 'hidden': 'h'}
totals: dict[str, int] = {}
every: dict[str, list[float]] = {}
for out, rec in zip(args[::2], args[1::2]):
    tracks, truth, _, _ = detection_eval._load(out, rec)
    detail, frames = detection_eval._matching(tracks, truth)
    matched, first = {}, {}
    for f, t, p in sorted(zip(frames, detail.track_id, detail.person_id)):
        if t >= 0 and p >= 0:
            matched[(f, t)] = p
            first.setdefault(t, p)
    shown = {(t.frame, t.track_id): t for t in tracks}
    fits: dict[int, list[tuple[int, float]]] = {}
    with (out / 'appearance.csv').open(encoding='utf-8') as handle:
        for r in csv.DictReader(handle):
            fits.setdefault(int(r['track_id']), []).append((int(r['frame']), float(r['fit'])))

    def label(f: int, tid: int) -> str:
        p = matched.get((f, tid))
        return ('hidden' if (f, tid) not in shown else 'none' if p is None
                else 'own' if first.get(tid) == p else 'other')

    for tid, rows in fits.items():
        for f, v in rows:
            if np.isfinite(v):
                every.setdefault(label(f, tid), []).append(v)
        run: list[tuple[int, float]] = []
        for item in rows + [None]:
            if item is not None and item[1] < threshold and (not run
                                                             or item[0] - run[-1][0] <= 1):
                run.append(item)
                continue
            if len(run) >= length:
                labels = [label(f, tid) for f, _ in run]
                kind = labels[length - 1]
                totals[kind] = totals.get(kind, 0) + 1
                f = run[length - 1][0]
                t = shown.get((f, tid))
                where = f'({t.x:.2f}, {t.y:.2f})' if t else '(hidden)'
                print(f'{out.name} track {tid} frames {run[0][0]}-{run[-1][0]}, at {f} {where}: '
                      f'{kind} [{"".join(letter[k] for k in labels[::3])}]')
            run = [item] if item is not None and item[1] < threshold else []
print(f'fit < {threshold} for >= {length} frames: {totals}')
for kind, values in sorted(every.items()):
    q = np.percentile(values, [5, 25, 50, 75, 95])
    print(f'{kind}: {len(values)} track frames, fit 5/25/50/75/95 % '
          + ' / '.join(f'{v:.1f}' for v in q))
