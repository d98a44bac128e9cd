"""``mbtrack calibrate``: calibrate a room's cameras with a printed board and check the result.

``board`` writes the printable board, ``intrinsics`` solves each camera's lens from views of
the board held in front of it, ``extrinsics`` places the cameras in the room from pictures of
the board lying on the floor and writes the room (floor, entry zones, exits) with them,
``room`` rewrites the room of a calibration, ``check`` draws the calibration over the
cameras' images and from above.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from mbtrack_ros.commands import one_line_error

__all__ = ['add_parser', 'run']

_PROG = 'mbtrack calibrate'
_BOARD_HELP = ('board: charuco:COLS:ROWS:SQUARE_M:MARKER_M:DICT[:FIRST_ID] (e.g. '
               'charuco:5:4:0.25:0.19:DICT_4X4_50) or chessboard:COLS:ROWS:SQUARE_M')


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``calibrate`` and its actions."""
    parser = subparsers.add_parser(
        'calibrate', help='calibrate the cameras against the floor with a printed board',
        description='Calibrate a room\'s cameras with a printed board (docs/user_guide.md, '
                    '"Calibrate your room"): '
                    'board -> print it; intrinsics -> each camera\'s lens; extrinsics -> the '
                    'cameras in the room frame of the board on the floor, plus the room; '
                    'check -> pictures to verify it by eye.')
    actions = parser.add_subparsers(dest='action', metavar='ACTION')

    p = actions.add_parser('board', help='write the printable board (PNG, A4 sheets when '
                                         'large)')
    p.add_argument('board', metavar='BOARD', help=_BOARD_HELP)
    p.add_argument('out', type=Path, metavar='OUT.png')
    p.add_argument('--dpi', type=float, default=150.0, help='print resolution (default 150)')
    p.add_argument('--one-image', action='store_true',
                   help='one image of the whole board, not split into A4 sheets')

    p = actions.add_parser('intrinsics', help='lens of each camera from views of the board '
                                              'held in front of it')
    p.add_argument('out', type=Path, metavar='OUT.yaml')
    p.add_argument('sources', nargs='+', metavar='NAME=SOURCE',
                   help='camera name = image folder or video of the board moved in front '
                        'of it')
    p.add_argument('--board', required=True, help=_BOARD_HELP)
    p.add_argument('--max-frames', type=int, default=300,
                   help='frames read per source at most, evenly spread (default 300)')

    p = actions.add_parser('extrinsics', help='camera poses from the board lying on the '
                                              'floor, plus the room')
    p.add_argument('out', type=Path, metavar='OUT.yaml')
    p.add_argument('sources', nargs='+', metavar='NAME=SOURCE',
                   help='camera name = image, image folder or short video of the floor '
                        'with the board(s); corners are averaged over the frames')
    p.add_argument('--intrinsics', required=True, type=Path, metavar='CAL.yaml',
                   help='intrinsics of the cameras (from "calibrate intrinsics" or a room '
                        'calibration)')
    p.add_argument('--board', action='append', required=True,
                   help=_BOARD_HELP + '; repeat for several boards with distinct marker ids, '
                        'or give a YAML file: boards: [{board: SPEC, pose: [X, Y, YAW]}]')
    p.add_argument('--board-pose', action='append', default=[], metavar='X,Y,YAW',
                   help='floor pose of the n-th --board: its origin at room (X, Y) metres, '
                        'its x axis YAW degrees from the room x axis (default 0,0,0 for the '
                        'first board, which defines the room frame)')
    _room_options(p)
    p.add_argument('--max-frames', type=int, default=50,
                   help='frames read per video at most (default 50)')

    p = actions.add_parser('room', help='set the floor, entry zones and exits of a '
                                        'calibration')
    p.add_argument('calibration', type=Path, metavar='CAL.yaml')
    p.add_argument('out', type=Path, metavar='OUT.yaml')
    _room_options(p)

    p = actions.add_parser('check', help='draw the calibration over the cameras\' images and '
                                         'from above')
    p.add_argument('calibration', type=Path, metavar='CAL.yaml')
    p.add_argument('sources', nargs='*', metavar='SOURCE',
                   help='a recording directory (first frame of each camera) or NAME=PATH '
                        'images/videos; none: grey images')
    p.add_argument('--out', type=Path, required=True, metavar='DIR',
                   help='folder for NAME.png per camera and top.png')
    p = actions.add_parser('compare', help='differences between two calibrations of the same '
                                           'cameras (e.g. a recovered one and the truth)')
    p.add_argument('reference', type=Path, metavar='REFERENCE.yaml')
    p.add_argument('calibration', type=Path, metavar='CAL.yaml')
    for sub in actions.choices.values():
        sub.error = one_line_error(sub.prog)
    return parser


