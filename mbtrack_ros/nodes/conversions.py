"""rclpy ``sensor_msgs/Image`` and ``CompressedImage`` <-> ``(H, W, 3) uint8`` RGB arrays.

Thin wrappers around :mod:`mbtrack_ros.recording.images` (the one decoder, shared with the
rosbags reader) for rclpy message classes; there is no cv_bridge on this platform.
"""
from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header

from mbtrack_ros.recording.images import (
    ImageConversionError, decode_compressed, decode_raw, encode_compressed, encode_raw)

__all__ = [
    'ImageConversionError', 'compressed_to_rgb', 'image_to_rgb', 'rgb_to_compressed',
    'rgb_to_image', 'stamp_to_ns', 'ns_to_stamp',
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
                 max_scale: float = 1.0) -> np.ndarray:
    """``sensor_msgs/Image`` (rgb8, bgr8, mono8, rgba8, bgra8) -> (H, W, 3) uint8 RGB.

    Raises :class:`ImageConversionError` (one line) on an unknown encoding, a size that does
    not match ``step * height``, ``step < width * channels``, a declared size above 8192 or,
    with ``expected`` = (width, height), one that differs from it (``max_scale`` > 1: more
    than that many times larger per side), all checked before any conversion.
    """
    return decode_raw(msg.encoding, msg.height, msg.width, msg.step, msg.data,
                      is_bigendian=msg.is_bigendian, expected=expected, max_scale=max_scale)


def compressed_to_rgb(msg: CompressedImage, *, expected: tuple[int, int] | None = None,
                      max_scale: float = 1.0) -> np.ndarray:
    """``sensor_msgs/CompressedImage`` (jpeg/png) -> (H, W, 3) uint8 RGB; the size its PNG
    or JPEG header declares is checked (as in :func:`image_to_rgb`) before decoding."""
    return decode_compressed(msg.format, msg.data, expected=expected, max_scale=max_scale)


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
