"""camera_node + tracker_node in fusion mode over DDS: a camera node killed and restarted."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest

# a domain of our own, before any rclpy context creates a participant
os.environ['ROS_DOMAIN_ID'] = str(30 + os.getpid() % 70)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

from conftest import REPO, spinning  # noqa: E402

KILL, BACK = 12, 18       # frames at which the camera node of DYING dies and comes back
DYING = 'cam1'


@pytest.fixture(scope='module')
def recording(tmp_path_factory) -> Path:
    from mbtrack_ros.synth.generator import generate
    return generate('clear-room-short', tmp_path_factory.mktemp('rec') / 'room', seed=100,
                    width=160, height=120)


def camera_args(calibration: Path, camera: str) -> list[str]:
    return ['--ros-args', '-r', f'__ns:=/{camera}', '-p', f'calibration_file:={calibration}',
            '-p', f'camera:={camera}']


def start_camera_process(calibration: Path, camera: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, '-m', 'mbtrack_ros.nodes.camera_node',
         *camera_args(calibration, camera)],
        cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT)


def wait_for(condition, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.05)
    return False


@pytest.mark.ros
def test_tracker_keeps_tracking_when_a_camera_node_dies_and_picks_it_up_again(
        recording, context):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CompressedImage, Image, PointCloud2

    from mbtrack_ros.nodes.camera_node import CameraNode
    from mbtrack_ros.nodes.conversions import rgb_to_image
    from mbtrack_ros.nodes.messages import make_header
    from mbtrack_ros.nodes.tracker_node import TrackerNode
    from mbtrack_ros.recording.bag import RecordingReader

    calibration = recording / 'calibration.yaml'
    with RecordingReader(recording) as reader:
        frame_sets = list(reader.frames())
    cameras = sorted(frame_sets[0].images)
    tracker = TrackerNode(context=context, cli_args=[
        '--ros-args', '-p', f'calibration_file:={calibration}', '-p', 'input_mode:=foreground',
        '-p', 'tracker.seed:=7', '-p', 'warm_up:=false', '-p', 'diagnostics_period:=0.05',
        '-p', 'image_reliability:=reliable',
        # the in-process camera nodes share one interpreter: a loaded machine may need
        # more than the default to answer (a late answer only costs the tracker CPU)
        '-p', 'score_timeout:=1.0'])
    stages = [CameraNode(context=context, cli_args=camera_args(calibration, c))
              for c in cameras if c != DYING]
    probe = Node('probe', context=context)
    reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    pubs = {c: probe.create_publisher(Image, f'/{c}/image_raw', reliable) for c in cameras}
    tracks: dict[int, int] = {}     # stamp -> number of tracks
    warned: dict[int, bool] = {}    # stamp -> DYING reported missing
    lock = threading.Lock()

    def on_tracks(msg):
        with lock:
            tracks[msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec] = msg.width

    def on_diag(msg):
        main = msg.status[0]
        with lock:
            warned[msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec] = (
                main.level == DiagnosticStatus.WARN and DYING in main.message)

    probe.create_subscription(PointCloud2, '/tracker_node/tracks', on_tracks, reliable)
    done: set[tuple[str, int]] = set()    # (camera, stamp) of the stages' foreground sent

    def on_mask(camera):
        def record(msg):
            with lock:
                done.add((camera, msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec))
        return record
    for c in cameras:
        if c != DYING:
            probe.create_subscription(Image, f'/{c}/working/foreground', on_mask(c),
                                      reliable)
    probe.create_subscription(DiagnosticArray, '/diagnostics', on_diag, reliable)
    spin = ExitStack()
    spin.enter_context(spinning([tracker, probe, *stages], context))
    dying = start_camera_process(calibration, DYING)
    def readers(camera: str) -> set[bytes]:
        """The DDS endpoint ids of the readers of a camera's image topic."""
        return {bytes(info.endpoint_gid)
                for info in probe.get_subscriptions_info_by_topic(f'/{camera}/image_raw')}

    old: set[bytes] = set()
    try:
        assert wait_for(lambda: all(p.get_subscription_count() >= 1 for p in pubs.values()),
                        60.0), 'camera nodes did not come up'
        time.sleep(1.0)
        for k, fs in enumerate(frame_sets):
            if k == KILL:
                # DDS forgets a killed participant only when its lease runs out (Fast DDS:
                # 20 s); the tracker must not need that, so the test does not wait for it
                old = readers(DYING)
                dying.send_signal(signal.SIGKILL)
                dying.wait(timeout=10)
            if k == BACK:
                answered_before = tracker._fusion.scorers[DYING].answered
                dying = start_camera_process(calibration, DYING)
                # the new process's own reader, not the dead one DDS may still list
                assert wait_for(lambda: readers(DYING) - old, 60.0), 'no restarted camera node'
                time.sleep(1.0)
            for c, pub in pubs.items():
                pub.publish(rgb_to_image(fs.images[c],
                                         make_header(fs.stamp_ns, f'{c}_optical_frame')))
            time.sleep(0.25)
            # the in-process stages share one interpreter and lag on a loaded machine: pace
            # the frames by them, so that the separate DYING process does not run ahead of
            # them by more than the synchroniser's timeout (message time)
            wait_for(lambda: all((c, fs.stamp_ns) in done for c in cameras if c != DYING),
                     20.0)
        last = frame_sets[-1].stamp_ns
        wait_for(lambda: last in tracks, 90.0)  # generous: a loaded machine lags
    finally:
        if dying.poll() is None:
            dying.send_signal(signal.SIGINT)
            try:
                dying.wait(timeout=10)
            except subprocess.TimeoutExpired:
                dying.kill()
        spin.close()
        for node in [tracker, probe, *stages]:
            node.destroy_node()
    stamps = [fs.stamp_ns for fs in frame_sets]
    gap = stamps[KILL + 1:BACK]
    with lock:
        # the tracker went on without the camera: tracks on the frames of the gap, WARN
        assert all(s in tracks for s in gap), sorted(set(gap) - set(tracks))
        assert sum(tracks[s] > 0 for s in gap) >= len(gap) // 2
        assert any(warned.get(s) for s in gap)
        # and took it up again: the last frame sets are complete, with its foreground
        assert last in tracks and not warned.get(last, True)
    bank = tracker.tracker.detection.background
    assert bank.models[DYING].ready, 'no foreground from the restarted camera node'
    # the camera nodes scored the particles, the restarted one too (it gets the key views
    # again after answering that it lacks them)
    # (the cameras the filter reads: not the top-down one)
    scorers = {c: s for c, s in tracker._fusion.scorers.items() if s.asked}
    assert len(scorers) >= len(cameras) - 1 and DYING in scorers
    # every camera node answered (how many in time depends on the machine's load: a late
    # answer is scored by the tracker and that camera skipped during its back-off)
    assert all(s.answered >= 1 for s in scorers.values()), \
        {c: s.answered for c, s in scorers.items()}
    assert scorers[DYING].answered > answered_before
    assert np.isfinite(tracker.tracker.last_stamp_ns)


