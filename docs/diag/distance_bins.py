"""Does a coarser colour histogram tell people apart better? ``appearance.model_distance``
(512 RGB bins, 8 per channel) against the same distance on 64 bins (4 per channel, the
512 summed in 2 x 2 x 2 blocks), for every track a detection decision compared
(``near`` of the decision rows), labelled by whether the track had followed the detected
person (docs/detection.md, "Coarser colour bins for the identity checks").

usage:
  .venv/bin/python docs/diag/distance_bins.py run REC SEED OUT
      ``detection_eval.py run REC OUT --seed SEED`` (the same outputs, the tracker is not
      changed) that also writes OUT/distances.json: frame, 512-bin and 64-bin distance of
      each comparison.
  .venv/bin/python docs/diag/distance_bins.py report OUT REC [OUT REC ...]
      per label (same person, another), the two distances' quartiles and how well each
      separates the labels (area under the ROC curve, and the share of other people's
      tracks at or under the 10th, 25th and 50th percentile of the same person's); the
      decision's gain (nats per camera, negated) beside them for comparison.
"""
import json
import sys
from pathlib import Path

import numpy as np

from _eval import detection_eval, run_context
from mbtrack_ros.core import appearance
from mbtrack_ros.core.detection import manager
from mbtrack_ros.recording.bag import RecordingReader


def coarse_distance(a, b) -> float:
    """``model_distance`` on 64 bins: the view-averaged part histograms (3, 512) summed in
    2 x 2 x 2 blocks of the RGB cube (bin ``r * 64 + g * 8 + b``, 3 bits each)."""
    ha, hb = a.completed_histograms(), b.completed_histograms()
    if not len(ha) or not len(hb):
        return 1.0
    sums = [h.mean(axis=0).reshape(3, 4, 2, 4, 2, 4, 2).sum(axis=(2, 4, 6)).reshape(3, 64)
            for h in (ha, hb)]
    ma, mb = (appearance._normalise(s) for s in sums)
    both = (ma.sum(axis=1) > 0) & (mb.sum(axis=1) > 0)
    if not both.any():
        return 1.0
    return float(np.sqrt(appearance.bhattacharyya_distance_sq(ma[both], mb[both])).mean())


def run(rec: Path, seed: int, out: Path) -> None:
    rows, frame = [], {'index': -1}
    read, fine = RecordingReader.frames, manager.model_distance

    def counted(self, *args, **kwargs):
        for fs in read(self, *args, **kwargs):
            frame['index'] = fs.index
            yield fs

    def logged(a, b):
        d = fine(a, b)
        rows.append((frame['index'], round(d, 3), round(coarse_distance(a, b), 3)))
        return d

    RecordingReader.frames, manager.model_distance = counted, logged
    detection_eval.run(rec, out, seed)
    (out / 'distances.json').write_text(json.dumps(rows), encoding='utf-8')


def auc(same: np.ndarray, other: np.ndarray) -> float:
    """P(a same-person distance < another person's), ties counted half."""
    s, o = same[:, None], other[None, :]
    return float(((s < o).sum() + 0.5 * (s == o).sum()) / (s.size * o.size))


def report(args: list[str]) -> None:
    pairs = list(zip(map(Path, args[::2]), map(Path, args[1::2])))
    by_label: dict[str, list[tuple[float, float]]] = {'same': [], 'other': []}
    for out, rec in pairs:
        dist_file = out / 'distances.json'
        if not dist_file.exists():
            print(f'{out}: no distances.json (not made by "distance_bins.py run")')
            continue
        coarse = {(f, d): c for f, d, c in json.loads(dist_file.read_text())}
        events, detail, frames, people, _ = run_context(out, rec)
        for e in events:
            if e['kind'] != 'decision' or not people.get(e['frame']):
                continue
            for tid, _, gain, unlike in e.get('near', []):
                c = coarse.get((e['frame'], round(unlike, 3)))
                label = detection_eval.decision_label(detail, frames, people[e['frame']],
                                                      e, tid)
                if c is not None and label in by_label:
                    by_label[label].append((unlike, c, -gain))
    same, other = (np.asarray(by_label[k]).reshape(-1, 3) for k in ('same', 'other'))
    if not len(same) or not len(other):
        raise SystemExit('need comparisons of both labels')
    print(f'{len(same)} comparisons with the track of the detected person, {len(other)} '
          f'with another person\'s')
    print('| bins | same: quartiles | other: quartiles | AUC | other <= same p10 / p25 / '
          'p50 |')
    print('| --- | --- | --- | --- | --- |')
    for col, name in ((0, '512'), (1, '64'), (2, 'minus the gain')):
        s, o = same[:, col], other[:, col]
        q = ' / '.join(f'{v:.3f}' for v in np.percentile(s, [25, 50, 75]))
        r = ' / '.join(f'{v:.3f}' for v in np.percentile(o, [25, 50, 75]))
        under = ' / '.join(f'{(o <= np.percentile(s, p)).mean():.2f}' for p in (10, 25, 50))
        print(f'| {name} | {q} | {r} | {auc(s, o):.3f} | {under} |')


if __name__ == '__main__':
    if len(sys.argv) == 5 and sys.argv[1] == 'run':
        run(Path(sys.argv[2]), int(sys.argv[3]), Path(sys.argv[4]))
    elif len(sys.argv) >= 4 and sys.argv[1] == 'report' and len(sys.argv) % 2 == 0:
        report(sys.argv[2:])
    else:
        sys.exit(__doc__)
