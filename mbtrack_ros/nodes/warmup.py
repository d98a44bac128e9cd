"""Warm-up of the tracker pipeline at node start (issue 5, the start-up backlog).

The first frames a live node sees would otherwise pay one-off costs inside the step: numba
loads each compiled kernel from its cache (or compiles it, after a code change: tens of
seconds) on its first call, and many kernels are first called only when the first person is
detected, acquired or tracked. :func:`warm_up` runs the whole pipeline once on a few frames
of a small synthetic room with people in it (background bootstrap, detection search,
acquisition, filter with tracks, existence, release checks, the output messages and the
debug images) with a *throwaway* :class:`~mbtrack_ros.core.tracker.Tracker` of the same
configuration, so the node's own tracker keeps its state, random generator and ids.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from mbtrack_ros.core.tracker import Tracker, TrackerConfig

__all__ = ['WarmUpReport', 'warm_up']

WARM_UP_FRAMES = 14     # bootstrap (6 frames) + confirmation + a few tracked frames
WARM_UP_SIZE = (160, 120)  # the kernels are typed by dtype and rank, not by image size


@dataclass(frozen=True)
class WarmUpReport:
    """What the warm-up ran: frames, tracks started, the largest track count, seconds."""

    frames: int
    births: int
    max_tracks: int
    seconds: float


def warm_up(config: TrackerConfig, *, ceiling: bool = False,
            frames: int = WARM_UP_FRAMES) -> WarmUpReport:
    """Run ``frames`` synthetic frame sets through a throwaway tracker built like ``config``.

    Detection is always on in the warm-up (the tracks it starts exercise the filter kernels
    too, whatever the node's track source). ``ceiling``: include a top-down camera (its
    detection path differs). Nothing outside the throwaway tracker is changed.
    """
    from mbtrack_ros.nodes import messages
    from mbtrack_ros.nodes.debug import occlusion_layers
    from mbtrack_ros.synth.generator import Synthesizer

    t0 = time.perf_counter()
    synth = Synthesizer('clear-room', seed=0, frames=frames, width=WARM_UP_SIZE[0],
                        height=WARM_UP_SIZE[1], ceiling=ceiling)
    tracker = Tracker(synth.calibration, replace(config, detection=True, seed=0),
                      rng=np.random.default_rng(0))
    tracker.detection.prepare()
    cameras = list(synth.calibration.names)
    births = max_tracks = 0
    result = None
    for frame in synth:
        result = tracker.step(frame.stamp_ns, frame.images, search=False)
        messages.people_message(result)
        messages.tracks_cloud(result, cameras)
        messages.markers_message(result)
        births += len(tracker.search())
        max_tracks = max(max_tracks, len(result.tracks))
    if result is not None and result.tracks:
        # the debug overlay; its occlusion maps need two tracks: add a twin of the first
        track = result.tracks[0]
        twin = replace(track, track_id=-1)
        models = {track.track_id: tracker.models[track.track_id],
                  -1: tracker.models[track.track_id]}
        both = replace(result, tracks=[track, twin])
        camera = tracker.calibration.cameras[cameras[0]]  # at the tracker's image size
        occ, sil = occlusion_layers(tracker.measurement, camera, both, models)
        messages.debug_overlay(frame.images[camera.name], occlusion=occ, silhouettes=sil)
    return WarmUpReport(frames=frames, births=births, max_tracks=max_tracks,
                        seconds=time.perf_counter() - t0)
