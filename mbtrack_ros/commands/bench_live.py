"""``mbtrack bench --live``: the tracker as it runs live, over DDS, and offline replay speed.

A ``clear-room`` recording (four corner cameras, no ceiling camera, 320x240, 15 Hz) is played
in real time by ``bag_player`` (own process, with ``/clock``) to ``tracker_node`` (own
process, automatic detection, ``use_sim_time``). A listener in this process records, with its
DDS time stamps (system clock, one machine) the moment the player published the first
``/clock`` message carrying a frame's stamp (the player publishes one ``/clock`` = the stamp
just before the first message of the frame set, so this is when the frame set starts to go
out; cheaper to receive than an image: its ``source_timestamp``) and the moment the
``/tracker_node/people`` message with that stamp reached the listener (its
``received_timestamp``); the difference is the end-to-end latency. Taking both times from the
middleware, not from the Python callbacks, keeps a busy listener out of the measurement; the
latency to the people message's ``source_timestamp`` (taken in the tracker as it sends it)
also keeps out the listener's reception, which a loaded machine delays. It also
reads the node's counters from ``/diagnostics`` and the CPU time of the tracker process from
``/proc/<pid>/stat``. Then ``mbtrack replay`` runs over the same recording, timed, for the
offline speed: with the default parameters and, in a source checkout, with the fast and the
offline profiles (``config/clear_room_fast.yaml``, ``config/clear_room_offline.yaml``).

**Soak** (``--live-bad-rate P``, with a long ``--live-frames``, ``--live-compressed`` to
keep its recording small, and ``--live-no-offline``): the listener also publishes a bad
image on one camera's topic (``--live-bad-camera``, reliable) for a share ``P`` of the frame
sets, right after the ``/clock`` tick of that stamp, cycling through kinds the node must
refuse (unknown encoding,
unexpected frame id, a declared 8192x8192 image, a data length that does not match, a zero
stamp). The resident memory of the tracker process is sampled every second; the summary gives
its growth (median of the last tenth of the run against the median of the second tenth, after
start-up), the frame sets processed against the frames played, and the node's final
``/diagnostics`` count of bad images against the number injected (the node publishes its
counts on a wall-clock period once no frame set forms, so the last message has them all).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

__all__ = ['BAD_KINDS', 'LatencyError', 'LatencyStats', 'LiveResult', 'add_arguments',
           'bad_image', 'cpu_seconds', 'latency_stats', 'make_recording', 'match_latencies',
           'memory_growth', 'nearest_rank', 'rss_megabytes', 'run_live', 'run_offline',
           'main_live', 'soak_summary']

_PROG = 'mbtrack bench'
FPS = 15.0
# the player's last log line: how long publishing one stamp's messages took
_BURST = re.compile(r"one stamp's messages took p50 (?P<p50>[\d.]+) ms, p95 (?P<p95>[\d.]+) ms")
REPO = Path(__file__).resolve().parents[2]
FAST_PROFILE = REPO / 'config' / 'clear_room_fast.yaml'  # tracker_node parameters
# the offline speed profile: fewer particles, detection on every
# 3rd frame set, images processed at half size
OFFLINE_PROFILE = REPO / 'config' / 'clear_room_offline.yaml'


class LatencyError(ValueError):
    """Arrival times that cannot give a latency (no common frame, answer before image)."""


@dataclass
class LatencyStats:
    """End-to-end latencies, seconds; ``matched`` frames answered, ``missing`` not."""

    matched: int
    missing: int
    p50: float
    p95: float
    max: float
    mean: float


def match_latencies(image_arrival: Mapping[int, float], people_arrival: Mapping[int, float]
                    ) -> tuple[np.ndarray, np.ndarray, int]:
    """Pair arrivals by frame stamp.

    Args:
        image_arrival: stamp (ns) -> arrival time of the image, seconds (one clock).
        people_arrival: stamp (ns) -> arrival time of the output with that stamp, seconds.

    Returns:
        ``(stamps (M,) int64 sorted, latency (M,) float64 s, missing)``, where ``missing``
        counts images without an output (outputs without an image are ignored).
    """
    stamps = np.array(sorted(set(image_arrival) & set(people_arrival)), dtype=np.int64)
    lat = np.array([people_arrival[int(s)] - image_arrival[int(s)] for s in stamps],
                   dtype=np.float64)
    return stamps, lat, len(image_arrival) - stamps.size


def nearest_rank(values: np.ndarray, q: float) -> float:
    """Nearest-rank percentile ``q`` in (0, 1] of a non-empty (M,) array."""
    v = np.sort(np.asarray(values, np.float64))
    return float(v[max(int(np.ceil(q * v.size)) - 1, 0)])


def latency_stats(image_arrival: Mapping[int, float],
                  people_arrival: Mapping[int, float]) -> LatencyStats:
    """p50 / p95 / max / mean latency (s) of the frames with both arrivals.

    Raises :class:`LatencyError` when no frame has both, or an output arrived before its
    image (the two times were not taken on one clock).
    """
    _, lat, missing = match_latencies(image_arrival, people_arrival)
    if lat.size == 0:
        raise LatencyError('no frame has both an image and an output arrival')
    if np.any(lat < 0):
        raise LatencyError(f'{int(np.sum(lat < 0))} output(s) arrived before their image')
    return LatencyStats(int(lat.size), int(missing), nearest_rank(lat, 0.5),
                        nearest_rank(lat, 0.95), float(lat.max()), float(lat.mean()))


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far, seconds (``/proc/<pid>/stat``)."""
    text = Path(f'/proc/{pid}/stat').read_text()
    fields = text[text.rindex(')') + 2:].split()  # after "pid (comm) "
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def make_recording(path: Path, *, frames: int, seed: int = 0,
                   compressed: bool = False, size: tuple[int, int] | None = None,
                   preset: str = 'clear-room') -> Path:
    """The benchmark recording: ``preset`` (clear-room: 4 corner cameras) without a ceiling
    camera, ``size`` (default: the preset's, 320x240 for clear-room), 15 Hz
    (``compressed``: JPEG images, ~15 kB instead of 230 kB each at 320x240, for long
    soaks). Raises :class:`~mbtrack_ros.synth.errors.SynthError` on an unknown preset."""
    from mbtrack_ros.synth.generator import generate
    from mbtrack_ros.synth.presets import get_preset
    size = size or get_preset(preset).size
    return generate(preset, path, seed=seed, frames=frames, width=size[0],
                    height=size[1], fps=FPS, ceiling=False, compressed=compressed)


