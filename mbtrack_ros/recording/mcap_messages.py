"""Messages of indexed MCAP files as views of their chunks, for image topics.

rosbags reads a message of an MCAP chunk through three copies (the chunk, the record, the
record body) and its CRC; for a 1280x720 camera that is the larger part of reading an image.
:class:`McapMessages` reads each chunk once into a reused buffer (``os.preadv``) and yields
each message's CDR bytes as a ``memoryview`` of it (uncompressed chunks) or of the chunk
decompressed once (zstd, lz4): with :func:`~mbtrack_ros.recording.cdr_images.image_view`
the pixels reach the one resize of :func:`~mbtrack_ros.recording.images.decode_raw`
without another copy.

The order is rosbags' (``Rosbag2 Reader.messages``): file by file; within a file the chunks
of the summary's chunk index merged by log time (ties: the earlier chunk), each chunk's
messages sorted by log time (stable). As by the mcap library's reader by default
(``validate_crcs=False``), chunk CRCs are not computed (that work would scale with the
pixels: ~2 ms per 1280x720 frame set of five cameras); the structure is checked: a chunk
whose record disagrees with its index entry or whose records overrun it is skipped whole, so
that the caller's per-topic message counts (the bag's metadata) show the loss. A file
without a summary, a chunk index or with an unknown chunk compression raises
:class:`McapIndexError` at opening: the caller reads it with rosbags instead.
"""
from __future__ import annotations

import heapq
import os
import struct
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

__all__ = ['McapIndexError', 'McapMessages']

_MAGIC = b'\x89MCAP0\r\n'
_U16, _U32, _U64 = struct.Struct('<H'), struct.Struct('<I'), struct.Struct('<Q')
_FOOTER = struct.Struct('<BQQQI')        # opcode, length, summary start, offsets, crc
_MESSAGE = struct.Struct('<HIQQ')        # channel, sequence, log time, publish time
_OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_CHUNK_INDEX = (
    0x02, 0x03, 0x04, 0x05, 0x06, 0x08)


def _decompressor(name: str):
    if name == '':
        return None
    if name == 'zstd':
        try:
            from compression import zstd  # Python >= 3.14
        except ImportError:
            from backports import zstd    # rosbags' dependency before 3.14
        return zstd.decompress
    if name == 'lz4':
        from lz4.frame import decompress
        return decompress
    raise McapIndexError(f'unsupported chunk compression {name[:20]!r}')


class McapIndexError(RuntimeError):
    """An MCAP file that cannot be read through its summary (the caller falls back)."""


class _Damaged(Exception):
    """A chunk whose structure does not hold together (skipped)."""


@dataclass(frozen=True)
class _Chunk:
    start_time: int
    offset: int
    length: int
    channels: frozenset[int]
    compression: str
    compressed_size: int
    uncompressed_size: int


def _string(buf, pos: int, end: int) -> tuple[str, int]:
    if pos + 4 > end:
        raise _Damaged('string length past its record')
    n = _U32.unpack_from(buf, pos)[0]
    if pos + 4 + n > end:
        raise _Damaged('string past its record')
    return bytes(buf[pos + 4:pos + 4 + n]).decode('utf-8', 'replace'), pos + 4 + n


class _Buffers:
    """Read buffers reused from chunk to chunk: filling a buffer already in memory costs
    the kernel's copy only; a new one (or a memory map of the file) costs a page fault per
    page as well, more than the copy."""

    def __init__(self, keep: int = 4) -> None:
        self.keep = keep
        self.free: list[bytearray] = []

    def take(self, size: int) -> bytearray:
        fits = [b for b in self.free if len(b) >= size]
        if fits:
            buf = min(fits, key=len)
            self.free.remove(buf)
            return buf
        return bytearray(size)

    def give(self, buf: bytearray) -> None:
        self.free.append(buf)
        if len(self.free) > self.keep:
            self.free.remove(min(self.free, key=len))


