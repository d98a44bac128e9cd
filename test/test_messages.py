"""Output message builders: PointCloud2 layout, PoseArray yaw, MarkerArray lifecycle."""
from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import PointField
from visualization_msgs.msg import Marker

from mbtrack_ros.core.state import WALKING_SPEED, FrameResult, TrackEstimate
from mbtrack_ros.nodes.conversions import stamp_to_ns
from mbtrack_ros.nodes.messages import (
    TRACK_FIELDS, DiagnosticsSnapshot, debug_overlay, delete_all_markers, diagnostics_message,
    markers_message, people_message, track_color, tracks_cloud, tracks_dtype)

CAMS = ('cam0', 'cam-1')
STAMP = 1_700_000_000_123_456_789


def make_result(seed=0, n=3, ended=()):
    rng = np.random.default_rng(seed)
    tracks = []
    for k in range(n):
        mean = np.array([rng.uniform(0, 5), rng.uniform(0, 4), rng.normal(), rng.normal(),
                         rng.uniform(-math.pi, math.pi), 0.0])
        a = rng.normal(size=(4, 4))
        tracks.append(TrackEstimate(
            track_id=int(rng.integers(1, 2 ** 24 + 100)) if k == 0 else 2 ** 24 + 1 + k,
            mean=mean, covariance=a @ a.T, height=float(rng.uniform(1.5, 1.9)),
            visible_fraction={'cam0': 0.25, 'cam-1': 0.75},
            visibility={'cam0': float(rng.uniform())} if k != 1 else {},
            existence=float(rng.uniform())))
    return FrameResult(stamp_ns=STAMP, tracks=tracks, ended=list(ended))


def test_tracks_cloud_reads_back_into_numpy():
    result = make_result()
    msg = tracks_cloud(result, CAMS, frame_id='world')
    assert msg.header.frame_id == 'world' and stamp_to_ns(msg.header.stamp) == STAMP
    names = [f.name for f in msg.fields]
    assert names == list(TRACK_FIELDS) + ['visibility_cam0', 'visibility_cam_1']
    assert {f.name: f.datatype for f in msg.fields}['id'] == PointField.UINT32
    assert all(f.datatype == PointField.FLOAT32 for f in msg.fields if f.name != 'id')
    assert msg.width == 3 and msg.height == 1 and msg.point_step == 4 * len(names)
    assert msg.row_step == msg.point_step * msg.width and len(msg.data) == msg.row_step
    # offsets declared in the fields agree with the documented dtype
    dtype = tracks_dtype(CAMS)
    assert [f.offset for f in msg.fields] == [dtype.fields[n][1] for n in dtype.names]
    pts = np.frombuffer(bytes(msg.data), dtype=dtype)
    for p, t in zip(pts, result.tracks):
        assert int(p['id']) == t.track_id  # exact beyond 2^24
        np.testing.assert_allclose([p['x'], p['y'], p['vx'], p['vy']], t.mean[:4], rtol=1e-6)
        np.testing.assert_allclose([p['cov_xx'], p['cov_xy'], p['cov_yy']],
                                   [t.covariance[0, 0], t.covariance[0, 1],
                                    t.covariance[1, 1]], rtol=1e-6)
        assert p['z'] == 0.0
        np.testing.assert_allclose(p['existence'], t.existence, rtol=1e-6)
        np.testing.assert_allclose(p['height'], t.height, rtol=1e-6)
        # visibility process when reported, else the expected visible fraction
        v0 = t.visibility.get('cam0', 0.25)
        np.testing.assert_allclose(p['visibility_cam0'], v0, rtol=1e-6)
        np.testing.assert_allclose(p['visibility_cam_1'], 0.75)
        np.testing.assert_allclose(p['visibility'], max(v0, 0.75), rtol=1e-6)


def test_empty_cloud_is_valid():
    msg = tracks_cloud(FrameResult(stamp_ns=5), CAMS)
    assert msg.width == 0 and len(msg.data) == 0 and len(msg.fields) == 14


