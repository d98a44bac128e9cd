"""``mbtrack bench``: speed of the HJS, separable and joint filters on synthetic scenes.

Scenes are generated here, quickly and deterministically: a 6 m x 5 m room with 1 or 4
corner cameras (:func:`~mbtrack_ros.core.camera.look_at`), a noisy random background, and
K people painted as flat-coloured body-shape silhouettes (head / torso / legs, random
colours; :func:`~mbtrack_ros.core.shape.rasterize`, far to near). "Spread" scenes put the
people on a wide grid (few occlusions); "occluded" scenes pack them within about a metre of
the room centre (every camera sees overlapping people).

Per configuration the tracker is stepped over static frames at 15 Hz after a warm-up step
(numba compilation) and the median per-frame time of ``Tracker.step`` is reported, with
frames/s, HJS/separable ratios, scaling exponents in K and N (least-squares fit of
``log t = a + b log K``) and the peak memory of the process. The median CPU time per step
(``time.process_time``, all threads of the process) is printed next to it, and the load
average before and after the run: on a machine shared with other jobs the wall-clock time
depends on the load, the CPU time much less.

The data-association baselines of 004 (``pdaf``, ``jpdaf``, ``jlf``;
:mod:`mbtrack_ros.core.association`) are timed in the same run on the same scenes (K = 2, 3,
5, N = 100 samples, 4 cameras 320x240, spread and occluded) next to HJS, with the ratio of
their time per frame to HJS's (also in ``--quick``, which stays well under a minute;
``--no-baselines`` leaves them out).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
import tracemalloc
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from mbtrack_ros.core.appearance import PersonModel, model_from_images
from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.state import STATE_DIM, THETA, VX, VY, X, Y
from mbtrack_ros.core.tracker import Tracker, TrackerConfig

__all__ = ['BenchResult', 'add_parser', 'bench_room', 'fit_exponent', 'paint_people',
           'run', 'run_config', 'scene_states']

_PROG = 'mbtrack bench'
BASELINES = ('pdaf', 'jpdaf', 'jlf')  # 004 association baselines (--baselines)
BASELINE_KS = (2, 3, 5)
FLOOR = (0.0, 0.0, 6.0, 5.0)


def bench_room(n_cameras: int, width: int, height: int) -> RoomCalibration:
    """A 6 x 5 m room with ``n_cameras`` (1-4) corner cameras at 2.6 m, images W x H."""
    corners = [(0.05, 0.05), (5.95, 4.95), (5.95, 0.05), (0.05, 4.95)]
    cams = {}
    f = 0.75 * width
    for i in range(n_cameras):
        cx, cy = corners[i]
        R, t = look_at((cx, cy, 2.6), (3.0, 2.5, 0.8))
        K = [[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]]
        cams[f'cam{i}'] = Camera(name=f'cam{i}', width=width, height=height, K=K, dist=[],
                                 R=R, t=t)
    return RoomCalibration(cameras=cams, floor=FLOOR)


def scene_states(k: int, *, occluded: bool, rng: np.random.Generator) -> np.ndarray:
    """(k, 6) standing people, walking slowly: on a wide grid, or packed at the centre."""
    states = np.zeros((k, STATE_DIM))
    if occluded:
        ang = 2 * np.pi * np.arange(k) / max(k, 1) + rng.uniform(0, 2 * np.pi)
        rad = 0.45 + 0.12 * (np.arange(k) % 3)
        states[:, X] = 3.0 + rad * np.cos(ang)
        states[:, Y] = 2.5 + rad * np.sin(ang)
    else:
        cols = int(np.ceil(np.sqrt(k)))
        rows = int(np.ceil(k / cols))
        gx = np.linspace(1.2, 4.8, cols) if cols > 1 else np.array([3.0])
        gy = np.linspace(1.0, 4.0, rows) if rows > 1 else np.array([2.5])
        pts = np.array([(x, y) for y in gy for x in gx])[:k]
        states[:, [X, Y]] = pts + rng.normal(0, 0.05, (k, 2))
    heading = rng.uniform(-np.pi, np.pi, k)
    states[:, VX] = 0.3 * np.cos(heading)
    states[:, VY] = 0.3 * np.sin(heading)
    states[:, THETA] = heading
    return states


def paint_people(calibration: RoomCalibration, states: np.ndarray, heights: np.ndarray,
                 colours: np.ndarray, backgrounds: dict[str, np.ndarray], *,
                 widths: np.ndarray | None = None, noise: float = 0.0,
                 rng: np.random.Generator | None = None) -> dict[str, np.ndarray]:
    """Paint people into every camera, far to near.

    Args:
        calibration: the cameras.
        states: (K, 6) people states.
        heights: (K,) metres.
        colours: (K, 3, 3) uint8 RGB colours of head, torso, legs.
        backgrounds: camera name -> (H, W, 3) uint8 background image.
        widths: (K,) metres (default 0.5).
        noise: std of additive Gaussian pixel noise (needs ``rng``).

    Returns:
        camera name -> (H, W, 3) uint8 RGB image.
    """
    k = states.shape[0]
    widths = np.full(k, 0.5) if widths is None else np.asarray(widths, np.float64)
    out = {}
    for name, cam in calibration.cameras.items():
        img = backgrounds[name].copy()
        if k:
            sil = rasterize(cam, states, BodyShape(), heights=np.asarray(heights, np.float64),
                            widths=widths)
            for i in np.argsort(-sil.distance):
                labels = sil.mask(int(i))
                for part in range(3):
                    img[labels == part + 1] = colours[i, part]
        if noise > 0 and rng is not None:
            img = np.clip(img + rng.normal(0, noise, img.shape), 0, 255).astype(np.uint8)
        out[name] = img
    return out


def _backgrounds(calibration: RoomCalibration, rng: np.random.Generator) -> dict[str, np.ndarray]:
    out = {}
    for name, cam in calibration.cameras.items():
        base = rng.integers(90, 170, size=3)
        img = base + rng.normal(0, 12, (cam.height, cam.width, 3))
        out[name] = np.clip(img, 0, 255).astype(np.uint8)
    return out


def _models(calibration: RoomCalibration, states: np.ndarray, heights: np.ndarray,
            colours: np.ndarray, backgrounds: dict[str, np.ndarray]) -> list[PersonModel]:
    models = []
    for i in range(states.shape[0]):
        imgs = paint_people(calibration, states[i:i + 1], heights[i:i + 1], colours[i:i + 1],
                            backgrounds)
        m = model_from_images(imgs, calibration, states[i], float(heights[i]), 0.5,
                              min_visible=0.3)
        if m.view_angles.size == 0:  # seen by no camera well enough: flat model of its colours
            m = model_from_images(imgs, calibration, states[i], float(heights[i]), 0.5,
                                  min_visible=0.0)
        models.append(m)
    return models


@dataclass
class BenchResult:
    """Timing of one configuration (seconds per frame: median over the timed frames)."""

    algorithm: str
    people: int
    particles: int
    cameras: int
    width: int
    height: int
    occluded: bool
    seconds_per_frame: float
    frames_per_second: float
    frames: int
    bp_iterations: float
    visible_fraction: float
    stage_ms: dict
    cpu_seconds_per_frame: float = float('nan')


def run_config(algorithm: str, k: int, n: int, n_cameras: int, size: tuple[int, int], *,
               occluded: bool, frames: int = 5, seed: int = 0,
               joint_particles: int | None = None) -> BenchResult:
    """Time ``frames`` tracker steps of one synthetic scene (after one warm-up step)."""
    rng = np.random.default_rng(seed)
    calibration = bench_room(n_cameras, *size)
    states = scene_states(k, occluded=occluded, rng=rng)
    heights = rng.uniform(1.6, 1.9, k)
    colours = rng.integers(0, 256, size=(k, 3, 3)).astype(np.uint8)
    backgrounds = _backgrounds(calibration, rng)
    images = paint_people(calibration, states, heights, colours, backgrounds)
    models = _models(calibration, states, heights, colours, backgrounds)
    cfg = TrackerConfig(algorithm=algorithm, particles=n,
                        joint_particles=joint_particles or 10 * n, seed=seed)
    tracker = Tracker(calibration, cfg, rng=np.random.default_rng(seed))
    for i in range(k):
        tracker.add_track(models[i], states[i], 0)
    period = 66_666_667
    tracker.step(period, images)  # warm-up: numba compilation, caches
    times, cpu, bp, vis = [], [], [], []
    stages: dict[str, list[float]] = {}
    for f in range(frames):
        c0 = time.process_time()
        res = tracker.step((f + 2) * period, images)
        cpu.append(time.process_time() - c0)      # all threads of the process
        times.append(res.timings['total'])
        for stage, sec in res.timings.items():
            stages.setdefault(stage, []).append(1e3 * sec)
        bp.append(tracker.filter.stats.get('bp_iterations', 0.0))
        vis.extend(v for t in res.tracks for v in t.visible_fraction.values() if v > 0)
    spf = float(np.median(times))
    return BenchResult(algorithm, k, n, n_cameras, size[0], size[1], occluded, spf,
                       1.0 / spf, frames, float(np.mean(bp)),
                       float(np.mean(vis)) if vis else float('nan'),
                       {k: float(np.median(v)) for k, v in stages.items()},
                       float(np.median(cpu)))


def _loadavg() -> float:
    """1-minute load average (NaN where the OS does not report it)."""
    try:
        return float(os.getloadavg()[0])
    except OSError:
        return float('nan')


def fit_exponent(x: Sequence[float], t: Sequence[float]) -> float:
    """Slope b of the least-squares fit ``log t = a + b log x``."""
    lx, lt = np.log(np.asarray(x, np.float64)), np.log(np.asarray(t, np.float64))
    A = np.stack([np.ones_like(lx), lx], axis=1)
    return float(np.linalg.lstsq(A, lt, rcond=None)[0][1])


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``bench``."""
    parser = subparsers.add_parser(
        'bench', help='time the HJS, separable and joint filters and the 004 baselines '
                      'on synthetic scenes',
        description='Per-frame time and frames/s of the tracker for K people, N particles, '
                    '1 and 4 cameras, two image sizes; HJS/separable ratios, scaling '
                    'exponents in K and N, occluded vs spread scenes, peak memory; the '
                    'PDAF/JPDAF/JLF baselines next to HJS with their time ratio to HJS.')
    parser.add_argument('--quick', action='store_true', help='a reduced grid (< 1 minute)')
    parser.add_argument('--json', type=Path, default=None, metavar='FILE',
                        help='also write all results as JSON')
    parser.add_argument('--frames', type=int, default=None,
                        help='timed frames per configuration (default 3 quick, 8 full)')
    parser.add_argument('--seed', type=int, default=0, help='scene seed')
    parser.add_argument('--no-baselines', dest='baselines', action='store_false',
                        help='leave out the 004 baselines pdaf, jpdaf, jlf (timed by default, '
                             'also with --quick, next to HJS: K = 2, 3, 5, N = 100, 4 cameras '
                             '320x240, spread and occluded)')
    # -- live benchmark (mbtrack_ros.commands.bench_live) --
    from mbtrack_ros.commands.bench_live import add_arguments as _live_arguments
    _live_arguments(parser)
    from mbtrack_ros.commands.bench_fusion import add_arguments as _fusion_arguments
    _fusion_arguments(parser)
    return parser


