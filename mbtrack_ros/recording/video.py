"""Import synchronised video files of a calibrated rig into a recording directory.

A recording directory has the same layout as ``mbtrack synth`` writes::

    OUTDIR/bag/               rosbag2 (MCAP) written by RecordingWriter (with the reference
                              also on the ground-truth topic)
    OUTDIR/calibration.yaml   the cameras, scaled to the imported image size
    OUTDIR/recording.yaml     source videos, offsets, frames, fps, size, cameras
    OUTDIR/ground_truth.csv   only with a reference (Pose2Sim TRC keypoints)

Policies (checked before anything is written; each violation is one :class:`VideoImportError`
line):

* every calibrated camera must have a video unless videos are given as ``name=path``;
* frame counts after the start offsets must agree, unless ``shortest`` (cut all to the
  shortest) or ``max_frames`` no larger than the shortest is given;
* a video whose size differs from its calibration is accepted only if it is a pure scale of
  it (same aspect ratio to within a pixel); the camera is then scaled, and a note says so.
  ``fit_size`` also accepts other sizes by stretching the intrinsics (x and y scaled
  independently; right for a resampled video, wrong by up to the difference for a cropped one).
"""
from __future__ import annotations

import math
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from mbtrack_ros.core.camera import Camera, RoomCalibration
from mbtrack_ros.recording.calibration_io import world_rotation
from mbtrack_ros.recording.csvfiles import GroundTruthRow, write_ground_truth

__all__ = [
    'EPOCH_NS', 'ImportSummary', 'TrcData', 'VideoImportError', 'VideoInfo', 'fit_camera',
    'import_videos', 'probe_video', 'read_trc', 'reference_ground_truth', 'resize_frame',
    'trc_to_room',
]


#: default stamp of the first imported frame set (the epoch synthetic recordings use), ns
EPOCH_NS = 1_700_000_000 * 1_000_000_000


class VideoImportError(ValueError):
    """A user error in a video import (one-line message)."""


# -- videos ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class VideoInfo:
    """What OpenCV reports about a video file.

    Attributes:
        path: the file.
        width, height: decoded frame size, pixels.
        frame_count: number of frames (counted by decoding if the container does not say).
        fps: frames per second from the container (0 if unknown).
    """

    path: Path
    width: int
    height: int
    frame_count: int
    fps: float


def _open(path: Path) -> cv2.VideoCapture:
    if not path.exists():
        raise VideoImportError(f'video {path} does not exist')
    if path.is_dir():
        raise VideoImportError(f'video {path} is a directory, not a video file')
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise VideoImportError(f'cannot open video {path} (not a format OpenCV reads)')
    return capture


def probe_video(path: str | Path) -> VideoInfo:
    """Open a video and read its size, frame count and frame rate."""
    path = Path(path)
    capture = _open(path)
    try:
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        fps = float(capture.get(cv2.CAP_PROP_FPS) or 0.0)
        ok, frame = capture.read()
        if not ok or frame is None:
            raise VideoImportError(f'video {path} has no decodable frame')
        height, width = frame.shape[:2]
        if count <= 0:  # container does not say: count by decoding
            count = 1
            while capture.grab():
                count += 1
    finally:
        capture.release()
    return VideoInfo(path=path, width=int(width), height=int(height), frame_count=count,
                     fps=fps if math.isfinite(fps) and fps > 0 else 0.0)


def resize_frame(bgr: np.ndarray, width: int, height: int) -> np.ndarray:
    """Decoded OpenCV frame ``(h, w, 3)`` BGR -> ``(height, width, 3) uint8`` RGB.

    Shrinking uses pixel-area averaging (``INTER_AREA``), enlarging bilinear interpolation.
    """
    if bgr.ndim == 2:
        bgr = cv2.cvtColor(bgr, cv2.COLOR_GRAY2BGR)
    h, w = bgr.shape[:2]
    if (w, h) != (width, height):
        shrink = width * height < w * h
        bgr = cv2.resize(bgr, (width, height),
                         interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    return np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))


