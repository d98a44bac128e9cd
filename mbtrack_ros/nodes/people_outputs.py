"""The standard people outputs: REP-155 persons, vision_msgs detections and /tf frames.

Components written against the field's conventions read these instead of the ``~/tracks``
cloud of our own layout:

* **REP-155 (ROS4HRI) persons** (``hri_msgs``): ``/humans/persons/tracked``
  (``hri_msgs/IdsList``: the ids of the reported tracks); per person
  ``/humans/persons/<id>/location_confidence`` (``std_msgs/Float32``, see
  :func:`location_confidence`) and ``/humans/persons/<id>/anonymous`` (``std_msgs/Bool``,
  transient local, ``true``: the tracker does not identify people, so every person is an
  *anonymous person* of REP-155 whose id lives as long as its track); person id
  ``mbtrack_<track id>`` (:func:`person_id`). When a track is no longer reported its id
  leaves the tracked list and its ``location_confidence`` is 0 once.
* ``~/detections`` (``vision_msgs/Detection3DArray``): per track the box of the person
  model (centre at half the body height, size width x width x height, turned by the
  heading), ``id`` = the track id, one result of class ``person`` with the existence
  probability as score and the posterior position covariance.
* ``/tf`` (``tf2_msgs/TFMessage``): per reported track a frame ``person_<id>`` under the
  output frame at the head (REP-155 places the person frame at the head), turned by the
  heading.

The message packages are optional (``mbtrack_ros.interfaces_build`` builds them into the
virtual environment; a ROS 2 installation has them): :func:`message_types` says which are
importable, and an output whose package is missing is off.
"""
from __future__ import annotations

import importlib
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

from mbtrack_ros.core.state import SIT, X, Y, FrameResult, TrackEstimate
from mbtrack_ros.nodes.messages import make_header, yaw_to_quaternion

__all__ = ['HEAD_HEIGHT_SHARE', 'HIDDEN_CONFIDENCE_CAP', 'OUTPUT_PACKAGES', 'PERSON_PREFIX',
           'PeopleFrame', 'PeopleFrameBuilder', 'PeopleOutputs', 'body_height',
           'detections_message', 'location_confidence', 'message_definitions',
           'message_types', 'person_id', 'persons_message', 'seen_probability',
           'tf_message']

PERSON_PREFIX = 'mbtrack_'
#: location confidence of a person not seen now is its existence probability, at most this
#: (REP-155: below 1 when not seen)
HIDDEN_CONFIDENCE_CAP = 0.99
#: eye height / stature of adults (anthropometric tables: ~0.93): the person frame's height
HEAD_HEIGHT_SHARE = 0.93
#: output -> (message package, the message types of it the output needs)
OUTPUT_PACKAGES = {
    'persons': ('hri_msgs', ('hri_msgs/msg/IdsList',)),
    'detections': ('vision_msgs', (
        'vision_msgs/msg/ObjectHypothesis', 'vision_msgs/msg/ObjectHypothesisWithPose',
        'vision_msgs/msg/BoundingBox3D', 'vision_msgs/msg/Detection3D',
        'vision_msgs/msg/Detection3DArray')),
    'tf': ('tf2_msgs', ('tf2_msgs/msg/TFMessage',)),
}
_INTERFACES = Path(__file__).resolve().parents[2] / 'interfaces'


def message_types() -> dict[str, bool]:
    """Output -> whether its message package imports (``persons``, ``detections``, ``tf``)."""
    out = {}
    for output, (package, _) in OUTPUT_PACKAGES.items():
        try:
            importlib.import_module(package + '.msg')
        except ImportError:
            out[output] = False
        else:
            out[output] = True
    return out


def message_definitions(output: str) -> dict[str, str]:
    """Message type -> its ``.msg`` definition text for an output's types: from the
    installed package (``share/<package>/msg``, a ROS 2 installation or the bootstrap's
    build), else from the repository's ``interfaces/``. Raises OSError when neither has it.
    """
    package, types = OUTPUT_PACKAGES[output]
    shares = [Path(sys.prefix) / 'share' / package, _INTERFACES / package]
    try:
        from ament_index_python.packages import get_package_share_directory
        shares.insert(0, Path(get_package_share_directory(package)))
    except (ImportError, LookupError, OSError, ValueError):  # not in the ament index
        pass
    out = {}
    for name in types:
        filename = name.rsplit('/', 1)[1] + '.msg'
        path = next((p / 'msg' / filename for p in shares if (p / 'msg' / filename).is_file()),
                    shares[-1] / 'msg' / filename)
        out[name] = path.read_text()
    return out


def person_id(track_id: int) -> str:
    """The REP-155 person id of a track: ``mbtrack_<track id>`` (starts with a letter, as
    REP-155 recommends)."""
    return f'{PERSON_PREFIX}{int(track_id)}'


