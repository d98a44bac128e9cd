"""Release of tracks that lost their foreground support (003 §4.3).

A track's foreground support in a frame is the coverage of its rendered silhouette (the
share of it that is foreground) in every camera that sees it (silhouette at least
``min_area`` pixels in the image; a top-down camera's cylinder blob counts twice, clipped
to 1, see :func:`blob_coverage`), weighed together as the existence process weighs them
(001 §3.2, :func:`~mbtrack_ros.core.existence.coverage_log_ratio`): each camera is a
witness whose log-likelihood ratio "a person" over "nobody" is ``2 k (f_c - f_s)``, neutral
at ``min_coverage``, and the track is supported when their sum is positive. No camera
decides alone: a person sitting on a chair by a wall covers a small share of the top-down
camera's blob and most of the side views' silhouettes. When the caller filters the
existence probability (001 §3.2, :mod:`mbtrack_ros.core.existence`), which accumulates
that evidence with the appearance's over time, the existence replaces the frame's coverage
verdict (:attr:`Releaser.kept`), with each side camera's coverage counted on the pixels
no other track covers (:attr:`Releaser.exclusive_views`). The background bootstrap's
possible-person pixels (``FrameEvidence.undecided``: foreground by guess until seen
without a track over them, which the track standing on them prevents) count at the
neutral coverage ``min_coverage``, as in the filter's coverage term, not as foreground
(:func:`neutral_counts`). A track whose existence is below ``existence_threshold`` (or
that is spare, or unsupported in a doorway, below) for ``timeout`` seconds in a row is
terminated.

**Spare tracks.** A track that lost its person often moves on to somebody nearby who is
tracked already (a crowd at the door): its silhouette still lies on foreground, so the
plain support keeps it alive for tens of seconds. Its *exclusive* support tells it apart:
the foreground in the pixels that no other track's silhouette covers, per silhouette
pixel, averaged over the corner cameras that see it. A track that overlaps another one
and whose exclusive support is below ``spare_support`` is *spare* in that frame (it
explains no foreground that the others do not) and counts as unsupported; of several
such tracks the one with the least exclusive support is taken first and the others are
judged again without it, so that of two tracks on one person one survives (see
:func:`spare_tracks`). In a crowd such a track is supported now and then for a frame or
two; once it has been spare, only ``recover_time`` of support in a row restarts its
unsupported time.

**Exits.** When the calibration has exits (rectangles beyond a door, see
``RoomCalibration.exits``) a track whose estimate is inside one and more than
``exit_margin`` from the floor is released at once (:meth:`Releaser.exited`): its person
walked out. Without exits a person who leaves holds the track at the floor edge while
they stay visible through the open door, and the timeout only starts after that.

**Doorways**. Seen from a camera facing the door, a track standing in the doorway
lies in front of the corridor: the person who just walked out is still foreground behind
it, and so is a track left on the floor edge, which keeps it "supported" for seconds
after its person has gone (the ceiling camera's blob of such a track reaches into the
corridor too). The cameras on the door's wall (``RoomCalibration.doorway_witnesses``) see
the doorway from the side and cannot see beyond the wall, so for a track within
``doorway_band`` of an exit's border, or inside the exit, only their foreground counts as
support (003 §4.3: the release follows the foreground that the person explains); when none
of them sees the track the ordinary rule applies. A track they see and do not cover ends
after ``doorway_timeout``; one they cover keeps the ordinary ``timeout`` even when it
counts as unsupported for another reason (spare, low existence): in a crowd at the door
such a track usually still stands on its person.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from mbtrack_ros.core import _kernels
from mbtrack_ros.core.camera import Camera, RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.detector import FrameEvidence, is_ceiling
from mbtrack_ros.core.detection.features import span_counts
from mbtrack_ros.core.shape import Silhouettes

__all__ = ['ReleaseConfig', 'Releaser', 'blob_coverage', 'neutral_counts', 'paint_blobs',
           'spare_tracks']


def _blob_windows(camera: Camera, xy: np.ndarray, heights: np.ndarray, radius: float,
                  sides: int) -> list[tuple[int, int, np.ndarray] | None]:
    """Per upright cylinder (floor point ``xy``, height, ``radius``) the image window it
    covers: ``(x0, y0, inside)`` with ``inside`` the bool hull of the projected floor and head
    circles, clipped to the image; None where it is behind the camera or off the image."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    k = xy.shape[0]
    a = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], axis=1) * radius            # (S, 2)
    pts = np.zeros((k, 2, sides, 3))
    pts[:, :, :, :2] = xy[:, None, None, :] + ring[None, None]
    pts[:, 1, :, 2] = np.asarray(heights, dtype=np.float64).reshape(-1)[:, None]
    pix = camera.project(pts.reshape(k, 2 * sides, 3))                    # (K, 2S, 2)
    h, w = camera.height, camera.width
    out: list[tuple[int, int, np.ndarray] | None] = []
    for i in range(k):
        p = pix[i][np.all(np.isfinite(pix[i]), axis=1)]
        if len(p) < 3:
            out.append(None)
            continue
        x0, y0 = np.floor(p.min(axis=0)).astype(int)
        x1, y1 = np.ceil(p.max(axis=0)).astype(int) + 1
        cx0, cy0, cx1, cy1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if cx1 <= cx0 or cy1 <= cy0:
            out.append(None)
            continue
        hull = cv2.convexHull(np.round(p - [cx0, cy0]).astype(np.int32))
        roi = np.zeros((cy1 - cy0, cx1 - cx0), np.uint8)
        cv2.fillConvexPoly(roi, hull, 1)
        out.append((int(cx0), int(cy0), roi.astype(bool)))
    return out


