"""``mbtrack bench --fusion``: one process against camera stages + a fusion tracker.

Generates fresh recordings of a preset (one per ``--fusion-seeds`` seed) at the preset's
image size (as ``mbtrack synth`` renders it), tracks each both ways
(:func:`mbtrack_ros.evaluation.fusion.fusion_vs_single`) with the tracker configuration and
frame-set synchroniser of ``mbtrack replay REC --seed S`` (so that the one-process MOTA is
the replay's), and prints per recording the CLEAR MOT scores of both, the frames with the
same ids, the position gaps, and the CPU time per frame set of the one process, the camera
stages and the fusion tracker (run one after another in this process), with the share of
the fusion tracker's step in its filter and its detection; the same CPU after the
start-up (the frame sets once every camera stage gives a foreground: without the
background bootstrap and the fusion node's people cue, what a long run costs per frame
set); and what reading one camera's frame costs the fusion tracker in each encoding of
``camera_node`` (raw or PNG masks, raw or JPEG images). The camera stages score the
fusion tracker's particles in their cameras (the bytes of a request and its reply per
camera and frame set are printed); ``--fusion-tracker-likelihood`` leaves that to the
fusion tracker.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

__all__ = ['add_arguments', 'main_fusion']

_PROG = 'mbtrack bench'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``--fusion`` options of ``mbtrack bench``."""
    parser.add_argument('--fusion', metavar='PRESET', default=None,
                        help='instead of the filter grid: track fresh recordings of PRESET in '
                             'one process and as camera stages + fusion tracker, compare '
                             '(MOTA, ids, position gaps)')
    parser.add_argument('--fusion-seeds', type=int, nargs='+', default=[200, 201],
                        metavar='S', help='recording seeds of --fusion (default 200 201)')
    parser.add_argument('--fusion-frames', type=int, default=None, metavar='N',
                        help='frames of each --fusion recording (default: the preset\'s)')
    parser.add_argument('--fusion-jpeg', type=int, default=None, metavar='Q',
                        help='the camera stages send their working images JPEG-coded at '
                             'quality Q (1-100; camera_node image_format jpeg, jpeg_quality '
                             'Q) instead of raw')
    parser.add_argument('--fusion-tracker-likelihood', action='store_true',
                        help='the fusion tracker scores its particles in every camera '
                             'itself instead of asking the camera stages')


