"""Where the people cue puts the people of a recording's bootstrap frames.

Usage: cue_places.py REC [REC ...]

Runs :class:`~mbtrack_ros.core.detection.people.PeopleCue` on the first six frame sets of
each recording (the online bootstrap's), once with the greedy places only
(``refine_radius=0``) and once refined (the default), and prints each place with its
distance to the nearest ground-truth person of frame 5 and the time ``places`` took.
"""
import csv
import sys
import time
from pathlib import Path

import numpy as np

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection.people import PeopleCue, PeopleCueConfig
from mbtrack_ros.recording.bag import RecordingReader

for rec in map(Path, sys.argv[1:]):
    cal = RoomCalibration.load(rec / 'calibration.yaml')
    frames = []
    with RecordingReader(rec / 'bag') as reader:
        for fs in reader.frames():
            frames.append(fs.images)
            if len(frames) == 6:
                break
    cal = cal.subset(list(frames[0]))
    truth = [(float(r['x']), float(r['y'])) for r in csv.DictReader(open(rec / 'ground_truth.csv'))
             if r['frame'] == '5']
    for label, config in (('greedy', PeopleCueConfig(refine_radius=0.0)),
                          ('refined', PeopleCueConfig())):
        cue = PeopleCue(cal, config)
        start = time.perf_counter()
        places = cue.places(frames)
        seconds = time.perf_counter() - start
        shown = []
        for p in places:
            d = min(np.hypot(p[0] - g[0], p[1] - g[1]) for g in truth) if truth else np.nan
            shown.append(f'({p[0]:.1f}, {p[1]:.1f}) {d:.2f} m')
        print(f'{rec.name} {label} ({seconds:.2f} s): {len(truth)} people; places: '
              + '; '.join(shown))