def _room_options(p: argparse.ArgumentParser) -> None:
    p.add_argument('--floor', metavar='X0,Y0,X1,Y1',
                   help='walkable floor rectangle, metres (default: the bounding box of the '
                        'camera centres)')
    p.add_argument('--entry-zone', action='append', default=[], metavar='X0,Y0,X1,Y1',
                   help='floor rectangle where people enter (repeatable)')
    p.add_argument('--exit', action='append', default=[], metavar='X0,Y0,X1,Y1',
                   help='rectangle beyond a door, outside the floor and sharing its border '
                        '(repeatable)')
    p.add_argument('--room', type=Path, metavar='ROOM.yaml',
                   help='YAML with floor: [X0, Y0, X1, Y1], entry_zones: [[...]], exits: '
                        '[[...]] (the options above override it)')


def _error(msg: str) -> int:
    print(f'{_PROG}: error: {msg}', file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    """Run one action; 0 on success, 2 on bad input (one line on stderr)."""
    from mbtrack_ros.calibration.errors import CalibrateError
    from mbtrack_ros.core.camera import CalibrationError

    action = getattr(args, 'action', None)
    if action is None:
        return _error('give an action: board, intrinsics, extrinsics, room, check or compare')
    try:
        return {'board': _board, 'intrinsics': _intrinsics, 'extrinsics': _extrinsics,
                'room': _room, 'check': _check, 'compare': _compare}[action](args)
    except (CalibrateError, CalibrationError) as err:
        return _error(str(err).splitlines()[0])
    except OSError as err:
        return _error(f'{getattr(err, "filename", "") or ""}: {err.strerror or err}')


# -- helpers ----------------------------------------------------------------------------------
def _write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (a temporary file renamed over it)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f'.{path.name}.part')
    tmp.write_text(text, encoding='utf-8')
    os.replace(tmp, path)


def _save_calibration(calibration, path: Path, header: str = '') -> None:
    import yaml
    _write_text(path, '# mbtrack_ros room calibration: metres, floor z = 0, z up;\n'
                      '# extrinsics map world to camera: x_cam = R X + t (R row-major).\n'
                + header + yaml.safe_dump(calibration.to_dict(), sort_keys=False))


def _rect(text: str, what: str) -> tuple[float, float, float, float]:
    from mbtrack_ros.calibration.errors import CalibrateError
    try:
        values = tuple(float(v) for v in str(text).split(','))
    except ValueError as err:
        raise CalibrateError(f'{what} expects X0,Y0,X1,Y1 in metres, got {text!r}') from err
    if len(values) != 4:
        raise CalibrateError(f'{what} expects 4 numbers X0,Y0,X1,Y1, got {text!r}')
    return values


