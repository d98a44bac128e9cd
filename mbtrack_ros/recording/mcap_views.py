"""Messages of indexed MCAP files read in place: memory-mapped, never copied.

A raw camera image is most of its message (2.8 MB at 1280x720). rosbags reads a message by
copying its chunk from the file, then the record out of the chunk, then the message out of
the record, and checks the chunk's CRC when it has one. :class:`McapViews` maps each file
(``mmap``, read-only) and yields every message as a ``memoryview`` into the mapping (into
the decompressed chunk for a zstd or lz4 chunk): the pixels are first read by the one resize
to the tracker's working size (:func:`~mbtrack_ros.recording.images.decode_raw`). The MCAP
layout (https://mcap.dev/spec): the summary, read with the ``mcap`` library, lists the
chunks (``ChunkIndex``: offset, time range, the channels they hold); a chunk record is
``message_start_time, message_end_time, uncompressed_size`` (uint64), ``uncompressed_crc``
(uint32, 0: none), ``compression`` (string), ``records`` (uint64-sized bytes); a message
record ``channel_id`` (uint16), ``sequence`` (uint32), ``log_time, publish_time`` (uint64),
``data``. Messages come in log-time order across chunks and files (ties in file, chunk and
record order), as rosbags yields them. A chunk whose CRC or sizes do not fit raises
:class:`McapViewError` when it is reached (the messages before it have been yielded); a
damaged record inside a chunk without a CRC ends that chunk (``McapViews._records``).
"""
from __future__ import annotations

import heapq
import mmap
import struct
import zlib
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

from mcap.reader import make_reader

__all__ = ['McapViewError', 'McapViews']

_CHUNK = 0x06
_MESSAGE = 0x05
_U64 = struct.Struct('<Q')
_CHUNK_HEAD = struct.Struct('<QQQI')      # start time, end time, uncompressed size, CRC
_MESSAGE_HEAD = struct.Struct('<HIQQ')    # channel, sequence, log time, publish time


class McapViewError(ValueError):
    """An MCAP file that cannot be read in place (no summary, a damaged chunk: one line)."""


def _decompress(data: memoryview, compression: str, size: int) -> memoryview:
    if compression == '':
        return data
    if compression == 'zstd':
        try:
            from compression import zstd
        except ImportError:
            from backports import zstd
        return memoryview(zstd.decompress(data))
    if compression == 'lz4':
        import lz4.frame
        return memoryview(lz4.frame.decompress(data))
    raise McapViewError(f'unsupported chunk compression {compression[:20]!r}')


