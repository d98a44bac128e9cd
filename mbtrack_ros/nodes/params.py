"""Parameters of ``tracker_node``: declared in one place, read once into frozen dataclasses.

Parameter reference (YAML: ``tracker_node: ros__parameters: ...``; doubles written as
``1.0``; per-camera entries under ``camera.<name>.``):

==============================  =========  =================================================
name                            type       meaning (default)
==============================  =========  =================================================
calibration_file                string     room calibration YAML (required)
cameras                         string[]   cameras to use (default: all in the calibration)
input_mode                      string     ``images`` (cameras' images, default) or
                                           ``foreground`` (fusion: the camera nodes'
                                           working images and foreground masks)
image_transport                 string     ``raw`` or ``compressed`` for every camera (raw)
image_reliability               string     ``best_effort`` (sensor data QoS) or ``reliable``
                                           (no frame lost when replaying a bag)
qos_depth                       int        history depth of reliable image subscriptions
                                           and of every output publisher: a reliable
                                           peer lagging more messages loses the oldest (10)
camera.<name>.image_topic       string     (``/<name>/image_raw``, ``.../compressed``;
                                           foreground mode: ``/<name>/working/image``)
camera.<name>.foreground_topic  string     foreground mode: the camera node's masks
                                           (``/<name>/working/foreground``, mono8;
                                           ``.../compressed``, PNG, with the
                                           compressed transport)
score_timeout                   double     foreground mode: wall-clock wait for a camera
                                           node's scores of the frame set's particles, s;
                                           a camera that did not answer in time is scored
                                           by the tracker and not waited for during a
                                           back-off (1, 2, 4, ... 64 frame sets); 0 = the
                                           tracker scores every camera itself (0.05)
camera.<name>.transport         string     per-camera override of ``image_transport``
camera.<name>.camera_info_topic string     optional CameraInfo topic for a size check ('')
sync.tolerance                  double     largest distance of an image's capture time
                                           from its frame set's time, s; 0 = half the
                                           frame period, measured from the stamps (0.0)
sync.frame_rate                 double     the cameras' nominal frame rate, Hz, checked
                                           against the stamps (0.0 = not given)
sync.timeout                    double     wait for a late camera, message time, s (0.2)
camera.<name>.time_offset       double     s added to the camera's stamps to give its
                                           capture time (a clock offset; default: the
                                           calibration's ``time_offset``, else 0.0)
output_frame_id                 string     frame of all outputs ('' = calibration frame)
rescale_images                  bool       resize images whose size differs from the
                                           calibration (up to 4 times larger per side)
                                           instead of dropping them (false)
debug_images                    bool       always publish ``~/debug/<cam>/occlusion``
                                           (default false: only when subscribed)
diagnostics_period              double     seconds of message time between /diagnostics (1.0);
                                           of wall-clock time while no frame set forms
init_ground_truth               string     ground-truth CSV to start/end tracks from ('')
output_bag                      string     also write every output to this MCAP bag ('')
max_pending_sets                int        frame sets queued for the tracker; the oldest
                                           is dropped (counted in /diagnostics) only when
                                           it stays this far behind (15 = 1 s at 15 Hz)
executor                        string     ``events`` (rclpy EventsExecutor, default),
                                           ``single`` or ``multi`` (Python executors)
warm_up                         bool       run the pipeline on a few synthetic frames at
                                           start so the first real frames pay no kernel
                                           loading (true)
outputs.persons                 bool       REP-155 persons: /humans/persons/tracked and
                                           per person location_confidence, anonymous
                                           (true; needs hri_msgs)
outputs.detections              bool       ~/detections vision_msgs/Detection3DArray
                                           (true; needs vision_msgs)
outputs.tf                      bool       person_<id> frames on /tf (true; needs
                                           tf2_msgs)
tracker.algorithm               string     hjs | hjs-groups | separable | joint | a registered
                                           baseline
tracker.particles               int        particles per target (100)
tracker.subsample               int        likelihood on every k-th image row, 1-8 (1; a
                                           speed option that costs accuracy)
tracker.pipeline_search         bool       search frame t for new people on a worker
                                           thread while frame t+1 is filtered (false;
                                           people start one frame later)
tracker.working_pixels          int        pixels per camera image the tracker works
                                           on; larger images are resized once per frame
                                           (76800 = 320x240; fewer: less CPU, less
                                           accuracy)
tracker.joint_particles         int        joint-filter particles (10000)
tracker.sigma                   double     likelihood width, 000 Eq. 19 (0.12)
tracker.d_occ                   double     occlusion penalty, 000 Eq. 26 (0.15)
tracker.coverage_gain           double     weight k of the foreground coverage f of a
                                           particle's silhouette, k f per camera, in the
                                           particle weights; 0 = colour alone (2.0)
tracker.min_inside_share        double     a camera that sees less of a target inside its
                                           image says nothing about it, share 0-1 (0.5)
tracker.min_visible_share       double     a camera in which a target is hidden behind
                                           others (expected visible fraction below this)
                                           says nothing about it, share 0-1 (0.1)
tracker.mrf_radius              double     exclusion radius, m (0.3; 000 §VI-A: 0.4)
tracker.use_mrf                 bool       spatial-exclusion MRF prior (true)
tracker.seed                    int        random seed, -1 = fresh entropy (-1)
tracker.release_time            double     s without foreground support before a track is
                                           released, 003 §4.3 (1.0)
tracker.release_recover_time    double     s of support in a row after which that time
                                           starts again for a track that was spare in it;
                                           0 = one supported frame (0.2)
detection.enabled               bool       automatic detection, model acquisition and release
                                           inside the tracker step; off with
                                           init_ground_truth (true)
detection.threshold             double     smallest combined log response of a new
                                           detection (1.0)
detection.beside_threshold      double     smallest score of a detection that starts a
                                           track within 1 m of another track; 0 = the
                                           threshold above alone (3.0)
detection.spare_support         double     exclusive support below which a track that
                                           overlaps another one is released as spare;
                                           0 = off (0.25)
detection.reuse_time            double     s a released track stays lost: a person re-found
                                           within 1.5 m who looks like it takes its id back
                                           (no new id); it ends after that (3.0; 0 = at once)
detection.every                 int        run the detection pipeline (release, existence,
                                           background, search) on every k-th frame set
                                           only (1; a speed option that costs accuracy)
detection.adaptation_rate       double     blending rate of the slow appearance-model
                                           adaptation of confirmed, unoccluded tracks;
                                           0 = off (0.05)
motion.velocity_noise           double     velocity diffusion, m/s per sqrt(s) (0.6)
motion.position_noise           double     extra position diffusion, m per sqrt(s) (0.15)
motion.orientation_noise        double     orientation diffusion, rad per sqrt(s) (1.0)
motion.max_speed                double     velocities are clipped to this, m/s (3.0)
motion.orientation_follows_velocity
                                bool       a walking body faces its direction of motion,
                                           as in 000 §VI (false: the orientation is a
                                           random walk of its own)
motion.wall_stops               bool       a particle reaching the floor's border loses its
                                           velocity into it (true; false: it bounces)
motion.sit_flip_rate            double     rate of sitting <-> standing flips of the
                                           particles, 1/s (0.05; 0 = the posture of the
                                           track's start, as 000 §VI-A's 4D state)
==============================  =========  =================================================
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import (
    InvalidParameterTypeException, InvalidParameterValueException, ParameterException)
from rclpy.node import Node

from mbtrack_ros.core.camera import CalibrationError, RoomCalibration
from mbtrack_ros.core.dynamics import MotionConfig
from mbtrack_ros.core.detection.manager import AutoDetectionConfig
from mbtrack_ros.core.detection.release import ReleaseConfig
from mbtrack_ros.core.likelihood import LikelihoodConfig
from mbtrack_ros.core.tracker import (
    MAX_JOINT_PARTICLES, MAX_PARTICLES, TrackerConfig, TrackerError)
from mbtrack_ros.nodes.tracker_parameters import TRACKER_PARAMETERS, tracker_config_values
from mbtrack_ros.recording.calibration_io import load_calibration

__all__ = ['EXECUTORS', 'RELIABILITIES', 'TRACKER_PARAMETERS', 'TRANSPORTS', 'CameraInput',
           'NodeParams', 'ParamsError', 'declare_and_read']

TRANSPORTS = ('raw', 'compressed')
INPUT_MODES = ('images', 'foreground')
RELIABILITIES = ('best_effort', 'reliable')
EXECUTORS = ('events', 'single', 'multi')


class ParamsError(ValueError):
    """A missing, out-of-range or inconsistent node parameter (one-line reason)."""


@dataclass(frozen=True)
class CameraInput:
    """Where one camera's images come from."""

    name: str
    image_topic: str
    transport: str
    camera_info_topic: str = ''


