"""Look-alike tracks near births (docs/detection.md, "Look-alike tracks lagging at the wall").

    .venv/bin/python docs/diag/look_alike.py runs OUT [OUT ...]   # runs a slack could change
    .venv/bin/python docs/diag/look_alike.py band OUT [OUT ...]   # the probe's support rows
    .venv/bin/python docs/diag/look_alike.py wider SLACK DISTANCE OUT [OUT ...]

OUT is a ``detection_eval.py suite`` output (OUT/runs/REC_sS, OUT/rec/REC). ``runs`` lists
each decision of a strong detection (score >= ``beside_threshold``) with a track whose
gain is within SLACK nats under ``relocate_margin`` and whose model is within
``move_distance`` (the defaults, ``look_alike_slack`` 3), each labelled by the person the
track had followed: only runs with such a decision can change with ``look_alike_slack``
(the tracker is deterministic, and the decisions before the first such one are the
same). ``band`` reads the rows that
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

CFG = AutoDetectionConfig()


def _runs(bases):
    for base in bases:
        for out in sorted(Path(base, 'runs').iterdir()):
            if (out / 'events.json').exists():
                yield out, Path(base, 'rec', out.name.split('_s')[0])


def _labeller(out: Path, rec: Path):
    """label(decision, track id): whose person the track had followed ('same', 'other',
    'unmatched'; :func:`detection_eval.decision_label`), None where no one is in the
    ground truth of the decision's frame."""
    tracks, truth, _, _ = de._load(out, rec)
    d, frames = de._matching(tracks, truth)
    gt: dict[int, list] = {}
    for r in truth:
        gt.setdefault(r.frame, []).append(r)

    def label(e: dict, tid: int):
        people = gt.get(e['frame'])
        return de.decision_label(d, frames, people, e, int(tid)) if people else None
    return label


def _in_band(gain: float, unlike: float, slack: float, distance: float) -> bool:
    """A look-alike track (appearance distance <= distance) whose gain is within slack
    under relocate_margin."""
    return CFG.relocate_margin - slack < gain <= CFG.relocate_margin and unlike <= distance


def _listed(bases, keep) -> None:
    """Print the near tracks of strong detections' decisions that keep(decision, near row)
    selects, each labelled, then the counts per label and the runs."""
    labels: dict[str, int] = {}
    names = set()
    for out, rec in _runs(bases):
        events = json.loads((out / 'events.json').read_text(encoding='utf-8'))
        rows = [(e, n[:4]) for e in events if e['kind'] == 'decision'
                and e['score'] >= CFG.beside_threshold
                for n in e.get('near', []) if keep(e, n)]
        if not rows:
            continue
        names.add(out.name)
        label = _labeller(out, rec)
        for e, (tid, metres, gain, unlike) in rows:
            who = label(e, tid)
            labels[str(who)] = labels.get(str(who), 0) + 1
            print(f"{out.name} frame {e['frame']}: track {tid} {metres} m, gain {gain}, "
                  f"appearance {unlike}, followed the {who} person -> {e['action']}")
    print(', '.join(f'{k} {v}' for k, v in sorted(labels.items())))
    print(f'{len(names)} runs: {" ".join(sorted(names))}')


def runs(bases) -> None:
    _listed(bases, lambda e, n: _in_band(n[2], n[3], CFG.look_alike_slack,
                                         CFG.move_distance))


def wider(slack: float, distance: float, bases) -> None:
    _listed(bases, lambda e, n: e['action'].startswith(('birth', 'reuse'))
            and _in_band(n[2], n[3], slack, distance)
            and not _in_band(n[2], n[3], CFG.look_alike_slack, CFG.move_distance))


def band(bases) -> None:
    for out, rec in _runs(bases):
        events = json.loads((out / 'events.json').read_text(encoding='utf-8'))
        if not any('band' in e for e in events):
            continue
        label = _labeller(out, rec)
        for e in events:
            if e['kind'] != 'decision' or 'band' not in e or label(e, 0) is None:
                continue
            near = {n[0]: n for n in e['near']}
            for tid, alone, with_det, spare in e['band']:
                _, metres, gain, unlike = near[tid][:4]
                print(f"{out.name} frame {e['frame']} score {e['score']:.2f}: track {tid} "
                      f"{metres} m, gain {gain}, appearance {unlike}, exclusive support "
                      f"{alone} -> {with_det} with the detection, spare {spare}, followed "
                      f"the {label(e, tid)} person -> {e['action']}")


if __name__ == '__main__':
    if len(sys.argv) >= 5 and sys.argv[1] == 'wider':
        wider(float(sys.argv[2]), float(sys.argv[3]), sys.argv[4:])
    elif len(sys.argv) >= 3 and sys.argv[1] in ('runs', 'band'):
        {'runs': runs, 'band': band}[sys.argv[1]](sys.argv[2:])
    else:
        sys.exit(__doc__)