def fit_camera(camera: Camera, width: int, height: int, *, fit_size: bool = False
               ) -> tuple[Camera, str | None]:
    """The camera for a video of ``width`` x ``height`` pixels, and a note if it changed.

    Same size: unchanged. Same aspect ratio (the scale factors differ by less than one pixel
    over the image): scaled with :meth:`Camera.scaled`. Otherwise :class:`VideoImportError`,
    or, with ``fit_size``, stretched with independent x/y scales.
    """
    cw, ch = camera.width, camera.height
    if (width, height) == (cw, ch):
        return camera, None
    sx, sy = width / cw, height / ch
    pure = abs(sx - sy) * max(cw, ch) < 1.0
    if pure:
        return camera.scaled(width, height), (
            f'{camera.name}: video is {width}x{height}, calibration {cw}x{ch}: same aspect '
            f'ratio, calibration scaled by {sx:.4g}')
    if not fit_size:
        raise VideoImportError(
            f'{camera.name}: video is {width}x{height} but the calibration is {cw}x{ch} '
            f'(aspect ratio differs, not a pure scale); pass --fit-size to stretch the '
            f'calibration to the video')
    return camera.scaled(width, height), (
        f'{camera.name}: video is {width}x{height}, calibration {cw}x{ch}: calibration '
        f'stretched by {sx:.4g} x {sy:.4g} (--fit-size)')


# -- Pose2Sim TRC reference --------------------------------------------------------------------

@dataclass(frozen=True)
class TrcData:
    """Keypoints of a ``.trc`` file (OpenSim / Pose2Sim).

    Attributes:
        markers: marker names, in file order.
        rate: data rate, frames per second.
        frames: (F,) frame numbers of the file (``Frame#``, usually from 1).
        times: (F,) seconds.
        points: (F, M, 3) float64 marker positions in the file's frame, metres (NaN missing).
    """

    markers: tuple[str, ...]
    rate: float
    frames: np.ndarray
    times: np.ndarray
    points: np.ndarray

    def marker(self, name: str) -> np.ndarray:
        """(F, 3) trajectory of one marker; :class:`VideoImportError` if absent."""
        try:
            return self.points[:, self.markers.index(name)]
        except ValueError as err:
            raise VideoImportError(f'TRC has no marker {name!r} '
                                   f'(has {", ".join(self.markers)})') from err


def read_trc(path: str | Path) -> TrcData:
    """Read a tab-separated TRC file; units ``mm``/``cm``/``m`` are converted to metres."""
    path = Path(path)
    try:
        lines = path.read_text(encoding='utf-8', errors='replace').splitlines()
    except OSError as err:
        raise VideoImportError(f'cannot read reference {path}: {err.strerror or err}') from err
    if len(lines) < 6 or not lines[0].startswith('PathFileType'):
        raise VideoImportError(f'{path}: not a TRC file (no PathFileType header)')
    keys, values = lines[1].split('\t'), lines[2].split('\t')
    meta = dict(zip(keys, values))
    try:
        rate = float(meta.get('DataRate', 'nan'))
        n_markers = int(meta['NumMarkers'])
    except (KeyError, ValueError) as err:
        raise VideoImportError(f'{path}: TRC header lacks DataRate/NumMarkers') from err
    scale = {'mm': 1e-3, 'cm': 1e-2, 'm': 1.0}.get(meta.get('Units', 'm').strip(), None)
    if scale is None:
        raise VideoImportError(f'{path}: unknown TRC units {meta.get("Units")!r}')
    markers = tuple(n.strip() for n in lines[3].split('\t')[2:] if n.strip())
    if len(markers) != n_markers:
        raise VideoImportError(f'{path}: header names {len(markers)} markers, '
                               f'NumMarkers says {n_markers}')
    rows = []
    for lineno, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = line.split('\t')
        cells += [''] * (2 + 3 * n_markers - len(cells))
        try:
            rows.append([float(c) if c.strip() else math.nan
                         for c in cells[:2 + 3 * n_markers]])
        except ValueError as err:
            raise VideoImportError(f'{path}:{lineno}: not a number ({err})') from err
    if not rows:
        raise VideoImportError(f'{path}: TRC has no data rows')
    data = np.asarray(rows, dtype=np.float64)
    return TrcData(markers=markers, rate=rate, frames=data[:, 0].astype(np.int64),
                   times=data[:, 1], points=data[:, 2:].reshape(len(data), n_markers, 3) * scale)


