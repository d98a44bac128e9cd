"""Interleaved A/B timing of ``Tracker.step``: an older commit against the working tree.

Used for the speed section of docs/experiments_hjs.md. The machine is shared, so the two
versions run in one process on the same scene of ``mbtrack bench`` (K people, N = 100,
4 cameras 320x240), steps alternating old/new, and the median CPU time per step
(``time.process_time``, all threads) is reported next to the wall-clock time. The old
commit is exported with ``git archive`` and imported as package ``mbtrack_old``.

    .venv/bin/python docs/hjs_speed_ab.py e0ecd45 [--occluded] [--algorithm separable]
"""
from __future__ import annotations

import argparse
import importlib
import io
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _export(commit: str, dest: Path) -> None:
    """The old package under ``dest/mbtrack_old`` (every ``mbtrack_ros`` renamed)."""
    blob = subprocess.run(['git', '-C', str(REPO), 'archive', commit, 'mbtrack_ros'],
                          check=True, capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(blob)) as tar:
        tar.extractall(dest, filter='data')
    (dest / 'mbtrack_ros').rename(dest / 'mbtrack_old')
    for path in (dest / 'mbtrack_old').rglob('*.py'):
        path.write_text(path.read_text().replace('mbtrack_ros', 'mbtrack_old'))


def _tracker(pkg: str, algorithm: str, k: int, occluded: bool):
    bench = importlib.import_module(f'{pkg}.commands.bench')
    tracking = importlib.import_module(f'{pkg}.core.tracker')
    rng = np.random.default_rng(0)                    # the scene of bench.run_config, seed 0
    cal = bench.bench_room(4, 320, 240)
    states = bench.scene_states(k, occluded=occluded, rng=rng)
    heights = rng.uniform(1.6, 1.9, k)
    colours = rng.integers(0, 256, size=(k, 3, 3)).astype(np.uint8)
    backgrounds = bench._backgrounds(cal, rng)
    images = bench.paint_people(cal, states, heights, colours, backgrounds)
    models = bench._models(cal, states, heights, colours, backgrounds)
    tracker = tracking.Tracker(cal, tracking.TrackerConfig(algorithm=algorithm, particles=100,
                                                           seed=0),
                               rng=np.random.default_rng(0))
    for i in range(k):
        tracker.add_track(models[i], states[i], 0)
    return tracker, images


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('commit', help='old commit (e.g. e0ecd45)')
    parser.add_argument('--algorithm', default='hjs', choices=('hjs', 'separable'))
    parser.add_argument('--people', type=int, default=5)
    parser.add_argument('--occluded', action='store_true')
    parser.add_argument('--frames', type=int, default=40)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        _export(args.commit, Path(tmp))
        sys.path.insert(0, tmp)
        runs = {name: _tracker(pkg, args.algorithm, args.people, args.occluded)
                for name, pkg in (('old', 'mbtrack_old'), ('new', 'mbtrack_ros'))}
        period = 66_666_667
        for tracker, images in runs.values():
            tracker.step(period, images)              # warm-up: numba compilation
        cpu: dict[str, list[float]] = {n: [] for n in runs}
        wall: dict[str, list[float]] = {n: [] for n in runs}
        identical = True
        max_diff = 0.0
        for f in range(2, args.frames + 2):
            means = {}
            for name, (tracker, images) in runs.items():
                c0, w0 = time.process_time(), time.perf_counter()
                res = tracker.step(f * period, images)
                wall[name].append(time.perf_counter() - w0)
                cpu[name].append(time.process_time() - c0)
                means[name] = np.array([t.mean for t in res.tracks])
            identical &= bool(np.array_equal(means['old'], means['new']))
            max_diff = max(max_diff, float(np.max(np.abs(means['old'] - means['new']))))
    scene = 'occluded' if args.occluded else 'spread'
    for name in runs:
        print(f'{args.algorithm} K={args.people} N=100 4x320x240 {scene} {name}: CPU '
              f'{1e3 * np.median(cpu[name]):.1f} ms/frame, wall '
              f'{1e3 * np.median(wall[name]):.1f} ms/frame')
    print(f'identical track means over {args.frames} frames: {identical} (largest '
          f'difference {max_diff:.2e}); load average {os.getloadavg()[0]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