class _File:
    """One MCAP file: its channels (id -> topic, schema name) and chunk index."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.fd = os.open(path, os.O_RDONLY)
        try:
            self.size = os.fstat(self.fd).st_size
            self.schemas: dict[int, str] = {}
            self.channels: dict[int, tuple[str, str]] = {}
            self._channel_schema: dict[int, int] = {}
            self.chunks: list[_Chunk] = []
            self._read_summary()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    def _read(self, offset: int, size: int, into: bytearray | None = None) -> memoryview:
        """``size`` bytes at ``offset``: a view of ``into`` (filled) or of new bytes."""
        if into is None:
            data = memoryview(os.pread(self.fd, size, offset))
            done = len(data)
        else:
            data = memoryview(into)[:size]
            done = 0
            while done < size:
                n = os.preadv(self.fd, [data[done:]], offset + done)
                if n <= 0:
                    break
                done += n
        if done != size:
            raise _Damaged(f'{size} bytes at {offset} past the end of the file')
        return data

    def _read_summary(self) -> None:
        size = self.size
        tail = 8 + _FOOTER.size
        if size < 8 + tail:
            raise McapIndexError(f'{self.path.name}: too short for an MCAP file')
        try:
            head, end = bytes(self._read(0, 8)), self._read(size - tail, tail)
        except _Damaged as err:
            raise McapIndexError(f'{self.path.name}: {err}') from err
        if head != _MAGIC or bytes(end[-8:]) != _MAGIC:
            raise McapIndexError(f'{self.path.name}: no MCAP magic at both ends')
        footer = size - tail
        op, length, start, _, _ = _FOOTER.unpack_from(end, 0)
        if op != _OP_FOOTER or length != 20 or not 8 <= start <= footer:
            raise McapIndexError(f'{self.path.name}: no summary section')
        try:
            buf = self._read(start, footer - start)
            pos, stop = 0, len(buf)
            while pos < stop:
                if pos + 9 > stop:
                    raise _Damaged('summary record past the footer')
                op, length = buf[pos], _U64.unpack_from(buf, pos + 1)[0]
                body, rec_end = pos + 9, pos + 9 + length
                if rec_end > stop:
                    raise _Damaged('summary record past the footer')
                if op in (_OP_SCHEMA, _OP_CHANNEL):
                    self._register(op, buf, body, rec_end)
                elif op == _OP_CHUNK_INDEX:
                    self.chunks.append(self._chunk_index(buf, body, rec_end))
                pos = rec_end
        except (_Damaged, struct.error) as err:
            raise McapIndexError(f'{self.path.name}: damaged summary ({err})') from err
        if not self.chunks:
            raise McapIndexError(f'{self.path.name}: no chunk index')
        for chunk in self.chunks:
            _decompressor(chunk.compression)   # McapIndexError on an unknown one

    def _register(self, op: int, buf, pos: int, end: int) -> None:
        """A Schema or Channel record of the summary (the channels of chunks are those the
        summary declares: :meth:`McapMessages.topics`)."""
        if op == _OP_SCHEMA:
            sid = _U16.unpack_from(buf, pos)[0]
            self.schemas[sid], _ = _string(buf, pos + 2, end)
        else:
            cid, sid = _U16.unpack_from(buf, pos)[0], _U16.unpack_from(buf, pos + 2)[0]
            topic, _ = _string(buf, pos + 4, end)
            self._channel_schema[cid] = sid
            self.channels[cid] = (topic, self.schemas.get(sid, ''))
        # a channel may come before its schema: resolve names again
        for cid, sid in self._channel_schema.items():
            if not self.channels[cid][1] and sid in self.schemas:
                self.channels[cid] = (self.channels[cid][0], self.schemas[sid])

    @staticmethod
    def _chunk_index(buf, pos: int, end: int) -> _Chunk:
        if pos + 36 > end:
            raise _Damaged('short chunk index')
        start_time = _U64.unpack_from(buf, pos)[0]
        offset, length = _U64.unpack_from(buf, pos + 16)[0], _U64.unpack_from(buf, pos + 24)[0]
        n = _U32.unpack_from(buf, pos + 32)[0]
        p = pos + 36
        if p + n + 8 > end or n % 10:
            raise _Damaged('chunk index offsets past the record')
        channels = frozenset(_U16.unpack_from(buf, q)[0] for q in range(p, p + n, 10))
        compression, p = _string(buf, p + n + 8, end)
        if p + 16 > end:
            raise _Damaged('short chunk index')
        return _Chunk(start_time, offset, length, channels, compression,
                      _U64.unpack_from(buf, p)[0], _U64.unpack_from(buf, p + 8)[0])

    def chunk_messages(self, chunk: _Chunk, wanted: set[int], into: bytearray
                       ) -> list[tuple[int, int, memoryview]]:
        """(log time, channel id, cdr view) of ``chunk``'s messages on ``wanted`` channels,
        sorted by log time (stable), read into ``into`` (at least ``chunk.length`` bytes;
        the views of an uncompressed chunk are views of it); [] for a damaged chunk."""
        try:
            if chunk.length < 9 + 40 or chunk.offset + chunk.length > self.size:
                raise _Damaged('chunk index entry past the file')
            buf = self._read(chunk.offset, chunk.length, into)
            p, end = 0, chunk.length
            if buf[0] != _OP_CHUNK or 9 + _U64.unpack_from(buf, 1)[0] != chunk.length:
                raise _Damaged('no chunk record of the indexed length at its offset')
            uncompressed = _U64.unpack_from(buf, p + 25)[0]
            compression, q = _string(buf, p + 37, end)
            size = _U64.unpack_from(buf, q)[0] if q + 8 <= end else -1
            if (compression, size, uncompressed) != (
                    chunk.compression, chunk.compressed_size, chunk.uncompressed_size) \
                    or q + 8 + size > end:
                raise _Damaged('chunk header differs from the index')
            records = buf[q + 8:q + 8 + size]
            decompress = _decompressor(compression)
            if decompress is not None:
                records = memoryview(decompress(records))
                if len(records) != uncompressed:
                    raise _Damaged('decompressed size differs from the index')
            found = []
            pos, stop = 0, len(records)
            while pos < stop:
                if pos + 9 > stop:
                    raise _Damaged('record header past the chunk')
                op, length = records[pos], _U64.unpack_from(records, pos + 1)[0]
                body, rec_end = pos + 9, pos + 9 + length
                if rec_end > stop:
                    raise _Damaged('record past the chunk')
                if op == _OP_MESSAGE:
                    if length < _MESSAGE.size:
                        raise _Damaged('short message record')
                    cid, _, log_time, _ = _MESSAGE.unpack_from(records, body)
                    if cid in wanted:
                        found.append((log_time, cid, records[body + _MESSAGE.size:rec_end]))
                pos = rec_end
        except (_Damaged, struct.error, IndexError, ValueError, RuntimeError):
            return []   # zstd/lz4 raise their own errors on damaged data
        found.sort(key=lambda m: m[0])
        return found


class McapMessages:
    """Image-topic messages of MCAP files (a rosbag2 bag's, in its order) as views.

    Args:
        paths: the bag's ``.mcap`` files in the bag's order.

    Raises :class:`McapIndexError` when a file cannot be read through its summary. Use as a
    context manager (it holds the files open). A view :meth:`messages` yields is valid
    until the next message is asked for: its chunk's buffer is then reused.
    """

    def __init__(self, paths: Sequence[str | Path]) -> None:
        self._files: list[_File] = []
        try:
            for path in paths:
                self._files.append(_File(Path(path)))
        except BaseException:
            self.close()
            raise

    def __enter__(self) -> McapMessages:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        files, self._files = self._files, []
        for f in files:
            f.close()

    def topics(self) -> dict[str, str]:
        """Topic -> message type of the channels the summaries declare."""
        return {topic: schema for f in self._files for topic, schema in f.channels.values()}

    def messages(self, topics: Iterable[str]) -> Iterator[tuple[str, str, memoryview]]:
        """(topic, message type, CDR view) of every message on ``topics``, in rosbags'
        order (module docstring); a chunk is decompressed when the merge reaches it."""
        topics = set(topics)
        buffers = _Buffers()
        for f in list(self._files):
            wanted = {cid for cid, (topic, _) in f.channels.items() if topic in topics}
            chunks = [c for c in f.chunks if not c.channels or c.channels & wanted]
            for _, _, cid, data in heapq.merge(*(self._chunk_source(f, c, wanted, buffers)
                                                 for c in chunks)):
                if cid >= 0:
                    topic, msgtype = f.channels[cid]
                    yield topic, msgtype, data

    @staticmethod
    def _chunk_source(f: _File, chunk: _Chunk, wanted: set[int], buffers: _Buffers
                      ) -> Iterator[tuple[int, int, int, memoryview | None]]:
        # a marker at the chunk's start time first, so the merge reads a chunk only when it
        # reaches it; ties between chunks go to the earlier offset. heapq.merge asks a
        # source for its next item after the caller has taken the previous one, so the
        # buffer goes back to the pool (and may be refilled) only after the caller asked
        # for the message after this chunk's last
        yield chunk.start_time, chunk.offset, -1, None
        buf = buffers.take(chunk.length)
        try:
            for log_time, cid, data in f.chunk_messages(chunk, wanted, buf):
                yield log_time, chunk.offset, cid, data
        finally:
            buffers.give(buf)
