"""Frame sets read, decoded and resized in a child process (``mbtrack replay``'s input path).

Reading a recording costs CPU in proportion to its pixels: rosbags copies every message out
of its chunk (and checks a chunk's CRC when it has one), and the decoder resizes each image to the
tracker's working size (``RecordingReader.decode_to``). A 1280x720 camera moves 12 times
the bytes of a 320x240 one. In a thread of the tracker's process that work holds the
interpreter lock in its Python parts and copies, and the tracker's own threads (the
per-camera likelihood pool, the detection worker) wait for it. :class:`ReaderProcess`
runs the same :class:`~mbtrack_ros.recording.bag.RecordingReader` in a child Python
process (``python -c``, a fresh interpreter) at a lower priority: it uses the CPU the
tracker leaves, holds no lock of the tracker's, and sends each frame set, already at the
working size, through a pipe (about 1.2 MB for 5 cameras, whatever the camera's size).
The frame sets, their order, the synchroniser's warnings and counts and the position of a
:class:`~mbtrack_ros.recording.bag.BagError` are those of reading in the caller's process.

This module imports nothing of the tracker, so the child starts with the reader's imports
only (rosbags, OpenCV, the numba area shrink).
"""
from __future__ import annotations

import os
import pickle
import subprocess
import sys
from collections.abc import Iterator

__all__ = ['ReaderProcess', 'serve']

# Linux: fcntl F_SETPIPE_SZ; the pipe from the child holds about one 5-camera frame set at
# 320x240 (capped by /proc/sys/fs/pipe-max-size), so a read takes a frame set at once
_F_SETPIPE_SZ = 1031
_PIPE_SIZE = 1 << 20
# glibc's allocator in the child: blocks up to 32 MiB come from the heap, and freed heap
# memory is kept (up to 256 MiB), so that the next message's copies (rosbags reads a chunk,
# then its record, then the message; about 2.8 MB each at 1280x720) reuse the pages of the
# last one instead of mapping fresh ones (a page fault per 4 kB: 300 000 faults in 150
# frame sets of five 1280x720 cameras, 40 000 with these settings). Ignored elsewhere.
_TUNABLES = 'glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=268435456'
#: the child's niceness above the caller's: it takes the CPU the tracker's threads leave
#: and keeps a few frame sets ahead (prefetch depth), never starving: when the tracker waits
#: for a frame set, the reader is all that runs
READER_NICENESS = 5


class ReaderProcess:
    """Iterate the frame sets of ``reader`` (a :class:`RecordingReader`, opened and set up
    with ``limit_image_sizes`` / ``decode_to``) read in a child process.

    Use it as an iterator of :class:`~mbtrack_ros.recording.bag.FrameSet` and :meth:`close`
    it (or use ``with``); a :class:`BagError` of the reading is raised after every frame set
    read before it. After the last frame set, :attr:`warnings` holds the synchroniser's
    warnings and :attr:`dropped_frames` its count of images placed in no set (as
    ``reader.warnings`` and ``reader.sync.counters.dropped_frames`` after ``frames()``).

    Args:
        reader: the reader whose settings (``RecordingReader.settings``) the child opens.
        depth: frame sets received ahead of the caller (a thread of this process reads the
            pipe), besides the one the pipe holds.
        niceness: the child's niceness above this process's.
    """

    def __init__(self, reader, *, depth: int = 4, niceness: int = READER_NICENESS) -> None:
        from mbtrack_ros.recording.bag import prefetched

        self.warnings: list[str] = []
        self.dropped_frames = 0
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        env['GLIBC_TUNABLES'] = ':'.join(t for t in (env.get('GLIBC_TUNABLES'), _TUNABLES) if t)
        self._child = subprocess.Popen(
            [sys.executable, '-c',
             'from mbtrack_ros.recording.reader_process import serve; serve()'],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        _tune(self._child.pid, self._child.stdout.fileno(), niceness)
        try:
            pickle.dump(reader.settings(), self._child.stdin)
            self._child.stdin.close()
        except OSError:   # the child died at start: its reply (or EOF) says why
            pass
        self._items = prefetched(self._receive(), depth=depth)

    def _receive(self) -> Iterator:
        from mbtrack_ros.recording.bag import BagError

        source = self._child.stdout
        while True:
            try:
                kind, value = pickle.load(source)
            except (EOFError, pickle.UnpicklingError, OSError, ValueError) as err:
                code = self._child.poll()
                raise BagError(f'the bag reader process ended without finishing (exit code '
                               f'{code}, {type(err).__name__})') from None
            if kind == 'item':
                yield value
                continue
            error, self.warnings, self.dropped_frames = value
            if error is not None:
                raise error
            return

    def __iter__(self) -> Iterator:
        return self._items

    def __next__(self):
        return next(self._items)

    def close(self) -> None:
        """Stop the child (at once when the caller stops early) and the receiving thread."""
        if self._child.poll() is None:
            self._child.kill()
        self._items.close()
        self._child.wait()
        if not self._child.stdout.closed:
            self._child.stdout.close()

    def __enter__(self) -> ReaderProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _tune(pid: int, pipe_fd: int, niceness: int) -> None:
    """Raise the child's niceness by ``niceness`` and enlarge the pipe it writes into,
    where the system allows (best effort: neither changes what is read)."""
    if niceness:
        try:
            os.setpriority(os.PRIO_PROCESS, pid,
                           os.getpriority(os.PRIO_PROCESS, 0) + niceness)
        except (AttributeError, OSError):
            pass
    try:
        import fcntl
        with open('/proc/sys/fs/pipe-max-size') as limit:
            fcntl.fcntl(pipe_fd, _F_SETPIPE_SZ, min(_PIPE_SIZE, int(limit.read())))
    except (ImportError, OSError, ValueError):  # not Linux: the default pipe
        pass


def serve() -> None:
    """The child of :class:`ReaderProcess`: from stdin the reader's settings, to stdout
    ``('item', FrameSet)`` per frame set, then ``('end', (error or None, warnings,
    dropped images))``. It stops when the parent closes the pipe."""
    from mbtrack_ros.recording.bag import BagError, RecordingReader

    out = os.fdopen(os.dup(1), 'wb')   # the pipe; anything printed goes to stderr
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    error: BaseException | None = None
    reader = None
    try:
        reader = RecordingReader.from_settings(pickle.load(sys.stdin.buffer))
        with reader:
            for frame_set in reader.frames():
                pickle.dump(('item', frame_set), out, protocol=pickle.HIGHEST_PROTOCOL)
                out.flush()
    except (BrokenPipeError, KeyboardInterrupt):
        os._exit(0)   # the parent stopped early
    except BaseException as err:  # noqa: BLE001 - raised in the parent, in order
        error = err if isinstance(err, BagError) else BagError(
            f'reading the bag failed: {type(err).__name__}: {str(err)[:200]}')
    sync = getattr(reader, 'sync', None)
    try:
        pickle.dump(('end', (error, list(getattr(reader, 'warnings', [])),
                             sync.counters.dropped_frames if sync is not None else 0)), out)
        out.flush()
    except (BrokenPipeError, OSError):
        pass
    sys.stderr.flush()
    os._exit(0)
