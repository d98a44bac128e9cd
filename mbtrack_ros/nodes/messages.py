"""Output messages of the tracker node, built from a :class:`~mbtrack_ros.core.state.FrameResult`.

Every builder stamps its message with the frame set's time (``FrameResult.stamp_ns``, image
header time, never wall-clock time) and the output frame id (default ``room``). The same
builders feed the live node and the offline output bag (:mod:`.output_bag`).

``~/tracks`` (sensor_msgs/PointCloud2) layout, one point per reported track, little endian,
``point_step`` = 4 bytes x number of fields, no padding; read it into numpy with
``np.frombuffer(msg.data, dtype=tracks_dtype(cameras))``:

==================  =======  ==============================================================
field               type     meaning
==================  =======  ==============================================================
x, y                float32  posterior mean floor position, metres, output frame
z                   float32  0.0 (floor point)
id                  uint32   track id (exact; a UINT32 PointField, not a float)
existence           float32  posterior existence probability (001)
visibility          float32  largest per-camera visibility (probability seen by a camera)
vx, vy              float32  posterior mean velocity, m/s
cov_xx/cov_xy/yy    float32  posterior position covariance, m^2
height              float32  body height of the person model, metres
visibility_<cam>    float32  per camera: posterior visibility (001), or the expected
                             visible silhouette fraction from the HJS occlusion map (000
                             Eq. 34) when the tracker reports no visibility process
==================  =======  ==============================================================

Camera names are sanitised to ``[A-Za-z0-9_]`` in field names.
"""
from __future__ import annotations

import colorsys
import copy
import functools
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, PoseArray, Quaternion, Vector3
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from mbtrack_ros.core.state import SIT, VX, VY, X, Y, FrameResult, TrackEstimate
from mbtrack_ros.nodes.conversions import ns_to_stamp

__all__ = [
    'DiagnosticsSnapshot', 'TRACK_FIELDS', 'debug_overlay', 'delete_all_markers',
    'diagnostics_message', 'field_name', 'make_header', 'markers_message', 'people_message',
    'track_color', 'tracks_cloud', 'tracks_dtype', 'yaw_to_quaternion',
]

#: fixed fields of the ``~/tracks`` cloud, in order (then ``visibility_<camera>``)
TRACK_FIELDS = ('x', 'y', 'z', 'id', 'existence', 'visibility', 'vx', 'vy', 'cov_xx',
                'cov_xy', 'cov_yy', 'height')
GOLDEN = 0.618033988749895
BODY_DIAMETER = 0.5  # marker cylinder diameter, metres


def make_header(stamp_ns: int, frame_id: str) -> Header:
    """A ``std_msgs/Header`` with the given stamp (integer ns) and frame id."""
    header = Header()
    header.frame_id = frame_id
    ns_to_stamp(stamp_ns, header.stamp)
    return header


def yaw_to_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """Rotation about +z by ``yaw`` radians -> quaternion ``(x, y, z, w)``."""
    return 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)


def field_name(camera: str) -> str:
    """The ``visibility_<camera>`` field name of a camera (sanitised)."""
    return 'visibility_' + re.sub(r'[^A-Za-z0-9_]', '_', camera)


def tracks_dtype(cameras: Sequence[str]) -> np.dtype:
    """Structured numpy dtype of one ``~/tracks`` point for these cameras."""
    names = list(TRACK_FIELDS) + [field_name(c) for c in cameras]
    return np.dtype([(n, '<u4' if n == 'id' else '<f4') for n in names])


# Default messages copied (shallow) instead of constructed: a generated message's __init__
# builds every default sub-message (a Marker: header, pose, texture image, mesh file, ...),
# which the builders below would replace anyway. The copies share the defaults they do not
# set (the builders always assign new sub-messages and never change a shared one), except
# a marker's lists (points, colors, uv_coordinates) and lifetime: each marker gets its own,
# so a caller appending points to a returned marker, or setting its lifetime in place,
# changes no other marker.
_POSE = Pose()
_MARKER = Marker()


def _pose(track: TrackEstimate, z: float = 0.0, *, upright: bool = False) -> Pose:
    """The track's floor position at height ``z``, turned by its heading (the direction of
    walking, or the body orientation of a person standing: ``TrackEstimate.heading``;
    ``upright``: no turn)."""
    pose = copy.copy(_POSE)
    pose.position = Point(x=float(track.mean[X]), y=float(track.mean[Y]), z=float(z))
    qx, qy, qz, qw = (0.0, 0.0, 0.0, 1.0) if upright \
        else yaw_to_quaternion(track.heading())
    pose.orientation = Quaternion(x=qx, y=qy, z=qz, w=qw)
    return pose


