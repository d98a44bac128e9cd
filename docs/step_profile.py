"""Per-frame time of Tracker.step with automatic detection, and its stages (docs/live_measurements.md).

Usage: python docs/step_profile.py RECORDING FRAMES OUT.json

Steps the tracker as `mbtrack replay` does (seed 0) over the first FRAMES frame sets, writes
(frame, seconds, tracks, FrameResult.timings) per frame to OUT.json and prints the median,
the p95 and the 25 slowest frames with their four largest stages.
"""
import sys, time, json
import numpy as np
from pathlib import Path
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader
rec = Path(sys.argv[1]); n = int(sys.argv[2])
room = RoomCalibration.load(rec / 'calibration.yaml')
tr = Tracker(room, TrackerConfig(detection=True, seed=0), rng=np.random.default_rng(0))
out = []
with RecordingReader(rec) as reader:
    for fs in reader.frames():
        if fs.index >= n: break
        t0 = time.perf_counter()
        r = tr.step(fs.stamp_ns, fs.images)
        out.append((fs.index, time.perf_counter() - t0, len(r.tracks), {k: v for k, v in r.timings.items()}))
json.dump(out, open(sys.argv[3], 'w'))
tot = np.array([o[1] for o in out]) * 1e3
print('median', np.median(tot), 'p95', np.percentile(tot, 95))
for i in np.argsort(tot)[::-1][:25]:
    idx, t, k, tm = out[i]
    top = sorted(tm.items(), key=lambda kv: -kv[1])[:4]
    print(idx, f'{t*1e3:.0f} ms', k, [(a, round(b*1e3)) for a, b in top])
