"""The ROS 2 nodes: parameter files, start-up errors, and tracking end to end over DDS."""
from __future__ import annotations

import math
import os
import py_compile
import threading
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest
import yaml

# a domain of our own, before any rclpy import creates a participant
os.environ['ROS_DOMAIN_ID'] = str(100 + os.getpid() % 100)

import rclpy  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402

from conftest import REPO, playing, spinning  # noqa: E402
from mbtrack_ros.core.dynamics import MotionConfig  # noqa: E402
from mbtrack_ros.nodes import tracker_node  # noqa: E402
from mbtrack_ros.nodes.params import ParamsError  # noqa: E402
from mbtrack_ros.nodes.tracker_node import TrackerNode  # noqa: E402

CONFIGS = sorted((REPO / 'config').glob('*.yaml'))


@pytest.fixture(scope='module')
def room_calibration(tmp_path_factory) -> Path:
    """The synthetic room's calibration (cam0..cam4), as the configs expect."""
    from mbtrack_ros.synth.room import default_room, make_calibration
    path = tmp_path_factory.mktemp('calib') / 'calibration.yaml'
    make_calibration(default_room()).save(path)
    return path


def flatten(doc: dict, prefix: str = '') -> dict:
    out = {}
    for key, value in doc.items():
        if isinstance(value, dict):
            out.update(flatten(value, f'{prefix}{key}.'))
        else:
            out[prefix + key] = value
    return out


def start(context, *args: str, step_thread: bool = False) -> TrackerNode:
    """A node; without ``step_thread`` queued sets wait for process_pending() (by hand)."""
    return TrackerNode(cli_args=['--ros-args', *args], context=context,
                       step_thread=step_thread)


@pytest.mark.parametrize('config', CONFIGS, ids=[c.name for c in CONFIGS])
def test_every_example_config_loads(config, room_calibration, context):
    node = start(context, '--params-file', str(config),
                 '-p', f'calibration_file:={room_calibration}')
    try:
        values = flatten(yaml.safe_load(config.read_text())['tracker_node']['ros__parameters'])
        values['calibration_file'] = str(room_calibration)
        for name, value in values.items():
            assert node.get_parameter(name).value == value, name
        p = node.params
        assert p.camera_names == values['cameras']
        assert p.tolerance_ns == round(values['sync.tolerance'] * 1e9)
        assert p.tracker.algorithm == values['tracker.algorithm']
        assert p.tracker.particles == values.get('tracker.particles', 100)
        transport = values.get('image_transport', 'raw')
        for cam in p.cameras:
            override = values.get(f'camera.{cam.name}.image_topic')
            suffix = '/compressed' if transport == 'compressed' else ''
            assert cam.image_topic == (override or f'/{cam.name}/image_raw{suffix}')
            assert cam.transport == transport
        assert sorted(node.pub_debug) == sorted(p.camera_names)
    finally:
        node.destroy_node()


def test_detection_parameter_reaches_the_tracker(room_calibration, context, tmp_path):
    # automatic detection is the default, with the release time and threshold passed on
    node = start(context, '-p', f'calibration_file:={room_calibration}',
                 '-p', 'tracker.particles:=50', '-p', 'tracker.release_time:=1.5',
                 '-p', 'detection.threshold:=2.5', '-p', 'tracker.subsample:=2',
                 '-p', 'detection.spare_support:=0.0', '-p', 'detection.reuse_time:=0.5',
                 '-p', 'tracker.coverage_gain:=1.5')
    try:
        assert node.params.tracker.detection is True
        assert node.tracker.config.detection is True and node.tracker.config.particles == 50
        assert node.tracker.measurement.config.subsample == 2  # the fast profile's option
        assert node.tracker.detection is not None  # the automatic detection is running
        cfg = node.tracker.config.detection_config()
        assert cfg.release.timeout == 1.5 and cfg.detector.threshold == 2.5
        assert cfg.release.spare_support == 0.0  # the spare-track rule switched off
        assert node.tracker.detection.releaser.config.spare_support == 0.0
        assert cfg.reuse_time == 0.5 and node.tracker.detection.config.reuse_time == 0.5
        assert node.tracker.measurement.config.coverage_gain == 1.5  # default: 2.0
    finally:
        node.destroy_node()
    node = start(context, '-p', f'calibration_file:={room_calibration}',
                 '-p', 'detection.enabled:=false')
    try:
        assert node.params.tracker.detection is False and node.tracker.detection is None
    finally:
        node.destroy_node()
    # tracks started from ground truth: no detection on top
    gt = tmp_path / 'gt.csv'
    gt.write_text('stamp_ns,frame,person_id,x,y,z_head,sitting,visible_cameras\n')
    node = start(context, '-p', f'calibration_file:={room_calibration}',
                 '-p', f'init_ground_truth:={gt}')
    try:
        assert node.tracker.detection is None
    finally:
        node.destroy_node()


