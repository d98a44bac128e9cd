"""Writing the tracker's frame results beside the tracker, for ``mbtrack replay``.

:class:`BackgroundWriter` hands results to a writer (``nodes.output_bag.OutputBagWriter``
for ``tracks.mcap``) in a thread or in a child Python process. This module imports nothing
but the standard library and numpy, so the child (``python -c '... import serve; serve()'``)
starts without the tracker's imports (numba, scipy, rosbags' readers): it imports only what
unpickling the writer's factory needs (rclpy's serialisation and the message builders).
"""
from __future__ import annotations

import dataclasses
import os
import pickle
import queue
import subprocess
import sys
import threading

import numpy as np

__all__ = ['BackgroundWriter', 'DiagnosticCounts', 'output_bag_writer', 'serve']

# Bytes of pickled results buffered before they are written to the child's pipe (a frame
# with 4 tracks pickles to ~2 kB). One pipe write per frame cost the replay's main thread
# ~0.9 ms (load 6): each write releases the interpreter lock, and taking it back waits for
# the reader thread.
_PIPE_BUFFER = 32768
# Linux: fcntl F_SETPIPE_SZ, and the size asked for the pipe to the child (capped by
# /proc/sys/fs/pipe-max-size): ~500 frame results, so that a child running behind at a
# lower priority does not block the tracker's writes.
_F_SETPIPE_SZ = 1031
_PIPE_SIZE = 1 << 20


@dataclasses.dataclass(frozen=True)
class DiagnosticCounts:
    """A ``/diagnostics`` message to write at ``stamp_ns``: ``values`` are
    ``nodes.messages.DiagnosticsSnapshot`` fields (``OutputBagWriter.write_diagnostics``)."""

    stamp_ns: int
    values: dict


def _write_item(writer, item) -> None:
    if isinstance(item, DiagnosticCounts):
        writer.write_diagnostics(item.stamp_ns, item.values)
    else:
        writer.write(item)


def output_bag_writer(path, camera_names: list[str], frame_id: str):
    """``OutputBagWriter(path, None, camera_names, frame_id=frame_id)``, imported where it is
    called: a picklable factory for :class:`BackgroundWriter` whose unpickling in the child
    imports neither rclpy in the parent nor the room calibration's module in the child."""
    from mbtrack_ros.nodes.output_bag import OutputBagWriter
    return OutputBagWriter(path, None, list(camera_names), frame_id=frame_id)


