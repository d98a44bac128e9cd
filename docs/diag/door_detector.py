"""Why the detector misses an entering person: at the person's ground-truth position the
coarse score, per-camera coverage, veto, views, and the refined detection's score/motion."""
import sys
from pathlib import Path
import numpy as np
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import detector as dm
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader
from mbtrack_ros.recording.csvfiles import read_ground_truth
rec, seed, pid, f_lo, f_hi = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
gt = {r.frame: r for r in read_ground_truth(rec / 'ground_truth.csv') if r.person_id == pid}
frame = {'i': 0}
D = dm.Detector
detect = D.detect
def ldetect(self, evidence, track_xy=None):
    f = frame['i']
    if f_lo <= f <= f_hi and f in gt:
        p = np.array([gt[f].x, gt[f].y])
        k = int(np.argmin(np.linalg.norm(self.coarse_xy - p, axis=1)))
        score, mean_cov = self.coarse(evidence, track_xy=track_xy)
        per = {}
        for name, ev in evidence.items():
            if name in self._coarse:
                resp, sees, cov = self._view_terms(name, ev, self._coarse[name], full=False)
                per[name] = (round(float(cov[k]), 2), bool(sees[k]))
        det = self._refine(evidence, p, np.zeros((0, 2)))
        print(f'f{f} person ({p[0]:.2f},{p[1]:.2f}) coarse pt {np.round(self.coarse_xy[k],2)} score {score[k]:.2f} mean_cov {mean_cov[k]:.2f} per-cam {per}; refine at person: '
              + (f'({det.xy[0]:.2f},{det.xy[1]:.2f}) score {det.score:.2f} motion {det.motion:.3f} cov {{{", ".join(f"{a}: {b:.2f}" for a, b in det.coverage.items())}}}' if det else 'None'))
    return detect(self, evidence, track_xy=track_xy)
D.detect = ldetect
cal = RoomCalibration.load(rec / 'calibration.yaml')
with RecordingReader(rec / 'bag') as reader:
    cal = cal.subset([n for n in cal.names if n in reader.cameras])
    tr = Tracker(cal, TrackerConfig(seed=seed, detection=True))
    for fs in reader.frames():
        frame['i'] = fs.index
        if fs.index > f_hi:
            break
        tr.step(fs.stamp_ns, {c: im for c, im in fs.images.items() if c in cal.cameras})
