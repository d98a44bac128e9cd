"""h-rel, offline: per 0.1 m bin of y in front of the door (x 4.2-5.1, y 4.2-5.0), the larger
foreground coverage of the door-wall cameras cam2/cam3 for track-frames matched to a person
and for unmatched ones, from the logs of docs/diag/release_probe.py (dir PROBE) and the
outputs of the same runs (dir BASE).

    usage: PROBE=DIR BASE=DIR doorway_coverage.py RUN...     (RUN = rec_sS)
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import detection_eval as de  # noqa: E402

RECORDINGS = Path(os.environ.get('MBTRACK_RECS', '/tmp/h4'))


def probe_run(run: str):
    """(probe rows, their frame index, matching detail d, its frames, ground truth, events,
    door-wall coverage per probe row) of one run."""
    out = Path(os.environ.get('PROBE', '/tmp/h-rel/probe')) / run
    rec = RECORDINGS / run.rsplit('_s', 1)[0]
    tracks, truth, events, _ = de._load(Path(os.environ.get('BASE', '/tmp/h-exit/v3')) / run, rec)
    d, frames = de._matching(tracks, truth)
    pr = np.genfromtxt(out / 'probe.csv', delimiter=',', names=True)
    s0 = min(r.stamp_ns for r in truth)
    pf = np.round((pr['stamp_ns'] - s0) / (1e9 / de.FPS)).astype(int)
    wall = np.nanmax(np.stack([pr['coverage_cam2'], pr['coverage_cam3']]), axis=0)
    return pr, pf, d, frames, truth, events, wall


def main(runs: list[str]) -> None:
    acc: dict[tuple[str, str], list[float]] = {}
    for run in runs:
        pr, pf, d, frames, _, _, wall = probe_run(run)
        matched = {(int(f), int(t)) for f, t, p in zip(frames, d.track_id, d.person_id)
                   if t >= 0 and p >= 0}
        for i in range(len(pr)):
            x, y = pr['x'][i], pr['y'][i]
            if not (4.2 <= x <= 5.1 and 4.2 <= y <= 5.0):
                continue
            label = 'matched' if (pf[i], int(pr['track_id'][i])) in matched else 'unmatched'
            acc.setdefault((label, f'{np.floor(y * 10) / 10:.1f}'), []).append(wall[i])
    for key in sorted(acc):
        w = np.array(acc[key])
        print(key, len(w), 'p5/25/50', np.round(np.nanpercentile(w, [5, 25, 50]), 2),
              '<0.3:', round(float(np.mean(~(w >= 0.3))), 2))


if __name__ == '__main__':
    main(sys.argv[1:])
