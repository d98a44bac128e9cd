"""rclpy ``sensor_msgs/Image`` and ``CompressedImage`` <-> ``(H, W, 3) uint8`` RGB arrays.

Thin wrappers around :mod:`mbtrack_ros.recording.images` (the one decoder, shared with the
rosbags reader) for rclpy message classes; there is no cv_bridge on this platform.
"""
from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header

from mbtrack_ros.recording.images import (
    ImageConversionError, _check_size, decode_compressed, decode_raw, encode_compressed,
    encode_raw)

__all__ = [
    'ImageConversionError', 'compressed_to_rgb', 'image_to_mono', 'image_to_rgb',
    'mono_to_image', 'rgb_to_compressed', 'rgb_to_image', 'stamp_to_ns', 'ns_to_stamp',
]


def stamp_to_ns(stamp) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(stamp_ns: int, stamp=None):
    """Integer nanoseconds -> ``builtin_interfaces/Time`` (filled in place if given)."""
    from builtin_interfaces.msg import Time
    stamp = Time() if stamp is None else stamp
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    stamp.sec, stamp.nanosec = int(sec), int(nsec)
    return stamp


def image_to_rgb(msg: Image, *, expected: tuple[int, int] | None = None,
                 max_scale: float = 1.0, to=None) -> np.ndarray:
    """``sensor_msgs/Image`` (rgb8, bgr8, mono8, rgba8, bgra8) -> (H, W, 3) uint8 RGB.

    Raises :class:`ImageConversionError` (one line) on an unknown encoding, a size that does
    not match ``step * height``, ``step < width * channels``, a declared size above 8192 or,
    with ``expected`` = (width, height), one that differs from it (``max_scale`` > 1: more
    than that many times larger per side), all checked before any conversion. ``to``: a
    ``Camera`` whose size the image is resized to, once, from the message's own pixels
    (``decode_raw``, the decoder ``mbtrack replay`` uses on a bag's messages).
    """
    return decode_raw(msg.encoding, msg.height, msg.width, msg.step, msg.data,
                      is_bigendian=msg.is_bigendian, expected=expected, max_scale=max_scale,
                      to=to)


def compressed_to_rgb(msg: CompressedImage, *, expected: tuple[int, int] | None = None,
                      max_scale: float = 1.0, to=None) -> np.ndarray:
    """``sensor_msgs/CompressedImage`` (jpeg/png) -> (H, W, 3) uint8 RGB; the size its PNG
    or JPEG header declares is checked (as in :func:`image_to_rgb`) before decoding; ``to``
    as in :func:`image_to_rgb`."""
    return decode_compressed(msg.format, msg.data, expected=expected, max_scale=max_scale,
                             to=to)


def rgb_to_image(rgb: np.ndarray, header: Header | None = None, *,
                 encoding: str = 'rgb8') -> Image:
    """(H, W, 3) uint8 RGB -> ``sensor_msgs/Image`` with the given header and encoding."""
    height, width, step, data = encode_raw(rgb, encoding)
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width, msg.step = height, width, step
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.data = data
    return msg


def mono_to_image(plane: np.ndarray, header: Header | None = None) -> Image:
    """(H, W) uint8 plane (e.g. packed mask bits) -> ``sensor_msgs/Image`` mono8, raw."""
    plane = np.ascontiguousarray(plane, dtype=np.uint8)
    if plane.ndim != 2:
        raise ImageConversionError(f'expected an (H, W) uint8 plane, got {plane.shape}',
                                   'format')
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width = plane.shape
    msg.step = plane.shape[1]
    msg.encoding = 'mono8'
    msg.is_bigendian = 0
    msg.data = plane.tobytes()
    return msg


def image_to_mono(msg: Image, *, expected: tuple[int, int] | None = None) -> np.ndarray:
    """``sensor_msgs/Image`` mono8 -> (H, W) uint8 plane as sent (no colour conversion; a
    copy that does not alias the message). Raises :class:`ImageConversionError` (one line)
    on another encoding, a size that does not match ``step * height`` or, with
    ``expected`` = (width, height), one that differs from it (and, as :func:`image_to_rgb`,
    on an empty or too large declared size before reading the data)."""
    if str(msg.encoding).strip().lower() != 'mono8':
        raise ImageConversionError(f'expected mono8, got {str(msg.encoding)[:40]!r}',
                                   'encoding')
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    _check_size(width, height, expected)
    if step < width:
        raise ImageConversionError(f'step {step} < width {width} for mono8', 'step')
    try:
        buf = np.frombuffer(memoryview(msg.data).cast('B'), dtype=np.uint8)
    except TypeError:
        buf = np.asarray(msg.data, dtype=np.uint8).ravel()
    if buf.size != step * height:
        raise ImageConversionError(f'data has {buf.size} bytes, expected step*height = '
                                   f'{step}*{height} = {step * height}', 'data-length')
    return buf.reshape(height, step)[:, :width].copy()


def rgb_to_compressed(rgb: np.ndarray, header: Header | None = None, fmt: str = 'jpeg', *,
                      quality: int = 90) -> CompressedImage:
    """(H, W, 3) uint8 RGB -> ``sensor_msgs/CompressedImage`` (``fmt`` jpeg or png)."""
    fmt_field, data = encode_compressed(rgb, fmt, quality=quality)
    msg = CompressedImage()
    if header is not None:
        msg.header = header
    msg.format = fmt_field
    msg.data = data
    return msg
