"""At the given frames, what each side camera's colour likelihood (003 Eq. 3, the track's
own model, no occlusion) says along the line from a track's mean (0) to a ground-truth
person (1), from -0.5 to 1.5: the log-likelihood against the mean's, the share of the
silhouette inside the image and its foreground coverage. A silhouette the camera sees no
pixel of scores 0, the best score (``single_target_loglik``). Steps the tracker as
``detection_eval.py run`` does (same seed).

usage: .venv/bin/python docs/diag/edge_loglik.py REC SEED TRACK PERSON FRAME[,FRAME...]
"""
import sys
from pathlib import Path

import numpy as np

from _eval import places, tracked_frames
from mbtrack_ros.core.appearance import relative_angle, single_target_loglik
from mbtrack_ros.core.detection import release
from mbtrack_ros.core.detection.features import span_coverage
from mbtrack_ros.core.shape import rasterize
from mbtrack_ros.core.state import THETA, X, Y

if len(sys.argv) != 6:
    sys.exit('usage: edge_loglik.py REC SEED TRACK PERSON FRAME[,FRAME...]')
rec, seed, tid, pid = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
frames = sorted(int(f) for f in sys.argv[5].split(','))
people = places(rec)
evidence = {}
support = release.Releaser.support


def keep_evidence(self, frame_evidence, *args, **kwargs):
    evidence['now'] = frame_evidence        # the frame's FrameEvidence per camera
    return support(self, frame_evidence, *args, **kwargs)


release.Releaser.support = keep_evidence
steps = np.linspace(-0.5, 1.5, 9)
for fs, result, tracker in tracked_frames(rec, seed, frames[-1]):
    if fs.index not in frames:
        continue
    auto = tracker.detection
    track = next(t for t in result.tracks if t.track_id == tid)
    model = tracker.models[tid]
    person = people[fs.index][pid]
    states = np.repeat(track.mean[None].astype(np.float64), len(steps), 0)
    states[:, X] = track.mean[X] + steps * (person[0] - track.mean[X])
    states[:, Y] = track.mean[Y] + steps * (person[1] - track.mean[Y])
    print(f'frame {fs.index}: track {tid} at ({track.mean[X]:.2f}, {track.mean[Y]:.2f}), '
          f'person {pid} at ({person[0]:.2f}, {person[1]:.2f}); steps {steps.round(2)}')
    for name in auto.side:
        cam = auto.calibration.cameras[name]
        sil = rasterize(cam, states, model.shape)
        rel = relative_angle(states[:, THETA], cam.viewing_angle(states[:, [X, Y]]))
        ll = single_target_loglik(evidence['now'][name].bins, sil, model.interpolate(rel),
                                  sigma=auto.config.sigma)
        cover = span_coverage(evidence['now'][name].foreground, sil)[0]
        inside = sil.area / np.maximum(sil.full_area, 1)
        print(f'  {name}: log-lik - mean\'s {np.round(ll - ll[2], 1)}, inside '
              f'{np.round(inside, 2)}, coverage {np.round(cover, 2)}')
