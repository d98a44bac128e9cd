"""``camera_node``: the per-camera half of the pipeline, on the camera's host.

One node per camera (:class:`~mbtrack_ros.core.detection.camera_stage.CameraStage`):
subscribes to the camera (raw or compressed, ``qos_profile_sensor_data``), adds the
camera's ``time_offset`` to the stamps, resizes once to the tracker's working size
(``tracker.working_pixels``), runs the background model and the foreground test (003 §4.2),
and publishes per frame, stamped with the (offset) input stamp and the camera's frame id:

* ``working/image`` (``sensor_msgs/Image`` rgb8, or with ``image_format: jpeg``
  ``working/image/compressed``): the working-size image;
* ``working/foreground`` (``sensor_msgs/Image`` ``mono8``, or with ``image_format: jpeg``
  ``working/foreground/compressed``, ``sensor_msgs/CompressedImage`` PNG ``mono8``): bit
  planes 0x80 foreground, 0x40 possible person of the bootstrap, 0x20 presence
  (foreground that is no ghost); while the model bootstraps an empty message whose
  ``encoding`` (``format``) is ``bootstrap`` (``bootstrap started`` on the frame that
  completes it). The masks follow the image's encoding: raw (75 KiB at 320x240) where
  bandwidth is cheap (one host: shared memory), as the fusion node reads a raw plane in
  0.03 ms per camera and frame and decodes a PNG in 0.5 ms (``mbtrack bench --fusion``
  prints both); PNG (2-3 KiB) next to JPEG images, for camera hosts on a slower network.

It subscribes to the tracker's ``~/tracks`` (``tracks_topic``) and keeps the model update
of each frame off the silhouettes of the latest tracks (one frame of latency: frame t's
update uses frame t-1's tracks), and to ``working/regions`` (the people cue of the online
bootstrap, which the fusion tracker computes from every camera on a thread of its own, in
1-3 s: until the regions come, at most ``region_wait`` seconds, the frames go out as those
of a bootstrapping model, without foreground and without updating it, so that no frame
waits for them). Topic names are relative: start the node in the camera's namespace
(``/<camera>``).

It also scores the fusion tracker's particles in its camera: a request on
``working/score_request`` (``std_msgs/UInt8MultiArray``,
:mod:`~mbtrack_ros.nodes.score_messages`: the particles of the frame set, the key views
when they changed) is answered on ``working/scores`` with the camera's share of the HJS
likelihood on the frame of the request's stamp (:meth:`CameraStage.score`; on the raw
working image, also with ``image_format: jpeg``), or with no scores when the frame is
not among the last ``RECENT_FRAMES`` or the key views are missing (a restarted node: the
tracker then scores the camera itself and sends them again). The answer runs in the
request's callback (a few milliseconds of compiled code that the tracker waits for).
"""
from __future__ import annotations

import sys
import threading
import time
from collections import OrderedDict, deque

import cv2
import numpy as np
import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CompressedImage, Image, PointCloud2
from std_msgs.msg import UInt8MultiArray

from mbtrack_ros.core.camera import CalibrationError, RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.camera_stage import (
    CameraStage, pack_masks, unpack_regions)
from mbtrack_ros.core.likelihood import CameraRequest
from mbtrack_ros.core.tracker import TrackerConfig, TrackerError, length_scale
from mbtrack_ros.nodes.conversions import (
    ImageConversionError, compressed_to_rgb, image_to_rgb, mono_to_image, rgb_to_compressed,
    rgb_to_image, stamp_to_ns)
from mbtrack_ros.nodes.messages import make_header
from mbtrack_ros.nodes.score_messages import (
    ScoreMessageError, read_request, scores_message)
from mbtrack_ros.nodes.transport import use_large_shm_segment

__all__ = ['CAMERA_PARAMETERS', 'CameraNode', 'cloud_columns', 'foreground_message', 'main']

FOREGROUND_FORMAT = 'mono8; png compressed mono8'
WARN_PERIOD_S = 10.0
RECENT_FRAMES = 8   # frames kept for the tracker's score requests (about 0.5 s at 15 Hz)


