"""rosbag2 recordings (MCAP or sqlite3) of a calibrated camera rig, read and written with rosbags.

Topics of a recording (documented in the README):

========================================  =====================================================
``/<camera>/image_raw``                   ``sensor_msgs/Image`` (rgb8), or with ``compressed``
``/<camera>/image_raw/compressed``        ``sensor_msgs/CompressedImage`` (jpeg)
``/<camera>/camera_info``                 ``sensor_msgs/CameraInfo`` (plumb_bob)
``/ground_truth/people``                  ``sensor_msgs/PointCloud2``, one point per person,
                                          float32 fields ``x, y, z, z_head, sitting`` and
                                          uint32 ``id`` (synthetic recordings only)
========================================  =====================================================

Header stamps are the capture time (integer nanoseconds); frame ids are the cameras'
optical frames (``Camera.frame_id``) and ``room`` for the ground truth, as a ROS camera
driver and a motion-capture bridge would write them. No rclpy is imported here.
"""
from __future__ import annotations

import queue
import re
import threading
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePath
from types import TracebackType
from typing import TypeVar

import numpy as np
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.recording.cdr_images import image_view
from mbtrack_ros.recording.csvfiles import GroundTruthRow
from mbtrack_ros.recording.images import (
    MAX_RESCALE, ImageConversionError, decode_compressed, decode_raw, encode_compressed)
from mbtrack_ros.recording.mcap_views import McapViewError, McapViews

__all__ = [
    'GROUND_TRUTH_TOPIC', 'BagError', 'FrameSet', 'RecordingReader', 'RecordingWriter',
    'camera_info_topic', 'image_topic', 'prefetched', 'stream_mcap', 'typestore',
]

GROUND_TRUTH_TOPIC = '/ground_truth/people'
IMAGE = 'sensor_msgs/msg/Image'
COMPRESSED = 'sensor_msgs/msg/CompressedImage'
CAMERA_INFO = 'sensor_msgs/msg/CameraInfo'
POINT_CLOUD = 'sensor_msgs/msg/PointCloud2'

typestore = get_typestore(Stores.ROS2_JAZZY)
_T = typestore.types


class BagError(RuntimeError):
    """A bag that cannot be read or written (one-line reason)."""


def image_topic(camera: str, compressed: bool = False) -> str:
    """The image topic of a camera: ``/<camera>/image_raw[/compressed]``."""
    return f'/{camera}/image_raw' + ('/compressed' if compressed else '')


def camera_info_topic(camera: str) -> str:
    return f'/{camera}/camera_info'


def _header(stamp_ns: int, frame_id: str):
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return _T['std_msgs/msg/Header'](
        stamp=_T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec), frame_id=frame_id)


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


# Ground-truth point layout: (name, numpy dtype, PointField datatype)
_GT_FIELDS = (('x', '<f4', 7), ('y', '<f4', 7), ('z', '<f4', 7), ('z_head', '<f4', 7),
              ('sitting', '<f4', 7), ('id', '<u4', 6))
_GT_DTYPE = np.dtype([(n, t) for n, t, _ in _GT_FIELDS])