def people_message(result: FrameResult, frame_id: str = 'room') -> PoseArray:
    """``~/people``: one pose per reported track (floor point z = 0, yaw = heading: the
    direction of walking, or the body orientation of a person standing)."""
    msg = PoseArray()
    msg.header = make_header(result.stamp_ns, frame_id)
    msg.poses = [_pose(t) for t in result.tracks]
    return msg


def _camera_visibility(track: TrackEstimate, camera: str) -> float:
    if camera in track.visibility:
        return float(track.visibility[camera])
    return float(track.visible_fraction.get(camera, 0.0))


@functools.lru_cache(maxsize=8)
def _cloud_layout(cameras: tuple[str, ...]) -> tuple[np.dtype, tuple[PointField, ...]]:
    """The point dtype and PointFields of ``~/tracks`` for these cameras (built once; the
    fields are shared by every cloud, never changed)."""
    dtype = tracks_dtype(cameras)
    fields = tuple(PointField(name=n, offset=int(dtype.fields[n][1]), count=1,
                              datatype=PointField.UINT32 if n == 'id' else PointField.FLOAT32)
                   for n in dtype.names)
    return dtype, fields


def tracks_cloud(result: FrameResult, cameras: Sequence[str],
                 frame_id: str = 'room') -> PointCloud2:
    """``~/tracks``: one PointCloud2 point per track (fields in the module docstring)."""
    cameras = tuple(cameras)
    dtype, fields = _cloud_layout(cameras)
    tracks = result.tracks
    points = np.zeros(len(tracks), dtype=dtype)
    if tracks:
        per_cam = np.array([[_camera_visibility(t, c) for c in cameras] for t in tracks],
                           dtype=np.float64).reshape(len(tracks), len(cameras))
        columns = {
            'x': [t.mean[X] for t in tracks], 'y': [t.mean[Y] for t in tracks],
            'id': [t.track_id for t in tracks], 'existence': [t.existence for t in tracks],
            'visibility': [max(row, default=0.0) for row in per_cam.tolist()],
            'vx': [t.mean[VX] for t in tracks], 'vy': [t.mean[VY] for t in tracks],
            'height': [t.height for t in tracks]}
        cov = [np.asarray(t.covariance, dtype=np.float64) for t in tracks]
        columns['cov_xx'] = [c[0, 0] for c in cov]
        columns['cov_xy'] = [c[0, 1] for c in cov]
        columns['cov_yy'] = [c[1, 1] for c in cov]
        for name, values in columns.items():
            points[name] = values
        for k, c in enumerate(cameras):
            points[field_name(c)] = per_cam[:, k]
    msg = PointCloud2()
    msg.header = make_header(result.stamp_ns, frame_id)
    msg.height, msg.width = 1, len(points)
    msg.fields = list(fields)
    msg.is_bigendian = False
    msg.point_step = dtype.itemsize
    msg.row_step = dtype.itemsize * len(points)
    msg.is_dense = True
    msg.data = points.tobytes()
    return msg


def track_color(track_id: int) -> tuple[float, float, float]:
    """A colour stable per id: hue stepped by the golden ratio -> RGB in [0, 1]."""
    hue = (int(track_id) * GOLDEN) % 1.0
    return colorsys.hsv_to_rgb(hue, 0.85, 0.95)


def _marker(header: Header, ns: str, track_id: int, action: int, *, kind: int = 0,
            pose: Pose | None = None, scale: tuple[float, float, float] | None = None,
            color: tuple[float, float, float, float] | None = None, text: str = '') -> Marker:
    """A marker (a shallow copy of the default one, see ``_MARKER``) with new sub-messages
    for what is given; lifetime zero = forever (tracks are removed with explicit DELETE
    markers)."""
    m = copy.copy(_MARKER)
    m.points, m.colors, m.uv_coordinates = [], [], []
    m.lifetime = Duration()  # its own (0 = forever): a caller may set a lifetime in place
    m.header = header
    m.ns, m.id, m.action, m.type = ns, int(track_id), action, kind
    if pose is not None:
        m.pose = pose
    if scale is not None:
        m.scale = Vector3(x=scale[0], y=scale[1], z=scale[2])
    if color is not None:
        m.color = ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3])
    if text:
        m.text = text
    return m


def _clip01(value: float) -> float:
    """``value`` clipped to [0, 1] (NaN stays NaN, as ``np.clip``)."""
    return min(max(float(value), 0.0), 1.0)