def seen_probability(track: TrackEstimate) -> float:
    """Probability that at least one camera sees the person now, ``1 - prod_c (1 - v_c)``
    with ``v_c`` the posterior visibility in camera c (001 Eq. 16), or the expected visible
    fraction of the silhouette (000 Eq. 34) when the tracker runs no visibility process;
    cameras taken as independent."""
    cams = track.visibility or track.visible_fraction
    hidden = 1.0
    for value in cams.values():
        hidden *= 1.0 - min(max(float(value), 0.0), 1.0)
    return 1.0 - hidden


def location_confidence(track: TrackEstimate) -> float:
    """REP-155 ``location_confidence`` of a reported track: 1 when it is seen now
    (:func:`seen_probability` at least 1/2), else its existence probability (001), at most
    ``HIDDEN_CONFIDENCE_CAP`` and above 0 (a hidden person whose place is known). A person
    whose track is no longer reported gets 0 (:class:`PeopleFrameBuilder`)."""
    if seen_probability(track) >= 0.5:
        return 1.0
    existence = float(track.existence)
    if not math.isfinite(existence):
        existence = 0.5
    return min(max(existence, 1e-3), HIDDEN_CONFIDENCE_CAP)


def body_height(track: TrackEstimate) -> float:
    """Height of the person model now, metres: the body height, 30 % lower when sitting
    (as the ``~/markers`` cylinder)."""
    sit = min(max(float(track.mean[SIT]), 0.0), 1.0)
    return max(float(track.height) * (1.0 - 0.3 * sit), 1e-3)


def persons_message(result: FrameResult, frame_id: str):
    """``/humans/persons/tracked``: ``hri_msgs/IdsList`` of the reported tracks' ids."""
    from hri_msgs.msg import IdsList
    return IdsList(header=make_header(result.stamp_ns, frame_id),
                   ids=[person_id(t.track_id) for t in result.tracks])