def test_motion_parameters_reach_the_tracker(room_calibration, context):
    node = start(context, '-p', f'calibration_file:={room_calibration}')
    try:   # the defaults are MotionConfig's: the node moves particles as replay does
        assert node.tracker.config.motion == MotionConfig()
    finally:
        node.destroy_node()
    node = start(context, '-p', f'calibration_file:={room_calibration}',
                 '-p', 'motion.orientation_follows_velocity:=true',
                 '-p', 'motion.velocity_noise:=0.4', '-p', 'motion.max_speed:=2.5')
    try:
        assert node.tracker.config.motion == MotionConfig(
            orientation_follows_velocity=True, velocity_noise=0.4, max_speed=2.5)
    finally:
        node.destroy_node()


def test_qos_depth_reaches_image_subscriptions_and_outputs(room_calibration, context):
    from rclpy.qos import ReliabilityPolicy
    node = start(context, '-p', f'calibration_file:={room_calibration}',
                 '-p', 'image_reliability:=reliable', '-p', 'qos_depth:=77')
    try:
        images = [s for s in node._subs if s.topic_name.endswith('image_raw')]
        assert len(images) == len(node.params.cameras)
        for sub in images:
            assert sub.qos_profile.depth == 77
            assert sub.qos_profile.reliability == ReliabilityPolicy.RELIABLE
        for pub in (node.pub_people, node.pub_tracks, node.pub_markers, node.pub_diag,
                    *node.pub_debug.values()):
            assert pub.qos_profile.depth == 77
    finally:
        node.destroy_node()
    # best effort keeps the sensor-data profile, whatever the depth
    node = start(context, '-p', f'calibration_file:={room_calibration}', '-p', 'qos_depth:=77')
    try:
        sub = next(s for s in node._subs if s.topic_name.endswith('image_raw'))
        assert sub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
        assert node.pub_people.qos_profile.depth == 77
    finally:
        node.destroy_node()


BAD = [
    (['-p', 'qos_depth:=0'], "'qos_depth': value out of range"),
    (['-p', 'tracker.particles:=0'], "'tracker.particles': value out of range"),
    (['-p', 'detection.reuse_time:=-1.0'], "'detection.reuse_time': value out of range"),
    (['-p', 'tracker.subsample:=0'], "'tracker.subsample': value out of range"),
    (['-p', 'tracker.working_pixels:=100'], "'tracker.working_pixels': value out of range"),
    (['-p', 'tracker.working_pixels:=0.5'], "'tracker.working_pixels': wrong type"),
    (['-p', 'image_transport:=udp'], "image_transport: 'udp' is not one of raw, compressed"),
    (['-p', 'camera.cam0.transport:=theora'], 'camera.cam0.transport'),
    (['-p', 'sync.tolerance:=1'], "'sync.tolerance': wrong type"),
    (['-p', 'sync.tolerance:=0.5', '-p', 'sync.timeout:=0.2'], 'must exceed sync.tolerance'),
    (['-p', 'camera.cam0.time_offset:=20.0'], "'camera.cam0.time_offset': value out of range"),
    (['-p', 'tracker.algorithm:=magic'], "tracker.algorithm: 'magic' is not one of"),
    (['-p', 'motion.velocity_noise:=-0.1'], "'motion.velocity_noise': value out of range"),
    (['-p', 'motion.orientation_follows_velocity:=1.0'],
     "'motion.orientation_follows_velocity': wrong type"),
    (['-p', 'tracker.coverage_gain:=true'], "'tracker.coverage_gain': wrong type"),
    (['-p', 'cameras:=[cam0,cam9]'], 'unknown camera(s) cam9'),
    (['-p', 'init_ground_truth:=/nonexistent/gt.csv'], 'does not exist'),
]


