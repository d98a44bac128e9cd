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

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader

rec, seed, track_id = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[4])
frames = {int(a) for a in sys.argv[3].split(',')}
cal = RoomCalibration.load(rec / 'calibration.yaml')
with RecordingReader(rec / 'bag') as reader:
    cal = cal.subset([n for n in cal.names if n in reader.cameras])
    tracker = Tracker(cal, TrackerConfig.from_dict({'seed': seed, 'detection': True}))
    for fs in reader.frames():
        res = tracker.step(fs.stamp_ns, {c: im for c, im in fs.images.items()
                                         if c in cal.cameras})
        if fs.index in frames:
            for t in res.tracks:
                if t.track_id != track_id:
                    continue
                shown = []
                for name, cam in cal.cameras.items():
                    model = tracker.detection.background.models[name]
                    sil = rasterize(cam, t.mean[None], BodyShape(height=t.height)).mask(0) > 0
                    shown.append(f'{name}: silhouette {sil.sum()} unknown '
                                 f'{int((model.unknown & sil).sum())} possible '
                                 f'{int((model.possible_foreground & sil).sum())}')
                print(fs.index, t.mean[:2].round(2), ' | '.join(shown), flush=True)
        if fs.index >= max(frames):
            break