class McapViews:
    """The messages of MCAP files (one rosbag2 recording, its files in order) as views.

    Args:
        paths: the MCAP files; each must have a summary with chunk indexes (a file written
            to its end), else :class:`McapViewError`.

    Use :meth:`messages`, then :meth:`close` (or ``with``). The views stay valid while
    they are referenced (a mapping with live views is unmapped when the last one goes).
    """

    def __init__(self, paths: Sequence[str | Path]) -> None:
        self._maps: list[mmap.mmap] = []
        self._chunks: list[tuple[int, object]] = []   # (file index, ChunkIndex)
        self.channels: dict[tuple[int, int], tuple[str, str]] = {}  # (file, id) -> topic, type
        try:
            for k, path in enumerate(paths):
                with Path(path).open('rb') as handle:
                    summary = make_reader(handle).get_summary()
                    if summary is None or not summary.chunk_indexes:
                        raise McapViewError(f'{Path(path).name}: no summary with chunk indexes')
                    self._maps.append(mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ))
                for cid, channel in summary.channels.items():
                    schema = summary.schemas.get(channel.schema_id)
                    self.channels[k, cid] = (channel.topic, schema.name if schema else '')
                self._chunks.extend((k, index) for index in summary.chunk_indexes)
        except McapViewError:
            self.close()
            raise
        except Exception as err:   # the mcap library's errors of a damaged summary
            self.close()
            raise McapViewError(f'unreadable MCAP summary: {type(err).__name__}: '
                                f'{str(err)[:120]}') from err

    def messages(self, topics: Iterable[str]) -> Iterator[tuple[str, str, int, memoryview]]:
        """``(topic, message type, log time ns, cdr view)`` of the messages on ``topics``,
        in log-time order."""
        topics = set(topics)
        wanted = {key for key, (topic, _) in self.channels.items() if topic in topics}
        sources = []
        for k, index in sorted(self._chunks, key=lambda c: (c[1].message_start_time, c[0],
                                                            c[1].chunk_start_offset)):
            held = index.message_index_offsets   # channels with messages (empty: unknown)
            if held and not any((k, cid) in wanted for cid in held):
                continue
            sources.append(self._chunk_messages(k, index, wanted))
        for log_time, _, _, _, key, view in heapq.merge(*sources):
            if key is not None:
                topic, msgtype = self.channels[key]
                yield topic, msgtype, log_time, view

    def _chunk_messages(self, k: int, index, wanted: set) -> Iterator[tuple]:
        """The chunk's wanted messages as ``(log time, file, chunk offset, record, key,
        view)``, sorted by log time (ties in record order); first a marker at the chunk's
        start time, so that ``heapq.merge`` maps and decompresses a chunk only when its
        time comes."""
        at = index.chunk_start_offset
        yield (index.message_start_time, k, at, -1, None, None)
        found = [(log_time, k, at, n, key, view)
                 for n, (key, log_time, view) in enumerate(self._records(k, index))
                 if key in wanted]
        found.sort(key=lambda m: (m[0], m[3]))
        yield from found

    def _records(self, k: int, index) -> Iterator[tuple[tuple[int, int], int, memoryview]]:
        """``((file, channel id), log time, data view)`` of every message record of a
        chunk, in record order. A chunk outside the file, of another size than it declares
        or failing its CRC raises :class:`McapViewError`; records after a damaged record
        length (without a CRC to tell) are skipped, as rosbags skips them: the bag's
        message counts then tell the loss (``RecordingReader.frames``)."""
        where = f'chunk at byte {index.chunk_start_offset}'
        buf = memoryview(self._maps[k])
        pos = index.chunk_start_offset
        if pos + 9 + _CHUNK_HEAD.size + 4 > len(buf) or buf[pos] != _CHUNK:
            raise McapViewError(f'{where}: not a chunk record')
        end = pos + 9 + _U64.unpack_from(buf, pos + 1)[0]
        _, _, size, crc = _CHUNK_HEAD.unpack_from(buf, pos + 9)
        p = pos + 9 + _CHUNK_HEAD.size
        n = struct.unpack_from('<I', buf, p)[0]
        compression = bytes(buf[p + 4:p + 4 + n]).decode('utf-8', 'replace')
        p += 4 + n
        if end > len(buf) or p + 8 > end:
            raise McapViewError(f'{where}: runs past the end of the file')
        length = _U64.unpack_from(buf, p)[0]
        if p + 8 + length > end:
            raise McapViewError(f'{where}: records run past the chunk')
        records = _decompress(buf[p + 8:p + 8 + length], compression, size)
        if len(records) != size:
            raise McapViewError(f'{where}: {len(records)} bytes, the chunk declares {size}')
        if crc and zlib.crc32(records) != crc:
            raise McapViewError(f'{where}: checksum mismatch')
        q = 0
        while q + 9 <= size:
            op = records[q]
            stop = q + 9 + _U64.unpack_from(records, q + 1)[0]
            if stop > size or (op == _MESSAGE and stop - q - 9 < _MESSAGE_HEAD.size):
                return   # a damaged record: the rest of the chunk is skipped, as rosbags does
            if op == _MESSAGE:
                cid, _, log_time, _ = _MESSAGE_HEAD.unpack_from(records, q + 9)
                yield (k, cid), log_time, records[q + 9 + _MESSAGE_HEAD.size:stop]
            q = stop

    def close(self) -> None:
        """Unmap the files (a mapping still viewed is unmapped when its views go)."""
        for m in self._maps:
            try:
                m.close()
            except BufferError:   # views alive: the mapping closes with the last one
                pass
        self._maps = []

    def __enter__(self) -> McapViews:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
