"""CPU time of the detection stages per frame set (docs/live_measurements.md, h-cpu).

Usage:
    python docs/stage_cpu.py run RECORDING FRAMES OUT.json
    python docs/stage_cpu.py table OUT.json...

``run`` steps the tracker as ``mbtrack replay`` does (seed 0) over the first FRAMES frame sets
and records per frame the *thread* CPU time (``time.thread_time``) of each detection stage
that runs on the caller's thread (``detect_render``, ``detect_existence``,
``detect_background_update``, ``detect_search``...: the stage clocks of
``AutoDetection`` are switched from wall to thread CPU time), the CPU of the foreground
(``BackgroundBank.apply``) and of the model update (``BackgroundBank.update_pending``) on
whichever thread they run, the wall time of the filter and the process CPU
time of the step. Run it with ``PYTHONPATH=<tree>`` to measure that tree. ``table`` prints
mean / p50 in ms over frames FIRST.. (default 50) of each file, side by side:
``table A.json B.json [FIRST]``.
"""
import json
import sys
import threading
import time
import types
from pathlib import Path

import numpy as np


def run(rec: Path, n: int, out: str) -> None:
    from mbtrack_ros.core.camera import RoomCalibration
    from mbtrack_ros.core.detection import background, manager
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig
    from mbtrack_ros.recording.bag import RecordingReader
    # the stage clocks of AutoDetection measure the calling thread's CPU time
    manager.time = types.SimpleNamespace(perf_counter=time.thread_time)
    spent: dict[str, float] = {}

    def timed(cls, method, key):
        """Wrap cls.method to add its thread CPU time to spent[key] (any thread)."""
        plain = getattr(cls, method)

        def wrapper(self, *a, **k):
            t = time.thread_time()
            try:
                return plain(self, *a, **k)
            finally:
                spent[key] = spent.get(key, 0.0) + time.thread_time() - t
        setattr(cls, method, wrapper)
    timed(background.BackgroundBank, 'apply', 'foreground_cpu')
    timed(background.BackgroundBank, 'update_pending', 'background_update_cpu')
    room = RoomCalibration.load(rec / 'calibration.yaml')
    tr = Tracker(room, TrackerConfig(detection=True, seed=0), rng=np.random.default_rng(0))
    rows = []
    with RecordingReader(rec) as reader:
        for fs in reader.frames():
            if fs.index >= n:
                break
            spent.clear()
            c0, t0 = time.process_time(), time.perf_counter()
            r = tr.step(fs.stamp_ns, fs.images)
            c1, t1 = time.process_time(), time.perf_counter()
            tm = dict(r.timings)
            tm.update(spent)
            tm['process_cpu'] = c1 - c0
            tm['wall'] = t1 - t0
            rows.append((fs.index, len(r.tracks), tm))
    json.dump({'module': __import__('mbtrack_ros').__file__, 'threads':
               threading.active_count(), 'rows': rows}, open(out, 'w'))
    print(out, __import__('mbtrack_ros').__file__)


KEYS = ('process_cpu', 'wall', 'filter', 'update', 'detect_render', 'foreground_cpu',
        'detect_existence', 'detect_background_update', 'background_update_cpu',
        'detect_search', 'detect')


def table(paths: list[str], first: int) -> None:
    data = [json.load(open(p)) for p in paths]
    print('ms mean / p50 over frames >=', first)
    print('stage'.ljust(26) + ''.join(Path(p).stem[:16].rjust(18) for p in paths))
    for key in KEYS:
        cells = []
        for d in data:
            v = np.array([r[2].get(key, np.nan) for r in d['rows'] if r[0] >= first]) * 1e3
            cells.append(f'{np.nanmean(v):7.2f} / {np.nanmedian(v):6.2f}')
        print(key.ljust(26) + ''.join(c.rjust(18) for c in cells))


if __name__ == '__main__':
    if sys.argv[1] == 'run':
        run(Path(sys.argv[2]), int(sys.argv[3]), sys.argv[4])
    elif sys.argv[1] == 'table':
        args = sys.argv[2:]
        first = 50
        if args and args[-1].isdigit():
            first = int(args.pop())
        table(args, first)
    else:
        raise SystemExit(__doc__)
