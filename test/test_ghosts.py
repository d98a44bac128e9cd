"""Occupied start: a person who stood in the bootstrap frames is part of the background
model; once he has gone, the place he revealed differs from the model (a ghost). A track
born there (its appearance model is the empty floor) would freeze the model under it and
live on the ghost's foreground for ever; the background's border test
(:func:`mbtrack_ros.core.detection.background.ghost_components`) learns the ghost whatever
the tracks, so the existence process drops the track."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from test_detection import FPS, backgrounds, make_room, paint, person

START = (2.5, 2.5)


def _track_on_a_ghost(ghost_edge_ratio: float, frames: int = 45) -> list[list[int]]:
    """The ids of the reported tracks per frame from its birth: the background learnt with
    a person standing at START, the frames show the empty room, and in the fourth frame a
    track starts at START with the appearance it has there (what a detection of the ghost
    would acquire)."""
    from mbtrack_ros.core.detection.acquisition import acquire
    from mbtrack_ros.core.detection.detector import Detection
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig

    rng = np.random.default_rng(5)
    calib = make_room()
    bgs = backgrounds(calib)
    tracker = Tracker(calib, TrackerConfig(detection=True, particles=50, seed=4),
                      rng=np.random.default_rng(4))
    auto = tracker.detection
    auto.config = replace(auto.config, background=replace(
        auto.config.background, ghost_edge_ratio=ghost_edge_ratio))
    auto.background.config = auto.config.background
    standing = paint(calib, bgs, [person(*START, theta=0.0)], rng)
    auto.bootstrap({n: [standing[n]] for n in calib.cameras})
    empty = paint(calib, bgs, [], rng)
    state = np.array([*START, 0.0, 0.0, 0.0, 0.0])
    model = acquire(Detection(state, 1.8, 0.5, 5.0), empty, calib)
    assert model is not None
    out = []
    for k in range(frames):
        if k == 3:      # born on the ghost after it appeared, like a confirmed detection
            tracker.add_track(model, state, int(round(k * 1e9 / FPS)))
        res = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, [], rng))
        out.append([t.track_id for t in res.tracks])
    return out[3:]


@pytest.mark.parametrize('ratio', [1.5, 0.0])
def test_a_track_on_a_ghost_is_dropped_within_two_seconds(ratio):
    """With the border test the track on the ghost is gone within 2 s; without it (ratio
    0) the ghost keeps it reported to the end, 3 s."""
    reported = _track_on_a_ghost(ratio)
    last = max((k for k, ids in enumerate(reported) if ids), default=-1)
    if ratio > 0:
        assert (last + 1) / FPS <= 2.0, reported
    else:
        assert last == len(reported) - 1, reported
