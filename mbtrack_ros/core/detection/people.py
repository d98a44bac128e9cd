"""Background-independent multi-view person cue for bootstrapping a never-empty room.

A background model learnt from the first frames of a recording contains whoever stands in
the room then; the detector (003 §4.1) needs foreground, so a person who is there from the
first frame and barely moves is never found, and a ghost appears where he stood once he
leaves. The cure is to *not learn* the pixels that likely hold a person: this module finds
them without a background, and :class:`~.background.BackgroundModel` treats them as "not
yet known" (possible foreground) until they are seen empty.

The cue scores a floor grid of standing-person hypotheses (one size, a few orientations)
over the bootstrap frames, in every side camera, with evidence that does not depend on a
background:

* **motion**: the fraction of the silhouette covered by pixels that changed between
  consecutive bootstrap frames (a person present from the start moves limbs, head or
  balance even on the spot; furniture does not);
* the detector's **contour likelihood** (003 Eq. 5) against the Canny edges of the *whole*
  last frame, plus its upper-body **colour symmetry** (003 §4.2, third feature). A
  cluttered room (furniture, a treadmill, posters) has person-like edges everywhere, so a
  camera's response is taken relative to that camera's clutter: the robust z-score
  ``(r - median) / (1.4826 MAD)`` over all hypotheses it sees (most floor points hold
  nobody).

A place is person-like if ``min_views`` cameras see it, the motion fraction reaches
``min_motion`` in *every* camera that sees it and the mean contour/symmetry z-score reaches
``min_score`` (multi-view consistency: motion or clutter edges in one view do not line up
with evidence in the others). Places are taken greedily, most moving first, and the motion
inside a taken place's region is explained away (it no longer counts for the others), so
the places on a person's lines of sight are not taken too. Each place is then refined
near where it was taken, with only the other places' bodies explained away: among the
places that move nearly as much, the one whose outline in the last frame is most
person-like (:meth:`PeopleCue._refine`).

Per place and camera three nested masks are returned (:meth:`PeopleCue.regions`): a larger
body (not to be learnt: arms, a lean, the grid's position error), the tested body (possible
foreground: a person-sized blob the detector can localise) and its core (a narrow strip: a
hypothesis that covers the core in every view stands where the cue's person stands; one
that combines the blobs of two people from different views does not).

On real footage the contour/symmetry z-score alone ranks a person anywhere among the
first few dozen floor places of a frame (furniture and posters are person-like too);
motion over the first frames (0.1 s) singles him out, and a person who barely moves still
passes at ``min_motion = 0.03``. A person who stands perfectly still during the bootstrap is
found by the **floor parallax** of the last frame set instead (:meth:`PeopleCue._still`,
:class:`~.parallax.FloorParallax`): the core of his silhouettes (the body's axis strip,
which he fills in every view whatever his build) shows something other than the floor
the other cameras see behind him (an object stands there), and his outline is a
person's (a contour/symmetry z-score about ``min_still_score``, well above the
``min_score`` that motion needs: furniture stands on the floor too); the two are weighed
together (:func:`still_evidence`), so that either, well above its threshold, makes up
for the other falling short by up to half (the floor a neighbour hides behind him, an
outline against a busy background). An object stands where it stands in *every* view:
a camera that sees the floor behind the place and shows it as the floor refutes it
(:meth:`PeopleCue._parallax_cover`), however much the other views disagree there (their
lines of sight meet other objects). The test asks as many views as see the place, up to
three: in a room (or a corner of it) that only two cameras see, the two views' agreement
is all there is, and the weaker of the two decides (no third view can refute a phantom of
the two-view hull). Where fewer than two cameras see the floor behind him he is learnt
into the background, found when he moves, and the place he reveals is recognised as a
ghost by the background's border test (:func:`~.background.ghost_components`).

OpenCV's HOG people detector (``cv2.HOGDescriptor``) would be the obvious single-view cue,
but OpenCV 5 moved it out of the main package (``opencv-python-headless`` 5.0 has no
``HOGDescriptor``), hence the detector's own features here.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from mbtrack_ros.core.camera import Camera, RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.shadow import shadow_change
from mbtrack_ros.core.detection.detector import (
    _grid, _max_span_width, _nms, _states, is_ceiling)
from mbtrack_ros.core.detection.features import (
    EdgeMap, ForegroundIntegral, Spans, colour_symmetry, contour_loglik_spans)
from mbtrack_ros.core.detection.parallax import FloorParallax
from mbtrack_ros.core.shape import BodyShape, Silhouettes, rasterize

__all__ = ['PeopleCue', 'PeopleCueConfig', 'REFUTE_SHARE', 'STILL_ACCEPT', 'STILL_MAKE_UP',
           'still_evidence']

#: still_evidence (in units of the thresholds) at which a place is a person
STILL_ACCEPT = 2.0
#: each evidence counts up to this: neither makes up for more than half of the other's
#: threshold (still_evidence)
STILL_MAKE_UP = STILL_ACCEPT - 0.5
#: a view that tests a place's floor and disagrees on less of it than this share refutes it
REFUTE_SHARE = 0.1


@dataclass(frozen=True)
class PeopleCueConfig:
    """Parameters of the person cue (metres, radians, pixels at 320x240).

    Attributes:
        spacing: floor grid spacing of the hypotheses.
        height, width: the single body size tested.
        orientations: body orientations tested (the best one counts per camera).
        min_views: cameras that must see a hypothesis (silhouette mostly inside the image);
            all side cameras when the room has fewer.
        min_visible: fraction of a silhouette inside the image for a camera to see it.
        min_area: smallest silhouette area seen, pixels at 320x240 (scaled).
        motion_threshold: frame-difference luminance above which a pixel moved.
        motion_dilation: pixels by which the moving pixels grow (limbs that moved by a few
            pixels fill the body between them).
        min_motion: smallest moving fraction of the silhouette in every seeing camera
            (ignored with a single bootstrap frame).
        w_symmetry: weight of the colour-symmetry term against the contour term.
        min_score: smallest mean contour/symmetry robust z-score over the seeing cameras.
        min_parallax: the share of a place's floor-backed core pixels (``core_width``;
            pooled over the side cameras) that shows something other than the floor the
            other cameras see there (:class:`~.parallax.FloorParallax`: an object stands
            there) at which a place that does not move is a person on that evidence alone
            (fraction in (0, 1]; see :func:`still_evidence`).
        min_still_score: the mean contour/symmetry robust z-score of such a place at which
            its outline alone makes it a person's (not a table's or a chair's), robust
            standard deviations (> 0); ``inf`` disables the still-person stage. A still
            place no view refutes is a person when the two evidences, each in units of
            its threshold, sum to at least :data:`STILL_ACCEPT`, neither making up for
            more than half of the other (:func:`still_evidence`).
        max_people: largest number of person-like places marked; ``None`` (default):
            as many as the evidence shows, which places ``nms_radius`` apart bound.
        nms_radius: smallest distance between two marked places.
        refine_radius: how far a chosen place may move when it is refined with only the
            other places' bodies explained away (0 disables; see ``PeopleCue._refine``).
        refine_share: places within this share of the best moving fraction there compete
            on the contour/symmetry score in that refinement.
        region_height, region_width: size of the body whose silhouette is marked as not
            yet known (larger than a person: arms, a lean, the grid's position error), so
            that no part of the person is learnt into the background.
        dilation: pixels by which those silhouettes grow.
        core_width: width of the body's core, metres: the strip the floor-parallax test
            measures and a hypothesis must cover (see :meth:`PeopleCue.regions`).
        edge_min_pixels: smallest edge component of the contour feature, pixels.
        The possible foreground inside the region is the silhouette of the tested body
        (``height`` x ``width``): a person-sized blob the detector can localise.
    """

    spacing: float = 0.1
    height: float = 1.75
    width: float = 0.5
    orientations: tuple[float, ...] = (0.0, np.pi / 4, np.pi / 2, 3 * np.pi / 4)
    min_views: int = 3
    min_visible: float = 0.7
    min_area: int = 60
    motion_threshold: float = 20.0
    motion_dilation: int = 2
    min_motion: float = 0.03
    w_symmetry: float = 0.3
    min_score: float = 0.0
    min_parallax: float = 0.5
    min_still_score: float = 1.0
    max_people: int | None = None
    nms_radius: float = 0.7
    refine_radius: float = 0.5
    refine_share: float = 0.9
    region_height: float = 2.1
    region_width: float = 1.0
    core_width: float = 0.15
    dilation: int = 3
    edge_min_pixels: int = 12

    def __post_init__(self) -> None:
        if not (self.spacing > 0 and self.height > 0 and self.width > 0
                and self.region_height > 0 and self.region_width > 0
                and self.core_width > 0):
            raise DetectionError('people cue spacing and sizes must be > 0')
        if not self.orientations:
            raise DetectionError('people cue needs at least one orientation')
        capped_below_zero = self.max_people is not None and self.max_people < 0
        if self.min_views < 1 or capped_below_zero or self.dilation < 0:
            raise DetectionError('people cue min_views >= 1, max_people >= 0 or None, '
                                 'dilation >= 0')
        if not 0.0 < self.min_parallax <= 1.0:
            raise DetectionError(f'people cue min_parallax must be in (0, 1], got '
                                 f'{self.min_parallax}')
        if not self.min_still_score > 0.0:
            raise DetectionError(f'people cue min_still_score must be > 0, got '
                                 f'{self.min_still_score}')
        if not 0.0 < self.min_visible <= 1.0:
            raise DetectionError(f'people cue min_visible must be in (0, 1], got '
                                 f'{self.min_visible}')


def still_evidence(cover: np.ndarray, score: np.ndarray, min_parallax: float,
                   min_still_score: float) -> np.ndarray:
    """The evidence (P,) that a place which does not move holds a person: the sum of the
    floor-parallax share ``cover`` (P,) (an object stands there) and the outline's
    contour/symmetry robust z-score ``score`` (P,) (it is a person's), each in units of
    its threshold (``min_parallax``, ``min_still_score``) and at most
    :data:`STILL_MAKE_UP` of it. A place is a person at :data:`STILL_ACCEPT` or more
    (both near their thresholds, the parallax share of a place that no view refutes:
    :meth:`PeopleCue._parallax_cover`), or one short of its threshold by at most half and
    made up by the other
    (a neighbour who hides part of the floor behind him lowers his parallax share; his
    outline against a busy background lowers his z-score). Neither makes up for more
    than half of the other: a cabinet fills its silhouette with parallax whatever its
    outline, a poster has a person's outline and no parallax. ``-inf`` where ``cover`` is
    0 (the parallax test does not apply: too few cameras see the floor behind the place,
    :meth:`PeopleCue._parallax_cover`) or ``score`` is not finite."""
    cover = np.asarray(cover, np.float64)
    score = np.asarray(score, np.float64)
    out = np.minimum(cover / float(min_parallax), STILL_MAKE_UP) \
        + np.minimum(score / float(min_still_score), STILL_MAKE_UP)
    return np.where((cover > 0.0) & np.isfinite(score), out, -np.inf)


class PeopleCue:
    """Where people likely stand in one multi-view frame set, without a background.

    Args:
        calibration: the room (its floor is searched; top-down cameras are skipped: a
            person's contour seen from above is not an upright silhouette).
        config: cue parameters.
    """

    def __init__(self, calibration: RoomCalibration, config: PeopleCueConfig | None = None
                 ) -> None:
        self.calibration = calibration
        self.config = cfg = config or PeopleCueConfig()
        self.cameras = [n for n, c in calibration.cameras.items() if not is_ceiling(c)]
        xy = _grid([calibration.floor], cfg.spacing)
        self.xy = np.concatenate([xy] * len(cfg.orientations))
        self.states = np.concatenate([_states(xy, th, 0.0) for th in cfg.orientations])
        self.n_places = len(xy)
        self.shape = BodyShape(height=cfg.height, width=cfg.width)
        self._sils = {n: rasterize(calibration.cameras[n], self.states, self.shape)
                      for n in self.cameras}
        self._seen = {n: _SeenHypotheses.of(self._sils[n], cfg, calibration.cameras[n])
                      for n in self.cameras}
        # the body's core (``core_width`` wide) of the hypotheses each camera sees: what
        # the floor-parallax test measures (:meth:`_parallax_cover`)
        core = BodyShape(height=cfg.height, width=cfg.core_width)
        self._core = {n: rasterize(calibration.cameras[n], self.states[self._seen[n].index],
                                   core) for n in self.cameras}
        self._parallax: FloorParallax | None = None    # built on first use

    @property
    def max_places(self) -> int:
        """The most places :meth:`places` marks: ``max_people``, or without it the floor
        grid's places (``nms_radius`` apart, far fewer are ever chosen)."""
        cap = self.config.max_people
        return self.n_places if cap is None else int(cap)

    @staticmethod
    def _kernel(radius: int) -> np.ndarray:
        return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))

    def score(self, frames: Sequence[Mapping[str, np.ndarray]]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Evidence per floor place over consecutive frame sets (camera -> (H, W, 3) uint8).

        Returns:
            (P, 2) place positions (metres); (P,) mean contour/symmetry robust z-score of
            the last frame set over the seeing cameras; (P,) smallest moving fraction over
            the seeing cameras (``nan`` with one frame set). Places seen by fewer than
            ``min_views`` cameras score ``-inf``.
        """
        xy, mean, moved = self._evidence(frames)
        motion = self._motion(moved) if moved else np.full(len(xy), np.nan)
        return xy, mean, motion

    def _evidence(self, frames: Sequence[Mapping[str, np.ndarray]]
                  ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Places, mean z-score, and per camera the moving pixels (H, W) bool when there
        are several frame sets."""
        cfg = self.config
        frames = list(frames)
        if not frames:
            raise DetectionError('the people cue needs at least one frame set')
        images = frames[-1]
        m = self.n_places
        n_or = len(cfg.orientations)
        total = np.zeros(m)
        views = np.zeros(m, np.int64)
        moved_by_cam: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for name in self.cameras:
            if name not in images or any(name not in f for f in frames):
                continue
            image = images[name]
            cam = self.calibration.cameras[name]
            for f in frames:
                if f[name].shape[:2] != (cam.height, cam.width):
                    raise DetectionError(
                        f'camera {name!r}: image {f[name].shape[1]}x{f[name].shape[0]} '
                        f'differs from the calibration {cam.width}x{cam.height}')
            seen_hyp = self._seen[name]     # unseen hypotheses score -inf: not computed
            # whole image: no background needed
            edges = EdgeMap.from_image(image, min_edge_pixels=cfg.edge_min_pixels)
            con, _ = contour_loglik_spans(edges, seen_hyp.spans, seen_hyp.width)  # 003 Eq. 5
            sym = colour_symmetry(image, seen_hyp.spans)
            resp = np.full(n_or * m, -np.inf)
            resp[seen_hyp.index] = con + cfg.w_symmetry * np.where(np.isfinite(sym),
                                                                   1.0 - sym, 0.0)
            resp = resp.reshape(n_or, m).max(axis=0)
            seen = np.isfinite(resp)
            if seen.sum() < 8:
                continue
            med = float(np.median(resp[seen]))
            mad = 1.4826 * float(np.median(np.abs(resp[seen] - med)))
            z = (resp - med) / max(mad, 1e-6)
            total += np.where(seen, z, 0.0)
            views += seen
            if len(frames) > 1:
                moved = self._moved(name, frames)
                if cfg.motion_dilation > 0:      # limbs move, the body between them not
                    moved = cv2.dilate(moved, self._kernel(cfg.motion_dilation))
                moved_by_cam[name] = moved.astype(bool)
        need = min(cfg.min_views, max(len(self.cameras), 1))
        mean = np.where(views >= need, total / np.maximum(views, 1), -np.inf)
        return self.xy[:m], mean, moved_by_cam

    def _moved(self, name: str, frames: Sequence[Mapping[str, np.ndarray]]) -> np.ndarray:
        """(H, W) uint8, 1 where camera ``name``'s luminance changed by more than
        ``motion_threshold`` over the bootstrap frames, before the dilation: between
        consecutive frames (fast motion, a limb that swings back) or between a frame and
        the first one (the displacement accumulated since: a slow motion whose step per
        frame moves an edge by less than a pixel, which changes a pixel of an
        area-sampled image by only that fraction of the edge's contrast). A pixel whose
        change is a moving shadow's (:func:`~.shadow.shadow_change`) is not motion."""
        cfg = self.config
        cam = self.calibration.cameras[name]
        moved = np.zeros((cam.height, cam.width), np.uint8)
        grey = [cv2.cvtColor(f[name], cv2.COLOR_RGB2GRAY) for f in frames]
        for k in range(1, len(frames)):
            for j in {k - 1, 0}:        # the previous frame, the first frame
                change = cv2.absdiff(grey[k], grey[j]) > cfg.motion_threshold
                if change.any():
                    change &= ~shadow_change(frames[j][name], frames[k][name])
                moved |= change.view(np.uint8)
        return moved

    def _coverage(self, name: str, moved: np.ndarray) -> np.ndarray:
        """(n_or * P,) moving fraction of every hypothesis in a camera, ``-inf`` where the
        camera does not see it."""
        seen_hyp = self._seen[name]
        cov = np.full(len(self.states), -np.inf)
        cov[seen_hyp.index] = ForegroundIntegral(moved).coverage(seen_hyp.spans)[0]
        return cov

    def _min_over_cameras(self, cov_by_cam: Mapping[str, np.ndarray]) -> np.ndarray:
        """(P,) smallest moving fraction of each place (best orientation per camera) over
        the cameras that see it; 0 where none does."""
        m = self.n_places
        n_or = len(self.config.orientations)
        motion = np.full(m, np.inf)
        for cov in cov_by_cam.values():
            cov = cov.reshape(n_or, m).max(axis=0)
            motion = np.where(np.isfinite(cov), np.minimum(motion, cov), motion)
        return np.where(np.isfinite(motion), motion, 0.0)

    def _motion(self, moved_by_cam: Mapping[str, np.ndarray]) -> np.ndarray:
        """(P,) smallest moving fraction of each place over the cameras that see it."""
        return self._min_over_cameras({n: self._coverage(n, mv)
                                       for n, mv in moved_by_cam.items()})

    def places(self, frames: Sequence[Mapping[str, np.ndarray]]) -> np.ndarray:
        """(K, 2) floor positions of person-like places, most moving first (at most
        ``max_people``, at least ``nms_radius`` apart).

        With several frame sets the places are chosen greedily with explaining-away: the
        moving pixels inside a chosen place's region no longer count for the others, so
        that a person's motion does not also make the places on his lines of sight (which
        see him in one camera and something else in another) person-like. After each
        choice only the hypotheses whose box meets the pixels just explained are counted
        again (the others' coverage cannot change).
        """
        cfg = self.config
        frames = list(frames)
        xy, score, moved = self._evidence(frames)
        ok = np.isfinite(score) & (score >= cfg.min_score)
        cap = self.max_places
        if cap == 0 or not ok.any():
            return np.zeros((0, 2))
        if not moved:
            good = np.flatnonzero(ok)
            keep = _nms(xy[good], score[good], cfg.nms_radius, cap)
            return xy[good[keep]]
        original = moved
        moved = {n: mv.copy() for n, mv in moved.items()}
        cov = {n: self._coverage(n, mv) for n, mv in moved.items()}
        chosen: list[int] = []
        while len(chosen) < cap:
            motion = self._min_over_cameras(cov)
            cand = ok & (motion >= cfg.min_motion)
            if chosen:
                d = np.linalg.norm(xy[:, None] - xy[chosen][None], axis=2).min(axis=1)
                cand &= d >= cfg.nms_radius
            if not cand.any():
                break
            best = int(np.flatnonzero(cand)[np.argmax(motion[cand])])
            chosen.append(best)
            if len(chosen) == cap:
                break
            for name, mv in moved.items():     # explained: not evidence for others
                explained = mv & self._region(name, xy[best:best + 1], cfg.region_height,
                                              cfg.region_width)
                if not explained.any():
                    continue
                mv &= ~explained
                seen_hyp = self._seen[name]
                rows = np.flatnonzero(explained.any(axis=1))
                cols = np.flatnonzero(explained.any(axis=0))
                bx = seen_hyp.bbox
                hit = (bx[:, 0] <= cols[-1]) & (bx[:, 2] > cols[0]) \
                    & (bx[:, 1] <= rows[-1]) & (bx[:, 3] > rows[0])
                if hit.any():
                    sub = _take(seen_hyp.spans, np.flatnonzero(hit))
                    cov[name][seen_hyp.index[hit]] = ForegroundIntegral(mv).coverage(sub)[0]
        moving = self._refine(xy, score, ok, chosen, original) if chosen \
            else np.zeros((0, 2))
        return self._still(frames[-1], xy, score, moving)

    def _still(self, images: Mapping[str, np.ndarray], xy: np.ndarray, score: np.ndarray,
               taken: np.ndarray) -> np.ndarray:
        """(K + J, 2) the places ``taken`` (K, 2) followed by those of people who stand
        still: an object on the floor (floor parallax, :class:`~.parallax.FloorParallax`:
        the share of the silhouette's floor-backed pixels that disagree) whose outline is a
        person's (mean contour/symmetry z-score ``score`` (P,)), the two evidences combined
        by :func:`still_evidence` (at least :data:`STILL_ACCEPT`), the largest parallax
        first (it places the object; the outline varies little over a body's width),
        ``nms_radius`` apart,
        at most ``max_people`` in all. What a chosen person explains (his body, the floor
        he hides from the other cameras, :meth:`~.parallax.FloorParallax.decide`) is no
        evidence for the next, nor is what the places ``taken`` explain."""
        cfg = self.config
        cap = self.max_places
        if len(taken) >= cap or not np.isfinite(cfg.min_still_score):
            return taken
        if self._parallax is None:
            self._parallax = FloorParallax(self.calibration,
                                           threshold=cfg.motion_threshold)
        evidence = {n: ev for n, ev in self._parallax.differences(images).items()
                    if n in self.cameras}
        out = [p for p in np.asarray(taken, np.float64).reshape(-1, 2)]
        while evidence and len(out) < cap:
            bodies = {n: self._region(n, np.array(out).reshape(-1, 2), cfg.height,
                                      cfg.width, 0) for n in self.calibration.cameras}
            shown = {}
            for name, ev in evidence.items():
                disagree, known = self._parallax.decide(ev, hidden=bodies)
                shown[name] = (disagree & ~bodies[name], known & ~bodies[name])
            cover = self._parallax_cover(shown)
            cand = still_evidence(cover, score, cfg.min_parallax,
                                  cfg.min_still_score) >= STILL_ACCEPT
            if out:
                cand &= np.linalg.norm(xy[:, None] - np.array(out)[None], axis=2
                                       ).min(axis=1) >= cfg.nms_radius
            if not cand.any():
                break
            out.append(xy[int(np.flatnonzero(cand)[np.argmax(cover[cand])])])
        return np.array(out).reshape(-1, 2)

    def _parallax_cover(self, shown: Mapping[str, tuple[np.ndarray, np.ndarray]]
                        ) -> np.ndarray:
        """(P,) share of each place's floor-backed core pixels that disagree with the
        other cameras' floor, pooled over the cameras ``shown`` (name -> (disagree,
        known) (H, W) bool), best orientation. The core is the body's ``core_width`` axis
        strip: a person standing at the place fills it in every view whatever his build,
        whereas his share of the whole ``width`` silhouette depends on how wide he is
        against the model (arms, legs apart, a slim person). 0 where fewer than two
        cameras see floor behind a quarter of the core (one view cannot place an object
        in depth) or fewer than three behind a tenth of it, of the cameras that see the place
        (silhouette mostly in the image; all of them when fewer than three do): two views'
        disagreements meet also where nothing stands (a phantom of the two-view visual
        hull: one view's line of sight meets one object, the other's another, as between
        two chairs in a row, or a person in front of the place in one view and the floor
        his body hides from it in the other), and a third view that sees the floor there
        refutes it. Where only two views test the place (no third sees it), the share is
        the smaller of the two views' own shares, not the pooled one (which the view
        closer to the place, with the larger silhouette, would dominate): each of them
        must show the object. Likewise 0 where any camera that
        sees the floor behind a tenth of the core disagrees on less than
        :data:`REFUTE_SHARE` of it: an object on the floor stands in every view's line of
        sight (the visual hull is the intersection of the views' silhouette cones), so a
        view that shows the floor there refutes it, however much the others' disagreements
        (other objects on their lines of sight) weigh in the pooled share."""
        n = len(self.states)
        hits, known = np.zeros(n), np.zeros(n)
        views, third = np.zeros(n, np.int64), np.zeros(n, np.int64)
        seeing = np.zeros(n, np.int64)
        weakest = np.full(n, np.inf)
        refuted = np.zeros(n, bool)
        for name, (disagree, kn) in shown.items():
            seen_hyp = self._seen[name]
            h, k, area = ForegroundIntegral(disagree, ~kn).counts(self._core[name])
            hits[seen_hyp.index] += h
            known[seen_hyp.index] += k
            seeing[seen_hyp.index] += 1
            views[seen_hyp.index] += k >= 0.25 * np.maximum(area, 1)
            tests = k >= 0.1 * np.maximum(area, 1)
            third[seen_hyp.index] += tests
            refuted[seen_hyp.index] |= tests & (h < REFUTE_SHARE * k)
            weakest[seen_hyp.index] = np.where(
                tests, np.minimum(weakest[seen_hyp.index], h / np.maximum(k, 1.0)),
                weakest[seen_hyp.index])
        pooled = hits / np.maximum(known, 1.0)
        # no third view to refute a phantom of the two-view hull: the weaker view decides
        cover = np.where(third >= 3, pooled, np.minimum(pooled, weakest))
        cover = np.where((views >= 2) & (third >= np.minimum(3, seeing)) & ~refuted,
                         cover, 0.0)
        return cover.reshape(len(self.config.orientations), self.n_places).max(axis=0)

    def _refine(self, xy: np.ndarray, score: np.ndarray, ok: np.ndarray,
                chosen: list[int], moved: Mapping[str, np.ndarray]) -> np.ndarray:
        """(K, 2) the chosen places, each refined within ``refine_radius`` of it with only
        the *bodies* (``height`` x ``width``) of the other chosen places explained away: of
        the places whose smallest moving fraction is within ``refine_share`` of the best
        there, the one with the highest contour/symmetry z-score (the person's outline in
        the last frame, where he is now; motion spans all the bootstrap frames).

        The greedy choice explains away a chosen place's whole region (a 1 m wide body, to
        keep the places on its lines of sight out); in a camera where two people stand side
        by side in the image, that region also takes the second person's near half, whose
        smallest moving fraction over the cameras then peaks off him (by up to about
        0.4 m; the refinement brings it back to the grid's spacing)."""
        cfg = self.config
        if cfg.refine_radius <= 0:
            return xy[chosen]
        out = []
        for k, best in enumerate(chosen):
            near = ok & (np.linalg.norm(xy - xy[best], axis=1) <= cfg.refine_radius)
            others = xy[[c for j, c in enumerate(chosen) if j != k]]
            cov = {name: self._coverage(name, mv & ~self._region(name, others, cfg.height,
                                                                   cfg.width, 0))
                   for name, mv in moved.items()}
            motion = np.where(near, self._min_over_cameras(cov), -np.inf)
            top = near & (motion >= cfg.min_motion) \
                & (motion >= cfg.refine_share * motion.max())
            place = xy[int(np.argmax(np.where(top, score, -np.inf)))] if top.any() \
                else xy[best]
            # two places must stay nms_radius apart (the refined ones before this one, the
            # ones still to refine as taken)
            kept = np.array(out + [xy[c] for c in chosen[k + 1:]]).reshape(-1, 2)
            if len(kept) and np.linalg.norm(kept - place, axis=1).min() < cfg.nms_radius:
                place = xy[best]
            out.append(place)
        return np.array(out)

    def _region(self, name: str, xy: np.ndarray, height: float, width: float,
                dilation: int | None = None) -> np.ndarray:
        """(H, W) bool union of the silhouettes of ``height`` x ``width`` bodies standing at
        places ``xy`` (K, 2) in a camera, dilated by ``dilation`` (default the config's)."""
        cfg = self.config
        cam = self.calibration.cameras[name]
        mask = np.zeros((cam.height, cam.width), np.uint8)
        n = len(xy)
        if n:
            sil = rasterize(cam, _states(np.asarray(xy, np.float64)), self.shape,
                            heights=np.full(n, height), widths=np.full(n, width))
            for i in range(n):
                mask |= (sil.mask(i) > 0).view(np.uint8)
            dilation = cfg.dilation if dilation is None else dilation
            if dilation > 0:
                mask = cv2.dilate(mask, self._kernel(dilation))
        return mask.astype(bool)

    def regions(self, frames: Sequence[Mapping[str, np.ndarray]], *,
                places: np.ndarray | None = None
                ) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per camera of the last frame set, three (H, W) bool masks of the person-like
        places: the pixels not to learn (``region_*`` bodies, dilated); inside them, the
        possible foreground (the tested body); inside that, the body's core
        (``core_width`` wide), where the person stands whichever view. ``places`` (K, 2),
        metres: those of :meth:`places` on ``frames`` when already known."""
        cfg = self.config
        frames = list(frames)
        xy = self.places(frames) if places is None else np.asarray(places, np.float64)
        out = {}
        for name in frames[-1]:
            if name in self.calibration.cameras:
                region = self._region(name, xy, cfg.region_height, cfg.region_width)
                body = self._region(name, xy, cfg.height, cfg.width, 0)
                core = self._region(name, xy, cfg.height, cfg.core_width, 0) & body
                out[name] = (region | body, body, core)
        return out


def _take(spans: Spans, index: np.ndarray) -> Spans:
    """The silhouettes ``index`` (K,) of ``spans`` as :class:`Spans` with contiguous int64
    arrays (what the compiled kernels take, so that they are converted once)."""
    off = np.asarray(spans.offsets, np.int64)
    start = off[index]
    count = off[index + 1] - start
    offsets = np.zeros(len(index) + 1, np.int64)
    np.cumsum(count, out=offsets[1:])
    at = np.repeat(start - offsets[:-1], count) + np.arange(offsets[-1])
    take = (lambda a: np.asarray(a)[at].astype(np.int64, copy=False))
    return Spans(row=take(spans.row), x0=take(spans.x0), x1=take(spans.x1),
                 part=take(spans.part), offsets=offsets)

@dataclass(frozen=True)
class _SeenHypotheses:
    """The hypotheses a camera sees (``min_visible`` of the silhouette inside the image and
    at least ``min_area`` pixels): fixed geometry, so selected once.

    Attributes:
        index: (K,) indices into the (n_or * P,) hypotheses.
        spans: their silhouettes.
        width: (K,) projected body width (widest span), pixels.
        bbox: (K, 4) ``x0, y0, x1, y1`` (exclusive) of their spans.
    """

    index: np.ndarray
    spans: Spans
    width: np.ndarray
    bbox: np.ndarray

    @classmethod
    def of(cls, sil: Silhouettes, cfg: PeopleCueConfig, cam: Camera) -> _SeenHypotheses:
        min_area = cfg.min_area * cam.width * cam.height / (320.0 * 240.0)
        sees = (sil.area >= cfg.min_visible * np.maximum(sil.full_area, 1)) \
            & (sil.area >= min_area)
        index = np.flatnonzero(sees)
        spans = _take(sil, index)
        return cls(index, spans, _max_span_width(spans), np.asarray(sil.bbox)[index])
