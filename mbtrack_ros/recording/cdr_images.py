"""The fields of a serialised ``sensor_msgs/Image`` or ``CompressedImage``, without a copy.

A rosbag2 message is its CDR serialisation (a 4-byte encapsulation header, then the fields
aligned relative to its end). :func:`image_view` reads the few fields the image decoders
(:mod:`mbtrack_ros.recording.images`) need and returns the pixel bytes as a ``memoryview``
into the caller's buffer: an image is never copied between the bag file and the one resize
to the tracker's working size. rosbags' ``deserialize_cdr`` gives the same values but copies
the whole message first. Little- and big-endian encapsulations (``00 01``, ``00 00``) are
read; every length is checked against the buffer, a bad one raises :class:`CdrError` (one
line). Pure Python (``struct``), no rclpy.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

__all__ = ['COMPRESSED', 'IMAGE', 'CdrError', 'ImageView', 'image_view']

IMAGE = 'sensor_msgs/msg/Image'
COMPRESSED = 'sensor_msgs/msg/CompressedImage'


class CdrError(ValueError):
    """A serialised image message whose fields do not fit its buffer (one line)."""


@dataclass(frozen=True)
class ImageView:
    """The fields of one image message; ``data`` views the caller's buffer (valid while
    it is). Raw images have ``encoding, height, width, step, is_bigendian``; compressed
    ones ``format`` (the others empty / 0)."""

    stamp_ns: int
    frame_id: str
    data: memoryview
    encoding: str = ''
    height: int = 0
    width: int = 0
    step: int = 0
    is_bigendian: int = 0
    format: str = ''


class _Cursor:
    """Aligned reads from a CDR body (``buf`` after the encapsulation header)."""

    def __init__(self, buf: memoryview, little: bool) -> None:
        self.buf, self.pos = buf, 0
        self.u32 = struct.Struct('<I' if little else '>I')
        self.i32 = struct.Struct('<i' if little else '>i')

    def _take(self, size: int, align: int, what: str) -> int:
        pos = (self.pos + align - 1) & -align
        if pos + size > len(self.buf):
            raise CdrError(f'{what} at byte {pos + 4} runs past the end of the '
                           f'{len(self.buf) + 4}-byte message')
        self.pos = pos + size
        return pos

    def uint32(self, what: str) -> int:
        return self.u32.unpack_from(self.buf, self._take(4, 4, what))[0]

    def int32(self, what: str) -> int:
        return self.i32.unpack_from(self.buf, self._take(4, 4, what))[0]

    def uint8(self, what: str) -> int:
        return self.buf[self._take(1, 1, what)]

    def string(self, what: str) -> str:
        n = self.uint32(what)
        pos = self._take(n, 1, what)
        raw = bytes(self.buf[pos:pos + n])
        if n == 0 or raw[-1] != 0:
            raise CdrError(f'{what} is not a terminated CDR string')
        try:
            return raw[:-1].decode()
        except UnicodeDecodeError as err:
            raise CdrError(f'{what} is not UTF-8') from err

    def octets(self, what: str) -> memoryview:
        n = self.uint32(what)
        pos = self._take(n, 1, what)
        return self.buf[pos:pos + n]


def image_view(cdr, msgtype: str) -> ImageView:
    """The fields of a CDR-serialised ``msgtype`` (:data:`IMAGE` or :data:`COMPRESSED`) in
    ``cdr`` (bytes, memoryview, mmap slice ...); ``data`` is a view of ``cdr``, not a copy.
    Raises :class:`CdrError` on a message that does not fit its buffer."""
    buf = memoryview(cdr).cast('B')
    if len(buf) < 4 or buf[0] != 0 or buf[1] not in (0, 1):
        raise CdrError('not a CDR message (encapsulation header)')
    c = _Cursor(buf[4:], little=bool(buf[1]))
    sec = c.int32('header.stamp.sec')
    nsec = c.uint32('header.stamp.nanosec')
    frame_id = c.string('header.frame_id')
    stamp = sec * 1_000_000_000 + nsec
    if msgtype == COMPRESSED:
        fmt = c.string('format')
        return ImageView(stamp, frame_id, c.octets('data'), format=fmt)
    if msgtype != IMAGE:
        raise CdrError(f'{msgtype} is not an image message type')
    height = c.uint32('height')
    width = c.uint32('width')
    encoding = c.string('encoding')
    big = c.uint8('is_bigendian')
    step = c.uint32('step')
    return ImageView(stamp, frame_id, c.octets('data'), encoding=encoding, height=height,
                     width=width, step=step, is_bigendian=big)
