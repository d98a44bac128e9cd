"""Write everything the tracker node publishes to a rosbag2 MCAP bag, for offline replay.

The messages are built by :mod:`mbtrack_ros.nodes.messages` (the same builders as the live
node), serialised with ``rclpy.serialization.serialize_message`` (CDR) and written raw with
``rosbags.rosbag2.Writer``. Topics (node name ``tracker_node``):

=====================================  =======================================
``/tracker_node/people``               geometry_msgs/PoseArray
``/tracker_node/tracks``               sensor_msgs/PointCloud2 (layout in messages.py)
``/tracker_node/markers``              visualization_msgs/MarkerArray
``/tracker_node/debug/<cam>/occlusion``  sensor_msgs/Image rgb8 (only when given)
``/diagnostics``                       diagnostic_msgs/DiagnosticArray (when given)
``/humans/persons/tracked``            hri_msgs/IdsList (REP-155)
``/humans/persons/<id>/...``           ``location_confidence`` std_msgs/Float32,
                                       ``anonymous`` std_msgs/Bool (REP-155)
``/tracker_node/detections``           vision_msgs/Detection3DArray
``/tf``                                tf2_msgs/TFMessage (``person_<id>`` frames)
=====================================  =======================================

The last four (:mod:`.people_outputs`) are written when their message packages import;
their types are registered from the packages' ``.msg`` definitions, so the bag carries the
released packages' type names, definitions and hashes.

Log time of every message = the frame set's stamp (message time), so the bag replays in
sync with the input recording.
"""
from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore

from mbtrack_ros.core.state import FrameResult
from mbtrack_ros.nodes import messages
from mbtrack_ros.nodes.people_outputs import (
    PeopleFrame, PeopleFrameBuilder, message_definitions)

if TYPE_CHECKING:  # not imported at run time: replay's writer process starts without numba
    from mbtrack_ros.core.camera import RoomCalibration

__all__ = ['OutputBagError', 'OutputBagWriter', 'output_topics']

_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
_TYPES = {
    'people': 'geometry_msgs/msg/PoseArray',
    'tracks': 'sensor_msgs/msg/PointCloud2',
    'markers': 'visualization_msgs/msg/MarkerArray',
    'diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
    'debug': 'sensor_msgs/msg/Image',
    'tracked': 'hri_msgs/msg/IdsList',
    'detections': 'vision_msgs/msg/Detection3DArray',
    'tf': 'tf2_msgs/msg/TFMessage',
    'location_confidence': 'std_msgs/msg/Float32',
    'anonymous': 'std_msgs/msg/Bool',
}


class OutputBagError(RuntimeError):
    """The output bag cannot be created or written (one-line reason)."""


def output_topics(node_name: str = 'tracker_node') -> dict[str, str]:
    """Output kind -> topic name of a node called ``node_name`` (debug: a prefix)."""
    base = f'/{node_name}'
    return {'people': f'{base}/people', 'tracks': f'{base}/tracks',
            'markers': f'{base}/markers', 'diagnostics': '/diagnostics',
            'debug': f'{base}/debug', 'tracked': '/humans/persons/tracked',
            'detections': f'{base}/detections', 'tf': '/tf', 'persons': '/humans/persons'}