def trc_to_room(points: np.ndarray, *, up_axis: str = 'y') -> np.ndarray:
    """TRC points (..., 3) -> room frame (..., 3), z up.

    TRC files are Y up; the default maps ``(x, y, z)`` to ``(z, x, y)``, i.e. room
    ``(X, Y, Z) = (trc Z, trc X, trc Y)`` (see :func:`calibration_io.world_rotation`).
    """
    return np.asarray(points, dtype=np.float64) @ world_rotation(up_axis).T


def reference_ground_truth(trc: TrcData, calibration: RoomCalibration,
                           stamps_ns: Sequence[int], rows: Sequence[int], *,
                           person_id: int = 1, up_axis: str = 'y') -> list[GroundTruthRow]:
    """Ground-truth rows of one person from TRC keypoints.

    ``rows[i]`` is the TRC row (0-based) of recording frame ``i`` stamped ``stamps_ns[i]``.
    Position: midpoint of ``RHip``/``LHip`` dropped onto the floor; ``z_head``: the ``Head``
    marker's height (else the highest marker); ``visible_cameras``: cameras in whose image at
    least one keypoint projects. Frames without the TRC row or with missing hips are skipped.
    """
    world = trc_to_room(trc.points, up_axis=up_axis)  # (F, M, 3)
    hip = 0.5 * (world[:, trc.markers.index('RHip')] + world[:, trc.markers.index('LHip')]) \
        if {'RHip', 'LHip'} <= set(trc.markers) else None
    if hip is None:
        raise VideoImportError('TRC reference needs RHip and LHip markers')
    head = world[:, trc.markers.index('Head'), 2] if 'Head' in trc.markers \
        else np.nanmax(world[:, :, 2], axis=1)
    visible = {}
    for name, cam in calibration.cameras.items():
        pix = cam.project(world)  # (F, M, 2), NaN behind the camera
        visible[name] = np.any(cam.in_image(pix), axis=1)  # (F,)
    out = []
    for frame, (stamp, row) in enumerate(zip(stamps_ns, rows)):
        if not 0 <= row < len(world) or not np.all(np.isfinite(hip[row, :2])):
            continue
        out.append(GroundTruthRow(
            stamp_ns=int(stamp), frame=frame, person_id=int(person_id),
            x=float(hip[row, 0]), y=float(hip[row, 1]),
            z_head=float(head[row]) if np.isfinite(head[row]) else float('nan'),
            sitting=False,
            visible_cameras=tuple(n for n in calibration.names if visible[n][row])))
    return out


# -- the import ----------------------------------------------------------------------------------

@dataclass
class ImportSummary:
    """What :func:`import_videos` wrote.

    Attributes:
        outdir: the recording directory.
        frames: frame sets written.
        fps: frame rate used for the stamps.
        sizes: camera name -> (width, height) of the written images.
        notes: one-line remarks (scaled calibrations, truncation).
        ground_truth_rows: rows written to ``ground_truth.csv`` (0 without reference).
    """

    outdir: Path
    frames: int
    fps: float
    sizes: dict[str, tuple[int, int]]
    notes: list[str] = field(default_factory=list)
    ground_truth_rows: int = 0


def _resolve_videos(calibration: RoomCalibration,
                    videos: Mapping[str, str | Path] | Sequence[str | Path]) -> dict[str, Path]:
    if isinstance(videos, Mapping):
        unknown = [n for n in videos if n not in calibration.cameras]
        if unknown:
            raise VideoImportError(
                f'camera name(s) {", ".join(unknown)} not in the calibration '
                f'(it has {", ".join(calibration.names)})')
        if not videos:
            raise VideoImportError('no videos given')
        return {n: Path(videos[n]) for n in calibration.names if n in videos}
    videos = [Path(v) for v in videos]
    if len(videos) != len(calibration.names):
        raise VideoImportError(
            f'{len(videos)} video(s) for {len(calibration.names)} calibrated cameras '
            f'({", ".join(calibration.names)}); give one per camera in this order, '
            f'or name=path pairs')
    return dict(zip(calibration.names, videos))


