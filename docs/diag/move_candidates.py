"""The move decisions ("move N" in events.json, not hidden or beside) where two or more
tracks passed the gates of ``AutoDetection._identify`` (the gain against
``relocate_margin``, the look-alike band of ``move_distance`` and ``look_alike_slack``,
``move_support``), each candidate labelled by whose person it had followed (same as the
detection's, other, unmatched); which one the largest gain and which one the nearest
model would move (docs/detection.md, "Of several movable tracks, the look-alike").

usage: .venv/bin/python docs/diag/move_candidates.py OUT REC [OUT REC ...]
"""
from _eval import detection_eval, pairs
from mbtrack_ros.core.detection.manager import AutoDetectionConfig

CFG = AutoDetectionConfig()


def candidates(e: dict) -> list[tuple[int, float, float]]:
    """(id, gain, appearance distance) of the tracks the decision's gates let the gain
    move, from its ``near`` and ``support`` rows."""
    strong = e['score'] >= CFG.beside_threshold
    margin = CFG.relocate_margin if strong \
        else max(CFG.relocate_margin, CFG.weak_relocate_margin)
    alike = CFG.relocate_margin - CFG.look_alike_slack if strong else margin
    support = {int(t): s for t, s in e.get('support', [])}
    out = []
    for tid, _, gain, unlike in e.get('near', []):
        looks_alike = unlike <= CFG.move_distance
        if margin < gain <= 0.0 and not looks_alike:
            continue
        if (gain > margin or (looks_alike and gain > alike)) \
                and not support.get(tid, 0.0) >= CFG.move_support:
            out.append((int(tid), gain, unlike))
    return out


total = 0
for out, rec in pairs('move_candidates.py OUT REC [OUT REC ...]'):
    tracks, truth, events, _ = detection_eval._load(out, rec)
    rows = [(e, c) for e in events if e['kind'] == 'decision'
            and e['action'].startswith('move ') and '(' not in e['action']
            for c in [candidates(e)] if len(c) >= 2]
    if not rows:
        continue
    detail, frames = detection_eval._matching(tracks, truth)
    people: dict[int, list] = {}
    for r in truth:
        people.setdefault(r.frame, []).append(r)
    for e, cands in rows:
        total += 1
        here = people.get(e['frame'])
        label = {t: detection_eval.decision_label(detail, frames, here, e, t) if here
                 else None for t, _, _ in cands}
        by_gain = max(cands, key=lambda c: c[1])[0]
        by_model = min(cands, key=lambda c: c[2])[0]
        print(f"{out.name} frame {e['frame']}: {e['action']}; candidates (id, gain, "
              f"distance, followed) {[(t, g, u, label[t]) for t, g, u in cands]}; largest "
              f"gain {by_gain} ({label[by_gain]}), nearest model {by_model} "
              f"({label[by_model]})")
print(f'{total} decisions with two or more movable tracks')