def _grid(quick: bool, baselines: bool = True) -> list[dict]:
    big, small = (320, 240), (200, 150)
    jobs = []

    def add(alg, k, n, cams, size, occ, group):
        jobs.append(dict(algorithm=alg, k=k, n=n, n_cameras=cams, size=size, occluded=occ,
                         group=group))

    ks = (1, 2, 3, 5) if quick else tuple(range(1, 9))
    ns = (50, 100, 200) if quick else (50, 100, 200, 500)
    for occ in (False, True):
        for k in ks:
            for alg in ('hjs', 'separable'):
                add(alg, k, 100, 4, big, occ, 'K')
    for n in ns:
        for alg in ('hjs', 'separable'):
            add(alg, 5, n, 4, big, False, 'N')
    for cams in (1, 4):
        for size in (small, big):
            for alg in ('hjs', 'separable'):
                add(alg, 5, 100, cams, size, False, 'cameras')
    joint_ks = (1, 2, 3) if quick else (1, 2, 3, 5)
    for k in joint_ks:
        add('joint', k, 100, 4, big, False, 'joint')
    if baselines:  # 004 baselines next to HJS on the same scenes (HJS results are shared)
        for occ in (False, True):
            for k in BASELINE_KS:
                for alg in ('hjs',) + BASELINES:
                    add(alg, k, 100, 4, big, occ, 'assoc')
    return jobs