def test_fusion_launch_file_compiles(tmp_path):
    import py_compile
    py_compile.compile(str(REPO / 'launch' / 'fusion.launch.py'),
                       cfile=str(tmp_path / 'launch.pyc'), doraise=True)


@pytest.mark.ros
@pytest.mark.parametrize('args, message', [
    ((), 'parameter calibration_file is required'),
    (('-p', 'camera:=nope'), "parameter camera: 'nope' is not one of"),
    (('-p', 'camera:=cam0', '-p', 'image_format:=gif'), "image_format: 'gif' is not one of"),
])
def test_camera_node_refuses_bad_parameters(args, message, recording, context):
    from mbtrack_ros.nodes.camera_node import CameraNode, CameraParamsError

    if args:
        args = ('-p', f'calibration_file:={recording / "calibration.yaml"}', *args)
    with pytest.raises(CameraParamsError, match=message):
        CameraNode(context=context, worker=False, cli_args=['--ros-args', *args])


@pytest.mark.ros
def test_fusion_mode_parameter_refused_when_unknown(recording, context):
    from mbtrack_ros.nodes.params import ParamsError
    from mbtrack_ros.nodes.tracker_node import TrackerNode

    with pytest.raises(ParamsError, match="input_mode: 'both' is not one of"):
        TrackerNode(context=context, step_thread=False, cli_args=[
            '--ros-args', '-p', f'calibration_file:={recording / "calibration.yaml"}',
            '-p', 'input_mode:=both', '-p', 'warm_up:=false'])


