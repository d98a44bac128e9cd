"""Filter speed tools of docs/live_measurements.md, "Filter speed (h-filt)" and "Filter
speed, outside the kernel (h-filt2)".

Usage (PYTHONPATH=<tree> /work/main/.venv/bin/python docs/filter_bench.py ...):
  capture REC FRAMES OUT.pkl    pickle HJSFilter.step's inputs (particles, weights, models,
                                images, generator state) on every 3rd frame with >= 5
                                tracks, at most 60, while stepping REC as step_profile.py does
  step CAPS.pkl OUT.npz REPS    run HJSFilter.step on each capture (fresh filter, same
                                generator state); print stage ms p50/p95 and CPU per step;
                                save the outputs for `compare`
  compare A.npz B.npz           how many saved arrays differ and by how much
  kernel CAPS.pkl OLD.py REPS [planar]
                                hjs_camera_ws of OLD.py (an older _kernels.py copied with
                                cache=False; its workspaces (H, W, K) unless `planar`)
                                against this tree's, alternating, same inputs: CPU per
                                frame and equality
  balance CAPS.pkl              per-camera kernel CPU (one thread) and the time two threads
                                need for the four kernels, cameras in calibration order or
                                longest first by the previous frame's times
  outside CAPS.pkl REPS         MeasurementModel.hjs on one thread over the captures: CPU per
                                frame, of it in hjs_camera_ws and the rest (outside the
                                kernel), ms p50; run it with the old and the new tree in turn
  predict                       CPU per predict() call on 100 particles (2000 calls)
  profile REC FRAMES OUT.json   step_profile.py plus process CPU time and the filter's track
                                count per frame
  table OUT.json...             p50/p95 of the stages over frames 75+, all and >= 5 tracks
"""
import copy
import dataclasses
import importlib.util
import json
import pickle
import sys
import time
from pathlib import Path

import numpy as np

from mbtrack_ros.core import _kernels, filters
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.likelihood import MeasurementModel
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader


def _frames(rec: Path, n: int):
    room = RoomCalibration.load(rec / 'calibration.yaml')
    tr = Tracker(room, TrackerConfig(detection=True, seed=0), rng=np.random.default_rng(0))
    with RecordingReader(rec) as reader:
        for fs in reader.frames():
            if fs.index >= n:
                break
            yield fs, tr


def capture(rec: str, n: str, out: str) -> None:
    caps, frame = [], [0]
    orig = filters.HJSFilter.step

    def step(self, dt, measurement, images, rng):
        if len(self._particles) >= 5 and len(caps) < 60 and frame[0] % 3 == 0:
            caps.append(dict(dt=dt, particles=copy.deepcopy(self._particles),
                             logw=copy.deepcopy(self._logw), models=dict(self._models),
                             images={k: v.copy() for k, v in measurement._images.items()},
                             rng=copy.deepcopy(rng.bit_generator.state), floor=self.floor,
                             config=self.config, camera_names=self.camera_names))
        return orig(self, dt, measurement, images, rng)

    filters.HJSFilter.step = step
    tr = None
    for fs, tr in _frames(Path(rec), int(n)):
        frame[0] = fs.index
        tr.step(fs.stamp_ns, fs.images)
    pickle.dump(dict(calib=str(Path(rec) / 'calibration.yaml'),
                     likelihood=tr.measurement.config, caps=caps), open(out, 'wb'))
    print(len(caps), 'frames captured')


def _model(d: dict, threads: int | None = None) -> MeasurementModel:
    cfg = d['likelihood'] if threads is None else dataclasses.replace(d['likelihood'],
                                                                      threads=threads)
    return MeasurementModel(RoomCalibration.load(d['calib']), cfg)