@dataclass
class LiveResult:
    """What one live run measured."""

    frames: int
    people_messages: int
    latency_all: LatencyStats
    latency_after_1s: LatencyStats
    latency_after_5s: LatencyStats  # without the start-up backlog
    diagnostics: dict
    cpu_seconds: float
    wall_seconds: float
    cpu_percent: float
    mean_people_truth: float
    mean_tracks: float
    publish_spread_p50: float = float('nan')
    publish_spread_p95: float = float('nan')
    latency_series: tuple[tuple[float, float], ...] = ()  # (s since first frame, latency s)
    injected_bad: int = 0  # bad images published on the soak camera
    rss_mb: tuple[tuple[float, float], ...] = ()  # (s since the player started, RSS MB)
    camera_node_cpu_seconds: tuple[float, ...] = ()  # per camera node (--live-camera-nodes)
    camera_node_logs: tuple[str, ...] = ()           # their counters at the end
    tracker_score_logs: tuple[str, ...] = ()  # the tracker's warnings, its score requests
    mask_bytes_per_frame: float = float('nan')       # mean mask message data, bytes
    image_bytes_per_frame: float = float('nan')      # mean working image data, bytes
    image_format: str = 'raw'                        # of the working images: raw | jpeg
    cameras: int = 4
    tracker_threads: tuple[tuple[str, float], ...] = ()  # (thread, CPU s) of the tracker
    unanswered: tuple[int, ...] = ()  # frame indices seen on /clock without an output
    # to the people message's sending (its DDS source_timestamp, taken in the tracker):
    # without this listener's own reception, which a loaded machine can delay
    sent_all: LatencyStats | None = None
    sent_after_1s: LatencyStats | None = None
    sent_series: tuple[tuple[float, float], ...] = ()  # (s since first frame, latency s)


#: kinds of bad images the soak injects, in turn
BAD_KINDS = ('encoding', 'frame-id', 'too-large', 'data-length', 'stamp')


def bad_image(kind: str, stamp_ns: int, camera: str, width: int, height: int, *,
              compressed: bool = False):
    """A ``sensor_msgs/Image`` (``compressed``: ``CompressedImage``) of camera ``camera``
    (``width`` x ``height`` rgb8) made bad in the way ``kind`` (one of :data:`BAD_KINDS`)
    names; small (at most one row of data, or a PNG header)."""
    from sensor_msgs.msg import CompressedImage, Image

    from mbtrack_ros.nodes.messages import make_header
    header = make_header(0 if kind == 'stamp' else stamp_ns,
                         'elsewhere' if kind == 'frame-id' else f'{camera}_optical_frame')
    if compressed:
        msg = CompressedImage(header=header, format='tiff' if kind == 'encoding' else 'png')
        side = 8192 if kind == 'too-large' else None
        # a PNG signature and header (declaring 8192x8192 for too-large), then junk; the
        # data-length kind has no header at all
        ihdr = (b'\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR'
                + (side or width).to_bytes(4, 'big') + (side or height).to_bytes(4, 'big'))
        msg.data = (b'' if kind == 'data-length' else ihdr) + bytes(64)
        return msg
    msg = Image(height=height, width=width, encoding='rgb8', step=width * 3)
    msg.header = header
    if kind == 'encoding':
        msg.encoding = 'yuv422'
    elif kind == 'too-large':
        msg.width = msg.height = 8192
        msg.step = 8192 * 3
    msg.data = bytes(width * 3)  # one row: the length never matches
    return msg


def thread_cpu_seconds(pid: int) -> dict[tuple[int, str], float]:
    """User + system CPU time, seconds, of each thread ``(tid, name)`` of process ``pid``
    (``/proc/<pid>/task/<tid>/stat``); threads that ended meanwhile are left out."""
    out = {}
    for task in Path(f'/proc/{pid}/task').iterdir():
        try:
            text = (task / 'stat').read_text()
        except OSError:
            continue
        name = text[text.index('(') + 1:text.rindex(')')]
        fields = text[text.rindex(')') + 2:].split()
        out[(int(task.name), name)] = (int(fields[11]) + int(fields[12])) \
            / os.sysconf('SC_CLK_TCK')
    return out