def _room_parts(args, cameras, current=None):
    """(floor, entry_zones, exits) from --room, --floor, --entry-zone, --exit; what they do
    not give is kept from ``current`` (a RoomCalibration) when there is one."""
    import yaml

    from mbtrack_ros.calibration.errors import CalibrateError
    from mbtrack_ros.recording.calibration_io import default_floor
    floor, zones, exits = None, [], []
    if current is not None:
        floor, zones, exits = current.floor, list(current.entry_zones), list(current.exits)
    if args.room is not None:
        try:
            doc = yaml.safe_load(args.room.read_text(encoding='utf-8')) or {}
        except (OSError, yaml.YAMLError) as err:
            raise CalibrateError(f'cannot read --room {args.room}: '
                                 f'{str(err).splitlines()[0]}') from err
        if not isinstance(doc, dict):
            raise CalibrateError(f'--room {args.room}: expected keys floor, entry_zones, exits')
        f = doc.get('floor')
        if isinstance(f, dict):
            f = [f.get(k) for k in ('x_min', 'y_min', 'x_max', 'y_max')]
        if f is not None:
            floor = _rect(','.join(str(v) for v in f), f'{args.room} floor')
        if 'entry_zones' in doc:
            zones = [_rect(','.join(str(v) for v in z), f'{args.room} entry_zones')
                     for z in doc.get('entry_zones') or []]
        if 'exits' in doc:
            exits = [_rect(','.join(str(v) for v in e), f'{args.room} exits')
                     for e in doc.get('exits') or []]
    if args.floor:
        floor = _rect(args.floor, '--floor')
    if args.entry_zone:
        zones = [_rect(z, '--entry-zone') for z in args.entry_zone]
    if args.exit:
        exits = [_rect(e, '--exit') for e in args.exit]
    if floor is None:
        floor = default_floor(cameras)
        print(f'{_PROG}: note: no --floor; using the cameras\' bounding box '
              f'{", ".join(f"{v:.2f}" for v in floor)}', file=sys.stderr)
    return floor, tuple(zones), tuple(exits)


def _gray(image):
    import cv2
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image


# -- actions ----------------------------------------------------------------------------------
def _board(args) -> int:
    from mbtrack_ros.calibration.board import parse_board, printable_sheets, write_png
    board = parse_board(args.board)
    sheets = printable_sheets(board, args.dpi, split=not args.one_image)
    out = args.out if args.out.suffix.lower() == '.png' else args.out.with_suffix('.png')
    out.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for label, image in sheets:
        path = out if not label else out.with_name(f'{out.stem}_{label}.png')
        write_png(path, image)
        written.append(path)
    w, h = board.size
    what = (f'{len(written)} A4 sheets {written[0].name} .. {written[-1].name}'
            if len(written) > 1 else str(written[0]))
    print(f'{_PROG}: wrote {what}: {board.text}, squares {w:.3f} x {h:.3f} m at '
          f'{args.dpi:g} dpi; print at 100 % scale and measure one square '
          f'({board.square * 1000:.1f} mm)')
    return 0


def _detections(name, path, board, max_frames):
    from mbtrack_ros.calibration.sources import read_frames
    size, dets = None, []
    for _, image in read_frames(name, path, max_frames=max_frames):
        shape = image.shape[1::-1]
        if size is None:
            size = shape
        elif shape != size:
            from mbtrack_ros.calibration.errors import CalibrateError
            raise CalibrateError(f'{name}: images of {path} differ in size ({size[0]}x'
                                 f'{size[1]} and {shape[0]}x{shape[1]}): give one camera\'s '
                                 f'images')
        dets.append(board.detect(_gray(image)))
    return size, dets


def _intrinsics(args) -> int:
    import yaml

    from mbtrack_ros.calibration.board import parse_board
    from mbtrack_ros.calibration.solve import calibrate_intrinsics
    from mbtrack_ros.calibration.sources import parse_sources
    board = parse_board(args.board)
    sources = parse_sources(args.sources)
    results = []
    for name, path in sources.items():
        (width, height), dets = _detections(name, path, board, args.max_frames)
        res = calibrate_intrinsics(name, board, dets, width, height, source=str(path))
        results.append(res)
        print(f'{name}: {res.width}x{res.height}, {res.views} of {res.usable} usable views '
              f'({len(dets)} images), RMS {res.rms:.3f} px, fx {res.K[0, 0]:.1f} fy '
              f'{res.K[1, 1]:.1f} cx {res.K[0, 2]:.1f} cy {res.K[1, 2]:.1f} px, '
              f'k1 {res.dist[0]:+.4f} k2 {res.dist[1]:+.4f}')
    doc = {'format': 'mbtrack_ros/camera_intrinsics', 'version': 1, 'board': board.text,
           'cameras': [{
               'camera_name': r.name, 'image_width': r.width, 'image_height': r.height,
               'camera_matrix': {'rows': 3, 'cols': 3, 'data': r.K.ravel().tolist()},
               'distortion_model': 'plumb_bob',
               'distortion_coefficients': {'rows': 1, 'cols': 5, 'data': r.dist.tolist()},
               'rms_px': round(r.rms, 4), 'views': r.views} for r in results]}
    _write_text(args.out, '# mbtrack_ros camera intrinsics (mbtrack calibrate intrinsics)\n'
                + yaml.safe_dump(doc, sort_keys=False))
    print(f'{_PROG}: wrote {args.out} ({len(results)} cameras)')
    return 0


