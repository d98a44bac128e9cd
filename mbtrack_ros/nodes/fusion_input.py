"""The fusion tracker's input (``tracker_node`` with ``input_mode: foreground``).

Instead of the cameras' images the tracker takes the camera nodes' streams
(:mod:`mbtrack_ros.nodes.camera_node`): per camera the working-size image (``image_topic``,
``sensor_msgs/Image`` or ``CompressedImage``) and its foreground masks
(``camera.<name>.foreground_topic``: ``sensor_msgs/Image`` mono8 with the raw image
transport, ``CompressedImage`` PNG on ``.../foreground/compressed`` with the compressed
one, as the camera node's ``image_format`` publishes them), paired by stamp into a
:class:`~mbtrack_ros.core.detection.camera_stage.CameraFrame` and handed to the node's
frame-set synchroniser. Before each tracker step the frame set's masks go to the
detection's :class:`~mbtrack_ros.core.detection.camera_stage.ReceivedForeground` (in place
of the background models), and the bootstrap regions of the people cue, computed here from
every camera's frames on a thread of its own (1-3 s of CPU; the frame sets go on
meanwhile, the waiting cameras without foreground), go back to the cameras whose model
started (``<foreground_topic's namespace>/regions``, PNG bit planes). The filter, detection search,
existence and release run as in one process, except that each camera node scores the
frame set's particles in its camera (the camera's share of the HJS likelihood): the
filter's likelihood sends every camera its request
(``<foreground_topic's namespace>/score_request``) and waits up to ``score_timeout`` for
the answers (``.../scores``, :mod:`~mbtrack_ros.nodes.score_messages`); a camera that did
not answer in time is scored here, as in one process, and not waited for during a back-off,
and one whose node is not matched yet (not up, or not discovered) is scored here without
a wait (:class:`RemoteScorer`).
"""
from __future__ import annotations

import itertools
import threading
import time
from collections import OrderedDict

import cv2
import numpy as np
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import UInt8MultiArray

from mbtrack_ros.core.detection.camera_stage import (
    CameraFrame, ReceivedForeground, pack_regions, unpack_masks)
from mbtrack_ros.nodes.conversions import (
    ImageConversionError, compressed_to_rgb, image_to_mono, image_to_rgb, stamp_to_ns)
from mbtrack_ros.nodes.messages import make_header
from mbtrack_ros.nodes.score_messages import (
    ScoreMessageError, read_scores, request_message)

__all__ = ['FusionInput', 'RemoteScorer']

PAIRING = 30  # unpaired stamps kept per camera (2 s at 15 Hz)


def _masks(msg):
    """A ``working/foreground`` message -> (foreground, possible, presence) (H, W) bool,
    or while the camera's model bootstraps whether it started with this frame."""
    raw = isinstance(msg, Image)
    marker = msg.encoding if raw else msg.format
    if marker.startswith('bootstrap'):
        return marker == 'bootstrap started'
    return unpack_masks(image_to_mono(msg) if raw else compressed_to_rgb(msg))


def _none():
    return None