def _people_typestore(outputs: list[str]):
    """The Jazzy typestore plus the types of the people ``outputs`` (from their ``.msg``
    definitions; a type the store has already is kept)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for output in outputs:
        types = {}
        for name, text in message_definitions(output).items():
            if name not in store.fielddefs:
                types.update(get_types_from_msg(text, name))
        store.register(types)
    return store


class OutputBagWriter:
    """Writes tracker outputs frame by frame into ``path`` (a new rosbag2 directory, MCAP).

    Args:
        path: bag directory to create (must not exist).
        calibration: the room (its frame id is the default output frame); may be None
            when ``camera_names`` and ``frame_id`` are given.
        camera_names: cameras of the ``visibility_<camera>`` fields of ``~/tracks``
            (default: the calibration's).
        frame_id: output frame id (default: the calibration's).
        node_name: node name used in the topic names.
        people: write the standard people outputs (:mod:`.people_outputs`) whose message
            packages import.
    """

    def __init__(self, path: str | Path, calibration: RoomCalibration | None,
                 camera_names: list[str] | tuple[str, ...] | None = None, *,
                 frame_id: str | None = None, node_name: str = 'tracker_node',
                 people: bool = True) -> None:
        if calibration is None and (camera_names is None or not frame_id):
            raise OutputBagError('output bag: give a calibration, or camera names and a '
                                 'frame id')
        self.path = Path(path)
        self.camera_names = list(camera_names or calibration.names)
        self.frame_id = frame_id or calibration.frame_id
        self.topics = output_topics(node_name)
        if self.path.exists():
            raise OutputBagError(f'output bag {self.path} already exists')
        if not self.path.parent.is_dir():
            raise OutputBagError(f'directory {self.path.parent} does not exist')
        self._people = PeopleFrameBuilder(self.frame_id, persons=people, detections=people,
                                          tf=people)
        on = [k for k, v in self._people.enabled.items() if v]
        try:
            self._typestore = _people_typestore(on) if on else _TYPESTORE
        except (OSError, TypesysError) as err:
            raise OutputBagError(f'output bag: message definitions of {", ".join(on)}: '
                                 f'{err}') from err
        kinds = ['people', 'tracks', 'markers', 'diagnostics']
        kinds += [k for k, out in (('tracked', 'persons'), ('detections', 'detections'),
                                   ('tf', 'tf')) if self._people.enabled[out]]
        try:
            self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
            self._writer.open()
            self._conn = {kind: self._writer.add_connection(
                self.topics[kind], _TYPES[kind], typestore=self._typestore)
                for kind in kinds}
        except (WriterError, OSError) as err:
            raise OutputBagError(f'cannot create output bag {self.path}: {err}') from err
        self._person_conn: dict[tuple[str, str], object] = {}
        self._debug_conn: dict[str, object] = {}
        self._shown: set[int] = set()
        self.frames_written = 0
        self._closed = False

    def _put(self, conn, stamp_ns: int, msg) -> None:
        try:
            self._writer.write(conn, int(stamp_ns), serialize_message(msg))
        except (WriterError, OSError) as err:
            raise OutputBagError(f'cannot write to {self.path}: {err}') from err

    def write(self, result: FrameResult, *, people=None, cloud=None, markers=None,
              diagnostics=None, debug: dict | None = None,
              standard: PeopleFrame | None = None) -> None:
        """Write one frame's outputs; messages not given are built from ``result``
        (``standard``: the people outputs of :mod:`.people_outputs`)."""
        if self._closed:
            raise OutputBagError(f'output bag {self.path} is closed')
        stamp = result.stamp_ns
        self._put(self._conn['people'], stamp,
                  people if people is not None
                  else messages.people_message(result, self.frame_id))
        self._put(self._conn['tracks'], stamp,
                  cloud if cloud is not None
                  else messages.tracks_cloud(result, self.camera_names, self.frame_id))
        current = {t.track_id for t in result.tracks}
        if markers is None:  # also remove tracks that stopped being reported
            markers = messages.markers_message(result, self.frame_id,
                                               also_delete=sorted(self._shown - current))
        self._shown = current
        self._put(self._conn['markers'], stamp, markers)
        if diagnostics is not None:
            self._put(self._conn['diagnostics'], stamp, diagnostics)
        for cam, image in (debug or {}).items():
            if cam not in self._debug_conn:
                self._debug_conn[cam] = self._writer.add_connection(
                    f'{self.topics["debug"]}/{cam}/occlusion', _TYPES['debug'],
                    typestore=_TYPESTORE)
            self._put(self._debug_conn[cam], stamp, image)
        self._write_standard(standard if standard is not None else self._people.build(result))
        self.frames_written += 1

    def _person_topic(self, person: str, kind: str):
        key = (person, kind)
        if key not in self._person_conn:
            self._person_conn[key] = self._writer.add_connection(
                f'{self.topics["persons"]}/{person}/{kind}', _TYPES[kind],
                typestore=self._typestore)
        return self._person_conn[key]

    def _write_standard(self, frame: PeopleFrame) -> None:
        from std_msgs.msg import Bool, Float32
        stamp = frame.stamp_ns
        if frame.tracked is not None and 'tracked' in self._conn:
            self._put(self._conn['tracked'], stamp, frame.tracked)
            for person in frame.appeared:
                self._put(self._person_topic(person, 'anonymous'), stamp, Bool(data=True))
            for person, value in frame.confidence.items():
                self._put(self._person_topic(person, 'location_confidence'), stamp,
                          Float32(data=float(value)))
        if frame.detections is not None and 'detections' in self._conn:
            self._put(self._conn['detections'], stamp, frame.detections)
        if frame.tf is not None and frame.tf.transforms and 'tf' in self._conn:
            self._put(self._conn['tf'], stamp, frame.tf)

    def write_diagnostics(self, stamp_ns: int, values: dict) -> None:
        """Write a ``/diagnostics`` message of a :class:`messages.DiagnosticsSnapshot` with
        these field values (the counts of an offline replay)."""
        self._put(self._conn['diagnostics'], stamp_ns, messages.diagnostics_message(
            stamp_ns, messages.DiagnosticsSnapshot(**values)))

    def write_markers(self, stamp_ns: int, markers) -> None:
        """Write an extra MarkerArray (e.g. DELETEALL after a reset)."""
        self._put(self._conn['markers'], stamp_ns, markers)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._writer.close()

    def __enter__(self) -> OutputBagWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
