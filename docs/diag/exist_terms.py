"""Which existence term drops when a track lags its person (h-exist).

Usage: exist_terms.py REC SEED FIRST LAST TRACK:PERSON [TRACK:PERSON ...]

Steps the tracker as ``detection_eval.py run`` does (same config, same seed) up to frame
LAST and prints, from frame FIRST on, for each named track: its existence, the distance
of its mean, of its heaviest particle and of its nearest particle to the ground-truth
person, and the existence log-ratio terms of each camera: coverage ``w k (2 f - 1)`` at the
mean (what the tracker uses), the same at the person's ground-truth place (track's
shape and orientation), the particle average ``log mean_n exp(w k (2 f_n - 1))`` over all the
track's particles, and the appearance term ``a w log(xi p1/p0 + 1 - xi)``.
"""
import csv
import math
import sys
from pathlib import Path

import numpy as np

from mbtrack_ros.core import existence as E
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import manager as M
from mbtrack_ros.core.detection import release as R
from mbtrack_ros.core.detection.features import span_coverage
from mbtrack_ros.core.shape import rasterize
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader

rec = Path(sys.argv[1])
seed, first, last = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
pairs: dict[int, list[int]] = {}
for a in sys.argv[5:]:
    tid_, person_ = (int(v) for v in a.split(':'))
    pairs.setdefault(tid_, []).append(person_)
gt: dict[tuple[int, int], tuple[float, float]] = {}
for r in csv.DictReader(open(rec / 'ground_truth.csv')):
    gt[int(r['frame']), int(r['person_id'])] = (float(r['x']), float(r['y']))
FR = {'i': 0}
EV: dict = {}
TERMS: dict[int, dict] = {}
AUX_OWNER: dict[int, int] = {}

orig_support = R.Releaser.support


def support(self, evidence, *a, **k):
    EV['e'] = evidence
    return orig_support(self, evidence, *a, **k)


R.Releaser.support = support
orig_update = E.TrackAuxiliary.update


def update(self, dt, *, loglik_visible, loglik_hidden, coverage=None, visible_fraction=None):
    tid = AUX_OWNER.get(id(self))
    if tid in pairs and FR['i'] >= first:
        cfg = self.config
        app = {}
        for cam in loglik_visible:
            l1, l0 = float(loglik_visible[cam]), float(loglik_hidden[cam])
            xi_prev = self.visibility.get(cam, cfg.initial_visibility)
            _, prior = E.binary_step(xi_prev, E.transition(cfg.desocclusion, cfg.occlusion, dt),
                                     l0, l1)
            pv = min(prior, cfg.visibility_cap)
            w = visible_fraction.get(cam, 1.0)
            app[cam] = cfg.appearance_weight * w * E._logaddexp(E._log(pv) + l1 - l0,
                                                                E._log1p_neg(pv))
        TERMS[tid] = {'app': app, 'w': dict(visible_fraction or {}),
                      'cov': dict(coverage or {}), 'k': cfg.support_gain}
    out = orig_update(self, dt, loglik_visible=loglik_visible, loglik_hidden=loglik_hidden,
                      coverage=coverage, visible_fraction=visible_fraction)
    if tid in TERMS:
        TERMS[tid]['ex'] = self.existence
    return out


E.TrackAuxiliary.update = update
orig_aux = M.AutoDetection._auxiliary
TRK: dict = {}


def auxiliary(self, dt, colour, tracks, models, *a):
    for t in tracks:
        aux = self.aux.setdefault(t.track_id, E.TrackAuxiliary(self.config.existence))
        AUX_OWNER[id(aux)] = t.track_id
    if FR['i'] >= first:
        for t in tracks:
            if t.track_id in pairs:
                TRK[t.track_id] = (t, self._shape(models.get(t.track_id), t), self)
    return orig_aux(self, dt, colour, tracks, models, *a)


M.AutoDetection._auxiliary = auxiliary


def report(frame: int, tid: int, person: int) -> None:
    t, shape, det = TRK[tid]
    g = gt.get((frame, person))
    terms = TERMS.get(tid, {})
    if g is None or not terms:
        return
    existence = terms['ex']
    p = t.particles[:, :2]
    w = t.weights if t.weights is not None else np.full(len(p), 1.0 / len(p))
    d = np.hypot(p[:, 0] - g[0], p[:, 1] - g[1])
    dmean = math.hypot(t.mean[0] - g[0], t.mean[1] - g[1])
    k = terms['k']
    line = [f'{frame} t{tid} p{person} ex {existence:.2f} d mean {dmean:.2f} heavy {d[np.argmax(w)]:.2f} '
            f'nearest {d.min():.2f} sd {np.hypot(*p.std(0)):.2f}']
    tot = {'mean': 0.0, 'gt': 0.0, 'parts': 0.0, 'app': sum(terms['app'].values())}
    for cam, f in sorted(terms['cov'].items()):
        wc = min(max(terms['w'].get(cam, 1.0), 0.0), 1.0)
        fg = EV['e'][cam].foreground
        camera = det.calibration.cameras[cam]
        if cam in det.side:
            at_gt = t.mean.copy()
            at_gt[:2] = g
            f_gt = span_coverage(fg, rasterize(camera, at_gt[None], [shape]))[0][0]
            f_n = span_coverage(fg, rasterize(camera, t.particles, [shape] * len(p)))[0]
            parts = float(np.log(np.sum(w * np.exp(wc * k * (2 * f_n - 1)))) / np.sum(w))
        else:   # top-down camera: the release's cylinder blob, doubled as in support()
            height = np.array([shape.height])
            f_gt = min(2 * R.blob_coverage(camera, fg, np.array([g]), height)[0][0], 1.0)
            f_n = np.minimum(2 * R.blob_coverage(camera, fg, p, np.full(len(p), shape.height))[0], 1.0)
            parts = float(np.log(np.sum(w * np.exp(wc * k * (2 * f_n - 1)))) / np.sum(w))
        tot['mean'] += wc * k * (2 * f - 1)
        tot['gt'] += wc * k * (2 * f_gt - 1)
        tot['parts'] += parts
        line.append(f'{cam}: f {f:.2f} gt {f_gt:.2f} w {wc:.2f} app {terms["app"].get(cam, 0):+.1f}')
    line.append('sum cov@mean {mean:+.1f} cov@gt {gt:+.1f} cov(parts) {parts:+.1f} app {app:+.1f}'
                .format(**tot))
    print(' | '.join(line), flush=True)


cal = RoomCalibration.load(rec / 'calibration.yaml')
with RecordingReader(rec / 'bag') as reader:
    cal = cal.subset([n for n in cal.names if n in reader.cameras])
    tracker = Tracker(cal, TrackerConfig.from_dict({'seed': seed, 'detection': True}))
    for fs in reader.frames():
        if fs.index > last:
            break
        FR['i'] = fs.index
        TRK.clear()
        TERMS.clear()
        tracker.step(fs.stamp_ns, {c: im for c, im in fs.images.items() if c in cal.cameras})
        for tid in TRK:
            for person in pairs[tid]:
                report(fs.index, tid, person)
