"""End to end over DDS: a consumer written only against REP-155 follows the people of a
short recording with the ids and positions the tracker reports on ``~/tracks``.

bag_player and tracker_node run as their own processes; the consumer reads
``/humans/persons/tracked``, subscribes to each listed person's ``location_confidence`` and
``anonymous`` and reads the ``person_<id>`` frames of ``/tf`` (the REP-155 person frame),
nothing else. A reference subscriber in the test reads ``~/tracks`` to compare.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

# a domain of our own, before any rclpy import creates a participant
os.environ['ROS_DOMAIN_ID'] = str(100 + (os.getpid() + 37) % 100)

pytest.importorskip('rclpy')
for _package in ('hri_msgs', 'tf2_msgs'):
    pytest.importorskip(f'{_package}.msg', reason=f'{_package} not built here (the bootstrap '
                        'builds it; cmake or a compiler missing)')

import rclpy  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import (  # noqa: E402
    DurabilityPolicy, QoSProfile, ReliabilityPolicy)

from conftest import REPO, playing  # noqa: E402

pytestmark = pytest.mark.ros

LAST_FRAME_OF_PERSON_2 = 34  # the trimmed ground truth ends person 2's track after it
# the tracker sees the room through this camera alone: in it one person is hidden behind
# the other for a few frame sets (frames 26-29 of clear-room-short, seed 0)
CAMERA = 'cam0'


class Rep155Consumer(Node):
    """Knows REP-155 only: the tracked list, per-person subtopics, person frames on /tf."""

    def __init__(self, context) -> None:
        from hri_msgs.msg import IdsList
        from tf2_msgs.msg import TFMessage
        super().__init__('rep155_consumer', context=context)
        self.lock = threading.Lock()
        self.tracked: list[tuple[int, list[str]]] = []  # (stamp ns, ids) in arrival order
        self.confidence: dict[str, list[float]] = {}
        self.anonymous: dict[str, bool] = {}
        self.frames: dict[tuple[int, str], tuple[float, float]] = {}  # (stamp, id) -> x, y
        self._subs = {}
        self.qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(IdsList, '/humans/persons/tracked', self.on_tracked, self.qos)
        self.create_subscription(TFMessage, '/tf', self.on_tf, self.qos)

    def on_tracked(self, msg) -> None:
        from std_msgs.msg import Bool, Float32
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self.lock:
            self.tracked.append((stamp, list(msg.ids)))
        for pid in msg.ids:
            if pid in self._subs:
                continue
            self.confidence.setdefault(pid, [])
            base = f'/humans/persons/{pid}'
            # the publisher's latched value on subscribing, then a queue that drops nothing
            latched = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self._subs[pid] = (
                self.create_subscription(Float32, f'{base}/location_confidence',
                                         lambda m, p=pid: self.on_confidence(p, m), latched),
                self.create_subscription(
                    Bool, f'{base}/anonymous', lambda m, p=pid: self.on_anonymous(p, m),
                    latched))

    def on_confidence(self, pid: str, msg) -> None:
        with self.lock:
            self.confidence[pid].append(float(msg.data))

    def on_anonymous(self, pid: str, msg) -> None:
        with self.lock:
            self.anonymous[pid] = bool(msg.data)

    def on_tf(self, msg) -> None:
        with self.lock:
            for t in msg.transforms:
                if t.child_frame_id.startswith('person_'):
                    stamp = t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec
                    self.frames[(stamp, t.child_frame_id[len('person_'):])] = (
                        t.transform.translation.x, t.transform.translation.y)


class TracksReference(Node):
    """The tracker's own ``~/tracks`` cloud (to compare with, not used by the consumer)."""

    def __init__(self, context, cameras: list[str]) -> None:
        from sensor_msgs.msg import PointCloud2
        super().__init__('tracks_reference', context=context)
        from mbtrack_ros.nodes.messages import tracks_dtype
        self.dtype = tracks_dtype(cameras)
        self.cameras = cameras
        self.lock = threading.Lock()
        self.clouds: list[tuple[int, np.ndarray]] = []
        self.create_subscription(PointCloud2, '/tracker_node/tracks', self.on_cloud,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))

    def on_cloud(self, msg) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        points = np.frombuffer(bytes(msg.data), dtype=self.dtype).copy()
        with self.lock:
            self.clouds.append((stamp, points))