@dataclass(frozen=True)
class NodeParams:
    """Every tracker_node parameter, validated (see the module docstring)."""

    calibration_file: str
    cameras: tuple[CameraInput, ...]
    image_reliability: str
    tracker: TrackerConfig
    tolerance_ns: int
    timeout_ns: int
    output_frame_id: str
    rescale_images: bool
    debug_images: bool
    diagnostics_period_ns: int
    init_ground_truth: str
    output_bag: str
    max_pending_sets: int
    executor: str = 'events'
    warm_up: bool = True
    qos_depth: int = 10
    outputs_persons: bool = True
    outputs_detections: bool = True
    outputs_tf: bool = True
    frame_rate: float = 0.0
    time_offsets: dict[str, float] = field(default_factory=dict)
    input_mode: str = 'images'
    score_timeout: float = 0.05

    @property
    def camera_names(self) -> list[str]:
        return [c.name for c in self.cameras]


def _fr(lo: float, hi: float) -> dict[str, Any]:
    return {'floating_point_range': [FloatingPointRange(from_value=lo, to_value=hi, step=0.0)]}


def _ir(lo: int, hi: int) -> dict[str, Any]:
    return {'integer_range': [IntegerRange(from_value=lo, to_value=hi, step=1)]}


_MOTION = MotionConfig()

