"""Nearest-capture-time synchronisation of camera streams into frame sets (pure Python).

The tracker needs one image per camera of (nearly) the same instant. Cameras deliver frames
independently: hardware-triggered ones with jitter, free-running ones (USB, IP) at the same
rate but with capture times anywhere within a frame period of each other, all with the odd
drop and the odd silent camera. One :class:`FrameSetSynchronizer` serves the live node and
the offline replay (:meth:`~mbtrack_ros.recording.bag.RecordingReader.frames`). It buffers
frames per camera and emits :class:`FrameSet` objects in time order:

* **capture time**: a frame's capture time is its header stamp plus its camera's
  ``time_offset`` (a constant clock offset of that camera, seconds; ``Camera.time_offset``
  in the calibration);
* **nearest capture time**: a set has a reference time ``r``; each camera contributes the
  frame whose capture time is nearest ``r`` among its frames within ``tolerance`` of it.
  The tolerance defaults to half the frame period, so a set may span a whole period:
  free-running cameras, whatever their phases, give complete sets. The first reference is
  the oldest buffered capture time plus the tolerance; after each set the next reference
  is the set's mean capture time plus one frame period, so the window follows the
  cameras' phases and centres itself again after a dropped frame;
* **frame period**: the median difference of consecutive capture times of every camera
  (the last 16 of each), or ``1 / frame_rate`` until that is measured. A given frame rate
  the stamps contradict (measured period off by more than 25 %) gives one warning
  (:attr:`FrameSetSynchronizer.warnings`), and the measured period is used;
* **incomplete** sets, with the views that are there and the names of the missing cameras,
  when every missing camera has already delivered a frame past the window, or when a frame
  ``timeout`` newer than the set's reference time arrived (a camera that fell silent never
  stalls the others);
* after a **reset**: stamps going backwards on a camera (a bag restarted, simulated time
  reset) or jumping forward by more than ``jump_ns`` clear all buffers; the next emitted set
  carries ``after_reset=True`` so the caller can reset its tracker too.

Every set keeps each image's own capture time (:attr:`FrameSet.stamps`); the set's stamp is
the **latest** capture time in it (the tracker's state and every published output refer to
that instant; the filter predicts each camera's particles to the camera's own capture time,
:meth:`mbtrack_ros.core.likelihood.MeasurementModel.set_capture_offsets`).

Time is message time only (integer nanoseconds), never wall-clock time, so replay at any
rate gives the same sets.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

__all__ = ['FrameSet', 'FrameSetSynchronizer', 'SyncCounters', 'SyncError']

_PERIOD_SAMPLES = 16      # capture-time differences kept per camera for the period
_RATE_MISMATCH = 0.25     # relative period difference that contradicts a given frame rate


class SyncError(ValueError):
    """Invalid synchroniser configuration or an unknown camera."""


@dataclass
class FrameSet:
    """Images of (nearly) the same instant, one per camera that delivered one.

    Attributes:
        index: running number of emitted sets (0-based, not reset by :meth:`reset`).
        stamp_ns: the set's stamp: the latest capture time in it (or 1 ns after the
            previous set's stamp, should that be later), integer ns.
        images: camera name -> image (whatever object was passed to ``add``).
        stamps: camera name -> that frame's own capture time (stamp + time offset), ns.
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
        tolerance_ns: largest distance of a frame's capture time from its set's reference
            time, ns; 0 (default): half the frame period.
        timeout_ns: how long (in message time) past a set's reference time to wait for a
            late camera, ns (> tolerance).
        frame_rate: the cameras' nominal frame rate, Hz; 0: measured from the stamps. Used
            until the period is measured, and checked against it.
        time_offsets: camera name -> seconds added to its stamps to give its capture time
            on the common clock (default 0 for every camera).
        jump_ns: a frame newer than the newest seen by more than this resets, ns.
        max_queue: frames kept per camera; the oldest is dropped on overflow.
    """

    def __init__(self, cameras: list[str] | tuple[str, ...], tolerance_ns: int = 0,
                 timeout_ns: int = 200_000_000, *, frame_rate: float = 0.0,
                 time_offsets: dict[str, float] | None = None,
                 jump_ns: int = 10_000_000_000, max_queue: int = 32) -> None:
        cameras = tuple(str(c) for c in cameras)
        if not cameras:
            raise SyncError('at least one camera is needed')
        if len(set(cameras)) != len(cameras):
            raise SyncError(f'duplicate camera names in {list(cameras)}')
        if int(tolerance_ns) < 0:
            raise SyncError(f'tolerance_ns must be >= 0, got {tolerance_ns}')
        if int(timeout_ns) <= 0:
            raise SyncError(f'timeout_ns must be > 0, got {timeout_ns}')
        if int(timeout_ns) <= int(tolerance_ns):
            raise SyncError(f'timeout_ns ({timeout_ns}) must exceed the tolerance '
                            f'({tolerance_ns})')
        if int(jump_ns) <= int(timeout_ns):
            raise SyncError(f'jump_ns ({jump_ns}) must exceed timeout_ns ({timeout_ns})')
        if int(max_queue) < 1:
            raise SyncError('max_queue must be >= 1')
        if not (frame_rate >= 0 and frame_rate < float('inf')):
            raise SyncError(f'frame_rate must be a number of Hz >= 0, got {frame_rate}')
        offsets = dict(time_offsets or {})
        unknown = sorted(set(offsets) - set(cameras))
        if unknown:
            raise SyncError(f'time offsets of unknown camera(s) {", ".join(unknown)}')
        self.cameras = cameras
        self.tolerance_ns = int(tolerance_ns)
        self.timeout_ns = int(timeout_ns)
        self.frame_rate = float(frame_rate)
        self.offsets_ns = {c: int(round(float(offsets.get(c, 0.0)) * 1e9)) for c in cameras}
        self.jump_ns = int(jump_ns)
        self.max_queue = int(max_queue)
        self.counters = SyncCounters(missing={c: 0 for c in cameras})
        #: one-line warnings not yet shown (the caller logs and clears them)
        self.warnings: list[str] = []
        self._rate_checked = False
        self._queues: dict[str, deque[tuple[int, Any]]] = {c: deque() for c in cameras}
        self._diffs: dict[str, deque[int]] = {c: deque(maxlen=_PERIOD_SAMPLES)
                                              for c in cameras}
        self._last: dict[str, int] = {}
        self._newest: int | None = None
        self._reference: int | None = None
        self._emitted: int | None = None  # end of the last emitted set's window
        self._last_set: int | None = None  # stamp of the last emitted set
        self._index = 0
        self._after_reset = False

    # -- public ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget every buffered frame and stamp (counters and the measured frame period
        are kept: a replay that starts again runs at the same rate)."""
        for q in self._queues.values():
            q.clear()
        self._last.clear()
        self._newest = None
        self._reference = None
        self._emitted = None
        self._after_reset = True

    @property
    def pending(self) -> dict[str, int]:
        """Buffered frames per camera."""
        return {c: len(q) for c, q in self._queues.items()}

    @property
    def period_ns(self) -> int | None:
        """The frame period in use, ns: measured (median of the recent capture-time
        differences of all cameras), else ``1 / frame_rate``, else None (not known yet)."""
        diffs = sorted(d for q in self._diffs.values() for d in q)
        if diffs:
            return diffs[len(diffs) // 2]
        if self.frame_rate > 0:
            return int(round(1e9 / self.frame_rate))
        return None

    @property
    def tolerance(self) -> int | None:
        """The tolerance in use, ns (``tolerance_ns`` or half the period, at least 1 ns so
        that a window is never empty; None: unknown)."""
        if self.tolerance_ns:
            return self.tolerance_ns
        period = self.period_ns
        return None if period is None else max(1, period // 2)

    def add(self, camera: str, stamp_ns: int, image: Any) -> list[FrameSet]:
        """Buffer one frame (header stamp, ns); return the sets that became ready, oldest
        first."""
        if camera not in self._queues:
            raise SyncError(f'unknown camera {camera!r}; known: {", ".join(self.cameras)}')
        stamp_ns = int(stamp_ns) + self.offsets_ns[camera]   # capture time
        self.counters.frames += 1
        last = self._last.get(camera)
        if (last is not None and stamp_ns < last) or (
                self._newest is not None and stamp_ns > self._newest + self.jump_ns):
            self.counters.resets += 1
            self.reset()
            last = None
        elif last is not None and stamp_ns == last:
            self.counters.dropped_frames += 1  # duplicate stamp on one camera
            return []
        if last is not None:
            self._diffs[camera].append(stamp_ns - last)
            self._check_rate()
        self._last[camera] = stamp_ns
        self._newest = stamp_ns if self._newest is None else max(self._newest, stamp_ns)
        if self._emitted is not None and stamp_ns < self._emitted:
            self.counters.dropped_frames += 1  # too late: its set has already been emitted
            return []
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
    def _check_rate(self) -> None:
        """One warning when the measured period contradicts the given frame rate."""
        if self._rate_checked or self.frame_rate <= 0:
            return
        samples = sum(len(d) for d in self._diffs.values())
        if samples < min(_PERIOD_SAMPLES, 4 * len(self.cameras)):
            return
        self._rate_checked = True
        measured = self.period_ns
        expected = 1e9 / self.frame_rate
        if measured and abs(measured - expected) > _RATE_MISMATCH * expected:
            self.warnings.append(
                f'the image stamps say {1e9 / measured:.3g} frames/s, not the '
                f'{self.frame_rate:.3g} given; synchronising with the measured rate')

    def _drain(self, *, force: bool) -> list[FrameSet]:
        out: list[FrameSet] = []
        while True:
            heads = [q[0][0] for q in self._queues.values() if q]
            if not heads:
                return out
            tol = self.tolerance
            if tol is None:
                if not force and len(self.cameras) > 1:
                    return out   # the period is not known yet: wait for a second frame
                tol = self.timeout_ns // 2   # (one camera: each frame is a set of its own)
            anchor = min(heads)
            ref = self._reference
            if ref is None or ref + tol <= anchor:
                ref = anchor + tol   # first set, or nothing in the expected window
            start, end = ref - tol, ref + tol   # the window [start, end)
            picks: dict[str, int] = {}  # camera -> position in its queue
            waiting = False
            for cam, q in self._queues.items():
                while q and q[0][0] < start:       # older than the window: a late frame
                    q.popleft()
                    self.counters.dropped_frames += 1
                best = None
                for i, (stamp, _) in enumerate(q):
                    if stamp >= end:
                        break
                    if best is None or abs(stamp - ref) < abs(q[best][0] - ref):
                        best = i
                if best is not None:
                    picks[cam] = best
                elif self._last.get(cam, start - 1) < end:
                    waiting = True  # this camera may still deliver a frame for the window
            if not any(self._queues.values()):
                return out
            complete = len(picks) == len(self.cameras)
            timed_out = self._newest is not None and self._newest >= max(
                end, ref + self.timeout_ns)
            if not (complete or force or timed_out or not waiting):
                return out
            if not picks:   # the window is empty (frames were all late): move on
                self._reference = ref + 2 * tol
                continue
            out.append(self._emit(picks, end))

    def _emit(self, picks: dict[str, int], end: int) -> FrameSet:
        images: dict[str, Any] = {}
        stamps: dict[str, int] = {}
        for cam, pos in picks.items():
            q = self._queues[cam]
            for _ in range(pos):      # a second frame in the window: not the nearest
                q.popleft()
                self.counters.dropped_frames += 1
            stamp, image = q.popleft()
            images[cam], stamps[cam] = image, stamp
        missing = tuple(c for c in self.cameras if c not in images)
        if missing:
            self.counters.incomplete += 1
            for c in missing:
                self.counters.missing[c] += 1
        else:
            self.counters.complete += 1
        period = self.period_ns
        if period is None:   # no period yet (one camera, or a flush): start afresh
            self._reference = None
            self._emitted = max(stamps.values()) + 1
        else:
            # the next window: centred one period after this set's mean capture time
            self._reference = int(round(sum(stamps.values()) / len(stamps))) + period
            self._emitted = min(end, self._reference - (self.tolerance or 0))
        # the latest capture; never before the previous set's (an incomplete set after a
        # complete one could end earlier, and the tracker's time must not go back)
        stamp = max(stamps.values())
        if self._last_set is not None and not self._after_reset:
            stamp = max(stamp, self._last_set + 1)
        self._last_set = stamp
        fs = FrameSet(index=self._index, stamp_ns=stamp,
                      images={c: images[c] for c in self.cameras if c in images},
                      stamps={c: stamps[c] for c in self.cameras if c in stamps},
                      missing=missing, after_reset=self._after_reset)
        self._index += 1
        self._after_reset = False
        return fs