class RecordingWriter:
    """Write a camera recording into a new rosbag2 directory.

    Args:
        path: the bag directory to create (must not exist).
        calibration: the cameras; CameraInfo is written from it with every frame.
        storage: ``'mcap'`` (default) or ``'sqlite3'``.
        compressed: write ``CompressedImage`` (JPEG) instead of raw ``Image``.
        jpeg_quality: JPEG quality 1-100.
    """

    def __init__(self, path: str | Path, calibration: RoomCalibration, *,
                 storage: str = 'mcap', compressed: bool = False,
                 jpeg_quality: int = 90) -> None:
        plugins = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
        if storage not in plugins:
            raise BagError(f'unknown storage {storage!r} (mcap or sqlite3)')
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'{self.path} exists already; choose a new bag directory')
        self.calibration = calibration
        self.compressed = compressed
        self.jpeg_quality = int(jpeg_quality)
        self._writer = Writer(self.path, version=9, storage_plugin=plugins[storage])
        self._image_conn: dict[str, object] = {}
        self._info_conn: dict[str, object] = {}
        self._gt_conn = None
        self._infos = {}
        self.frames_written = 0

    def __enter__(self) -> RecordingWriter:
        self._writer.open()
        for name, cam in self.calibration.cameras.items():
            self._image_conn[name] = self._writer.add_connection(
                image_topic(name, self.compressed), COMPRESSED if self.compressed else IMAGE,
                typestore=typestore)
            self._info_conn[name] = self._writer.add_connection(
                camera_info_topic(name), CAMERA_INFO, typestore=typestore)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._writer.close()

    def _camera_info(self, name: str, stamp_ns: int):
        cam = self.calibration.cameras[name]
        return _T[CAMERA_INFO](
            header=_header(stamp_ns, cam.frame_id), height=cam.height, width=cam.width,
            distortion_model='plumb_bob', d=cam.dist.astype(np.float64),
            k=cam.K.ravel().astype(np.float64), r=np.eye(3).ravel(),
            p=cam.projection_matrix.ravel().astype(np.float64), binning_x=0, binning_y=0,
            roi=_T['sensor_msgs/msg/RegionOfInterest'](
                x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))

    def write_frame(self, stamp_ns: int, images: dict[str, np.ndarray], *,
                    stamps: dict[str, int] | None = None) -> None:
        """Write one frame set: an image and a CameraInfo per camera.

        ``images`` maps camera names to ``(H, W, 3) uint8`` RGB arrays of the calibrated size;
        ``stamps`` gives a camera's own capture time, ns (free-running cameras; default
        ``stamp_ns`` for every camera).
        """
        unknown = set(images) - set(self.calibration.cameras)
        if unknown:
            raise BagError(f'unknown camera(s) {sorted(unknown)}')
        for name, rgb in images.items():
            cam = self.calibration.cameras[name]
            rgb = np.asarray(rgb)
            if rgb.shape != (cam.height, cam.width, 3) or rgb.dtype != np.uint8:
                raise BagError(f'{name}: expected ({cam.height}, {cam.width}, 3) uint8 RGB, '
                               f'got {rgb.dtype} {rgb.shape}')
            own = int(stamps.get(name, stamp_ns)) if stamps else int(stamp_ns)
            header = _header(own, cam.frame_id)
            if self.compressed:
                fmt, data = encode_compressed(rgb, 'jpeg', quality=self.jpeg_quality)
                msg = _T[COMPRESSED](header=header, format=fmt,
                                     data=np.frombuffer(data, dtype=np.uint8))
            else:
                msg = _T[IMAGE](header=header, height=cam.height, width=cam.width,
                                encoding='rgb8', is_bigendian=0, step=cam.width * 3,
                                data=np.ascontiguousarray(rgb).reshape(-1))
            self._writer.write(self._image_conn[name], own,
                               typestore.serialize_cdr(msg, msg.__msgtype__))
            info = self._camera_info(name, own)
            self._writer.write(self._info_conn[name], own,
                               typestore.serialize_cdr(info, CAMERA_INFO))
        self.frames_written += 1

    def write_ground_truth(self, stamp_ns: int, rows: Sequence[GroundTruthRow]) -> None:
        """Write the people's true positions at a frame as a PointCloud2."""
        if self._gt_conn is None:
            self._gt_conn = self._writer.add_connection(GROUND_TRUTH_TOPIC, POINT_CLOUD,
                                                        typestore=typestore)
        points = np.zeros(len(rows), dtype=_GT_DTYPE)
        for i, r in enumerate(rows):
            points[i] = (r.x, r.y, 0.0, r.z_head, float(r.sitting), r.person_id)
        fields = [_T['sensor_msgs/msg/PointField'](
            name=n, offset=_GT_DTYPE.fields[n][1], datatype=d, count=1)
            for n, _, d in _GT_FIELDS]
        msg = _T[POINT_CLOUD](
            header=_header(stamp_ns, self.calibration.frame_id), height=1, width=len(rows),
            fields=fields, is_bigendian=False, point_step=_GT_DTYPE.itemsize,
            row_step=_GT_DTYPE.itemsize * len(rows),
            data=np.frombuffer(points.tobytes(), dtype=np.uint8), is_dense=True)
        self._writer.write(self._gt_conn, int(stamp_ns),
                           typestore.serialize_cdr(msg, POINT_CLOUD))


@dataclass
class FrameSet:
    """Images of all cameras taken at one instant.

    Attributes:
        index: position of the set in the recording, from 0.
        stamp_ns: stamp of the set: the latest capture time of its images, nanoseconds.
        images: camera name -> ``(H, W, 3) uint8`` RGB.
        missing: cameras without an image in this set.
        errors: camera name -> one-line reason, for images that could not be decoded.
        stamps: camera name -> the capture time of its image (stamp + time offset), ns.
    """

    index: int
    stamp_ns: int
    images: dict[str, np.ndarray]
    missing: list[str] = field(default_factory=list)
    errors: dict[str, str] = field(default_factory=dict)
    stamps: dict[str, int] = field(default_factory=dict)