class RemoteScorer:
    """One camera node scoring the tracker's particles (a
    :data:`~mbtrack_ros.core.likelihood.Scorer` of :meth:`MeasurementModel.set_scorers`):
    called by the tracker's step with the camera's request, it publishes it and returns
    the wait for the answer, until ``timeout`` s (wall clock) after the request (the
    requests of a frame set go out together, so their waits end together). A camera that
    did not answer in time is not waited for (the tracker scores it; its requests still go
    out) for the next 1, 2, 4, ... up to ``MAX_BACKOFF`` requests, one answer in time
    resetting it: a dead or overloaded camera node costs the tracker at most one timeout
    per back-off, and one that comes back is asked again within it. ``stamp_ns``: the
    capture stamp of the camera's frame in the frame set being stepped
    (:meth:`FusionInput.prepare`). ``ready``: whether the camera node's request
    subscription and answer publisher are matched (discovered) now; while they are not,
    no request goes out and none is waited for (``unready`` counts them): a camera node
    that is not up yet, or whose end points DDS has not discovered yet, is scored here
    without costing a timeout or a back-off (default: always ready)."""

    MAX_BACKOFF = 64   # requests (about 4 s at 15 Hz)

    def __init__(self, camera: str, publish, timeout: float, warn, ready=None) -> None:
        self.camera, self.publish, self.timeout, self.warn = camera, publish, timeout, warn
        self.ready = ready
        self.unready = 0     # requests not sent: the camera node not matched
        self.stamp_ns = 0
        self.asked = 0       # requests sent
        self.answered = 0    # answers with scores taken
        self.missed = 0      # waits in vain
        self._backoff = 1
        self._skip_until = 0  # requests up to this one are not waited for
        self._seq = itertools.count(1)
        self._waiting = 0    # seq of the request being waited for
        self._shape = (0, 0)  # (particles, targets) its answer must have
        self.refused = 0     # answers of the wrong shape or with non-finite scores
        self._answer = None
        self._cond = threading.Condition()

    def __call__(self, request):
        if self.ready is not None and not self.ready():
            self.unready += 1
            return _none
        seq = next(self._seq)
        with self._cond:
            self._waiting, self._answer = seq, None
            self._shape = (len(request.states), len(request.n_views))
        end = time.monotonic() + self.timeout
        self.publish(request_message(seq, self.stamp_ns, request))
        self.asked += 1
        if self.asked <= self._skip_until:   # not waited for: taken if there already
            return self._ready
        return lambda: self._wait(end)

    def _ready(self):
        with self._cond:
            answer, self._answer, self._waiting = self._answer, None, 0
        scores = None if answer is None else answer[1]
        self.answered += scores is not None
        return scores

    def _wait(self, end: float):
        with self._cond:
            while self._answer is None and (left := end - time.monotonic()) > 0:
                self._cond.wait(left)
            answer, self._answer, self._waiting = self._answer, None, 0
        if answer is None:
            self.missed += 1
            self._skip_until = self.asked + self._backoff
            self._backoff = min(2 * self._backoff, self.MAX_BACKOFF)
            self.warn(f'{self.camera}:scores', f'{self.camera}: no scores from its camera '
                      f'node within {self.timeout} s: scored by the tracker meanwhile')
            return None
        self._backoff = 1
        scores = answer[1]
        self.answered += scores is not None
        return scores

    def on_answer(self, msg) -> None:
        """An answer message (the executor's thread); one to an earlier request is late
        and dropped. Scores of another shape than the request's particles and targets, or
        with a non-finite log-likelihood, visible or inside share, are refused (counted,
        warned): the answer then carries no scores, and the tracker scores the camera."""
        try:
            seq, _, scores = read_scores(msg)
        except ScoreMessageError as err:
            self.warn(f'{self.camera}:scores', f'{self.camera}: bad scores message: {err}')
            return
        with self._cond:
            if seq != self._waiting:
                return
            n, k = self._shape
            if scores is not None and not (
                    scores.loglik.shape == scores.inside.shape == scores.cover.shape == (n,)
                    and scores.visible.shape == (k,)
                    and all(np.isfinite(a).all() for a in (scores.loglik, scores.visible,
                                                            scores.inside))):
                self.refused += 1
                self.warn(f'{self.camera}:scores', f'{self.camera}: scores refused: not '
                          f'{n} particles and {k} targets of finite numbers')
                scores = None
            self._answer = (seq, scores)
            self._cond.notify_all()