@pytest.fixture(scope='module')
def recording(tmp_path_factory) -> Path:
    from mbtrack_ros.synth.generator import generate
    return generate('clear-room-short', tmp_path_factory.mktemp('rec') / 'crs', seed=0)


def expected_confidence(point, cameras: list[str]) -> float:
    """REP-155 location_confidence from a ``~/tracks`` point (people_outputs' rule)."""
    from mbtrack_ros.nodes.messages import field_name
    from mbtrack_ros.nodes.people_outputs import HIDDEN_CONFIDENCE_CAP
    hidden = np.prod([1.0 - float(point[field_name(c)]) for c in cameras])
    if 1.0 - hidden >= 0.5:
        return 1.0
    return min(max(float(point['existence']), 1e-3), HIDDEN_CONFIDENCE_CAP)


def test_rep155_consumer_follows_the_tracks(recording, tmp_path):
    from rclpy.context import Context
    from rosbags.highlevel import AnyReader

    from mbtrack_ros.recording.csvfiles import read_ground_truth

    # person 2 leaves the ground truth after frame 24: its track ends there
    lines = (recording / 'ground_truth.csv').read_text().splitlines()
    kept = [lines[0]] + [line for line in lines[1:] if not (
        line.split(',')[2] == '2' and int(line.split(',')[1]) > LAST_FRAME_OF_PERSON_2)]
    truth = tmp_path / 'ground_truth.csv'
    truth.write_text('\n'.join(kept) + '\n')
    rows = read_ground_truth(truth)
    assert {r.person_id for r in rows} >= {1, 2}
    last_stamp = max(r.stamp_ns for r in read_ground_truth(recording / 'ground_truth.csv'))

    context = Context()
    rclpy.init(context=context)
    log = open(tmp_path / 'tracker.log', 'w')
    tracker = subprocess.Popen(
        [sys.executable, '-m', 'mbtrack_ros.nodes.tracker_node', '--ros-args',
         '-p', f'calibration_file:={recording / "calibration.yaml"}',
         '-p', f'init_ground_truth:={truth}', '-p', 'tracker.seed:=0',
         '-p', 'image_reliability:=reliable', '-p', 'qos_depth:=100',
         '-p', 'max_pending_sets:=100', '-p', 'warm_up:=true',
         '-p', f'cameras:=[{CAMERA}]', '-p', f'output_bag:={tmp_path / "out"}'],
        cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), stdout=log,
        stderr=subprocess.STDOUT)
    try:
        cameras = [CAMERA]
        consumer = Rep155Consumer(context)
        reference = TracksReference(context, cameras)
        # warm_up before subscribing: the player starts once the tracker keeps pace, so the
        # per-person publishers appear while the recording plays (a backlog processed in a
        # burst would leave the consumer's subscriptions no time to match before frame 26)
        # and only once the tracker's outputs are discovered: what it publishes before its
        # subscribers match is lost (volatile durability)
        def matched() -> bool:
            return (consumer.count_publishers('/humans/persons/tracked') > 0
                    and consumer.count_publishers('/tf') > 0
                    and reference.count_publishers('/tracker_node/tracks') > 0)

        with playing(recording, [consumer, reference], context, rate=0.5,
                     timeout=240, topics=[f'/{CAMERA}/image_raw'], ready=matched):
            deadline = time.monotonic() + 180
            while time.monotonic() < deadline:
                with consumer.lock:
                    if consumer.tracked and consumer.tracked[-1][0] == last_stamp:
                        break
                time.sleep(0.2)
            time.sleep(1.0)  # the last per-person messages of that frame set
    finally:
        tracker.send_signal(signal.SIGINT)
        try:
            tracker.wait(timeout=60)
        except subprocess.TimeoutExpired:
            tracker.kill()
        log.close()
        rclpy.try_shutdown(context=context)
    output = (tmp_path / 'tracker.log').read_text()
    assert 'Traceback' not in output and 'dropped' not in output, output

    clouds = dict(reference.clouds)
    tracked = dict(consumer.tracked)
    assert len(tracked) >= 40, f'{len(tracked)} tracked lists for 45 frames\n{output}'
    # the same people, frame by frame, under their REP-155 ids
    common = sorted(set(tracked) & set(clouds))
    assert len(common) >= 40
    for stamp in common:
        ids = [f'mbtrack_{int(i)}' for i in clouds[stamp]['id']]
        assert tracked[stamp] == ids, stamp
    # where they are: the person frames at the positions of ~/tracks
    positions = 0
    for stamp in common:
        for p in clouds[stamp]:
            x, y = consumer.frames[(stamp, f'mbtrack_{int(p["id"])}')]
            assert abs(x - float(p['x'])) < 1e-4 and abs(y - float(p['y'])) < 1e-4
            positions += 1
    assert positions >= 60  # two people for most of the recording
    # location_confidence: what the tracks' visibility and existence say, in order; a
    # person seen now has 1, one hidden now a value between 0 and 1
    listed = {}
    for _, ids in consumer.tracked:
        for pid in ids:
            listed[pid] = listed.get(pid, 0) + 1
    # a REP-155 consumer subscribes once it sees the id; location_confidence is latched, so
    # it gets the value current then and every later one
    persons = sorted(pid for pid, n in listed.items() if n >= 5)
    assert len(persons) >= 2, listed
    ended = []
    hidden = 0  # values of persons not seen now
    for pid in persons:
        got = consumer.confidence[pid]
        assert got and all(0.0 <= v <= 1.0 for v in got), (pid, got)
        expected = [expected_confidence(p, cameras) for stamp in sorted(clouds)
                    for p in clouds[stamp] if f'mbtrack_{int(p["id"])}' == pid]
        shown = got[:-1] if got[-1] == 0.0 else got
        assert 1.0 in shown, (pid, got)
        # the consumer subscribed once it saw the id: its values end the expected ones
        np.testing.assert_allclose(shown, expected[len(expected) - len(shown):], atol=1e-6)
        assert all(v == 1.0 or 0.0 < v < 1.0 for v in shown)
        hidden += sum(0.0 < v < 1.0 for v in shown)
        assert consumer.anonymous.get(pid) is True
        if got[-1] == 0.0:
            ended.append(pid)
    assert hidden >= 2, consumer.confidence  # hidden behind the other person in CAMERA
    # the track of person 2 ended: its id left the tracked list after a last 0
    assert ended, consumer.confidence
    for pid in ended:
        last_in = max(s for s, ids in consumer.tracked if pid in ids)
        assert all(pid not in ids for s, ids in consumer.tracked if s > last_in)
        assert last_in < last_stamp
    # the node's output bag holds the same standard outputs
    with AnyReader([tmp_path / 'out']) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
    assert types['/humans/persons/tracked'] == 'hri_msgs/msg/IdsList'
    assert types['/tf'] == 'tf2_msgs/msg/TFMessage'
    print(f'rep155: {len(tracked)} tracked lists, {positions} person frames, persons '
          f'{persons}, ended {ended}, {hidden} hidden values')


