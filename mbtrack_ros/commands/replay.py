"""``mbtrack replay``: run the tracker offline over a recording, write tracks (and particles).

BAG is a rosbag2 directory (MCAP or sqlite3) or a recording directory made by
``mbtrack synth`` (then ``--config`` defaults to its ``calibration.yaml``). Frames are read
with :class:`~mbtrack_ros.recording.bag.RecordingReader` and fed to the
:class:`~mbtrack_ros.core.tracker.Tracker` as fast as possible (a reader thread decodes, and
to the tracker's working size (``--working-pixels``) resizes, the next frame sets while
the tracker works:
:func:`~mbtrack_ros.recording.bag.prefetched`); ``tracks.mcap`` is written by a child
process (:mod:`mbtrack_ros.commands.output_writer`). Outputs in ``--out``:

* ``tracks.csv`` (``recording.csvfiles`` format), written row by row while tracking;
* ``particles.npz`` with ``--save-particles`` (format of ``evaluation.posterior``).

Tracks are initialised from ground truth (``--init-from``, :mod:`mbtrack_ros.core.initiation`):
each person's track starts at its first ground-truth frame and ends after its last one.
Without ``--init-from`` people are detected, acquired and released automatically
(:mod:`mbtrack_ros.core.detection`).
A damaged bag stops the run with a message naming the last good frame (or, for a damaged
chunk inside the bag, the frame sets lost); what was tracked up to there is kept on disk and
the exit code is 1. A frame set whose stamp is not later than the last processed one is
dropped (never processed twice); undecodable images are dropped; both are counted in the
summary and in the ``/diagnostics`` of ``tracks.mcap``.
"""
from __future__ import annotations

import argparse
import functools
import importlib.util
import shutil
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import yaml

from mbtrack_ros.commands.output_writer import BackgroundWriter, output_bag_writer
from mbtrack_ros.core.camera import CalibrationError, RoomCalibration, yaml_error_line
from mbtrack_ros.core.filters import FilterError
from mbtrack_ros.core.initiation import InitiationError, initial_tracks, plan_key_views
from mbtrack_ros.core.likelihood import LikelihoodError
from mbtrack_ros.core.tracker import Tracker, TrackerConfig, TrackerError
from mbtrack_ros.recording.bag import BagError, RecordingReader, prefetched
from mbtrack_ros.recording.calibration_io import load_calibration
from mbtrack_ros.recording.csvfiles import (
    CsvFormatError, GroundTruthRow, TrackRow, read_ground_truth, write_tracks)

__all__ = ['add_parser', 'run']

_PROG = 'mbtrack replay'
# The tracks.mcap writer runs at this niceness above the replay: it takes the CPU the
# tracker's threads leave.
_WRITER_NICENESS = 10
# /diagnostics of tracks.mcap: one message per second of message time (as the node's
# diagnostics_period) and one with the final counts
_DIAGNOSTICS_PERIOD_NS = 1_000_000_000