def step(caps: str, out: str, reps: str) -> None:
    d = pickle.load(open(caps, 'rb'))
    mm = _model(d)
    last = {}
    orig = mm.hjs

    def hjs(*a, **k):
        last['r'] = orig(*a, **k)
        return last['r']

    mm.hjs = hjs
    keys = ('predict', 'mrf', 'update', 'posterior', 'step', 'cpu')
    tim = {k: [] for k in keys}
    saved = {}

    def run(c):
        f = filters.HJSFilter(c['config'], floor=c['floor'], camera_names=c['camera_names'])
        f._particles = {k: v.copy() for k, v in c['particles'].items()}
        f._logw = {k: v.copy() for k, v in c['logw'].items()}
        f._models = dict(c['models'])
        rng = np.random.default_rng(0)
        rng.bit_generator.state = copy.deepcopy(c['rng'])
        mm.set_images(c['images'])
        c0, t0 = time.process_time(), time.perf_counter()
        u = f.step(c['dt'], mm, c['images'], rng)
        return f, u, time.perf_counter() - t0, time.process_time() - c0, rng

    for c in d['caps'][:2]:
        run(c)                                      # warm-up
    for rep in range(int(reps)):
        for i, c in enumerate(d['caps']):
            f, u, wall, cpu, rng = run(c)
            for k in keys[:4]:
                tim[k].append(f.timings[k])
            tim['step'].append(wall)
            tim['cpu'].append(cpu)
            if rep == 0:
                for tid, x in u.items():
                    for name, v in (('mean', x.mean), ('cov', x.covariance),
                                    ('p', x.particles), ('w', x.weights),
                                    ('vis', np.array(list(x.visible_fraction.values()))),
                                    ('logw', f._logw[tid])):
                        saved[f'{i}_{tid}_{name}'] = v
                saved[f'{i}_rng'] = rng.random(3)
    np.savez(out, **saved)
    print(' '.join(f'{k} {np.median(v) * 1e3:.2f}/{np.percentile(v, 95) * 1e3:.2f}'
                   for k, v in tim.items()), '(ms p50/p95)')


def compare(a: str, b: str) -> None:
    a, b = np.load(a), np.load(b)
    assert set(a.files) == set(b.files), 'different arrays'
    diff = [k for k in a.files if not np.array_equal(a[k], b[k])]
    worst = max((float(np.max(np.abs(a[k] - b[k]))) for k in diff), default=0.0)
    print(f'{len(a.files)} arrays, {len(diff)} differ, largest difference {worst:g}')


def kernel(caps: str, old: str, reps: str, layout: str = 'interleaved') -> None:
    spec = importlib.util.spec_from_file_location('old_kernels', old)
    ka = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ka)
    kb = _kernels
    d = pickle.load(open(caps, 'rb'))
    mm = _model(d, threads=1)
    calls, orig = [], kb.hjs_camera_ws

    def grab(*a):
        calls.append(a[:20])
        return orig(*a)

    kb.hjs_camera_ws = grab
    for c in d['caps']:
        ids = list(c['particles'])
        mm.set_images(c['images'])
        mm.hjs([c['particles'][t] for t in ids], [np.exp(c['logw'][t]) for t in ids],
               [c['models'][t] for t in ids])
    kb.hjs_camera_ws = orig
    h, w, ch = calls[0][0].shape + (8,)
    new_ws = (np.zeros((2 * ch, h, w)), np.zeros((ch, h, w)), np.empty((ch, h, w)))
    old_ws = new_ws if layout == 'planar' else (
        np.zeros((h, w, 2 * ch)), np.zeros((h, w, ch)), np.empty((h, w, ch)))
    ta, tb = np.zeros(len(calls)), np.zeros(len(calls))
    for a in calls[:4]:
        ka.hjs_camera_ws(*a, *old_ws)
        kb.hjs_camera_ws(*a, *new_ws)
    same = True
    for rep in range(int(reps)):
        for i, a in enumerate(calls):
            t0 = time.thread_time()
            ra = ka.hjs_camera_ws(*a, *old_ws)
            t1 = time.thread_time()
            rb = kb.hjs_camera_ws(*a, *new_ws)
            t2 = time.thread_time()
            ta[i] += t1 - t0
            tb[i] += t2 - t1
            same &= all(np.array_equal(x, y) for x, y in zip(ra, rb))
    fa = ta.reshape(-1, 4).sum(1) / int(reps) * 1e3
    fb = tb.reshape(-1, 4).sum(1) / int(reps) * 1e3
    print(f'kernel CPU ms per frame: old {np.median(fa):.2f} (p95 {np.percentile(fa, 95):.2f})'
          f' new {np.median(fb):.2f} (p95 {np.percentile(fb, 95):.2f}); identical: {same}')


