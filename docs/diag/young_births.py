"""The births (and drops, "drop (young look-alike N)") of a detection within
``relocate_radius`` of a track born or moved within ``relocate_interval``: for each such
track, its appearance distance to the detection, the person it followed over the next two
seconds against the detection's person (nearest ground-truth row), and whom the track born
there followed (docs/detection.md, "No birth beside a young look-alike").

usage: .venv/bin/python docs/diag/young_births.py OUT REC [OUT REC ...]
"""
import numpy as np

from _eval import detection_eval, pairs, run_context
from mbtrack_ros.core.detection.manager import AutoDetectionConfig

FPS = detection_eval.FPS
CONFIG = AutoDetectionConfig()
WITHIN = CONFIG.relocate_interval * FPS     # frames


def followed_after(detail, frames: np.ndarray, tid: int | None, f: int) -> int | None:
    """The person track ``tid`` was matched to most over the 40 frames from ``f``."""
    sel = (detail.track_id == tid) & (frames >= f) & (frames < f + 2 * FPS)
    people = detail.person_id[sel]
    return None if tid is None or not people.size else int(np.bincount(people).argmax())


counts: dict[tuple[str, str], int] = {}
for out, rec in pairs('young_births.py OUT REC [OUT REC ...]'):
    events, detail, frames, people, placed = run_context(out, rec)
    born_at = {e['frame']: e['id'] for e in events if e['kind'] == 'birth'}  # frame -> id
    for e in events:
        action = e.get('action', '') if e['kind'] == 'decision' else ''
        if not (action == 'birth' or action.startswith('drop (young')):
            continue
        f, here = e['frame'], people.get(e['frame'], [])
        if not here:
            continue
        at = detection_eval.nearest_row(here, e['xy']).person_id
        new = followed_after(detail, frames, born_at.get(f) if action == 'birth' else None,
                             f + 1)
        for tid, dist, _, unlike in (n for n in e.get('near', []) if len(n) > 3):
            age = [f - g for g in placed.get(int(tid), []) if f - WITHIN < g < f]
            if not age:
                continue
            young = followed_after(detail, frames, int(tid), f)
            label = ('young track on the detected person' if young == at else
                     'new track on nobody' if action == 'birth' and new is None else
                     'new track on a person of its own' if action == 'birth' and new != young
                     else 'dropped beside the young track of another person'
                     if action != 'birth' else 'new track on the young track\'s person')
            alike = 'look-alike' if CONFIG.looks_alike(unlike) else 'unlike'
            counts[alike, label] = counts.get((alike, label), 0) + 1
            print(f"{out.name} frame {f}: {action}, track {tid} {dist:.2f} m, placed "
                  f"{min(age) / FPS:.2f} s before, appearance {unlike:.3f}; detection on "
                  f"person {at}, track {tid} followed {young}, the new track {new}: {label}")
for (alike, label), n in sorted(counts.items()):
    print(f"{alike} (appearance {'<=' if alike == 'look-alike' else '>'} "
          f'{CONFIG.move_distance:g}), {label}: {n}')