class _UserError(Exception):
    """A problem with the command's input, reported as one line with exit code 2."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``replay``."""
    parser = subparsers.add_parser(
        'replay', help='run the tracker offline over a recorded bag',
        description='Track people through a recorded rosbag2 (or an mbtrack synth '
                    'recording directory) as fast as possible; writes OUTDIR/tracks.csv and '
                    'optionally the particle sets, and scores the tracks with CLEAR MOT.')
    parser.add_argument('bag', type=Path, metavar='BAG',
                        help='rosbag2 directory, or a recording directory with bag/ inside')
    parser.add_argument('--config', type=Path, default=None, metavar='ROOM.yaml',
                        help='room calibration (default: BAG/calibration.yaml)')
    parser.add_argument('--out', type=Path, required=True, metavar='OUTDIR',
                        help='output directory (created)')
    parser.add_argument('--params', type=Path, default=None, metavar='NODE.yaml',
                        help='take the tracker settings (tracker.*, motion.*, '
                             'detection.threshold, detection.every, ...) '
                             'from a tracker_node parameter file (config/*.yaml); the '
                             'options below override it')
    parser.add_argument('--algorithm', default=None,
                        help='hjs (default), hjs-groups, separable, joint, or a registered '
                        'baseline')
    parser.add_argument('--particles', type=int, default=None, metavar='N',
                        help='particles per person (default 100, at most 100000)')
    parser.add_argument('--joint-particles', type=int, default=None, metavar='N',
                        help='joint particles of --algorithm joint (default 10000, at '
                             'most 1000000)')
    parser.add_argument('--no-mrf', action='store_true',
                        help='disable the spatial-exclusion MRF prior (ablation)')
    parser.add_argument('--mrf-radius', type=float, default=None, metavar='R',
                        help='spatial-exclusion radius of the MRF prior, metres (default '
                             '0.3; 000 uses 0.4)')
    parser.add_argument('--paper-motion', action='store_true',
                        help='the motion of 000 §VI: the state is position and velocity '
                             '(no sitting posture: MotionConfig.sit_flip_rate 0) and a '
                             'walking body faces its direction of motion (the default keeps '
                             'orientation apart from velocity: '
                             'MotionConfig.orientation_follows_velocity, node parameter '
                             'motion.orientation_follows_velocity)')
    parser.add_argument('--sigma', type=float, default=None,
                        help='likelihood width sigma (default 0.12)')
    parser.add_argument('--d-occ', type=float, default=None,
                        help='occlusion penalty d_occ (default 0.15)')
    parser.add_argument('--subsample', type=int, default=None, metavar='K',
                        help='likelihood on every K-th image row (default 1; a speed option '
                             'that costs accuracy)')
    parser.add_argument('--pipeline-search', action='store_true',
                        help='search frame t for new people while frame t+1 is filtered '
                             '(people start one frame later; TrackerConfig.pipeline_search)')
    parser.add_argument('--detection-every', type=int, default=None, metavar='K',
                        help='run the detection pipeline on every K-th frame set only '
                             '(default 1; a speed option that costs accuracy)')
    parser.add_argument('--working-pixels', type=int, default=None, metavar='P',
                        help='pixels per camera image the tracker works on; larger images '
                             'are resized once per frame (default 76800 = 320x240; fewer is '
                             'a speed option)')
    parser.add_argument('--sync-tolerance', type=float, default=None, metavar='S',
                        help='largest distance of an image\'s capture time from its frame '
                             'set\'s time, seconds (default: half the frame period, measured '
                             'from the stamps)')
    parser.add_argument('--init-from', type=Path, default=None, metavar='GROUND_TRUTH.csv',
                        help='start tracks from this ground truth (models from key views)')
    parser.add_argument('--eval', type=Path, default=None, metavar='GROUND_TRUTH.csv',
                        help='score the tracks against this ground truth (CLEAR MOT)')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('--save-particles', action='store_true',
                        help='write OUTDIR/particles.npz (posterior particle sets)')
    parser.add_argument('--max-frames', type=int, default=None, metavar='N',
                        help='stop after N frames')
    # run as the mbtrack command, the process ends right after run() (mbtrack_ros.cli.main)
    parser.set_defaults(_quick_exit=True)
    return parser


def _error(msg: str, code: int = 2) -> int:
    print(f'{_PROG}: error: {msg}', file=sys.stderr)
    return code


def _resolve_inputs(args: argparse.Namespace) -> tuple[Path, RoomCalibration]:
    bag = Path(args.bag)
    if not bag.exists():
        raise _UserError(f'{bag} does not exist')
    config = args.config
    if config is None:
        if (bag / 'calibration.yaml').exists():
            config = bag / 'calibration.yaml'
        else:
            raise _UserError(f'{bag} is not a recording directory with calibration.yaml; '
                             'give the room calibration with --config ROOM.yaml')
    try:
        calibration = load_calibration(config, 'room', warn=lambda line: print(
            f'{_PROG}: warning: {line}', file=sys.stderr))
    except CalibrationError as err:
        raise _UserError(str(err)) from err
    return bag, calibration