def thread_split(before: dict, after: dict, pid: int) -> tuple[tuple[str, float], ...]:
    """CPU seconds spent between two :func:`thread_cpu_seconds` readings, grouped: the main
    thread (``main``: the executor's callbacks, message conversion), the other Python
    threads (``python threads``: the tracker step and its workers), and the middleware's
    threads by name (digits dropped, e.g. ``dds.shm.``), largest first."""
    groups: dict[str, float] = {}
    for (tid, name), cpu in after.items():
        used = cpu - before.get((tid, name), 0.0)
        if tid == pid:
            key = 'main'
        elif name.startswith('python'):
            key = 'python threads'
        else:
            key = re.sub(r'\d+', '', name)
        groups[key] = groups.get(key, 0.0) + used
    return tuple(sorted(groups.items(), key=lambda kv: -kv[1]))


def rss_megabytes(pid: int) -> float:
    """Resident set size of process ``pid``, MB (``/proc/<pid>/status`` VmRSS)."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return float('nan')


def memory_growth(series) -> float:
    """Relative RSS growth of a ``(t, MB)`` series: the median of its last tenth over the
    median of its second tenth (after start-up), minus 1; NaN for fewer than 20 samples."""
    values = np.array([mb for _, mb in series], dtype=np.float64)
    if values.size < 20:
        return float('nan')
    tenth = values.size // 10
    return float(np.median(values[-tenth:]) / np.median(values[tenth:2 * tenth]) - 1.0)


def _diag_values(msg) -> dict:
    main = next(s for s in msg.status if s.name == 'mbtrack_ros: tracker')
    return {kv.key: kv.value for kv in main.values}


def run_live(recording: Path, *, seed: int = 0, rate: float = 1.0,
             max_pending_sets: int = 15, timeout: float = 600.0, use_sim_time: bool = True,
             ground_truth: bool = False, node_args: tuple[str, ...] = (),
             bad_rate: float = 0.0, bad_camera: str = 'cam0',
             camera_nodes: bool = False, image_format: str = 'raw',
             cameras: int | None = None) -> LiveResult:
    """Play ``recording`` to a tracker_node process and measure (see the module docstring).

    ``camera_nodes``: one ``camera_node`` process per camera and the tracker in fusion mode
    (``input_mode: foreground``), the player started once each camera node is up and
    discovered by the tracker; their CPU and the masks' and working images' bytes are
    measured too. ``image_format``: the camera nodes' working images, ``raw``
    (``sensor_msgs/Image``) or ``jpeg`` (``CompressedImage``, decoded in the tracker).
    ``cameras``: track with the first ``cameras`` cameras of the calibration only (the
    player plays only theirs; default all).

    ``ground_truth``: start tracks from the recording's ground truth (``init_ground_truth``)
    instead of the automatic detection. ``bad_rate``: share of the frame sets after whose
    ``/clock`` tick a bad image (:func:`bad_image`) is published on ``bad_camera`` (soak).
    """
    if ground_truth:
        node_args = ('-p', 'detection.enabled:=false',
                     '-p', f'init_ground_truth:={recording / "ground_truth.csv"}', *node_args)
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseArray
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.context import Context
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CompressedImage

    from sensor_msgs.msg import CompressedImage, Image

    from mbtrack_ros.nodes.conversions import stamp_to_ns
    from mbtrack_ros.recording.bag import COMPRESSED, RecordingReader, image_topic
    from mbtrack_ros.recording.csvfiles import read_ground_truth

    from mbtrack_ros.core.camera import RoomCalibration

    with RecordingReader(recording / 'bag') as reader:
        frames = reader.frame_count
        # a recording of JPEG images: the node subscribes to the compressed topics
        compressed = reader.topics.get(image_topic('cam0', True)) == COMPRESSED \
            and image_topic('cam0') not in reader.topics
    if compressed and not camera_nodes:
        node_args = ('-p', 'image_transport:=compressed', *node_args)
    if camera_nodes and image_format == 'jpeg':  # the working images the tracker takes
        node_args = ('-p', 'image_transport:=compressed', *node_args)
    soak_cam = RoomCalibration.load(recording / 'calibration.yaml').cameras[bad_camera] \
        if bad_rate > 0 else None
    truth_count: dict[int, int] = {}
    for r in read_ground_truth(recording / 'ground_truth.csv'):
        truth_count[r.stamp_ns] = truth_count.get(r.stamp_ns, 0) + 1
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get('PYTHONPATH', ''),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    env.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    os.environ['ROS_DOMAIN_ID'] = env['ROS_DOMAIN_ID']
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    images: dict[int, float] = {}
    people: dict[int, float] = {}
    sent: dict[int, float] = {}
    tracks: dict[int, int] = {}
    diags: list[dict] = []
    lock = threading.Lock()
    context = Context()
    rclpy.init(context=context)
    listener = rclpy.create_node('bench_live_listener', context=context)
    group = ReentrantCallbackGroup()  # a /clock callback never waits for a people callback
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)

    injected = [0]
    bad_pub = None
    if soak_cam is not None:
        bad_pub = listener.create_publisher(
            CompressedImage if compressed else Image, image_topic(bad_camera, compressed),
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))

    def on_clock(msg, info) -> None:  # info: rmw message info, system clock ns
        t = info['source_timestamp'] / 1e9
        s = stamp_to_ns(msg.clock)
        with lock:
            new = s not in images
            images.setdefault(s, t)
            k = len(images) - 1
            inject = (bad_pub is not None and new
                      and int((k + 1) * bad_rate) > int(k * bad_rate))
            if inject:
                kind = BAD_KINDS[injected[0] % len(BAD_KINDS)]
                injected[0] += 1
        if inject:
            bad_pub.publish(bad_image(kind, s, bad_camera, soak_cam.width, soak_cam.height,
                                      compressed=compressed))

    def on_people(msg, info) -> None:
        t = info['received_timestamp'] / 1e9
        s = stamp_to_ns(msg.header.stamp)
        with lock:
            people.setdefault(s, t)
            sent.setdefault(s, info['source_timestamp'] / 1e9)
            tracks[s] = len(msg.poses)

    def on_diag(msg) -> None:
        main = next(s for s in msg.status if s.name == 'mbtrack_ros: tracker')
        values = _diag_values(msg)
        if main.message.startswith('no frame set'):
            values['_reason'] = main.message
        with lock:
            diags.append(values)

    listener.create_subscription(Clock, '/clock', on_clock,
                                 QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE),
                                 callback_group=group)
    listener.create_subscription(PoseArray, '/tracker_node/people', on_people, qos,
                                 callback_group=group)
    listener.create_subscription(DiagnosticArray, '/diagnostics', on_diag, qos,
                                 callback_group=group)
    cams = RoomCalibration.load(recording / 'calibration.yaml').names[:cameras]
    masks: list[int] = []
    jpegs: list[int] = []

    def on_mask(msg) -> None:
        if msg.data:
            with lock:
                masks.append(len(msg.data))

    def on_jpeg(msg) -> None:
        with lock:
            jpegs.append(len(msg.data))

    if camera_nodes:
        for cam in cams:
            if image_format == 'jpeg':   # PNG masks next to JPEG images, else raw mono8
                listener.create_subscription(CompressedImage,
                                             f'/{cam}/working/foreground/compressed',
                                             on_mask, qos, callback_group=group)
            else:
                listener.create_subscription(Image, f'/{cam}/working/foreground', on_mask,
                                             qos, callback_group=group)
            if image_format == 'jpeg':
                listener.create_subscription(CompressedImage,
                                             f'/{cam}/working/image/compressed', on_jpeg,
                                             qos, callback_group=group)
        node_args = ('-p', 'input_mode:=foreground', *node_args)
    executor = MultiThreadedExecutor(num_threads=3, context=context)
    executor.add_node(listener)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    log = tempfile.TemporaryFile(mode='w+')
    player_log = tempfile.TemporaryFile(mode='w+')
    node = subprocess.Popen(
        [sys.executable, '-m', 'mbtrack_ros.nodes.tracker_node', '--ros-args',
         '-p', f'calibration_file:={recording / "calibration.yaml"}',
         '-p', f'cameras:=[{",".join(cams)}]', '-p', 'detection.enabled:=true',
         '-p', f'tracker.seed:={seed}', '-p', 'image_reliability:=reliable',
         '-p', f'max_pending_sets:={max_pending_sets}',
         '-p', f'use_sim_time:={str(use_sim_time).lower()}', *node_args],
        cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT, text=True)
    player = None
    from mbtrack_ros.core.camera import RoomCalibration

    pixels = next((int(a.split(':=')[1]) for a in node_args
                   if a.startswith('tracker.working_pixels:=')), 76_800)
    working = {n: c.at_most(pixels) for n, c in
               RoomCalibration.load(recording / 'calibration.yaml').cameras.items()}
    working_bytes = 3 * working['cam0'].width * working['cam0'].height
    stages = []
    stage_logs = [tempfile.TemporaryFile(mode='w+') for _ in cams] if camera_nodes else []
    for cam, stage_log in zip(cams, stage_logs):
        stages.append(subprocess.Popen(
            [sys.executable, '-m', 'mbtrack_ros.nodes.camera_node', '--ros-args',
             '-r', f'__ns:=/{cam}', '-p', f'calibration_file:={recording / "calibration.yaml"}',
             '-p', f'camera:={cam}', '-p', 'image_reliability:=reliable',
             '-p', f'image_format:={image_format}',
             '-p', f'image_transport:={"compressed" if compressed else "raw"}',
             *[x for a in node_args if a.startswith('tracker.working_pixels:=')
               for x in ('-p', a)]],
            cwd=REPO, env=env, stdout=stage_log, stderr=subprocess.STDOUT, text=True))
    try:
        # the listener's subscriptions must be matched too: start the player once the
        # tracker's people publisher sees us (the node is up, its warm-up done: that can
        # take minutes when numba recompiles after a code change), then it waits for the
        # cameras
        deadline = time.monotonic() + 300
        while listener.count_publishers('/tracker_node/people') == 0:
            if node.poll() is not None or time.monotonic() > deadline:
                log.seek(0)
                raise RuntimeError(f'tracker_node did not start: {log.read()[-500:]}')
            time.sleep(0.1)
        # with camera nodes: every one of them up (warmed up: it creates its end points
        # after) and discovered with the tracker's end points, so that no frame set of the
        # start counts one as missing
        def connected(cam: str) -> bool:
            w = f'/{cam}/working/'
            image = w + ('image/compressed' if image_format == 'jpeg' else 'image')
            return (listener.count_publishers(image) >= 1
                    and listener.count_subscribers(image) >= 1
                    and listener.count_subscribers(w + 'score_request') >= 1)
        while camera_nodes and not all(map(connected, cams)):
            if any(p.poll() is not None for p in stages) or time.monotonic() > deadline:
                raise RuntimeError('the camera nodes did not come up and connect to the '
                                   'tracker within 300 s')
            time.sleep(0.1)
        player = subprocess.Popen(
            [sys.executable, '-m', 'mbtrack_ros.nodes.bag_player', '--ros-args',
             '-p', f'bag:={recording}', '-p', f'rate:={rate}',
             '-p', 'wait_for_subscribers:=true', '-p', 'start_delay:=1.0',
             # our /clock reader too: a listener that missed the first /clock messages timed
             # only later frames and took a later frame for frame 0
             '-p', f'clock_subscribers:={2 if use_sim_time else 1}',
             '-p', f'topics:=[{",".join(image_topic(c, compressed) for c in cams)}]'],
            cwd=REPO, env=env, stdout=player_log, stderr=subprocess.STDOUT, text=True)
        cpu0, wall0 = cpu_seconds(node.pid), time.monotonic()
        threads0 = thread_cpu_seconds(node.pid)
        rss: list[tuple[float, float]] = []
        sampling = threading.Event()

        def sample() -> None:
            while not sampling.wait(1.0):
                try:
                    rss.append((time.monotonic() - wall0, rss_megabytes(node.pid)))
                except OSError:
                    return

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        stage0 = [cpu_seconds(p.pid) for p in stages]
        if player.wait(timeout=timeout) != 0:
            raise RuntimeError(f'bag_player exited with {player.returncode}')
        # the last frame sets: wait until no output has come for 1 s
        last_n, quiet = -1, time.monotonic()
        while time.monotonic() - quiet < 1.0 and time.monotonic() - wall0 < timeout + 5:
            with lock:
                n = len(people)
            if n != last_n:
                last_n, quiet = n, time.monotonic()
            time.sleep(0.1)
        cpu1, wall1 = cpu_seconds(node.pid), time.monotonic()
        threads1 = thread_cpu_seconds(node.pid)
        # the final counts: the node publishes /diagnostics on a wall-clock period once no
        # frame set forms; wait until two such in a row, sent after the last output, show
        # the same counts (a loaded node may still be working through its queue)
        with lock:
            seen = len(diags)
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            with lock:
                last = diags[-2:] if len(diags) >= seen + 2 else []
            if len(last) == 2 and all(d.get('_reason') for d in last) \
                    and {k: v for k, v in last[0].items() if k != '_reason'
                         and 'time' not in k} == {k: v for k, v in last[1].items()
                                                  if k != '_reason' and 'time' not in k}:
                break
            time.sleep(0.1)
        sampling.set()
        sampler.join(timeout=5)
        stage_cpu = tuple(cpu_seconds(p.pid) - c for p, c in zip(stages, stage0))
    finally:
        for proc in (player, node, *stages):
            if proc is not None and proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()
        executor.shutdown()
        spinner.join(timeout=5)
        listener.destroy_node()
        rclpy.try_shutdown(context=context)
        log.seek(0)
        score_lines = [ln for ln in log.read().splitlines()
                       if 'score requests,' in ln or '[WARN]' in ln]
        log.close()
        stage_lines = []
        for stage_log in stage_logs:
            stage_log.seek(0)
            lines = [ln for ln in stage_log.read().splitlines() if 'frames processed' in ln]
            stage_lines += lines[-1:]
            stage_log.close()
        player_log.seek(0)
        burst = _BURST.search(player_log.read())
        player_log.close()
    with lock:
        images_c, people_c, diag = dict(images), dict(people), (diags[-1] if diags else {})
        sent_c = dict(sent)
    first = min(images_c) if images_c else 0
    later = {s: t for s, t in images_c.items() if s >= first + 1_000_000_000}
    settled = {s: t for s, t in images_c.items() if s >= first + 5_000_000_000}
    cpu = cpu1 - cpu0
    wall = wall1 - wall0
    stamps, lat, _ = match_latencies(images_c, people_c)
    sent_stamps, sent_lat, _ = match_latencies(images_c, sent_c)
    order = sorted(images_c)
    unanswered = tuple(k for k, s in enumerate(order) if s not in people_c)
    return LiveResult(
        frames=frames, people_messages=len(people_c),
        latency_all=latency_stats(images_c, people_c),
        latency_after_1s=latency_stats(later, people_c),
        latency_after_5s=latency_stats(settled or later, people_c),
        diagnostics=diag, cpu_seconds=cpu, wall_seconds=wall,
        cpu_percent=100.0 * cpu / max(wall, 1e-9),
        mean_people_truth=float(np.mean([truth_count.get(s, 0) for s in images_c]))
        if images_c else 0.0,
        mean_tracks=float(np.mean(list(tracks.values()))) if tracks else 0.0,
        publish_spread_p50=float(burst['p50']) / 1e3 if burst else float('nan'),
        publish_spread_p95=float(burst['p95']) / 1e3 if burst else float('nan'),
        latency_series=tuple(zip(((stamps - first) / 1e9).tolist(), lat.tolist())),
        injected_bad=injected[0], rss_mb=tuple(rss),
        camera_node_cpu_seconds=stage_cpu, camera_node_logs=tuple(stage_lines),
        tracker_score_logs=tuple(score_lines),
        mask_bytes_per_frame=float(np.mean(masks)) if masks else float('nan'),
        image_bytes_per_frame=(float(np.mean(jpegs)) if jpegs else float('nan'))
        if image_format == 'jpeg' else float(working_bytes) if camera_nodes else float('nan'),
        image_format=image_format, cameras=len(cams),
        tracker_threads=thread_split(threads0, threads1, node.pid), unanswered=unanswered,
        sent_all=latency_stats(images_c, sent_c),
        sent_after_1s=latency_stats(later, sent_c),
        sent_series=tuple(zip(((sent_stamps - first) / 1e9).tolist(), sent_lat.tolist())))


def run_offline(recording: Path, *, seed: int = 0, ground_truth: bool = False,
                params: Path | None = None) -> dict:
    """Time ``mbtrack replay`` over the recording (automatic detection, or ``--init-from``
    the ground truth; ``params``: a tracker_node parameter file, e.g. the fast profile):
    frames/s, CPU seconds of this process and the ratio to real time."""
    from mbtrack_ros.cli import main
    from mbtrack_ros.recording.bag import RecordingReader

    with RecordingReader(recording / 'bag') as reader:
        frames = reader.frame_count
    with tempfile.TemporaryDirectory() as tmp:
        t0, c0 = time.perf_counter(), time.process_time()
        extra = ['--init-from', str(recording / 'ground_truth.csv')] if ground_truth else []
        if params is not None:
            extra += ['--params', str(params)]
        code = main(['replay', str(recording), '--out', tmp, '--seed', str(seed), *extra])
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
    if code != 0:
        raise RuntimeError(f'mbtrack replay exited with {code}')
    return {'frames': frames, 'wall_seconds': wall, 'cpu_seconds': cpu,
            'frames_per_second': frames / wall, 'x_real_time': frames / wall / FPS,
            'params': None if params is None else str(params)}


def _size(text: str) -> tuple[int, int]:
    """``WxH`` -> (W, H), both 16-4096."""
    try:
        w, h = (int(v) for v in text.lower().split('x'))
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected WxH, got {text!r}') from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096):
        raise argparse.ArgumentTypeError(f'sizes must be 16-4096, got {text!r}')
    return w, h


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``--live`` options of ``mbtrack bench``."""
    parser.add_argument('--live', action='store_true',
                        help='instead of the filter grid: bag_player -> tracker_node over DDS '
                             'in real time (latency, dropped sets, CPU) and offline replay '
                             'speed, on clear-room with 4 corner cameras at 320x240')
    parser.add_argument('--live-frames', type=int, default=1800, metavar='N',
                        help='frames of the live recording (default 1800 = 2 minutes)')
    parser.add_argument('--live-recording', type=Path, default=None, metavar='DIR',
                        help='keep the generated recording here (reused if it exists)')
    parser.add_argument('--live-no-sim-time', action='store_true',
                        help='run tracker_node without use_sim_time (it then does not '
                             'subscribe to /clock; its outputs use message stamps anyway)')
    parser.add_argument('--live-no-warm-up', action='store_true',
                        help='start tracker_node with warm_up:=false (the start-up backlog '
                             'as it was before the warm-up)')
    parser.add_argument('--live-ground-truth', action='store_true',
                        help='start tracks from the ground truth (node init_ground_truth, '
                             'replay --init-from) instead of the automatic detection')
    parser.add_argument('--live-param', action='append', default=[], metavar='NAME:=VALUE',
                        help='a tracker_node parameter for the live run, as after ros-args '
                             '-p (repeatable), e.g. tracker.pipeline_search:=true')
    parser.add_argument('--live-size', type=_size, default=None, metavar='WxH',
                        help="image size of a generated live recording (default: the "
                             "preset's, 320x240 for clear-room)")
    parser.add_argument('--live-preset', default='clear-room', metavar='PRESET',
                        help='synth preset of a generated live recording, without its '
                             'ceiling camera (default clear-room: 4 corner cameras; '
                             'eight-cameras, twelve-cameras: 8 and 12 cameras at 640x480)')
    parser.add_argument('--live-rate', type=float, default=1.0, metavar='R',
                        help='play at R times real time (default 1: 15 Hz; 0.5: 7.5 Hz, '
                             'to measure the CPU per frame set of a set-up the machine '
                             'cannot run at 15 Hz)')
    parser.add_argument('--live-cameras', type=int, default=None, metavar='N',
                        help='track with the first N cameras of the recording only (the '
                             'same people seen by fewer cameras; default all)')
    parser.add_argument('--live-image-format', choices=('raw', 'jpeg'), default='raw',
                        help='with --live-camera-nodes: the working images the camera '
                             'nodes send the tracker (camera_node image_format; default '
                             'raw)')
    parser.add_argument('--live-camera-nodes', action='store_true',
                        help='one camera_node process per camera and tracker_node in fusion '
                             'mode (input_mode foreground): their CPU, the masks\' bytes')
    parser.add_argument('--live-no-offline', action='store_true',
                        help='skip the offline replays after the live run')
    parser.add_argument('--live-bad-rate', type=float, default=0.0, metavar='P',
                        help='soak: publish a bad image on --live-bad-camera for this share '
                             'of the frame sets (0..1, e.g. 0.01); the summary compares the '
                             "node's /diagnostics with what was injected and reports the "
                             "tracker process's memory growth (default 0: none)")
    parser.add_argument('--live-bad-camera', default='cam0', metavar='NAME',
                        help='camera whose topic gets the bad images (default cam0)')
    parser.add_argument('--live-compressed', action='store_true',
                        help='generate the recording with JPEG images (a long soak\'s '
                             'recording stays small); the node then subscribes to the '
                             'compressed topics')


