import sys, numpy as np
from pathlib import Path
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.recording.bag import RecordingReader
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.core.detection import manager as M
rec = Path(sys.argv[1]); seed = int(sys.argv[2]); nmax = int(sys.argv[3]); tid = int(sys.argv[4])
import csv
gt = {}
for r in csv.DictReader(open(rec/'ground_truth.csv')):
    gt.setdefault(int(r['frame']), []).append((float(r['x']), float(r['y'])))
orig = M.AutoDetection._auxiliary
log = {}
FR = {'i': 0}
def aux(self, dt, colour, tracks, models, parts, owner, part_sils, coverage):
    k = [i for i, t in enumerate(tracks) if t.track_id == tid]
    if k:
        k = k[0]; t = tracks[k]
        log['t'] = (t.mean[:4].copy(), None if t.particles is None else t.particles[:, :2].std(0),
                    {n: round(float(c[k]), 2) for n, c in coverage.items()})
        if FR['i'] in ():
            from mbtrack_ros.core.appearance import single_target_loglik, relative_angle
            from mbtrack_ros.core.shape import rasterize
            g = min(gt[FR['i']], key=lambda p: (p[0]-t.mean[0])**2+(p[1]-t.mean[1])**2)
            fr = np.linspace(-0.5, 1.5, 9)
            st = np.repeat(t.mean[None].astype(float), len(fr), 0)
            st[:, 0] = t.mean[0] + fr*(g[0]-t.mean[0]); st[:, 1] = t.mean[1] + fr*(g[1]-t.mean[1])
            model = models[tid]
            for n in self.side:
                cam = self.calibration.cameras[n]
                sil = rasterize(cam, st, model.shape)
                rel = relative_angle(st[:, 4], cam.viewing_angle(st[:, :2]))
                ll = single_target_loglik(colour(n), sil, model.interpolate(rel), sigma=self.config.sigma)
                from mbtrack_ros.core.detection.features import span_coverage
                cv = span_coverage(EV['e'][n].foreground, sil)[0]
                print(FR['i'], n, 'cov', np.round(cv, 2))
                import cv2
                fgm = EV['e'][n].foreground.astype(np.uint8)*255
                img = EV['e'][n].image[:, :, ::-1].copy()
                out = np.concatenate([img, np.repeat(fgm[:, :, None], 3, 2)], 1)
                for j, colr in ((2, (0, 255, 0)), (6, (0, 0, 255))):
                    m = (sil.mask(j) > 0).astype(np.uint8)
                    cs, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
                    cv2.drawContours(out, cs, -1, colr, 1)
                    cs2 = [c + np.array([[fgm.shape[1], 0]]) for c in cs]
                    cv2.drawContours(out, cs2, -1, colr, 1)
                cv2.imwrite(f'f{FR["i"]}_{n}.png', cv2.resize(out, None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST))
                print(FR['i'], n, 'frac', fr.round(2), 'll-ll(mean)', np.round(ll - ll[2], 2))
    return orig(self, dt, colour, tracks, models, parts, owner, part_sils, coverage)
M.AutoDetection._auxiliary = aux
EV = {}
from mbtrack_ros.core.detection import release as R
osup = R.Releaser.support
def sup(self, evidence, *a, **k):
    EV['e'] = evidence
    return osup(self, evidence, *a, **k)
R.Releaser.support = sup
cal = RoomCalibration.load(rec / 'calibration.yaml')
with RecordingReader(rec / 'bag') as reader:
    cal = cal.subset([n for n in cal.names if n in reader.cameras])
    from mbtrack_ros.core.dynamics import MotionConfig
    tr = Tracker(cal, TrackerConfig(seed=seed, detection=True, motion=MotionConfig(position_noise=float(sys.argv[5]), velocity_noise=float(sys.argv[6]))))
    for fs in reader.frames():
        if fs.index > nmax: break
        log.clear(); FR['i'] = fs.index
        res = tr.step(fs.stamp_ns, {c: im for c, im in fs.images.items() if c in cal.cameras})
        for t in res.tracks:
            if t.track_id == tid and 't' in log:
                m, sd, cov = log['t']
                g = gt.get(fs.index, [])
                d = min(((m[0]-x)**2+(m[1]-y)**2)**.5 for x, y in g) if g else -1
                print(fs.index, 'gt', gt.get(fs.index), 'mean', np.round(m, 2), 'sd', np.round(sd, 2), 'gtdist %.2f' % d, 'ex %.2f' % t.existence, cov)
