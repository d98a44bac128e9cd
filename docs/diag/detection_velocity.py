"""Each detection decision between two frames with the detection's confirming places, the
least-squares speed over them and the velocity it was given, and the chosen tracks'
means and velocities per frame, the tracker stepped as ``detection_eval.py run`` steps it
(docs/detection.md, "No velocity from a detection that jumped").

usage: .venv/bin/python docs/diag/detection_velocity.py REC SEED FIRST LAST TRACK [TRACK ...]
"""
import sys
from pathlib import Path

import numpy as np

from _eval import tracked_frames
from mbtrack_ros.core.detection.detector import fitted_velocity
from mbtrack_ros.core.detection.manager import AutoDetection
from mbtrack_ros.core.state import VX, VY, X, Y

if len(sys.argv) < 6:
    sys.exit(__doc__.split('usage: ')[1])
rec, seed, first, last = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), \
    int(sys.argv[4])
shown = {int(a) for a in sys.argv[5:]}
identify = AutoDetection._identify
frame = [0]


def logged(self, det, *args, **kwargs):
    """``_identify`` with the detection's places and velocity printed."""
    birth = identify(self, det, *args, **kwargs)
    fit = fitted_velocity(det.history)
    if frame[0] >= first and fit is not None:
        places = ', '.join(f'({x:.2f}, {y:.2f})' for _, x, y in det.history)
        print(f'frame {frame[0]}: detection at {places}, fitted {np.hypot(*fit):.2f} m/s, '
              f'given ({det.state[VX]:.2f}, {det.state[VY]:.2f}) -> '
              f"{self.decisions[-1]['action']}")
    return birth


AutoDetection._identify = logged
for fs, result, _ in tracked_frames(rec, seed, last):
    frame[0] = fs.index + 1             # the decisions made in the next step are its
    if fs.index >= first:
        print(f'frame {fs.index}: ' + '; '.join(
            f'track {t.track_id} ({t.mean[X]:.2f}, {t.mean[Y]:.2f}) v ({t.mean[VX]:.2f}, '
            f'{t.mean[VY]:.2f})' for t in result.tracks if t.track_id in shown))
