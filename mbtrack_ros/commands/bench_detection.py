"""Detection cost for ``mbtrack bench`` (issue 4): ms per frame of the automatic detection
with nobody entering and with people entering, and the whole pipeline's frames/s.

Scenes are rendered with the synthetic smart room (:mod:`mbtrack_ros.synth`, the room of
the ``clear-room`` preset, 320x240, 15 Hz): five people walking in the room, with (5
cameras) and without (4 corner cameras) the ceiling camera. The background models are
bootstrapped from empty-room frames of the same seed (same camera gains and noise).

* **nobody entering** - :class:`~mbtrack_ros.core.tracker.Tracker` with detection, the five
  people tracked from the start (models acquired from the first frame): the detection
  stages (render, background, existence, release, search away from the tracks) per frame,
  and the whole pipeline (filter + detection + release) per frame and frames/s;
* **people entering** - :class:`~mbtrack_ros.core.detection.manager.AutoDetection` alone
  with no track: every frame the five people are candidates being refined and confirmed,
  the worst case of the search (the spikes of a frame where people walk in);
* **empty room** - nobody, the screen changing.

Times are medians (and maxima) of ``time.perf_counter`` around each step after one
warm-up frame (numba compilation, caches), with the CPU time of the process
(``time.process_time``, all threads) beside them: on a shared machine the wall-clock time
varies with the load.
"""
from __future__ import annotations

import time
import numpy as np

from mbtrack_ros.core.appearance import model_from_images
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection.acquisition import occluders
from mbtrack_ros.core.detection.manager import AutoDetection
from mbtrack_ros.core.shape import BodyShape
from mbtrack_ros.core.state import SIT, STATE_DIM, X, Y
from mbtrack_ros.core.tracker import Tracker, TrackerConfig

__all__ = ['bench_detection', 'print_detection']

PEOPLE = 5


def _walkers(crowd) -> None:
    for _ in range(PEOPLE):
        crowd.add(tuple(crowd.random_free_point(min_gap=0.9)), behaviour='room',
                  leave_time=1e6)


def _render(people: bool, frames: int, seed: int, ceiling: bool, size: tuple[int, int]
            ) -> tuple[RoomCalibration, list]:
    from mbtrack_ros.synth.generator import Synthesizer
    from mbtrack_ros.synth.presets import Preset

    preset = Preset('bench-detection', 'five people walking in the room' if people
                    else 'empty room', frames, None, _walkers if people else (lambda c: None))
    synth = Synthesizer(preset, seed=seed, ceiling=ceiling, width=size[0], height=size[1])
    return synth.calibration, list(synth)


def _bootstrap(auto: AutoDetection, empty: list) -> None:
    auto.bootstrap({n: [f.images[n] for f in empty] for n in empty[0].images})


def _ms(values: list[float]) -> dict:
    v = np.asarray(values, dtype=np.float64) * 1e3
    if v.size == 0:
        return {'median_ms': float('nan'), 'p90_ms': float('nan'), 'max_ms': float('nan')}
    return {'median_ms': float(np.median(v)), 'p90_ms': float(np.percentile(v, 90)),
            'max_ms': float(v.max())}


def _models(calibration: RoomCalibration, images: dict, truth: list) -> list:
    """(model, state) of every ground-truth person of a frame (key views where unoccluded)."""
    states = np.zeros((len(truth), STATE_DIM))
    heights = np.zeros(len(truth))
    for k, r in enumerate(truth):
        states[k, X], states[k, Y], states[k, SIT] = r.x, r.y, float(r.sitting)
        heights[k] = r.z_head
    out = []
    shapes = [BodyShape(height=float(h)) for h in heights]
    for k in range(len(truth)):
        others = np.delete(states, k, axis=0)
        oshapes = [s for j, s in enumerate(shapes) if j != k]
        side = {n: im for n, im in images.items()}
        occ = {n: occluders(calibration, states[k], others, oshapes, n, shape=shapes[k])
               for n in side}
        model = model_from_images(side, calibration, states[k], heights[k], 0.5,
                                  occluded=occ, min_visible=0.3)
        if model.view_angles.size:
            out.append((model, states[k]))
    return out


def _entering(cal: RoomCalibration, scene: list, empty: list) -> dict:
    auto = AutoDetection(cal)
    _bootstrap(auto, empty)
    total, cpu, search, found = [], [], [], 0
    for i, f in enumerate(scene):
        t0, c0 = time.perf_counter(), time.process_time()
        _, births = auto.step(f.stamp_ns, f.images, [], {})
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        found += len(births)
        if i:  # the first frame compiles and fills caches
            total.append(dt)
            cpu.append(dc)
            search.append(auto.timings['detect_search'])
    return {'cameras': len(cal.cameras), 'frames': len(total), 'detect': _ms(total),
            'detect_cpu': _ms(cpu), 'search': _ms(search), 'detections': found}


