"""Readers of foreign camera-calibration formats into a ``core.camera.RoomCalibration``.

Three sources are understood:

* **OpenCV style** (:func:`read_opencv_calibration`): JSON, YAML, Pose2Sim TOML or an OpenCV
  ``FileStorage`` YAML (``%YAML``, ``!!opencv-matrix``), one entry per camera with an
  intrinsic matrix, distortion, a world -> camera rotation (3x3 or Rodrigues vector) and
  translation, and the image size ``[width, height]``; ``x_cam = R X_world + t``.
* **ROS camera_info YAML** (:func:`read_camera_info`, camera_calibration_parsers format) for
  the intrinsics of one camera, combined with extrinsics from another source by
  :func:`read_camera_info_calibration`.
* **Qualisys** ``.qca.txt`` (:func:`read_qualisys_calibration`), conventions in its docstring.

Every reader can re-express the world frame so that the floor is ``z = 0`` and ``z`` points up
(:func:`reexpress_world`: ``up_axis`` names the source axis that points up, ``floor_offset``
the floor's coordinate along it). The projection itself stays in :mod:`mbtrack_ros.core.camera`.
Every malformed file raises :class:`CalibrationError` with a one-line reason naming the file.

:func:`load_calibration` is the one validation layer every command and ``tracker_node`` read
their calibration through: the readers check types, finiteness and ranges (image sides up to
``MAX_IMAGE_SIDE``, a floor side up to ``MAX_FLOOR_SIDE`` metres, entry zones and exits as
4 finite numbers), then :func:`~mbtrack_ros.core.camera.check_floor_views` warns about a
camera that sees less than ``MIN_FLOOR_VIEW`` of the floor and refuses a room where no
camera sees it. Messages are one line naming the file, the camera and the key.
"""
from __future__ import annotations

import json
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from mbtrack_ros.core.camera import (
    CalibrationError, Camera, RoomCalibration, check_floor_views, yaml_error_line)

__all__ = [
    'FORMATS', 'UP_AXES', 'CalibrationError', 'Intrinsics', 'default_floor',
    'load_calibration', 'read_calibration',
    'read_camera_info', 'read_camera_info_calibration', 'read_opencv_calibration',
    'read_qualisys_calibration', 'reexpress_world', 'world_rotation',
]

#: calibration formats accepted by :func:`read_calibration` (and ``--calibration-format``)
FORMATS = ('opencv', 'camera-info', 'qualisys')
#: values of ``up_axis``: the source-frame axis (with sign) that points away from the floor
UP_AXES = ('z', '-z', 'y', '-y', 'x', '-x')

# Accepted key spellings of an OpenCV-style camera entry (first match wins).
_KEYS = {
    'K': ('K', 'camera_matrix', 'cameraMatrix', 'matrix', 'intrinsics', 'intrinsic'),
    'dist': ('dist', 'D', 'distortion', 'distortions', 'distortion_coefficients',
             'dist_coeffs', 'distCoeffs'),
    'R': ('R', 'rotation', 'rotation_matrix', 'rvec'),
    't': ('t', 'T', 'translation', 'tvec'),
    'size': ('image_size', 'size', 'imageSize', 'resolution'),
    'width': ('image_width', 'width'),
    'height': ('image_height', 'height'),
}


@dataclass(frozen=True)
class Intrinsics:
    """Intrinsics of one camera from a camera_info file.

    Attributes:
        name: ``camera_name`` of the file (may be empty).
        width, height: image size, pixels.
        K: (3, 3) intrinsic matrix, pixels.
        dist: (<= 5,) plumb_bob coefficients ``[k1, k2, p1, p2, k3]``.
    """

    name: str
    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray


# -- world frame -------------------------------------------------------------------------------