def _load_intrinsics(path: Path):
    """{name: Camera} with identity extrinsics from an intrinsics or room calibration."""
    import numpy as np
    import yaml

    from mbtrack_ros.calibration.errors import CalibrateError
    from mbtrack_ros.core.camera import CalibrationError, Camera
    try:
        doc = yaml.safe_load(path.read_text(encoding='utf-8'))
    except OSError as err:
        raise CalibrateError(f'cannot read --intrinsics {path}: {err.strerror}') from err
    except yaml.YAMLError as err:
        raise CalibrateError(f'--intrinsics {path} is not valid YAML') from err
    if not isinstance(doc, dict) or not isinstance(doc.get('cameras'), list):
        raise CalibrateError(f'--intrinsics {path}: no "cameras" list (write it with '
                             f'"mbtrack calibrate intrinsics")')
    cams = {}
    for entry in doc['cameras']:
        entry = dict(entry)
        entry['extrinsics'] = {'rotation': np.eye(3).ravel().tolist(),
                               'translation': [0.0, 0.0, 0.0]}
        try:
            cam = Camera.from_dict(entry)
        except CalibrationError as err:
            raise CalibrateError(f'--intrinsics {path}: {err}') from err
        cams[cam.name] = cam
    return cams


def _boards(args):
    """[(Board, BoardPose)] from --board (specs or a YAML) and --board-pose."""
    import yaml

    from mbtrack_ros.calibration.board import BoardPose, parse_board, parse_pose
    from mbtrack_ros.calibration.errors import CalibrateError
    boards = []
    for value in args.board:
        if value.lower().endswith(('.yaml', '.yml')):
            try:
                doc = yaml.safe_load(Path(value).read_text(encoding='utf-8'))
            except (OSError, yaml.YAMLError) as err:
                raise CalibrateError(f'cannot read boards file {value}: '
                                     f'{str(err).splitlines()[0]}') from err
            items = doc.get('boards') if isinstance(doc, dict) else None
            if not isinstance(items, list) or not items:
                raise CalibrateError(f'{value}: expected boards: [{{board: SPEC, pose: '
                                     f'[X, Y, YAW]}}, ...]')
            for item in items:
                if not isinstance(item, dict) or 'board' not in item:
                    raise CalibrateError(f'{value}: each board needs "board: SPEC"')
                pose = item.get('pose', [0, 0, 0])
                boards.append((parse_board(item['board']),
                               parse_pose(','.join(str(v) for v in pose))))
        else:
            boards.append((parse_board(value), None))
    if len(args.board_pose) > len(boards):
        raise CalibrateError(f'{len(args.board_pose)} --board-pose for {len(boards)} boards')
    poses = iter(args.board_pose)
    out = []
    for board, pose in boards:
        if pose is None:
            text = next(poses, None)
            pose = parse_pose(text) if text is not None else None
        if pose is None:
            if out:
                raise CalibrateError(f'board {board.text}: give its --board-pose X,Y,YAW '
                                     f'(only the first board may default to the room origin)')
            pose = BoardPose()
        out.append((board, pose))
    ids = [set(b.marker_ids.tolist()) for b, _ in out]
    for i in range(len(ids)):
        for j in range(i):
            if ids[i] & ids[j] or (out[i][0].kind == 'chessboard' and len(out) > 1):
                raise CalibrateError(f'boards {out[j][0].text} and {out[i][0].text} share '
                                     f'marker ids: give each board its own FIRST_ID')
    return out


