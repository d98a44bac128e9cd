"""``tracker_node``: multi-camera people tracking as a ROS 2 node.

Inputs (``qos_profile_sensor_data``): one image topic per camera (``sensor_msgs/Image`` or
``sensor_msgs/CompressedImage``), optional ``sensor_msgs/CameraInfo`` per camera.
Outputs (reliable, stamped with the frame set's time: the latest capture time of its images,
:mod:`mbtrack_ros.recording.sync`; frame ``output_frame_id``):
``~/people`` (PoseArray), ``~/tracks`` (PointCloud2), ``~/markers`` (MarkerArray),
``~/debug/<camera>/occlusion`` (Image, only computed when subscribed or enabled),
``/diagnostics`` (DiagnosticArray), and the standard people outputs of
:mod:`mbtrack_ros.nodes.people_outputs` (REP-155 ``/humans/persons/...``,
``~/detections``, ``/tf``). See :mod:`mbtrack_ros.nodes.params` for parameters and
:mod:`mbtrack_ros.nodes.messages` for the message layouts.

Bad input: an image is checked before it is decoded (frame id, a zero stamp, the size its
header declares against the calibration, :mod:`mbtrack_ros.recording.images`); a refused
image is counted in ``/diagnostics`` (``dropped images (bad)``) and logged once per cause
and camera every 10 s. A frame set whose stamp equals the last processed one is dropped and
counted (``dropped frame sets (repeated stamp)``). While no frame set forms, ``/diagnostics``
is still published every ``diagnostics_period`` seconds of wall-clock time, with the counts
and the reason.

Threading: image callbacks only convert the image and hand it to the
:class:`~mbtrack_ros.recording.sync.FrameSetSynchronizer`; complete (or timed-out) frame sets
are queued (at most ``max_pending_sets``) and the tracker step runs in its own plain thread,
woken by a condition variable, so it overlaps with message reception (the numba kernels and
OpenCV release the GIL). The callbacks are dispatched by rclpy's ``EventsExecutor`` (C++
event queue; ``executor`` parameter): the Python ``MultiThreadedExecutor`` rebuilt its wait
set for every message, which costs CPU and latency. Time is message time only.

Track start: with ``detection.enabled`` the tracker step detects, acquires and releases
people itself (``TrackerConfig.detection``); with ``init_ground_truth`` tracks are started and
ended from a ground-truth CSV (oracle initialisation, for experiments). Both may be combined;
:meth:`TrackerNode.start_track` is the hook for other sources.
"""
from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Sequence

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import (
    Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor)
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, PointCloud2
from visualization_msgs.msg import MarkerArray

from mbtrack_ros.core.appearance import AppearanceError, PersonModel, model_from_images
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.initiation import KeyView, body_height, initial_state, plan_key_views
from mbtrack_ros.core.state import FrameResult
from mbtrack_ros.core.tracker import Tracker, TrackerError
from mbtrack_ros.nodes import messages
from mbtrack_ros.nodes.conversions import (
    ImageConversionError, compressed_to_rgb, image_to_rgb, rgb_to_image, stamp_to_ns)
from mbtrack_ros.nodes.debug import occlusion_layers, shadow_layer
from mbtrack_ros.nodes.params import NodeParams, ParamsError, declare_and_read
from mbtrack_ros.nodes.people_outputs import PeopleFrameBuilder, PeopleOutputs
from mbtrack_ros.nodes.transport import use_large_shm_segment
from mbtrack_ros.recording.csvfiles import CsvFormatError, GroundTruthRow, read_ground_truth
from mbtrack_ros.recording.images import MAX_RESCALE
from mbtrack_ros.recording.sync import FrameSet, FrameSetSynchronizer

__all__ = ['GroundTruthInitializer', 'TrackerNode', 'main', 'make_executor', 'spin']

WARN_PERIOD_S = 10.0
RATE_WINDOW_NS = 1_000_000_000  # input rates in /diagnostics: the last second of stamps
RATE_WINDOW_MAX = 1024  # stamps kept per camera for the rate (bounded under any input)