def test_replay_output_bag_holds_the_standard_outputs(recording, tmp_path):
    """`mbtrack replay`'s tracks.mcap: the REP-155, vision_msgs and /tf messages, readable
    by rosbags and by the mcap reader, with the released type names and hashes."""
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    from mbtrack_ros.cli import main
    from test_interfaces import RELEASED

    out = tmp_path / 'replay'
    assert main(['replay', str(recording), '--out', str(out), '--init-from',
                 str(recording / 'ground_truth.csv')]) == 0
    wanted = {'/humans/persons/tracked': 'hri_msgs/msg/IdsList',
              '/tracker_node/detections': 'vision_msgs/msg/Detection3DArray',
              '/tf': 'tf2_msgs/msg/TFMessage'}
    counts: dict[str, int] = {}
    with AnyReader([out / 'tracks.mcap']) as reader:
        for conn in reader.connections:
            if conn.topic in wanted:
                assert (conn.msgtype, conn.digest) == (wanted[conn.topic],
                                                       RELEASED[wanted[conn.topic]])
        people = {}
        for conn, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            if conn.topic == '/tracker_node/people':
                people[stamp] = len(msg.poses)
            elif conn.topic == '/tracker_node/detections':
                assert len(msg.detections) == people[stamp]
    assert counts['/humans/persons/tracked'] == counts['/tracker_node/detections'] == 45
    assert counts['/tf'] >= 30  # frame sets with tracks
    (path,) = (out / 'tracks.mcap').glob('*.mcap')
    mcap_counts: dict[str, int] = {}
    with open(path, 'rb') as stream:
        for schema, channel, _message in make_reader(stream).iter_messages():
            if channel.topic in wanted:
                assert schema.name == wanted[channel.topic] and schema.encoding == 'ros2msg'
                mcap_counts[channel.topic] = mcap_counts.get(channel.topic, 0) + 1
    assert mcap_counts == {t: counts[t] for t in wanted}


