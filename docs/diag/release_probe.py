"""Run `detection_eval.py run` and log, per frame and live track (reported or hidden), what
the releaser saw: position, existence, support, spare flag, exclusive support and the
coverage per camera (a ceiling camera's blob coverage doubled, as `Releaser.support`
returns it) (h-rel). Writes OUT/probe.csv next to tracks.csv and events.json; `docs/
detection_eval.py releases OUT REC` reads it.

    .venv/bin/python docs/diag/release_probe.py REC OUT SEED
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import detection_eval  # noqa: E402
from mbtrack_ros.core.detection import release as release_module  # noqa: E402


def main(rec: Path, out: Path, seed: int) -> None:
    rows: list[str] = []
    now: dict = {}
    header = {'cams': []}
    support, exited, update = (release_module.Releaser.support, release_module.Releaser.exited,
                               release_module.Releaser.update)
    spare_tracks = release_module.spare_tracks

    def logged_spare(*a, **k):
        spare, sup = spare_tracks(*a, **k)
        now['exclusive'] = sup
        return spare, sup

    def logged_support(self, evidence, silhouettes, states=None, heights=None):
        now.clear()
        supported, coverage = support(self, evidence, silhouettes, states, heights)
        side = sorted(coverage)
        now.update(supported=supported, spare=self.spare.copy(),
                   coverage=np.array([coverage[n] for n in side]).T if side else None)
        header['cams'] = side
        return supported, coverage

    def logged_exited(self, ids, xy):
        now['ids'], now['xy'] = list(ids), np.asarray(xy).copy()
        return exited(self, ids, xy)

    def logged_update(self, stamp, ids, supported, existence=None, doorway=None, spare=None):
        ex = dict(zip(ids, existence if existence is not None else [np.nan] * len(ids)))
        for k, tid in enumerate(now.get('ids', [])):
            exc = now.get('exclusive')
            rows.append(f"{int(stamp)},{tid},{now['xy'][k, 0]:.4f},{now['xy'][k, 1]:.4f},"
                        f"{ex.get(tid, np.nan):.4f},{int(now['supported'][k])},"
                        f"{int(now['spare'][k]) if k < len(now['spare']) else 0},"
                        f"{exc[k] if exc is not None and k < len(exc) else np.nan:.4f}"
                        + ''.join(f',{v:.4f}' for v in (now['coverage'][k]
                                  if now['coverage'] is not None else [])))
        return update(self, stamp, ids, supported, existence, doorway, spare)

    release_module.spare_tracks = logged_spare
    release_module.Releaser.support = logged_support
    release_module.Releaser.exited = logged_exited
    release_module.Releaser.update = logged_update
    detection_eval.run(rec, out, seed)
    (out / 'probe.csv').write_text(
        'stamp_ns,track_id,x,y,existence,supported,spare,exclusive'
        + ''.join(f',coverage_{n}' for n in header['cams']) + '\n' + '\n'.join(rows)
        + '\n', encoding='utf-8')


if __name__ == '__main__':
    main(Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3]))