def _extrinsics(args) -> int:
    from dataclasses import replace

    import numpy as np

    from mbtrack_ros.calibration.align import refine_corners
    from mbtrack_ros.calibration.errors import CalibrateError
    from mbtrack_ros.calibration.solve import (MIN_CORNERS, FloorObservation,
                                               average_detections, solve_extrinsics,
                                               viewing_direction)
    from mbtrack_ros.calibration.sources import parse_sources
    from mbtrack_ros.core.camera import RoomCalibration
    intrinsics = _load_intrinsics(args.intrinsics)
    boards = _boards(args)
    sources = parse_sources(args.sources)
    cameras, observations = [], {}
    for name, path in sources.items():
        if name not in intrinsics:
            raise CalibrateError(f'{name}: not a camera of {args.intrinsics} (it has '
                                 f'{", ".join(intrinsics)})')
        cam = intrinsics[name]
        obs, partial = [], []
        size = None
        per_board = [[] for _ in boards]
        from mbtrack_ros.calibration.sources import read_frames
        total = None
        frames = 0
        for _, image in read_frames(name, path, max_frames=args.max_frames):
            if size is not None and image.shape[1::-1] != size:
                raise CalibrateError(f'{name}: the images of {path} differ in size: give one '
                                     f'camera\'s pictures')
            size = image.shape[1::-1]
            gray = _gray(image)
            total = gray.astype(np.float64) if total is None else total + gray
            frames += 1
            for k, (board, _) in enumerate(boards):
                per_board[k].append(board.detect(gray, far=True))
        mean_gray = (total / max(frames, 1)).astype(np.float32)
        if size != (cam.width, cam.height):
            sx, sy = size[0] / cam.width, size[1] / cam.height
            if abs(sx - sy) > 0.01 * sx:
                raise CalibrateError(f'{name}: images are {size[0]}x{size[1]} but the '
                                     f'intrinsics are for {cam.width}x{cam.height}: calibrate '
                                     f'the intrinsics at this size')
            cam = cam.scaled(*size)
        for k, dets in enumerate(per_board):
            ids, pixels = average_detections(dets)
            if len(ids) >= MIN_CORNERS:
                refined = refine_corners(mean_gray, cam, boards[k][0], ids, pixels)
                obs.append(FloorObservation(k, ids, refined, pixels))
            elif len(ids):
                partial.append((boards[k][0], len(ids)))
        if not obs:
            if partial:
                board, n = partial[0]
                raise CalibrateError(
                    f'{name}: only {n} corners of board {board.text} found in {path} (need '
                    f'{MIN_CORNERS}): the board is too small or partly hidden in this '
                    f'camera\'s image: use larger squares, move it nearer or uncover it')
            raise CalibrateError(
                f'{name}: no board ({", ".join(b.text for b, _ in boards)}) found in {path}: '
                f'check that the board lies in this camera\'s view, large enough (markers '
                f'at least 15 pixels wide: larger squares or nearer), lit and uncovered, and '
                f'that --board matches the printed one (dictionary, squares)')
        cameras.append(cam)
        observations[name] = obs
    poses, board_poses = solve_extrinsics(cameras, boards, observations)
    floor, zones, exits = _room_parts(args, [p.camera for p in poses])
    calibration = RoomCalibration(cameras={p.camera.name: p.camera for p in poses},
                                  floor=floor, entry_zones=zones, exits=exits)
    for p in poses:
        az, dep = viewing_direction(p.camera)
        c = p.camera.center
        warn = ''
        if c[2] <= 0.0:
            warn = '  WARNING: below the floor: check --board and the board\'s side'
        elif dep < 0.0:
            warn = '  WARNING: looks up: check that the board lies face up'
        elif p.rms > 2.0:
            warn = '  WARNING: large error: check the intrinsics and --board'
        print(f'{p.camera.name}: {p.corners} corners (boards '
              f'{",".join(str(b + 1) for b in p.boards)}), RMS {p.rms:.2f} px, at '
              f'({c[0]:.3f}, {c[1]:.3f}) m, height {c[2]:.3f} m, looking {az:.1f} deg from x, '
              f'{dep:.1f} deg down{warn}')
    for k, ((board, given), solved) in enumerate(zip(boards, board_poses)):
        if k and (given != solved):
            print(f'board {k + 1} ({board.text}): given ({given.x:.3f}, {given.y:.3f}, '
                  f'{given.yaw:.1f} deg), refined ({solved.x:.3f}, {solved.y:.3f}, '
                  f'{solved.yaw:.1f} deg)')
    header = '# from mbtrack calibrate extrinsics; boards: ' + '; '.join(
        f'{b.text} at {p.x:.4f},{p.y:.4f},{p.yaw:.3f}' for (b, _), p in
        zip(boards, board_poses)) + '\n'
    _save_calibration(replace(calibration), args.out, header)
    print(f'{_PROG}: wrote {args.out} ({len(poses)} cameras)')
    return 0