def import_videos(outdir: str | Path, calibration: RoomCalibration,
                  videos: Mapping[str, str | Path] | Sequence[str | Path], *,
                  fps: float | None = None, width: int | None = None,
                  start_offsets: Mapping[str, int] | None = None, compressed: bool = False,
                  reference: str | Path | None = None, reference_offset: int = 0,
                  shortest: bool = False, max_frames: int | None = None,
                  fit_size: bool = False, start_ns: int = EPOCH_NS,
                  source: Mapping[str, object] | None = None,
                  progress: bool | None = None,
                  note: Callable[[str], None] | None = None) -> ImportSummary:
    """Build a recording directory from synchronised videos; see the module docstring.

    Args:
        outdir: recording directory to create (may exist if empty).
        calibration: the rig; cameras without a video are dropped (``name=path`` input).
        videos: paths in the calibration's camera order, or camera name -> path.
        fps: frame rate for the stamps (default: the videos', which must agree).
        width: output image width, pixels; height keeps each video's aspect ratio.
        start_offsets: camera name -> frames to skip at the start of its video.
        compressed: write JPEG ``CompressedImage`` instead of raw ``Image``.
        reference: Pose2Sim TRC of the subject -> ``ground_truth.csv`` (person 1);
            TRC row ``frame + reference_offset`` belongs to recording frame ``frame``.
        shortest: cut all videos to the shortest instead of refusing differing counts.
        max_frames: import at most this many frame sets.
        fit_size: stretch calibrations whose aspect ratio differs from the video.
        start_ns: stamp of the first frame set, integer nanoseconds (default
            :data:`EPOCH_NS`, 2023-11-14, as synthetic recordings).
        source: extra entries for ``recording.yaml`` (e.g. the calibration file).
        progress: tqdm bar on stderr (None: only on a TTY).
        note: receives one-line notes (default: print to stderr).
    Raises:
        VideoImportError: any user error, before anything is written.
    """
    from mbtrack_ros.recording.bag import RecordingWriter  # rosbags import only when used

    note = note or (lambda msg: print(msg, file=sys.stderr))
    outdir = Path(outdir)
    paths = _resolve_videos(calibration, videos)
    offsets = {str(k): int(v) for k, v in (start_offsets or {}).items()}
    unknown = [n for n in offsets if n not in paths]
    if unknown:
        raise VideoImportError(f'--start-offset for unknown camera(s) {", ".join(unknown)} '
                               f'(videos: {", ".join(paths)})')
    negative = [n for n, v in offsets.items() if v < 0]
    if negative:
        raise VideoImportError(f'start offsets must be >= 0 (camera {negative[0]})')
    if width is not None and int(width) < 8:
        raise VideoImportError(f'--width must be at least 8 pixels, got {width}')
    if max_frames is not None and int(max_frames) < 1:
        raise VideoImportError(f'--frames must be at least 1, got {max_frames}')
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise VideoImportError(f'--fps must be a positive number, got {fps}')
    if outdir.exists() and (not outdir.is_dir() or any(outdir.iterdir())):
        raise VideoImportError(f'{outdir} exists and is not an empty directory')

    infos = {n: probe_video(p) for n, p in paths.items()}
    notes: list[str] = []

    # frame rate
    if fps is None:
        rates = {n: i.fps for n, i in infos.items()}
        if any(r <= 0 for r in rates.values()):
            raise VideoImportError(f'video {next(n for n, r in rates.items() if r <= 0)} does '
                                   f'not state its frame rate; pass --fps')
        lo, hi = min(rates.values()), max(rates.values())
        if hi - lo > 1e-3 * hi:
            raise VideoImportError('frame rates differ ('
                                   + ', '.join(f'{n}: {r:g}' for n, r in rates.items())
                                   + '); pass --fps to stamp them alike')
        fps = lo
    fps = float(fps)

    # frame counts after offsets
    counts = {n: i.frame_count - offsets.get(n, 0) for n, i in infos.items()}
    empty = [n for n, c in counts.items() if c <= 0]
    if empty:
        raise VideoImportError(f'{empty[0]}: start offset {offsets.get(empty[0], 0)} leaves no '
                               f'frame of {infos[empty[0]].frame_count}')
    n_frames = min(counts.values())
    if max_frames is not None:
        if int(max_frames) > n_frames and not shortest:
            raise VideoImportError(f'--frames {max_frames} but the shortest video has only '
                                   f'{n_frames} frame(s) after offsets')
        n_frames = min(n_frames, int(max_frames))
    elif len(set(counts.values())) > 1:
        listing = ', '.join(f'{n}: {c}' for n, c in counts.items())
        if not shortest:
            raise VideoImportError(f'frame counts differ after start offsets ({listing}); '
                                   f'pass --shortest to import the first {n_frames} of each, '
                                   f'or fix --start-offset')
        notes.append(f'frame counts differ ({listing}): importing the first {n_frames}')

    # cameras: fitted to the decoded size, then scaled to the output width
    cameras, sizes = {}, {}
    for name, info in infos.items():
        cam, msg = fit_camera(calibration.cameras[name], info.width, info.height,
                              fit_size=fit_size)
        if msg:
            notes.append(msg)
        if width is not None:
            out_w = int(width)
            out_h = max(1, int(round(info.height * out_w / info.width)))
            cam = cam.scaled(out_w, out_h)
        cameras[name] = cam
        sizes[name] = (cam.width, cam.height)
    room = RoomCalibration(cameras=cameras, floor=calibration.floor,
                           frame_id=calibration.frame_id, entry_zones=calibration.entry_zones,
                           exits=calibration.exits)

    trc = None
    if reference is not None:
        trc = read_trc(reference)
    for msg in notes:
        note(msg)

    # -- write ------------------------------------------------------------------------------
    try:
        outdir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise VideoImportError(f'cannot create {outdir}: {err.strerror or err}') from err
    period_ns = 1e9 / fps
    stamps = [int(start_ns) + int(round(i * period_ns)) for i in range(n_frames)]
    truth: dict[int, list[GroundTruthRow]] = {}
    if trc is not None:
        for row in reference_ground_truth(trc, room, stamps, [i + int(reference_offset)
                                                              for i in range(n_frames)]):
            truth.setdefault(row.frame, []).append(row)
    captures = {n: _open(p) for n, p in paths.items()}
    written = 0
    try:
        for name, cap in captures.items():
            for _ in range(offsets.get(name, 0)):  # grab() skips without full decode
                cap.grab()
        from tqdm import tqdm
        with RecordingWriter(outdir / 'bag', room, compressed=compressed) as writer, \
                tqdm(total=n_frames, desc='import-video', unit='frame', file=sys.stderr,
                     disable=None if progress is None else not progress) as bar:
            for i in range(n_frames):
                images = {}
                for name, cap in captures.items():
                    ok, frame = cap.read()
                    if not ok or frame is None:
                        break
                    cam = cameras[name]
                    images[name] = resize_frame(frame, cam.width, cam.height)
                if len(images) < len(captures):
                    short = next(n for n in captures if n not in images)
                    msg = (f'{short} ended after {i} frame(s) although its container '
                           f'announced more; recording cut to {i} frame(s)')
                    notes.append(msg)
                    note(msg)
                    break
                writer.write_frame(stamps[i], images)
                if trc is not None:
                    writer.write_ground_truth(stamps[i], truth.get(i, []))
                written += 1
                bar.update(1)
    finally:
        for cap in captures.values():
            cap.release()
    stamps = stamps[:written]

    room.save(outdir / 'calibration.yaml')
    gt_rows = 0
    if trc is not None:
        rows = [r for i in range(written) for r in truth.get(i, [])]
        write_ground_truth(outdir / 'ground_truth.csv', rows)
        gt_rows = len(rows)
    sizes_set = set(sizes.values())
    meta = {
        'source': 'import-video',
        'frames': written,
        'fps': fps,
        'width': next(iter(sizes_set))[0] if len(sizes_set) == 1 else None,
        'height': next(iter(sizes_set))[1] if len(sizes_set) == 1 else None,
        'size': {n: list(s) for n, s in sizes.items()},
        'cameras': list(cameras),
        'videos': {n: str(p) for n, p in paths.items()},
        'start_offsets': {n: offsets.get(n, 0) for n in paths},
        'compressed': bool(compressed),
        'storage': 'mcap',
        'epoch_ns': int(start_ns),
        'reference': None if reference is None else str(reference),
        'reference_offset': int(reference_offset),
        'notes': notes,
    }
    if source:
        meta.update({str(k): v for k, v in source.items()})
    (outdir / 'recording.yaml').write_text(yaml.safe_dump(meta, sort_keys=False),
                                           encoding='utf-8')
    return ImportSummary(outdir=outdir, frames=written, fps=fps, sizes=sizes, notes=notes,
                         ground_truth_rows=gt_rows)