def stream_mcap(paths: Sequence[Path], topics: set[str] | None = None
                ) -> Iterator[tuple[str, str, int, bytes]]:
    """(topic, msgtype, log time ns, cdr) of every complete message of MCAP files read
    front to back without their summary (a truncated or damaged file, which the indexed
    readers refuse); raises :class:`BagError` at the first damaged record."""
    for path in paths:
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        try:
            with Path(path).open('rb') as handle:
                for record in StreamReader(handle).records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record.name
                    elif isinstance(record, Channel):
                        channels[record.id] = (record.topic,
                                               schemas.get(record.schema_id, ''))
                    elif isinstance(record, Message):
                        topic, msgtype = channels[record.channel_id]
                        if topics is None or topic in topics:
                            yield topic, msgtype, int(record.log_time), record.data
        except Exception as err:
            raise BagError(f'{Path(path).name}: damaged MCAP ({err or type(err).__name__})') \
                from err


_IMAGE_TOPIC = re.compile(r'^/?(?P<camera>.+?)/image(?:_raw|_rect|_rect_color|_color)?'
                          r'(?P<compressed>/compressed)?$')


class RecordingReader:
    """Read a rosbag2 recording (MCAP or sqlite3) as synchronised frame sets.

    Cameras are found from the image topics (``/<camera>/image_raw`` and the like, raw or
    compressed; if both exist for a camera the raw one is used). Images are grouped into
    sets by nearest capture time (:meth:`frames`).

    Args:
        path: the bag directory (or a recording directory with a ``bag/`` inside).
        cameras: restrict to these cameras, in this order (default: all, sorted).
        tolerance_ns: largest distance of an image's capture time from its set's reference
            time, ns; 0 (default): half the frame period (measured from the stamps).
        frame_rate: the nominal frame rate, Hz, checked against the stamps (0: none).
        time_offsets: camera name -> seconds added to its stamps (its clock offset).
        timeout_ns: message time to wait for a camera missing from a set, ns.
    """

    def __init__(self, path: str | Path, *, cameras: Iterable[str] | None = None,
                 tolerance_ns: int = 0, frame_rate: float = 0.0,
                 time_offsets: dict[str, float] | None = None,
                 timeout_ns: int = 1_000_000_000) -> None:
        path = Path(path)
        if (path / 'bag' / 'metadata.yaml').exists():
            path = path / 'bag'
        if not (path / 'metadata.yaml').exists():
            raise BagError(f'{path} is not a rosbag2 directory (no metadata.yaml)')
        self.path = path
        self.tolerance_ns = int(tolerance_ns)
        self.frame_rate = float(frame_rate)
        self.time_offsets = dict(time_offsets or {})
        self.timeout_ns = int(timeout_ns)
        self.warnings: list[str] = []
        self.sync = None
        self._wanted = list(cameras) if cameras is not None else None
        self._reader: AnyReader | None = None
        self._views: McapViews | None = None
        self._mcap_files: list[Path] = []
        self._damaged: str | None = None
        self._sizes: dict[str, tuple[int, int]] = {}  # camera -> calibrated (width, height)
        self._max_scale = 1.0
        self._to: dict[str, object] = {}   # camera -> Camera of the size to decode to

    def limit_image_sizes(self, sizes: dict[str, tuple[int, int]], *,
                          max_scale: float = MAX_RESCALE) -> None:
        """Refuse, before decoding, images of camera ``c`` whose declared size (raw header,
        PNG/JPEG header) is more than ``max_scale`` times ``sizes[c]`` = (width, height) on
        a side (``max_scale`` 1: exactly that size): bounded work per message; they are
        listed in ``FrameSet.errors``."""
        self._sizes = {str(c): (int(w), int(h)) for c, (w, h) in sizes.items()}
        self._max_scale = float(max_scale)

    def decode_to(self, cameras: dict) -> None:
        """Deliver the images of camera ``c`` at the size of ``cameras[c]`` (a ``Camera``:
        the tracker's working camera, ``Camera.at_most``), resized once while decoding
        (``decode_raw`` / ``decode_compressed`` with ``to``: no full-size copy, JPEG decoded
        at a reduced scale); other cameras as they are."""
        self._to = dict(cameras)

    def __enter__(self) -> RecordingReader:
        try:
            reader = AnyReader([self.path], default_typestore=typestore)
            reader.open()
            self._reader = reader
            self._all = {c.topic: c.msgtype for c in reader.connections}
            self._counts = {c.topic: c.msgcount for c in reader.connections}
            self._views = _views_of(self.path)
        except Exception as err:  # rosbags raises several types for damaged bags
            files = sorted(self.path.glob('*.mcap'))
            if not files:
                raise BagError(f'cannot open bag {self.path}: {err}') from err
            # A truncated MCAP has no summary section, which rosbags needs; the mcap
            # stream reader still reads every complete record before the damage.
            self._damaged = f'{err}'
            self._mcap_files = files
            self._all, self._counts = {}, {}
            try:
                for topic, msgtype, _ in self._stream(None):
                    self._all.setdefault(topic, msgtype)
                    self._counts[topic] = self._counts.get(topic, 0) + 1
            except BagError:
                pass
        self._index_topics()
        return self

    def _stream(self, topics: set[str] | None) -> Iterator[tuple[str, str, bytes]]:
        """(topic, msgtype, cdr) of every complete message of damaged MCAP files."""
        for topic, msgtype, _, data in stream_mcap(self._mcap_files, topics):
            yield topic, msgtype, data

    def _messages(self, topics: Iterable[str]) -> Iterator[tuple[str, str, bytes]]:
        """(topic, msgtype, cdr) of the messages on ``topics`` in time order: views into
        the memory-mapped files of an indexed MCAP bag (:class:`McapViews`, no copy), else
        rosbags' copies."""
        topics = set(topics)
        if self._views is not None:
            for topic, msgtype, _, view in self._views.messages(topics):
                yield topic, msgtype, view
            return
        if self._reader is None:
            yield from self._stream(topics)
            return
        conns = [c for c in self._reader.connections if c.topic in topics]
        for conn, _, raw in self._reader.messages(connections=conns):
            yield conn.topic, conn.msgtype, raw

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._views is not None:
            self._views.close()
            self._views = None
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def _index_topics(self) -> None:
        found: dict[str, tuple[str, str]] = {}
        for topic, msgtype in self._all.items():
            match = _IMAGE_TOPIC.match(topic)
            if not match or msgtype not in (IMAGE, COMPRESSED):
                continue
            cam = match['camera'].strip('/')
            if cam in found and found[cam][1] == IMAGE:
                continue  # prefer raw over compressed
            found[cam] = (topic, msgtype)
        if self._wanted is not None:
            missing = [c for c in self._wanted if c not in found]
            if missing:
                raise BagError(f'{self.path}: no image topic for camera(s) '
                               f'{", ".join(missing)}; found {", ".join(sorted(found))}')
            found = {c: found[c] for c in self._wanted}
        else:
            found = dict(sorted(found.items()))
        if not found:
            raise BagError(f'{self.path}: no sensor_msgs/Image or CompressedImage topics')
        self._connections = found
        self._by_topic = {topic: cam for cam, (topic, _) in found.items()}
        self.frame_count = max(self._counts.get(topic, 0) for topic, _ in found.values())

    @property
    def cameras(self) -> list[str]:
        return list(self._connections)

    @property
    def topics(self) -> dict[str, str]:
        """All topics of the bag with their message types."""
        return dict(self._all)

    @property
    def damaged(self) -> str | None:
        """Why the bag could only be read up to a damaged part, or None if it is intact."""
        return self._damaged

    def _decode(self, msgtype: str, raw: bytes,
                camera: str = '') -> tuple[int, np.ndarray | None, str | None]:
        """``(stamp_ns, image, error)`` of an image message's CDR bytes: the image, or
        ``None`` and why it cannot be decoded (the stamp of a readable header is kept either
        way, so that an undecodable image takes its own place in its frame set). The pixels
        are read in place (``image_view``), resized once by the decoder."""
        msg = image_view(raw, msgtype)
        limit = dict(expected=self._sizes.get(camera), max_scale=self._max_scale,
                     to=self._to.get(camera))
        try:
            if msgtype == IMAGE:
                image = decode_raw(msg.encoding, msg.height, msg.width, msg.step, msg.data,
                                   **limit)
            else:
                image = decode_compressed(msg.format, msg.data, **limit)
        except ImageConversionError as err:
            return msg.stamp_ns, None, str(err)
        return msg.stamp_ns, image, None

    def frames(self) -> Iterator[FrameSet]:
        """Yield frame sets in time order.

        Images are grouped by nearest capture time (stamp + ``time_offsets``) with the
        :class:`~mbtrack_ros.recording.sync.FrameSetSynchronizer` the live node uses: a set
        is complete when every camera has an image within the tolerance of the set's
        reference time (half a frame period by default); a camera without one is listed in
        ``missing``. Undecodable images are listed in ``errors``. A damaged bag raises
        :class:`BagError` naming the last good frame. Frame-rate warnings of the
        synchroniser are in :attr:`warnings` as they come.
        """
        from mbtrack_ros.recording.sync import FrameSetSynchronizer

        self.warnings = []
        sync = FrameSetSynchronizer(self.cameras, self.tolerance_ns,
                                    max(self.timeout_ns, self.tolerance_ns + 1),
                                    frame_rate=self.frame_rate,
                                    time_offsets={c: o for c, o in self.time_offsets.items()
                                                  if c in self.cameras})
        self.sync = sync
        index = 0
        stamps: list[int] = []  # of the frame sets, to name the ones a damage lost

        def convert(ready) -> Iterator[FrameSet]:
            nonlocal index
            self.warnings.extend(sync.warnings)
            sync.warnings.clear()
            for s in ready:
                yield FrameSet(index=index, stamp_ns=s.stamp_ns,
                               images={c: im for c, (im, _) in s.images.items()
                                       if im is not None},
                               missing=list(s.missing),
                               errors={c: e for c, (_, e) in s.images.items() if e},
                               stamps=dict(s.stamps))
                stamps.append(s.stamp_ns)
                index += 1

        iterator = self._messages(self._by_topic)
        newest = {c: 0 for c in self.cameras}
        read: dict[str, int] = {}  # image messages read per topic
        while True:
            try:
                topic, msgtype, raw = next(iterator)
            except StopIteration:
                break
            except Exception as err:  # damaged chunk, truncated file ...
                yield from convert(sync.flush())
                raise BagError(f'{self.path}: unreadable after frame set {index - 1}: '
                               f'{err}') from err
            cam = self._by_topic[topic]
            read[topic] = read.get(topic, 0) + 1
            try:
                stamp, image, error = self._decode(msgtype, raw, cam)
            except ImageConversionError as err:
                stamp, image, error = None, None, str(err)
            except Exception as err:  # undecodable CDR
                stamp, image, error = None, None, f'cannot deserialise: {err}'
            if stamp is None:  # no stamp to read: taken one step after the camera's last
                stamp = newest[cam] + 1
            newest[cam] = stamp
            yield from convert(sync.add(cam, stamp, (image, error)))
        yield from convert(sync.flush())
        if self._damaged:
            raise BagError(f'{self.path}: damaged bag, read up to frame set {index - 1} '
                           f'({self._damaged})')
        lost = {t: self._counts.get(t, 0) - read.get(t, 0) for t in self._by_topic
                if read.get(t, 0) < self._counts.get(t, 0)}
        if lost:  # a damaged chunk the reader skipped: the bag's own counts say so
            raise BagError(f'{self.path}: damaged bag, '
                           + ', '.join(f'{n} of the {self._counts[t]} images of {t}'
                                       for t, n in lost.items())
                           + f' unreadable; {_gaps(stamps)}')

    def _deserialize(self, raw: bytes, msgtype: str, topic: str):
        try:
            return typestore.deserialize_cdr(raw, msgtype)
        except Exception as err:  # rosbags' SerdeError, struct errors ... of damaged data
            raise BagError(f'{self.path}: cannot deserialise a {msgtype} message on {topic}: '
                           f'{type(err).__name__}') from err

    def _checked(self, topics: Iterable[str]) -> Iterator[tuple[str, str, bytes]]:
        """:meth:`_messages` with every read error turned into :class:`BagError`."""
        iterator = self._messages(topics)
        while True:
            try:
                item = next(iterator)
            except StopIteration:
                return
            except BagError:
                raise
            except Exception as err:  # damaged chunk, truncated file ...
                raise BagError(f'{self.path}: unreadable: {type(err).__name__}: '
                               f'{str(err)[:200]}') from err
            yield item

    def camera_infos(self) -> dict[str, object]:
        """The first CameraInfo message of every camera that has one (rosbags objects)."""
        infos: dict[str, object] = {}
        topics = [t for t, m in self._all.items()
                  if m == CAMERA_INFO and t.endswith('/camera_info')]
        for topic, _, raw in self._checked(topics):
            cam = topic[: -len('/camera_info')].strip('/')
            if cam not in infos:
                infos[cam] = self._deserialize(raw, CAMERA_INFO, topic)
            if len(infos) == len(topics):
                break
        return infos

    def ground_truth(self) -> list[GroundTruthRow]:
        """Ground truth stored on :data:`GROUND_TRUTH_TOPIC` (empty list if none)."""
        rows: list[GroundTruthRow] = []
        if GROUND_TRUTH_TOPIC not in self._all:
            return rows
        for frame, (_, _, raw) in enumerate(self._checked([GROUND_TRUTH_TOPIC])):
            msg = self._deserialize(raw, POINT_CLOUD, GROUND_TRUTH_TOPIC)
            data = np.asarray(msg.data, dtype=np.uint8).tobytes()
            if msg.width * _GT_DTYPE.itemsize > len(data):
                raise BagError(f'{self.path}: ground truth message {frame} declares '
                               f'{msg.width} points in {len(data)} bytes')
            pts = np.frombuffer(data, dtype=_GT_DTYPE, count=msg.width)
            stamp = _stamp_ns(msg.header)
            rows.extend(GroundTruthRow(stamp, frame, int(p['id']), float(p['x']),
                                       float(p['y']), float(p['z_head']),
                                       bool(p['sitting'] > 0.5), ()) for p in pts)
        return rows