class GroundTruthInitializer:
    """Starts and ends tracks from ground truth (oracle initialisation, 000 §VI "by hand").

    Key views are planned from the ground truth alone (:func:`plan_key_views`: unoccluded,
    large views among each person's first frames). While frame sets stream in, the images of
    planned views are turned into appearance models (:func:`model_from_images`); a person's
    track starts at the first frame set where its model has a key view, with the
    ground-truth state of that frame (:func:`initial_state`), and ends when the person
    leaves the ground truth. Later planned views are added to the model as they arrive.
    """

    def __init__(self, calibration: RoomCalibration, rows: Sequence[GroundTruthRow], *,
                 tolerance_ns: int = 20_000_000, width: float = 0.5) -> None:
        self.calibration = calibration
        self.tolerance_ns = int(tolerance_ns)
        self.width = float(width)
        rows = [r for r in rows]
        self._frames_by_stamp: dict[int, int] = {}
        for r in rows:
            self._frames_by_stamp.setdefault(int(r.stamp_ns), int(r.frame))
        self._stamps = np.array(sorted(self._frames_by_stamp), dtype=np.int64)
        self._person_rows: dict[int, list[GroundTruthRow]] = {}
        for r in sorted(rows, key=lambda r: r.stamp_ns):
            self._person_rows.setdefault(r.person_id, []).append(r)
        self._present: dict[int, set[int]] = {}
        for r in rows:
            self._present.setdefault(int(r.frame), set()).add(r.person_id)
        plan = plan_key_views(calibration, rows, width=self.width) if rows else {}
        self._views_at: dict[int, list[KeyView]] = {}
        for views in plan.values():
            for v in views:
                self._views_at.setdefault(int(v.frame), []).append(v)
        self._heights = {pid: body_height(rs) for pid, rs in self._person_rows.items()}
        self.unplanned = sorted(pid for pid in self._person_rows if not plan.get(pid))
        self._models: dict[int, PersonModel] = {}
        self._track_of: dict[int, int] = {}  # person id -> track id

    def reset(self) -> None:
        """Forget the started tracks and learnt models (the recording restarted)."""
        self._models.clear()
        self._track_of.clear()

    def frame_at(self, stamp_ns: int) -> int | None:
        """Ground-truth frame index nearest ``stamp_ns`` within the tolerance, else None."""
        if self._stamps.size == 0:
            return None
        i = int(np.searchsorted(self._stamps, stamp_ns))
        j = min((k for k in (i - 1, i) if 0 <= k < self._stamps.size),
                key=lambda k: abs(int(self._stamps[k]) - stamp_ns))
        if abs(int(self._stamps[j]) - stamp_ns) > self.tolerance_ns:
            return None
        return self._frames_by_stamp[int(self._stamps[j])]

    def update(self, node: TrackerNode, stamp_ns: int,
               images: dict[str, np.ndarray]) -> list[int]:
        """Start/end tracks on ``node`` for this frame set; returns the ended track ids."""
        frame = self.frame_at(stamp_ns)
        if frame is None:
            return []
        present = self._present.get(frame, set())
        ended = []
        for pid in [p for p in self._track_of if p not in present]:
            tid = self._track_of.pop(pid)
            node.end_track(tid)
            ended.append(tid)
        for v in self._views_at.get(frame, []):
            if v.camera not in images:
                continue
            height = self._heights[v.person_id]
            try:
                single = model_from_images({v.camera: images[v.camera]}, self.calibration,
                                           v.state, height, self.width)
            except AppearanceError as err:
                node.warn_once('gt-model', f'ground-truth key view unusable: {err}')
                continue
            model = self._models.setdefault(
                v.person_id, PersonModel(height=height, width=self.width))
            for angle, hists in zip(single.view_angles, single.histograms):
                model.add_view(float(angle), hists)  # 003 §4: views within 20 deg merge
        for pid in sorted(present):
            model = self._models.get(pid)
            if pid in self._track_of or model is None or model.view_angles.size == 0:
                continue
            rows = self._person_rows[pid]
            index = next(i for i, r in enumerate(rows) if r.frame == frame)
            tid = node.start_track(model, initial_state(rows, index), stamp_ns)
            if tid is not None:
                self._track_of[pid] = tid
        return ended


