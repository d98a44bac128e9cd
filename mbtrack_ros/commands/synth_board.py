"""``mbtrack synth-board OUTDIR``: rendered pictures of a calibration board in the synthetic
room, with the true calibration, to test ``mbtrack calibrate`` end to end."""
from __future__ import annotations

import argparse
import sys
import time

__all__ = ['add_parser', 'run']

_PROG = 'mbtrack synth-board'


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``synth-board``."""
    parser = subparsers.add_parser(
        'synth-board', help='render a calibration board on the synthetic room\'s floor',
        description='Render what each camera of the synthetic room (mbtrack synth) sees of '
                    'calibration boards lying on its floor (OUTDIR/floor/NAME.png), optionally '
                    'the first board held in front of each camera (OUTDIR/intrinsics/NAME/), '
                    'and write the true calibration (OUTDIR/calibration.yaml).')
    parser.add_argument('outdir', metavar='OUTDIR', help='output directory (must not exist or '
                                                         'be empty)')
    parser.add_argument('--board', action='append', default=None,
                        help='board spec as for mbtrack calibrate (repeatable; default '
                             'charuco:5:4:0.25:0.19:DICT_4X4_50)')
    parser.add_argument('--board-pose', action='append', default=[], metavar='X,Y,YAW',
                        help='floor pose of the n-th board (default: first board centred in '
                             'the room)')
    parser.add_argument('--width', type=int, default=640, help='image width (default 640)')
    parser.add_argument('--height', type=int, default=480, help='image height (default 480)')
    parser.add_argument('--camera-height', type=float, default=None, metavar='METRES',
                        help='height of the four corner cameras (default: the synthetic '
                             'room\'s 2.6 m)')
    parser.add_argument('--no-ceiling', action='store_true',
                        help='leave out the ceiling camera')
    parser.add_argument('--intrinsics-views', type=int, default=0, metavar='N',
                        help='also render N views of the board in front of each camera')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    return parser


def run(args: argparse.Namespace) -> int:
    """Render; 0 on success, 2 on bad input (one line on stderr)."""
    from mbtrack_ros.calibration.board import BoardPose, parse_board, parse_pose
    from mbtrack_ros.calibration.errors import CalibrateError
    from mbtrack_ros.synth.board import rig_calibration, write_board_images
    from mbtrack_ros.synth.errors import SynthError
    try:
        specs = args.board or ['charuco:5:4:0.25:0.19:DICT_4X4_50']
        boards = [parse_board(s) for s in specs]
        if len(args.board_pose) > len(boards):
            raise CalibrateError(f'{len(args.board_pose)} --board-pose for {len(boards)} '
                                 f'boards')
        poses = [parse_pose(p) for p in args.board_pose]
        for board in boards[len(poses):]:
            w, h = board.size
            # centred in the 6 x 5 m room (its y axis is the board's -y)
            poses.append(BoardPose(3.0 - 0.5 * w, 2.5 + 0.5 * h, 0.0))
        if args.intrinsics_views < 0:
            raise CalibrateError('--intrinsics-views must be >= 0')
        calibration = rig_calibration(args.width, args.height,
                                      camera_height=args.camera_height,
                                      ceiling=not args.no_ceiling)
        start = time.perf_counter()
        write_board_images(args.outdir, calibration, list(zip(boards, poses)),
                           intrinsics_views=args.intrinsics_views, seed=args.seed)
    except (CalibrateError, SynthError, OSError) as err:
        print(f'{_PROG}: error: {str(err).splitlines()[0]}', file=sys.stderr)
        return 2
    print(f'{_PROG}: wrote {args.outdir} ({len(calibration.names)} cameras, '
          f'{args.width}x{args.height}) in {time.perf_counter() - start:.1f} s; board poses: '
          + '; '.join(f'{p.x:g},{p.y:g},{p.yaw:g}' for p in poses), file=sys.stderr)
    return 0
