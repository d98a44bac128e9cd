"""``mbtrack synth PRESET OUTDIR``: render a synthetic smart-room recording with ground truth."""
from __future__ import annotations

import argparse
import sys
import time

__all__ = ['add_parser', 'run']


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``synth`` subcommand."""
    parser = subparsers.add_parser(
        'synth', help='render a synthetic multi-camera recording with ground truth',
        description='Render a synthetic smart-room recording (rosbag2 + calibration.yaml + '
                    'ground_truth.csv + recording.yaml) from a named preset.')
    parser.add_argument('preset', nargs='?', help='preset name (see --list)')
    parser.add_argument('outdir', nargs='?', help='output directory (must not exist or be '
                                                  'empty)')
    parser.add_argument('--list', action='store_true', help='list the presets and exit')
    parser.add_argument('--frames', type=int, default=None,
                        help='number of frames (default: the preset\'s)')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('--compressed', action='store_true',
                        help='store JPEG CompressedImage messages instead of raw rgb8')
    parser.add_argument('--width', type=int, default=None,
                        help="image width (default: the preset's, 320 or 200 for lanz-seq*)")
    parser.add_argument('--height', type=int, default=None,
                        help="image height (default: the preset's, 240 or 150 for lanz-seq*)")
    parser.add_argument('--fps', type=float, default=15.0, help='frame rate (default 15)')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap',
                        help='rosbag2 storage plugin (default mcap)')
    parser.add_argument('--no-ceiling', action='store_true',
                        help='leave out the ceiling camera')
    real = parser.add_argument_group(
        'real-room conditions', 'added to any preset (mbtrack_ros/synth/conditions.py); '
        'default: the preset\'s own (real-room has them all), else none')
    real.add_argument('--capture-spread', type=float, default=None, metavar='F',
                      help='free-running cameras: capture times spread over F frame '
                           'periods, 0..1 (0: synchronised)')
    real.add_argument('--light-change', action='append', default=None, metavar='T:F[:RAMP]',
                      help='at T seconds the light is multiplied by F (one factor, or '
                           'R,G,B factors for a change of colour), reached over RAMP '
                           'seconds (default 0: in one frame); repeatable')
    real.add_argument('--lamps', type=int, default=None, metavar='L',
                      help='people cast shadows from L ceiling lamps (e.g. 2)')
    real.add_argument('--calibration-error', default=None, metavar='DEG,M',
                      help='also write calibration_perturbed.yaml: every camera turned by '
                           'DEG degrees and moved by M metres (e.g. 1,0.03)')
    real.add_argument('--exposure-drift', type=float, default=None, metavar='A',
                      help='auto exposure: each camera\'s gain drifts by +-A (e.g. 0.08)')
    return parser


def _light_change(text: str) -> tuple:
    """``T:F[:RAMP]`` -> (T, factors, RAMP); raises ValueError with a one-line reason."""
    parts = text.split(':')
    if len(parts) not in (2, 3):
        raise ValueError(f'--light-change {text!r}: expected T:F or T:F:RAMP')
    try:
        factors = [float(f) for f in parts[1].split(',')]
        if len(factors) not in (1, 3):
            raise ValueError
        return (float(parts[0]), tuple(factors * 3 if len(factors) == 1 else factors),
                float(parts[2]) if len(parts) == 3 else 0.0)
    except ValueError:
        raise ValueError(f'--light-change {text!r}: T, F (or R,G,B) and RAMP must be '
                         'numbers') from None


def _conditions(args: argparse.Namespace, preset):
    """The preset's conditions with the options given on top (None: the preset's)."""
    from dataclasses import replace

    from mbtrack_ros.synth.conditions import PRESET_CONDITIONS, Conditions

    given = {name: getattr(args, name) for name in ('capture_spread', 'exposure_drift',
                                                     'lamps')
             if getattr(args, name, None) is not None}
    if getattr(args, 'calibration_error', None):
        try:
            deg, metres = (float(v) for v in args.calibration_error.split(','))
        except ValueError:
            raise ValueError(f'--calibration-error {args.calibration_error!r}: expected '
                             'DEG,M (two numbers)') from None
        given['calibration_error'] = (deg, metres)
    if getattr(args, 'light_change', None):
        given['light_changes'] = tuple(_light_change(t) for t in args.light_change)
    if not given:
        return None
    return replace(PRESET_CONDITIONS.get(preset.name, Conditions()), **given)


def _error(message: str) -> int:
    print(f'mbtrack synth: error: {message}', file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    """Run ``mbtrack synth``; returns the exit code (2 on user errors)."""
    from mbtrack_ros.synth import PRESETS, SynthError, generate, get_preset

    if args.list:
        width = max(len(n) for n in PRESETS)
        for name, preset in PRESETS.items():
            print(f'{name:<{width}}  {preset.description}')
        return 0
    if not args.preset or not args.outdir:
        return _error('PRESET and OUTDIR are required (or use --list)')
    if args.frames is not None and args.frames <= 0:
        return _error(f'--frames must be positive, got {args.frames}')
    if not args.fps > 0:
        return _error(f'--fps must be positive, got {args.fps}')
    try:
        preset = get_preset(args.preset)
        conditions = _conditions(args, preset)
    except (SynthError, ValueError) as err:
        return _error(str(err).splitlines()[0])
    width = preset.size[0] if args.width is None else args.width
    height = preset.size[1] if args.height is None else args.height
    if not (16 <= width <= 4096 and 16 <= height <= 4096):
        return _error(f'image size {width}x{height} outside 16..4096 pixels')
    try:
        start = time.perf_counter()
        out = generate(preset, args.outdir, seed=args.seed, frames=args.frames,
                       width=width, height=height, fps=args.fps,
                       ceiling=not args.no_ceiling, compressed=args.compressed,
                       storage=args.storage, progress=sys.stderr.isatty(),
                       conditions=conditions)
    except (SynthError, OSError) as err:
        return _error(str(err).splitlines()[0] if str(err) else type(err).__name__)
    elapsed = time.perf_counter() - start
    frames = args.frames or preset.frames
    print(f'mbtrack synth: wrote {frames} frames of {preset.name} to {out} in {elapsed:.1f} s '
          f'({frames / max(elapsed, 1e-9):.1f} frames/s)', file=sys.stderr)
    return 0