def markers_message(result: FrameResult, frame_id: str = 'room', *,
                    also_delete: Sequence[int] = ()) -> MarkerArray:
    """``~/markers``: per track a cylinder of the person's height, a label with id and
    existence and a heading arrow; DELETE markers for the tracks that ended this frame and for
    ``also_delete`` (e.g. tracks shown before that are not reported any more)."""
    header = make_header(result.stamp_ns, frame_id)
    markers = []
    for t in result.tracks:
        r, g, b = track_color(t.track_id)
        height = float(t.height) * (1.0 - 0.3 * _clip01(t.mean[SIT]))
        markers += [
            _marker(header, 'people', t.track_id, Marker.ADD, kind=Marker.CYLINDER,
                    pose=_pose(t, 0.5 * height),
                    scale=(BODY_DIAMETER, BODY_DIAMETER, max(height, 1e-3)),
                    color=(r, g, b, float(0.25 + 0.5 * _clip01(t.existence)))),
            _marker(header, 'labels', t.track_id, Marker.ADD, kind=Marker.TEXT_VIEW_FACING,
                    pose=_pose(t, height + 0.25, upright=True), scale=(0.0, 0.0, 0.25),
                    color=(r, g, b, 1.0), text=f'{t.track_id} ({t.existence:.2f})'),
            _marker(header, 'heading', t.track_id, Marker.ADD, kind=Marker.ARROW,
                    pose=_pose(t, 0.05), scale=(0.5, 0.08, 0.08), color=(r, g, b, 0.9))]
    shown = {t.track_id for t in result.tracks}
    gone = list(dict.fromkeys([*result.ended, *also_delete]))
    for track_id in (i for i in gone if i not in shown):
        markers += [_marker(header, ns, track_id, Marker.DELETE)
                    for ns in ('people', 'labels', 'heading')]
    out = MarkerArray()
    out.markers = markers
    return out


def delete_all_markers(stamp_ns: int, frame_id: str = 'room') -> MarkerArray:
    """A MarkerArray clearing every marker (sent when the tracker is reset)."""
    out = MarkerArray()
    out.markers = [_marker(make_header(stamp_ns, frame_id), '', 0, Marker.DELETEALL)]
    return out


@dataclass
class DiagnosticsSnapshot:
    """What ``/diagnostics`` reports (collected by the node between two messages).

    Attributes:
        input_rate_hz: camera -> received frames per second (message time).
        step_seconds: mean wall-clock processing time of one tracker step, seconds.
        frame_sets: complete frame sets processed so far.
        incomplete_sets: frame sets processed with missing views so far.
        dropped_frames: frames dropped (bad, late, wrong size, overflow) so far.
        tracks: tracks reported in the last result.
        missing_cameras: cameras missing in the last frame set (WARN when not empty).
        resets: tracker resets so far (stamps jumped or went backwards).
        bad_images, late_frames: of ``dropped_frames``, images refused (encoding, size) and
            frames the synchroniser could not use (late, duplicate stamp, overflow).
        dropped_sets_full, dropped_sets_error: of ``dropped_frames``, whole frame sets lost
            because the tracker stayed ``max_pending_sets`` behind, or because its step
            raised.
        queued_sets, queue_peak: frame sets waiting for the tracker now, and the most that
            waited since the previous message.
        dropped_sets_repeated: of ``dropped_frames``, frame sets dropped because their stamp
            equals the last processed one (never processed twice).
        reason: why no frame set formed (a message sent on the wall-clock period while
            none does; WARN when not empty).
    """

    input_rate_hz: dict[str, float] = field(default_factory=dict)
    step_seconds: float = 0.0
    frame_sets: int = 0
    incomplete_sets: int = 0
    dropped_frames: int = 0
    tracks: int = 0
    missing_cameras: tuple[str, ...] = ()
    resets: int = 0
    bad_images: int = 0
    late_frames: int = 0
    dropped_sets_full: int = 0
    dropped_sets_error: int = 0
    queued_sets: int = 0
    queue_peak: int = 0
    dropped_sets_repeated: int = 0
    reason: str = ''