def blob_coverage(camera: Camera, foreground: np.ndarray, xy: np.ndarray,
                  heights: np.ndarray, *, radius: float = 0.25, sides: int = 12
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Foreground coverage of the image of upright cylinders (a top-down camera's view of
    people: a blob around the floor point, 003 §4.3).

    The body-outline silhouette degenerates to a line or a point for a person right below
    a ceiling camera; the convex hull of the projected floor and head circles does not.

    Args:
        camera: the (top-down) camera; foreground: (H, W) bool mask.
        xy: (K, 2) floor positions, metres; heights: (K,) cylinder heights, metres.

    Returns:
        coverage: (K,) foreground fraction of the blob (0 where it is empty);
        area: (K,) blob pixels inside the image.
    """
    fg = np.asarray(foreground, dtype=bool)
    windows = _blob_windows(camera, xy, heights, radius, sides)
    cov = np.zeros(len(windows))
    area = np.zeros(len(windows))
    for i, win in enumerate(windows):
        if win is None:
            continue
        x0, y0, inside = win
        area[i] = inside.sum()
        if area[i] > 0:
            cov[i] = fg[y0:y0 + inside.shape[0], x0:x0 + inside.shape[1]][inside].mean()
    return cov, area


def paint_blobs(mask: np.ndarray, camera: Camera, xy: np.ndarray, heights: np.ndarray, *,
                outline_area: np.ndarray | None = None, max_fill: float = 0.25,
                radius: float = 0.25, sides: int = 12) -> None:
    """Set in ``mask`` (H, W) bool the pixels of the cylinder blobs of :func:`blob_coverage`
    (what a top-down camera sees of people standing at ``xy``); with ``outline_area`` (K,)
    only of the people whose body outline covers less than ``max_fill`` of their blob (the
    outline degenerates near the point right below the camera)."""
    for k, win in enumerate(_blob_windows(camera, xy, heights, radius, sides)):
        if win is not None:
            x0, y0, inside = win
            if outline_area is not None and outline_area[k] >= max_fill * inside.sum():
                continue
            mask[y0:y0 + inside.shape[0], x0:x0 + inside.shape[1]] |= inside


def _covering(shape: tuple[int, int], sil: Silhouettes, weights: np.ndarray) -> np.ndarray:
    """(H, W) float64 count of the silhouettes covering each pixel, silhouette i counted
    ``weights[i]`` times (0: left out)."""
    count = np.zeros(shape, np.float64)
    _kernels.accumulate_spans(count, sil.row, sil.x0, sil.x1, sil.offsets, weights, 0, 0)
    return count


def spare_tracks(foregrounds: Sequence[np.ndarray], silhouettes: Sequence[object],
                 min_support: float, min_area: Sequence[float] | None = None,
                 xy: np.ndarray | None = None, radius: float = np.inf
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Tracks that explain no foreground the other tracks do not (module docstring).

    Per camera, the pixels covered by exactly one track's silhouette are that track's
    exclusive pixels; its exclusive support is the foreground among them divided by its
    silhouette area, averaged over the cameras where the silhouette has at least
    ``min_area`` pixels. A track that shares pixels with another track in one of these
    cameras, has another (not spare) track within ``radius`` on the floor and whose
    exclusive support is below ``min_support`` is spare; the least supported one is
    removed first and the rest are judged again without it.

    Args:
        foregrounds: per camera the (H, W) bool foreground.
        silhouettes: per camera the K tracks' silhouettes (``shape.rasterize`` output).
        min_support: exclusive support below which an overlapping track is spare.
        min_area: per camera the pixels for it to see a track (default 1).
        xy: (K, 2) floor positions, metres, for ``radius`` (needed when it is finite).

    Returns:
        spare: (K,) bool; support: (K,) exclusive support (of a spare track: when it was
        found spare; NaN where no camera sees the track).
    """
    k = len(silhouettes[0].offsets) - 1 if len(silhouettes) else 0
    spare = np.zeros(k, bool)
    support = np.full(k, np.nan)
    if k == 0:
        return spare, support
    counts = []
    min_area = [1.0] * len(silhouettes) if min_area is None else list(min_area)
    near = np.ones((k, k), bool)
    if np.isfinite(radius):
        xy = np.asarray(xy, dtype=np.float64).reshape(k, 2)
        near = np.linalg.norm(xy[:, None] - xy[None], axis=2) < radius
    np.fill_diagonal(near, False)
    for fg, sil in zip(foregrounds, silhouettes):
        counts.append(_covering(np.shape(fg), sil, np.ones(k)))
    while True:
        total = np.zeros(k)
        seen = np.zeros(k)
        shared = np.zeros(k, bool)
        for fg, sil, count, least in zip(foregrounds, silhouettes, counts, min_area):
            own_fg, own, area = span_counts(fg, sil, unknown=count >= 2)
            sees = (area >= least) & ~spare
            total += np.where(sees, own_fg / np.maximum(area, 1.0), 0.0)
            seen += sees
            shared |= sees & (own < area)
        support = np.where(spare, support, np.where(seen > 0, total / np.maximum(seen, 1.0),
                                                    np.nan))
        candidate = shared & ~spare & (support < min_support) & near[:, ~spare].any(axis=1)
        if not candidate.any():
            return spare, support
        worst = int(np.flatnonzero(candidate)[np.argmin(support[candidate])])
        spare[worst] = True
        for sil, count in zip(silhouettes, counts):        # judge the others without it
            one = np.zeros(k)
            one[worst] = -1.0
            _kernels.accumulate_spans(count, sil.row, sil.x0, sil.x1, sil.offsets,
                                      one, 0, 0)


def neutral_counts(foreground: np.ndarray, spans: Silhouettes, shared: np.ndarray | None = None,
                   undecided: np.ndarray | None = None, neutral: float = 0.0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K,) foreground pixels, pixels and area of each silhouette of ``spans`` outside the
    (H, W) bool ``shared`` pixels, the ``undecided`` ones among them counted as ``neutral``
    foreground each (float: a fraction of a pixel).

    An undecided pixel (the background bootstrap's possible person, not yet seen without a
    track over it) is no evidence either way: the existence evidence counts it at the
    neutral coverage, as the filter's coverage term does (``set_foreground(undecided=)``).
    Without undecided pixels this is :func:`span_counts` with ``unknown=shared``."""
    own_fg, own, area = span_counts(foreground, spans, unknown=shared)
    if undecided is None or not np.any(undecided):
        return own_fg, own, area
    either = undecided if shared is None else (undecided | shared)
    known_fg, known, _ = span_counts(foreground, spans, unknown=either)
    return known_fg + neutral * (own - known), own, area


class _SideViews(NamedTuple):
    """The side cameras' inputs of one :meth:`Releaser.support` call, camera by camera."""

    foregrounds: list[np.ndarray]        # (H, W) bool
    silhouettes: list[Silhouettes]       # the K tracks' silhouettes
    min_area: list[float]                # pixels for a camera to see a track
    undecided: list[np.ndarray | None]   # (H, W) bool (FrameEvidence.undecided)
    neutral: float                       # the coverage an undecided pixel counts as
    k: int                               # tracks


def _exclusive_views(names: Sequence[str], side: _SideViews, spare: np.ndarray
                     ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per side camera of ``names`` the (K,) share of each track's silhouette that no
    other track covers (spare tracks left out of the others) and (K,) the foreground
    coverage of those exclusive pixels, undecided pixels at the neutral coverage
    (:func:`neutral_counts`; NaN where a track has none, or the camera does not see it).

    The pixels another track's silhouette covers are explained by that track whether or
    not this one exists, so only the exclusive pixels are evidence of this track's
    existence (001 §3.2 with the pixel-level observation of 000 Eq. 20): their foreground
    is the likelihood ratio's data, their share of the silhouette its weight."""
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if not side.k:
        return out
    for name, fg, sil, small, unsure in zip(names, side.foregrounds, side.silhouettes,
                                            side.min_area, side.undecided):
        count = _covering(np.shape(fg), sil, (~spare).astype(np.float64))
        own_fg, own, area = neutral_counts(fg, sil, count >= 2, unsure, side.neutral)
        if spare.any():      # a spare track is not counted: any count over it is another
            s_fg, s_own, _ = neutral_counts(fg, sil, count >= 1, unsure, side.neutral)
            own_fg, own = np.where(spare, s_fg, own_fg), np.where(spare, s_own, own)
        sees = area >= small
        share = np.where(sees, own / np.maximum(area, 1.0), np.nan)
        cov = np.where(sees & (own > 0), own_fg / np.maximum(own, 1.0), np.nan)
        out[name] = (share, cov)
    return out


@dataclass(frozen=True)
class ReleaseConfig:
    """Parameters of the track release.

    Attributes:
        timeout: seconds without support before a track ends (003 §4.3: 1 s).
        min_coverage: foreground coverage (fraction of the silhouette in [0, 1]) at which a
            camera's view is neutral evidence of support (module docstring); the
            existence process's neutral coverage too.
        min_blob_coverage: the coverage of a top-down camera's cylinder blob at which it
            covers a track (the hull of the floor and head circles is about twice a
            person's image; an empty floor region gives ~0): for the doorway rule.
        min_area: pixels (at 320x240, scaled with the image) for a camera to see a track.
        existence_threshold: existence probability below which a track counts as
            unsupported (001 §3.2; 0 disables).
        merge_radius, merge_time: two tracks closer than ``merge_radius`` metres for
            ``merge_time`` seconds follow the same person; the younger one (larger id) is
            released (a person re-detected next to a lagging track), or, when the caller
            gives the stamps since which each track has been reported without a break,
            the one reported for the shorter time (see :meth:`Releaser.duplicates`).
        spare_support: exclusive support (mean over the corner cameras of the foreground
            in the pixels no other track covers, per silhouette pixel) below which a track
            that overlaps another one is spare and counts as unsupported (module
            docstring, :func:`spare_tracks`); 0 disables. ``spare_radius``: only a track
            with another track this close on the floor (metres) can be spare, when the
            caller gives the states. Dimensionless (a foreground fraction): tracks on a
            person typically reach 0.3-0.7, tracks on nobody stay below about 0.25. The
            association uses both (``AutoDetectionConfig.move_support``,
            ``relocate_radius``): a detection within ``spare_radius`` of a track may be
            its person, and a track that would keep ``spare_support`` with the detection
            as one more track is not moved onto it.
        exit_margin: metres from the floor rectangle beyond which a track inside one of the
            calibration's exits is released at once (module docstring); people standing in
            a doorway stay within it. It must exceed the overshoot of a track whose person
            stops in the doorway (a track keeps some of its velocity for a few frames);
            smaller releases people still in the room, larger keeps leavers longer.
        doorway_band: metres in front of an exit's border (and inside the exit) within
            which a track is supported only by the cameras on the door's wall (module
            docstring, "Doorways"); 0 disables. ``doorway_timeout``: seconds after which
            such a track ends when the door-wall cameras see it and find no foreground on
            it (instead of ``timeout``).
        recover_time: seconds a track that was spare during its unsupported time must be
            supported in a row before that time starts again from zero (one supported
            frame does for others; 0: for all). A track that lost its person in a crowd is
            spare most of the time with a supported frame or two in between; without this
            those frames would keep it alive until it takes over somebody else.
    """

    timeout: float = 1.0
    min_coverage: float = 0.3
    min_blob_coverage: float = 0.12
    min_area: int = 30
    existence_threshold: float = 0.1
    merge_radius: float = 0.35
    merge_time: float = 0.5
    spare_support: float = 0.25
    spare_radius: float = 1.0
    exit_margin: float = 0.6
    doorway_band: float = 0.5
    doorway_timeout: float = 0.5
    recover_time: float = 0.2

    def __post_init__(self) -> None:
        if not self.timeout >= 0:
            raise DetectionError(f'release timeout must be >= 0, got {self.timeout}')
        if not 0.0 <= self.min_coverage <= 1.0:
            raise DetectionError(f'min_coverage must be in [0, 1], got {self.min_coverage}')
        if not 0.0 <= self.spare_support <= 1.0 or not self.spare_radius >= 0:
            raise DetectionError('spare_support must be in [0, 1] and spare_radius >= 0, got '
                                 f'{self.spare_support}, {self.spare_radius}')
        if not (np.isfinite(self.exit_margin) and self.exit_margin >= 0):
            raise DetectionError(f'exit_margin must be a finite number >= 0, got '
                                 f'{self.exit_margin}')
        if not (np.isfinite(self.recover_time) and self.recover_time >= 0):
            raise DetectionError(f'recover_time must be a finite number >= 0, got '
                                 f'{self.recover_time}')
        if not self.doorway_timeout >= 0:
            raise DetectionError(f'doorway_timeout must be >= 0, got {self.doorway_timeout}')
        if not (np.isfinite(self.doorway_band) and self.doorway_band >= 0):
            raise DetectionError(f'doorway_band must be a finite number >= 0, got '
                                 f'{self.doorway_band}')


class Releaser:
    """Keeps, per track, the time since it was last supported and ends stale tracks."""

    def __init__(self, calibration: RoomCalibration, config: ReleaseConfig | None = None
                 ) -> None:
        self.calibration = calibration
        self.config = config or ReleaseConfig()
        self._since: dict[int, int] = {}
        self._spare_run: set[int] = set()       # spare on a frame of their unsupported time
        self._good_since: dict[int, int] = {}   # ... of those, supported again since
        self._close: dict[tuple[int, int], int] = {}
        # per close pair: summed exclusive support of each track and frames summed
        self._close_support: dict[tuple[int, int], tuple[float, float, int]] = {}
        self.spare = np.zeros(0, bool)    # tracks of the last support() that were spare
        self._side: _SideViews | None = None   # the last support()'s side-camera inputs
        self._exclusive: np.ndarray | None = None   # ... their exclusive_support(), cached
        self.doorway = np.zeros(0, bool)  # ... in a doorway, seen but not covered by the
        #                                     door-wall cameras (doorway_timeout applies)
        self.kept = np.zeros(0, bool)     # ... neither spare nor unsupported in a doorway
        self.exclusive_views: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # per side
        #   camera (K,) share of each silhouette no other kept track covers and (K,) its
        #   foreground coverage there (:func:`_exclusive_views`)

    def support(self, evidence: Mapping[str, FrameEvidence], silhouettes: Mapping[str, object],
                states: np.ndarray | None = None, heights: np.ndarray | None = None
                ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Support of K tracks from their rendered silhouettes.

        Args:
            evidence: per camera the frame's foreground.
            silhouettes: per camera the K tracks' silhouettes (``shape.rasterize`` output).
            states, heights: (K, 6) states and (K,) body heights; when given, top-down
                cameras use the cylinder blob of :func:`blob_coverage` instead of the
                silhouettes.

        Returns:
            supported: (K,) bool, the frame's pooled coverage evidence is positive (module
                docstring); False for spare tracks (also kept in ``self.spare``) and for
                tracks the door-wall cameras see without covering them (``self.doorway``).
                ``self.kept`` is the same verdict without the coverage evidence, for a
                caller whose existence process weighs that evidence.
            coverage: camera -> (K,) coverage (NaN where the camera does not see the track);
                all cameras with evidence; blob coverages are doubled (clipped to 1) to be
                comparable with silhouette coverages.
        """
        cfg = self.config
        coverage: dict[str, np.ndarray] = {}
        seen: dict[str, np.ndarray] = {}         # camera -> (K,) sees the track
        covered: dict[str, np.ndarray] = {}      # camera -> (K,) sees it on foreground
        evidence_sum = None                      # (K,) pooled coverage log-ratio / 2k
        for name, sil in silhouettes.items():
            if name not in evidence:
                continue
            cam = self.calibration.cameras[name]
            threshold = cfg.min_coverage
            blob = states is not None and heights is not None and is_ceiling(cam)
            if blob:
                cov, area = blob_coverage(cam, evidence[name].foreground, states[:, :2],
                                          heights)
                threshold = cfg.min_blob_coverage
            else:
                fg_n, _, area = neutral_counts(evidence[name].foreground, sil,
                                               undecided=evidence[name].undecided,
                                               neutral=cfg.min_coverage)
                cov = np.where(area > 0, fg_n / np.maximum(area, 1.0), 0.0)
            sees = area >= cfg.min_area * cam.width * cam.height / (320.0 * 240.0)
            scale = 2.0 if blob else 1.0
            coverage[name] = np.where(sees, np.minimum(scale * cov, 1.0), np.nan)
            seen[name], covered[name] = sees, sees & (cov >= threshold)
            # the camera's witness (001 §3.2, existence.coverage_log_ratio, per 2k)
            vote = np.where(sees, coverage[name] - cfg.min_coverage, 0.0)
            evidence_sum = vote if evidence_sum is None else evidence_sum + vote
        if evidence_sum is None:
            k = len(next(iter(silhouettes.values())).offsets) - 1 if silhouettes else 0
            evidence_sum = np.zeros(k)
        supported = evidence_sum > 0.0
        kept = np.ones(len(supported), bool)
        self.doorway = np.zeros(len(supported), bool)
        if cfg.doorway_band > 0 and states is not None and self.calibration.exits:
            # in front of a door only the cameras on the door's wall count (module docstring)
            watched = np.zeros(len(supported), bool)
            held = np.zeros(len(supported), bool)
            for name, front in self.calibration.doorway_witnesses(
                    states[:, :2], cfg.doorway_band).items():
                if name in seen:
                    watched |= front & seen[name]
                    held |= front & covered[name]
            supported = np.where(watched, held, supported)
            kept = np.where(watched, held, kept)
            # the short timeout is for this evidence only: a track the wall cameras cover
            # that is spare (a crowd at the door) or fading keeps the ordinary one
            self.doorway = watched & ~held
        self.spare = np.zeros(len(supported), bool)
        side = [n for n in silhouettes if n in evidence
                and not is_ceiling(self.calibration.cameras[n])]
        cams = [self.calibration.cameras[n] for n in side]
        self._side = _SideViews(
            [evidence[n].foreground for n in side], [silhouettes[n] for n in side],
            [cfg.min_area * c.width * c.height / (320.0 * 240.0) for c in cams],
            [evidence[n].undecided for n in side], cfg.min_coverage, len(supported))
        self._exclusive = None
        if cfg.spare_support > 0 and side and len(supported) > 1:
            self.spare, _ = spare_tracks(
                self._side.foregrounds, self._side.silhouettes, cfg.spare_support,
                self._side.min_area, None if states is None else states[:, :2],
                cfg.spare_radius if states is not None else np.inf)
            supported = supported & ~self.spare
        self.kept = kept & ~self.spare
        self.exclusive_views = _exclusive_views(side, self._side, self.spare)
        return supported, coverage

    def exclusive_support(self) -> np.ndarray:
        """(K,) exclusive support of the tracks of the last :meth:`support` call, all
        of them present (none taken out as spare; :func:`spare_tracks` with
        ``min_support`` 0), side cameras; NaN where no side camera sees a track or before
        any call. Computed on the first call after each :meth:`support`."""
        if self._exclusive is None:
            if self._side is None:
                return np.zeros(0)
            side = self._side
            self._exclusive = spare_tracks(side.foregrounds, side.silhouettes, 0.0,
                                           side.min_area)[1] if side.foregrounds \
                else np.full(side.k, np.nan)
        return self._exclusive

    def exited(self, ids: Sequence[int], xy: np.ndarray) -> list[int]:
        """Ids of the tracks whose floor position (K, 2) lies inside an exit more than
        ``exit_margin`` from the floor: their person left the room."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if len(ids) != len(xy):
            raise DetectionError('ids and positions must have the same length')
        depth = self.calibration.exit_depth(xy)
        return [int(ids[k]) for k in np.flatnonzero(depth > self.config.exit_margin)]

    def update(self, stamp_ns: int, ids: Sequence[int], supported: Sequence[bool],
               existence: Sequence[float] | None = None,
               doorway: Sequence[bool] | None = None,
               spare: Sequence[bool] | None = None) -> list[int]:
        """Record one frame's support; returns the ids to release now. A track flagged in
        ``doorway`` (``self.doorway`` of :meth:`support`) is released after
        ``doorway_timeout`` instead of ``timeout``. A track flagged in ``spare``
        (``self.spare``) on a frame of its unsupported time keeps that time through
        supported frames until they last ``recover_time``; otherwise one supported frame
        restarts it."""
        cfg = self.config
        if len(supported) != len(ids) or any(v is not None and len(v) != len(ids)
                                             for v in (existence, doorway, spare)):
            raise DetectionError('ids, supported, existence, doorway and spare must have the '
                                 'same length')
        ended = []
        live = set(int(i) for i in ids)
        for tid in list(self._since):
            if tid not in live:
                del self._since[tid]
        self._good_since = {t: s for t, s in self._good_since.items() if t in live}
        self._spare_run &= live
        for k, tid in enumerate(ids):
            tid = int(tid)
            bad = not bool(supported[k])
            if existence is not None and existence[k] < cfg.existence_threshold:
                bad = True
            if not bad:
                if tid in self._spare_run:   # spare in this unsupported time: hold it
                    good = self._good_since.setdefault(tid, int(stamp_ns))
                    if (int(stamp_ns) - good) / 1e9 < cfg.recover_time:
                        continue
                self._since.pop(tid, None)
                self._spare_run.discard(tid)
                self._good_since.pop(tid, None)
                continue
            self._good_since.pop(tid, None)
            if spare is not None and spare[k]:
                self._spare_run.add(tid)
            since = self._since.setdefault(tid, int(stamp_ns))
            timeout = cfg.doorway_timeout if doorway is not None and doorway[k] else cfg.timeout
            if (int(stamp_ns) - since) / 1e9 >= timeout:
                ended.append(tid)
                del self._since[tid]
        return ended

    def duplicates(self, stamp_ns: int, ids: Sequence[int], xy: np.ndarray,
                   shown_since: Sequence[int] | None = None,
                   prefer: Callable[[int, int], int | None] | None = None,
                   own_support: Sequence[float] | Callable[[], Sequence[float]] | None
                   = None) -> list[int]:
        """Ids of tracks that shadowed another one for ``merge_time`` seconds: of each
        such pair the younger one (larger id), or with ``shown_since`` the one reported
        without a break for the shorter time (later stamp; ties: the larger id). A track
        that was hidden (existence below the report threshold) while a new one took its
        person over is then the one released: the person's reported identity stays.

        Args:
            stamp_ns: frame stamp; ids: K track ids; xy: (K, 2) floor positions, metres.
            shown_since: optional (K,) stamps since which each track has been reported
                without a break (its birth, last move or last hidden frame).
            prefer: optional judge of a due pair: called with the two ids, returns the
                id to keep (the other is released) or None for the rule above.
            own_support: optional (K,) exclusive support of each track, or a function
                returning it, called on the frames a pair is close
                (:meth:`exclusive_support`): without a judge's decision, the track
                released is the one that explained no foreground of its own while the two
                were close (mean exclusive support over those frames below
                ``spare_support``) when the other one did, whatever their ages (a track
                born beside a person, then a second one on the person: the first goes;
                the mean, not one frame's support, so that a person passing behind
                another is not taken for it); the track a due pair would release is kept
                while its own support is at least ``spare_support`` (the pair is two
                people passing close, each explaining foreground the other does not);
                NaN counts as none.
        """
        cfg = self.config
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if len(ids) != len(xy) or any(
                v is not None and not callable(v) and len(v) != len(ids)
                for v in (shown_since, own_support)):
            raise DetectionError('ids, positions, shown_since and own_support must have the '
                                 'same length')
        own: dict[int, float] | None = None

        def own_of(tid: int) -> float:
            nonlocal own
            if own is None:
                values = own_support() if callable(own_support) else own_support
                if len(values) != len(ids):
                    raise DetectionError(f'own_support has {len(values)} values for '
                                         f'{len(ids)} tracks')
                own = {int(i): float(v) for i, v in zip(ids, values)}
            return own[int(tid)]
        rank = {int(i): (0 if shown_since is None else int(shown_since[k]), int(i))
                for k, i in enumerate(ids)}
        close = set()
        if len(ids) > 1:
            d = np.linalg.norm(xy[:, None] - xy[None], axis=2)
            for a, b in zip(*np.nonzero(np.triu(d < cfg.merge_radius, 1))):
                close.add((min(int(ids[a]), int(ids[b])), max(int(ids[a]), int(ids[b]))))
        self._close = {p: t for p, t in self._close.items() if p in close}
        self._close_support = {p: v for p, v in self._close_support.items() if p in close}
        out = set()
        for p in close:
            since = self._close.setdefault(p, int(stamp_ns))
            if own_support is not None:     # NaN (not seen) counts as none
                sa, sb, n = self._close_support.get(p, (0.0, 0.0, 0))
                self._close_support[p] = (sa + np.nan_to_num(own_of(p[0])),
                                          sb + np.nan_to_num(own_of(p[1])), n + 1)
            if (int(stamp_ns) - since) / 1e9 >= cfg.merge_time:
                keep = prefer(*p) if prefer is not None else None
                if keep in p:           # the judge decided: the other one goes
                    gone = p[1] if keep == p[0] else p[0]
                else:
                    gone = max(p, key=rank.__getitem__)
                    if own_support is not None:
                        # the foreground decides: the track that explained none of its own
                        # while the two were close (mean exclusive support below
                        # spare_support) goes when the other one did, whatever their ages
                        sa, sb, n = self._close_support[p]
                        mean = {p[0]: sa / n, p[1]: sb / n}
                        stays = p[0] if gone == p[1] else p[1]
                        if mean[gone] >= cfg.spare_support > mean[stays]:
                            gone = stays
                if own_support is None or not own_of(gone) >= cfg.spare_support:  # NaN: none
                    out.add(gone)
        for p in list(self._close):
            if p[0] in out or p[1] in out:
                del self._close[p]
                self._close_support.pop(p, None)
        return sorted(out)

    def forget(self, track_id: int) -> None:
        self._since.pop(int(track_id), None)
        self._good_since.pop(int(track_id), None)
        self._spare_run.discard(int(track_id))
