"""FrameSetSynchronizer: complete sets, slop, silent cameras, resets (pure Python, no ROS)."""
from __future__ import annotations

import numpy as np
import pytest

from mbtrack_ros.recording.sync import FrameSetSynchronizer, SyncError

MS = 1_000_000
PERIOD = 40 * MS
CAMS = ('cam0', 'cam1', 'cam2')


def feed(sync, events):
    out = []
    for cam, stamp in events:
        out += sync.add(cam, stamp, (cam, stamp))
    return out


def jittered_stream(n, cams=CAMS, *, seed=0, jitter_ms=3, silent=None):
    """Frames of every camera with small jitter, arrival order shuffled within a frame."""
    rng = np.random.default_rng(seed)
    events = []
    for k in range(n):
        base = 1_000 * MS + k * PERIOD
        frame = [(c, base + int(rng.integers(0, jitter_ms * MS)))
                 for c in cams if not (silent and c in silent[0] and k in silent[1])]
        rng.shuffle(frame)
        events += [tuple(e) for e in frame]
    return events


def test_complete_sets_in_order_and_matching():
    sync = FrameSetSynchronizer(CAMS, slop_ns=10 * MS, timeout_ns=100 * MS)
    events = jittered_stream(20)
    sets = feed(sync, events)
    # the last frame set completes with its last frame, so all 20 are out
    assert len(sets) == 20
    assert all(s.complete and set(s.images) == set(CAMS) for s in sets)
    stamps = [s.stamp_ns for s in sets]
    assert stamps == sorted(stamps)
    for k, s in enumerate(sets):
        # every image of set k was taken in frame period k, and the set stamp is the oldest
        assert all((st - 1_000 * MS) // PERIOD == k for st in s.stamps.values())
        assert s.stamp_ns == min(s.stamps.values())
        assert all(s.images[c] == (c, s.stamps[c]) for c in CAMS)
    assert sync.counters.complete == 20 and sync.counters.incomplete == 0
    assert [s.index for s in sets] == list(range(20))


def test_slop_separates_frames_too_far_apart():
    sync = FrameSetSynchronizer(('a', 'b'), slop_ns=5 * MS, timeout_ns=100 * MS)
    sets = feed(sync, [('a', 0), ('b', 8 * MS)])  # 8 ms apart > slop: cannot be one set
    assert len(sets) == 1 and sets[0].missing == ('b',) and set(sets[0].images) == {'a'}
    sets = feed(sync, [('a', 40 * MS), ('b', 44 * MS)])  # b@8 alone, then a@40 + b@44
    assert [(s.stamp_ns, s.missing) for s in sets] == [(8 * MS, ('a',)), (40 * MS, ())]


def test_silent_camera_does_not_stall_and_comes_back():
    sync = FrameSetSynchronizer(CAMS, slop_ns=10 * MS, timeout_ns=100 * MS)
    silent = ({'cam2'}, set(range(10, 30)))
    sets, lags = [], []
    for cam, stamp in jittered_stream(40, silent=silent):
        new = sync.add(cam, stamp, (cam, stamp))
        sets += new
        lags += [stamp - s.stamp_ns for s in new]
    by_period = {(s.stamp_ns - 1_000 * MS) // PERIOD: s for s in sets}
    # every period up to the end of the timeout horizon is emitted exactly once
    assert sorted(by_period) == list(range(len(sets)))
    assert len(sets) == 40
    for k, s in by_period.items():
        if k in silent[1]:
            assert s.missing == ('cam2',) and set(s.images) == {'cam0', 'cam1'}
        else:
            assert s.complete, k
    assert sync.counters.incomplete == 20 and sync.counters.missing['cam2'] == 20
    # while cam2 was silent, sets went out at most a timeout (+ one period) behind the newest
    assert max(lags) <= 100 * MS + PERIOD
    assert sum(sync.pending.values()) == 0


def test_incomplete_set_released_by_timeout_only():
    sync = FrameSetSynchronizer(('a', 'b'), slop_ns=5 * MS, timeout_ns=100 * MS)
    assert feed(sync, [('a', 0), ('a', 40 * MS), ('a', 80 * MS)]) == []  # b may still come
    sets = feed(sync, [('a', 120 * MS)])  # 120 ms > timeout past the set at 0 -> released
    assert [(s.stamp_ns, s.missing) for s in sets] == [(0, ('b',))]
    rest = sync.flush()
    assert [s.stamp_ns for s in rest] == [40 * MS, 80 * MS, 120 * MS]


def test_late_frame_dropped_after_its_set_was_emitted():
    sync = FrameSetSynchronizer(('a', 'b'), slop_ns=5 * MS, timeout_ns=50 * MS)
    sets = feed(sync, [('a', 0), ('a', 40 * MS), ('a', 80 * MS)])
    assert [s.stamp_ns for s in sets] == [0]
    assert feed(sync, [('b', 2 * MS)]) == []  # belongs to the set already out
    assert sync.counters.dropped_frames == 1
    sets = feed(sync, [('b', 41 * MS)])
    assert [(s.stamp_ns, s.complete) for s in sets] == [(40 * MS, True)]


def test_stamps_backwards_reset():
    sync = FrameSetSynchronizer(('a', 'b'), slop_ns=5 * MS, timeout_ns=100 * MS)
    first = feed(sync, [('a', 5000 * MS), ('b', 5000 * MS), ('a', 5040 * MS)])
    assert len(first) == 1 and not first[0].after_reset
    # the bag restarts: both cameras go back to t = 0
    sets = feed(sync, [('b', 0), ('a', 1 * MS), ('a', 40 * MS), ('b', 40 * MS)])
    assert sync.counters.resets == 1
    assert [(s.stamp_ns, s.complete, s.after_reset) for s in sets] == [
        (0, True, True), (40 * MS, True, False)]


def test_forward_jump_resets():
    sync = FrameSetSynchronizer(('a',), slop_ns=0, timeout_ns=MS, jump_ns=1000 * MS)
    sets = feed(sync, [('a', 0), ('a', 40 * MS), ('a', 5000 * MS), ('a', 5040 * MS)])
    assert [s.after_reset for s in sets] == [False, False, True, False]
    assert sync.counters.resets == 1


def test_bad_configuration_and_unknown_camera():
    with pytest.raises(SyncError, match='unknown camera'):
        FrameSetSynchronizer(('a',), 0, 10).add('b', 0, None)
    with pytest.raises(SyncError, match='timeout_ns'):
        FrameSetSynchronizer(('a',), 10, 5)
    with pytest.raises(SyncError, match='duplicate'):
        FrameSetSynchronizer(('a', 'a'), 0, 10)
    with pytest.raises(SyncError, match='at least one'):
        FrameSetSynchronizer((), 0, 10)
