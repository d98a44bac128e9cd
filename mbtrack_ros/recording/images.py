"""Pure numpy/OpenCV conversion between ROS image payloads and ``(H, W, 3) uint8`` RGB.

Shared by :mod:`mbtrack_ros.recording.bag` (rosbags message classes) and
:mod:`mbtrack_ros.nodes.conversions` (rclpy message classes): both pass the message fields
(``encoding, height, width, step, data`` of ``sensor_msgs/Image``; ``format, data`` of
``sensor_msgs/CompressedImage``) to the functions here, so there is one decoder.

Supported raw encodings: ``rgb8``, ``bgr8``, ``mono8``, ``rgba8``, ``bgra8`` (8 bits per
channel; rows may be padded, ``step >= width * channels``). Compressed: JPEG and PNG.
Every bad input raises :class:`ImageConversionError` with a one-line reason and a short
``cause`` (one of :data:`CAUSES`), before any large allocation. Work per message is bounded
before decoding: the declared size (raw header fields, or the PNG IHDR / JPEG SOF header of a
compressed payload, read without decoding) is checked against :data:`MAX_SIDE` and, when the
caller passes ``expected`` (the calibrated size), against it: equal, or with ``max_scale`` > 1
at most that many times larger per side. A compressed payload without a readable size header
is refused, never decoded blind.

Given ``to`` (the camera at the size the tracker works at, ``Camera.at_most``), the decoders
return the image at that camera's size, resized once (``Camera.fit``) from the message's own
pixels: a raw image is not copied first, a colour conversion runs on the small image, and a
JPEG is decoded by the decoder itself at 1/2, 1/4 or 1/8 scale (libjpeg's scaled inverse
DCT) while that is still at least the working size, then resized.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = [
    'CAUSES', 'CHANNELS', 'MAX_RESCALE', 'MAX_SIDE', 'ImageConversionError',
    'compressed_size',
    'decode_compressed', 'decode_raw', 'encode_compressed', 'encode_raw',
]

#: channels per pixel of each supported raw encoding
CHANNELS = {'rgb8': 3, 'bgr8': 3, 'mono8': 1, 'rgba8': 4, 'bgra8': 4}
#: largest accepted image side, pixels (refused before allocating)
MAX_SIDE = 8192
#: where images may be resized to the calibration (node ``rescale_images``, ``mbtrack
#: replay``), the most times larger than the calibrated size they may be on a side
MAX_RESCALE = 4.0
# JPEG segments (markers, fill bytes) read looking for the frame header: real files have ~10
_MAX_SEGMENTS = 1024


#: the ``cause`` of an :class:`ImageConversionError` (logs are throttled per cause)
CAUSES = ('encoding', 'empty', 'too-large', 'size-mismatch', 'step', 'data-length', 'format',
          'no-data', 'no-header', 'undecodable', 'decoded-size')


class ImageConversionError(ValueError):
    """An image message that cannot be converted (one-line reason; ``cause`` names the
    kind of defect, one of :data:`CAUSES`)."""

    def __init__(self, message: str, cause: str = 'undecodable') -> None:
        super().__init__(message)
        self.cause = cause

    def __reduce__(self):
        return type(self), (str(self), self.cause)


def _check_size(width: int, height: int, expected: tuple[int, int] | None = None,
                max_scale: float = 1.0) -> None:
    """Refuse a declared ``width`` x ``height``: empty, above :data:`MAX_SIDE`, or (with
    ``expected = (width, height)``) different from it, or with ``max_scale`` > 1 larger than
    ``max_scale`` times it on a side."""
    if width <= 0 or height <= 0:
        raise ImageConversionError(f'empty image ({width}x{height})', 'empty')
    if width > MAX_SIDE or height > MAX_SIDE:
        raise ImageConversionError(
            f'declared size {width}x{height} exceeds the limit {MAX_SIDE}x{MAX_SIDE}',
            'too-large')
    if expected is None:
        return
    ew, eh = int(expected[0]), int(expected[1])
    if max_scale <= 1.0:
        if (width, height) != (ew, eh):
            raise ImageConversionError(f'declared size {width}x{height} differs from the '
                                       f'calibration {ew}x{eh}', 'size-mismatch')
    elif width > max_scale * ew or height > max_scale * eh:
        raise ImageConversionError(
            f'declared size {width}x{height} is more than {max_scale:g} times the '
            f'calibration {ew}x{eh}', 'too-large')


def decode_raw(encoding: str, height: int, width: int, step: int, data,
               *, is_bigendian: int = 0, expected: tuple[int, int] | None = None,
               max_scale: float = 1.0, to=None) -> np.ndarray:
    """Decode a raw ``sensor_msgs/Image`` payload to ``(height, width, 3) uint8`` RGB.

    ``data`` is any bytes-like object or a uint8 array (rclpy gives ``array.array`` or bytes,
    rosbags a numpy array). The result never aliases ``data``. ``expected`` (width, height)
    and ``max_scale``: the size check of the module docstring, before any conversion.
    ``to``: a camera (``Camera``) whose size the image is resized to (module docstring).
    """
    del is_bigendian  # 8-bit encodings only: byte order does not matter
    encoding = str(encoding).strip().lower()
    channels = CHANNELS.get(encoding)
    if channels is None:
        raise ImageConversionError(
            f'unsupported encoding {encoding[:40]!r} (supported: {", ".join(CHANNELS)})',
            'encoding')
    height, width, step = int(height), int(width), int(step)
    _check_size(width, height, expected, max_scale)
    if step < width * channels:
        raise ImageConversionError(
            f'step {step} < width*channels = {width}*{channels} for {encoding}', 'step')
    try:
        buf = np.frombuffer(memoryview(data).cast('B'), dtype=np.uint8)
    except TypeError:
        buf = np.asarray(data, dtype=np.uint8).ravel()
    if buf.size != step * height:
        raise ImageConversionError(
            f'data has {buf.size} bytes, expected step*height = {step}*{height} = '
            f'{step * height}', 'data-length')
    rows = buf.reshape(height, step)[:, : width * channels]
    pixels = rows.reshape(height, width, channels)
    if to is not None and (height, width) != (to.height, to.width):
        pixels = to.fit(np.ascontiguousarray(pixels))   # a new array, at the working size
    elif encoding == 'rgb8':
        return pixels.copy()  # contiguous, never aliases the message buffer
    if encoding == 'rgb8':
        return pixels
    if encoding == 'bgr8':
        return cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_BGR2RGB)
    if encoding == 'mono8':
        grey = pixels if pixels.ndim == 2 else pixels[:, :, 0]   # a resize drops the axis
        return cv2.cvtColor(np.ascontiguousarray(grey), cv2.COLOR_GRAY2RGB)
    if encoding == 'rgba8':
        return cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_RGBA2RGB)
    return cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_BGRA2RGB)  # bgra8


def _check_rgb(rgb: np.ndarray) -> np.ndarray:
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ImageConversionError(
            f'expected an (H, W, 3) uint8 RGB array, got {rgb.dtype} {rgb.shape}', 'format')
    _check_size(rgb.shape[1], rgb.shape[0])
    return np.ascontiguousarray(rgb)


def encode_raw(rgb: np.ndarray, encoding: str = 'rgb8') -> tuple[int, int, int, bytes]:
    """Encode ``(H, W, 3) uint8`` RGB as a raw payload -> ``(height, width, step, data)``.

    ``encoding`` is one of ``rgb8``, ``bgr8``, ``mono8`` (luma), ``rgba8``, ``bgra8``.
    """
    rgb = _check_rgb(rgb)
    if encoding not in CHANNELS:
        raise ImageConversionError(
            f'unsupported encoding {encoding!r} (supported: {", ".join(CHANNELS)})',
            'encoding')
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
    raise ImageConversionError(f'unsupported compressed format {str(fmt)[:40]!r} (jpeg or '
                               'png)', 'format')


def _buffer(data) -> np.ndarray:
    try:
        return np.frombuffer(memoryview(data).cast('B'), dtype=np.uint8)
    except TypeError:
        return np.asarray(data, dtype=np.uint8).ravel()


def compressed_size(fmt: str, data) -> tuple[int, int]:
    """``(width, height)`` a JPEG/PNG payload declares in its header (PNG IHDR, JPEG SOF),
    read without decoding; raises :class:`ImageConversionError` when there is none."""
    _format_kind(fmt)
    buf = _buffer(data)
    if buf.size == 0:
        raise ImageConversionError('compressed image has no data', 'no-data')
    w, h = _peek_size(buf)
    if w is None:
        raise ImageConversionError(f'no PNG or JPEG header with an image size in {buf.size} '
                                   'bytes', 'no-header')
    return w, h


#: JPEG decoding at a reduced scale: factor -> imdecode flag (libjpeg's scaled IDCT)
_REDUCED = ((8, cv2.IMREAD_REDUCED_COLOR_8), (4, cv2.IMREAD_REDUCED_COLOR_4),
            (2, cv2.IMREAD_REDUCED_COLOR_2))


def decode_compressed(fmt: str, data, *, expected: tuple[int, int] | None = None,
                      max_scale: float = 1.0, to=None) -> np.ndarray:
    """Decode a ``sensor_msgs/CompressedImage`` payload (JPEG/PNG) to ``(H, W, 3) uint8`` RGB.

    ``fmt`` is the message's ``format`` field (``jpeg``, ``png``, ``rgb8; jpeg compressed
    bgr8`` ...); the decoder itself trusts the file signature. The size the header declares
    (:func:`compressed_size`) is checked before decoding (module docstring; ``expected`` =
    (width, height)), and the decoded image must have that size (divided by the reduction,
    rounded up). ``to``: a camera (``Camera``) whose size the image is resized to; a JPEG
    is decoded at the largest reduction (1/2, 1/4, 1/8) that keeps both sides at least
    that size when the size divides exactly (module docstring).
    """
    w, h = compressed_size(fmt, data)
    _check_size(w, h, expected, max_scale)
    buf = _buffer(data)
    flag, k = cv2.IMREAD_COLOR, 1
    if to is not None and buf[:2].tobytes() == b'\xff\xd8':
        for k, reduced in _REDUCED:
            if w % k == 0 and h % k == 0 and w // k >= to.width and h // k >= to.height:
                flag = reduced
                break
        else:
            k = 1
    image = cv2.imdecode(buf, flag)
    if image is None:
        raise ImageConversionError(f'cannot decode {buf.size} bytes as {str(fmt)[:40]!r}',
                                   'undecodable')
    if image.shape[:2] != (-(-h // k), -(-w // k)):
        raise ImageConversionError(f'decoded {image.shape[1]}x{image.shape[0]}, the header '
                                   f'declares {w}x{h}' + (f' (at 1/{k})' if k > 1 else ''),
                                   'decoded-size')
    if to is not None:
        image = to.fit(image)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def _peek_size(buf: np.ndarray) -> tuple[int | None, int | None]:
    """Declared (width, height) from a PNG IHDR or JPEG SOF header, without decoding: the
    JPEG segments before the frame header are skipped by their lengths (at most
    ``_MAX_SEGMENTS`` of them: bounded work for any payload)."""
    if buf.size >= 24 and buf[:8].tobytes() == b'\x89PNG\r\n\x1a\n' \
            and buf[12:16].tobytes() == b'IHDR':
        head = buf[:24].tobytes()
        return int.from_bytes(head[16:20], 'big'), int.from_bytes(head[20:24], 'big')
    if buf.size < 4 or buf[0] != 0xFF or buf[1] != 0xD8:
        return None, None
    data = buf.tobytes()
    i, n = 2, len(data)
    for _ in range(_MAX_SEGMENTS):
        if i + 9 >= n or data[i] != 0xFF:
            return None, None  # the end, or not at a marker: damaged header
        marker = data[i + 1]
        if marker == 0xFF:
            i += 1  # fill byte
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 2
            continue
        if marker in (0xD9, 0xDA):  # end of image or start of scan before any SOF
            return None, None
        length = (data[i + 2] << 8) | data[i + 3]
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            return (data[i + 7] << 8) | data[i + 8], (data[i + 5] << 8) | data[i + 6]
        if length < 2:
            return None, None
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
        raise ImageConversionError(f'OpenCV could not encode the image as {kind}', 'format')
    return f'rgb8; {kind} compressed bgr8', buf.tobytes()