def soak_summary(live: LiveResult, camera: str) -> str:
    """The soak's lines: memory growth, frame sets processed, injected vs counted."""
    d = live.diagnostics

    def count(key: str) -> int:
        try:
            return int(d.get(key, 0))
        except ValueError:
            return 0

    formed = count('frame sets') + count('incomplete frame sets')
    lost = (count('dropped frame sets (queue full)') + count('dropped frame sets (step error)')
            + count('dropped frame sets (repeated stamp)'))
    mb = [m for _, m in live.rss_mb]
    growth = memory_growth(live.rss_mb)
    return (f'soak: tracker_node RSS {mb[0] if mb else float("nan"):.0f} MB at start, '
            f'{max(mb) if mb else float("nan"):.0f} MB peak, {mb[-1] if mb else float("nan"):.0f}'
            f' MB at the end, growth {100 * growth:+.1f} % (median of the last tenth of '
            f'{len(mb)} samples over the second tenth)\n'
            f'soak: frame sets processed {formed - lost} of {live.frames} played ({formed} '
            f'formed, {count("incomplete frame sets")} incomplete, {lost} dropped)\n'
            f'soak: frames without an output (index in the recording): '
            f'{", ".join(map(str, live.unanswered[:12])) or "none"}'
            f'{" ..." if len(live.unanswered) > 12 else ""}\n'
            f'soak: bad images injected on {camera}: {live.injected_bad}; /diagnostics '
            f'dropped images (bad): {count("dropped images (bad)")}; dropped frames (late or '
            f'duplicate): {count("dropped frames (late or duplicate)")}')


