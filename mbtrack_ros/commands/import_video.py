"""``mbtrack import-video``: synchronised video files + calibration -> recording directory."""
from __future__ import annotations

import argparse
import math
import sys
from decimal import Decimal
from pathlib import Path

from mbtrack_ros.core.camera import CalibrationError
from mbtrack_ros.recording.calibration_io import FORMATS, UP_AXES, load_calibration
from mbtrack_ros.recording.video import EPOCH_NS, VideoImportError, import_videos

__all__ = ['add_parser', 'run']

_PROG = 'mbtrack import-video'


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``import-video``."""
    parser = subparsers.add_parser(
        'import-video', help='import synchronised videos of a calibrated rig as a recording',
        description='Build a recording directory (bag/ MCAP, calibration.yaml, recording.yaml, '
                    'optional ground_truth.csv) from synchronised video files that OpenCV can '
                    'read. Videos are given in the calibration\'s camera order or as name=path. '
                    'Differing frame counts are refused unless --shortest; a video whose size '
                    'differs from the calibration is accepted if it is a pure scale of it '
                    '(the calibration is scaled), else refused unless --fit-size.')
    parser.add_argument('outdir', type=Path, metavar='OUTDIR',
                        help='recording directory to create (must not exist or be empty)')
    parser.add_argument('videos', nargs='+', metavar='VIDEO',
                        help='video files in camera order, or NAME=PATH')
    parser.add_argument('--calibration', required=True, type=Path, metavar='FILE',
                        help='calibration file (for camera-info: the extrinsics file)')
    parser.add_argument('--calibration-format', default='auto',
                        choices=('auto', 'room') + FORMATS,
                        help='calibration format (default: guess from the file)')
    parser.add_argument('--camera-info', action='append', default=[], metavar='NAME=YAML',
                        help='camera_info YAML with the intrinsics of a camera '
                             '(camera-info format; repeat per camera)')
    parser.add_argument('--up-axis', default='z', choices=UP_AXES,
                        help='axis of the calibration\'s world frame that points up (default z)')
    parser.add_argument('--floor-offset', type=float, default=0.0, metavar='METRES',
                        help='floor coordinate along the up axis in the calibration frame')
    parser.add_argument('--floor', default=None, metavar='X0,Y0,X1,Y1',
                        help='walkable floor rectangle in metres, room frame (default: the '
                             'bounding box of the camera centres)')
    parser.add_argument('--fps', type=float, default=None,
                        help='frame rate for the stamps (default: the videos\')')
    parser.add_argument('--width', type=int, default=None, metavar='W',
                        help='resize to this width, keeping each video\'s aspect ratio')
    parser.add_argument('--start-offset', action='append', default=[], metavar='NAME=FRAMES',
                        help='skip FRAMES frames at the start of camera NAME (repeatable)')
    parser.add_argument('--frames', type=int, default=None, metavar='N',
                        help='import at most N frame sets')
    parser.add_argument('--shortest', action='store_true',
                        help='cut all videos to the shortest instead of refusing '
                             'differing frame counts')
    parser.add_argument('--fit-size', action='store_true',
                        help='stretch the calibration to a video whose aspect ratio differs')
    parser.add_argument('--compressed', action='store_true',
                        help='write JPEG CompressedImage instead of raw rgb8 Image')
    parser.add_argument('--reference', type=Path, default=None, metavar='TRC',
                        help='Pose2Sim TRC keypoints of the subject -> ground_truth.csv')
    parser.add_argument('--reference-offset', type=int, default=0, metavar='ROWS',
                        help='TRC row of recording frame 0 (default 0)')
    parser.add_argument('--start-time', type=float, default=EPOCH_NS / 1e9, metavar='SECONDS',
                        help='stamp of the first frame set, seconds since the epoch '
                             '(default 1.7e9, as mbtrack synth)')
    return parser


def _error(msg: str) -> int:
    print(f'{_PROG}: error: {msg}', file=sys.stderr)
    return 2


def _pairs(values: list[str], what: str) -> dict[str, str]:
    out = {}
    for value in values:
        name, sep, rest = value.partition('=')
        if not sep or not name or not rest:
            raise VideoImportError(f'{what} expects NAME=VALUE, got {value!r}')
        if name in out:
            raise VideoImportError(f'{what} given twice for camera {name}')
        out[name] = rest
    return out


def run(args: argparse.Namespace) -> int:
    """Import the videos; 0 on success, 2 on bad input (one line on stderr)."""
    try:
        named = ['=' in v and not Path(v).exists() for v in args.videos]
        if any(named) and not all(named):
            raise VideoImportError('give either all videos as NAME=PATH or none')
        videos = _pairs(args.videos, 'VIDEO') if all(named) else [Path(v) for v in args.videos]
        if isinstance(videos, dict):
            videos = {n: Path(p) for n, p in videos.items()}
        offsets = {}
        for name, value in _pairs(args.start_offset, '--start-offset').items():
            try:
                offsets[name] = int(value)
            except ValueError as err:
                raise VideoImportError(f'--start-offset {name}={value}: not a whole number '
                                       f'of frames') from err
        if not math.isfinite(args.start_time) or args.start_time < 0:
            raise VideoImportError(f'--start-time must be >= 0 seconds, got {args.start_time}')
        camera_info = _pairs(args.camera_info, '--camera-info') or None
        floor = None
        if args.floor is not None:
            try:
                floor = tuple(float(v) for v in args.floor.split(','))
            except ValueError as err:
                raise VideoImportError(f'--floor expects X0,Y0,X1,Y1 in metres, '
                                       f'got {args.floor!r}') from err
            if len(floor) != 4:
                raise VideoImportError(f'--floor expects 4 numbers X0,Y0,X1,Y1, '
                                       f'got {args.floor!r}')
        if args.calibration_format == 'camera-info' and not camera_info:
            raise VideoImportError('--calibration-format camera-info needs --camera-info '
                                   'NAME=YAML for each camera')
        calibration = load_calibration(
            args.calibration, args.calibration_format, camera_info=camera_info,
            up_axis=args.up_axis, floor_offset=args.floor_offset, floor=floor,
            warn=lambda line: print(f'{_PROG}: warning: {line}', file=sys.stderr))
        summary = import_videos(
            args.outdir, calibration, videos, fps=args.fps, width=args.width,
            start_offsets=offsets, compressed=args.compressed, reference=args.reference,
            reference_offset=args.reference_offset, shortest=args.shortest,
            max_frames=args.frames, fit_size=args.fit_size,
            start_ns=int(Decimal(str(args.start_time)) * 10**9),
            source={'calibration_file': str(args.calibration),
                    'calibration_format': args.calibration_format},
            note=lambda msg: print(f'{_PROG}: note: {msg}', file=sys.stderr))
    except (CalibrationError, VideoImportError) as err:
        return _error(str(err))
    except Exception as err:  # noqa: BLE001 - BagError / OSError from the writer: one line
        from mbtrack_ros.recording.bag import BagError
        if isinstance(err, (BagError, OSError)):
            return _error(str(err))
        raise
    sizes = sorted({f'{w}x{h}' for w, h in summary.sizes.values()})
    gt = f', {summary.ground_truth_rows} ground-truth rows' if args.reference else ''
    print(f'{_PROG}: wrote {summary.outdir}: {summary.frames} frame sets x '
          f'{len(summary.sizes)} cameras ({", ".join(sizes)}) at {summary.fps:g} fps{gt}')
    return 0
