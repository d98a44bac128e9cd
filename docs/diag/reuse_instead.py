"""The decisions where ``reuse_before_moving`` gave a lost track's id to a detection instead
of moving another track ("reuse N (not M)" in events.json), each labelled: the person of
the detection (nearest ground-truth row), the person the lost track N had followed
before its release, whether M was born or moved within ``relocate_interval`` before
(docs/detection.md, "No reuse instead of a move that would not happen").

usage: .venv/bin/python docs/diag/reuse_instead.py OUT REC [OUT REC ...]
"""
import re

from _eval import detection_eval, pairs, run_context
from mbtrack_ros.core.detection.manager import AutoDetectionConfig

FPS = detection_eval.FPS
WITHIN = AutoDetectionConfig().relocate_interval * FPS     # frames
counts: dict[tuple[bool, bool], int] = {}
for out, rec in pairs('reuse_instead.py OUT REC [OUT REC ...]'):
    events, detail, frames, people, placed = run_context(out, rec)
    for e in events:
        m = re.fullmatch(r'reuse (\d+) \(not (\d+)\)', e.get('action', '')) \
            if e['kind'] == 'decision' else None
        if m is None:
            continue
        lost, spared, f = int(m[1]), int(m[2]), e['frame']
        recent = any(f - WITHIN < g < f for g in placed.get(spared, []))
        here = people.get(f, [])
        at = detection_eval.nearest_row(here, e['xy']).person_id if here else None
        had = detection_eval._followed(detail, frames, lost, f)   # released < 3 s before
        right = had is not None and had == at
        counts[recent, right] = counts.get((recent, right), 0) + 1
        print(f"{out.name} frame {f}: {e['action']}, track {spared} "
              f"{'placed recently' if recent else 'old'}; detection on person {at}, lost "
              f"track {lost} had followed {had}: {'right' if right else 'wrong'}")
for (recent, right), n in sorted(counts.items()):
    print(f"{'placed recently' if recent else 'old'}, {'right' if right else 'wrong'}: {n}")