@pytest.mark.parametrize('args,message', BAD, ids=[m for _, m in BAD])
def test_bad_parameter_refused_with_clear_message(args, message, room_calibration, context):
    with pytest.raises(ParamsError) as info:
        start(context, '-p', f'calibration_file:={room_calibration}', *args)
    assert message in str(info.value) and '\n' not in str(info.value)


def test_missing_calibration_exits_nonzero(capsys):
    code = tracker_node.main(['tracker_node', '--ros-args', '-p',
                              'calibration_file:=/nonexistent/calibration.yaml'])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err[-1] == ("tracker_node: error: calibration_file "
                       "'/nonexistent/calibration.yaml' does not exist")


def test_launch_file_compiles(tmp_path):
    py_compile.compile(str(REPO / 'launch' / 'smart_room.launch.py'),
                       cfile=str(tmp_path / 'launch.pyc'), doraise=True)


def image_msg(rgb, stamp, frame_id='cam0_optical_frame'):
    from mbtrack_ros.nodes.conversions import rgb_to_image
    from mbtrack_ros.nodes.messages import make_header
    return rgb_to_image(rgb, make_header(stamp, frame_id))


def test_bad_frames_dropped_and_stamps_backwards_reset(room_calibration, context):
    """Callbacks called directly (no DDS): bad frames are counted and dropped, the node keeps
    running, and stamps going backwards reset synchroniser and tracker."""
    node = start(context, '-p', f'calibration_file:={room_calibration}',
                 '-p', 'cameras:=[cam0,cam1]', '-p', 'sync.timeout:=0.1')
    try:
        rgb = np.full((240, 320, 3), 90, np.uint8)
        t0 = 1_000_000_000
        bad = image_msg(rgb, t0)
        bad.encoding = 'yuv422'
        node._on_image('cam0', bad)
        node._on_image('cam0', image_msg(rgb[:100], t0))  # wrong size, no rescaling
        assert node._dropped == 2 and sum(node.sync.pending.values()) == 0
        period = 66_666_667
        for k in range(4):
            node._on_image('cam0', image_msg(rgb, t0 + k * period))
            if k != 2:  # cam1 misses frame 2: that set goes out without cam1
                node._on_image('cam1', image_msg(rgb, t0 + k * period, 'cam1_optical_frame'))
            node.process_pending()  # what the step thread does
        assert node._last_stamp == t0 + 3 * period
        snap = node.snapshot(messages_result())
        assert snap.frame_sets == 3 and snap.incomplete_sets == 1 and snap.dropped_frames == 2
        assert snap.input_rate_hz['cam0'] == pytest.approx(1e9 / period)
        # a sliding window: a second snapshot right after (a tracker lagging behind its
        # inputs) still reports the input rate, not an empty window
        again = node.snapshot(messages_result())
        assert again.input_rate_hz['cam0'] == pytest.approx(1e9 / period)
        assert snap.resets == 0
        # the recording restarts: both cameras back at t0
        node._on_image('cam0', image_msg(rgb, t0))
        node._on_image('cam1', image_msg(rgb, t0, 'cam1_optical_frame'))
        node.process_pending()
        assert node._resets == 1 and node._last_stamp == t0
        assert node.sync.counters.resets == 1
    finally:
        node.destroy_node()