def _published(node, among: set[str], expected: set[str], timeout: float = 10.0) -> set[str]:
    """The topics of ``among`` that ``node`` publishes, as the ROS graph tells, once they
    are ``expected`` or after ``timeout`` seconds: the graph learns a new node's publishers,
    and forgets those of a destroyed node of the same name, a moment later."""
    deadline = time.monotonic() + timeout
    while True:
        names = among & {name for name, _ in node.get_publisher_names_and_types_by_node(
            node.get_name(), node.get_namespace())}
        if names == expected or time.monotonic() > deadline:
            return names
        time.sleep(0.05)


def test_outputs_switch_by_parameter_and_without_their_packages(recording, monkeypatch):
    """outputs.* turn each output off; a missing message package turns its output off
    (one warning) and the node still publishes the rest."""
    from rclpy.context import Context

    from mbtrack_ros.core.state import FrameResult, TrackEstimate
    from mbtrack_ros.nodes import people_outputs
    from mbtrack_ros.nodes.tracker_node import TrackerNode
    from mbtrack_ros.recording.sync import FrameSet

    standard = {'/humans/persons/tracked', '/tracker_node/detections', '/tf'}
    context = Context()
    rclpy.init(context=context)
    try:
        args = ['--ros-args', '-p', f'calibration_file:={recording / "calibration.yaml"}',
                '-p', 'warm_up:=false', '-p', 'detection.enabled:=false']
        node = TrackerNode(cli_args=args, context=context, step_thread=False)
        assert _published(node, standard, standard) == standard
        node.destroy_node()
        node = TrackerNode(cli_args=args + ['-p', 'outputs.persons:=false', '-p',
                                            'outputs.tf:=false'],
                           context=context, step_thread=False)
        assert _published(node, standard, {'/tracker_node/detections'}) == {
            '/tracker_node/detections'}
        node.destroy_node()
        monkeypatch.setattr(people_outputs, 'message_types',
                            lambda: {'persons': False, 'detections': True, 'tf': False})
        node = TrackerNode(cli_args=args, context=context, step_thread=False)
        assert node.people_outputs.builder.missing == ['persons', 'tf']
        assert _published(node, standard, {'/tracker_node/detections'}) == {
            '/tracker_node/detections'}
        track = TrackEstimate(1, np.array([2.0, 2.0, 0, 0, 0, 0]), np.eye(4), 1.7,
                              visibility={'cam0': 1.0})
        frame = node.people_outputs.publish(FrameResult(1, [track]))
        assert frame.tracked is None and frame.tf is None
        assert [d.id for d in frame.detections.detections] == ['1']
        node.publish(FrameResult(2, [track]), FrameSet(0, 2, {}, {}, ()))  # the rest goes out
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