def _tracked(cal: RoomCalibration, scene: list, empty: list, seed: int) -> dict:
    tracker = Tracker(cal, TrackerConfig(detection=True, seed=seed),
                      rng=np.random.default_rng(seed))
    _bootstrap(tracker.detection, empty)
    total, cpu, detect, search, tracks = [], [], [], [], []
    initial: set[int] = set()
    born: set[int] = set()
    for i, f in enumerate(scene):
        if i == 0:
            side = tracker.detection.tracking_images(f.images)
            for model, state in _models(cal, side, f.ground_truth):
                initial.add(tracker.add_track(model, state, f.stamp_ns))
        c0 = time.process_time()
        result = tracker.step(f.stamp_ns, f.images)
        dc = time.process_time() - c0
        born |= set(tracker.track_ids) - initial
        if i:
            total.append(result.timings['total'])
            cpu.append(dc)
            detect.append(result.timings.get('detect', np.nan))
            search.append(result.timings.get('detect_search', np.nan))
            tracks.append(len(result.tracks))
    med = float(np.median(total)) if total else float('nan')
    return {'cameras': len(cal.cameras), 'frames': len(total), 'step': _ms(total),
            'step_cpu': _ms(cpu), 'detect': _ms(detect), 'search': _ms(search),
            'frames_per_second': 1.0 / med, 'births': len(born),
            'tracks_mean': float(np.mean(tracks)) if tracks else 0.0}


def _empty_room(cal: RoomCalibration, scene: list, empty: list) -> dict:
    auto = AutoDetection(cal)
    _bootstrap(auto, empty)
    total, cpu = [], []
    for i, f in enumerate(scene):
        t0, c0 = time.perf_counter(), time.process_time()
        auto.step(f.stamp_ns, f.images, [], {})
        if i:
            total.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    return {'cameras': len(cal.cameras), 'frames': len(total), 'detect': _ms(total),
            'detect_cpu': _ms(cpu)}


def bench_detection(*, frames: int = 30, seed: int = 0,
                    size: tuple[int, int] = (320, 240)) -> dict:
    """Detection and whole-pipeline timings (see the module docstring); plain dict.

    Args:
        frames: timed frames per scene (after one warm-up frame).
        seed: scene seed (people, clothing, camera gains).
        size: image width and height.
    """
    out: dict = {'size': tuple(size)}
    boot = 10
    for ceiling in (True, False):
        tag = '5cams' if ceiling else '4cams'
        _, empty = _render(False, boot + (frames + 1 if ceiling else 0), seed, ceiling, size)
        cal, scene = _render(True, frames + 1, seed, ceiling, size)
        out[f'entering_{tag}'] = _entering(cal, scene, empty[:boot])
        out[f'tracked_{tag}'] = _tracked(cal, scene, empty[:boot], seed)
        if ceiling:
            out[f'empty_{tag}'] = _empty_room(cal, empty[boot:], empty[:boot])
    return out


def print_detection(results: dict) -> dict:
    """Print the table of :func:`bench_detection`; returns summary keys for ``bench``."""
    print()
    size = results.get('size', (320, 240))
    print(f'detection (issue 4), {size[0]}x{size[1]}, synthetic room, {PEOPLE} people '
          '(ms per frame: median / 90 % / max)')
    summary: dict = {}
    for key, r in results.items():
        if key == 'size':
            continue
        scene, tag = key.rsplit('_', 1)
        d = r['detect']
        line = (f'{scene:9} {tag:6} detection {d["median_ms"]:6.1f} / {d["p90_ms"]:6.1f} / '
                f'{d["max_ms"]:6.1f}')
        if 'detect_cpu' in r:
            line += f'  (CPU {r["detect_cpu"]["median_ms"]:6.1f})'
        if 'search' in r:
            s = r['search']
            line += f'  search {s["median_ms"]:6.1f} / {s["max_ms"]:6.1f}'
        if 'step' in r:
            line += (f'  whole step {r["step"]["median_ms"]:6.1f} ms, CPU '
                     f'{r["step_cpu"]["median_ms"]:6.1f} ms '
                     f'({r["frames_per_second"]:.1f} frames/s, {r["tracks_mean"]:.1f} tracks)')
        print(line)
        summary[f'detect_{scene}_{tag}_ms'] = d['median_ms']
        summary[f'detect_{scene}_{tag}_max_ms'] = d['max_ms']
        if 'frames_per_second' in r:
            summary[f'pipeline_{tag}_fps'] = r['frames_per_second']
    fps = summary.get('pipeline_4cams_fps')
    if fps is not None:
        print(f'target detection + HJS + release, {PEOPLE} people, 4 cameras '
              f'{size[0]}x{size[1]} >= 15 frames/s: '
              f'{"met" if fps >= 15 else "NOT met"} ({fps:.1f})')
    return summary


def run_detection(args) -> dict:
    """``mbtrack bench`` hook: run, print and return the summary keys (``--quick``: 10
    frames per scene, otherwise 30; ``--seed`` picks the scene)."""
    frames = 10 if getattr(args, 'quick', False) else 30
    return print_detection(bench_detection(frames=frames, seed=int(getattr(args, 'seed', 0))))