def test_people_pose_yaw_and_position():
    """The yaw is the direction of walking, or the body orientation of a track slower than
    WALKING_SPEED."""
    result = make_result(seed=1, n=4)
    result.tracks[3].mean[[2, 3]] = (0.1, -0.15)                    # 0.18 m/s: standing
    msg = people_message(result)
    assert msg.header.frame_id == 'room' and stamp_to_ns(msg.header.stamp) == STAMP
    assert len(msg.poses) == 4
    for k, (pose, t) in enumerate(zip(msg.poses, result.tracks)):
        q = pose.orientation
        assert abs(q.x) < 1e-12 and abs(q.y) < 1e-12
        np.testing.assert_allclose(q.z ** 2 + q.w ** 2, 1.0)
        yaw = 2 * math.atan2(q.z, q.w)
        walking = math.hypot(t.mean[2], t.mean[3]) >= WALKING_SPEED
        assert walking == (k < 3)
        expected = math.atan2(t.mean[3], t.mean[2]) if walking else t.mean[4]
        np.testing.assert_allclose(math.remainder(yaw - expected, 2 * math.pi), 0,
                                   atol=1e-9)
        assert (pose.position.x, pose.position.y, pose.position.z) == (
            t.mean[0], t.mean[1], 0.0)


def test_markers_add_and_delete_ended():
    result = make_result(seed=2, ended=[7, 9])
    msg = markers_message(result)
    adds = [m for m in msg.markers if m.action == Marker.ADD]
    deletes = [m for m in msg.markers if m.action == Marker.DELETE]
    assert {(m.ns, m.id) for m in deletes} == {
        (ns, i) for ns in ('people', 'labels', 'heading') for i in (7, 9)}
    cylinders = [m for m in adds if m.type == Marker.CYLINDER]
    assert [m.id for m in cylinders] == [t.track_id for t in result.tracks]
    for m, t in zip(cylinders, result.tracks):
        np.testing.assert_allclose(m.scale.z, t.height)
        np.testing.assert_allclose(m.pose.position.z, 0.5 * t.height)
        np.testing.assert_allclose((m.color.r, m.color.g, m.color.b), track_color(t.track_id),
                                   rtol=1e-6)
    labels = [m for m in adds if m.type == Marker.TEXT_VIEW_FACING]
    assert [m.text for m in labels] == [
        f'{t.track_id} ({t.existence:.2f})' for t in result.tracks]
    assert all(stamp_to_ns(m.header.stamp) == STAMP for m in msg.markers)
    # colours are stable per id and differ between consecutive ids
    assert track_color(5) == track_color(5)
    assert np.linalg.norm(np.subtract(track_color(5), track_color(6))) > 0.2
    # tracks no longer reported are deleted too, live ones never
    live = result.tracks[0].track_id
    msg2 = markers_message(result, also_delete=[7, 11, live])
    gone = {(m.ns, m.id) for m in msg2.markers if m.action == Marker.DELETE}
    assert gone == {(ns, i) for ns in ('people', 'labels', 'heading') for i in (7, 9, 11)}
    clear = delete_all_markers(STAMP)
    assert [m.action for m in clear.markers] == [Marker.DELETEALL]


def test_markers_do_not_share_their_lists():
    """The builders copy one default Marker: a caller appending points or colours to one
    returned marker (e.g. to draw a trail) or giving it a lifetime in place changes no
    other marker, now or later."""
    from geometry_msgs.msg import Point

    first = markers_message(make_result(seed=2, ended=[7]))
    first.markers[0].points.append(Point(x=1.0))
    first.markers[0].colors.append(first.markers[0].color)
    first.markers[0].lifetime.sec = 5
    later = markers_message(make_result(seed=3, ended=[7]))
    assert all(len(m.points) == 0 and len(m.colors) == 0 and len(m.uv_coordinates) == 0
               and m.lifetime.sec == 0 for m in [*first.markers[1:], *later.markers])


