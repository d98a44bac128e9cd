"""Look-alike tracks near births (docs/detection.md, "Look-alike tracks lagging at the wall").

    .venv/bin/python docs/diag/look_alike.py runs OUT [OUT ...]   # runs a slack could change
    .venv/bin/python docs/diag/look_alike.py band OUT [OUT ...]   # the probe's support rows
    .venv/bin/python docs/diag/look_alike.py wider SLACK DISTANCE OUT [OUT ...]

OUT is a ``detection_eval.py suite`` output (OUT/runs/REC_sS, OUT/rec/REC). ``runs`` lists
each decision of a strong detection (score >= ``beside_threshold``) with a track whose
gain is within SLACK nats under ``relocate_margin`` and whose model is within
``move_distance`` (defaults of today's tree, SLACK 3): only runs with such a decision can
change with ``look_alike_slack`` (the tracker is deterministic, and the decisions before
the first such one are the same). ``band`` reads the rows that
``probe_look_alike_support.patch`` adds to events.json (exclusive support of those tracks
without and with the detection) and labels each track by the person it had followed.
``wider`` lists the tracks near births of strong detections that a wider gate (gain within
SLACK under the margin, appearance distance at most DISTANCE) would add to today's, each
labelled the same way (whether ``move_support`` would keep it is not known there).
"""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import detection_eval as de  # noqa: E402
from mbtrack_ros.core.detection.manager import AutoDetectionConfig  # noqa: E402

SLACK = 3.0


def _runs(bases):
    for base in bases:
        for out in sorted(Path(base, 'runs').iterdir()):
            if (out / 'events.json').exists():
                yield out, Path(base, 'rec', out.name.split('_s')[0])


def runs(bases) -> None:
    cfg = AutoDetectionConfig()
    low = cfg.relocate_margin - SLACK
    names = set()
    for out, _ in _runs(bases):
        for e in json.loads((out / 'events.json').read_text(encoding='utf-8')):
            if e['kind'] != 'decision' or e['score'] < cfg.beside_threshold:
                continue
            for tid, metres, gain, unlike in (n[:4] for n in e.get('near', [])):
                if low < gain <= cfg.relocate_margin and unlike <= cfg.move_distance:
                    names.add(out.name)
                    print(f"{out.name} frame {e['frame']}: track {tid} {metres} m, gain "
                          f"{gain}, appearance {unlike} -> {e['action']}")
    print(f'{len(names)} runs: {" ".join(sorted(names))}')


def band(bases) -> None:
    for out, rec in _runs(bases):
        tracks, truth, events, _ = de._load(out, rec)
        d, frames = de._matching(tracks, truth)
        gt: dict[int, list] = {}
        for r in truth:
            gt.setdefault(r.frame, []).append(r)
        for e in events:
            if e['kind'] != 'decision' or 'band' not in e or not gt.get(e['frame']):
                continue
            near = {n[0]: n for n in e['near']}
            for tid, alone, with_det, spare in e['band']:
                _, metres, gain, unlike = near[tid][:4]
                label = de.decision_label(d, frames, gt[e['frame']], e, tid)
                print(f"{out.name} frame {e['frame']} score {e['score']:.2f}: track {tid} "
                      f"{metres} m, gain {gain}, appearance {unlike}, exclusive support "
                      f"{alone} -> {with_det} with the detection, spare {spare}, followed "
                      f"the {label} person -> {e['action']}")


def wider(slack: float, distance: float, bases) -> None:
    cfg = AutoDetectionConfig()
    margin = cfg.relocate_margin

    def inside(gain, unlike, s, dist):
        return margin - s < gain <= margin and unlike <= dist

    labels: dict[str, int] = {}
    for out, rec in _runs(bases):
        events = json.loads((out / 'events.json').read_text(encoding='utf-8'))
        added = [(e, n) for e in events if e['kind'] == 'decision'
                 and e['score'] >= cfg.beside_threshold
                 and e['action'].startswith(('birth', 'reuse'))
                 for n in e.get('near', []) if inside(n[2], n[3], slack, distance)
                 and not inside(n[2], n[3], cfg.look_alike_slack, cfg.move_distance)]
        if not added:
            continue
        tracks, truth, _, _ = de._load(out, rec)
        d, frames = de._matching(tracks, truth)
        gt: dict[int, list] = {}
        for r in truth:
            gt.setdefault(r.frame, []).append(r)
        for e, (tid, metres, gain, unlike) in ((e, n[:4]) for e, n in added):
            if not gt.get(e['frame']):
                continue
            label = de.decision_label(d, frames, gt[e['frame']], e, int(tid))
            labels[label] = labels.get(label, 0) + 1
            print(f"{out.name} frame {e['frame']}: track {tid} {metres} m, gain {gain}, "
                  f"appearance {unlike}, followed the {label} person -> {e['action']}")
    print(', '.join(f'{k} {v}' for k, v in sorted(labels.items())))


if __name__ == '__main__':
    if len(sys.argv) >= 5 and sys.argv[1] == 'wider':
        wider(float(sys.argv[2]), float(sys.argv[3]), sys.argv[4:])
    elif len(sys.argv) >= 3 and sys.argv[1] in ('runs', 'band'):
        {'runs': runs, 'band': band}[sys.argv[1]](sys.argv[2:])
    else:
        sys.exit(__doc__)