# tracker_node parameter (under ``tracker_node: ros__parameters:``) -> TrackerConfig field;
# ``tracker.seed`` is left to ``--seed`` (a replay is always seeded)
def tracker_values_from_params(path: Path) -> dict:
    """TrackerConfig values of a tracker_node parameter file (the ``tracker.*``,
    ``motion.*`` and ``detection.*`` entries of ``TRACKER_PARAMETERS``, the node's own map); raises
    TrackerError on an unreadable file or unknown key."""
    from mbtrack_ros.nodes.tracker_parameters import (  # no rclpy
        TRACKER_PARAMETERS, tracker_config_values)
    try:
        doc = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
        params = doc['tracker_node']['ros__parameters']
        flat: dict = {}
        for section in ('tracker', 'detection', 'motion'):
            for key, value in (params.get(section) or {}).items():
                flat[f'{section}.{key}'] = value
    except UnicodeDecodeError as err:
        raise TrackerError(f'{path}: not a text file (not UTF-8 at byte {err.start})') \
            from err
    except OSError as err:
        raise TrackerError(f'{path}: not a tracker_node parameter file (cannot read it: '
                           f'{err.strerror or err})') from err
    except yaml.YAMLError as err:
        raise TrackerError(f'{path}: not valid YAML: {yaml_error_line(err)}') from err
    except (KeyError, TypeError, AttributeError) as err:
        raise TrackerError(f'{path}: not a tracker_node parameter file (expected '
                           f'tracker_node: ros__parameters: ..., {type(err).__name__} '
                           f'{err})') from err
    unknown = sorted(k for k in flat if k.startswith(('tracker.', 'motion.'))
                     and k != 'tracker.seed' and k not in TRACKER_PARAMETERS)
    if unknown:
        raise TrackerError(f'{path}: unknown tracker parameter(s) {", ".join(unknown)}')
    try:
        return tracker_config_values(flat)
    except TrackerError as err:
        raise TrackerError(f'{path}: {err}') from err


def _config(args: argparse.Namespace) -> TrackerConfig:
    if args.max_frames is not None and args.max_frames < 1:
        raise _UserError(f'--max-frames must be >= 1, got {args.max_frames}')
    try:
        values = tracker_values_from_params(args.params) if args.params is not None else {}
        for name in ('algorithm', 'particles', 'joint_particles', 'sigma', 'd_occ',
                     'mrf_radius', 'subsample', 'detection_every', 'working_pixels'):
            if getattr(args, name) is not None:  # an explicit option beats the file
                values[name] = getattr(args, name)
        if args.no_mrf:
            values['use_mrf'] = False
        if args.pipeline_search:
            values['pipeline_search'] = True
        if args.paper_motion:    # on top of the file's other motion values
            # 000 §VI-A: a 4D state, floor position and velocity; bodies face their motion.
            # No posture: with one camera a standing person is matched about as well by a
            # seated hypothesis 0.5-1 m farther along the line of sight (its smaller
            # silhouette lies inside the person's), and particles flipped to sitting
            # carry the track there (docs/hjs_fidelity.md, deliberate difference 6).
            motion = values.setdefault('motion', {})
            motion['orientation_follows_velocity'] = True
            motion['sit_flip_rate'] = 0.0
        values.update(seed=args.seed, detection=args.init_from is None)
        return TrackerConfig.from_dict(values)
    except TrackerError as err:
        raise _UserError(str(err)) from err


def _sync_options(args: argparse.Namespace, bag: Path,
                  calibration: RoomCalibration) -> dict:
    """The frame-set synchroniser's settings (:class:`RecordingReader`): the tolerance
    (``--sync-tolerance``, else half the measured frame period), the nominal frame rate of
    a synth recording (recording.yaml ``fps``, checked against the stamps) and the
    cameras' ``time_offset`` from the calibration."""
    tolerance = args.sync_tolerance
    if tolerance is not None and not (0 <= tolerance <= 1.0):
        raise _UserError(f'--sync-tolerance must be in [0, 1] seconds, got {tolerance}')
    return sync_options(bag, calibration, tolerance)


