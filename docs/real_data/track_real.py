"""Track a recording with automatic detection, optionally with a clip-median background.

Usage: python docs/real_data/track_real.py RECORDING OUT_TRACKS.csv [--background first|median]
       [--seed S] [--algorithm hjs] [--report-hidden]

``first`` is what ``mbtrack replay`` does (the background model bootstraps from the first
frames of the recording); ``median`` bootstraps it from the per-pixel median of every frame of
the recording, the usual offline remedy when the room is never empty. Everything else is the
library's default configuration.
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader
from mbtrack_ros.recording.csvfiles import TrackRow, write_tracks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('recording')
    parser.add_argument('out')
    parser.add_argument('--background', choices=('first', 'median'), default='first')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--algorithm', default='hjs')
    parser.add_argument('--report-hidden', action='store_true',
                        help='also write tracks whose existence is below the report level')
    args = parser.parse_args()
    room = RoomCalibration.load(f'{args.recording}/calibration.yaml')
    with RecordingReader(args.recording) as reader:
        sets = [(fs.stamp_ns, fs.images) for fs in reader.frames()]
    tracker = Tracker(room, TrackerConfig(algorithm=args.algorithm, detection=True,
                                          seed=args.seed),
                      rng=np.random.default_rng(args.seed))
    if args.report_hidden:
        tracker.detection.config = replace(tracker.detection.config, report_hidden=True)
    if args.background == 'median':
        tracker.detection.bootstrap({c: [im[c] for _, im in sets] for c in room.names})
    rows, births = [], {}
    t0 = time.perf_counter()
    for frame, (stamp, images) in enumerate(sets):
        result = tracker.step(stamp, images)
        for t in result.tracks:
            births.setdefault(t.track_id, frame)
            rows.append(TrackRow(stamp_ns=stamp, frame=frame, track_id=t.track_id,
                                 x=float(t.mean[0]), y=float(t.mean[1]),
                                 existence=float(t.existence)))
    wall = time.perf_counter() - t0
    write_tracks(args.out, rows)
    print(f'{len(sets)} frames in {wall:.1f} s ({len(sets) / wall:.1f} frames/s), '
          f'tracks (id: first frame): {births}')


if __name__ == '__main__':
    main()