def test_diagnostics_warn_on_missing_camera():
    snap = DiagnosticsSnapshot(input_rate_hz={'cam0': 25.0, 'cam1': 0.0}, step_seconds=0.05,
                               frame_sets=10, incomplete_sets=2, dropped_frames=1, tracks=2,
                               missing_cameras=('cam1',))
    msg = diagnostics_message(STAMP, snap)
    levels = {s.name: s.level for s in msg.status}
    main = msg.status[0]
    assert main.level == DiagnosticStatus.WARN and 'cam1' in main.message
    assert levels['mbtrack_ros: tracker: input cam0'] == DiagnosticStatus.OK
    assert levels['mbtrack_ros: tracker: input cam1'] == DiagnosticStatus.WARN
    values = {kv.key: kv.value for kv in main.values}
    assert values['step time [ms]'] == '50.0' and values['incomplete frame sets'] == '2'
    ok = diagnostics_message(STAMP, DiagnosticsSnapshot(input_rate_hz={'cam0': 25.0}))
    assert ok.status[0].level == DiagnosticStatus.OK


def test_debug_overlay_marks_only_occluded_and_silhouette_pixels():
    rgb = np.full((40, 60, 3), 100, np.uint8)
    occ = np.zeros((40, 60))
    occ[:, :10] = 1.0
    mask = np.zeros((40, 60), bool)
    mask[15:30, 30:45] = True
    out = debug_overlay(rgb, occlusion=occ, silhouettes={3: mask})
    assert out.shape == rgb.shape and out.dtype == np.uint8
    assert out[20, 5, 0] > 150 and out[20, 5, 1] < 100  # red tint where occluded
    np.testing.assert_array_equal(out[5, 20], rgb[5, 20])  # untouched elsewhere
    assert np.abs(out[22, 37].astype(int) - 100).max() > 10  # tinted inside the silhouette
    np.testing.assert_array_equal(rgb, 100)  # input not modified


def test_output_bag_round_trip(tmp_path):
    from rosbags.highlevel import AnyReader

    from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
    from mbtrack_ros.nodes.output_bag import OutputBagError, OutputBagWriter

    R, t = look_at((0.0, 0.0, 2.5), (3.0, 3.0, 0.0))
    cam = Camera('cam0', 64, 48, [[50, 0, 32], [0, 50, 24], [0, 0, 1]], [0] * 5, R, t)
    calibration = RoomCalibration(cameras={'cam0': cam}, floor=(0, 0, 5, 5))
    results = [make_result(seed=k, n=k + 1, ended=[99] if k == 2 else []) for k in range(3)]
    for k, r in enumerate(results):
        r.stamp_ns = STAMP + k * 40_000_000
    out = tmp_path / 'tracks.mcap'
    with OutputBagWriter(out, calibration, ['cam0'], people=False) as writer:
        for r in results:
            writer.write(r)
    with pytest.raises(OutputBagError, match='already exists'):
        OutputBagWriter(out, calibration)
    seen = {}
    with AnyReader([out]) as reader:
        for conn, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            seen.setdefault(conn.topic, []).append((stamp, msg))
    assert set(seen) == {'/tracker_node/people', '/tracker_node/tracks',
                         '/tracker_node/markers'}
    for (stamp, cloud), r in zip(seen['/tracker_node/tracks'], results):
        assert stamp == r.stamp_ns
        pts = np.frombuffer(bytes(cloud.data), dtype=tracks_dtype(['cam0']))
        assert [int(i) for i in pts['id']] == [t.track_id for t in r.tracks]
        np.testing.assert_allclose(pts['x'], [t.mean[0] for t in r.tracks], rtol=1e-6)
    last_markers = seen['/tracker_node/markers'][-1][1].markers
    assert sum(m.action == Marker.DELETE and m.id == 99 for m in last_markers) == 3


