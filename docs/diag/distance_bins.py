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

from scipy.stats import mannwhitneyu

from _eval import detection_eval, run_context
from mbtrack_ros.core.appearance import model_distance as fine_distance
from mbtrack_ros.core.detection import association
from mbtrack_ros.recording.bag import RecordingReader


class _Coarse:
    """A model's key views as 64 bins: its part histograms (V, 3, 512) summed in 2 x 2 x 2
    blocks of the RGB cube (bin ``r * 64 + g * 8 + b``, 3 bits each), held in the first
    64 of 512 bins (the others empty), so that ``model_distance`` itself compares them."""

    def __init__(self, model) -> None:
        h = model.completed_histograms()
        self._hists = np.zeros_like(h)
        self._hists[..., :64] = h.reshape(*h.shape[:2], 4, 2, 4, 2, 4, 2).sum(
            axis=(3, 5, 7)).reshape(*h.shape[:2], 64)

    def completed_histograms(self) -> np.ndarray:
        return self._hists


def coarse_distance(a, b) -> float:
    """``appearance.model_distance`` on 64 bins (:class:`_Coarse`)."""
    return fine_distance(_Coarse(a), _Coarse(b))


def run(rec: Path, seed: int, out: Path) -> None:
    rows, frame = [], {'index': -1}
    read = RecordingReader.frames

    def counted(self, *args, **kwargs):
        for fs in read(self, *args, **kwargs):
            frame['index'] = fs.index
            yield fs

    def logged(a, b):
        d = fine_distance(a, b)
        rows.append((frame['index'], round(d, 3), round(coarse_distance(a, b), 3)))
        return d

    RecordingReader.frames, association.model_distance = counted, logged
    try:
        detection_eval.run(rec, out, seed)
    finally:
        RecordingReader.frames, association.model_distance = read, fine_distance
    (out / 'distances.json').write_text(json.dumps(rows), encoding='utf-8')


def auc(same: np.ndarray, other: np.ndarray) -> float:
    """P(a same-person value < another person's), ties counted half: the Mann-Whitney U of
    ``other`` against ``same`` over the number of pairs."""
    return float(mannwhitneyu(other, same).statistic / (same.size * other.size))


def report(args: list[str]) -> None:
    pairs = list(zip(map(Path, args[::2]), map(Path, args[1::2])))
    by_label: dict[str, list[tuple[float, float, float]]] = {'same': [], 'other': []}
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
    print('| cue | same: quartiles | other: quartiles | AUC | other <= same p10 / p25 / '
          'p50 |')
    print('| --- | --- | --- | --- | --- |')
    for col, name in ((0, 'distance, 512 bins'), (1, 'distance, 64 bins'),
                      (2, 'minus the gain')):
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