# name -> (default, description, extra descriptor fields). The one place parameters live.
GLOBAL_PARAMETERS: dict[str, tuple[Any, str, dict[str, Any]]] = {
    'calibration_file': ('', 'room calibration YAML (required)', {}),
    'cameras': ([''], 'camera names to use; empty = all cameras of the calibration', {}),
    'input_mode': ('images', 'images | foreground: the cameras\' images, or (fusion) the '
                   'camera nodes\' working images and foreground masks', {}),
    'score_timeout': (0.05, 'foreground mode: wall-clock wait for a camera node\'s scores of '
                      'the particles, s; 0 = the tracker scores every camera itself',
                      _fr(0.0, 10.0)),
    'image_transport': ('raw', 'raw | compressed: default image transport', {}),
    'image_reliability': ('best_effort', 'best_effort (sensor data QoS) | reliable: image '
                          'subscriptions; reliable loses no frame of a replayed bag', {}),
    'qos_depth': (10, 'history depth of reliable image subscriptions and of the outputs; '
                  'a reliable subscriber (or camera) lagging more messages loses the oldest',
                  _ir(1, 1000)),
    'sync.tolerance': (0.0, 'largest distance of an image capture time from its frame '
                       'set time, s; 0 = half the frame period (measured)', _fr(0.0, 1.0)),
    'sync.frame_rate': (0.0, 'nominal camera frame rate, Hz, checked against the stamps; '
                        '0 = not given', _fr(0.0, 1000.0)),
    'sync.timeout': (0.2, 'message-time wait for a late camera, s', _fr(0.001, 10.0)),
    'output_frame_id': ('', 'frame id of all outputs; empty = calibration frame', {}),
    'rescale_images': (False, 'resize images whose size differs from the calibration', {}),
    'debug_images': (False, 'always compute the occlusion debug images', {}),
    'diagnostics_period': (1.0, 'message time between /diagnostics messages, s',
                           _fr(0.05, 60.0)),
    'init_ground_truth': ('', 'ground-truth CSV used to start and end tracks', {}),
    'output_bag': ('', 'also write all outputs to this MCAP bag directory', {}),
    'max_pending_sets': (15, 'frame sets queued for the tracker before dropping the oldest',
                         _ir(1, 300)),
    'executor': ('events', 'events (rclpy EventsExecutor) | single | multi: how callbacks '
                 'are dispatched; the tracker step has its own thread', {}),
    'warm_up': (True, 'run the tracker on a few synthetic frames at start (loads every '
                'compiled kernel before the first real frame)', {}),
    'outputs.persons': (True, 'REP-155 persons: /humans/persons/tracked, per person '
                        'location_confidence and anonymous (needs hri_msgs)', {}),
    'outputs.detections': (True, '~/detections as vision_msgs/Detection3DArray (needs '
                           'vision_msgs)', {}),
    'outputs.tf': (True, 'a person_<id> frame per track on /tf under the output frame '
                   '(needs tf2_msgs)', {}),
    'tracker.algorithm': ('hjs', 'hjs | hjs-groups | separable | joint | a registered baseline',
                          {}),
    'tracker.particles': (100, 'particles per target (000 §VI)', _ir(1, MAX_PARTICLES)),
    'tracker.subsample': (1, 'likelihood on every k-th image row (speed option)', _ir(1, 8)),
    'tracker.pipeline_search': (False, 'search frame t for new people on a worker thread '
                                'while frame t+1 is filtered (TrackerConfig.pipeline_search)',
                                {}),
    'tracker.working_pixels': (76_800, 'pixels per camera image the tracker works on: '
                               'larger images are resized once per frame, every pixel '
                               'threshold follows (TrackerConfig.working_pixels)',
                               _ir(4800, 100_000_000)),
    'tracker.joint_particles': (10_000, 'joint-filter particles',
                                _ir(1, MAX_JOINT_PARTICLES)),
    'tracker.sigma': (0.12, 'likelihood width sigma (000 Eq. 19)', _fr(1e-4, 10.0)),
    'tracker.d_occ': (0.15, 'occlusion penalty d_occ (000 Eq. 26)', _fr(0.0, 10.0)),
    'tracker.coverage_gain': (LikelihoodConfig().coverage_gain, 'weight k of the foreground '
                              'coverage f of a particle silhouette, k f per camera, in the '
                              'tracking filter particle weights '
                              '(LikelihoodConfig.coverage_gain); 0 = colour alone',
                              _fr(0.0, 100.0)),
    'tracker.min_inside_share': (0.5, 'a camera that sees less of a target\'s silhouettes '
                                 'inside its image says nothing about the target '
                                 '(TrackerConfig.min_inside_share)', _fr(0.0, 1.0)),
    'tracker.min_visible_share': (0.1, 'a camera in which a target is hidden behind others '
                                  '(expected visible fraction below this) says nothing about '
                                  'it (TrackerConfig.min_visible_share)', _fr(0.0, 1.0)),
    'tracker.mrf_radius': (0.3, 'spatial exclusion radius, m (000 §VI-A: 0.4)',
                           _fr(0.0, 5.0)),
    'tracker.use_mrf': (True, 'apply the spatial-exclusion MRF prior', {}),
    'tracker.seed': (-1, 'random seed; -1 = fresh entropy', _ir(-1, 2 ** 31 - 1)),
    'tracker.release_time': (1.0, 's without foreground support before a track is released '
                             '(003 §4.3)', _fr(0.01, 3600.0)),
    'tracker.release_recover_time': (ReleaseConfig().recover_time, 's of foreground support '
                                     'in a row after which the unsupported time of a track '
                                     'that was spare in it starts again '
                                     '(ReleaseConfig.recover_time); 0 = one supported frame',
                                     _fr(0.0, 60.0)),
    'detection.enabled': (True, 'automatic detection, acquisition and release of people '
                          '(TrackerConfig.detection); off when init_ground_truth is set', {}),
    'detection.threshold': (1.0, 'smallest combined log response of a new detection',
                            _fr(-100.0, 100.0)),
    'detection.beside_threshold': (AutoDetectionConfig().beside_threshold, 'smallest '
                                   'combined log response of a detection that starts a track '
                                   'within AutoDetectionConfig.relocate_radius of another '
                                   'track (the fringe of a tracked person is no newcomer); '
                                   '0 = detection.threshold alone', _fr(0.0, 100.0)),
    'detection.spare_support': (ReleaseConfig().spare_support, 'exclusive foreground support '
                                'below which a track that overlaps another one is released as '
                                'spare (ReleaseConfig.spare_support); 0 = off',
                                _fr(0.0, 1.0)),
    'detection.reuse_time': (AutoDetectionConfig().reuse_time, 'seconds a released track '
                             'stays lost, its id given back to a person re-found within '
                             'AutoDetectionConfig.reuse_radius who looks like it; it ends '
                             'after (0 = at once)', _fr(0.0, 60.0)),
    'detection.every': (1, 'run the detection pipeline on every k-th frame set only (speed '
                        'option, TrackerConfig.detection_every)', _ir(1, 30)),
    'detection.adaptation_rate': (AutoDetectionConfig().adaptation.rate, 'blending rate of '
                                  'the slow appearance-model adaptation of confirmed, '
                                  'unoccluded tracks (TrackerConfig.adaptation_rate); '
                                  '0 = off', _fr(0.0, 1.0)),
    'motion.velocity_noise': (_MOTION.velocity_noise, 'velocity diffusion of the motion '
                              'model, m/s per sqrt(s) (000 §VI-A)', _fr(0.0, 10.0)),
    'motion.position_noise': (_MOTION.position_noise, 'extra position diffusion, m per '
                              'sqrt(s)', _fr(0.0, 10.0)),
    'motion.orientation_noise': (_MOTION.orientation_noise, 'orientation diffusion, rad per '
                                 'sqrt(s)', _fr(0.0, 10.0)),
    'motion.max_speed': (_MOTION.max_speed, 'velocities are clipped to this norm, m/s',
                         _fr(0.01, 20.0)),
    'motion.orientation_follows_velocity': (
        _MOTION.orientation_follows_velocity, 'a walking body faces its direction of motion '
        '(000 §VI); false: the orientation is a random walk of its own', {}),
    'motion.wall_stops': (_MOTION.wall_stops, 'a particle reaching the floor\'s border loses '
                          'its velocity into it; false: it bounces back', {}),
    'motion.sit_flip_rate': (_MOTION.sit_flip_rate, 'rate of sitting <-> standing flips of '
                             'the particles, 1/s; 0: the posture of the track\'s start (000 '
                             '§VI-A: position and velocity only)', _fr(0.0, 10.0)),
}