class TrackerNode(Node):
    """The tracker node (see the module docstring). Raises :class:`ParamsError` at start.

    ``step_thread=False`` starts no step thread: queued frame sets then wait until
    :meth:`process_pending` is called (tests drive the node by hand this way).
    """

    def __init__(self, *, cli_args: list[str] | None = None, context=None,
                 tracker: Tracker | None = None, step_thread: bool = True) -> None:
        super().__init__('tracker_node', cli_args=cli_args, context=context)
        self.params: NodeParams
        self.params, self.calibration = declare_and_read(self)
        p = self.params
        try:
            self.tracker = tracker or Tracker(self.calibration, p.tracker,
                                              rng=np.random.default_rng(p.tracker.seed))
        except TrackerError as err:
            raise ParamsError(str(err)) from err
        if getattr(self.tracker, 'detection', None) is not None:
            self.tracker.detection.prepare()  # one-off work now, not at the bootstrap frame
        if p.warm_up:  # before any subscription: a player waiting for us waits for this too
            self._warm_up()
        # frame sets by nearest capture time (half a frame period, or sync.tolerance)
        self.sync = FrameSetSynchronizer(p.camera_names, p.tolerance_ns, p.timeout_ns,
                                         frame_rate=p.frame_rate, time_offsets=p.time_offsets)
        self._lock = threading.Lock()  # synchroniser, frame-set queue and counters
        self._wake = threading.Condition(self._lock)  # a frame set was queued, or closing
        self._step_lock = threading.Lock()  # one tracker step at a time; held while closing
        self._closing = False
        self._shown: set[int] = set()  # track ids with markers on screen
        self._pending: deque[FrameSet] = deque()
        self._warned: dict[str, float] = {}
        self._dropped = 0  # images refused (bad encoding/size/frame id/stamp)
        self._received = 0  # images received
        self._last_bad: tuple[str, str] | None = None  # (camera, cause) of the last refusal
        self._repeated_sets = 0  # frame sets dropped: stamp equal to the last processed one
        self._newest_stamp = 0  # newest image stamp received (for idle /diagnostics)
        self._last_diag_wall = time.monotonic()  # wall time of the last /diagnostics
        self._at_last_diag = (0, 0, 0)  # received, refused, late at the last /diagnostics
        self._dropped_sets = 0  # frame sets lost: queue full (tracker behind) or step error
        self._dropped_full = 0  # of these, because the queue was full
        self._queue_peak = 0  # longest frame-set queue since the last /diagnostics
        self._resets = 0
        self._last_stamp: int | None = None
        self._last_diag: int | None = None
        self._step_times: list[float] = []
        self._rate_window: dict[str, deque[int]] = {
            c: deque(maxlen=RATE_WINDOW_MAX) for c in p.camera_names}
        self._last_missing: tuple[str, ...] = ()
        self._ground_truth: GroundTruthInitializer | None = None
        if p.init_ground_truth:
            try:
                rows = read_ground_truth(p.init_ground_truth)
            except CsvFormatError as err:
                raise ParamsError(f'init_ground_truth: {err}') from err
            self._ground_truth = GroundTruthInitializer(self.calibration, rows)
            if self._ground_truth.unplanned:
                self.get_logger().warning(
                    'no unoccluded key view in the ground truth for person(s) '
                    f'{self._ground_truth.unplanned}: they will not be tracked')
        people = PeopleFrameBuilder(p.output_frame_id, persons=p.outputs_persons,
                                    detections=p.outputs_detections, tf=p.outputs_tf)
        if people.missing:
            self.get_logger().warning(
                f'output(s) {", ".join(people.missing)} off: their message packages '
                '(hri_msgs, vision_msgs, tf2_msgs) are not installed (python3 -m '
                'mbtrack_ros.bootstrap builds them into its environment)')
        self._output_bag = None
        if p.output_bag:
            from mbtrack_ros.nodes.output_bag import OutputBagError, OutputBagWriter
            try:
                self._output_bag = OutputBagWriter(p.output_bag, self.calibration,
                                                   p.camera_names,
                                                   frame_id=p.output_frame_id,
                                                   people=any(people.enabled.values()))
            except OutputBagError as err:
                raise ParamsError(f'output_bag: {err}') from err

        # outputs: reliable, keep the last qos_depth messages for a subscriber that lags
        output_qos = QoSProfile(depth=p.qos_depth, reliability=ReliabilityPolicy.RELIABLE)
        self.pub_people = self.create_publisher(PoseArray, '~/people', output_qos)
        self.pub_tracks = self.create_publisher(PointCloud2, '~/tracks', output_qos)
        self.pub_markers = self.create_publisher(MarkerArray, '~/markers', output_qos)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics',
                                              output_qos)
        self.pub_debug = {c: self.create_publisher(Image, f'~/debug/{c}/occlusion', output_qos)
                          for c in p.camera_names}
        self.people_outputs = PeopleOutputs(self, people, output_qos)
        # inputs: cheap callbacks, one mutually exclusive group per camera (frames of one
        # camera stay in order under a multi-threaded executor)
        self._subs = []
        image_qos = qos_profile_sensor_data if p.image_reliability == 'best_effort' else \
            QoSProfile(depth=p.qos_depth, reliability=ReliabilityPolicy.RELIABLE)
        self._fusion = None
        if p.input_mode == 'foreground':  # the camera nodes' streams (nodes/fusion_input.py)
            from mbtrack_ros.nodes.fusion_input import FusionInput
            self._fusion = FusionInput(self)
        for cam in p.cameras if self._fusion is None else ():
            group = MutuallyExclusiveCallbackGroup()
            kind = CompressedImage if cam.transport == 'compressed' else Image
            self._subs.append(self.create_subscription(
                kind, cam.image_topic, lambda msg, c=cam.name: self._on_image(c, msg),
                image_qos, callback_group=group))
            if cam.camera_info_topic:
                self._subs.append(self.create_subscription(
                    CameraInfo, cam.camera_info_topic,
                    lambda msg, c=cam.name: self._on_camera_info(c, msg),
                    qos_profile_sensor_data, callback_group=group))
        # the tracker step: a plain thread woken by self._wake when a frame set is queued
        # (no executor involved, no polling; it runs while callbacks receive the next set)
        self._worker: threading.Thread | None = None
        if step_thread:
            self._worker = threading.Thread(target=self._step_loop, name='tracker_step',
                                            daemon=True)
            self._worker.start()
        self.get_logger().info(
            f'tracking with {p.tracker.algorithm} on {len(p.cameras)} camera(s): '
            + ', '.join(f'{c.name} <- {c.image_topic} ({c.transport})' for c in p.cameras))

    def _warm_up(self) -> None:
        """Load every compiled kernel of the step now (:func:`warm_up`, a throwaway
        tracker): without it the first frame sets with people queued up behind kernel
        loading."""
        from mbtrack_ros.core.detection.detector import is_ceiling
        from mbtrack_ros.nodes.warmup import warm_up

        ceiling = any(is_ceiling(c) for c in self.calibration.cameras.values())
        try:
            report = warm_up(self.params.tracker, ceiling=ceiling)
        except Exception as err:  # noqa: BLE001 - a failed warm-up only costs latency
            self.get_logger().warning(f'warm-up skipped: {type(err).__name__}: {err}')
            return
        self.get_logger().info(
            f'warm-up: {report.frames} synthetic frame sets, {report.births} track(s) '
            f'started, in {report.seconds:.1f} s')

    # -- hooks ----------------------------------------------------------------------------
    def start_track(self, model: PersonModel, state: np.ndarray, stamp_ns: int) -> int | None:
        """Start a track with appearance ``model`` at ``state`` (6,); None if refused.

        The hook for track sources outside :meth:`Tracker.step` (ground truth; automatic
        detection starts its tracks inside the step).
        """
        try:
            track_id = self.tracker.add_track(model, state, stamp_ns)
        except TrackerError as err:
            self.warn_once('add_track', f'cannot start a track: {err}')
            return None
        return track_id

    def end_track(self, track_id: int) -> None:
        """End a track started with :meth:`start_track`."""
        try:
            self.tracker.remove_track(track_id)
        except TrackerError as err:
            self.warn_once('remove_track', f'cannot end track {track_id}: {err}')

    # -- callbacks ------------------------------------------------------------------------
    def warn_once(self, cause: str, text: str) -> None:
        """Log once per cause every WARN_PERIOD_S seconds (throttled per cause)."""
        now = time.monotonic()
        if now - self._warned.get(cause, -1e9) >= WARN_PERIOD_S:
            self._warned[cause] = now
            self.get_logger().warning(text)

    def _refuse(self, camera: str, cause: str, text: str) -> None:
        """Drop an image: count it and log once per (camera, cause) every WARN_PERIOD_S."""
        with self._lock:
            self._dropped += 1
            self._last_bad = (camera, cause)
        self.warn_once(f'{camera}:{cause}', f'{camera}: dropping image ({cause}): {text}')

    def _on_camera_info(self, camera: str, msg: CameraInfo) -> None:
        cam = self.calibration.cameras[camera]
        if (msg.width, msg.height) != (cam.width, cam.height):
            self.warn_once(f'{camera}:info', f'{camera}: CameraInfo says '
                           f'{msg.width}x{msg.height}, the calibration {cam.width}x{cam.height}')

    def _on_image(self, camera: str, msg: Image | CompressedImage) -> None:
        """Check (before decoding: frame id, stamp, declared size), convert, synchronise."""
        stamp = stamp_to_ns(msg.header.stamp)
        cam = self.calibration.cameras[camera]
        with self._lock:
            self._received += 1
            self._newest_stamp = max(self._newest_stamp, stamp)
        if msg.header.frame_id and msg.header.frame_id != cam.frame_id:
            self._refuse(camera, 'frame-id', f'unexpected frame id '
                         f'{msg.header.frame_id[:60]!r} (calibration: {cam.frame_id!r}; '
                         'set frame_id of this camera in the calibration file)')
            return
        if stamp <= 0:
            self._refuse(camera, 'stamp', 'the header stamp is zero (not set by the driver)')
            return
        # rescale_images: at most MAX_RESCALE times the calibrated size on a side. Decoded
        # at the tracker's working size (tracker.working_pixels), resized once from the
        # message's pixels: the decoder and resize of mbtrack replay's reader
        scale = MAX_RESCALE if self.params.rescale_images else 1.0
        limits = dict(expected=(cam.width, cam.height), max_scale=scale,
                      to=self.tracker.calibration.cameras[camera])
        try:
            rgb = (compressed_to_rgb(msg, **limits) if isinstance(msg, CompressedImage)
                   else image_to_rgb(msg, **limits))
        except ImageConversionError as err:
            hint = (' (set rescale_images to resize)' if err.cause == 'size-mismatch'
                    else '')
            self._refuse(camera, err.cause, f'{err}{hint}')
            return
        with self._lock:
            window = self._rate_window[camera]
            window.append(stamp)
            while window and window[0] < stamp - RATE_WINDOW_NS:
                window.popleft()
            ready = self.sync.add(camera, stamp, rgb)
            self._queue(ready)
            warnings, self.sync.warnings = self.sync.warnings, []
        for text in warnings:
            self.warn_once('sync:rate', text)

    def _queue(self, ready: list[FrameSet]) -> None:
        """Queue frame sets for the step (caller holds the lock); drop the oldest when full.

        A tracker must see every set under normal load, so the queue absorbs a step that is
        momentarily slower than the frame rate; only a tracker that stays behind for
        ``max_pending_sets`` frames loses sets (oldest first, counted in /diagnostics as
        ``dropped frame sets (queue full)``; the next step predicts over the longer gap).
        """
        if not ready:
            return
        self._pending.extend(ready)
        while len(self._pending) > self.params.max_pending_sets:
            old = self._pending.popleft()
            if old.after_reset and self._pending:
                self._pending[0].after_reset = True  # keep the reset request
            self._dropped_sets += 1
            self._dropped_full += 1
        self._queue_peak = max(self._queue_peak, len(self._pending))
        self._wake.notify()

    def _step_loop(self) -> None:
        """The step thread: wait for queued frame sets, process them, until closing; while
        none comes, publish /diagnostics every diagnostics_period of wall-clock time."""
        period = self.params.diagnostics_period_ns / 1e9
        while True:
            with self._wake:
                if not self._pending and not self._closing:
                    self._wake.wait(timeout=period)
                if self._closing:
                    return
                idle = not self._pending
            if idle:
                self.idle_diagnostics()
            else:
                self.process_pending()

    def idle_diagnostics(self) -> DiagnosticArray | None:
        """Publish /diagnostics when none went out for ``diagnostics_period`` of wall-clock
        time (no frame set formed): the counts and why no set formed. Stamped with the
        newest image stamp received (message time), else the node's clock."""
        period = self.params.diagnostics_period_ns / 1e9
        if time.monotonic() - self._last_diag_wall < period:
            return None
        stamp = self._newest_stamp or self.get_clock().now().nanoseconds
        snap = self.snapshot(FrameResult(stamp_ns=stamp), reason=self._idle_reason(period))
        diag = messages.diagnostics_message(stamp, snap)
        self.pub_diag.publish(diag)
        return diag

    def _idle_reason(self, period: float) -> str:
        with self._lock:
            received, refused, late = self._at_last_diag
            received = self._received - received
            refused = self._dropped - refused
            late = self.sync.counters.dropped_frames - late
            last_bad = self._last_bad
            waiting = [c for c, n in self.sync.pending.items() if n == 0]
        head = f'no frame set in the last {period:g} s: '
        if received == 0:
            return head + 'no images received'
        if refused >= received:
            return head + (f'all {received} images refused as bad (last: {last_bad[0]}, '
                           f'{last_bad[1]})' if last_bad else f'all {received} images refused')
        if late:
            return head + f'{late} frames dropped by the synchroniser (late or repeated stamps)'
        return head + 'waiting for camera(s) ' + (', '.join(waiting) or '?')

    def _on_frame_sets(self) -> None:
        """Alias of :meth:`process_pending` (older tests and tools call this name)."""
        self.process_pending()

    def process_pending(self) -> None:
        """Process every queued frame set, oldest first, in the calling thread.

        A set is taken from the queue under the step lock, so two callers (the step thread
        and :meth:`flush`) never process sets out of order.
        """
        while not self._closing:
            with self._step_lock:
                with self._lock:
                    if not self._pending or self._closing:
                        return
                    fs = self._pending.popleft()
                    repeated = (not fs.after_reset and self._last_stamp is not None
                                and fs.stamp_ns == self._last_stamp)
                    if repeated:  # never process an instant twice
                        self._repeated_sets += 1
                if repeated:
                    self.warn_once('repeated', f'frame set at {fs.stamp_ns} ns dropped: its '
                                   'stamp equals the last processed one')
                    continue
                try:
                    self.process(fs)
                except Exception as err:  # noqa: BLE001 - a bad frame must not kill the node
                    with self._lock:
                        self._dropped_sets += 1
                    self.warn_once(f'step:{type(err).__name__}',
                                   f'frame set at {fs.stamp_ns} ns dropped: '
                                   f'{type(err).__name__}: {err}')

    # -- processing -----------------------------------------------------------------------
    def reset(self, stamp_ns: int, reason: str) -> None:
        """Reset the tracker (and ground-truth bookkeeping), clear the markers."""
        self._resets += 1
        self.get_logger().warning(f'resetting the tracker: {reason}')
        self.tracker.reset()
        if self._ground_truth is not None:
            self._ground_truth.reset()
        self._shown = set()
        clear = messages.delete_all_markers(stamp_ns, self.params.output_frame_id)
        self.pub_markers.publish(clear)
        if self._output_bag is not None:
            self._output_bag.write_markers(stamp_ns, clear)

    def process(self, fs: FrameSet) -> FrameResult:
        """Run one tracker step on a frame set and publish everything."""
        if self._fusion is not None:  # camera nodes' frames: masks in, working images out
            self._fusion.prepare(fs)
        if fs.after_reset or (self._last_stamp is not None and fs.stamp_ns < self._last_stamp):
            self.reset(fs.stamp_ns, 'image stamps jumped or went backwards '
                       f'(now {fs.stamp_ns} ns, before {self._last_stamp} ns)')
        if fs.missing:
            self.warn_once('missing', f'frame set without camera(s) {", ".join(fs.missing)}')
        ended = []
        if self._ground_truth is not None:
            ended = self._ground_truth.update(self, fs.stamp_ns, fs.images)
        # with detection enabled, Tracker.step also releases tracks (003 §4.3) and updates
        # existence and visibility (001); its search for new people (003 §4.1) only adds
        # tracks for the next frame, so it runs after publishing (same outputs, the
        # latency of the frame set does not include it); with tracker.pipeline_search
        # search() adds the people of the previous frame's search, which ran on the
        # detection's worker, and starts this frame's there
        t0 = time.perf_counter()
        try:
            result = self.tracker.step(fs.stamp_ns, fs.images, search=False, stamps=fs.stamps)
        except TrackerError as err:
            self.reset(fs.stamp_ns, str(err))
            result = self.tracker.step(fs.stamp_ns, fs.images, search=False, stamps=fs.stamps)
        spent = time.perf_counter() - t0
        result.ended = list(result.ended) + [t for t in ended if t not in result.ended]
        self._last_stamp = fs.stamp_ns
        self._last_missing = fs.missing
        self.publish(result, fs)
        t1 = time.perf_counter()
        self.tracker.search()
        self._step_times.append(spent + time.perf_counter() - t1)
        return result

    def publish(self, result: FrameResult, fs: FrameSet) -> None:
        frame = self.params.output_frame_id
        cams = self.params.camera_names
        people = messages.people_message(result, frame)
        cloud = messages.tracks_cloud(result, cams, frame)
        current = {t.track_id for t in result.tracks}
        markers = messages.markers_message(result, frame,
                                           also_delete=sorted(self._shown - current))
        self._shown = current
        self.pub_people.publish(people)
        self.pub_tracks.publish(cloud)
        self.pub_markers.publish(markers)
        standard = self.people_outputs.publish(result)
        debug = {}
        for cam, pub in self.pub_debug.items():
            if cam in fs.images and (self.params.debug_images
                                     or pub.get_subscription_count() > 0):
                debug[cam] = self.debug_image(cam, fs.images[cam], result)
                pub.publish(debug[cam])
        diag = None
        if self._last_diag is None or (
                result.stamp_ns - self._last_diag >= self.params.diagnostics_period_ns):
            diag = messages.diagnostics_message(result.stamp_ns, self.snapshot(result))
            self.pub_diag.publish(diag)
            self._last_diag = result.stamp_ns
        if self._output_bag is not None:
            self._output_bag.write(result, people=people, cloud=cloud, markers=markers,
                                   diagnostics=diag, debug=debug, standard=standard)

    def debug_image(self, camera: str, rgb: np.ndarray, result: FrameResult) -> Image:
        """``~/debug/<camera>/occlusion``: occlusion maps and silhouettes (000 Fig. 4)."""
        # the layers at the working size (tracker.working_pixels), drawn on the image as the
        # tracker received it (at the working size too)
        occ, sil = occlusion_layers(self.tracker.measurement,
                                    self.tracker.calibration.cameras[camera],
                                    result, self.tracker.models)
        out = messages.debug_overlay(rgb, occlusion=occ, silhouettes=sil,
                                     shadows=shadow_layer(self.tracker, camera, rgb))
        return rgb_to_image(out, messages.make_header(
            result.stamp_ns, self.calibration.cameras[camera].frame_id))

    def snapshot(self, result: FrameResult, reason: str = '') -> messages.DiagnosticsSnapshot:
        """The counts of /diagnostics (and the rates of the last second of message time);
        ``reason``: why no frame set formed (idle /diagnostics)."""
        with self._lock:
            rates = {}
            for cam, stamps in self._rate_window.items():
                # frames of the last second of message time before this camera's newest
                # frame: a sliding window, so the rate does not depend on when the (slower)
                # tracker step takes this snapshot
                newest = max(stamps) if stamps else 0
                recent = sorted({t for t in stamps if t >= newest - RATE_WINDOW_NS})
                span = (recent[-1] - recent[0]) / 1e9 if len(recent) > 1 else 0.0
                rates[cam] = (len(recent) - 1) / span if span > 0 else 0.0
                self._rate_window[cam] = deque(recent, maxlen=RATE_WINDOW_MAX)
            counters = self.sync.counters
            snap = messages.DiagnosticsSnapshot(
                input_rate_hz=rates,
                step_seconds=float(np.mean(self._step_times)) if self._step_times else 0.0,
                frame_sets=counters.complete, incomplete_sets=counters.incomplete,
                dropped_frames=(self._dropped + counters.dropped_frames + self._dropped_sets
                                + self._repeated_sets),
                tracks=len(result.tracks), missing_cameras=tuple(self._last_missing),
                resets=self._resets, bad_images=self._dropped,
                late_frames=counters.dropped_frames, dropped_sets_full=self._dropped_full,
                dropped_sets_error=self._dropped_sets - self._dropped_full,
                queued_sets=len(self._pending), queue_peak=self._queue_peak,
                dropped_sets_repeated=self._repeated_sets, reason=reason)
            self._queue_peak = len(self._pending)
            self._last_diag_wall = time.monotonic()
            self._at_last_diag = (self._received, self._dropped, counters.dropped_frames)
            self._step_times.clear()
        return snap

    def flush(self) -> None:
        """Process every frame set still buffered (end of a replay)."""
        with self._lock:
            self._pending.extend(self.sync.flush())
        self.process_pending()

    def destroy_node(self) -> None:
        for name, scorer in (self._fusion.scorers if self._fusion is not None else {}).items():
            self.get_logger().info(
                f'{name}: {scorer.asked} score requests, {scorer.answered} answered with '
                f'scores, {scorer.missed} not in time, {scorer.refused} refused, '
                f'{scorer.unready} not sent (camera node not matched yet)')
        with self._wake:
            self._closing = True
            self._wake.notify_all()
        if self._worker is not None and self._worker is not threading.current_thread():
            self._worker.join(timeout=30.0)  # a running step finishes first
        with self._step_lock:  # let a running step finish its output-bag write
            if self._output_bag is not None:
                self._output_bag.close()
                self._output_bag = None
        super().destroy_node()


