"""Where calibration images come from: ``NAME=PATH`` with PATH an image, a folder of images or
a video that OpenCV reads, or a recording directory (its bag's first frame per camera)."""
from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import cv2
import numpy as np

from mbtrack_ros.calibration.errors import CalibrateError

__all__ = ['IMAGE_SUFFIXES', 'parse_sources', 'read_frames', 'recording_frames']

IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff', '.pgm', '.ppm')


def parse_sources(values: Sequence[str]) -> dict[str, Path]:
    """``NAME=PATH`` arguments -> {name: path}, in the given order."""
    out: dict[str, Path] = {}
    for value in values:
        name, sep, path = value.partition('=')
        if not sep or not name or not path:
            raise CalibrateError(f'expected NAME=PATH (camera name = image, folder of images '
                                 f'or video), got {value!r}')
        if name in out:
            raise CalibrateError(f'camera {name} given twice')
        out[name] = Path(path)
    return out


def read_frames(name: str, path: Path, *, max_frames: int = 200
                ) -> Iterator[tuple[str, np.ndarray]]:
    """``(label, (H, W, 3) uint8 BGR)`` frames of camera ``name`` from an image, a folder of
    images (sorted by name) or a video (at most ``max_frames`` frames, evenly spread);
    raises :class:`CalibrateError` naming the camera when the source cannot be read."""
    if not path.exists():
        raise CalibrateError(f'{name}: {path} does not exist: give an image, a folder of '
                             f'images or a video')
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise CalibrateError(f'{name}: no images ({", ".join(IMAGE_SUFFIXES)}) in folder '
                                 f'{path}')
        step = max(1, -(-len(files) // max_frames))
        for p in files[::step]:
            yield p.name, _read_image(name, p)
        return
    if path.suffix.lower() in IMAGE_SUFFIXES:
        yield path.name, _read_image(name, path)
        return
    # keep FFmpeg's own messages about a broken file off stderr: the refusal below says it
    os.environ.setdefault('OPENCV_FFMPEG_LOGLEVEL', '-8')
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise CalibrateError(f'{name}: cannot read video {path}: give a video OpenCV '
                                 f'reads (e.g. mp4, avi), an image or a folder of images')
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        step = max(1, -(-count // max_frames)) if count > 0 else 1
        index = got = 0
        while got < max_frames:
            ok, frame = cap.read()
            if not ok:
                break
            if index % step == 0:
                got += 1
                yield f'{path.name}#{index}', frame
            index += 1
        if got == 0:
            raise CalibrateError(f'{name}: video {path} has no readable frames: re-encode '
                                 f'it (e.g. ffmpeg -i IN -c:v libx264 OUT.mp4) or give images')
    finally:
        cap.release()


def _read_image(name: str, path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise CalibrateError(f'{name}: cannot read image {path}: give a PNG or JPEG file')
    return image


def recording_frames(path: Path, cameras: Sequence[str]) -> dict[str, np.ndarray]:
    """The first frame (H, W, 3) uint8 BGR of each of ``cameras`` in a recording directory
    (its ``bag/``) or a bag directory."""
    from mbtrack_ros.recording.bag import BagError, RecordingReader
    bag = path / 'bag' if (path / 'bag').is_dir() else path
    out: dict[str, np.ndarray] = {}
    try:
        with RecordingReader(bag, cameras=[c for c in cameras]) as reader:
            for frame in reader.frames():
                for name, rgb in frame.images.items():
                    out.setdefault(name, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
                if len(out) == len(cameras):
                    break
    except (BagError, OSError) as err:
        raise CalibrateError(f'cannot read recording {path}: {err}') from err
    return out
