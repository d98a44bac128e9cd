"""The background models next to the camera images at chosen frames.

Usage: background_dump.py REC SEED FRAME[,FRAME...] OUTDIR

Steps the tracker as ``detection_eval.py run`` does and writes, for each named frame and
camera, OUTDIR/<frame>_<camera>.png: the camera image on the left, the background model
(Y, Cb, Cr shown as colour) on the right; and prints the tracks' places at those frames.
"""
import sys
from pathlib import Path

import cv2
import numpy as np

from _eval import tracked_frames

rec, seed = Path(sys.argv[1]), int(sys.argv[2])
frames = {int(a) for a in sys.argv[3].split(',')}
out = Path(sys.argv[4])
out.mkdir(parents=True, exist_ok=True)
for fs, result, tracker in tracked_frames(rec, seed, max(frames)):
    if fs.index not in frames:
        continue
    for cam, image in fs.images.items():
        ycc = np.clip(tracker.detection.background.model(cam).background_ycc, 0, 255)
        model = cv2.cvtColor(ycc.astype(np.uint8)[..., [0, 2, 1]], cv2.COLOR_YCrCb2BGR)
        cv2.imwrite(str(out / f'{fs.index}_{cam}.png'),
                    np.hstack([cv2.cvtColor(image, cv2.COLOR_RGB2BGR), model]))
    print(fs.index, {t.track_id: tuple(np.round(t.mean[:2], 2)) for t in result.tracks})