def diagnostics_message(stamp_ns: int, snap: DiagnosticsSnapshot, *,
                        name: str = 'mbtrack_ros: tracker',
                        hardware_id: str = 'smart_room') -> DiagnosticArray:
    """``/diagnostics``: one tracker status plus one status per camera input."""
    def kv(key: str, value) -> KeyValue:
        return KeyValue(key=key, value=str(value))

    msg = DiagnosticArray()
    msg.header = make_header(stamp_ns, '')
    main = DiagnosticStatus(name=name, hardware_id=hardware_id)
    if snap.reason:
        main.level = DiagnosticStatus.WARN
        main.message = snap.reason
    elif snap.missing_cameras:
        main.level = DiagnosticStatus.WARN
        main.message = 'missing camera(s): ' + ', '.join(snap.missing_cameras)
    else:
        main.level = DiagnosticStatus.OK
        main.message = f'tracking {snap.tracks} people'
    main.values = [
        kv('step time [ms]', f'{1e3 * snap.step_seconds:.1f}'),
        kv('frame sets', snap.frame_sets), kv('incomplete frame sets', snap.incomplete_sets),
        kv('dropped frames', snap.dropped_frames), kv('tracks', snap.tracks),
        kv('resets', snap.resets), kv('missing cameras', ','.join(snap.missing_cameras)),
        kv('dropped images (bad)', snap.bad_images),
        kv('dropped frames (late or duplicate)', snap.late_frames),
        kv('dropped frame sets (queue full)', snap.dropped_sets_full),
        kv('dropped frame sets (step error)', snap.dropped_sets_error),
        kv('dropped frame sets (repeated stamp)', snap.dropped_sets_repeated),
        kv('queued frame sets', snap.queued_sets),
        kv('queued frame sets (peak)', snap.queue_peak)]
    statuses = [main]
    for cam, rate in snap.input_rate_hz.items():
        st = DiagnosticStatus(name=f'{name}: input {cam}', hardware_id=cam)
        missing = cam in snap.missing_cameras
        st.level = DiagnosticStatus.WARN if missing or rate <= 0 else DiagnosticStatus.OK
        st.message = 'no frame in the last set' if missing else f'{rate:.1f} Hz'
        st.values = [kv('rate [Hz]', f'{rate:.2f}')]
        statuses.append(st)
    msg.status = statuses
    return msg


#: colour of cast-shadow pixels in the debug image (RGB)
SHADOW_COLOUR = (170, 0, 255)


def debug_overlay(rgb: np.ndarray, *, occlusion: np.ndarray | None = None,
                  silhouettes: Mapping[int, np.ndarray] | None = None,
                  alpha: float = 0.45, shadows: np.ndarray | None = None) -> np.ndarray:
    """Paint the HJS occlusion map and the track silhouettes over a camera image.

    Args:
        rgb: (H, W, 3) uint8 camera image.
        occlusion: (H, W) float in [0, 1], the occlusion map w* (000 Eq. 34: probability
            that a pixel is hidden by a target in front); shown as a red tint.
        silhouettes: track id -> (H, W) bool or float mask of its rendered silhouette
            (000 Fig. 4), outlined and tinted in the track colour.
        alpha: blending weight of the overlays.
        shadows: (h, w) bool cast-shadow pixels (any size, resized), painted in purple
            (``SHADOW_COLOUR``).

    Returns:
        (H, W, 3) uint8 RGB image (a new array).
    """
    out = np.ascontiguousarray(rgb, dtype=np.uint8).copy()
    h, w = out.shape[:2]
    if shadows is not None and np.any(shadows):
        sh = np.asarray(shadows, dtype=np.uint8)
        if sh.shape != (h, w):
            sh = cv2.resize(sh, (w, h), interpolation=cv2.INTER_NEAREST)
        out[sh > 0] = (out[sh > 0] * (1.0 - alpha)
                       + np.asarray(SHADOW_COLOUR) * alpha).astype(np.uint8)
    if occlusion is not None:
        occ = np.clip(np.asarray(occlusion, dtype=np.float32), 0.0, 1.0)
        if occ.shape != (h, w):
            occ = cv2.resize(occ, (w, h), interpolation=cv2.INTER_LINEAR)
        tint = np.zeros_like(out)
        tint[..., 0] = 255
        weight = (alpha * occ)[..., None]
        out = (out * (1.0 - weight) + tint * weight).astype(np.uint8)
    for track_id, mask in (silhouettes or {}).items():
        m = np.asarray(mask)
        if m.shape != (h, w):
            m = cv2.resize(m.astype(np.float32), (w, h), interpolation=cv2.INTER_NEAREST)
        m8 = (m > 0.5).astype(np.uint8)
        colour = tuple(int(255 * c) for c in track_color(track_id))
        layer = out.copy()
        layer[m8 > 0] = colour
        out = cv2.addWeighted(layer, 0.5 * alpha, out, 1.0 - 0.5 * alpha, 0.0)
        contours, _ = cv2.findContours(m8, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(out, contours, -1, colour, 2)
    return out