class FusionInput:
    """Subscriptions and per-step work of a fusion tracker node (``node``: a
    :class:`~mbtrack_ros.nodes.tracker_node.TrackerNode` being built)."""

    def __init__(self, node) -> None:
        self.node = node
        p = node.params
        detection = getattr(node.tracker, 'detection', None)
        self.bank = None
        if detection is not None:
            # the bootstrap's people cue on its own thread: 1-3 s of CPU that would hold
            # up the frame sets behind it (the cameras send no foreground until it is done)
            self.bank = ReceivedForeground(detection.calibration,
                                           detection.config.background, background_cue=True)
            self.bank.prepare()
            detection.background = self.bank
        self.cameras = node.tracker.calibration.cameras  # the working size
        self._parts: dict[str, OrderedDict] = {c: OrderedDict() for c in p.camera_names}
        self._regions = {}
        self._started: dict[str, int] = {}  # camera -> stamp of its model's start
        qos = qos_profile_sensor_data if p.image_reliability == 'best_effort' else \
            QoSProfile(depth=p.qos_depth, reliability=ReliabilityPolicy.RELIABLE)
        reliable = QoSProfile(depth=p.qos_depth, reliability=ReliabilityPolicy.RELIABLE)
        self.topics = {}
        self.scorers: dict[str, RemoteScorer] = {}
        for cam in p.cameras:
            compressed = cam.transport == 'compressed'
            fg_topic = str(node.declare_parameter(
                f'camera.{cam.name}.foreground_topic',
                f'/{cam.name}/working/foreground' + ('/compressed' if compressed else '')
            ).value)
            kind = CompressedImage if compressed else Image
            node.create_subscription(kind, cam.image_topic,
                                     lambda m, c=cam.name: self._on_part(c, m, 0), qos)
            node.create_subscription(kind, fg_topic,
                                     lambda m, c=cam.name: self._on_part(c, m, 1), qos)
            base = fg_topic[:-len('/compressed')] if fg_topic.endswith('/compressed') \
                else fg_topic
            regions = base.rsplit('/', 1)[0] + '/regions'
            self._regions[cam.name] = node.create_publisher(CompressedImage, regions,
                                                            reliable)
            self.topics[cam.name] = (cam.image_topic, fg_topic, regions)
            measurement = node.tracker.measurement
            if p.score_timeout > 0 and hasattr(measurement, 'set_scorers'):
                working = base.rsplit('/', 1)[0]
                pub = node.create_publisher(UInt8MultiArray, working + '/score_request',
                                            reliable)
                sub = node.create_subscription(UInt8MultiArray, working + '/scores',
                                               lambda m, c=cam.name:
                                               self.scorers[c].on_answer(m), reliable)
                scorer = RemoteScorer(
                    cam.name, pub.publish, p.score_timeout, node.warn_once,
                    ready=lambda pub=pub, sub=sub: (pub.get_subscription_count() > 0
                                                    and sub.get_publisher_count() > 0))
                self.scorers[cam.name] = scorer
        if self.scorers:
            node.tracker.measurement.set_scorers(self.scorers)

    def _on_part(self, camera: str, msg, which: int) -> None:
        """An image (``which`` 0) or foreground message (1) of ``camera``: paired with the
        other half of its stamp, the pair goes to the synchroniser."""
        node = self.node
        stamp = stamp_to_ns(msg.header.stamp)
        try:
            if which == 0:
                part = compressed_to_rgb(msg) if isinstance(msg, CompressedImage) \
                    else image_to_rgb(msg)
                cam = self.cameras[camera]
                if part.shape[:2] != (cam.height, cam.width):
                    raise ImageConversionError(
                        f'working image is {part.shape[1]}x{part.shape[0]}, the tracker '
                        f'works at {cam.width}x{cam.height} (tracker.working_pixels)')
            else:
                part = _masks(msg)
        except ImageConversionError as err:
            node._count_drop()
            node.warn_once(f'{camera}:convert', f'{camera}: dropping bad input: {err}')
            return
        parts = self._parts[camera]
        pair = parts.setdefault(stamp, [None, None])
        pair[which] = part
        while len(parts) > PAIRING:
            parts.popitem(last=False)
        if pair[0] is None or pair[1] is None:
            return
        del parts[stamp]
        image, masks = pair
        if isinstance(masks, bool):
            frame = CameraFrame(image, started=masks)
        else:
            fg, possible, presence = masks
            if fg.shape != image.shape[:2]:
                node._count_drop()
                node.warn_once(f'{camera}:size', f'{camera}: mask and image sizes differ')
                return
            frame = CameraFrame(image, fg, possible, presence)
        with node._lock:
            node._rate_window[camera].append(stamp)
            node._queue(node.sync.add(camera, stamp, frame))

    def prepare(self, fs) -> None:
        """Before the tracker step of frame set ``fs`` (its images are
        :class:`CameraFrame` s): masks to the detection, regions back to the cameras that
        started their model; ``fs.images`` become the working images."""
        frames = fs.images
        for name, scorer in self.scorers.items():   # the frames the particles are scored on
            scorer.stamp_ns = int(fs.stamps.get(name, fs.stamp_ns))
        if self.bank is not None:
            for name, f in frames.items():
                if f.started:
                    self._started[name] = int(fs.stamps.get(name, fs.stamp_ns))
            for name, (region, body, core) in self.bank.receive(frames).items():
                ok, data = cv2.imencode('.png', pack_regions(region, body, core))
                msg = CompressedImage()
                # stamped with the frame that started the model (the stage takes regions
                # of its own start only, not of an earlier one after a restart)
                msg.header = make_header(self._started.get(name, fs.stamp_ns),
                                         self.cameras[name].frame_id)
                msg.format = 'mono8; png compressed mono8'
                msg.data = data.tobytes()
                self._regions[name].publish(msg)
        fs.images = {n: f.image for n, f in frames.items()}