def run(args: argparse.Namespace) -> int:
    """Run the benchmark grid, print tables and fits; 0 on success, 2 on bad arguments."""
    if getattr(args, 'live', False):  # live benchmark over DDS (bench_live)
        from mbtrack_ros.commands.bench_live import main_live
        return main_live(args)
    if getattr(args, 'fusion', None):  # one process vs camera stages (bench_fusion)
        from mbtrack_ros.commands.bench_fusion import main_fusion
        return main_fusion(args)
    frames = args.frames if args.frames is not None else (3 if args.quick else 8)
    if frames < 1:
        print(f'{_PROG}: error: --frames must be >= 1, got {frames}', file=sys.stderr)
        return 2
    from tqdm import tqdm

    jobs = _grid(args.quick, getattr(args, 'baselines', True))
    results: list[tuple[str, BenchResult]] = []
    load_before = _loadavg()
    t0 = time.perf_counter()
    seen: dict[tuple, BenchResult] = {}
    for job in tqdm(jobs, desc='bench', unit='config', file=sys.stderr,
                    disable=not sys.stderr.isatty()):
        key = (job['algorithm'], job['k'], job['n'], job['n_cameras'], job['size'],
               job['occluded'])
        if key not in seen:
            seen[key] = run_config(job['algorithm'], job['k'], job['n'], job['n_cameras'],
                                   job['size'], occluded=job['occluded'], frames=frames,
                                   seed=args.seed, joint_particles=10 * job['n'])
        results.append((job['group'], seen[key]))
    # peak memory of the main configuration, measured alone with tracemalloc
    tracemalloc.start()
    run_config('hjs', 5, 100, 4, (320, 240), occluded=False, frames=1, seed=args.seed)
    traced_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    summary = _report(seen, results, frames)
    from mbtrack_ros.commands.bench_detection import run_detection  # issue 4
    summary.update(run_detection(args))
    load_after = _loadavg()
    print(f'load average (1 min) before / after the run: {load_before:.2f} / {load_after:.2f} '
          f'on {os.cpu_count()} cores')
    summary.update({'load_before': load_before, 'load_after': load_after})
    summary.update({'peak_rss_mb': rss_mb, 'tracemalloc_peak_mb_hjs_k5_n100': traced_peak / 2**20,
                    'wall_seconds': time.perf_counter() - t0, 'frames_per_config': frames,
                    'quick': bool(args.quick)})
    print(f'peak memory: {rss_mb:.0f} MB resident (process), '
          f'{traced_peak / 2**20:.1f} MB traced by tracemalloc for HJS K=5 N=100 4x320x240')
    print(f'{_PROG}: {len(seen)} configurations in {summary["wall_seconds"]:.1f} s')
    if args.json is not None:
        doc = {'results': [dict(asdict(r), group=g) for g, r in results], 'summary': summary}
        try:
            args.json.write_text(json.dumps(doc, indent=1), encoding='utf-8')
        except OSError as err:
            print(f'{_PROG}: error: cannot write {args.json}: {err.strerror or err}',
                  file=sys.stderr)
            return 2
    return 0


