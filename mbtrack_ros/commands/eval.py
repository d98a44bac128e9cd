"""``mbtrack eval``: CLEAR MOT scores, posterior-mass curve and plots of a tracks CSV."""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from mbtrack_ros.core.camera import CalibrationError, RoomCalibration
from mbtrack_ros.evaluation.clear_mot import clear_mot
from mbtrack_ros.evaluation.errors import EvaluationError
from mbtrack_ros.evaluation.posterior import posterior_mass
from mbtrack_ros.evaluation.report import format_table, write_report
from mbtrack_ros.recording.csvfiles import CsvFormatError, read_ground_truth, read_tracks

__all__ = ['add_parser', 'run']

_PROG = 'mbtrack eval'


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``eval``."""
    parser = subparsers.add_parser(
        'eval', help='score a tracks CSV against ground truth (CLEAR MOT, posterior mass)',
        description='Score tracks against ground truth with CLEAR MOT on floor positions '
                    '(py-motmetrics, MOTP in mm), optionally the posterior-mass curve of a '
                    'particle file; writes scores.md, scores.json and PNG plots.')
    parser.add_argument('tracks', type=Path, metavar='TRACKS.csv',
                        help='tracks CSV (stamp_ns,frame,track_id,x,y[,visibility,existence])')
    parser.add_argument('ground_truth', type=Path, metavar='GROUND_TRUTH.csv',
                        help='ground-truth CSV written by mbtrack synth')
    parser.add_argument('--out', type=Path, default=None, metavar='DIR',
                        help='output directory (default: the tracks file\'s directory)')
    parser.add_argument('--particles', type=Path, default=None, metavar='particles.npz',
                        help='particle file of mbtrack replay --save-particles')
    parser.add_argument('--threshold', type=float, default=0.5, metavar='METRES',
                        help='match threshold in metres (default 0.5, as CLEAR\'07)')
    parser.add_argument('--calibration', type=Path, default=None, metavar='calibration.yaml',
                        help='room calibration drawn in the top view (default: '
                             'calibration.yaml beside the ground truth, if present)')
    parser.add_argument('--name', default=None,
                        help='sequence name in the tables (default: the tracks file stem, or '
                             'its directory name for tracks.csv)')
    parser.add_argument('--no-plots', action='store_true', help='skip the PNG plots')
    return parser


def _error(msg: str) -> int:
    print(f'{_PROG}: error: {" ".join(msg.split())}', file=sys.stderr)
    return 2


def _calibration(args: argparse.Namespace, notes: list[str]) -> RoomCalibration | None:
    """The explicitly given calibration (errors propagate) or the optional default one."""
    from mbtrack_ros.recording.calibration_io import load_calibration
    if args.calibration is not None:
        return load_calibration(args.calibration, 'room', warn=notes.append)
    default = Path(args.ground_truth).parent / 'calibration.yaml'
    if not default.is_file():
        return None
    try:
        return load_calibration(default, 'room', warn=notes.append)
    except CalibrationError as err:
        notes.append(f'{default} not drawn: {err}')
        return None


def run(args: argparse.Namespace) -> int:
    """Score, print the table, write the report; 0 on success, 2 on bad input."""
    if not (math.isfinite(args.threshold) and args.threshold > 0):
        return _error(f'--threshold must be a positive number of metres, got {args.threshold}')
    out_dir = Path(args.out) if args.out is not None else Path(args.tracks).parent
    tracks_path = Path(args.tracks)
    name = args.name or (tracks_path.stem if tracks_path.stem != 'tracks'
                         else tracks_path.resolve().parent.name or 'tracks')
    notes = []
    try:
        tracks = read_tracks(args.tracks)
        truth = read_ground_truth(args.ground_truth)
        if not truth:
            return _error(f'{args.ground_truth}: ground truth is empty')
        result = clear_mot(tracks, truth, threshold_m=args.threshold, name=name)
        if result.ignored_track_rows:
            notes.append(f'{result.ignored_track_rows} track row(s) at stamps absent from the '
                         'ground truth were ignored')
        posterior = {}
        if args.particles is not None:
            pm = posterior_mass(args.particles, truth, tracks, matching=result)
            posterior[name] = pm
            if pm.missing_particle_rows:
                notes.append(f'{pm.missing_particle_rows} matched person-frame(s) have no '
                             'particle row (counted as zero mass)')
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            return _error(f'cannot create {out_dir}: {err.strerror or err}')
        images = []
        if not args.no_plots:
            from mbtrack_ros.evaluation import plots  # matplotlib import only when plotting
            calibration = _calibration(args, notes)
            images.append(plots.plot_trajectories(
                tracks, truth, out_dir / 'trajectories.png', title=f'{name}: trajectories',
                calibration=calibration))
            images.append(plots.plot_localisation_error(result, out_dir / 'error.png'))
            if posterior:
                images.append(plots.plot_posterior_curves(
                    {name: (pm.distances, pm.fraction)}, out_dir / 'posterior_mass.png'))
        inputs = {'tracks': str(args.tracks), 'ground_truth': str(args.ground_truth)}
        if args.particles is not None:
            inputs['particles'] = str(args.particles)
        paths = write_report(out_dir, [result], posterior=posterior, images=images,
                             inputs=inputs, notes=notes)
    except (CsvFormatError, EvaluationError, CalibrationError) as err:
        return _error(str(err))
    for note in notes:
        print(f'{_PROG}: warning: {note}', file=sys.stderr)
    print(format_table([result], posterior))
    print(f'wrote {paths["markdown"]}, {paths["json"]} and {len(images)} plot(s) '
          f'into {out_dir}')
    return 0
