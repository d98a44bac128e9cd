"""How much of a track's silhouette is still not-yet-known background (the people cue's
region around a bootstrap person), per camera.

Usage: bootstrap_void.py REC SEED FRAMES TRACK      (FRAMES comma-separated, e.g. 20,40,50)

Steps the tracker as ``docs/detection_eval.py run`` does and prints, at the given frames,
for the track: its place and per camera the pixels of its silhouette at its mean, how many
of them are not yet known, and how many of those count as possible foreground (the rest is
undecided: neither foreground nor background).
"""
import sys
from pathlib import Path

from _eval import tracked_frames
from mbtrack_ros.core.shape import BodyShape, rasterize

rec, seed, track_id = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[4])
frames = {int(a) for a in sys.argv[3].split(',')}
for fs, res, tracker in tracked_frames(rec, seed, max(frames)):
    if fs.index not in frames:
        continue
    for t in res.tracks:
        if t.track_id != track_id:
            continue
        shown = []
        for name, cam in tracker.calibration.cameras.items():
            model = tracker.detection.background.models[name]
            sil = rasterize(cam, t.mean[None], BodyShape(height=t.height)).mask(0) > 0
            shown.append(f'{name}: silhouette {sil.sum()} unknown '
                         f'{int((model.unknown & sil).sum())} possible '
                         f'{int((model.possible_foreground & sil).sum())}')
        print(fs.index, t.mean[:2].round(2), ' | '.join(shown), flush=True)