class BackgroundWriter:
    """Writes frame results to an ``OutputBagWriter`` beside the tracker (in order): in a
    thread (bounded queue), or with ``process`` in a child Python process fed through a pipe.

    Building and serialising the rclpy messages of a frame (MarkerArray above all) costs
    ~3 ms of CPU with 4 tracks, all of it holding the interpreter lock; in a thread it
    still competes with the tracker's Python code for that lock, in a child process it
    runs on the other core (the same writer code, the same bag). The child is a fresh
    interpreter (``python -c``), not a ``multiprocessing`` child, so it never re-imports
    the caller's main script. Each result is snapshotted (track means and covariances
    copied, particles left out) so the tracker may reuse its buffers. A write error is
    raised by a later :meth:`write` or by :meth:`close`.

    Args:
        writer: the writer object (thread), or with ``process`` a picklable callable that
            builds it in the child.
        wait: with ``process``, wait until the child has built the writer (its error, e.g.
            an existing bag, raised here); with False the child starts (its imports, ~1 s)
            while the caller goes on, and :meth:`ready` (or the first :meth:`write`) waits.
        niceness: with ``process``, the child's niceness above the caller's (0: the same):
            it then takes the CPU the tracker's threads leave, and a larger pipe holds what
            it has not written yet (``close`` waits for it).
    """

    def __init__(self, writer, depth: int = 8, *, process: bool = False,
                 wait: bool = True, niceness: int = 0) -> None:
        self._error: BaseException | None = None
        self._child: subprocess.Popen | None = None
        self._starting = False
        if process:
            env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
            self._child = subprocess.Popen(
                [sys.executable, '-c', 'from mbtrack_ros.commands.output_writer import '
                 'serve; serve()'],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, bufsize=_PIPE_BUFFER)
            if niceness:
                _lower_priority(self._child.pid, self._child.stdin.fileno(), niceness)
            self._send(writer)
            self._starting = True
            if wait:
                self.ready()
            return
        self._writer = writer
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._thread = threading.Thread(target=self._run, name='output_bag', daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            result = self._queue.get()
            if result is None:
                return
            if self._error is None:
                try:
                    _write_item(self._writer, result)
                except BaseException as err:  # reported in the main thread
                    self._error = err

    def ready(self) -> None:
        """Wait until the child process has built the writer; raise its error if it could
        not (then the child has stopped)."""
        if not self._starting:
            return
        self._starting = False
        failed = self._reply()  # None once the child's writer exists
        if failed is not None:
            self._child.wait()
            self._error = failed
            raise failed

    def discard(self) -> None:
        """Stop a writer that will not be used (the caller failed before tracking): the
        child closes its bag without writing a frame."""
        if self._child is None:
            self.close()
            return
        try:
            self.ready()
            self.close()
        except BaseException:  # noqa: BLE001 - the caller's own error matters here
            pass

    def _send(self, item, *, flush: bool = True) -> None:
        """Pickle ``item`` to the child (results without ``flush``: they reach the pipe
        when the buffer fills, a dozen frames at a time); when the child has stopped, raise
        its error."""
        try:
            pickle.dump(item, self._child.stdin)
            if flush:
                self._child.stdin.flush()
        except (BrokenPipeError, OSError):
            self._error = self._error or self._reply() or RuntimeError(
                'the output bag writer process stopped')
            raise self._error from None

    def _reply(self) -> BaseException | None:
        """The child's next reply: None (ready / closed) or its error."""
        try:
            return pickle.load(self._child.stdout)
        except (EOFError, pickle.UnpicklingError, OSError):
            return RuntimeError(f'the output bag writer process ended without a reply '
                                f'(exit code {self._child.wait()})')

    def write(self, result) -> None:
        self.ready()
        if self._error is not None:
            raise self._error
        tracks = [dataclasses.replace(t, mean=np.array(t.mean), covariance=np.array(
            t.covariance), visible_fraction=dict(t.visible_fraction),
            visibility=dict(t.visibility), particles=None, weights=None)
            for t in result.tracks]
        item = dataclasses.replace(result, tracks=tracks, ended=list(result.ended))
        if self._child is not None:
            self._send(item, flush=False)
        else:
            self._queue.put(item)

    def write_diagnostics(self, stamp_ns: int, values: dict) -> None:
        """Queue a ``/diagnostics`` message with these counts (:class:`DiagnosticCounts`)."""
        self.ready()
        if self._error is not None:
            raise self._error
        item = DiagnosticCounts(int(stamp_ns), dict(values))
        if self._child is not None:
            self._send(item, flush=False)
        else:
            self._queue.put(item)

    def close(self) -> None:
        """Write what is queued, close the bag, raise a write error if one happened."""
        self.ready()
        if self._child is None:
            self._queue.put(None)
            self._thread.join()
            self._writer.close()
        elif self._error is None:
            self._send(None)
            self._child.stdin.close()
            self._error = self._reply()  # None when the bag was closed without error
            self._child.wait()
        if self._error is not None:
            raise self._error


def _lower_priority(pid: int, pipe_fd: int, niceness: int) -> None:
    """Raise the niceness of process ``pid`` by ``niceness`` and enlarge the pipe that
    feeds it, where the system allows (best effort: neither changes what is written)."""
    try:
        os.setpriority(os.PRIO_PROCESS, pid, os.getpriority(os.PRIO_PROCESS, 0) + niceness)
    except (AttributeError, OSError):
        pass
    try:
        import fcntl
        with open('/proc/sys/fs/pipe-max-size') as limit:
            fcntl.fcntl(pipe_fd, _F_SETPIPE_SZ, min(_PIPE_SIZE, int(limit.read())))
    except (ImportError, OSError, ValueError):  # not Linux: the default pipe
        pass


def serve() -> None:
    """The child process of ``BackgroundWriter(..., process=True)``: from stdin, a callable
    that builds the writer, then results until None; to stdout, None once the writer exists
    and None when the bag is closed, or the first error (then the child stops)."""
    source = sys.stdin.buffer
    replies = os.fdopen(os.dup(1), 'wb')  # the pipe; anything printed goes to stderr
    os.dup2(2, 1)
    sys.stdout = sys.stderr

    def reply(value) -> None:
        try:
            pickle.dump(value, replies)
        except Exception:  # noqa: BLE001 - an error that does not pickle
            pickle.dump(RuntimeError(f'{type(value).__name__}: {value}'), replies)
        replies.flush()

    try:
        writer = pickle.load(source)()
        reply(None)
        while (result := pickle.load(source)) is not None:
            _write_item(writer, result)
        writer.close()
    except BaseException as err:  # noqa: BLE001 - raised in the parent
        reply(err)
        raise SystemExit(1) from None
    reply(None)
    # the bag is closed and the parent told: end without the interpreter's tear-down of
    # rclpy and the message modules (~0.2 s that the parent's close() waited for)
    sys.stderr.flush()
    os._exit(0)