def _fr(lo: float, hi: float) -> dict:
    return {'floating_point_range': [FloatingPointRange(from_value=lo, to_value=hi, step=0.0)]}


def _ir(lo: int, hi: int) -> dict:
    return {'integer_range': [IntegerRange(from_value=lo, to_value=hi, step=1)]}


#: name -> (default, description, descriptor extras): every camera_node parameter
CAMERA_PARAMETERS = {
    'calibration_file': ('', 'room calibration YAML (required)', {}),
    'camera': ('', 'name of this camera in the calibration (required)', {}),
    'image_topic': ('', 'camera image topic; empty = /<camera>/image_raw[/compressed]', {}),
    'image_transport': ('raw', 'raw | compressed: the camera topic\'s type', {}),
    'image_reliability': ('best_effort', 'best_effort (sensor data QoS) | reliable: the '
                          'camera subscription; reliable loses no frame of a replayed bag',
                          {}),
    'time_offset': (0.0, 'seconds added to the camera\'s stamps (its clock against the '
                    'tracker\'s)', _fr(-3600.0, 3600.0)),
    'rescale_images': (False, 'resize images whose size differs from the calibration '
                       'instead of dropping them', {}),
    'tracker.working_pixels': (76800, 'the tracker\'s working size, pixels per image: a '
                               'larger image is resized once, here', _ir(4800, 100_000_000)),
    'image_format': ('raw', 'raw | jpeg: the encoding of the working image and its masks '
                     '(raw: rgb8 and mono8, the tracks of one process and the least CPU '
                     'in the tracker; jpeg: JPEG and PNG, about a tenth of the bandwidth)',
                     {}),
    'jpeg_quality': (90, 'JPEG quality of image_format jpeg', _ir(1, 100)),
    'tracks_topic': ('/tracker_node/tracks', 'the fusion tracker\'s tracks (PointCloud2)',
                     {}),
    'region_wait': (5.0, 'seconds after the bootstrap the model waits for the '
                    'tracker\'s people-cue regions (meanwhile its frames go out without '
                    'foreground), then goes on without', _fr(0.0, 60.0)),
    'warm_up': (True, 'run a throwaway stage on a few synthetic frames at start (loads the '
                'compiled kernels before the first real frame)', {}),
    'max_pending': (15, 'frames queued for processing; the oldest is dropped beyond',
                    _ir(1, 300)),
}


def foreground_message(frame, header, *, compressed: bool = False):
    """The ``working/foreground`` message of a :class:`CameraFrame`: its packed masks
    (:func:`pack_masks`) as a raw ``mono8`` ``Image``, or with ``compressed`` a PNG
    ``CompressedImage``; while the model bootstraps an empty one whose encoding (format) is
    ``bootstrap`` or ``bootstrap started``."""
    if frame.foreground is None:
        marker = 'bootstrap started' if frame.started else 'bootstrap'
        msg = CompressedImage() if compressed else Image()
        msg.header = header
        if compressed:
            msg.format = marker
        else:
            msg.encoding = marker
        return msg
    packed = pack_masks(frame.foreground, frame.possible, frame.presence)
    if not compressed:
        return mono_to_image(packed, header)
    ok, data = cv2.imencode('.png', packed)
    msg = CompressedImage()
    msg.header = header
    msg.format = FOREGROUND_FORMAT
    msg.data = data.tobytes()
    return msg


class CameraParamsError(ValueError):
    """A missing or invalid camera_node parameter (one line)."""


