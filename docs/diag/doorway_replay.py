"""h-rel, offline: replay the rule "in the doorway band only the door-wall cameras support a
track, release after TIMEOUT without them" on docs/diag/release_probe.py logs: which tracks
it would end, their class (premature / left / nobody, as ``detection_eval exits``) and how
much sooner than the run did.

    usage: PROBE=DIR BASE=DIR doorway_replay.py BAND TIMEOUT MIN_COVERAGE RUN...
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import detection_eval as de  # noqa: E402
from doorway_coverage import probe_run  # noqa: E402


def main(band: float, timeout: float, threshold: float, runs: list[str]) -> None:
    frames_needed = int(round(timeout * de.FPS))
    total: dict[str, float] = {}
    for run in runs:
        pr, pf, d, frames, truth, events, wall = probe_run(run)
        present = {(r.frame, r.person_id) for r in truth}
        ends: dict[int, list[int]] = {}
        for e in events:
            if e['kind'] == 'end':
                ends.setdefault(e['id'], []).append(e['frame'])
        in_band = (pr['x'] >= 4.2) & (pr['x'] <= 5.1) & (pr['y'] >= 4.7 - band) & (pr['y'] <= 5.0)
        bad = in_band & ~(wall >= threshold)
        found = []
        for tid in np.unique(pr['track_id']).astype(int):
            run_len, prev = 0, None
            for i in np.flatnonzero(pr['track_id'] == tid):
                f = pf[i]
                if prev is not None and f != prev + 1:
                    run_len = 0                               # id reused / gap
                prev = f
                run_len = run_len + 1 if bad[i] else 0
                if run_len >= frames_needed:
                    end = min([g for g in ends.get(tid, []) if g >= f], default=None)
                    kind, _ = de.end_class(d, frames, present, tid, f)
                    gain = (end - f) / de.FPS if end is not None else np.nan
                    found.append((tid, f, kind, gain))
                    total[kind] = total.get(kind, 0) + 1
                    total[kind + '_gain'] = total.get(kind + '_gain', 0) + gain
                    break
        print(run, ' '.join(f'{t}@{f}:{k}:{g:+.1f}s' for t, f, k, g in found))
    print({k: (round(v, 1) if 'gain' in k else v) for k, v in total.items()})


if __name__ == '__main__':
    main(float(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3]), sys.argv[4:])