def balance(caps: str) -> None:
    d = pickle.load(open(caps, 'rb'))
    mm = _model(d, threads=1)
    cost, orig = [], _kernels.hjs_camera_ws

    def timed(*a):
        t0 = time.thread_time()
        r = orig(*a)
        cost.append(time.thread_time() - t0)
        return r

    _kernels.hjs_camera_ws = timed
    for c in d['caps'] * 2:
        ids = list(c['particles'])
        mm.set_images(c['images'])
        mm._camera_cost.clear()                     # calibration order
        mm.hjs([c['particles'][t] for t in ids], [np.exp(c['logw'][t]) for t in ids],
               [c['models'][t] for t in ids])
    _kernels.hjs_camera_ws = orig
    per = np.array(cost[len(cost) // 2:]).reshape(len(d['caps']), -1) * 1e3

    def two_threads(costs, order):
        end = [0.0, 0.0]
        for i in order:
            end[int(np.argmin(end))] += costs[i]
        return max(end)

    in_order = [two_threads(c, range(len(c))) for c in per]
    longest = [two_threads(c, np.argsort(-per[max(i - 1, 0)], kind='stable'))
               for i, c in enumerate(per)]
    print('per camera ms (median)', np.round(np.median(per, axis=0), 2))
    for name, v in (('calibration order', in_order), ('longest first', longest),
                    ('even split', per.sum(1) / 2)):
        print(f'{name}: {np.median(v):.2f} / {np.percentile(v, 95):.2f} ms p50 / p95')


def outside(caps: str, reps: str) -> None:
    d = pickle.load(open(caps, 'rb'))
    mm = _model(d, threads=1)
    spent, orig = [0.0], _kernels.hjs_camera_ws

    def timed(*a):
        t0 = time.thread_time()
        r = orig(*a)
        spent[0] += time.thread_time() - t0
        return r

    _kernels.hjs_camera_ws = timed
    total, kern = [], []
    for rep in range(int(reps) + 1):                 # the first pass warms up
        for c in d['caps']:
            ids = list(c['particles'])
            spent[0] = 0.0
            t0 = time.thread_time()
            mm.set_images(c['images'])
            mm.hjs([c['particles'][t] for t in ids], [np.exp(c['logw'][t]) for t in ids],
                   [c['models'][t] for t in ids])
            if rep:
                total.append(time.thread_time() - t0)
                kern.append(spent[0])
    _kernels.hjs_camera_ws = orig
    total, kern = np.array(total) * 1e3, np.array(kern) * 1e3
    print(f'hjs CPU ms per frame p50 {np.median(total):.2f}: kernel {np.median(kern):.2f}, '
          f'outside the kernel {np.median(total - kern):.2f} '
          f'(p95 {np.percentile(total - kern, 95):.2f})')


def predict() -> None:
    from mbtrack_ros.core.dynamics import MotionConfig
    from mbtrack_ros.core.dynamics import predict as move
    p = np.zeros((100, 6))
    p[:, :4] = np.random.default_rng(2).normal(size=(100, 4))
    rng = np.random.default_rng(0)
    move(p, 1 / 15, MotionConfig(), rng, floor=(-2.0, -1.5, 2.5, 3.0))
    c0 = time.process_time()
    for _ in range(2000):
        move(p, 1 / 15, MotionConfig(), rng, floor=(-2.0, -1.5, 2.5, 3.0))
    print(f'predict: {(time.process_time() - c0) / 2000 * 1e6:.0f} us CPU per call')


def profile(rec: str, n: str, out: str) -> None:
    rows = []
    for fs, tr in _frames(Path(rec), int(n)):
        c0, t0 = time.process_time(), time.perf_counter()
        r = tr.step(fs.stamp_ns, fs.images)
        t1 = time.perf_counter()
        tm = dict(r.timings, cpu=time.process_time() - c0,
                  n_filter=len(tr.filter.track_ids()))
        rows.append((fs.index, t1 - t0, len(r.tracks), tm))
    json.dump(rows, open(out, 'w'))


def table(*paths: str) -> None:
    rows = ['before publishing', 'filter', 'update', 'predict', 'mrf', 'posterior', 'cpu']
    for five in (False, True):
        print('frames with >= 5 tracks' if five else 'frames 75+')
        for path in paths:
            out = [o for o in json.load(open(path))
                   if o[0] >= 75 and (not five or o[3].get('n_filter', 0) >= 5)]
            t = {k: np.array([o[3].get(k, 0.0) for o in out]) * 1e3
                 for k in rows + ['total', 'detect_search', 'detect_background_update']}
            t['before publishing'] = (t['total'] - t['detect_search']
                                      - t['detect_background_update'])
            print(f'  {path} n={len(out)}', ' | '.join(
                f'{k} {np.median(t[k]):.1f} / {np.percentile(t[k], 95):.1f}' for k in rows))


if __name__ == '__main__':
    dict(capture=capture, step=step, compare=compare, kernel=kernel, balance=balance,
         outside=outside, predict=predict, profile=profile,
         table=table)[sys.argv[1]](*sys.argv[2:])