def _views_of(bag: Path) -> McapViews | None:
    """The messages of the rosbag2 bag directory ``bag`` read in place (:class:`McapViews`)
    when its metadata names MCAP files without rosbag2 compression, else None (rosbags
    reads them)."""
    import yaml

    try:
        info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        if info.get('storage_identifier') != 'mcap' or info.get('compression_mode'):
            return None
        return McapViews([bag / PurePath(name).name for name in info['relative_file_paths']])
    except (McapViewError, OSError, yaml.YAMLError, KeyError, TypeError):
        return None


def _gaps(stamps: list[int], shown: int = 3) -> str:
    """Where frame sets are missing: the stamp gaps longer than 1.5 frame periods (the
    median step) between the frame sets read, or after the last one."""
    if len(stamps) < 2:
        return f'read {len(stamps)} frame set(s)'
    steps = np.diff(np.asarray(stamps, dtype=np.int64))
    period = float(np.median(steps))
    big = np.flatnonzero(steps > 1.5 * period)
    if big.size == 0:
        return (f'frame sets after frame set {len(stamps) - 1} (stamp {stamps[-1]}) or '
                'within a frame set lost')
    parts = [f'between frame sets {i} and {i + 1} (stamps {stamps[i]} .. {stamps[i + 1]}, '
             f'~{round(steps[i] / period) - 1} lost)' for i in big[:shown]]
    more = f' and {big.size - shown} more gap(s)' if big.size > shown else ''
    return 'frame sets lost ' + '; '.join(parts) + more