def _room(args) -> int:
    from dataclasses import replace

    from mbtrack_ros.core.camera import RoomCalibration
    calibration = RoomCalibration.load(args.calibration)
    floor, zones, exits = _room_parts(args, list(calibration.cameras.values()), calibration)
    out = replace(calibration, floor=floor, entry_zones=zones, exits=exits)
    out = RoomCalibration.from_dict(out.to_dict())  # validates the exits against the floor
    _save_calibration(out, args.out)
    print(f'{_PROG}: wrote {args.out}')
    return 0


def _check(args) -> int:
    from mbtrack_ros.calibration.board import write_png
    from mbtrack_ros.calibration.check import camera_overlay, top_view
    from mbtrack_ros.calibration.errors import CalibrateError
    from mbtrack_ros.calibration.sources import parse_sources, read_frames, recording_frames
    from mbtrack_ros.core.camera import RoomCalibration
    calibration = RoomCalibration.load(args.calibration)
    images = {}
    if len(args.sources) == 1 and '=' not in args.sources[0]:
        images = recording_frames(Path(args.sources[0]), calibration.names)
        if not images:
            raise CalibrateError(f'{args.sources[0]}: no images of the cameras '
                                 f'{", ".join(calibration.names)}')
    elif args.sources:
        for name, path in parse_sources(args.sources).items():
            if name not in calibration.cameras:
                raise CalibrateError(f'{name}: not a camera of {args.calibration}')
            images[name] = next(iter(read_frames(name, path, max_frames=1)))[1]
    args.out.mkdir(parents=True, exist_ok=True)
    for name in calibration.names:
        write_png(args.out / f'{name}.png', camera_overlay(calibration, name,
                                                           images.get(name)))
    write_png(args.out / 'top.png', top_view(calibration))
    print(f'{_PROG}: wrote {len(calibration.names)} camera pictures and top.png to {args.out}')
    return 0


def _compare(args) -> int:
    import numpy as np

    from mbtrack_ros.calibration.errors import CalibrateError
    from mbtrack_ros.core.camera import RoomCalibration
    ref = RoomCalibration.load(args.reference)
    cal = RoomCalibration.load(args.calibration)
    common = [n for n in cal.names if n in ref.cameras]
    if not common:
        raise CalibrateError(f'{args.calibration} and {args.reference} have no camera in '
                             f'common')
    worst = np.zeros(3)
    for name in common:
        a, b = ref.cameras[name], cal.cameras[name]
        if (a.width, a.height) != (b.width, b.height):
            a = a.scaled(b.width, b.height)
        cos = (np.trace(b.R @ a.R.T) - 1.0) / 2.0
        rot = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
        centre = float(np.linalg.norm(b.center - a.center))
        focal = float(b.focal / a.focal - 1.0)
        worst = np.maximum(worst, [rot, centre, abs(focal)])
        print(f'{name}: rotation {rot:.3f} deg, centre {100 * centre:.2f} cm, focal '
              f'{100 * focal:+.3f} %')
    print(f'worst: rotation {worst[0]:.3f} deg, centre {100 * worst[1]:.2f} cm, focal '
          f'{100 * worst[2]:.3f} %')
    return 0