def _declare(node: Node, name: str, default: Any, description: str,
             extra: dict[str, Any]) -> Any:
    descriptor = ParameterDescriptor(description=description, **extra)
    try:
        return node.declare_parameter(name, default, descriptor).value
    except InvalidParameterTypeException as err:
        raise ParamsError(f'parameter {name!r}: wrong type (expected '
                          f'{type(default).__name__}, e.g. {default!r})') from err
    except InvalidParameterValueException as err:
        rng = extra.get('floating_point_range') or extra.get('integer_range')
        bounds = f' (allowed {rng[0].from_value} .. {rng[0].to_value})' if rng else ''
        raise ParamsError(f'parameter {name!r}: value out of range{bounds}') from err
    except ParameterException as err:
        raise ParamsError(f'parameter {name!r}: {err}') from err


def declare_and_read(node: Node) -> tuple[NodeParams, RoomCalibration]:
    """Declare every parameter on ``node``, validate and return them with the calibration.

    Raises:
        ParamsError: with a one-line reason (bad enum or range, missing calibration file,
            camera unknown to the calibration ...).
    """
    v = {name: _declare(node, name, *spec) for name, spec in GLOBAL_PARAMETERS.items()}
    calib_file = str(v['calibration_file'])
    if not calib_file:
        raise ParamsError('parameter calibration_file is required')
    if not Path(calib_file).is_file():
        raise ParamsError(f'calibration_file {calib_file!r} does not exist')
    calibration_warnings: list[str] = []
    try:
        calibration = load_calibration(calib_file, 'room', warn=calibration_warnings.append)
    except CalibrationError as err:
        raise ParamsError(str(err)) from err
    for line in calibration_warnings:
        node.get_logger().warning(line)
    names = [str(c) for c in v['cameras'] if str(c)] or calibration.names
    try:
        calibration = calibration.subset(names)
    except CalibrationError as err:
        raise ParamsError(f'parameter cameras: {err}') from err
    default_transport = str(v['image_transport'])
    if default_transport not in TRANSPORTS:
        raise ParamsError(f'parameter image_transport: {default_transport!r} is not one of '
                          f'{", ".join(TRANSPORTS)}')
    cameras = []
    offsets: dict[str, float] = {}
    for cam in names:
        transport = str(_declare(node, f'camera.{cam}.transport', default_transport,
                                 f'raw | compressed for {cam}', {}))
        if transport not in TRANSPORTS:
            raise ParamsError(f'parameter camera.{cam}.transport: {transport!r} is not one '
                              f'of {", ".join(TRANSPORTS)}')
        suffix = '/compressed' if transport == 'compressed' else ''
        base = 'working/image' if v['input_mode'] == 'foreground' else 'image_raw'
        topic = str(_declare(node, f'camera.{cam}.image_topic', f'/{cam}/{base}{suffix}',
                             f'image topic of {cam}', {}))
        info = str(_declare(node, f'camera.{cam}.camera_info_topic', '',
                            f'optional CameraInfo topic of {cam} (size check)', {}))
        if not topic:
            raise ParamsError(f'parameter camera.{cam}.image_topic is empty')
        cameras.append(CameraInput(cam, topic, transport, info))
        offset = _declare(node, f'camera.{cam}.time_offset',
                          float(calibration.cameras[cam].time_offset),
                          f's added to the stamps of {cam} to give its capture time',
                          _fr(-10.0, 10.0))
        if offset:
            offsets[cam] = float(offset)
    if v['input_mode'] not in INPUT_MODES:
        raise ParamsError(f'parameter input_mode: {v["input_mode"]!r} is not one of '
                          f'{", ".join(INPUT_MODES)}')
    reliability = str(v['image_reliability'])
    if reliability not in RELIABILITIES:
        raise ParamsError(f'parameter image_reliability: {reliability!r} is not one of '
                          f'{", ".join(RELIABILITIES)}')
    tolerance_ns = int(round(v['sync.tolerance'] * 1e9))
    timeout_ns = int(round(v['sync.timeout'] * 1e9))
    if timeout_ns <= tolerance_ns:
        raise ParamsError(f'sync.timeout ({v["sync.timeout"]}) must exceed sync.tolerance '
                          f'({v["sync.tolerance"]})')
    executor = str(v['executor'])
    if executor not in EXECUTORS:
        raise ParamsError(f'parameter executor: {executor!r} is not one of '
                          f'{", ".join(EXECUTORS)}')
    gt = str(v['init_ground_truth'])
    if gt and not Path(gt).is_file():
        raise ParamsError(f'init_ground_truth {gt!r} does not exist')
    try:
        tracker_values = tracker_config_values(v)
        tracker_values.update(
            seed=None if v['tracker.seed'] < 0 else int(v['tracker.seed']),
            # automatic detection (003 §4, 001) inside Tracker.step
            detection=bool(v['detection.enabled']) and not gt)  # ground truth starts tracks
        tracker = TrackerConfig.from_dict(tracker_values)
    except TrackerError as err:
        raise ParamsError(str(err)) from err
    _check_algorithm(tracker.algorithm)
    params = NodeParams(
        calibration_file=calib_file, cameras=tuple(cameras), image_reliability=reliability,
        tracker=tracker,
        tolerance_ns=tolerance_ns, timeout_ns=timeout_ns,
        frame_rate=float(v['sync.frame_rate']), time_offsets=offsets,
        output_frame_id=str(v['output_frame_id']) or calibration.frame_id,
        rescale_images=bool(v['rescale_images']), debug_images=bool(v['debug_images']),
        diagnostics_period_ns=int(round(v['diagnostics_period'] * 1e9)),
        init_ground_truth=gt, output_bag=str(v['output_bag']),
        max_pending_sets=int(v['max_pending_sets']), executor=executor,
        warm_up=bool(v['warm_up']), qos_depth=int(v['qos_depth']),
        outputs_persons=bool(v['outputs.persons']),
        outputs_detections=bool(v['outputs.detections']), outputs_tf=bool(v['outputs.tf']),
        input_mode=str(v['input_mode']), score_timeout=float(v['score_timeout']))
    return params, calibration


def _check_algorithm(name: str) -> None:
    from mbtrack_ros.core.filters import available_filters
    names = available_filters()
    if name not in names:
        raise ParamsError(f'parameter tracker.algorithm: {name!r} is not one of '
                          f'{", ".join(names)}')