def world_rotation(up_axis: str) -> np.ndarray:
    """Proper rotation (3, 3) ``A`` taking source coordinates to ``z``-up ones: ``X' = A X``.

    ``+e_i`` up uses the cyclic permutation ``(e_{i+1}, e_{i+2}, e_i)`` (so ``'y'`` maps a
    Y-up frame ``(x, y, z)`` to ``(z, x, y)``, the TRC -> room convention); ``-e_i`` up uses
    ``(e_{i+1}, -e_{i+2}, -e_i)`` (``'-z'`` is a half turn about x).
    """
    axis = str(up_axis).strip().lower()
    if axis not in UP_AXES:
        raise CalibrationError(f'up_axis must be one of {", ".join(UP_AXES)}, got {up_axis!r}')
    i = 'xyz'.index(axis[-1])
    eye = np.eye(3)
    if axis.startswith('-'):
        return np.stack([eye[(i + 1) % 3], -eye[(i + 2) % 3], -eye[i]])
    return np.stack([eye[(i + 1) % 3], eye[(i + 2) % 3], eye[i]])


def reexpress_world(calibration: RoomCalibration, *, up_axis: str = 'z',
                    floor_offset: float = 0.0,
                    floor: tuple[float, float, float, float] | None = None) -> RoomCalibration:
    """Re-express a calibration in a world frame with the floor at ``z = 0`` and ``z`` up.

    New world points are ``X' = A X - (0, 0, floor_offset)`` with ``A = world_rotation(up_axis)``
    (``floor_offset``: the floor's coordinate along the up axis in the source frame, metres).
    Cameras keep their images: ``R' = R A^T``, ``t' = t + R' (0, 0, floor_offset)``.
    ``floor`` (new frame, metres) defaults to :func:`default_floor` of the moved cameras;
    entry zones are kept only if the frame does not change; exits (which must share the
    floor's border) only if the floor does not change either.
    """
    A = world_rotation(up_axis)
    if not np.isfinite(floor_offset):
        raise CalibrationError(f'floor_offset must be finite, got {floor_offset}')
    shift = np.array([0.0, 0.0, float(floor_offset)])
    cameras = {}
    for name, cam in calibration.cameras.items():
        R = cam.R @ A.T
        cameras[name] = replace(cam, R=R, t=cam.t + R @ shift)
    moved = replace(calibration, cameras=cameras)
    identity = bool(np.allclose(A, np.eye(3)) and floor_offset == 0.0)
    if identity and floor is None:
        return moved
    return replace(moved, floor=tuple(floor) if floor is not None
                   else default_floor(cameras.values()),
                   entry_zones=calibration.entry_zones if identity else (),
                   exits=())


def default_floor(cameras: Iterable[Camera], *, margin: float = 0.0
                  ) -> tuple[float, float, float, float]:
    """Floor rectangle ``(x_min, y_min, x_max, y_max)`` spanned by the camera centres, metres.

    Cameras of a smart room stand around the walkable area, so the bounding box of their
    floor positions is a conservative walkable floor; widened by ``margin`` on every side.
    Falls back to a 1 m square around a single camera.
    """
    centres = np.array([c.center for c in cameras])
    lo, hi = centres[:, :2].min(axis=0) - margin, centres[:, :2].max(axis=0) + margin
    hi = np.where(hi - lo < 1e-6, lo + 1.0, hi)
    return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))


def _finish(cameras: list[Camera], source: Path, *, up_axis: str, floor_offset: float,
            floor: tuple[float, float, float, float] | None) -> RoomCalibration:
    names = [c.name for c in cameras]
    if not cameras:
        raise CalibrationError(f'{source}: no cameras found')
    if len(set(names)) != len(names):
        raise CalibrationError(f'{source}: duplicate camera names in {names}')
    cams = {c.name: c for c in cameras}
    try:
        room = RoomCalibration(cameras=cams, floor=floor or default_floor(cams.values()))
        if np.allclose(world_rotation(up_axis), np.eye(3)) and floor_offset == 0.0:
            return room
        return reexpress_world(room, up_axis=up_axis, floor_offset=floor_offset, floor=floor)
    except CalibrationError as err:
        raise CalibrationError(f'{source}: {err}') from err


# -- small parsing helpers -----------------------------------------------------------------------

def _read_text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding='utf-8')
    except FileNotFoundError as err:
        raise CalibrationError(f'{what} {path} does not exist') from err
    except (OSError, UnicodeDecodeError) as err:
        raise CalibrationError(f'cannot read {what} {path}: {err}') from err


