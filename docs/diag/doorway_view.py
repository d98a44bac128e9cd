"""Why a camera does not see an entering person as foreground (h-enter).

    .venv/bin/python docs/diag/doorway_view.py REC SEED PERSON FIRST LAST OUTDIR \
        --synth-seed N [--no-ceiling]

Steps the tracker on REC as ``detection_eval run`` does and, at frames FIRST..LAST of
PERSON's ground truth, prints per camera the coverage of the coarse silhouette (1.75 x
0.5 m) at the person: by the tracker's foreground, and by the foreground of the same test
against a clean render of the empty room (same door angle, no people) from re-running the
synth (``mbtrack synth clear-room --seed N``), the fraction of the silhouette the
person's own pixels fill (synth id buffer: is the projection right?) and the median
|model - empty room| luminance on them (has the model learnt the person?). Writes
OUTDIR/fF.png: per camera image | model | |dY| x4 | foreground with the silhouette in red |
track mask.
"""
import argparse
from pathlib import Path

import cv2
import numpy as np

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import detector as dm
from mbtrack_ros.core.detection.background import (
    BackgroundConfig, _foreground_kernel, _to_ycc, clean_mask)
from mbtrack_ros.core.shape import rasterize
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader
from mbtrack_ros.recording.csvfiles import read_ground_truth
from mbtrack_ros.synth.body import Ellipsoids
from mbtrack_ros.synth.generator import Synthesizer, render_view
from mbtrack_ros.synth.raster import expose

ap = argparse.ArgumentParser()
ap.add_argument('rec', type=Path)
ap.add_argument('seed', type=int)
ap.add_argument('person', type=int)
ap.add_argument('first', type=int)
ap.add_argument('last', type=int)
ap.add_argument('out', type=Path)
ap.add_argument('--synth-seed', type=int, required=True)
ap.add_argument('--no-ceiling', action='store_true')
a = ap.parse_args()
a.out.mkdir(parents=True, exist_ok=True)
gt = {r.frame: r for r in read_ground_truth(a.rec / 'ground_truth.csv')
      if r.person_id == a.person}
frames = [f for f in range(a.first, a.last + 1) if f in gt]

# the synth again: id buffers and the empty room with the door as it was
synth = Synthesizer('clear-room', seed=a.synth_seed, frames=a.last + 1,
                    ceiling=not a.no_ceiling)
clean = {}
for fr in synth:
    if fr.index in gt and fr.index >= a.first:
        t = fr.index / synth.fps
        gain = synth.illumination(t)
        for k, (n, view) in enumerate(synth.views.items()):
            rad, _, _ = render_view(view, Ellipsoids.concat([]), time_s=t,
                                    door_angle=fr.door_angle)
            clean[fr.index, n] = (expose(rad, synth.gains[k] * np.float32(gain),
                                         synth.noise_bank, 0), fr.id_buffers[n] == a.person)
bcfg = BackgroundConfig()
state = {'i': 0, 'tracker': None}
detect = dm.Detector.detect


def logged_detect(self, evidence, track_xy=None):
    f = state['i']
    if f in frames:
        bank = state['tracker'].detection.background
        st = np.zeros((1, 6))
        st[0, :2] = gt[f].x, gt[f].y
        rows = []
        for name, ev in evidence.items():
            cam = self.calibration.cameras[name]
            sil = rasterize(cam, st, self.shape, heights=np.array([self.config.coarse_height]),
                            widths=np.array([self.config.coarse_width]))
            mask = np.zeros(ev.foreground.shape, bool)
            for r, x0, x1 in zip(sil.row, sil.x0, sil.x1):
                mask[r, x0:x1] = True
            model = bank.model(name)
            bg, gain = model._bg, model.gain
            empty, own = clean[f, name]
            fg_clean = clean_mask(_foreground_kernel(
                _to_ycc(ev.image), _to_ycc(empty), 1.0, bcfg.luma_threshold,
                bcfg.chroma_threshold, *bcfg.shadow_ratio), open_size=bcfg.open_size,
                close_size=bcfg.close_size, min_area=0).astype(bool)
            img, emp = _to_ycc(ev.image), _to_ycc(empty)
            learnt = np.abs(bg[..., 0] - emp[..., 0])
            dy_model = np.abs(img[..., 0] - gain * bg[..., 0])
            dy_empty = np.abs(img[..., 0] - emp[..., 0])
            dc_empty = np.hypot(img[..., 1] - emp[..., 1], img[..., 2] - emp[..., 2])

            def med(v):
                return float(np.median(v[own])) if own.any() else np.nan

            print(f'f{f} {name}: coverage {ev.foreground[mask].mean():.2f}, against the empty '
                  f'room {fg_clean[mask].mean():.2f}; person fills {own[mask].mean():.2f} '
                  f'of the silhouette; medians on the person: |model - empty| Y '
                  f'{med(learnt):.1f}, |image - model| Y {med(dy_model):.1f}, |image - '
                  f'empty| Y {med(dy_empty):.1f} chroma {med(dc_empty):.1f}')
            red = np.zeros_like(ev.image)
            red[mask] = (255, 0, 0)
            edge = cv2.morphologyEx(mask.view(np.uint8), cv2.MORPH_GRADIENT,
                                    np.ones((3, 3), np.uint8)) > 0
            ycrcb = np.dstack([bg[..., 0], bg[..., 2], bg[..., 1]]).clip(0, 255)
            model_rgb = cv2.cvtColor(ycrcb.astype(np.uint8), cv2.COLOR_YCrCb2RGB)
            dy = np.abs(_to_ycc(ev.image)[..., 0] - gain * bg[..., 0])
            panels = [ev.image, model_rgb, np.dstack([np.clip(4 * dy, 0, 255)] * 3),
                      np.dstack([ev.foreground * 255] * 3),
                      np.dstack([(ev.tracks if ev.tracks is not None else mask * 0) * 255] * 3)]
            panels = [p.astype(np.uint8).copy() for p in panels]
            for p in panels:
                p[edge] = (255, 0, 0)
            rows.append(np.concatenate(panels, axis=1))
        cv2.imwrite(str(a.out / f'f{f}.png'),
                    cv2.cvtColor(np.concatenate(rows, axis=0), cv2.COLOR_RGB2BGR))
    return detect(self, evidence, track_xy=track_xy)


dm.Detector.detect = logged_detect
cal = RoomCalibration.load(a.rec / 'calibration.yaml')
with RecordingReader(a.rec / 'bag') as reader:
    cal = cal.subset([n for n in cal.names if n in reader.cameras])
    state['tracker'] = Tracker(cal, TrackerConfig(seed=a.seed, detection=True))
    for fs in reader.frames():
        state['i'] = fs.index
        if fs.index > a.last:
            break
        state['tracker'].step(fs.stamp_ns, {c: im for c, im in fs.images.items()
                                            if c in cal.cameras})