def messages_result():
    from mbtrack_ros.core.state import FrameResult
    return FrameResult(stamp_ns=0)


def test_step_thread_processes_every_queued_set_in_order(room_calibration, context):
    """The step thread: sets queued while a step is running are all processed, in stamp
    order, none dropped (the queue holds up to max_pending_sets)."""
    node = start(context, '-p', f'calibration_file:={room_calibration}',
                 '-p', 'cameras:=[cam0,cam1]', '-p', 'detection.enabled:=false',
                 step_thread=True)
    seen = []
    process = node.process

    def spy(fs):
        seen.append(fs.stamp_ns)
        return process(fs)

    node.process = spy
    try:
        rgb = np.full((240, 320, 3), 90, np.uint8)
        period = 66_666_667
        stamps = [1_000_000_000 + k * period for k in range(12)]
        with node._step_lock:  # a long step: the thread cannot process while we feed
            for t in stamps:
                node._on_image('cam0', image_msg(rgb, t))
                node._on_image('cam1', image_msg(rgb, t, 'cam1_optical_frame'))
            time.sleep(0.2)
            assert len(node._pending) >= 11  # queued, not dropped (default queue: 15)
        deadline = time.monotonic() + 30
        while len(seen) < len(stamps) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert seen == stamps
        snap = node.snapshot(messages_result())
        assert snap.dropped_sets_full == 0 and snap.dropped_frames == 0
        assert snap.queue_peak >= 11 and snap.frame_sets == len(stamps)
    finally:
        node.destroy_node()


def test_queue_overflow_drops_oldest_and_says_why(room_calibration, context):
    """A tracker that stays max_pending_sets behind loses the oldest sets, counted as
    'dropped frame sets (queue full)' in /diagnostics; the newest are kept."""
    from mbtrack_ros.nodes.messages import diagnostics_message

    node = start(context, '-p', f'calibration_file:={room_calibration}',
                 '-p', 'cameras:=[cam0]', '-p', 'max_pending_sets:=3',
                 '-p', 'detection.enabled:=false')
    try:
        rgb = np.full((240, 320, 3), 90, np.uint8)
        stamps = [1_000_000_000 + k * 66_666_667 for k in range(5)]
        for t in stamps:
            node._on_image('cam0', image_msg(rgb, t))
        assert [fs.stamp_ns for fs in node._pending] == stamps[2:]
        snap = node.snapshot(messages_result())
        assert snap.dropped_sets_full == 2 and snap.dropped_sets_error == 0
        assert snap.queued_sets == 3 and snap.queue_peak == 3
        values = {kv.key: kv.value for kv in diagnostics_message(0, snap).status[0].values}
        assert values['dropped frame sets (queue full)'] == '2'
        node.process_pending()
        assert node._last_stamp == stamps[-1]
    finally:
        node.destroy_node()


def test_compressed_transport_and_rescaling(room_calibration, context):
    from sensor_msgs.msg import CompressedImage

    from mbtrack_ros.nodes.conversions import rgb_to_compressed
    from mbtrack_ros.nodes.messages import make_header

    node = start(context, '-p', f'calibration_file:={room_calibration}',
                 '-p', 'cameras:=[cam0]', '-p', 'image_transport:=compressed',
                 '-p', 'rescale_images:=true')
    try:
        assert node._subs[0].msg_type is CompressedImage
        assert node._subs[0].topic_name == '/cam0/image_raw/compressed'
        half = np.zeros((120, 160, 3), np.uint8)
        half[:, 80:] = 200  # right half bright
        node._on_image('cam0', rgb_to_compressed(half, make_header(5, 'cam0_optical_frame'),
                                                 'png'))
        assert node._dropped == 0
        fs = node._pending[0]
        image = fs.images['cam0']
        assert image.shape == (240, 320, 3)  # resized to the calibration
        assert image[:, :150].max() == 0 and image[:, 170:].min() == 200
    finally:
        node.destroy_node()


