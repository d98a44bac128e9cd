"""Standard people outputs (REP-155 persons, vision_msgs detections, /tf): the messages
built from a frame result, and the output bag that holds them."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mbtrack_ros.core.state import FrameResult, TrackEstimate

for _package in ('hri_msgs', 'vision_msgs', 'tf2_msgs'):
    pytest.importorskip(f'{_package}.msg', reason=f'{_package} not built here (the bootstrap '
                        'builds it; cmake or a compiler missing)')

from mbtrack_ros.nodes import people_outputs as po  # noqa: E402

STAMP = 1_700_000_000_250_000_000


def track(track_id: int, x: float, y: float, *, visibility: dict[str, float],
          existence: float = 0.9, sitting: float = 0.0, height: float = 1.8,
          width: float = 0.45, velocity=(0.0, 0.0)) -> TrackEstimate:
    mean = np.array([x, y, velocity[0], velocity[1], 0.3, sitting])  # X, Y, VX, VY, THETA, SIT
    cov = np.array([[0.04, 0.01, 0, 0], [0.01, 0.09, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    return TrackEstimate(track_id, mean, cov, height, visibility=dict(visibility),
                         existence=existence, width=width)


def test_location_confidence_seen_hidden_and_cap():
    seen = track(1, 1, 1, visibility={'a': 0.3, 'b': 0.3})  # 1 - 0.7^2 = 0.51 >= 1/2
    assert po.seen_probability(seen) == pytest.approx(0.51)
    assert po.location_confidence(seen) == 1.0
    hidden = track(2, 1, 1, visibility={'a': 0.2, 'b': 0.3}, existence=0.7)  # 0.44
    assert po.location_confidence(hidden) == pytest.approx(0.7)
    sure = track(3, 1, 1, visibility={'a': 0.0}, existence=1.0)
    assert 0.0 < po.location_confidence(sure) == po.HIDDEN_CONFIDENCE_CAP < 1.0
    # no visibility process: the expected visible fractions stand in
    fractions = TrackEstimate(4, np.zeros(6), np.eye(4), 1.7,
                              visible_fraction={'a': 0.8}, existence=0.9)
    assert po.location_confidence(fractions) == 1.0


def test_persons_appear_stay_and_leave_with_zero_confidence():
    builder = po.PeopleFrameBuilder('room', detections=False, tf=False)
    a = track(3, 1.0, 2.0, visibility={'c': 0.9})
    b = track(5, 3.0, 1.0, visibility={'c': 0.01}, existence=0.6)
    f1 = builder.build(FrameResult(STAMP, [a, b]))
    assert list(f1.tracked.ids) == ['mbtrack_3', 'mbtrack_5']
    assert f1.appeared == ['mbtrack_3', 'mbtrack_5']
    assert f1.confidence == {'mbtrack_3': 1.0, 'mbtrack_5': pytest.approx(0.6)}
    assert f1.detections is None and f1.tf is None
    f2 = builder.build(FrameResult(STAMP + 1, [a]))
    assert list(f2.tracked.ids) == ['mbtrack_3'] and f2.appeared == []
    assert f2.confidence == {'mbtrack_3': 1.0, 'mbtrack_5': 0.0}  # 0 once: lost
    f3 = builder.build(FrameResult(STAMP + 2, [a]))
    assert f3.confidence == {'mbtrack_3': 1.0}
    f4 = builder.build(FrameResult(STAMP + 3, [a, b]))  # its id back (a re-found track)
    assert f4.appeared == ['mbtrack_5']


def test_detection_box_is_the_person_model():
    walking = track(7, 2.0, 3.0, visibility={'c': 1.0}, velocity=(0.0, 1.0), width=0.4)
    sitting = track(8, 4.0, 1.0, visibility={'c': 1.0}, sitting=1.0, height=1.7)
    msg = po.detections_message(FrameResult(STAMP, [walking, sitting]), 'room')
    assert msg.header.frame_id == 'room'
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_000_000, 250_000_000)
    d, s = msg.detections
    assert d.id == '7' and s.id == '8'
    c = d.bbox.center
    assert (c.position.x, c.position.y, c.position.z) == pytest.approx((2.0, 3.0, 0.9))
    assert (d.bbox.size.x, d.bbox.size.y, d.bbox.size.z) == pytest.approx((0.4, 0.4, 1.8))
    yaw = 2 * math.atan2(c.orientation.z, c.orientation.w)
    assert yaw == pytest.approx(math.pi / 2)  # facing its walking direction (+y)
    assert s.bbox.size.z == pytest.approx(1.7 * 0.7) and s.bbox.center.position.z == \
        pytest.approx(0.5 * 1.7 * 0.7)
    (result,) = d.results
    assert result.hypothesis.class_id == 'person'
    assert result.hypothesis.score == pytest.approx(0.9)
    cov = np.array(result.pose.covariance).reshape(6, 6)
    np.testing.assert_allclose(cov[:2, :2], [[0.04, 0.01], [0.01, 0.09]])
    assert result.pose.pose == d.bbox.center


def test_tf_frames_at_the_head_under_the_output_frame():
    msg = po.tf_message(FrameResult(STAMP, [track(7, 2.0, 3.0, visibility={'c': 1.0})]),
                        'room')
    (t,) = msg.transforms
    assert t.header.frame_id == 'room' and t.child_frame_id == 'person_mbtrack_7'
    v = t.transform.translation
    assert (v.x, v.y, v.z) == pytest.approx((2.0, 3.0, po.HEAD_HEIGHT_SHARE * 1.8))
    q = t.transform.rotation
    assert q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2 == pytest.approx(1.0)


def test_output_bag_holds_the_standard_outputs_with_released_types(tmp_path):
    """Readable by rosbags and by the mcap reader; type names, hashes and definitions of
    the released packages."""
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    from mbtrack_ros.nodes.output_bag import OutputBagWriter
    from test_interfaces import RELEASED

    a = track(3, 1.0, 2.0, visibility={'cam0': 0.9})
    b = track(4, 3.0, 1.0, visibility={'cam0': 0.0}, existence=0.5)
    out = tmp_path / 'bag'
    with OutputBagWriter(out, None, ['cam0'], frame_id='room') as writer:
        writer.write(FrameResult(STAMP, [a, b]))
        writer.write(FrameResult(STAMP + 66_000_000, [a]))
    topics: dict[str, list] = {}
    with AnyReader([out]) as reader:
        hashes = {c.topic: (c.msgtype, c.digest) for c in reader.connections}
        for conn, stamp, raw in reader.messages():
            topics.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    for topic, name in (('/humans/persons/tracked', 'hri_msgs/msg/IdsList'),
                        ('/tracker_node/detections', 'vision_msgs/msg/Detection3DArray'),
                        ('/tf', 'tf2_msgs/msg/TFMessage')):
        assert hashes[topic] == (name, RELEASED[name])
    assert [list(m.ids) for m in topics['/humans/persons/tracked']] == [
        ['mbtrack_3', 'mbtrack_4'], ['mbtrack_3']]
    assert [m.data for m in topics['/humans/persons/mbtrack_4/location_confidence']] == [
        0.5, 0.0]
    assert [m.data for m in topics['/humans/persons/mbtrack_4/anonymous']] == [True]
    assert [d.id for d in topics['/tracker_node/detections'][0].detections] == ['3', '4']
    assert [t.child_frame_id for t in topics['/tf'][1].transforms] == ['person_mbtrack_3']
    # the mcap reader: schemas named and defined as the released messages
    (path,) = out.glob('*.mcap')
    schemas, counts = {}, {}
    with open(path, 'rb') as stream:
        for schema, channel, _message in make_reader(stream).iter_messages():
            schemas[channel.topic] = schema
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert schemas['/humans/persons/tracked'].name == 'hri_msgs/msg/IdsList'
    assert schemas['/tracker_node/detections'].name == 'vision_msgs/msg/Detection3DArray'
    assert schemas['/tf'].name == 'tf2_msgs/msg/TFMessage'
    assert schemas['/tf'].encoding == 'ros2msg'
    definition = schemas['/tracker_node/detections'].data.decode()
    assert 'MSG: vision_msgs/BoundingBox3D' in definition and 'string id' in definition
    assert counts['/humans/persons/tracked'] == counts['/tf'] == 2