def test_occlusion_layers_with_the_measurement_model():
    """Two people on one line of sight: the far one is hidden where the near one stands."""
    from mbtrack_ros.core.appearance import PersonModel
    from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
    from mbtrack_ros.core.likelihood import LikelihoodConfig, MeasurementModel
    from mbtrack_ros.nodes.debug import occlusion_layers

    R, t = look_at((0.0, 0.0, 1.6), (4.0, 0.0, 1.0))
    cam = Camera('cam0', 80, 60, [[60, 0, 39.5], [0, 60, 29.5], [0, 0, 1]], [0] * 5, R, t)
    calibration = RoomCalibration(cameras={'cam0': cam}, floor=(-1, -3, 6, 3))
    measurement = MeasurementModel(calibration, LikelihoodConfig())
    rng = np.random.default_rng(4)
    tracks, models = [], {}
    for tid, x in ((1, 2.0), (2, 3.5)):  # 1 in front of 2
        particles = np.zeros((40, 6))
        particles[:, 0] = x + 0.02 * rng.normal(size=40)
        particles[:, 1] = 0.02 * rng.normal(size=40)
        tracks.append(TrackEstimate(tid, particles.mean(axis=0), np.eye(4) * 0.01, 1.75,
                                    particles=particles, weights=np.full(40, 1 / 40)))
        models[tid] = PersonModel(height=1.75, width=0.5)
        models[tid].add_view(0.0, np.full((3, 512), 1.0 / 512))
    result = FrameResult(stamp_ns=1, tracks=tracks)
    occ, sil = occlusion_layers(measurement, cam, result, models)
    assert set(sil) == {1, 2} and sil[1].sum() > sil[2].sum() > 0
    overlap = sil[1] & sil[2]
    assert overlap.sum() > 0.5 * sil[2].sum()
    # pixels of the far person behind the near one: hidden with high probability
    assert occ[overlap].mean() > 0.7
    # nothing hides anybody outside the silhouettes
    assert occ[~(sil[1] | sil[2])].max() == 0.0
    # a single track has nobody to be hidden by: no occlusion layer
    occ1, sil1 = occlusion_layers(measurement, cam, FrameResult(1, tracks[:1]), models)
    assert occ1 is None and set(sil1) == {1}


# -- the builders against the straightforward construction (same serialized bytes) ------------
def _reference_pose(track, z=0.0):
    from geometry_msgs.msg import Pose

    from mbtrack_ros.nodes.messages import yaw_to_quaternion
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (
        float(track.mean[0]), float(track.mean[1]), float(z))
    q = yaw_to_quaternion(track.heading())
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = q
    return pose


def _reference_marker(header, ns, track_id, action):
    from builtin_interfaces.msg import Duration
    m = Marker()
    m.header = header
    m.ns, m.id, m.action = ns, int(track_id), action
    m.lifetime = Duration()
    return m


def _reference_markers(result, frame_id, also_delete):
    """Every Marker built field by field from a fresh Marker() (the former builder)."""
    from visualization_msgs.msg import MarkerArray

    from mbtrack_ros.nodes.messages import make_header
    header = make_header(result.stamp_ns, frame_id)
    out = MarkerArray()
    for t in result.tracks:
        r, g, b = track_color(t.track_id)
        height = float(t.height) * (1.0 - 0.3 * float(np.clip(t.mean[5], 0.0, 1.0)))
        body = _reference_marker(header, 'people', t.track_id, Marker.ADD)
        body.type = Marker.CYLINDER
        body.pose = _reference_pose(t, 0.5 * height)
        body.scale.x = body.scale.y = 0.5
        body.scale.z = max(height, 1e-3)
        body.color.r, body.color.g, body.color.b = r, g, b
        body.color.a = float(0.25 + 0.5 * np.clip(t.existence, 0.0, 1.0))
        label = _reference_marker(header, 'labels', t.track_id, Marker.ADD)
        label.type = Marker.TEXT_VIEW_FACING
        label.pose = _reference_pose(t, height + 0.25)
        label.pose.orientation.z, label.pose.orientation.w = 0.0, 1.0
        label.scale.z = 0.25
        label.color.r, label.color.g, label.color.b, label.color.a = r, g, b, 1.0
        label.text = f'{t.track_id} ({t.existence:.2f})'
        arrow = _reference_marker(header, 'heading', t.track_id, Marker.ADD)
        arrow.type = Marker.ARROW
        arrow.pose = _reference_pose(t, 0.05)
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.5, 0.08, 0.08
        arrow.color.r, arrow.color.g, arrow.color.b, arrow.color.a = r, g, b, 0.9
        out.markers += [body, label, arrow]
    shown = {t.track_id for t in result.tracks}
    for i in dict.fromkeys([*result.ended, *also_delete]):
        if i not in shown:
            out.markers += [_reference_marker(header, ns, i, Marker.DELETE)
                            for ns in ('people', 'labels', 'heading')]
    return out