def _pose(track: TrackEstimate, z: float):
    from geometry_msgs.msg import Point, Pose, Quaternion
    qx, qy, qz, qw = yaw_to_quaternion(track.heading())
    return Pose(position=Point(x=float(track.mean[X]), y=float(track.mean[Y]), z=float(z)),
                orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def detections_message(result: FrameResult, frame_id: str):
    """``~/detections``: ``vision_msgs/Detection3DArray``, one detection per reported track
    (box of the person model, id = track id, class ``person`` scored by existence)."""
    from geometry_msgs.msg import PoseWithCovariance, Vector3
    from vision_msgs.msg import (
        BoundingBox3D, Detection3D, Detection3DArray, ObjectHypothesis,
        ObjectHypothesisWithPose)
    header = make_header(result.stamp_ns, frame_id)
    detections = []
    for t in result.tracks:
        height = body_height(t)
        width = float(t.width) if math.isfinite(t.width) and t.width > 0 else 0.5
        center = _pose(t, 0.5 * height)
        covariance = [0.0] * 36  # x, y, z, rot x, rot y, rot z; row major
        cov = t.covariance
        covariance[0], covariance[1] = float(cov[0][0]), float(cov[0][1])
        covariance[6], covariance[7] = float(cov[1][0]), float(cov[1][1])
        hypothesis = ObjectHypothesisWithPose(
            hypothesis=ObjectHypothesis(class_id='person', score=float(t.existence)),
            pose=PoseWithCovariance(pose=center, covariance=covariance))
        detections.append(Detection3D(
            header=header, results=[hypothesis], id=str(t.track_id),
            bbox=BoundingBox3D(center=center, size=Vector3(x=width, y=width, z=height))))
    return Detection3DArray(header=header, detections=detections)


def tf_message(result: FrameResult, frame_id: str):
    """``/tf``: ``tf2_msgs/TFMessage`` with a frame ``person_<person id>`` per reported
    track under ``frame_id``, at the head (``HEAD_HEIGHT_SHARE`` of the body height),
    x axis along the heading."""
    from geometry_msgs.msg import Quaternion, Transform, TransformStamped, Vector3
    from tf2_msgs.msg import TFMessage
    transforms = []
    for t in result.tracks:
        qx, qy, qz, qw = yaw_to_quaternion(t.heading())
        transforms.append(TransformStamped(
            header=make_header(result.stamp_ns, frame_id),
            child_frame_id='person_' + person_id(t.track_id),
            transform=Transform(
                translation=Vector3(x=float(t.mean[X]), y=float(t.mean[Y]),
                                    z=HEAD_HEIGHT_SHARE * body_height(t)),
                rotation=Quaternion(x=qx, y=qy, z=qz, w=qw))))
    return TFMessage(transforms=transforms)


@dataclass
class PeopleFrame:
    """The standard people outputs of one frame set (messages None when off).

    Attributes:
        stamp_ns: the frame set's stamp, integer ns.
        tracked: ``hri_msgs/IdsList`` for ``/humans/persons/tracked``.
        confidence: person id -> ``location_confidence`` in [0, 1] (0 for a person whose
            track stopped being reported at this frame set).
        appeared: person ids published for the first time (their ``anonymous`` is due).
        detections: ``vision_msgs/Detection3DArray``.
        tf: ``tf2_msgs/TFMessage``.
    """

    stamp_ns: int
    tracked: object | None = None
    confidence: dict[str, float] = field(default_factory=dict)
    appeared: list[str] = field(default_factory=list)
    detections: object | None = None
    tf: object | None = None


class PeopleFrameBuilder:
    """Builds :class:`PeopleFrame` s frame by frame, remembering which persons were out.

    Args:
        frame_id: output frame.
        persons, detections, tf: the outputs wanted; each one whose message package does
            not import is off (``enabled`` says what is on, ``missing`` what was wanted
            but is not installed).
    """

    def __init__(self, frame_id: str, *, persons: bool = True, detections: bool = True,
                 tf: bool = True) -> None:
        self.frame_id = frame_id
        wanted = {'persons': persons, 'detections': detections, 'tf': tf}
        have = message_types()
        self.enabled = {k: v and have[k] for k, v in wanted.items()}
        self.missing = [k for k, v in wanted.items() if v and not have[k]]
        self._out: set[str] = set()  # person ids published and not yet given 0

    def build(self, result: FrameResult) -> PeopleFrame:
        frame = PeopleFrame(result.stamp_ns)
        if self.enabled['persons']:
            frame.tracked = persons_message(result, self.frame_id)
            now = {person_id(t.track_id): location_confidence(t) for t in result.tracks}
            frame.appeared = [p for p in now if p not in self._out]
            frame.confidence = dict(now)
            for gone in sorted(self._out - set(now)):
                frame.confidence[gone] = 0.0  # REP-155: location unknown
            self._out = set(now)
        if self.enabled['detections']:
            frame.detections = detections_message(result, self.frame_id)
        if self.enabled['tf']:
            frame.tf = tf_message(result, self.frame_id)
        return frame


class PeopleOutputs:
    """Publishes :class:`PeopleFrame` s of a node: ``/humans/persons/...`` (REP-155),
    ``~/detections`` and ``/tf``.

    Per-person publishers are made when a person appears and destroyed one frame set after
    its ``location_confidence`` 0 was sent, so their number stays that of the tracks.

    Args:
        node: the publishing node.
        builder: what to publish (its ``enabled`` outputs).
        qos: QoS of ``/humans/persons/tracked`` and ``~/detections`` (``/tf`` uses tf2's:
            reliable, depth 100; a person's ``location_confidence`` and ``anonymous`` are
            latched, transient local with depth 1, so that a consumer that subscribes when
            it first sees the id gets the current value at once).
    """

    def __init__(self, node, builder: PeopleFrameBuilder, qos) -> None:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        self.node = node
        self.builder = builder
        self.qos = qos
        self._latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                   durability=DurabilityPolicy.TRANSIENT_LOCAL)
        on = builder.enabled
        self.pub_tracked = self.pub_detections = self.pub_tf = None
        if on['persons']:
            from hri_msgs.msg import IdsList
            self.pub_tracked = node.create_publisher(IdsList, '/humans/persons/tracked', qos)
        if on['detections']:
            from vision_msgs.msg import Detection3DArray
            self.pub_detections = node.create_publisher(Detection3DArray, '~/detections', qos)
        if on['tf']:
            from tf2_msgs.msg import TFMessage
            self.pub_tf = node.create_publisher(
                TFMessage, '/tf', QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        self._person_pubs: dict[str, tuple] = {}  # person id -> (confidence, anonymous)
        self._closing: list[str] = []  # persons given 0 at the previous frame set

    def publish(self, result: FrameResult) -> PeopleFrame:
        """Build and publish this frame set's people outputs; returns them (for a bag)."""
        from std_msgs.msg import Bool, Float32
        frame = self.builder.build(result)
        for pid in self._closing:
            if frame.confidence.get(pid, 0.0) == 0.0 and pid in self._person_pubs:
                for pub in self._person_pubs.pop(pid):
                    self.node.destroy_publisher(pub)
        self._closing = []
        for pid in frame.appeared:
            if pid not in self._person_pubs:
                base = f'/humans/persons/{pid}'
                self._person_pubs[pid] = (
                    self.node.create_publisher(Float32, f'{base}/location_confidence',
                                               self._latched),
                    self.node.create_publisher(Bool, f'{base}/anonymous', self._latched))
            self._person_pubs[pid][1].publish(Bool(data=True))
        if frame.tracked is not None:
            self.pub_tracked.publish(frame.tracked)
        for pid, value in frame.confidence.items():
            if pid in self._person_pubs:
                self._person_pubs[pid][0].publish(Float32(data=float(value)))
            if value == 0.0:
                self._closing.append(pid)
        if frame.detections is not None:
            self.pub_detections.publish(frame.detections)
        if frame.tf is not None and frame.tf.transforms:
            self.pub_tf.publish(frame.tf)
        return frame