def _matrix(value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    if isinstance(value, Mapping) and 'data' in value:  # camera_info {rows, cols, data}
        value = value['data']
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise CalibrationError(f'{what}: expected numbers, got {value!r:.60}') from err
    if array.size != int(np.prod(shape)):
        raise CalibrationError(f'{what}: expected {int(np.prod(shape))} numbers, '
                               f'got {array.size}')
    if not np.all(np.isfinite(array)):
        raise CalibrationError(f'{what}: contains non-finite values')
    return array.reshape(shape)


def _lookup(entry: Mapping[str, Any], key: str) -> Any:
    for alias in _KEYS[key]:
        if alias in entry:
            return entry[alias]
    return None


def _filestorage_to_python(node: Any) -> Any:
    """Convert an OpenCV ``FileNode`` tree to dicts, lists, arrays and scalars."""
    if node.isMap():
        return {k: _filestorage_to_python(node.getNode(k)) for k in node.keys()}
    if node.isSeq():
        return [_filestorage_to_python(node.at(i)) for i in range(node.size())]
    if node.isString():
        return node.string()
    if node.isInt():
        return int(node.real())
    if node.isReal():
        return node.real()
    mat = node.mat()
    return None if mat is None else np.asarray(mat, dtype=np.float64)


def _load_document(path: Path) -> Any:
    """Parse a JSON / YAML / TOML / OpenCV FileStorage file into Python objects."""
    text = _read_text(path, 'calibration file')
    suffix = path.suffix.lower()
    try:
        if text.lstrip().startswith('%YAML') or '!!opencv-matrix' in text:  # cv::FileStorage
            fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
            try:
                return _filestorage_to_python(fs.root())
            finally:
                fs.release()
        if suffix == '.json':
            return json.loads(text)
        if suffix == '.toml':
            return tomllib.loads(text)
        return yaml.safe_load(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError, yaml.YAMLError, cv2.error) as err:
        first = (yaml_error_line(err) if isinstance(err, yaml.YAMLError)
                 else str(err).strip().splitlines()[0] if str(err).strip()
                 else type(err).__name__)
        raise CalibrationError(
            f'{path}: not a readable {suffix or "YAML"} file ({first})') from err


def _camera_entries(doc: Any, path: Path) -> list[tuple[str, Mapping[str, Any]]]:
    """(name, entry) pairs of a document: a mapping name -> entry or a list of entries."""
    if isinstance(doc, Mapping) and isinstance(doc.get('cameras'), (list, Mapping)):
        doc = doc['cameras']
    if isinstance(doc, Mapping):
        items = [(str(k), v) for k, v in doc.items()
                 if isinstance(v, Mapping) and k not in ('metadata',)]
        out = []
        for key, value in items:
            out.append((str(value.get('name', value.get('camera_name', key))), value))
        return out
    if isinstance(doc, list):
        out = []
        for i, value in enumerate(doc):
            if not isinstance(value, Mapping):
                raise CalibrationError(f'{path}: camera entry {i} is not a mapping')
            out.append((str(value.get('name', value.get('camera_name', f'cam{i}'))), value))
        return out
    raise CalibrationError(f'{path}: expected a mapping or list of cameras, '
                           f'got {type(doc).__name__}')


def _extrinsics(entry: Mapping[str, Any], what: str) -> tuple[np.ndarray, np.ndarray]:
    if 'extrinsics' in entry and isinstance(entry['extrinsics'], Mapping):
        entry = entry['extrinsics']
    rot, trans = _lookup(entry, 'R'), _lookup(entry, 't')
    if rot is None or trans is None:
        raise CalibrationError(f'{what}: needs a rotation (R) and a translation (t)')
    rot = np.asarray(rot['data'] if isinstance(rot, Mapping) else rot, dtype=object)
    if rot.size == 3:  # Rodrigues vector (Pose2Sim TOML, OpenCV rvec)
        R, _ = cv2.Rodrigues(_matrix(rot.tolist(), (3, 1), f'{what}.rvec'))
    else:
        R = _matrix(rot.tolist(), (3, 3), f'{what}.R')
    return R, _matrix(trans, (3,), f'{what}.t')


def _image_size(entry: Mapping[str, Any], what: str) -> tuple[int, int]:
    size = _lookup(entry, 'size')
    if size is not None:
        values = _matrix(size, (2,), f'{what}.image_size')
        width, height = values
    else:
        width, height = _lookup(entry, 'width'), _lookup(entry, 'height')
        if width is None or height is None:
            raise CalibrationError(f'{what}: needs image_size [width, height]')
        width, height = _matrix(width, (1,), what)[0], _matrix(height, (1,), what)[0]
    if width != round(width) or height != round(height) or width <= 0 or height <= 0:
        raise CalibrationError(f'{what}: image size must be positive integers, '
                               f'got {width} x {height}')
    return int(width), int(height)


def _distortion(value: Any, what: str) -> np.ndarray:
    if value is None:
        return np.zeros(5)
    if isinstance(value, Mapping) and 'data' in value:
        value = value['data']
    dist = np.asarray(value, dtype=np.float64).ravel() if not isinstance(value, str) else None
    if dist is None or not np.all(np.isfinite(dist)):
        raise CalibrationError(f'{what}: distortion must be finite numbers')
    if dist.size > 5:
        if np.any(dist[5:] != 0):
            raise CalibrationError(f'{what}: only plumb_bob [k1, k2, p1, p2, k3] distortion is '
                                   f'supported, got {dist.size} non-zero coefficients')
        dist = dist[:5]
    return dist


def _make_camera(name: str, width: int, height: int, K: np.ndarray, dist: np.ndarray,
                 R: np.ndarray, t: np.ndarray, what: str) -> Camera:
    if not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0 or K[2, 0] != 0:
        raise CalibrationError(f'{what}: K is not an upper-triangular intrinsic matrix')
    try:
        return Camera(name=name, width=width, height=height, K=K, dist=dist, R=R, t=t)
    except CalibrationError as err:
        raise CalibrationError(f'{what}: {err}') from err


# -- OpenCV style --------------------------------------------------------------------------------

def read_opencv_calibration(path: str | Path, *, up_axis: str = 'z', floor_offset: float = 0.0,
                            floor: tuple[float, float, float, float] | None = None,
                            units: float = 1.0) -> RoomCalibration:
    """Read an OpenCV-style calibration (JSON, YAML, Pose2Sim TOML, OpenCV FileStorage).

    The document is a mapping ``name -> entry`` (or a list of entries with ``name``, or the
    same under a ``cameras`` key). Each entry holds ``K`` (3x3, pixels), ``dist``
    (``[k1, k2, p1, p2[, k3]]``, optional), ``R`` (3x3 world -> camera, or a Rodrigues
    vector), ``t`` (3,) and ``image_size = [width, height]`` (or ``width``/``height``);
    ``x_cam = R X_world + t``. ``units`` converts ``t`` to metres (``0.001`` for mm).
    Options ``up_axis``/``floor_offset``/``floor``: see :func:`reexpress_world`.
    """
    path = Path(path)
    doc = _load_document(path)
    cameras = []
    for name, entry in _camera_entries(doc, path):
        what = f'{path}: camera {name}'
        K = _lookup(entry, 'K')
        if K is None:
            raise CalibrationError(f'{what}: needs an intrinsic matrix K')
        K = _matrix(K, (3, 3), f'{what}.K')
        R, t = _extrinsics(entry, what)
        width, height = _image_size(entry, what)
        cameras.append(_make_camera(name, width, height, K,
                                    _distortion(_lookup(entry, 'dist'), what), R,
                                    t * float(units), what))
    return _finish(cameras, path, up_axis=up_axis, floor_offset=floor_offset, floor=floor)


# -- ROS camera_info ------------------------------------------------------------------------------

def read_camera_info(path: str | Path) -> Intrinsics:
    """Read one ROS ``camera_info`` YAML (camera_calibration_parsers format).

    Keys: ``image_width``, ``image_height``, ``camera_name``, ``camera_matrix``
    ``{rows: 3, cols: 3, data: [...]}``, ``distortion_model`` (``plumb_bob`` or
    ``rational_polynomial`` with zero extra terms), ``distortion_coefficients``; the
    rectification and projection matrices are ignored (the cameras are unrectified).
    """
    path = Path(path)
    text = _read_text(path, 'camera_info file')
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise CalibrationError(f'{path}: not valid YAML ({yaml_error_line(err)})') from err
    if not isinstance(doc, Mapping):
        raise CalibrationError(f'{path}: not a camera_info YAML (expected a mapping)')
    missing = [k for k in ('image_width', 'image_height', 'camera_matrix') if k not in doc]
    if missing:
        raise CalibrationError(f'{path}: not a camera_info YAML (missing {", ".join(missing)})')
    model = str(doc.get('distortion_model', 'plumb_bob') or 'plumb_bob')
    if model not in ('plumb_bob', 'rational_polynomial'):
        raise CalibrationError(f'{path}: unsupported distortion_model {model!r} '
                               f'(plumb_bob only)')
    what = str(path)
    K = _matrix(doc['camera_matrix'], (3, 3), f'{what}: camera_matrix')
    width, height = _image_size(doc, what)
    dist = _distortion(doc.get('distortion_coefficients'), what)
    return Intrinsics(name=str(doc.get('camera_name', '') or ''), width=width, height=height,
                      K=K, dist=dist)


def read_camera_info_calibration(
        intrinsics: Mapping[str, str | Path] | Sequence[str | Path],
        extrinsics: str | Path | Mapping[str, tuple[Any, Any]], *, up_axis: str = 'z',
        floor_offset: float = 0.0, floor: tuple[float, float, float, float] | None = None,
        units: float = 1.0) -> RoomCalibration:
    """Combine per-camera ``camera_info`` intrinsics with extrinsics from another source.

    ``intrinsics``: camera name -> camera_info YAML (or a list of files named by their
    ``camera_name``). ``extrinsics``: a mapping name -> ``(R (3, 3), t (3,))`` or an
    OpenCV-style file (see :func:`read_opencv_calibration`) whose ``R``/``t`` are used and
    whose intrinsics, if any, are ignored. Cameras come in the order of ``intrinsics``.
    """
    if isinstance(intrinsics, Mapping):
        infos = {str(n): read_camera_info(p) for n, p in intrinsics.items()}
        source = Path(next(iter(intrinsics.values()), '.'))
    else:
        infos = {}
        for p in intrinsics:
            info = read_camera_info(p)
            if not info.name:
                raise CalibrationError(f'{p}: no camera_name; pass intrinsics as name -> file')
            infos[info.name] = info
        source = Path(intrinsics[0]) if intrinsics else Path('.')
    if not infos:
        raise CalibrationError('no camera_info files given')
    if isinstance(extrinsics, Mapping):
        try:
            pairs = {str(n): tuple(pose) for n, pose in extrinsics.items()}
        except TypeError as err:
            raise CalibrationError('extrinsics must map camera names to (R, t)') from err
        bad = [n for n, pose in pairs.items() if len(pose) != 2]
        if bad:
            raise CalibrationError(f'extrinsics of camera {bad[0]} must be a pair (R, t)')
        poses = {n: (_matrix(R, (3, 3), f'{n}.R'), _matrix(t, (3,), f'{n}.t'))
                 for n, (R, t) in pairs.items()}
        ext_source = 'the extrinsics'
    else:
        ext_path = Path(extrinsics)
        ext_source = str(ext_path)
        poses = {name: _extrinsics(entry, f'{ext_path}: camera {name}')
                 for name, entry in _camera_entries(_load_document(ext_path), ext_path)}
    missing = [n for n in infos if n not in poses]
    if missing:
        raise CalibrationError(f'no extrinsics for camera(s) {", ".join(missing)} in '
                               f'{ext_source} (it has {", ".join(poses) or "none"})')
    cameras = [_make_camera(n, i.width, i.height, i.K, i.dist, poses[n][0],
                            poses[n][1] * float(units), f'camera {n}')
               for n, i in infos.items()]
    return _finish(cameras, source, up_axis=up_axis, floor_offset=floor_offset, floor=floor)


# -- Qualisys -------------------------------------------------------------------------------------

_QCA_SUBPIXEL = 64.0  # Qualisys sensor coordinates are in 1/64 pixel


def read_qualisys_calibration(path: str | Path, *, up_axis: str = 'z',
                              floor_offset: float = 0.0,
                              floor: tuple[float, float, float, float] | None = None
                              ) -> RoomCalibration:
    """Read a Qualisys Track Manager calibration export (``.qca.txt``, XML).

    Conventions (worked out from ``Calib.qca.txt`` of the Pose2Sim demo and checked against
    its ``calibration_opencv.json`` and the projected reference keypoints):

    * ``<camera serial=...>`` names the camera; inactive cameras (``active="0"``) are skipped.
    * ``<transform x y z>`` is the camera centre in the world frame, **millimetres**.
    * ``r11 .. r33``: the camera -> world rotation stored column by column, i.e. read row by
      row ``[[r11, r12, r13], [r21, r22, r23], [r31, r32, r33]]`` is the world -> Qualisys
      camera rotation.
    * the Qualisys camera frame has x right, y up and looks along **-z**; the OpenCV optical
      frame (x right, y down, z forward) is ``diag(1, -1, -1)`` times it, so
      ``R = diag(1, -1, -1) [r_ij]`` and ``t = -R C / 1000``.
    * ``<intrinsic>``: ``focalLengthU/V`` and ``centerPointU/V`` are in 1/64 pixel on the
      sensor; the principal point is relative to the ``fov_video`` window
      (``cx = centerPointU / 64 - left``); the image is ``right - left + 1`` by
      ``bottom - top + 1`` pixels.
    * ``radialDistortion1..3``, ``tangentalDistortion1..2`` are divided by 64 into OpenCV's
      ``k1, k2, k3, p1, p2`` as Pose2Sim's converter does: its triangulated reference
      keypoints (and the OpenCV JSON) were made with this reading.
    * the world frame is Z up with the floor near Z = 0 (so the defaults need no re-expression).
    """
    path = Path(path)
    text = _read_text(path, 'Qualisys calibration')
    try:
        root = ET.fromstring(text.encode('utf-8'))
    except ET.ParseError as err:
        raise CalibrationError(f'{path}: not a Qualisys XML calibration ({err})') from err
    nodes = root.findall('cameras/camera') if root.tag == 'calibration' else []
    if not nodes:
        raise CalibrationError(f'{path}: no <calibration><cameras><camera> elements '
                               f'(not a Qualisys .qca.txt file)')
    flip = np.diag([1.0, -1.0, -1.0])
    cameras = []
    for index, node in enumerate(nodes):
        name = node.get('serial') or f'cam{index}'
        what = f'{path}: camera {name}'
        if node.get('active', '1').strip() == '0':
            continue
        transform, intrinsic = node.find('transform'), node.find('intrinsic')
        fov = node.find('fov_video')
        if transform is None or intrinsic is None or fov is None:
            raise CalibrationError(f'{what}: needs <transform>, <intrinsic> and <fov_video>')

        def num(element: ET.Element, key: str, default: float | None = None) -> float:
            value = element.get(key)
            if value is None:
                if default is not None:
                    return default
                raise CalibrationError(f'{what}: <{element.tag}> misses {key}')
            try:
                result = float(value)
            except ValueError as err:
                raise CalibrationError(f'{what}: <{element.tag}> {key}={value!r} is not a '
                                       f'number') from err
            if not np.isfinite(result):
                raise CalibrationError(f'{what}: <{element.tag}> {key} is not finite')
            return result

        rq = np.array([[num(transform, f'r{i}{j}') for j in (1, 2, 3)] for i in (1, 2, 3)])
        centre = np.array([num(transform, k) for k in 'xyz']) / 1000.0  # mm -> m
        R = flip @ rq
        t = -R @ centre
        left, top = num(fov, 'left'), num(fov, 'top')
        width = int(num(fov, 'right') - left + 1)
        height = int(num(fov, 'bottom') - top + 1)
        K = np.array([
            [num(intrinsic, 'focalLengthU') / _QCA_SUBPIXEL,
             num(intrinsic, 'skew', 0.0) / _QCA_SUBPIXEL,
             num(intrinsic, 'centerPointU') / _QCA_SUBPIXEL - left],
            [0.0, num(intrinsic, 'focalLengthV') / _QCA_SUBPIXEL,
             num(intrinsic, 'centerPointV') / _QCA_SUBPIXEL - top],
            [0.0, 0.0, 1.0]])
        dist = np.array([num(intrinsic, 'radialDistortion1', 0.0),
                         num(intrinsic, 'radialDistortion2', 0.0),
                         num(intrinsic, 'tangentalDistortion1', 0.0),
                         num(intrinsic, 'tangentalDistortion2', 0.0),
                         num(intrinsic, 'radialDistortion3', 0.0)]) / _QCA_SUBPIXEL
        if width <= 0 or height <= 0:
            raise CalibrationError(f'{what}: empty <fov_video> window')
        if not np.allclose(rq @ rq.T, np.eye(3), atol=1e-5):
            raise CalibrationError(f'{what}: r11..r33 is not a rotation matrix')
        cameras.append(_make_camera(name, width, height, K, dist, R, t, what))
    return _finish(cameras, path, up_axis=up_axis, floor_offset=floor_offset, floor=floor)


# -- dispatch -------------------------------------------------------------------------------------

def read_calibration(path: str | Path, fmt: str = 'auto', *,
                     camera_info: Mapping[str, str | Path] | None = None,
                     up_axis: str = 'z', floor_offset: float = 0.0,
                     floor: tuple[float, float, float, float] | None = None) -> RoomCalibration:
    """Read any supported calibration; ``fmt`` is one of :data:`FORMATS`, ``'room'`` or ``'auto'``.

    ``'auto'``: ``*.qca.txt``/XML -> qualisys; an mbtrack room calibration YAML -> room;
    otherwise opencv. ``'camera-info'`` needs ``camera_info`` (name -> YAML) and takes the
    extrinsics from ``path``.
    """
    path = Path(path)
    fmt = str(fmt).strip().lower()
    if fmt == 'auto':
        text = _read_text(path, 'calibration file')
        if path.name.lower().endswith('.qca.txt') or text.lstrip().startswith('<'):
            fmt = 'qualisys'
        elif 'mbtrack_ros/room_calibration' in text:
            fmt = 'room'
        else:
            fmt = 'camera-info' if camera_info else 'opencv'
    options = dict(up_axis=up_axis, floor_offset=floor_offset, floor=floor)
    if fmt == 'room':
        room = RoomCalibration.load(path)
        if up_axis == 'z' and floor_offset == 0.0 and floor is None:
            return room
        return reexpress_world(room, **options)
    if fmt == 'opencv':
        return read_opencv_calibration(path, **options)
    if fmt == 'qualisys':
        return read_qualisys_calibration(path, **options)
    if fmt == 'camera-info':
        if not camera_info:
            raise CalibrationError('camera-info format needs camera_info files (name=YAML)')
        return read_camera_info_calibration(camera_info, path, **options)
    raise CalibrationError(f'unknown calibration format {fmt!r} '
                           f'(one of {", ".join(FORMATS)}, room, auto)')


def load_calibration(path: str | Path, fmt: str = 'auto', *,
                     warn: Callable[[str], None] | None = None,
                     **options: Any) -> RoomCalibration:
    """Read a calibration (:func:`read_calibration`, same ``fmt`` and options) and check that
    its cameras see the floor (:func:`~mbtrack_ros.core.camera.check_floor_views`).

    ``warn`` receives one line per camera that sees too little of the floor. Raises
    :class:`CalibrationError` (one line naming the file, the camera and the key) for every
    unusable file, including one where no camera sees the floor.
    """
    calibration = read_calibration(path, fmt, **options)
    for line in check_floor_views(calibration, str(path)):
        if warn is not None:
            warn(line)
    return calibration