def _report(seen: dict, results: list[tuple[str, BenchResult]], frames: int) -> dict:
    def get(alg, k, n, cams, size, occ):
        return seen.get((alg, k, n, cams, size, occ))

    print(f'{"group":8} {"alg":9} {"K":>2} {"N":>4} {"cams":>4} {"size":>8} {"occl":>5} '
          f'{"ms/frame":>9} {"frames/s":>9} {"cpu ms":>7} {"BP it":>5} {"vis":>5} '
          f'{"HJS/sep":>7}')
    done = set()
    for group, r in results:
        key = (group, r.algorithm, r.people, r.particles, r.cameras, r.width, r.occluded)
        if key in done:
            continue
        done.add(key)
        ratio = ''
        if r.algorithm == 'hjs':
            s = get('separable', r.people, r.particles, r.cameras, (r.width, r.height),
                    r.occluded)
            if s is not None:
                ratio = f'{r.seconds_per_frame / s.seconds_per_frame:.2f}'
        print(f'{group:8} {r.algorithm:9} {r.people:2d} {r.particles:4d} {r.cameras:4d} '
              f'{r.width:>4}x{r.height:<3} {str(r.occluded):>5} '
              f'{1e3 * r.seconds_per_frame:9.2f} {r.frames_per_second:9.1f} '
              f'{1e3 * r.cpu_seconds_per_frame:7.1f} '
              f'{r.bp_iterations:5.1f} {r.visible_fraction:5.2f} {ratio:>7}')
    summary: dict = {}
    big = (320, 240)
    for alg in ('hjs', 'separable'):
        for occ in (False, True):
            pts = sorted((r.people, r.seconds_per_frame) for g, r in results
                         if g == 'K' and r.algorithm == alg and r.occluded == occ)
            if len(pts) >= 2:
                b = fit_exponent([p[0] for p in pts], [p[1] for p in pts])
                summary[f'exponent_K_{alg}_{"occluded" if occ else "spread"}'] = b
        pts = sorted((r.particles, r.seconds_per_frame) for g, r in results
                     if g == 'N' and r.algorithm == alg)
        if len(pts) >= 2:
            summary[f'exponent_N_{alg}'] = fit_exponent([p[0] for p in pts],
                                                        [p[1] for p in pts])
    main = get('hjs', 5, 100, 4, big, False)
    sep = get('separable', 5, 100, 4, big, False)
    for r in (main, sep):
        if r is not None:
            print(f'{r.algorithm} K=5 N=100 4x320x240 stages (median ms): '
                  + ', '.join(f'{k} {v:.1f}' for k, v in r.stage_ms.items()))
    if main is not None:
        summary['hjs_k5_n100_4x320x240_fps'] = main.frames_per_second
        summary['hjs_k5_n100_4x320x240_cpu_ms'] = 1e3 * main.cpu_seconds_per_frame
    if main is not None and sep is not None:
        summary['hjs_over_separable_k5_spread'] = main.seconds_per_frame / sep.seconds_per_frame
    main_occ = get('hjs', 5, 100, 4, big, True)
    sep_occ = get('separable', 5, 100, 4, big, True)
    if main_occ is not None and sep_occ is not None:
        summary['hjs_over_separable_k5_occluded'] = (main_occ.seconds_per_frame
                                                     / sep_occ.seconds_per_frame)
    summary.update(_report_baselines(seen))
    print()
    for key, value in summary.items():
        print(f'{key}: {value:.3g}')
    fps = summary.get('hjs_k5_n100_4x320x240_fps')
    if fps is not None:
        print(f'target K=5 N=100 4 cameras 320x240 >= 30 frames/s: '
              f'{"met" if fps >= 30 else "NOT met"} ({fps:.1f}; >= 50 wanted by issues 4 '
              f'and 5: {"met" if fps >= 50 else "NOT met"}; CPU '
              f'{summary["hjs_k5_n100_4x320x240_cpu_ms"]:.1f} ms per frame)')
    r = summary.get('hjs_over_separable_k5_spread')
    if r is not None:
        print(f'target HJS/separable <= 2 without occlusion: {"met" if r <= 2 else "NOT met"} '
              f'({r:.2f})')
    b = summary.get('exponent_K_hjs_occluded')
    if b is not None:
        print(f'target HJS growth in K under occlusion <= K^2: '
              f'{"met" if b <= 2.0 else "NOT met"} (exponent {b:.2f})')
    return summary