def test_bag_player_bad_bag_exits_nonzero(tmp_path, capsys):
    from mbtrack_ros.nodes import bag_player
    code = bag_player.main(['bag_player', '--ros-args', '-p', f'bag:={tmp_path}'])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err[-1] == (f"bag_player: error: '{tmp_path}' is not a rosbag2 directory "
                       '(no metadata.yaml)')


# -- end to end --------------------------------------------------------------------------
@pytest.fixture(scope='module')
def recording(tmp_path_factory) -> Path:
    from mbtrack_ros.synth.generator import generate
    return generate('lanz-seq1', tmp_path_factory.mktemp('rec') / 'lanz', frames=30, seed=3)


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


@pytest.mark.ros
def test_end_to_end_bag_player_tracker_subscriber(recording, context, tmp_path):
    """bag_player (own process) -> DDS -> tracker_node -> DDS -> test subscriber."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseArray
    from rosbags.highlevel import AnyReader
    from sensor_msgs.msg import Image
    from visualization_msgs.msg import Marker, MarkerArray

    from mbtrack_ros.nodes.conversions import image_to_rgb
    from mbtrack_ros.recording.csvfiles import read_ground_truth

    truth: dict[int, list[tuple[float, float]]] = {}
    for row in read_ground_truth(recording / 'ground_truth.csv'):
        truth.setdefault(row.stamp_ns, []).append((row.x, row.y))
    node = start(context, '-p', f'calibration_file:={recording / "calibration.yaml"}',
                 '-p', f'init_ground_truth:={recording / "ground_truth.csv"}',
                 '-p', 'tracker.seed:=0', '-p', 'max_pending_sets:=100',
                 # no frame lost on a loaded machine: reliable images, and queues deep
                 # enough for callbacks that stall a few seconds (CI lost a third of a
                 # second's frames with the default depth 10: 9.64 Hz input rate)
                 '-p', 'image_reliability:=reliable', '-p', 'qos_depth:=100',
                 '-p', f'output_bag:={tmp_path / "out"}', step_thread=True)
    listener = rclpy.create_node('e2e_listener', context=context)
    qos = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
    got: dict[str, list] = {'people': [], 'markers': [], 'diagnostics': [], 'debug': []}
    lock = threading.Lock()

    def keep(kind):
        def callback(msg):
            with lock:
                got[kind].append(msg)
        return callback

    listener.create_subscription(PoseArray, '/tracker_node/people', keep('people'), qos)
    listener.create_subscription(MarkerArray, '/tracker_node/markers', keep('markers'), qos)
    listener.create_subscription(DiagnosticArray, '/diagnostics', keep('diagnostics'), qos)
    # subscribing is what switches the debug image on
    listener.create_subscription(Image, '/tracker_node/debug/cam0/occlusion', keep('debug'), qos)
    with playing(recording, [node, listener], context, rate=1.0, timeout=60):
        # let the last frame sets through (a cold numba cache compiles for a while, and a
        # slow machine's node works through the sets for tens of seconds after the player)
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            with lock:
                if got['people'] and stamp_ns(got['people'][-1].header) == max(truth):
                    break
            time.sleep(0.1)

    people = got['people']
    assert len(people) >= 20, f'only {len(people)} PoseArray messages for 30 frames'
    tracked = 0
    errors = []
    for msg in people:
        stamp = stamp_ns(msg.header)
        assert stamp in truth, 'outputs must carry the frame set stamp'
        assert msg.header.frame_id == 'room'
        for pose in msg.poses:
            d = min(math.hypot(pose.position.x - x, pose.position.y - y)
                    for x, y in truth[stamp])
            assert d < 0.5, f'track {d:.2f} m from the nearest person at {stamp}'
            errors.append(d)
            q = pose.orientation
            assert abs(q.z ** 2 + q.w ** 2 - 1.0) < 1e-6
            tracked += 1
    assert tracked >= 20  # ground-truth starts produced tracks, not empty arrays
    by_stamp = {stamp_ns(m.header): m for m in people}
    cylinders = 0
    for msg in got['markers']:
        adds = [m for m in msg.markers if m.action == Marker.ADD and m.type == Marker.CYLINDER]
        if adds:
            stamp = stamp_ns(adds[0].header)
            assert stamp in by_stamp and len(adds) == len(by_stamp[stamp].poses)
            cylinders += len(adds)
    assert cylinders == tracked
    assert got['diagnostics'], 'no /diagnostics message'
    status = got['diagnostics'][-1].status[0]
    assert status.name == 'mbtrack_ros: tracker'
    assert {kv.key for kv in status.values} >= {'step time [ms]', 'frame sets', 'tracks'}
    # debug images: camera size, stamped like the outputs, differ from a plain frame
    assert got['debug'], 'no debug image although subscribed'
    debug = image_to_rgb(got['debug'][-1])
    assert debug.shape == (240, 320, 3)
    assert stamp_ns(got['debug'][-1].header) in by_stamp
    # the output bag holds what was published
    with AnyReader([tmp_path / 'out']) as reader:
        bag_people = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                      if c.topic == '/tracker_node/people']
    assert len(bag_people) >= len(people)
    bag_by_stamp = {stamp_ns(m.header): m for m in bag_people}
    for stamp, msg in by_stamp.items():
        assert [(p.position.x, p.position.y) for p in bag_by_stamp[stamp].poses] == [
            (p.position.x, p.position.y) for p in msg.poses]
    # the input rate: frames per second of message time over the last second of cam0
    # stamps the node had received when it sent the status (one camera: each frame it
    # received is a frame set in the bag). 15 Hz when no frame was lost on the way
    rate = next(s for s in got['diagnostics'][-1].status if s.name.endswith('input cam0'))
    reported = float(rate.values[0].value)
    received = np.array(sorted(bag_by_stamp))
    sent = stamp_ns(got['diagnostics'][-1].header)

    def rate_before(newest: int) -> float:
        recent = received[(received >= newest - 1_000_000_000) & (received <= newest)]
        return (len(recent) - 1) / ((recent[-1] - recent[0]) / 1e9)

    candidates = [rate_before(int(n)) for n in received if n >= sent]
    assert any(abs(reported - c) < 0.006 for c in candidates), (reported, candidates)
    if len(received) == len(truth):
        assert np.isclose(reported, 15.0, rtol=0.01), reported
    print(f'e2e: {len(people)} PoseArray for 30 frames, {tracked} poses, position error '
          f'mean {np.mean(errors):.3f} m max {np.max(errors):.3f} m, '
          f'{len(got["debug"])} debug images')


def test_bag_player_loops_and_publishes_clock(recording, context):
    """In-process player at 20x speed with loop: every message once per loop, /clock in bag
    time going back to the start on each loop."""
    from rosbags.highlevel import AnyReader
    from rosgraph_msgs.msg import Clock

    from mbtrack_ros.nodes.bag_player import BagPlayer

    with AnyReader([recording / 'bag']) as reader:
        count = sum(c.msgcount for c in reader.connections)
        first, last = reader.start_time, reader.end_time - 1
    player = BagPlayer(cli_args=['--ros-args', '-p', f'bag:={recording}', '-p', 'rate:=20.0',
                                 '-p', 'loop:=true', '-p', 'start_delay:=0.0'],
                       context=context)
    listener = rclpy.create_node('clock_listener', context=context)
    clocks = []
    listener.create_subscription(Clock, '/clock', lambda m: clocks.append(
        m.clock.sec * 1_000_000_000 + m.clock.nanosec), 1000)
    spin = ExitStack()
    spin.enter_context(spinning([listener], context))
    time.sleep(1.0)  # discovery of the /clock subscription
    thread = threading.Thread(target=player.play, daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 30
        while player.loops < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        player.stop()
        thread.join(timeout=5)
        assert player.loops >= 2
        assert count * player.loops <= player.published < count * (player.loops + 1)
        # the listener may lag the player on a loaded machine: let it take what was sent
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not any(
                b < a for a, b in zip(clocks, clocks[1:])):
            time.sleep(0.05)
        time.sleep(0.3)
    finally:
        player.stop()
        spin.close()
        player.destroy_node()
        listener.destroy_node()
    assert clocks and min(clocks) == first and max(clocks) <= last
    back = [b < a for a, b in zip(clocks, clocks[1:])]
    assert sum(back) >= 1  # the clock restarted with the loop


def test_bag_player_waits_for_the_clock_subscribers(recording, context):
    """clock_subscribers: the player does not start before /clock has that many matched
    subscribers (a latency listener that missed the first /clock timed the wrong frames)."""
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Image

    from mbtrack_ros.nodes.bag_player import BagPlayer

    player = BagPlayer(cli_args=['--ros-args', '-p', f'bag:={recording}',
                                 '-p', 'wait_for_subscribers:=true',
                                 '-p', 'clock_subscribers:=2', '-p', 'subscriber_timeout:=2.0'],
                       context=context)
    warnings = []
    player.get_logger = lambda: type('L', (), {'warning': lambda self, m: warnings.append(m)})()
    listener = rclpy.create_node('clock_listener', context=context)
    subs = [listener.create_subscription(Image, '/cam0/image_raw', lambda m: None, 10),
            listener.create_subscription(Clock, '/clock', lambda m: None, 10)]
    try:
        player._wait_subscribers()  # one /clock subscriber of two: waits, then says so
        assert len(warnings) == 1 and 'fewer than 2' in warnings[0]
        subs.append(listener.create_subscription(Clock, '/clock', lambda m: None, 10))
        player._wait_subscribers()
        assert len(warnings) == 1  # now both are matched
    finally:
        player.destroy_node()
        listener.destroy_node()


def test_replay_writes_output_bag(recording, tmp_path):
    """`mbtrack replay` writes OUTDIR/tracks.mcap; its people agree with tracks.csv."""
    from rosbags.highlevel import AnyReader

    from mbtrack_ros.cli import main
    from mbtrack_ros.recording.csvfiles import read_tracks

    out = tmp_path / 'replay'
    code = main(['replay', str(recording), '--out', str(out),
                 '--init-from', str(recording / 'ground_truth.csv')])
    assert code == 0
    rows = read_tracks(out / 'tracks.csv')
    with AnyReader([out / 'tracks.mcap']) as reader:
        people = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                  if c.topic == '/tracker_node/people']
    assert len(people) == 30
    from_bag = sorted((stamp_ns(m.header), round(p.position.x, 3), round(p.position.y, 3))
                      for m in people for p in m.poses)
    from_csv = sorted((r.stamp_ns, round(r.x, 3), round(r.y, 3)) for r in rows)
    assert len(from_bag) == len(from_csv) > 0
    np.testing.assert_allclose(np.array(from_bag), np.array(from_csv), atol=2e-3, rtol=0)


def test_large_shm_segment_profile_respects_user_settings(tmp_path, monkeypatch):
    """The Fast DDS profile: installed for Fast DDS only, never over the user's own."""
    import xml.etree.ElementTree as ET

    from mbtrack_ros.nodes.transport import SEGMENT_BYTES, use_large_shm_segment

    monkeypatch.setattr('tempfile.tempdir', str(tmp_path))
    env = {}
    path = use_large_shm_segment(env)
    assert env['FASTRTPS_DEFAULT_PROFILES_FILE'] == str(path) and tmp_path in path.parents
    ns = {'p': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    root = ET.parse(path).getroot()
    sizes = [int(e.text) for e in root.iterfind('.//p:segment_size', ns)]
    assert sizes == [SEGMENT_BYTES] and SEGMENT_BYTES >= 4 * 320 * 240 * 3 * 4
    assert root.find('.//p:useBuiltinTransports', ns).text == 'false'
    for user in ({'FASTRTPS_DEFAULT_PROFILES_FILE': '/mine.xml'},
                 {'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4'},
                 {'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}):
        env = dict(user)
        assert use_large_shm_segment(env) is None and env == user
