"""Single-person state layout and the per-frame tracker outputs.

A particle (one hypothesis of one person) is a row of a float64 array of width
:data:`STATE_DIM` with columns ``x, y`` (floor position, metres, room frame),
``vx, vy`` (floor velocity, m/s), ``theta`` (body orientation, radians, world frame,
0 = facing +x) and ``sitting`` (0.0 standing, 1.0 sitting).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ['STATE_DIM', 'X', 'Y', 'VX', 'VY', 'THETA', 'SIT', 'WALKING_SPEED', 'FrameResult',
           'TrackEstimate']

X, Y, VX, VY, THETA, SIT = range(6)
STATE_DIM = 6
WALKING_SPEED = 0.2   # m/s: a body this fast faces its motion (reported heading, 000's motion)


@dataclass
class TrackEstimate:
    """What the tracker reports for one person at one frame.

    Attributes:
        track_id: increasing integer, never reused within a run.
        mean: (6,) posterior mean state (``sitting`` is the probability of sitting).
        covariance: (4, 4) posterior covariance of ``x, y, vx, vy``.
        height: body height of the person's model, metres.
        visible_fraction: per camera, the expected visible fraction of the silhouette under
            the prior (from the HJS occlusion maps w*); 0 where the camera does not see it.
        visibility: per camera, posterior probability that the person is seen there.
        existence: posterior probability that the person exists.
        particles: (N, 6) particle states after the update, or None.
        weights: (N,) normalised particle weights, or None.
        width: body width of the person's model, metres.
    """

    track_id: int
    mean: np.ndarray
    covariance: np.ndarray
    height: float
    visible_fraction: dict[str, float] = field(default_factory=dict)
    visibility: dict[str, float] = field(default_factory=dict)
    existence: float = 1.0
    particles: np.ndarray | None = None
    weights: np.ndarray | None = None
    width: float = 0.5

    def heading(self, walking_speed: float = WALKING_SPEED) -> float:
        """Radians: the direction of the mean velocity when the person walks (at least
        ``walking_speed`` m/s), else the body orientation. The orientation is what fits the
        appearance model, which is annotated automatically and often wrongly
        (``MotionConfig.orientation_follows_velocity``); the velocity is the person's."""
        vx, vy = float(self.mean[VX]), float(self.mean[VY])
        if math.hypot(vx, vy) >= walking_speed:
            return math.atan2(vy, vx)
        return float(self.mean[THETA])


@dataclass
class FrameResult:
    """The tracker's output for one synchronised frame set.

    Attributes:
        stamp_ns: the frame set's stamp, integer nanoseconds (image header time).
        tracks: the reported tracks, ordered by id.
        ended: ids that end at this frame: they never come back.
        timings: seconds spent per stage (``predict``, ``update``, ``detect`` ...).
        released: ids of tracks released at this frame (no longer tracked). With
            ``AutoDetectionConfig.reuse_time`` a released track is first lost, its id kept
            for a person re-found nearby, and ends later (or never, when re-found).
    """

    stamp_ns: int
    tracks: list[TrackEstimate] = field(default_factory=list)
    ended: list[int] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    released: list[int] = field(default_factory=list)