def _report_baselines(seen: dict) -> dict:
    """Table of the 004 baselines next to HJS; summary keys ``<alg>_k<K>_<scene>_over_hjs``."""
    big = (320, 240)
    rows = [(occ, k) for occ in (False, True) for k in BASELINE_KS
            if any((alg, k, 100, 4, big, occ) in seen for alg in BASELINES)]
    summary: dict = {}
    if not rows:
        return summary
    print()
    print('004 baselines vs HJS, N = 100, 4 cameras 320x240 (frames/s, time per frame / HJS)')
    print(f'{"scene":8} {"K":>2} ' + ' '.join(f'{a:>16}' for a in ('hjs',) + BASELINES))
    for occ, k in rows:
        hjs = seen.get(('hjs', k, 100, 4, big, occ))
        scene = 'occluded' if occ else 'spread'
        cells = []
        for alg in ('hjs',) + BASELINES:
            r = seen.get((alg, k, 100, 4, big, occ))
            if r is None:
                cells.append(f'{"-":>16}')
                continue
            ratio = ''
            if alg != 'hjs' and hjs is not None:
                ratio = r.seconds_per_frame / hjs.seconds_per_frame
                summary[f'{alg}_k{k}_{scene}_over_hjs'] = ratio
                ratio = f'{ratio:.2f}x'
            cells.append(f'{r.frames_per_second:8.1f} {ratio:>7}')
        print(f'{scene:8} {k:2d} ' + ' '.join(cells))
    return summary