def sync_options(bag: Path, calibration: RoomCalibration,
                 tolerance: float | None = None) -> dict:
    """:class:`RecordingReader` keyword arguments of a replay of ``bag`` (a recording or
    bag directory): ``tolerance`` seconds (None: half the measured frame period), the
    frame rate of recording.yaml and the calibration's ``time_offset`` s."""
    fps = 0.0
    meta = bag / 'recording.yaml'
    if meta.is_file():
        try:
            fps = float((yaml.safe_load(meta.read_text()) or {}).get('fps') or 0.0)
        except (OSError, yaml.YAMLError, TypeError, ValueError, AttributeError):
            fps = 0.0
    offsets = {n: c.time_offset for n, c in calibration.cameras.items() if c.time_offset}
    return {'tolerance_ns': int(round((tolerance or 0.0) * 1e9)),
            'frame_rate': fps if fps > 0 else 0.0, 'time_offsets': offsets}


class _FrameIndex:
    """Maps frame-set stamps to ground-truth frame numbers (nearest stamp, half a period)."""

    def __init__(self, truth: list[GroundTruthRow]) -> None:
        pairs = sorted({(r.stamp_ns, r.frame) for r in truth})
        self.stamps = np.array([p[0] for p in pairs], dtype=np.int64)
        self.frames = np.array([p[1] for p in pairs], dtype=np.int64)
        step = np.median(np.diff(self.stamps)) if self.stamps.size > 1 else 1e9
        self.tolerance = max(1, int(step // 2))

    def frame(self, stamp_ns: int) -> int | None:
        if self.stamps.size == 0:
            return None
        i = int(np.searchsorted(self.stamps, stamp_ns))
        best = None
        for j in (i - 1, i):
            if 0 <= j < self.stamps.size:
                d = abs(int(self.stamps[j]) - stamp_ns)
                if d <= self.tolerance and (best is None or d < best[0]):
                    best = (d, int(self.frames[j]))
        return None if best is None else best[1]


def _match_calibration(calibration: RoomCalibration, reader: RecordingReader,
                       first_images: dict[str, np.ndarray]) -> RoomCalibration:
    """Restrict to the bag's cameras and scale cameras whose images have another size."""
    names = [n for n in calibration.names if n in reader.cameras]
    if not names:
        raise _UserError(f'no camera of the calibration ({", ".join(calibration.names)}) is '
                         f'in the bag ({", ".join(reader.cameras) or "no image topics"})')
    extra = [c for c in reader.cameras if c not in calibration.cameras]
    if extra:
        print(f'{_PROG}: note: ignoring camera(s) without calibration: {", ".join(extra)}',
              file=sys.stderr)
    calibration = calibration.subset(names)
    cams = dict(calibration.cameras)
    for name, image in first_images.items():
        cam = cams.get(name)
        if cam is not None and image.shape[:2] != (cam.height, cam.width):
            print(f'{_PROG}: note: {name} images are {image.shape[1]}x{image.shape[0]}, '
                  f'calibration says {cam.width}x{cam.height}; scaling the intrinsics',
                  file=sys.stderr)
            cams[name] = cam.scaled(image.shape[1], image.shape[0])
    return RoomCalibration(cameras=cams, floor=calibration.floor,
                           frame_id=calibration.frame_id,
                           entry_zones=calibration.entry_zones, exits=calibration.exits)


def _collect_key_images(reader: RecordingReader, index: _FrameIndex,
                        needed: set[int]) -> dict[int, dict[str, np.ndarray]]:
    """Images of the key-view frames (frame number -> camera -> image)."""
    images: dict[int, dict[str, np.ndarray]] = {}
    if not needed:
        return images
    try:
        for fs in reader.frames():
            frame = index.frame(fs.stamp_ns)
            if frame in needed:
                images[frame] = dict(fs.images)
                if len(images) == len(needed):
                    break
    except BagError:
        pass  # the tracking pass reports the damage
    return images


def _track_rows(tracker: Tracker, reader: RecordingReader, index: _FrameIndex, starts: list,
                args: argparse.Namespace, recorder, status: dict,
                outputs=None) -> Iterator[TrackRow]:
    """Tracking pass: yields the rows of tracks.csv frame by frame."""
    from tqdm import tqdm

    total = reader.frame_count
    if args.max_frames is not None:
        total = min(total, args.max_frames) if total else args.max_frames
    pending = list(starts)  # InitialTrack, ordered by first stamp
    live: dict[int, object] = {}  # track id -> InitialTrack
    bar = tqdm(total=total or None, unit='frame', desc='replay', file=sys.stderr,
               disable=not sys.stderr.isatty())
    known = set(tracker.calibration.cameras)
    t_start = time.perf_counter()
    # read, decode and resize while tracking: the images of larger cameras are decoded
    # at the tracker's working size (TrackerConfig.working_pixels), resized once in the
    # reader thread; Tracker.step then finds them at its size
    reader.decode_to(tracker.resized_cameras)
    frames = prefetched(reader.frames(), depth=4)
    try:
        for fs in frames:
            if args.max_frames is not None and status['frames'] >= args.max_frames:
                break
            for cam, reason in fs.errors.items():  # undecodable images: counted, noted
                status['bad_images'][cam] = status['bad_images'].get(cam, 0) + 1
                status['bad_reasons'].setdefault(cam, reason)
            if tracker.last_stamp_ns is not None and fs.stamp_ns <= tracker.last_stamp_ns:
                # a repeated or earlier stamp: never process an instant twice
                status['skipped'] += 1
                continue
            frame = index.frame(fs.stamp_ns)
            for tid, init in list(live.items()):
                if frame is not None and frame > init.last_frame:
                    tracker.remove_track(tid)
                    del live[tid]
            while pending and pending[0].stamp_ns <= fs.stamp_ns:
                init = pending.pop(0)
                if frame is not None and frame > init.last_frame:
                    continue  # the person left before the replay got there
                tid = tracker.add_track(init.model, init.state, init.stamp_ns)
                live[tid] = init
                status['tracks'] += 1
            images = {c: im for c, im in fs.images.items() if c in known}
            try:
                result = tracker.step(fs.stamp_ns, images, stamps=fs.stamps)
            except (LikelihoodError, TrackerError) as err:
                status['bag_error'] = f'frame set {fs.index}: {err}'
                break
            status['frames'] += 1
            status['live_tracks'] = len(result.tracks)
            if not starts:  # automatic detection: ids 1, 2, ... count the births
                status['tracks'] = max([status['tracks']] + [t.track_id for t in result.tracks])
            status['tracker_s'] += result.timings.get('total', 0.0)
            status['last_frame'] = fs.index
            status['last_stamp'] = fs.stamp_ns
            if recorder is not None:
                recorder.add_frame(result)
            if outputs is not None:  # the tracker_node messages, for offline replay
                outputs.write(result)
                if (status['diag_stamp'] is None
                        or fs.stamp_ns - status['diag_stamp'] >= _DIAGNOSTICS_PERIOD_NS):
                    outputs.write_diagnostics(fs.stamp_ns, _counts(status))
                    status['diag_stamp'] = fs.stamp_ns
            for t in result.tracks:
                vis = max(t.visible_fraction.values()) if t.visible_fraction else float('nan')
                yield TrackRow(stamp_ns=fs.stamp_ns, frame=fs.index, track_id=t.track_id,
                               x=float(t.mean[0]), y=float(t.mean[1]), visibility=vis,
                               existence=t.existence)
            bar.update(1)
            elapsed = time.perf_counter() - t_start
            bar.set_postfix(fps=f'{status["frames"] / max(elapsed, 1e-9):.1f}')
    except BagError as err:
        status['bag_error'] = str(err)
    finally:
        frames.close()  # stop the reader thread before the reader closes
        sync = getattr(reader, 'sync', None)
        status['unplaced'] = sync.counters.dropped_frames if sync is not None else 0
        for text in reader.warnings:
            print(f'{_PROG}: warning: {text}', file=sys.stderr)
        if outputs is not None and status.get('last_stamp') is not None:
            try:  # the final counts; a writer error is raised by outputs.close()
                outputs.write_diagnostics(status['last_stamp'], _counts(status))
            except Exception:  # noqa: BLE001
                pass
        bar.close()
        status['wall_s'] = time.perf_counter() - t_start


def _counts(status: dict) -> dict:
    """The replay's counts as ``DiagnosticsSnapshot`` fields (``/diagnostics`` of
    tracks.mcap): undecodable images are the bad images, frame sets dropped for a repeated
    or earlier stamp, and images the synchroniser could place in no set (a repeated stamp
    on one camera, or later than its set), the dropped frames."""
    bad = sum(status['bad_images'].values())
    return dict(frame_sets=status['frames'], bad_images=bad, late_frames=status['skipped'],
                dropped_frames=bad + status['skipped'] + status.get('unplaced', 0),
                tracks=status.get('live_tracks', 0))


def _output_bag(out: Path, calibration: RoomCalibration):
    """Writer of OUTDIR/tracks.mcap: every tracker_node output topic (None without rclpy).
    Its child process starts here; :func:`_writer_ready` waits for it. rclpy is imported
    in the child only."""
    if importlib.util.find_spec('rclpy') is None:
        print(f'{_PROG}: note: no rclpy, so no {out / "tracks.mcap"}', file=sys.stderr)
        return None
    path = out / 'tracks.mcap'
    if (path / 'metadata.yaml').exists():
        shutil.rmtree(path)  # replaced like tracks.csv
    return BackgroundWriter(functools.partial(output_bag_writer, path, list(calibration.names),
                                              calibration.frame_id),
                            process=True, wait=False, niceness=_WRITER_NICENESS)


def _writer_ready(outputs: BackgroundWriter | None) -> None:
    """Wait for the writer of :func:`_output_bag`; its error (e.g. an unwritable bag) is a
    user error."""
    if outputs is None:
        return
    try:
        outputs.ready()
    except Exception as err:
        # the child's error arrived pickled, so its module is loaded already
        from mbtrack_ros.nodes.output_bag import OutputBagError
        if isinstance(err, OutputBagError):
            raise _UserError(str(err)) from err
        raise


def run(args: argparse.Namespace) -> int:
    """Replay a recording through the tracker; 0 on success, 2 on bad input, 1 on a bad bag."""
    try:
        bag, calibration = _resolve_inputs(args)
        config = _config(args)
        auto = args.init_from is None  # automatic detection instead of ground-truth starts
        try:
            truth = read_ground_truth(args.init_from) if not auto else []
            eval_truth = read_ground_truth(args.eval) if args.eval is not None else None
        except CsvFormatError as err:
            raise _UserError(str(err)) from err
        if not truth and not auto:
            raise _UserError(f'{args.init_from}: ground truth is empty')
        out = Path(args.out)
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise _UserError(f'cannot create {out}: {err.strerror or err}') from err
        for name in ('tracks.csv',) + (('particles.npz',) if args.save_particles else ()):
            if (out / name).exists() and not (out / name).is_file():
                raise _UserError(f'{out / name} exists and is not a file')
        index = _FrameIndex(truth or eval_truth or [])
        if not ((bag / 'metadata.yaml').exists() or (bag / 'bag' / 'metadata.yaml').exists()):
            raise _UserError(f'{bag} is not a rosbag2 directory nor a recording directory '
                             '(no metadata.yaml)')
        try:
            with RecordingReader(bag, **_sync_options(args, bag, calibration)) as reader:
                # opened once (~0.15 s an opening); bounded work per image: at most
                # MAX_RESCALE times the calibrated size
                reader.limit_image_sizes({n: (c.width, c.height)
                                          for n, c in calibration.cameras.items()})
                first: dict[str, np.ndarray] = {}
                try:
                    for fs in reader.frames():
                        first = dict(fs.images)
                        break
                except BagError:
                    pass
                calibration = _match_calibration(calibration, reader, first)
                starts = []
                if not auto:
                    plan = plan_key_views(calibration, truth)
                    needed = {v.frame for views in plan.values() for v in views}
                    key_images = _collect_key_images(reader, index, needed)
                    starts = initial_tracks(calibration, truth, key_images, plan,
                                            skip_missing=True)
                    skipped = sorted(set(plan) - {s.person_id for s in starts})
                    if skipped:
                        print(f'{_PROG}: note: no unoccluded key view of person(s) '
                              f'{", ".join(map(str, skipped))}; not tracked', file=sys.stderr)
                    if not starts:
                        raise _UserError('no person could be initialised from the ground '
                                         'truth')
                # the writer's child process starts (its imports) while the tracker is built
                outputs = _output_bag(out, calibration)
                try:
                    tracker = Tracker(calibration, config, rng=np.random.default_rng(args.seed))
                except TrackerError as err:
                    if outputs is not None:
                        outputs.discard()
                    raise _UserError(str(err)) from err
                handed = False  # the tracking pass below closes the writer
                try:
                    _writer_ready(outputs)
                    handed = True
                    recorder = None
                    if args.save_particles:
                        from mbtrack_ros.evaluation.posterior import ParticleRecorder
                        recorder = ParticleRecorder()
                    status = {'frames': 0, 'tracks': 0, 'skipped': 0, 'tracker_s': 0.0,
                              'wall_s': 0.0, 'last_frame': -1, 'bag_error': None,
                              'bad_images': {}, 'bad_reasons': {}, 'diag_stamp': None,
                              'last_stamp': None}
                    tracks_path = out / 'tracks.csv'
                    rows: list[TrackRow] = []

                    def collect() -> Iterator[TrackRow]:
                        for row in _track_rows(tracker, reader, index, starts, args, recorder,
                                               status, outputs):
                            rows.append(row)
                            yield row

                    try:
                        write_tracks(tracks_path, collect())
                    except OSError as err:
                        raise _UserError(f'cannot write {tracks_path}: '
                                         f'{err.strerror or err}') from err
                    finally:
                        if outputs is not None:
                            outputs.close()
                except BaseException:
                    if not handed and outputs is not None:
                        outputs.discard()
                    raise
        except BagError as err:
            return _error(str(err), 1)
        except (InitiationError, FilterError, CalibrationError) as err:
            raise _UserError(str(err)) from err
        if recorder is not None:
            recorder.save(out / 'particles.npz')
        shown_n = config.joint_particles if config.algorithm == 'joint' else config.particles
        fps = status['frames'] / max(status['wall_s'], 1e-9)
        tracker_fps = status['frames'] / max(status['tracker_s'], 1e-9)
        print(f'{_PROG}: {status["frames"]} frames, {status["tracks"]} tracks, '
              f'{fps:.1f} frames/s overall, {tracker_fps:.1f} frames/s in the tracker '
              f'({config.algorithm}, N={shown_n}); wrote {tracks_path}'
              + (f' and {out / "particles.npz"}' if recorder is not None else ''),
              file=sys.stderr)
        if status['skipped']:
            print(f'{_PROG}: note: dropped {status["skipped"]} frame set(s) whose stamp was '
                  'not later than the last processed one', file=sys.stderr)
        if status.get('unplaced'):
            print(f'{_PROG}: note: dropped {status["unplaced"]} image(s) that fit no frame set '
                  '(a repeated stamp on one camera, or later than its set)', file=sys.stderr)
        if status['bad_images']:
            print(f'{_PROG}: note: dropped {sum(status["bad_images"].values())} undecodable '
                  'image(s): ' + '; '.join(f'{cam}: {n} (first: {status["bad_reasons"][cam]})'
                                           for cam, n in status['bad_images'].items()),
                  file=sys.stderr)
        if eval_truth is not None:
            last = status.get('last_stamp')
            if last is not None:  # --max-frames or a damaged bag: score the replayed part
                eval_truth = [r for r in eval_truth if r.stamp_ns <= last]
            _evaluate(rows, eval_truth, out, bag, recorder)
        if status['bag_error']:
            return _error(f'{status["bag_error"]} (kept {status["frames"]} tracked frames, '
                          f'up to frame {status["last_frame"]}, in {tracks_path})', 1)
        return 0
    except _UserError as err:
        return _error(str(err))


def _evaluate(rows: list[TrackRow], truth: list[GroundTruthRow], out: Path, bag: Path,
              recorder) -> None:
    from mbtrack_ros.evaluation.clear_mot import clear_mot
    from mbtrack_ros.evaluation.errors import EvaluationError
    from mbtrack_ros.evaluation.posterior import posterior_mass
    from mbtrack_ros.evaluation.report import format_table

    name = bag.name if bag.name != 'bag' else bag.parent.name
    try:
        result = clear_mot(rows, truth, name=name)
        posterior = {}
        if recorder is not None and len(recorder):
            posterior[name] = posterior_mass(recorder.particle_set(), truth, rows,
                                             matching=result)
        print(format_table([result], posterior))
    except EvaluationError as err:
        print(f'{_PROG}: note: evaluation failed: {err}', file=sys.stderr)