def _reference_cloud(result, cameras, frame_id):
    """The cloud filled point by point (the former builder)."""
    from sensor_msgs.msg import PointCloud2

    from mbtrack_ros.nodes.messages import field_name, make_header
    dtype = tracks_dtype(cameras)
    points = np.zeros(len(result.tracks), dtype=dtype)
    for i, t in enumerate(result.tracks):
        cov = np.asarray(t.covariance, dtype=np.float64)
        per_cam = [float(t.visibility[c]) if c in t.visibility
                   else float(t.visible_fraction.get(c, 0.0)) for c in cameras]
        row = {'x': t.mean[0], 'y': t.mean[1], 'z': 0.0, 'id': t.track_id,
               'existence': t.existence, 'visibility': max(per_cam, default=0.0),
               'vx': t.mean[2], 'vy': t.mean[3], 'cov_xx': cov[0, 0], 'cov_xy': cov[0, 1],
               'cov_yy': cov[1, 1], 'height': t.height}
        row.update({field_name(c): v for c, v in zip(cameras, per_cam)})
        points[i] = tuple(row[n] for n in dtype.names)
    msg = PointCloud2()
    msg.header = make_header(result.stamp_ns, frame_id)
    msg.height, msg.width = 1, len(points)
    msg.fields = [PointField(name=n, offset=int(dtype.fields[n][1]), count=1,
                             datatype=PointField.UINT32 if n == 'id' else PointField.FLOAT32)
                  for n in dtype.names]
    msg.is_bigendian = False
    msg.point_step = dtype.itemsize
    msg.row_step = dtype.itemsize * len(points)
    msg.is_dense = True
    msg.data = points.tobytes()
    return msg


def _odd_result():
    """Sitting and standing, existence and sitting outside [0, 1] and NaN, NaN height."""
    result = make_result(seed=5, n=4, ended=[3, 3, 8])
    result.tracks[0].mean[5] = 0.4
    result.tracks[1].mean[5] = 1.7
    result.tracks[1].existence = -0.2
    result.tracks[2].existence = float('nan')
    result.tracks[2].height = float('nan')
    result.tracks[3].mean[5] = float('nan')
    result.tracks[3].existence = 1.4
    return result


def _cdr(msg) -> bytes:
    """The CDR bytes of an rclpy message with its alignment padding zeroed: rclpy leaves
    padding bytes uninitialised, a rosbags round trip writes them as zeros."""
    from rclpy.serialization import serialize_message
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    kind = type(msg).__module__.split('.')[0] + '/msg/' + type(msg).__name__
    return bytes(store.serialize_cdr(store.deserialize_cdr(serialize_message(msg), kind), kind))


@pytest.mark.parametrize('case', range(4))
def test_builders_serialize_as_the_straightforward_construction(case):
    from geometry_msgs.msg import PoseArray

    from mbtrack_ros.nodes.messages import make_header
    result = [make_result(seed=3, n=4, ended=[77]), FrameResult(stamp_ns=9, ended=[4]),
              _odd_result(), make_result(seed=4, n=1)][case]
    also = [[5, 77, result.tracks[0].track_id] if result.tracks else [5], [], [1, 2], []][case]
    cams = [CAMS, ('cam0',), CAMS, ()][case]
    people = PoseArray()
    people.header = make_header(result.stamp_ns, 'world')
    people.poses = [_reference_pose(t) for t in result.tracks]
    pairs = [(people_message(result, 'world'), people),
             (tracks_cloud(result, cams, 'world'), _reference_cloud(result, cams, 'world')),
             (markers_message(result, 'world', also_delete=also),
              _reference_markers(result, 'world', also))]
    for new, old in pairs:
        assert _cdr(new) == _cdr(old)
    # the shared default messages the builders copy are still the defaults
    from mbtrack_ros.nodes import messages
    assert _cdr(messages._MARKER) == _cdr(Marker())
    assert _cdr(messages._POSE) == _cdr(type(messages._POSE)())
