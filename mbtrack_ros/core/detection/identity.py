"""Appearance arbitration of identity swaps between two close tracks.

When two people walk close to each other, the HJS filter keeps their tracks apart (MRF,
000 §IV) but nothing in its likelihood stops the two tracks from exchanging people: each
track's particles only need *a* person that its model explains reasonably. After such a
swap each track sits on the other person and, with fixed appearance models, stays there.

The arbitration compares, for a pair of reported tracks A and B that came within
``close_radius`` of each other recently, the two assignments

* straight: A's model at A's state and B's model at B's state,
* crossed:  A's model at B's state and B's model at A's state,

with each track's own appearance model (003 Eq. 3, the tracker's likelihood) in the side
cameras where both silhouettes are in the image and neither is hidden (the filter's
expected visible fraction w*). When the crossed assignment explains the frame better by
more than ``margin`` nats per camera on ``frames`` consecutive frames, the pair is
swapped back (each track restarted at the other's state, ids kept).

:func:`arbitrate` is a pure function of the frame's estimates, models, colour bins and the
pairs' memory of the previous frame; :class:`~mbtrack_ros.core.detection.manager.AutoDetection`
calls it once per frame in ``search`` and hands the swaps to the tracker as relocations.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from mbtrack_ros.core.appearance import (
    PersonModel, key_view_loglik, key_view_stack, relative_angle, single_target_loglik,
    view_weights)
from mbtrack_ros.core.camera import Camera
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.shape import rasterize
from mbtrack_ros.core.state import THETA, X, Y

__all__ = ['PairMemory', 'Swap', 'SwapConfig', 'appearance_loglik', 'arbitrate', 'pair_gains']


@dataclass(frozen=True)
class SwapConfig:
    """Parameters of the swap arbitration.

    Attributes:
        enabled: arbitrate close pairs of reported tracks.
        close_radius: metres; a pair closer than this becomes a candidate.
        window: seconds after the pair was last that close during which it is arbitrated.
        margin: mean log-likelihood gain per camera (003 Eq. 3) of the crossed over the
            straight assignment above which a frame votes for a swap.
        frames: consecutive voting frames needed to swap (frames with fewer than
            ``min_cameras`` usable cameras neither vote nor break the run).
        min_visible: smallest expected visible fraction (w*) of both tracks in a camera
            for that camera to be used (an occluded silhouette measures its occluder).
        min_cameras: fewest usable cameras for a vote.
    """

    enabled: bool = True
    close_radius: float = 0.7
    window: float = 2.0
    margin: float = 1.0
    frames: int = 2
    min_visible: float = 0.7
    min_cameras: int = 2

    def __post_init__(self) -> None:
        if not (self.close_radius >= 0 and self.window >= 0 and np.isfinite(self.margin)
                and 0 <= self.min_visible <= 1):
            raise DetectionError('swap: close_radius and window must be >= 0, margin finite, '
                                 'min_visible in [0, 1]')
        if self.frames < 1 or self.min_cameras < 1:
            raise DetectionError('swap: frames and min_cameras must be >= 1')


@dataclass(frozen=True)
class PairMemory:
    """What the arbitration remembers of a pair: when it was last close (ns), the number
    of consecutive frames the crossed assignment won and this frame's gain (NaN: not
    compared this frame; for diagnostics, docs/detection_eval.py)."""

    last_close_ns: int
    votes: int = 0
    gain: float = float('nan')


@dataclass(frozen=True)
class Swap:
    """Tracks ``a`` and ``b`` exchange their states; ``gain``: the last frame's mean gain of
    the crossed assignment per camera."""

    a: int
    b: int
    gain: float


def appearance_loglik(model: PersonModel, states: np.ndarray, camera: Camera,
                      bins: np.ndarray, sigma: float) -> np.ndarray | None:
    """003 Eq. 3 of ``model`` at each of ``states`` (N, 6) in one camera -> (N,), or None
    when a silhouette is less than half in the image."""
    sil = rasterize(camera, states, model.shape)
    if np.any(sil.area <= 0) or np.any(sil.area < 0.5 * np.maximum(sil.full_area, 1)):
        return None
    rel = relative_angle(states[:, THETA], camera.viewing_angle(states[:, [X, Y]]))
    return single_target_loglik(bins, sil, model.interpolate(rel), sigma=sigma)


def pair_gains(pairs: Sequence[tuple[PersonModel, PersonModel]], states: np.ndarray,
               cameras: Mapping[str, Camera], bins: Mapping[str, np.ndarray],
               sigma: float) -> np.ndarray:
    """Per pair and camera, log p(crossed) - log p(straight) (003 Eq. 3 with each track's
    own model): ``states`` (N, 2, 6) are the pairs' two states; (N, C) gains, NaN where a
    silhouette is less than half in the image. One rasterisation and one likelihood call
    per camera for all pairs (the key views interpolated lazily, as in the filter)."""
    n = len(pairs)
    out = np.full((n, len(cameras)), np.nan)
    if not n:
        return out
    unique = {id(m): m for pair in pairs for m in pair}               # models, once each
    refs = list(unique.values())
    index = {key: k for k, key in enumerate(unique)}
    states = np.asarray(states, np.float64).reshape(n, 2, 6)
    # four rows per pair: A at a, A at b, B at a, B at b
    rows = states[:, [0, 1, 0, 1]].reshape(4 * n, 6)
    target = np.array([index[id(pair[w])] for pair in pairs for w in (0, 0, 1, 1)])
    shapes = [refs[t].shape for t in target]
    key = key_view_stack(refs)
    cams = list(cameras.values())
    va, vb, wa = view_weights(cams, rows, target, refs)
    for c, (name, cam) in enumerate(cameras.items()):
        if name not in bins:
            continue
        sil = rasterize(cam, rows, shapes)
        ll = key_view_loglik(bins[name], sil, key, target, va[c], vb[c], wa[c], sigma=sigma)
        ok = (sil.area > 0) & (sil.area >= 0.5 * np.maximum(sil.full_area, 1))
        ll = np.where(ok, ll, np.nan).reshape(n, 4)
        out[:, c] = (ll[:, 1] + ll[:, 2]) - (ll[:, 0] + ll[:, 3])
    return out


def arbitrate(stamp_ns: int, ids: Sequence[int], states: np.ndarray,
              visible: Sequence[Mapping[str, float]], models: Mapping[int, PersonModel],
              cameras: Mapping[str, Camera], bins: Mapping[str, np.ndarray],
              memory: Mapping[tuple[int, int], PairMemory], config: SwapConfig,
              sigma: float) -> tuple[list[Swap], dict[tuple[int, int], PairMemory]]:
    """One frame of swap arbitration.

    Args:
        stamp_ns: the frame stamp.
        ids, states, visible: the tracks to arbitrate (reported ones), their (K, 6) states
            and per-camera expected visible fractions (w*).
        models: track id -> appearance model.
        cameras, bins: side cameras by name and their colour bins of this frame.
        memory: the pairs' memory after the previous frame (not modified).
        config, sigma: parameters; ``sigma`` as the tracker's likelihood.

    Returns:
        (swaps to apply, ordered by pair; the pairs' memory after this frame). A track is in
        at most one swap.
    """
    states = np.asarray(states, dtype=np.float64).reshape(-1, 6)
    new: dict[tuple[int, int], PairMemory] = {}
    swaps: list[Swap] = []
    if not config.enabled or len(ids) < 2:
        return swaps, new
    horizon = int(config.window * 1e9)
    order = np.argsort(np.asarray(ids))
    names = list(cameras)
    candidates = []            # (a, b, i, j, last close stamp, usable cameras (C,) bool)
    for i_pos, i in enumerate(order):
        for j in order[i_pos + 1:]:
            a, b = int(ids[i]), int(ids[j])
            d = float(np.hypot(*(states[i, [X, Y]] - states[j, [X, Y]])))
            old = memory.get((a, b))
            last = int(stamp_ns) if d < config.close_radius else \
                (old.last_close_ns if old is not None else None)
            if last is None or int(stamp_ns) - last > horizon \
                    or a not in models or b not in models:
                continue
            usable = np.array([min(visible[i].get(n, 0.0), visible[j].get(n, 0.0))
                               >= config.min_visible for n in names], bool)
            candidates.append((a, b, i, j, last, usable))
    asked = [c for c in candidates if c[5].sum() >= config.min_cameras]
    used = np.any([c[5] for c in asked], axis=0) if asked else np.zeros(len(names), bool)
    gains = pair_gains([(models[c[0]], models[c[1]]) for c in asked],
                       np.array([[states[c[2]], states[c[3]]] for c in asked]).reshape(-1, 2, 6),
                       {n: cameras[n] for n, u in zip(names, used) if u}, bins, sigma)
    gain_of = {(c[0], c[1]): np.where(c[5][used], g, np.nan) for c, g in zip(asked, gains)}
    taken: set[int] = set()
    for a, b, _, _, last, _ in candidates:
        old = memory.get((a, b))
        votes = old.votes if old is not None else 0   # held over frames without a say
        gain = float('nan')
        g = gain_of.get((a, b))
        if g is not None and np.isfinite(g).sum() >= config.min_cameras:
            gain = float(np.nanmean(g))
            votes = votes + 1 if gain > config.margin else 0
        if votes >= config.frames and a not in taken and b not in taken:
            swaps.append(Swap(a, b, gain))
            taken.update((a, b))
            votes = 0
        new[(a, b)] = PairMemory(last, votes, gain)
    return swaps, new
