"""A/B of Tracker.step variants in one process, in alternating blocks of frames (same load;
docs/live_measurements.md, "Overlapped steps (h-pipe)").

Usage: python docs/step_ab.py RECORDING FRAMES OUT.json VARIANT [VARIANT ...]
(environment SWITCH=seconds sets sys.setswitchinterval, the GIL hand-over interval)
VARIANT: inline (foreground inside update, as before h-pipe), overlap (foreground on the
worker during the filter), pipe (overlap + TrackerConfig.pipeline_search), all three on the
colour likelihood alone (track_coverage 0, as they were measured); coverage (overlap +
AutoDetectionConfig.track_coverage 2, the default since the twenty-seventh session, the masks
joined once the colour kernels are done), coverage_first (the same, the masks joined before
the filter starts).
Frames are read per block of 25 sets, then each variant steps the block back to back as the
node does (step(search=False), [publish], search()); a variant's worker is drained at the
end of its block (counted in its block wall time). Per frame: pre-publish wall (step start
to result), post (search()), CPU of the process (all threads).
"""
import os, sys, time, json
import numpy as np
from pathlib import Path
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader
rec = Path(sys.argv[1]); n = int(sys.argv[2]); variants = sys.argv[4:]
BLOCK = 25
if os.environ.get('SWITCH'):
    sys.setswitchinterval(float(os.environ['SWITCH']))
room = RoomCalibration.load(rec / 'calibration.yaml')
trackers = {}
for v in variants:
    tr = Tracker(room, TrackerConfig(detection=True, seed=0, pipeline_search=v == 'pipe',
                                     track_coverage=2.0 if v.startswith('coverage') else 0.0),
                 rng=np.random.default_rng(0))
    if v == 'inline':
        tr.detection.start_foreground = lambda images: None
    if v == 'coverage_first':
        def first(masks, gain, given=tr.measurement.set_foreground):
            given(masks() if callable(masks) else masks, gain)
        tr.measurement.set_foreground = first
    trackers[v] = tr
out = {v: {'frames': [], 'wall': 0.0, 'cpu': 0.0} for v in variants}

def drain(tr):
    w = tr.detection._worker
    if w is not None:
        w.submit(lambda: None).result()

def run_block(block):
    for v, tr in trackers.items():
        c0 = time.process_time(); b0 = time.perf_counter()
        for fs in block:
            t0 = time.perf_counter()
            r = tr.step(fs.stamp_ns, fs.images, search=False)
            t1 = time.perf_counter()
            tr.search()
            t2 = time.perf_counter()
            out[v]['frames'].append((fs.index, t1 - t0, t2 - t1, len(r.tracks),
                                     dict(r.timings)))
        drain(tr)
        out[v]['wall'] += time.perf_counter() - b0
        out[v]['cpu'] += time.process_time() - c0

block = []
with RecordingReader(rec) as reader:
    for fs in reader.frames():
        if fs.index >= n: break
        block.append(fs)
        if len(block) == BLOCK:
            run_block(block); block = []
if block:
    run_block(block)
json.dump(out, open(sys.argv[3], 'w'))
for v, o in out.items():
    rows = o['frames'][75:]
    a = np.array([r[1:3] for r in rows]) * 1e3
    bg = np.array([r[4].get('detect_background', 0.0) for r in rows]) * 1e3
    print(f'{v:8s} pre-publish p50 {np.median(a[:,0]):.1f} p95 {np.percentile(a[:,0],95):.1f} | '
          f'search() p50 {np.median(a[:,1]):.1f} p95 {np.percentile(a[:,1],95):.1f} | '
          f'foreground wait p50 {np.median(bg):.1f} p95 {np.percentile(bg,95):.1f} | '
          f'all frames: wall {o["wall"]:.1f} s CPU {o["cpu"]:.1f} s -> {len(o["frames"])/o["wall"]/15:.2f}x real time')
