"""Approximate-time synchronisation of several camera streams into frame sets (pure Python).

The tracker needs one image per camera taken at (nearly) the same time. Cameras deliver
frames independently, with jitter, drops and the odd silent camera. The
:class:`FrameSetSynchronizer` buffers frames per camera and emits :class:`FrameSet` objects
in stamp order:

* **complete** sets: every camera has a frame within ``slop_ns`` of the set's anchor (the
  oldest buffered frame);
* **incomplete** sets, with the views that are there and the names of the missing cameras,
  when the set can no longer be completed (each missing camera already delivered a newer
  frame past the window) or when a frame newer than ``anchor + timeout_ns`` arrived (a
  camera that fell silent never stalls the others);
* after a **reset**: stamps going backwards on a camera (a bag restarted, simulated time
  reset) or jumping forward by more than ``jump_ns`` clear all buffers; the next emitted set
  carries ``after_reset=True`` so the caller can reset its tracker too.

Time is message time only (integer nanoseconds), never wall-clock time, so replay at any
rate gives the same sets.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

__all__ = ['FrameSet', 'FrameSetSynchronizer', 'SyncCounters', 'SyncError']


class SyncError(ValueError):
    """Invalid synchroniser configuration or an unknown camera."""


@dataclass
class FrameSet:
    """Images of (nearly) the same instant, one per camera that delivered one.

    Attributes:
        index: running number of emitted sets (0-based, not reset by :meth:`reset`).
        stamp_ns: the set's stamp: the oldest frame stamp in it, integer ns.
        images: camera name -> image (whatever object was passed to ``add``).
        stamps: camera name -> that frame's own stamp, ns.
        missing: cameras without a frame in this set, in configuration order.
        after_reset: True for the first set after a reset (stamps jumped or went back).
    """

    index: int
    stamp_ns: int
    images: dict[str, Any]
    stamps: dict[str, int]
    missing: tuple[str, ...] = ()
    after_reset: bool = False

    @property
    def complete(self) -> bool:
        return not self.missing


@dataclass
class SyncCounters:
    """Running counts (never reset by :meth:`FrameSetSynchronizer.reset`)."""

    frames: int = 0
    complete: int = 0
    incomplete: int = 0
    dropped_frames: int = 0
    resets: int = 0
    missing: dict[str, int] = field(default_factory=dict)


class FrameSetSynchronizer:
    """Group frames of ``cameras`` into frame sets (see the module docstring).

    Args:
        cameras: camera names; every emitted set refers to these.
        slop_ns: largest stamp difference between frames of one set, ns (>= 0).
        timeout_ns: how long (in message time) to wait for a late camera, ns (> slop_ns).
        jump_ns: a frame newer than the newest seen by more than this resets, ns.
        max_queue: frames kept per camera; the oldest is dropped on overflow.
    """

    def __init__(self, cameras: list[str] | tuple[str, ...], slop_ns: int, timeout_ns: int,
                 *, jump_ns: int = 10_000_000_000, max_queue: int = 32) -> None:
        cameras = tuple(str(c) for c in cameras)
        if not cameras:
            raise SyncError('at least one camera is needed')
        if len(set(cameras)) != len(cameras):
            raise SyncError(f'duplicate camera names in {list(cameras)}')
        if int(slop_ns) < 0:
            raise SyncError(f'slop_ns must be >= 0, got {slop_ns}')
        if int(timeout_ns) <= int(slop_ns):
            raise SyncError(f'timeout_ns ({timeout_ns}) must exceed slop_ns ({slop_ns})')
        if int(jump_ns) <= int(timeout_ns):
            raise SyncError(f'jump_ns ({jump_ns}) must exceed timeout_ns ({timeout_ns})')
        if int(max_queue) < 1:
            raise SyncError('max_queue must be >= 1')
        self.cameras = cameras
        self.slop_ns = int(slop_ns)
        self.timeout_ns = int(timeout_ns)
        self.jump_ns = int(jump_ns)
        self.max_queue = int(max_queue)
        self.counters = SyncCounters(missing={c: 0 for c in cameras})
        self._queues: dict[str, deque[tuple[int, Any]]] = {c: deque() for c in cameras}
        self._last: dict[str, int] = {}
        self._newest: int | None = None
        self._emitted: int | None = None
        self._last_missing: tuple[str, ...] = ()
        self._index = 0
        self._after_reset = False

    # -- public ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget every buffered frame and stamp (counters are kept)."""
        for q in self._queues.values():
            q.clear()
        self._last.clear()
        self._newest = None
        self._emitted = None
        self._last_missing = ()
        self._after_reset = True

    @property
    def pending(self) -> dict[str, int]:
        """Buffered frames per camera."""
        return {c: len(q) for c, q in self._queues.items()}

    def add(self, camera: str, stamp_ns: int, image: Any) -> list[FrameSet]:
        """Buffer one frame; return the frame sets that became ready, oldest first."""
        if camera not in self._queues:
            raise SyncError(f'unknown camera {camera!r}; known: {", ".join(self.cameras)}')
        stamp_ns = int(stamp_ns)
        self.counters.frames += 1
        last = self._last.get(camera)
        if (last is not None and stamp_ns < last) or (
                self._newest is not None and stamp_ns > self._newest + self.jump_ns):
            self.counters.resets += 1
            self.reset()
        elif last is not None and stamp_ns == last:
            self.counters.dropped_frames += 1  # duplicate stamp on one camera
            return []
        elif self._emitted is not None and stamp_ns <= self._emitted + (
                self.slop_ns if camera in self._last_missing else 0):
            self.counters.dropped_frames += 1  # too late: its set has already been emitted
            self._last[camera] = stamp_ns
            return []
        self._last[camera] = stamp_ns
        self._newest = stamp_ns if self._newest is None else max(self._newest, stamp_ns)
        queue = self._queues[camera]
        queue.append((stamp_ns, image))
        if len(queue) > self.max_queue:
            queue.popleft()
            self.counters.dropped_frames += 1
        return self._drain(force=False)

    def flush(self) -> list[FrameSet]:
        """Emit everything still buffered (end of stream), as possibly incomplete sets."""
        return self._drain(force=True)

    # -- internals ------------------------------------------------------------------------
    def _drain(self, *, force: bool) -> list[FrameSet]:
        out: list[FrameSet] = []
        while True:
            heads = [q[0][0] for q in self._queues.values() if q]
            if not heads:
                return out
            anchor = min(heads)
            window_end = anchor + self.slop_ns
            picks: dict[str, int] = {}  # camera -> position in its queue (always the head)
            waiting = False
            for cam, q in self._queues.items():
                # queues are sorted and no frame is older than the anchor, so the head is
                # the frame closest to the anchor
                if q and q[0][0] <= window_end:
                    picks[cam] = 0
                elif not q:
                    waiting = True  # this camera may still deliver a frame for the window
            complete = len(picks) == len(self.cameras)
            timed_out = self._newest is not None and self._newest > anchor + self.timeout_ns
            if not (complete or force or timed_out or not waiting):
                return out
            out.append(self._emit(anchor, picks))

    def _emit(self, anchor: int, picks: dict[str, int]) -> FrameSet:
        images: dict[str, Any] = {}
        stamps: dict[str, int] = {}
        for cam in picks:
            stamp, image = self._queues[cam].popleft()
            images[cam], stamps[cam] = image, stamp
        missing = tuple(c for c in self.cameras if c not in images)
        if missing:
            self.counters.incomplete += 1
            for c in missing:
                self.counters.missing[c] += 1
        else:
            self.counters.complete += 1
        fs = FrameSet(index=self._index, stamp_ns=anchor,
                      images={c: images[c] for c in self.cameras if c in images},
                      stamps=stamps, missing=missing, after_reset=self._after_reset)
        self._index += 1
        self._after_reset = False
        self._emitted = anchor
        self._last_missing = missing
        return fs
