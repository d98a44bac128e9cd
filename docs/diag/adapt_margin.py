"""Appearance margin of the tracks' models, adapted against acquired (h-adapt,
docs/detection.md "Appearance adaptation").

    .venv/bin/python docs/diag/adapt_margin.py REC RATE [--frames N] [--seed S] [--near M]

Tracks ``REC`` with automatic detection and ``AutoDetectionConfig.adaptation.rate`` RATE
(0: no adaptation) and keeps a copy of every track's model as acquired. On every detection
frame set, each reported track within 0.5 m of a ground-truth person p whose nearest
other person q is within M metres (default 1.5) is scored under both models: per side
camera that the ground truth lists as seeing both and where both silhouettes (the track's
shape and orientation, at p's and q's floor places) are at least half inside the image,
``log p(y | p) - log p(y | q)`` (003 Eq. 3, the tracker's likelihood) - how much better the
model explains its own person than the nearest other one; the mean over cameras is the
margin. Prints the margin quartiles and the share of positive margins for both models
(paired: same tracks, frames and cameras), and the adaptation's decisions.
"""
from __future__ import annotations

import argparse
import copy
import time
from dataclasses import replace
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from mbtrack_ros.core.appearance import quantize, relative_angle, single_target_loglik
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.shape import rasterize
from mbtrack_ros.core.state import SIT, THETA, X, Y
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader


def _truth(path: Path) -> dict[int, list[tuple[int, float, float, bool, set[str]]]]:
    """frame -> [(person, x, y, sitting, cameras seeing them)] of ground_truth.csv."""
    out: dict[int, list] = {}
    for line in path.read_text().splitlines()[1:]:
        f = line.split(',')
        out.setdefault(int(f[1]), []).append(
            (int(f[2]), float(f[3]), float(f[4]), f[6] == '1', set(f[7].split(';'))))
    return out


def _margin(model, bins, cal, side, theta, p, q) -> float | None:
    states = np.zeros((2, 6))
    states[:, THETA] = theta
    states[0, [X, Y]], states[1, [X, Y]] = p[1:3], q[1:3]
    states[0, SIT], states[1, SIT] = float(p[3]), float(q[3])
    gains = []
    for n in side:
        if n not in p[4] or n not in q[4]:
            continue
        cam = cal.cameras[n]
        sil = rasterize(cam, states, model.shape)
        if np.any(sil.area < 0.5 * np.maximum(sil.full_area, 1)) or np.any(sil.area <= 0):
            continue
        rel = relative_angle(states[:, THETA], cam.viewing_angle(states[:, [X, Y]]))
        ll = single_target_loglik(bins[n], sil, model.interpolate(rel))
        gains.append(float(ll[0] - ll[1]))
    return float(np.mean(gains)) if gains else None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('rec', type=Path)
    ap.add_argument('rate', type=float)
    ap.add_argument('--frames', type=int, default=None)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--near', type=float, default=1.5)
    ap.add_argument('--set', action='append', default=[], metavar='FIELD=VALUE',
                    help='override an AdaptationConfig field, e.g. foreground_only=0')
    args = ap.parse_args(argv)
    truth = _truth(args.rec / 'ground_truth.csv')
    cal = RoomCalibration.load(args.rec / 'calibration.yaml')
    acquired: dict[int, object] = {}
    adapted, frozen, actions, seen = [], [], Counter(), []
    adapt_cpu = 0.0
    with RecordingReader(args.rec / 'bag') as reader:
        cal = cal.subset([n for n in cal.names if n in reader.cameras])
        tracker = Tracker(cal, TrackerConfig(seed=args.seed, detection=True,
                                             adaptation_rate=args.rate))
        det = tracker.detection
        over = {k: type(getattr(det.config.adaptation, k))(float(v))
                for k, v in (a.split('=', 1) for a in args.set)}
        det.config = replace(det.config, adaptation=replace(det.config.adaptation, **over))
        adapt, cpu = det._adapt, {'s': 0.0, 'n': 0}

        def timed_adapt(*a, **kw):   # CPU time of the adaptation step (process_time)
            c0 = time.process_time()
            adapt(*a, **kw)
            cpu['s'] += time.process_time() - c0
            cpu['n'] += 1

        det._adapt = timed_adapt
        add = tracker.add_track

        def keep_acquired(model, state, stamp_ns, track_id=None):
            tid = add(model, state, stamp_ns, track_id=track_id)
            acquired[tid] = copy.deepcopy(model)
            return tid

        tracker.add_track = keep_acquired
        side = tracker.detection.side
        frames = 0
        for fs in reader.frames():
            frames += 1
            if args.frames is not None and fs.index >= args.frames:
                break
            result = tracker.step(fs.stamp_ns, {c: im for c, im in fs.images.items()
                                                if c in cal.cameras})
            adapt_cpu += result.timings.get('detect_adapt', 0.0)
            actions.update(a['action'] for a in tracker.detection.adaptations)
            seen.extend((a['distance'], a['other']) for a in tracker.detection.adaptations)
            if 'detect_render' not in result.timings:
                continue
            people = truth.get(fs.index, [])
            if len(people) < 2 or not result.tracks:
                continue
            bins = {n: quantize(fs.images[n]) for n in side if n in fs.images}
            models = tracker.models
            for t in result.tracks:
                if t.track_id not in acquired or t.track_id not in models:
                    continue
                gap = [np.hypot(pp[1] - t.mean[X], pp[2] - t.mean[Y]) for pp in people]
                i = int(np.argmin(gap))
                if gap[i] > 0.5:
                    continue
                p = people[i]
                others = [pp for j, pp in enumerate(people) if j != i]
                d = [np.hypot(pp[1] - p[1], pp[2] - p[2]) for pp in others]
                q = others[int(np.argmin(d))]
                if min(d) > args.near:
                    continue
                a = _margin(models[t.track_id], bins, cal, side, t.mean[THETA], p, q)
                b = _margin(acquired[t.track_id], bins, cal, side, t.mean[THETA], p, q)
                if a is not None and b is not None:
                    adapted.append(a)
                    frozen.append(b)
    adapted, frozen = np.array(adapted), np.array(frozen)
    print(f'{args.rec.name} rate {args.rate} {args.set} seed {args.seed}: '
          f'{len(adapted)} track-frames (nearest other person within {args.near} m)')
    for name, m in (('acquired', frozen), ('adapted', adapted)):
        if len(m):
            q = np.percentile(m, [25, 50, 75])
            print(f'  {name:9s} margin quartiles {q[0]:7.2f} {q[1]:7.2f} {q[2]:7.2f} nats, '
                  f'mean {m.mean():6.2f}, positive {100 * np.mean(m > 0):5.1f} %')
    if len(adapted):
        print(f'  adapted - acquired: mean {np.mean(adapted - frozen):.2f}, '
              f'better in {100 * np.mean(adapted > frozen):.1f} % of track-frames')
    print('  adaptation decisions:', dict(actions), f'(adaptation step {adapt_cpu:.2f} s '
          f'wall, {cpu["s"]:.2f} s CPU in all over {frames} frame sets, called on '
          f'{cpu["n"]}: {1e3 * cpu["s"] / max(frames, 1):.2f} ms CPU per frame set)')
    if seen:
        own, other = np.array(seen).T
        pct = [10, 25, 50, 75, 90]
        print('  observed vs own model d2 percentiles 10/25/50/75/90',
              np.round(np.percentile(own, pct), 3), '; vs nearest other model',
              np.round(np.percentile(other, pct), 3))
    return 0


if __name__ == '__main__':
    sys.exit(main())
