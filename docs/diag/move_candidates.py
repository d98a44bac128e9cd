"""The move decisions ("move N" in events.json, not hidden or beside) where two or more
tracks passed the gates of ``AutoDetection._identify`` (``AutoDetectionConfig.gain_gate``
and ``move_support``), each candidate labelled by whose person it had followed (same as the
detection's, other, unmatched); which one the largest gain and which one the nearest
model would move (docs/detection.md, "Of several movable tracks, the look-alike").

usage: .venv/bin/python docs/diag/move_candidates.py OUT REC [OUT REC ...]
"""
from _eval import detection_eval, pairs, run_context
from mbtrack_ros.core.detection.manager import AutoDetectionConfig

CFG = AutoDetectionConfig()


def candidates(e: dict) -> list[tuple[int, float, float]]:
    """(id, gain, appearance distance) of the tracks the decision's gates let the gain
    move (``AutoDetectionConfig.gain_gate``, then ``move_support``), from its ``near``
    and ``support`` rows."""
    support = {int(t): s for t, s in e.get('support', [])}
    return [(int(tid), gain, unlike) for tid, _, gain, unlike in e.get('near', [])
            if CFG.gain_gate(e['score'], gain, unlike) == 'move'
            and not support.get(tid, 0.0) >= CFG.move_support]


total = 0
for out, rec in pairs('move_candidates.py OUT REC [OUT REC ...]'):
    events, detail, frames, people, _ = run_context(out, rec)
    rows = [(e, c) for e in events if e['kind'] == 'decision'
            and e['action'].startswith('move ') and '(' not in e['action']
            for c in [candidates(e)] if len(c) >= 2]
    if not rows:
        continue
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