_T_item = TypeVar('_T_item')


def prefetched(items: Iterable[_T_item], depth: int = 4) -> Iterator[_T_item]:
    """Iterate ``items`` in a background thread, at most ``depth`` items ahead, in order.

    For :meth:`RecordingReader.frames`: reading, decompressing and decoding the next frame
    sets overlaps with the caller's work on the current one (zstd/lz4, numpy copies and the
    numba/OpenCV work of the caller release the GIL). An exception raised by ``items``
    (e.g. :class:`BagError` at a damaged chunk) is raised here after every item produced
    before it, so the caller sees the same sequence as without prefetching. Closing the
    iterator early (``break``) stops the thread at its next item.
    """
    if depth < 1:
        raise ValueError(f'depth must be >= 1, got {depth}')
    slots: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(entry: tuple) -> bool:
        while not stop.is_set():
            try:
                slots.put(entry, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        try:
            for item in items:
                if not put(('item', item)):
                    return
            put(('end', None))
        except BaseException as err:  # handed to the consumer, raised there in order
            put(('error', err))

    thread = threading.Thread(target=work, name='prefetch', daemon=True)
    thread.start()
    try:
        while True:
            kind, value = slots.get()
            if kind == 'item':
                yield value
            elif kind == 'end':
                return
            else:
                raise value
    finally:
        stop.set()
        thread.join(timeout=5.0)
