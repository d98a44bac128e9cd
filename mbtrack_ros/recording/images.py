"""Pure numpy/OpenCV conversion between ROS image payloads and ``(H, W, 3) uint8`` RGB.

Shared by :mod:`mbtrack_ros.recording.bag` (rosbags message classes) and
:mod:`mbtrack_ros.nodes.conversions` (rclpy message classes): both pass the message fields
(``encoding, height, width, step, data`` of ``sensor_msgs/Image``; ``format, data`` of
``sensor_msgs/CompressedImage``) to the functions here, so there is one decoder.

Supported raw encodings: ``rgb8``, ``bgr8``, ``mono8``, ``rgba8``, ``bgra8`` (8 bits per
channel; rows may be padded, ``step >= width * channels``). Compressed: JPEG and PNG.
Every bad input raises :class:`ImageConversionError` with a one-line reason, before any large
allocation.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = [
    'CHANNELS', 'MAX_SIDE', 'ImageConversionError', 'decode_compressed', 'decode_raw',
    'encode_compressed', 'encode_raw',
]

#: channels per pixel of each supported raw encoding
CHANNELS = {'rgb8': 3, 'bgr8': 3, 'mono8': 1, 'rgba8': 4, 'bgra8': 4}
#: largest accepted image side, pixels (refused before allocating)
MAX_SIDE = 8192


class ImageConversionError(ValueError):
    """An image message that cannot be converted (one-line reason)."""


def _check_size(width: int, height: int) -> None:
    if width <= 0 or height <= 0:
        raise ImageConversionError(f'empty image ({width}x{height})')
    if width > MAX_SIDE or height > MAX_SIDE:
        raise ImageConversionError(
            f'declared size {width}x{height} exceeds the limit {MAX_SIDE}x{MAX_SIDE}')


def decode_raw(encoding: str, height: int, width: int, step: int, data,
               *, is_bigendian: int = 0) -> np.ndarray:
    """Decode a raw ``sensor_msgs/Image`` payload to ``(height, width, 3) uint8`` RGB.

    ``data`` is any bytes-like object or a uint8 array (rclpy gives ``array.array`` or bytes,
    rosbags a numpy array). The result never aliases ``data``.
    """
    del is_bigendian  # 8-bit encodings only: byte order does not matter
    encoding = str(encoding).strip().lower()
    channels = CHANNELS.get(encoding)
    if channels is None:
        raise ImageConversionError(
            f'unsupported encoding {encoding!r} (supported: {", ".join(CHANNELS)})')
    height, width, step = int(height), int(width), int(step)
    _check_size(width, height)
    if step < width * channels:
        raise ImageConversionError(
            f'step {step} < width*channels = {width}*{channels} for {encoding}')
    try:
        buf = np.frombuffer(memoryview(data).cast('B'), dtype=np.uint8)
    except TypeError:
        buf = np.asarray(data, dtype=np.uint8).ravel()
    if buf.size != step * height:
        raise ImageConversionError(
            f'data has {buf.size} bytes, expected step*height = {step}*{height} = '
            f'{step * height}')
    rows = buf.reshape(height, step)[:, : width * channels]
    pixels = rows.reshape(height, width, channels)
    if encoding == 'rgb8':
        return pixels.copy()  # contiguous, never aliases the message buffer
    if encoding == 'bgr8':
        return cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_BGR2RGB)
    if encoding == 'mono8':
        return cv2.cvtColor(np.ascontiguousarray(pixels[:, :, 0]), cv2.COLOR_GRAY2RGB)
    if encoding == 'rgba8':
        return cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_RGBA2RGB)
    return cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_BGRA2RGB)  # bgra8


def _check_rgb(rgb: np.ndarray) -> np.ndarray:
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ImageConversionError(
            f'expected an (H, W, 3) uint8 RGB array, got {rgb.dtype} {rgb.shape}')
    _check_size(rgb.shape[1], rgb.shape[0])
    return np.ascontiguousarray(rgb)


def encode_raw(rgb: np.ndarray, encoding: str = 'rgb8') -> tuple[int, int, int, bytes]:
    """Encode ``(H, W, 3) uint8`` RGB as a raw payload -> ``(height, width, step, data)``.

    ``encoding`` is one of ``rgb8``, ``bgr8``, ``mono8`` (luma), ``rgba8``, ``bgra8``.
    """
    rgb = _check_rgb(rgb)
    if encoding not in CHANNELS:
        raise ImageConversionError(
            f'unsupported encoding {encoding!r} (supported: {", ".join(CHANNELS)})')
    conv = {'rgb8': None, 'bgr8': cv2.COLOR_RGB2BGR, 'mono8': cv2.COLOR_RGB2GRAY,
            'rgba8': cv2.COLOR_RGB2RGBA, 'bgra8': cv2.COLOR_RGB2BGRA}[encoding]
    out = rgb if conv is None else cv2.cvtColor(rgb, conv)
    h, w = rgb.shape[:2]
    return h, w, w * CHANNELS[encoding], np.ascontiguousarray(out).tobytes()


def _format_kind(fmt: str) -> str:
    f = str(fmt).lower()
    if 'png' in f:
        return 'png'
    if 'jpeg' in f or 'jpg' in f:
        return 'jpeg'
    raise ImageConversionError(f'unsupported compressed format {fmt!r} (jpeg or png)')


def decode_compressed(fmt: str, data) -> np.ndarray:
    """Decode a ``sensor_msgs/CompressedImage`` payload (JPEG/PNG) to ``(H, W, 3) uint8`` RGB.

    ``fmt`` is the message's ``format`` field (``jpeg``, ``png``, ``rgb8; jpeg compressed
    bgr8`` ...); the decoder itself trusts the file signature. The declared size in the
    header is checked against :data:`MAX_SIDE` before decoding.
    """
    _format_kind(fmt)
    try:
        buf = np.frombuffer(memoryview(data).cast('B'), dtype=np.uint8)
    except TypeError:
        buf = np.asarray(data, dtype=np.uint8).ravel()
    if buf.size == 0:
        raise ImageConversionError('compressed image has no data')
    w, h = _peek_size(buf)
    if w is not None:
        _check_size(w, h)
    image = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if image is None:
        raise ImageConversionError(f'cannot decode {buf.size} bytes as {fmt!r}')
    _check_size(image.shape[1], image.shape[0])
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def _peek_size(buf: np.ndarray) -> tuple[int | None, int | None]:
    """Declared (width, height) from a PNG IHDR or JPEG SOF header, without decoding."""
    head = buf[: 1 << 16].tobytes()
    if head[:8] == b'\x89PNG\r\n\x1a\n' and len(head) >= 24:
        return int.from_bytes(head[16:20], 'big'), int.from_bytes(head[20:24], 'big')
    if head[:2] == b'\xff\xd8':
        i = 2
        while i + 9 < len(head):
            if head[i] != 0xFF:
                i += 1
                continue
            marker = head[i + 1]
            if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7 or marker == 0xFF:
                i += 1 if marker == 0xFF else 2
                continue
            length = int.from_bytes(head[i + 2:i + 4], 'big')
            if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
                h = int.from_bytes(head[i + 5:i + 7], 'big')
                w = int.from_bytes(head[i + 7:i + 9], 'big')
                return w, h
            i += 2 + length
    return None, None


def encode_compressed(rgb: np.ndarray, fmt: str = 'jpeg', *,
                      quality: int = 90) -> tuple[str, bytes]:
    """Encode ``(H, W, 3) uint8`` RGB as JPEG or PNG -> ``(format_field, data)``.

    The format field follows image_transport: ``rgb8; jpeg compressed bgr8``.
    """
    rgb = _check_rgb(rgb)
    kind = _format_kind(fmt)
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if kind == 'jpeg' else []
    ok, buf = cv2.imencode('.jpg' if kind == 'jpeg' else '.png',
                           cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), params)
    if not ok:
        raise ImageConversionError(f'OpenCV could not encode the image as {kind}')
    return f'rgb8; {kind} compressed bgr8', buf.tobytes()