@pytest.mark.ros
@pytest.mark.parametrize('image_format', ['raw', 'jpeg'])
def test_camera_node_offsets_stamps_and_publishes_masks_of_the_stage(recording, context,
                                                                     image_format):
    """time_offset moves the stamps; the published masks are the stage's (raw mono8, or
    PNG next to JPEG images, round trip)."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CompressedImage, Image

    from mbtrack_ros.core.detection.camera_stage import CameraStage, unpack_masks
    from mbtrack_ros.nodes.camera_node import CameraNode
    from mbtrack_ros.nodes.conversions import (
        compressed_to_rgb, image_to_mono, rgb_to_image, stamp_to_ns)
    from mbtrack_ros.nodes.messages import make_header
    from mbtrack_ros.recording.bag import RecordingReader

    node = CameraNode(context=context, worker=False, cli_args=[
        *camera_args(recording / 'calibration.yaml', 'cam0'), '-p', 'time_offset:=-0.25',
        '-p', f'image_format:={image_format}', '-p', 'region_wait:=0.0'])  # as the stage
    probe = Node('probe', context=context)
    got = []
    raw = image_format == 'raw'
    probe.create_subscription(Image if raw else CompressedImage,
                              '/cam0/working/foreground' + ('' if raw else '/compressed'),
                              got.append,
                              QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(probe)
    assert wait_for(lambda: (executor.spin_once(timeout_sec=0.05),
                             node.pub_foreground.get_subscription_count())[1] > 0, 20.0)
    stage = CameraStage(node.camera, node.stage.config)  # the node's background settings
    with RecordingReader(recording) as reader:
        frame_sets = list(reader.frames())[:9]
    expected = []
    for fs in frame_sets:
        node._on_image(rgb_to_image(fs.images['cam0'], make_header(fs.stamp_ns, 'x')))
        node.process_pending()
        expected.append(stage.process(fs.images['cam0']))
    wait_for(lambda: (executor.spin_once(timeout_sec=0.05), len(got))[1] >= len(frame_sets),
             20.0)
    node.destroy_node()
    probe.destroy_node()
    assert [stamp_to_ns(m.header.stamp) for m in got] == \
        [fs.stamp_ns - 250_000_000 for fs in frame_sets]
    assert (got[0].encoding if raw else got[0].format) == 'bootstrap' and not got[0].data
    assert any((m.encoding if raw else m.format) == 'bootstrap started' for m in got)
    shown = [(m, e) for m, e in zip(got, expected) if e.foreground is not None]
    assert shown
    for msg, exp in shown:
        assert (msg.encoding == 'mono8') if raw else msg.format.startswith('mono8; png')
        for a, b in zip(unpack_masks(image_to_mono(msg) if raw else compressed_to_rgb(msg)),
                        (exp.foreground, exp.possible, exp.presence)):
            np.testing.assert_array_equal(a, b)


@pytest.mark.ros
def test_camera_node_sends_frames_without_foreground_until_its_regions_come(recording,
                                                                            context):
    """After the bootstrap the node waits for the tracker's regions without holding a
    frame back: the frames go out at once as a bootstrapping model's (no foreground, the
    model not updated); once the regions came, its masks are those of a stage given the
    same regions at that frame."""
    import cv2
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CompressedImage, Image

    from mbtrack_ros.core.detection.camera_stage import (
        CameraStage, pack_regions, unpack_masks)
    from mbtrack_ros.nodes.camera_node import CameraNode
    from mbtrack_ros.nodes.conversions import image_to_mono, rgb_to_image
    from mbtrack_ros.nodes.messages import make_header
    from mbtrack_ros.recording.bag import RecordingReader

    node = CameraNode(context=context, worker=False, cli_args=[
        *camera_args(recording / 'calibration.yaml', 'cam0'), '-p', 'region_wait:=60.0'])
    probe = Node('probe', context=context)
    got = []
    reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    probe.create_subscription(Image, '/cam0/working/foreground', got.append, reliable)
    regions_pub = probe.create_publisher(CompressedImage, '/cam0/working/regions', reliable)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(probe)
    executor.add_node(node)
    assert wait_for(lambda: (executor.spin_once(timeout_sec=0.05),
                             node.pub_foreground.get_subscription_count() > 0
                             and regions_pub.get_subscription_count() > 0)[1], 20.0)
    stage = CameraStage(node.camera, node.stage.config)
    with RecordingReader(recording) as reader:
        frame_sets = list(reader.frames())[:14]
    region = np.zeros((node.stage.camera.height, node.stage.camera.width), bool)
    region[:, :region.shape[1] // 3] = True
    kinds, started, held = [], None, 0
    for k, fs in enumerate(frame_sets):
        if started is not None and k == started + 4:   # the regions come after 3 frames
            ok, data = cv2.imencode('.png', pack_regions(region, region, region))
            regions_pub.publish(CompressedImage(header=make_header(frame_sets[started]
                                                                   .stamp_ns, 'x'),
                                                format='png', data=data.tobytes()))
            assert wait_for(lambda: (executor.spin_once(timeout_sec=0.05),
                                     node._regions is not None)[1], 20.0)
            stage.set_regions(region, region, region)
        t = time.monotonic()
        node._on_image(rgb_to_image(fs.images['cam0'], make_header(fs.stamp_ns, 'x')))
        node.process_pending()
        assert time.monotonic() - t < 5.0          # not the 60 s of region_wait
        if stage.awaiting_regions:
            expected = stage.hold(fs.images['cam0'])
            held += 1
        else:
            expected = stage.process(fs.images['cam0'])
        if expected.started:
            started = k
        kinds.append(expected)
    assert started is not None and held == 3 and not node.stage.awaiting_regions
    wait_for(lambda: (executor.spin_once(timeout_sec=0.05), len(got))[1] >= len(frame_sets),
             20.0)
    node.destroy_node()
    probe.destroy_node()
    assert len(got) == len(frame_sets)
    for k, (msg, exp) in enumerate(zip(got, kinds)):
        if started < k <= started + 3:               # held: a bootstrapping model's
            assert msg.encoding == 'bootstrap' and not msg.data
        elif k > started + 3:
            assert msg.encoding == 'mono8'
            for a, b in zip(unpack_masks(image_to_mono(msg)),
                            (exp.foreground, exp.possible, exp.presence)):
                np.testing.assert_array_equal(a, b)


def _launch_module(monkeypatch):
    """launch/fusion.launch.py with stand-ins for launch and launch_ros (not on the wheels
    index): actions record their arguments."""
    import importlib.util
    import types

    class Action:
        def __init__(self, *args, **kwargs):
            self.args, self.kwargs = args, kwargs

    fake = {'launch': types.ModuleType('launch'),
            'launch.actions': types.ModuleType('launch.actions'),
            'launch_ros': types.ModuleType('launch_ros'),
            'launch_ros.actions': types.ModuleType('launch_ros.actions')}
    fake['launch'].LaunchDescription = Action
    for name in ('DeclareLaunchArgument', 'GroupAction', 'OpaqueFunction'):
        setattr(fake['launch.actions'], name, type(name, (Action,), {}))
    for name in ('Node', 'PushRosNamespace'):
        setattr(fake['launch_ros.actions'], name, type(name, (Action,), {}))
    for name, module in fake.items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location('fusion_launch',
                                                  REPO / 'launch' / 'fusion.launch.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _nodes(actions, namespace=()):
    """(namespace, executable, parameters) of every Node in the action tree."""
    out = []
    for a in actions:
        kind = type(a).__name__
        if kind == 'GroupAction':
            inner = a.args[0]
            ns = namespace + tuple(x.args[0] for x in inner
                                   if type(x).__name__ == 'PushRosNamespace')
            out += _nodes([x for x in inner if type(x).__name__ != 'PushRosNamespace'], ns)
        elif kind == 'Node':
            params = {}
            for p in a.kwargs['parameters']:
                if isinstance(p, dict):
                    params.update(p)
            out.append(('/'.join(namespace), a.kwargs['executable'], params))
    return out


def test_fusion_launch_starts_each_host_its_group(monkeypatch, tmp_path):
    module = _launch_module(monkeypatch)
    hosts = tmp_path / 'hosts.yaml'
    hosts.write_text('fusion: hostF\nhosts:\n  hostA: [cam0, cam1]\n  hostF: [cam2]\n')

    def run(**given):
        conf = {'calibration_file': 'room.yaml', 'cameras': '', 'hosts_file': str(hosts),
                'host': '', 'room': '', 'params_file': '', 'working_pixels': '19200',
                'image_transport': 'raw', **given}
        context = type('Context', (), {'launch_configurations': conf})()
        return _nodes(module._groups(context))

    a = run(host='hostA')
    assert [(ns, exe, p['camera']) for ns, exe, p in a] == [
        ('cam0', 'camera_node', 'cam0'), ('cam1', 'camera_node', 'cam1')]
    assert all(p['tracker.working_pixels'] == 19200 for _, _, p in a)
    f = run(host='hostF', room='lab')
    assert [(ns, exe) for ns, exe, _ in f] == [('lab/cam2', 'camera_node'),
                                               ('lab', 'tracker_node')]
    tracker = f[1][2]
    assert tracker['input_mode'] == 'foreground' and tracker['cameras'] == [
        'cam0', 'cam1', 'cam2']
    assert tracker['camera.cam1.image_topic'] == '/lab/cam1/working/image'
    assert tracker['camera.cam1.foreground_topic'] == '/lab/cam1/working/foreground'
    assert f[0][2]['tracks_topic'] == '/lab/tracker_node/tracks'
    one = run(hosts_file='', cameras='cam0,cam1')
    assert [exe for _, exe, _ in one] == ['camera_node', 'camera_node', 'tracker_node']


def test_cloud_columns_read_the_tracks_cloud():
    """The camera node reads ~/tracks by the cloud's own field offsets."""
    pytest.importorskip('rclpy')
    from mbtrack_ros.core.state import FrameResult, TrackEstimate
    from mbtrack_ros.nodes.camera_node import cloud_columns
    from mbtrack_ros.nodes.messages import tracks_cloud

    tracks = [TrackEstimate(track_id=i, mean=np.array([1.0 + i, 2.0 - i, 0.3 * i, -0.1, 0, 0]),
                            covariance=np.eye(4), height=1.6 + 0.1 * i,
                            visible_fraction={'cam0': 0.5}) for i in (1, 2, 3)]
    cloud = tracks_cloud(FrameResult(stamp_ns=5, tracks=tracks), ['cam0', 'cam1'], 'room')
    got = cloud_columns(cloud, ('x', 'y', 'vx', 'vy', 'height', 'id', 'nope'))
    np.testing.assert_allclose(got['x'], [2, 3, 4], rtol=1e-6)
    np.testing.assert_allclose(got['y'], [1, 0, -1], rtol=1e-6)
    np.testing.assert_allclose(got['vx'], [0.3, 0.6, 0.9], rtol=1e-6)
    np.testing.assert_allclose(got['height'], [1.7, 1.8, 1.9], rtol=1e-6)
    assert got['id'].tolist() == [1, 2, 3] and np.isnan(got['nope']).all()