def make_executor(kind: str, context=None) -> Executor:
    """The executor named by the ``executor`` parameter (``events``, ``single``, ``multi``).

    ``events`` (default) is rclpy's C++ ``EventsExecutor``: per message it only calls the
    Python callback, where the Python executors rebuild a wait set (``multi`` also hands
    every callback to a thread pool). Falls back to ``single`` if this rclpy has none.
    Spin it with :func:`spin`.
    """
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:
            kind = 'single'
        else:
            return EventsExecutor(context=context)
    if kind == 'multi':
        return MultiThreadedExecutor(num_threads=3, context=context)
    return SingleThreadedExecutor(context=context)


def spin(executor: Executor, context=None) -> None:
    """Dispatch callbacks until the context shuts down (SIGINT/SIGTERM).

    ``spin_once`` in a loop rather than ``spin()``: the ``EventsExecutor`` of rclpy 7.1.5
    (Jazzy) dispatches nothing from ``spin()`` (not even a timer; it busy-waits and ignores
    SIGTERM), while ``spin_once`` works.
    """
    while rclpy.ok(context=context):
        executor.spin_once(timeout_sec=0.1)


def main(args: list[str] | None = None) -> int:
    """Entry point ``tracker_node``; exits non-zero on bad parameters."""
    use_large_shm_segment()  # before rclpy.init (debug images are large too)
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = TrackerNode()
        # callbacks in the executor, the tracker step in the node's own thread
        executor = make_executor(node.params.executor)
        executor.add_node(node)
        spin(executor)
    except ParamsError as err:
        print(f'tracker_node: error: {err}', file=sys.stderr)
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