def _error(message: str) -> int:
    print(f'{_PROG}: error: {message}', file=sys.stderr)
    return 2


def main_live(args: argparse.Namespace) -> int:
    """``mbtrack bench --live``: run, print a summary, optionally write JSON."""
    if args.live_frames < 30:
        return _error(f'--live-frames must be >= 30, got {args.live_frames}')
    if not 0.05 <= args.live_rate <= 4.0:
        return _error(f'--live-rate must be in [0.05, 4], got {args.live_rate}')
    if not 0.0 <= args.live_bad_rate <= 1.0:
        return _error(f'--live-bad-rate must be in [0, 1], got {args.live_bad_rate}')
    bad = [p for p in args.live_param if ':=' not in p or p.startswith(':=')]
    if bad:
        return _error(f'--live-param must be NAME:=VALUE, got {bad[0]!r}')
    node_args: tuple[str, ...] = ('-p', 'warm_up:=false') if args.live_no_warm_up else ()
    for param in args.live_param:
        node_args += ('-p', param)
    from mbtrack_ros.recording.bag import BagError
    from mbtrack_ros.synth.errors import SynthError

    seed = args.seed
    tmp = None
    try:
        if args.live_recording is not None and (args.live_recording / 'bag').exists():
            recording = args.live_recording
        else:
            if args.live_recording is None:
                tmp = Path(tempfile.mkdtemp(prefix='mbtrack_live_'))
                recording = tmp / 'clear-room'
            else:
                recording = args.live_recording
            print(f'{_PROG}: generating {args.live_frames} frames of {args.live_preset} '
                  f'into {recording}', file=sys.stderr)
            make_recording(recording, frames=args.live_frames, seed=seed,
                           compressed=args.live_compressed, size=args.live_size,
                           preset=args.live_preset)
        from mbtrack_ros.core.camera import CalibrationError, RoomCalibration
        try:
            names = RoomCalibration.load(recording / 'calibration.yaml').names
        except CalibrationError as err:
            return _error(str(err).splitlines()[0])
        if args.live_cameras is not None and not 1 <= args.live_cameras <= len(names):
            return _error(f'--live-cameras must be 1-{len(names)}, got {args.live_cameras}')
        names = names[:args.live_cameras]
        if args.live_bad_rate > 0 and args.live_bad_camera not in names:
            return _error(f'--live-bad-camera must be one of {", ".join(names)}, got '
                          f'{args.live_bad_camera!r}')
        load0 = os.getloadavg()
        live = run_live(recording, seed=seed, rate=args.live_rate,
                        use_sim_time=not args.live_no_sim_time,
                        ground_truth=args.live_ground_truth, node_args=node_args,
                        bad_rate=args.live_bad_rate, bad_camera=args.live_bad_camera,
                        camera_nodes=args.live_camera_nodes,
                        image_format=args.live_image_format, cameras=args.live_cameras,
                        timeout=max(600.0, 2.0 * args.live_frames / FPS / args.live_rate))
        load1 = os.getloadavg()
        offline = fast = quick = None
        if not args.live_no_offline:
            offline = run_offline(recording, seed=seed, ground_truth=args.live_ground_truth)
        if FAST_PROFILE.is_file() and not args.live_no_offline:  # a source checkout
            fast = run_offline(recording, seed=seed, ground_truth=args.live_ground_truth,
                               params=FAST_PROFILE)
        if OFFLINE_PROFILE.is_file() and not args.live_no_offline:
            quick = run_offline(recording, seed=seed, ground_truth=args.live_ground_truth,
                                params=OFFLINE_PROFILE)
    except (LatencyError, RuntimeError, OSError, SynthError, BagError,
            subprocess.TimeoutExpired) as err:
        return _error(str(err))
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    d = live.diagnostics
    a, b, c = live.latency_all, live.latency_after_1s, live.latency_after_5s
    print(f'live: {live.frames} frames at {FPS * args.live_rate:g} Hz, '
          f'{live.people_messages} PoseArrays '
          f'({live.frames - live.people_messages} frame sets without output), '
          f'{live.mean_people_truth:.2f} people / {live.mean_tracks:.2f} tracks on average')
    print(f'latency image -> people: p50 {1e3 * a.p50:.1f} ms, p95 {1e3 * a.p95:.1f} ms, '
          f'max {1e3 * a.max:.1f} ms ({a.matched} frames timed, {a.missing} seen on /clock '
          'without output); after the '
          f'first second: p50 {1e3 * b.p50:.1f} ms, p95 {1e3 * b.p95:.1f} ms; after the first '
          f'5 s: p50 {1e3 * c.p50:.1f} ms, p95 {1e3 * c.p95:.1f} ms')
    if live.sent_all is not None:
        e, f = live.sent_all, live.sent_after_1s
        print(f'latency image -> people sent (the tracker\'s send time): p50 '
              f'{1e3 * e.p50:.1f} ms, p95 {1e3 * e.p95:.1f} ms, max {1e3 * e.max:.1f} ms; '
              f'after the first second: p50 {1e3 * f.p50:.1f} ms, p95 {1e3 * f.p95:.1f} ms')
    print(f'node counters (last /diagnostics): frame sets {d.get("frame sets")}, incomplete '
          f'{d.get("incomplete frame sets")}, dropped frames/sets {d.get("dropped frames")}, '
          f'step time {d.get("step time [ms]")} ms')
    print(f'bag_player: publishing one frame set took p50 {1e3 * live.publish_spread_p50:.1f} '
          f'ms, p95 {1e3 * live.publish_spread_p95:.1f} ms (its own log: first to last message '
          'of a stamp)')
    print(f'tracker_node CPU: {live.cpu_seconds:.1f} s over {live.wall_seconds:.1f} s '
          f'= {live.cpu_percent:.0f} % of one core = {1e3 * live.cpu_seconds / live.frames:.1f} '
          f'ms per frame set played ({live.cameras} cameras; '
          f'{1e3 * live.cpu_seconds / max(live.people_messages, 1):.1f} ms per frame set '
          'answered); by thread: '
          + ', '.join(f'{k} {v:.1f} s' for k, v in live.tracker_threads if v >= 0.05))
    if args.live_bad_rate > 0:
        print(soak_summary(live, args.live_bad_camera))
    for name, off in (('default', offline), (f'fast profile {FAST_PROFILE.name}', fast),
                      (f'offline profile {OFFLINE_PROFILE.name}', quick)):
        if off is not None:
            print(f'offline replay ({name}): {off["frames"]} frames in '
                  f'{off["wall_seconds"]:.1f} s = {off["frames_per_second"]:.1f} frames/s = '
                  f'{off["x_real_time"]:.2f}x real time (CPU {off["cpu_seconds"]:.1f} s)')
    if live.camera_node_cpu_seconds:
        per = live.camera_node_cpu_seconds
        print(f'camera_node CPU: {sum(per):.1f} s in all ({", ".join(f"{c:.1f}" for c in per)}'
              f' s each) = {100.0 * sum(per) / max(live.wall_seconds, 1e-9):.0f} % of one '
              f'core = {1e3 * sum(per) / len(per) / live.frames:.1f} ms per camera and frame; '
              f'per camera and frame: working image {live.image_bytes_per_frame / 1024:.1f}'
              f' KiB ({"JPEG" if live.image_format == "jpeg" else "raw rgb8"}), foreground '
              f'masks {live.mask_bytes_per_frame / 1024:.2f} KiB '
              f'({"PNG" if live.image_format == "jpeg" else "raw mono8"})')
        for line in live.camera_node_logs + live.tracker_score_logs:
            print('  ' + line[line.find(']: ') + 3:] if ']: ' in line else line)
    print(f'load average before / after the live run: {load0[0]:.2f} / {load1[0]:.2f}')
    if args.json is not None:
        doc = {'live': asdict(live), 'offline': offline, 'offline_fast': fast,
               'offline_profile': quick,
               'loadavg_before': load0,
               'loadavg_after': load1, 'seed': seed, 'preset': args.live_preset,
               'rate': args.live_rate, 'cameras': live.cameras,
               'use_sim_time': not args.live_no_sim_time,
               'ground_truth': bool(args.live_ground_truth),
               'warm_up': not args.live_no_warm_up, 'node_params': list(args.live_param)}
        try:
            args.json.write_text(json.dumps(doc, indent=1), encoding='utf-8')
        except OSError as err:
            return _error(f'cannot write {args.json}: {err.strerror or err}')
    return 0