def main_fusion(args: argparse.Namespace) -> int:
    """Run the comparison; 0 on success, 2 on a bad preset or frame count."""
    if args.fusion_frames is not None and args.fusion_frames < 1:
        print(f'{_PROG}: error: --fusion-frames must be >= 1, got {args.fusion_frames}',
              file=sys.stderr)
        return 2
    if args.fusion_jpeg is not None and not 1 <= args.fusion_jpeg <= 100:
        print(f'{_PROG}: error: --fusion-jpeg must be 1-100, got {args.fusion_jpeg}',
              file=sys.stderr)
        return 2
    from mbtrack_ros.commands.replay import sync_options
    from mbtrack_ros.core.camera import RoomCalibration
    from mbtrack_ros.core.tracker import TrackerConfig
    from mbtrack_ros.evaluation.clear_mot import clear_mot
    from mbtrack_ros.evaluation.fusion import fusion_vs_single
    from mbtrack_ros.recording.csvfiles import read_ground_truth
    from mbtrack_ros.synth.errors import SynthError
    from mbtrack_ros.synth.generator import generate
    from mbtrack_ros.synth.presets import get_preset

    tmp = Path(tempfile.mkdtemp(prefix='mbtrack_fusion_'))
    doc = []
    try:
        for seed in args.fusion_seeds:
            rec = tmp / f'{args.fusion}-{seed}'
            try:   # at the preset's image size, as mbtrack synth renders it
                width, height = get_preset(args.fusion).size
                generate(args.fusion, rec, seed=seed, frames=args.fusion_frames,
                         width=width, height=height)
            except SynthError as err:
                print(f'{_PROG}: error: {err}', file=sys.stderr)
                return 2
            # what `mbtrack replay REC --seed S` runs: its default tracker configuration
            # and frame-set synchroniser
            config = TrackerConfig.from_dict({'seed': args.seed, 'detection': True})
            calibration = RoomCalibration.load(rec / 'calibration.yaml')
            got = fusion_vs_single(rec, config, sync_options(rec, calibration),
                                   jpeg_quality=args.fusion_jpeg,
                                   stage_likelihood=not args.fusion_tracker_likelihood)
            truth = read_ground_truth(rec / 'ground_truth.csv')
            m = {k: clear_mot(rows, truth) for k, rows in got.rows.items()}
            gaps = np.array(got.gaps or [0.0])
            codec = 'raw' if args.fusion_jpeg is None else f'JPEG {args.fusion_jpeg}'
            print(f'{args.fusion} seed {seed} (working images {codec}): MOTA one process '
                  f'{100 * m["single"].mota:.1f} / fusion {100 * m["fusion"].mota:.1f}, '
                  f'MOTP {m["single"].motp_mm:.0f} / '
                  f'{m["fusion"].motp_mm:.0f} mm, switches {m["single"].mismatches} / '
                  f'{m["fusion"].mismatches}; same ids on {got.same_ids}/{got.frames} frame '
                  f'sets; position gap median {1e3 * np.median(gaps):.1f} mm, max '
                  f'{1e3 * gaps.max():.1f} mm', flush=True)
            ms = {k: 1e3 * v / max(got.frames, 1) for k, v in got.cpu.items()}
            ft = got.fusion_timings
            share = {k: 100 * v / max(ft['total'], 1e-9) for k, v in ft.items()}
            print(f'  CPU per frame set ({len(calibration.cameras)} cameras): one process '
                  f'{ms["single"]:.1f} ms; camera stages {ms["stages"]:.1f} ms '
                  f'({ms["stages"] / len(calibration.cameras):.1f} ms per camera); fusion '
                  f'tracker {ms["fusion"]:.1f} ms = {ms["fusion"] / max(ms["single"], 1e-9):.2f}'
                  f' of one process; its step: filter {share["filter"]:.0f} %, search for '
                  f'new people {share["detect_search"]:.0f} %, other detection '
                  f'{share["detect"] - share["detect_search"]:.0f} %', flush=True)
            n_steady = max(got.steady_frames, 1)
            steady = {k: 1e3 * v / n_steady for k, v in got.steady_cpu.items()}
            boot = {k: 1e3 * (got.cpu[k] - got.steady_cpu[k]) for k in got.cpu}
            print(f'  after the start-up ({got.steady_frames} frame sets from frame set '
                  f'{got.started}): one process {steady["single"]:.1f} ms, camera stages '
                  f'{steady["stages"] / len(calibration.cameras):.1f} ms per camera, fusion '
                  f'tracker {steady["fusion"]:.1f} ms = '
                  f'{steady["fusion"] / max(steady["single"], 1e-9):.2f} of one process; the '
                  f'start-up: one process {boot["single"]:.0f} ms, fusion tracker '
                  f'{boot["fusion"]:.0f} ms in all', flush=True)
            dec = {k: 1e3 * v / max(got.decode_frames, 1) for k, v in got.decode.items()}
            print(f'  reading one camera frame in the fusion tracker ({got.decode_frames} '
                  f'frames): masks PNG {dec["mask_png"]:.3f} ms, raw {dec["mask_raw"]:.3f} '
                  f'ms; image JPEG {dec["image_jpeg"]:.3f} ms, raw {dec["image_raw"]:.3f} ms',
                  flush=True)
            if got.scored:
                kib = {k: v / 1024 / got.scored for k, v in got.score_bytes.items()}
                print(f'  particles scored by the camera stages: {got.scored} requests, '
                      f'{kib["request"]:.0f} KiB each, replies {kib["reply"]:.1f} KiB',
                      flush=True)
            doc.append({'seed': seed, 'jpeg_quality': args.fusion_jpeg,
                        'mota': {k: v.mota for k, v in m.items()},
                        'motp_mm': {k: v.motp_mm for k, v in m.items()},
                        'same_ids': got.same_ids, 'frames': got.frames,
                        'cpu_ms_per_frame_set': ms, 'fusion_step_share_percent': share,
                        'start_up_frame_sets': got.started,
                        'steady_cpu_ms_per_frame_set': steady,
                        'start_up_cpu_ms': boot, 'read_ms_per_camera_frame': dec,
                        'stage_likelihood': not args.fusion_tracker_likelihood,
                        'score_requests': got.scored,
                        'score_bytes': got.score_bytes,
                        'gap_median_m': float(np.median(gaps)), 'gap_max_m': float(gaps.max())})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if args.json is not None:
        try:
            args.json.write_text(json.dumps({'preset': args.fusion, 'runs': doc}, indent=1),
                                 encoding='utf-8')
        except OSError as err:
            print(f'{_PROG}: error: cannot write {args.json}: {err.strerror or err}',
                  file=sys.stderr)
            return 2
    return 0
