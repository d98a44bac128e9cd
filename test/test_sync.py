"""FrameSetSynchronizer: nearest capture time, free-running cameras, silent cameras, resets
(pure Python, no ROS)."""
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


def jittered_stream(n, cams=CAMS, *, seed=0, jitter_ms=3, silent=None, phases=None,
                    period=PERIOD):
    """Frames of every camera (capture at ``k period + phase + jitter``), in stamp order;
    ``silent = (cameras, frame numbers)`` leaves frames out."""
    rng = np.random.default_rng(seed)
    phases = phases or {c: 0 for c in cams}
    events = []
    for k in range(n):
        base = 1_000 * MS + k * period
        events += [(c, base + phases[c] + int(rng.integers(0, jitter_ms * MS) if jitter_ms
                                              else 0))
                   for c in cams if not (silent and c in silent[0] and k in silent[1])]
    events.sort(key=lambda e: e[1])
    return events


def test_complete_sets_in_order_and_matching():
    sync = FrameSetSynchronizer(CAMS, timeout_ns=100 * MS)
    sets = feed(sync, jittered_stream(20)) + sync.flush()
    assert len(sets) == 20
    assert all(s.complete and set(s.images) == set(CAMS) for s in sets)
    stamps = [s.stamp_ns for s in sets]
    assert stamps == sorted(stamps)
    for k, s in enumerate(sets):
        # every image of set k was taken in frame period k; the set stamp is the latest
        assert all((st - 1_000 * MS) // PERIOD == k for st in s.stamps.values())
        assert s.stamp_ns == max(s.stamps.values())
        assert all(s.images[c] == (c, s.stamps[c]) for c in CAMS)
    assert sync.counters.complete == 20 and sync.counters.incomplete == 0
    assert [s.index for s in sets] == list(range(20))
    assert sync.period_ns is not None and abs(sync.period_ns - PERIOD) <= 3 * MS
    assert sync.tolerance == sync.period_ns // 2


@pytest.mark.parametrize('seed', range(6))
def test_free_running_cameras_spread_over_a_whole_period(seed):
    """Capture phases anywhere in [0, period): every set is complete (half-period
    tolerance around the set's reference), and each camera's frames come in order."""
    rng = np.random.default_rng(seed)
    cams = ('a', 'b', 'c', 'd')
    phases = dict(zip(cams, [0] + sorted(int(p) for p in rng.integers(0, PERIOD - 2 * MS,
                                                                         3))))
    sync = FrameSetSynchronizer(cams)
    sets = feed(sync, jittered_stream(60, cams, phases=phases, jitter_ms=1, seed=seed))
    sets += sync.flush()
    assert sum(s.complete for s in sets) >= 58
    assert len(sets) <= 61
    for c in cams:
        own = [s.stamps[c] for s in sets if c in s.stamps]
        assert own == sorted(own) and len(own) >= 59
    for s in sets:
        assert max(s.stamps.values()) - min(s.stamps.values()) < PERIOD


def test_nearest_frame_brute_force():
    """Two synchronised cameras with jitter and drops: each set pairs the frames of one
    frame period, as brute force (frame number = round((t - t0) / period)) says."""
    rng = np.random.default_rng(3)
    cams = ('a', 'b')
    drops = {c: set(rng.choice(80, 8, replace=False).tolist()) for c in cams}
    events = []
    for k in range(80):
        for c in cams:
            if k not in drops[c]:
                events.append((c, k * PERIOD + int(rng.integers(-4, 5)) * MS))
    events.sort(key=lambda e: e[1])
    sync = FrameSetSynchronizer(cams, timeout_ns=100 * MS)
    sets = feed(sync, events) + sync.flush()
    for s in sets:
        frames = {round(t / PERIOD) for t in s.stamps.values()}
        assert len(frames) == 1, s.stamps
    numbers = [round(s.stamp_ns / PERIOD) for s in sets]
    both = [k for k in range(80) if k not in drops['a'] | drops['b']]
    assert set(both) <= set(numbers)
    assert len(numbers) == len(set(numbers))


def test_explicit_tolerance_separates_frames_too_far_apart():
    sync = FrameSetSynchronizer(('a', 'b'), tolerance_ns=4 * MS, timeout_ns=100 * MS)
    sets = feed(sync, [('a', 0), ('b', 10 * MS)])  # 10 ms > 2 x 4 ms: never one set
    assert len(sets) == 1 and sets[0].missing == ('b',) and set(sets[0].images) == {'a'}


def test_time_offsets_shift_capture_times():
    """A camera whose clock is 30 ms late (offset -0.03 s) pairs with the frames taken
    when its own were."""
    sync = FrameSetSynchronizer(('a', 'b'), time_offsets={'b': -0.030})
    events = []
    for k in range(10):
        events += [('a', k * PERIOD), ('b', k * PERIOD + 30 * MS)]
    sets = feed(sync, events) + sync.flush()
    assert len(sets) == 10 and all(s.complete for s in sets)
    assert all(s.stamps['a'] == s.stamps['b'] for s in sets)
    with pytest.raises(SyncError, match='unknown camera'):
        FrameSetSynchronizer(('a',), time_offsets={'z': 0.1})


def test_frame_rate_contradicted_by_stamps_warns_once():
    sync = FrameSetSynchronizer(CAMS, frame_rate=15.0)
    feed(sync, jittered_stream(30))   # 25 frames/s
    assert len(sync.warnings) == 1 and '15' in sync.warnings[0]
    ok = FrameSetSynchronizer(CAMS, frame_rate=25.0)
    feed(ok, jittered_stream(30))
    assert ok.warnings == []


def test_silent_camera_does_not_stall_and_comes_back():
    sync = FrameSetSynchronizer(CAMS, timeout_ns=100 * MS)
    silent = ({'cam2'}, set(range(10, 30)))
    sets, lags = [], []
    for cam, stamp in jittered_stream(40, silent=silent):
        new = sync.add(cam, stamp, (cam, stamp))
        sets += new
        lags += [stamp - min(s.stamps.values()) for s in new]
    sets += sync.flush()
    by_period = {(min(s.stamps.values()) - 1_000 * MS) // PERIOD: s for s in sets}
    assert sorted(by_period) == list(range(40)) and len(sets) == 40
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
    sync = FrameSetSynchronizer(('a', 'b'), timeout_ns=100 * MS, frame_rate=25.0)
    assert feed(sync, [('a', 0), ('a', 40 * MS), ('a', 80 * MS)]) == []  # b may still come
    sets = feed(sync, [('a', 120 * MS)])  # 120 ms > timeout past the set at 0 -> released
    assert [(s.stamp_ns, s.missing) for s in sets] == [(0, ('b',))]
    rest = sync.flush()
    assert [s.stamp_ns for s in rest] == [40 * MS, 80 * MS, 120 * MS]


def test_late_frame_dropped_after_its_set_was_emitted():
    sync = FrameSetSynchronizer(('a', 'b'), timeout_ns=50 * MS, frame_rate=25.0)
    sets = feed(sync, [('a', 0), ('a', 40 * MS), ('a', 80 * MS)])
    assert [s.stamp_ns for s in sets] == [0]
    assert feed(sync, [('b', 2 * MS)]) == []  # belongs to the set already out
    assert sync.counters.dropped_frames == 1
    sets = feed(sync, [('b', 41 * MS)])
    assert [(s.stamp_ns, s.complete) for s in sets] == [(41 * MS, True)]


def test_stamps_backwards_reset():
    sync = FrameSetSynchronizer(('a', 'b'), frame_rate=25.0)
    first = feed(sync, [('a', 5000 * MS), ('b', 5000 * MS), ('a', 5040 * MS)])
    assert len(first) == 1 and not first[0].after_reset
    # the bag restarts: both cameras go back to t = 0
    sets = feed(sync, [('b', 0), ('a', 1 * MS), ('a', 40 * MS), ('b', 40 * MS)])
    assert sync.counters.resets == 1
    assert [(s.stamp_ns, s.complete, s.after_reset) for s in sets] == [
        (1 * MS, True, True), (40 * MS, True, False)]


def test_forward_jump_resets():
    sync = FrameSetSynchronizer(('a',), timeout_ns=10 * MS, jump_ns=1000 * MS,
                                frame_rate=25.0)
    sets = feed(sync, [('a', 0), ('a', 40 * MS), ('a', 5000 * MS), ('a', 5040 * MS)])
    assert [s.after_reset for s in sets] == [False, False, True, False]
    assert sync.counters.resets == 1


def test_bad_configuration_and_unknown_camera():
    with pytest.raises(SyncError, match='unknown camera'):
        FrameSetSynchronizer(('a',)).add('b', 0, None)
    with pytest.raises(SyncError, match='timeout_ns'):
        FrameSetSynchronizer(('a',), 10, 5)
    with pytest.raises(SyncError, match='duplicate'):
        FrameSetSynchronizer(('a', 'a'))
    with pytest.raises(SyncError, match='at least one'):
        FrameSetSynchronizer(())
    with pytest.raises(SyncError, match='frame_rate'):
        FrameSetSynchronizer(('a',), frame_rate=-1.0)


def test_set_stamps_never_go_back():
    """Free-running cameras with drops: the set stamps (latest capture) increase."""
    rng = np.random.default_rng(11)
    cams = ('a', 'b', 'c')
    phases = {'a': 0, 'b': 15 * MS, 'c': 35 * MS}
    events = [e for e in jittered_stream(200, cams, phases=phases, jitter_ms=2)
              if rng.random() > 0.15]
    sync = FrameSetSynchronizer(cams)
    sets = feed(sync, events) + sync.flush()
    stamps = [s.stamp_ns for s in sets]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert all(s.stamp_ns >= max(s.stamps.values()) for s in sets)
