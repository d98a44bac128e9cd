"""When the track of a person who walks out is released (fifteenth session).

Usage: walk_out.py [--no-ceiling] [--doorway-band B] [--exit-margin M] [--reach-radius R]
                   [--paper-motion] [--seed S]

Tracks test_exits' walk-out clip (one person comes in, stands, leaves through the door;
synth seed 4, tracker seed S, default 0) with the given release settings (default: the
defaults) and prints the frame of the person's last ground-truth row, the frame the track
that followed her then was released (as test_release_doorway times it), the delay in
seconds, and the track's place every 3 frames from frame 141 on.
"""
import argparse
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'test'))
from test_exits import _leaver  # noqa: E402

from mbtrack_ros.core.detection.release import Releaser  # noqa: E402
from mbtrack_ros.core.dynamics import MotionConfig  # noqa: E402
from mbtrack_ros.core.tracker import Tracker, TrackerConfig  # noqa: E402
from mbtrack_ros.synth import Synthesizer  # noqa: E402
from mbtrack_ros.synth.presets import Preset  # noqa: E402

p = argparse.ArgumentParser()
p.add_argument('--no-ceiling', action='store_true')
p.add_argument('--doorway-band', type=float)
p.add_argument('--exit-margin', type=float)
p.add_argument('--reach-radius', type=float)
p.add_argument('--paper-motion', action='store_true')
p.add_argument('--seed', type=int, default=0)
a = p.parse_args()
synth = Synthesizer(Preset('leaver', 'one person leaves', 200, None, _leaver), seed=4,
                    width=320, height=240, ceiling=not a.no_ceiling)
tracker = Tracker(synth.calibration, TrackerConfig(
    detection=True, seed=a.seed, motion=MotionConfig(orientation_follows_velocity=a.paper_motion)))
release = {k: v for k, v in (('doorway_band', a.doorway_band), ('exit_margin', a.exit_margin))
           if v is not None}
tracker.detection.releaser = Releaser(synth.calibration,
                                      replace(tracker.detection.releaser.config, **release))
if a.reach_radius is not None:
    tracker.detection.config = replace(tracker.detection.config, reach_radius=a.reach_radius)
last = ended = None
following: set[int] = set()     # the tracks alive at the person's last row
for frame in synth:
    res = tracker.step(frame.stamp_ns, frame.images)
    if frame.ground_truth:
        last, following = frame.index, set(tracker.track_ids)
    if frame.index >= 141 and frame.index % 3 == 0:
        print(frame.index, 'person', [(round(g.x, 2), round(g.y, 2)) for g in frame.ground_truth],
              'tracks', [(t.track_id, round(float(t.mean[0]), 2), round(float(t.mean[1]), 2))
                         for t in res.tracks])
    if ended is None and not frame.ground_truth and following & set(res.released):
        ended = frame.index
if ended is None:
    print(f'last ground-truth row {last}, not released')
else:
    print(f'last ground-truth row {last}, released {ended}, '
          f'delay {(ended - last) / synth.fps:.2f} s')