def cloud_columns(msg: PointCloud2, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The named float32/uint32 fields of a ``PointCloud2`` as (N,) float64 arrays (by the
    message's own field offsets; a field missing from it is all NaN)."""
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    raw = np.frombuffer(bytes(msg.data), np.uint8)
    if n == 0 or step == 0 or raw.size < n * step:
        return {k: np.zeros(0) for k in names}
    rows = raw[:n * step].reshape(n, step)
    fields = {f.name: f for f in msg.fields}
    out = {}
    for k in names:
        f = fields.get(k)
        if f is None or f.datatype not in (6, 7) or f.offset + 4 > step:  # UINT32, FLOAT32
            out[k] = np.full(n, np.nan)
            continue
        kind = '<u4' if f.datatype == 6 else '<f4'
        out[k] = rows[:, f.offset:f.offset + 4].copy().view(kind).ravel().astype(np.float64)
    return out


class CameraNode(Node):
    """The camera node (see the module docstring). Raises :class:`CameraParamsError`."""

    def __init__(self, *, cli_args: list[str] | None = None, context=None,
                 worker: bool = True) -> None:
        super().__init__('camera_node', cli_args=cli_args, context=context)
        v = {}
        for name, (default, text, extra) in CAMERA_PARAMETERS.items():
            try:
                v[name] = self.declare_parameter(
                    name, default, ParameterDescriptor(description=text, **extra)).value
            except Exception as err:  # noqa: BLE001 - type or range: one line
                raise CameraParamsError(f'parameter {name!r}: {err}') from err
        if not v['calibration_file']:
            raise CameraParamsError('parameter calibration_file is required')
        try:
            calibration = RoomCalibration.load(v['calibration_file'])
        except (CalibrationError, OSError) as err:
            raise CameraParamsError(f'calibration_file: {err}') from err
        name = str(v['camera'])
        if name not in calibration.cameras:
            raise CameraParamsError(f'parameter camera: {name!r} is not one of '
                                    f'{", ".join(calibration.names)}')
        for key, allowed in (('image_transport', ('raw', 'compressed')),
                             ('image_reliability', ('best_effort', 'reliable')),
                             ('image_format', ('raw', 'jpeg'))):
            if v[key] not in allowed:
                raise CameraParamsError(f'parameter {key}: {v[key]!r} is not one of '
                                        f'{", ".join(allowed)}')
        try:
            config = TrackerConfig(working_pixels=int(v['tracker.working_pixels']))
            background = config.detection_config(length_scale(
                config.working_calibration(calibration))).background
        except TrackerError as err:
            raise CameraParamsError(str(err)) from err
        self.name = name
        self.camera = calibration.cameras[name]
        self.stage = CameraStage(self.camera, background,
                                 working_pixels=int(v['tracker.working_pixels']))
        self.offset_ns = int(round(float(v['time_offset']) * 1e9))
        self.rescale = bool(v['rescale_images'])
        self.jpeg = v['image_format'] == 'jpeg'
        self.quality = int(v['jpeg_quality'])
        self.region_wait = float(v['region_wait'])
        self.max_pending = int(v['max_pending'])
        self._lock = threading.Condition()
        self._queue: deque = deque()
        self._regions: tuple[int, np.ndarray] | None = None  # (stamp, packed) received
        self._started_stamp: int | None = None
        self._started_wall = 0.0   # monotonic time the model started (bootstrapped)
        self._closing = False
        self._warned: dict[str, float] = {}
        self.processed = 0
        self.dropped = 0
        self.scored = 0    # score requests answered with scores
        self._recent: OrderedDict = OrderedDict()   # stamp -> CameraFrame published
        self.seconds = 0.0  # processing time, wall clock
        if v['warm_up']:
            self._warm_up(background, int(v['tracker.working_pixels']))
        compressed = v['image_transport'] == 'compressed'
        topic = str(v['image_topic']) or \
            f'/{name}/image_raw' + ('/compressed' if compressed else '')
        out_qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.pub_image = (self.create_publisher(CompressedImage, 'working/image/compressed',
                                                out_qos) if self.jpeg else
                          self.create_publisher(Image, 'working/image', out_qos))
        self.pub_foreground = (
            self.create_publisher(CompressedImage, 'working/foreground/compressed', out_qos)
            if self.jpeg else self.create_publisher(Image, 'working/foreground', out_qos))
        in_qos = qos_profile_sensor_data if v['image_reliability'] == 'best_effort' else \
            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(CompressedImage if compressed else Image, topic,
                                 self._on_image, in_qos)
        self.create_subscription(PointCloud2, str(v['tracks_topic']), self._on_tracks,
                                 out_qos)
        self.create_subscription(CompressedImage, 'working/regions', self._on_regions,
                                 out_qos)
        self.pub_scores = self.create_publisher(UInt8MultiArray, 'working/scores', out_qos)
        self.create_subscription(UInt8MultiArray, 'working/score_request',
                                 self._on_score_request, out_qos)
        self._worker = None
        if worker:
            self._worker = threading.Thread(target=self._loop, name='camera_stage',
                                            daemon=True)
            self._worker.start()
        self.get_logger().info(f'{name}: {topic} -> working/image, working/foreground '
                               f'({self.stage.camera.width}x{self.stage.camera.height})')

    def _warm_up(self, background, working_pixels: int) -> None:
        """Load the stage's compiled kernels (numba cache) on synthetic frames with a
        throwaway stage, so the first real frames do not queue up behind the loading."""
        stage = CameraStage(self.camera, background, working_pixels=working_pixels)
        rng = np.random.default_rng(0)
        base = rng.integers(0, 255, (self.camera.height, self.camera.width, 3), np.uint8)
        for k in range(background.bootstrap_frames + 2):
            image = base.copy()
            image[:, 4 * k:4 * k + 8] = 255 - image[:, 4 * k:4 * k + 8]
            stage.process(image)
            stage.awaiting_regions = False
        # and the scoring kernel (the first score request is then answered within the
        # tracker's score_timeout)
        stage.score(CameraRequest(np.zeros((1, 6)), np.zeros(1, np.int64), np.ones(1),
                                  np.full(1, 1.7), np.full(1, 0.5), 0.45, np.zeros((1, 1)),
                                  np.ones(1, np.int64), np.full((1, 1, 1536), 1 / 512),
                                  False, 0.0288, 0.15, 1, 20, True, 0.3))

    def warn_once(self, cause: str, text: str) -> None:
        now = time.monotonic()
        if now - self._warned.get(cause, -1e9) >= WARN_PERIOD_S:
            self._warned[cause] = now
            self.get_logger().warning(text)

    # -- callbacks: convert and queue -----------------------------------------------------
    def _on_image(self, msg) -> None:
        # decoded at the working size, resized once from the message's pixels (the decoder
        # and resize of the tracker node and mbtrack replay); without rescale_images an
        # image of another size than the calibration's is refused before decoding
        limits = {'to': self.stage.camera}
        if not self.rescale:
            limits['expected'] = (self.camera.width, self.camera.height)
        try:
            rgb = compressed_to_rgb(msg, **limits) if isinstance(msg, CompressedImage) \
                else image_to_rgb(msg, **limits)
        except ImageConversionError as err:
            self.dropped += 1
            if err.cause == 'size-mismatch':
                self.warn_once('size', f'{self.name}: {err}: dropped (set rescale_images to '
                               'resize)')
            else:
                self.warn_once('convert', f'{self.name}: dropping bad image: {err}')
            return
        with self._lock:
            self._queue.append((stamp_to_ns(msg.header.stamp) + self.offset_ns, rgb))
            while len(self._queue) > self.max_pending:
                self._queue.popleft()
                self.dropped += 1
            self._lock.notify_all()

    def _on_tracks(self, msg: PointCloud2) -> None:
        c = cloud_columns(msg, ('x', 'y', 'vx', 'vy', 'height'))
        xy = np.stack([c['x'], c['y']], axis=1)
        good = np.all(np.isfinite(xy), axis=1)
        if not good.all() or (not len(xy) and msg.width * msg.height):
            self.warn_once('tracks', f'{self.name}: track points without a finite x, y '
                           'ignored (or a malformed cloud)')
        # renders, then swaps the stage's exclusion in one assignment: the next frame's
        # update takes the tracks whole, old or new
        try:
            self.stage.set_tracks(xy[good],
                                  np.nan_to_num(np.stack([c['vx'], c['vy']], axis=1)[good]),
                                  c['height'][good])
        except ValueError as err:  # ShapeError: an impossible shape
            self.warn_once('tracks', f'{self.name}: tracks ignored: {err}')

    def _on_regions(self, msg: CompressedImage) -> None:
        try:
            packed = compressed_to_rgb(msg)
        except ImageConversionError as err:
            self.warn_once('regions', f'{self.name}: bad regions message: {err}')
            return
        with self._lock:
            self._regions = (stamp_to_ns(msg.header.stamp), packed)
            self._lock.notify_all()

    def _on_score_request(self, msg: UInt8MultiArray) -> None:
        """The tracker's particles scored on the frame of the request's stamp, answered
        at once (no scores when the frame is gone or the request cannot be scored)."""
        try:
            seq, stamp, request = read_request(msg)
        except ScoreMessageError as err:
            self.warn_once('score', f'{self.name}: bad score request: {err}')
            return
        with self._lock:
            frame = self._recent.get(stamp)
        scores = None
        if frame is not None:
            try:
                scores = self.stage.score(request, frame)
            except DetectionError as err:
                self.warn_once('score', f'{self.name}: score request refused: {err}')
        self.pub_scores.publish(scores_message(seq, stamp, scores))
        self.scored += scores is not None

    # -- the stage ------------------------------------------------------------------------
    def _loop(self) -> None:
        while True:
            with self._lock:
                while not self._queue and not self._closing:
                    self._lock.wait()
                if self._closing:
                    return
            self.process_pending()

    def _take_regions(self) -> bool:
        """Apply the bootstrap regions the tracker sent for this model's start, if they
        came; True when the model goes on (with them, or without them ``region_wait`` s
        after its start), False while it still waits for them."""
        with self._lock:
            got = self._regions
            if got is not None and got[0] >= self._started_stamp:
                self._regions = None
            else:
                got = None
        if got is not None:
            region, body, core = unpack_regions(got[1])
            try:
                self.stage.set_regions(region, body, core)
            except DetectionError as err:
                self.warn_once('regions', f'{self.name}: regions refused: {err}')
        elif time.monotonic() - self._started_wall < self.region_wait:
            return False
        else:
            self.warn_once('regions', f'{self.name}: no bootstrap regions from the '
                           f'tracker within {self.region_wait} s: going on without')
        self.stage.awaiting_regions = False
        return True

    def process_pending(self) -> None:
        """Process every queued frame, oldest first."""
        while True:
            with self._lock:
                if not self._queue or self._closing:
                    return
                stamp, rgb = self._queue.popleft()
            t0 = time.perf_counter()
            try:
                if self.stage.awaiting_regions and not self._take_regions():
                    # the tracker is still computing the regions: the frame goes out as
                    # one of a bootstrapping model (no foreground), none is held back
                    frame = self.stage.hold(rgb)
                else:
                    frame = self.stage.process(rgb)
            except DetectionError as err:
                self.dropped += 1
                self.warn_once('stage', f'{self.name}: frame dropped: {err}')
                continue
            if frame.started:
                self._started_stamp = stamp
                self._started_wall = time.monotonic()
            self.publish(stamp, frame)
            self.seconds += time.perf_counter() - t0
            self.processed += 1

    def publish(self, stamp_ns: int, frame) -> None:
        with self._lock:   # the frames the tracker may ask to score particles on
            self._recent[stamp_ns] = frame
            while len(self._recent) > RECENT_FRAMES:
                self._recent.popitem(last=False)
        header = make_header(stamp_ns, self.camera.frame_id)
        if self.jpeg:
            image = rgb_to_compressed(frame.image, header, 'jpeg', quality=self.quality)
        else:
            image = rgb_to_image(frame.image, header)
        self.pub_image.publish(image)
        self.pub_foreground.publish(foreground_message(frame, header, compressed=self.jpeg))

    def destroy_node(self) -> None:
        self.get_logger().info(
            f'{self.name}: {self.processed} frames processed '
            f'({1e3 * self.seconds / max(self.processed, 1):.1f} ms each), '
            f'{self.dropped} dropped, {self.scored} score requests answered')
        with self._lock:
            self._closing = True
            self._lock.notify_all()
        if self._worker is not None:
            self._worker.join(timeout=10.0)
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point ``camera_node``; exits 2 on bad parameters."""
    use_large_shm_segment()  # before rclpy.init: it publishes working-size images
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = CameraNode()
        rclpy.spin(node)
    except CameraParamsError as err:
        print(f'camera_node: error: {err}', file=sys.stderr)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
