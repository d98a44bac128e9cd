"""Coarse-to-fine detection of new people on a floor grid (003 §4.1).

The floor (or the calibration's entry zones) is collapsed into a regular grid; each grid
point carries hypotheses over body height, width, orientation and pose (standing/sitting).
The likelihood of a hypothesis is the product over cameras of single-view responses
(a sum of log responses here, 003 §4.1), each built from the three features of
:mod:`.features`:

* **coarse level** - a sub-sampled grid with one height/width, scored by foreground coverage
  alone on all cameras (the ceiling camera included: it sees a person as a blob around the
  floor point). The silhouettes of this static grid are rasterised once at construction,
  so a frame costs one prefix-sum lookup per span;
* **fine level** - in the neighbourhood of promising coarse points, a full-resolution grid
  is scored with coverage, contour likelihood (003 Eq. 5) and colour symmetry (side
  cameras; the ceiling camera contributes coverage only), first over position and pose,
  then over height, width and orientation at the best position.

Hypotheses near current tracks are removed before each search (003 §4.1), pixels covered
by the tracks' rendered silhouettes are treated as unknown (neither support nor
contradiction), several simultaneous entries are separated by non-maximum suppression, and
a detection is only emitted after it has been found at a consistent position in
``confirm_frames`` consecutive frames.

Per-view log response of a hypothesis seen by camera ``c`` (relative to a neutral
reference, so that cameras that do not see it contribute 0 and evidence adds up):
``w_cov log(max(cov, floor) / cov_ref) + w_con (contour - con_ref) + w_sym (sym_ref - sym)``
plus, at the fine level, ``w_ctx log(max(1 - extra, floor) / cov_ref)`` where ``extra`` is
the foreground fraction of a larger standing body around the hypothesis that the
hypothesis does not cover (coverage alone favours any hypothesis inside the blob, e.g. a
sitting one inside a standing person).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from mbtrack_ros.core.appearance import quantize
from mbtrack_ros.core.camera import Camera, RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.features import (
    EdgeMap, ForegroundIntegral, colour_symmetry, contour_loglik_spans, span_count)
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.state import SIT, STATE_DIM, THETA, VX, VY, X, Y

__all__ = ['Detection', 'Detector', 'DetectorConfig', 'FrameEvidence', 'is_ceiling']


def is_ceiling(camera: Camera, *, cos_limit: float = 0.8) -> bool:
    """True for a camera looking (nearly) straight down at the floor."""
    forward = camera.R[2]                     # optical axis in world coordinates
    return bool(forward[2] < -cos_limit)


@dataclass(frozen=True)
class DetectorConfig:
    """Parameters of the detection search (metres, radians, pixels at 320x240).

    Attributes:
        coarse_spacing, fine_spacing: grid spacings of the two levels.
        fine_radius: half-size of the fine grid around a promising coarse point.
        zones: 'floor' (whole walkable floor and entry zones) or 'entry' (entry zones only).
        heights, widths, orientations: fine-level hypotheses (orientations in [0, pi)
            suffice: the shape model is symmetric).
        sitting: also test sitting hypotheses.
        coarse_height, coarse_width: the single size of the coarse level.
        coarse_coverage: mean coverage over the seeing cameras of a promising coarse point.
        veto_coverage: a seeing camera with coverage below this rejects the hypothesis.
        excuse_weakest: for a hypothesis inside an entry zone, farther than
            ``excuse_radius`` from every track and seen by at least ``min_views + 1``
            cameras, the side camera with the lowest coverage neither vetoes it nor counts
            in the coarse mean coverage (its log response still counts): in the doorway
            one view may show a person much like what its background model holds behind
            them (dark clothes against the corridor, a model that learnt the person while
            they stood beyond the open door), and it must not hide them from the others.
            Only there and only alone: elsewhere, and beside tracked people, the excuse
            let hypotheses between people through. Off by default: it makes entries
            earlier but lets more false hypotheses through.
        excuse_radius: metres; see ``excuse_weakest``.
        min_views: cameras that must see a hypothesis (in image, mostly not hidden by
            tracks, at least ``min_area`` pixels); a camera in which tracked people hide
            it counts towards them (not seen is not absent: in a two-camera room a person
            behind a tracked one in one view is confirmed by the other), unless what it
            does see of it is background, and at least one camera must see it.
        min_known: fraction of the silhouette not covered by tracks for a camera to count.
        min_area: smallest silhouette area in pixels at 320x240 (scaled with the image).
        w_coverage, w_contour, w_symmetry: weights of the three log responses.
        w_context, context_height, context_width: weight of the "unexplained foreground"
            response and the size of the standing body around a hypothesis it is measured
            in (fine level only).
        coverage_floor, coverage_ref, contour_ref, symmetry_ref: response references.
        threshold: smallest combined log response of a detection.
        confirm_frames: consecutive frames a detection must be found in.
        confirm_radius: largest position change between confirming frames.
        exclusion_radius: hypotheses this close to a track are not tested.
        nms_radius: non-maximum-suppression radius between detections.
        depth_range: metres; the fine search also tests the places on each side camera's
            line of sight through the best place of its window, up to this far from it
            (:meth:`Detector._sight_lines`): a view fixes the bearing of a person but hardly
            the depth, and where the views' evidence disagrees about the depth (a view that
            sees only part of the body, the edge of a door, a nearer person) the window
            around a coarse point can hold the wrong one. 0 turns it off.
        max_candidates: coarse neighbourhoods refined per frame (a fixed budget that bounds
            the search time; the neighbourhoods of candidates being confirmed go first).
        min_motion: fraction of recently moving pixels of the silhouette (in every side
            camera that sees it, in one of the confirming frames) to confirm a detection.
        min_speed, max_speed: m/s; a confirmed detection faster than ``min_speed`` over
            its confirming frames gets its walking direction as body orientation and is
            standing (a sitting best hypothesis is refined again with standing bodies
            only: a walker's spread legs fit a sitting body's thighs); one
            faster than ``max_speed`` gets no velocity: its places jumped (a neighbour,
            the fringe of a group), nobody walked there (a clipped velocity would send
            the new track off the wrong way).
        edge_min_pixels, edge_neighbourhood: edge validation of the contour feature,
            pixels (:meth:`EdgeMap.from_image`: smallest edge component, foreground
            neighbourhood searched).
    """

    coarse_spacing: float = 0.3
    fine_spacing: float = 0.1
    fine_radius: float = 0.2
    zones: str = 'floor'
    heights: tuple[float, ...] = (1.6, 1.75, 1.9)
    widths: tuple[float, ...] = (0.45, 0.55)
    orientations: tuple[float, ...] = (0.0, np.pi / 4, np.pi / 2, 3 * np.pi / 4)
    sitting: bool = True
    coarse_height: float = 1.75
    coarse_width: float = 0.5
    coarse_coverage: float = 0.45
    veto_coverage: float = 0.15
    excuse_weakest: bool = False
    excuse_radius: float = 1.0
    min_views: int = 2
    min_known: float = 0.5
    min_area: int = 60
    w_coverage: float = 1.0
    w_contour: float = 1.0
    w_symmetry: float = 0.3
    w_context: float = 1.0
    context_height: float = 2.1
    context_width: float = 0.8
    coverage_floor: float = 0.02
    coverage_ref: float = 0.5
    contour_ref: float = 0.0
    symmetry_ref: float = 1.0
    threshold: float = 1.0
    confirm_frames: int = 3
    confirm_radius: float = 0.4
    exclusion_radius: float = 0.5
    nms_radius: float = 0.6
    max_candidates: int = 3
    depth_range: float = 0.8
    min_motion: float = 0.05
    min_speed: float = 0.3
    max_speed: float = 2.0
    edge_min_pixels: int = 12
    edge_neighbourhood: int = 7

    def __post_init__(self) -> None:
        if not self.excuse_radius >= 0:
            raise DetectionError('detector excuse_radius must be >= 0')
        if not self.depth_range >= 0:
            raise DetectionError('detector depth_range must be >= 0')
        for name in ('coarse_spacing', 'fine_spacing', 'nms_radius', 'confirm_radius'):
            if not getattr(self, name) > 0:
                raise DetectionError(f'detector {name} must be > 0')
        if self.zones not in ('floor', 'entry'):
            raise DetectionError(f"detector zones must be 'floor' or 'entry', got {self.zones!r}")
        if not (self.heights and self.widths and self.orientations):
            raise DetectionError('detector needs at least one height, width and orientation')
        if min(self.heights) <= 0 or min(self.widths) <= 0:
            raise DetectionError('detector heights and widths must be positive')
        if self.min_views < 1 or self.confirm_frames < 1 or self.max_candidates < 1:
            raise DetectionError('min_views, confirm_frames and max_candidates must be >= 1')


def fitted_velocity(history: Sequence[tuple[int, float, float]]) -> np.ndarray | None:
    """Least-squares floor velocity (vx, vy), m/s, of ``(stamp_ns, x, y)`` places; None
    for fewer than two places or no time between them."""
    if len(history) < 2:
        return None
    h = np.asarray(history, dtype=np.float64)
    t = (h[:, 0] - h[0, 0]) / 1e9
    if np.ptp(t) <= 0:
        return None
    tc = t - t.mean()
    return (tc[:, None] * (h[:, 1:] - h[:, 1:].mean(axis=0))).sum(axis=0) / (tc ** 2).sum()


@dataclass
class Detection:
    """One detected person.

    Attributes:
        state: (6,) state ``x, y, vx, vy, theta, sitting`` (metres, m/s, radians).
        height, width: body size of the best hypothesis, metres.
        score: combined log response.
        coverage: per seeing camera, the foreground coverage of the silhouette.
        frames: consecutive frames the detection was found in.
        motion: smallest fraction of recently moving pixels in the silhouette over the side
            cameras that see it (largest over the confirming frames); ``inf`` when motion
            is not known.
    """

    state: np.ndarray
    height: float
    width: float
    score: float
    coverage: dict[str, float] = field(default_factory=dict)
    frames: int = 1
    motion: float = float('inf')
    history: list[tuple[int, float, float]] = field(default_factory=list, repr=False)

    @property
    def xy(self) -> np.ndarray:
        return self.state[[X, Y]]


@dataclass
class FrameEvidence:
    """Per-frame image evidence of one camera shared by detection and release.

    Attributes:
        image: (H, W, 3) uint8 RGB.
        foreground: (H, W) bool foreground mask.
        tracks: (H, W) bool pixels covered by the rendered silhouettes of current tracks.
        undecided: (H, W) bool pixels whose foreground is undecided (the background
            bootstrap's possible people, ``BackgroundModel.possible_foreground_as_tested``);
            the existence evidence counts them at the neutral coverage (None: none).
        motion: (H, W) bool pixels that moved recently (None: not checked).
        edge_min_pixels, edge_neighbourhood: edge validation (``DetectorConfig``).
    """

    image: np.ndarray
    foreground: np.ndarray
    tracks: np.ndarray | None = None
    undecided: np.ndarray | None = None
    motion: np.ndarray | None = None
    edge_min_pixels: int = 12
    edge_neighbourhood: int = 7
    _motion_integral: ForegroundIntegral | None = field(default=None, repr=False)
    _integral: ForegroundIntegral | None = field(default=None, repr=False)
    _edges: EdgeMap | None = field(default=None, repr=False)
    _bins: np.ndarray | None = field(default=None, repr=False)

    @property
    def bins(self) -> np.ndarray:
        """Colour bins of the image (``appearance.quantize``), computed once per frame."""
        if self._bins is None:
            self._bins = quantize(self.image)
        return self._bins

    @property
    def integral(self) -> ForegroundIntegral:
        """Prefix sums with the track pixels unknown (for new hypotheses)."""
        if self._integral is None:
            self._integral = ForegroundIntegral(self.foreground, self.tracks)
        return self._integral

    @property
    def motion_integral(self) -> ForegroundIntegral | None:
        if self.motion is None:
            return None
        if self._motion_integral is None:
            self._motion_integral = ForegroundIntegral(self.motion)
        return self._motion_integral

    @property
    def edges(self) -> EdgeMap:
        if self._edges is None:
            fg = self.foreground
            if self.tracks is not None:
                fg = fg & ~self.tracks
            self._edges = EdgeMap.from_image(self.image, fg,
                                             min_edge_pixels=self.edge_min_pixels,
                                             neighbourhood=self.edge_neighbourhood)
        return self._edges


def _grid(bounds: Sequence[tuple[float, float, float, float]], spacing: float) -> np.ndarray:
    pts = []
    for x0, y0, x1, y1 in bounds:
        xs = np.arange(x0, x1 + 1e-9, spacing)
        ys = np.arange(y0, y1 + 1e-9, spacing)
        gx, gy = np.meshgrid(xs + 0.5 * (x1 - xs[-1]), ys + 0.5 * (y1 - ys[-1]))
        pts.append(np.stack([gx.ravel(), gy.ravel()], axis=1))
    out = np.concatenate(pts)
    # drop duplicates of overlapping zones
    _, keep = np.unique(np.round(out / (0.5 * spacing)).astype(np.int64), axis=0,
                        return_index=True)
    return out[np.sort(keep)]


def _states(xy: np.ndarray, theta: np.ndarray | float = 0.0,
            sitting: np.ndarray | float = 0.0) -> np.ndarray:
    s = np.zeros((xy.shape[0], STATE_DIM))
    s[:, X], s[:, Y] = xy[:, 0], xy[:, 1]
    s[:, THETA] = theta
    s[:, SIT] = sitting
    return s


def _max_span_width(sil) -> np.ndarray:
    """(N,) widest span of each silhouette, pixels (the projected body width Delta)."""
    n = span_count(sil)
    w = (sil.x1 - sil.x0).astype(np.float64)
    off = np.asarray(sil.offsets)
    out = np.zeros(n)
    nonempty = off[1:] > off[:-1]
    if w.size:
        red = np.maximum.reduceat(w, np.minimum(off[:-1], w.size - 1))
        out[nonempty] = red[nonempty]
    return out


def _vetoes(covs: np.ndarray, side: np.ndarray, veto: float, excusable: np.ndarray,
            excuse_from: int) -> tuple[np.ndarray, np.ndarray]:
    """(vetoed (N,), counted (C, N)) of hypotheses from their per-camera coverage.

    ``covs`` (C, N) is NaN where a camera does not see a hypothesis, ``side`` (C,) flags the
    side cameras. A seeing camera below ``veto`` vetoes, except that for an ``excusable``
    hypothesis (N,) seen by at least ``excuse_from`` cameras the side camera with the
    lowest coverage is excused: it neither vetoes nor is ``counted`` (the coarse mean)."""
    sees = np.isfinite(covs)
    counted = sees.copy()
    if covs.size and excusable.any():
        side_cov = np.where(sees & side[:, None], covs, np.inf)
        weakest = np.argmin(side_cov, axis=0)
        cols = np.arange(covs.shape[1])
        excuse = excusable & (sees.sum(axis=0) >= excuse_from) \
            & np.isfinite(side_cov[weakest, cols])
        counted[weakest[excuse], cols[excuse]] = False
    return (counted & (np.where(sees, covs, np.inf) < veto)).any(axis=0), counted


def _nms(xy: np.ndarray, score: np.ndarray, radius: float, limit: int) -> np.ndarray:
    """Indices of local maxima of ``score`` at least ``radius`` apart, best first."""
    order = np.argsort(-score, kind='stable')
    keep: list[int] = []
    for i in order:
        if len(keep) >= limit:
            break
        if keep and np.min(np.linalg.norm(xy[keep] - xy[i], axis=1)) < radius:
            continue
        keep.append(int(i))
    return np.asarray(keep, dtype=np.int64)


class Detector:
    """Grid search for new people over the floor of a calibrated room.

    Args:
        calibration: the room; only its cameras (any subset) and floor/entry zones are used.
        config: search parameters.
        shape: body profile used for the hypotheses (sizes are overridden per hypothesis).
        beside_radius: metres; within this distance of a track a detection may be the
            track's own person (the association's ``relocate_radius``); there the search
            along lines of sight takes only places no more hidden by tracks than the
            window's best (:meth:`_comparable`). Default: ``exclusion_radius``.
    """

    def __init__(self, calibration: RoomCalibration, config: DetectorConfig | None = None, *,
                 shape: BodyShape | None = None, beside_radius: float | None = None) -> None:
        self.calibration = calibration
        self.config = cfg = config or DetectorConfig()
        self.beside_radius = cfg.exclusion_radius if beside_radius is None \
            else float(beside_radius)
        self.shape = shape or BodyShape(height=cfg.coarse_height, width=cfg.coarse_width)
        self.ceiling = {n: is_ceiling(c) for n, c in calibration.cameras.items()}
        zones = list(calibration.entry_zones)
        if cfg.zones == 'floor' or not zones:
            zones = [calibration.floor] + zones
        self.zones = zones
        xy = _grid(zones, cfg.coarse_spacing)
        poses = [0.0, 1.0] if cfg.sitting else [0.0]
        self.coarse_xy = np.concatenate([xy] * len(poses))
        self.coarse_states = np.concatenate([_states(xy, 0.0, p) for p in poses])
        self._coarse = {n: rasterize(c, self.coarse_states, self.shape,
                                     heights=np.full(len(self.coarse_states), cfg.coarse_height),
                                     widths=np.full(len(self.coarse_states), cfg.coarse_width))
                        for n, c in calibration.cameras.items()}
        # hypotheses whose weakest side camera may be excused from the veto (entry zones)
        self._coarse_in_entry = self._in_entry(self.coarse_xy)
        self._candidates: list[Detection] = []
        self.last_timing: dict[str, float] = {}

    # -- scoring --------------------------------------------------------------------------
    def _min_area(self, camera: Camera) -> float:
        return self.config.min_area * camera.width * camera.height / (320.0 * 240.0)

    def _view_terms(self, name: str, ev: FrameEvidence, sil, *, full: bool,
                    context=None, ctx_index: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-hypothesis (log response, seeing flag, coverage, hidden flag) of one camera:
        hidden where the silhouette is in the image (``min_area`` pixels) but mostly
        covered by tracks (less than ``min_known`` of it known), unless what the camera
        does see of it (``min_area`` pixels or more) is background (coverage below
        ``veto_coverage``): there it sees the place empty."""
        cfg = self.config
        cam = self.calibration.cameras[name]
        fg_n, kn_n, area = ev.integral.counts(sil)
        cov = np.where(kn_n > 0, fg_n / np.maximum(kn_n, 1.0), 0.0)
        known = np.where(area > 0, kn_n / np.maximum(area, 1.0), 0.0)
        min_area = self._min_area(cam)
        sees = (kn_n >= min_area) & (known >= cfg.min_known)
        hidden = (area >= min_area) & ~sees & ~((kn_n >= min_area) & (cov < cfg.veto_coverage))
        resp = cfg.w_coverage * np.log(np.maximum(cov, cfg.coverage_floor) / cfg.coverage_ref)
        if context is not None:
            # foreground around the hypothesis (a larger standing body at the same place)
            # that the hypothesis leaves unexplained: penalises too small / sitting
            # hypotheses inside a standing person's blob
            cf, ck, _ = ev.integral.counts(context)
            extra_fg = np.maximum(cf[ctx_index] - fg_n, 0.0)
            extra_kn = np.maximum(ck[ctx_index] - kn_n, 1.0)
            empty = 1.0 - np.minimum(extra_fg / extra_kn, 1.0)
            resp = resp + cfg.w_context * np.log(
                np.maximum(empty, cfg.coverage_floor) / cfg.coverage_ref)
        if full and not self.ceiling[name]:
            con, _ = contour_loglik_spans(ev.edges, sil, _max_span_width(sil))
            resp = resp + cfg.w_contour * (con - cfg.contour_ref)
            sym = colour_symmetry(ev.image, sil, bins=ev.bins)
            resp = resp + cfg.w_symmetry * np.where(np.isfinite(sym),
                                                    cfg.symmetry_ref - sym, 0.0)
        return np.where(sees, resp, 0.0), sees, np.where(sees, cov, np.nan), hidden

    def _enough_views(self, views: np.ndarray, hidden: np.ndarray) -> np.ndarray:
        """(N,) bool: ``min_views`` cameras see a hypothesis, a camera in which tracked
        people hide it counting towards them (it would see the place; not seen is not
        absent) as long as one camera sees it."""
        return (views >= 1) & (views + hidden >= self.config.min_views)

    def _in_entry(self, xy: np.ndarray) -> np.ndarray:
        """(N,) hypotheses in an entry zone, all False unless ``excuse_weakest``."""
        if not self.config.excuse_weakest:
            return np.zeros(len(xy), bool)
        return self.calibration.in_entry_zone(xy)

    def _excusable(self, xy: np.ndarray, in_entry: np.ndarray,
                   track_xy: np.ndarray | None) -> np.ndarray:
        """(N,) hypotheses whose weakest side camera may be excused from the veto: inside
        an entry zone (``in_entry``) and farther than ``excuse_radius`` from every track."""
        if track_xy is None or not len(track_xy) or not in_entry.any():
            return in_entry
        d = np.linalg.norm(xy[:, None, :] - np.asarray(track_xy)[None], axis=2)
        return in_entry & (d.min(axis=1) > self.config.excuse_radius)

    def _score(self, evidence: Mapping[str, FrameEvidence], states: np.ndarray,
               heights: np.ndarray, widths: np.ndarray, *, full: bool,
               track_xy: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Combined log response (N,), seeing cameras (N,), coverage (C, N) of hypotheses."""
        cfg = self.config
        n = states.shape[0]
        total = np.zeros(n)
        views = np.zeros(n, np.int64)
        hidden = np.zeros(n, np.int64)
        covs, side = [], []
        key = np.round(states[:, [X, Y]] / 1e-3).astype(np.int64)
        _, first, ctx_index = np.unique(key, axis=0, return_index=True, return_inverse=True)
        ctx_states = states[first].copy()
        ctx_states[:, SIT] = 0.0
        ctx_states[:, THETA] = 0.0
        m = len(ctx_states)
        both_states = np.concatenate([states, ctx_states])
        both_heights = np.concatenate([np.broadcast_to(heights, (n,)),
                                       np.full(m, cfg.context_height)])
        both_widths = np.concatenate([np.broadcast_to(widths, (n,)),
                                      np.full(m, cfg.context_width)])
        for name, ev in evidence.items():
            if name not in self.calibration.cameras:
                continue
            # the hypotheses and their context bodies in one rasterisation
            both = rasterize(self.calibration.cameras[name], both_states, self.shape,
                             heights=both_heights, widths=both_widths)
            sil, context = both.select(0, n), both.select(n, n + m)
            resp, sees, cov, hid = self._view_terms(name, ev, sil, full=full,
                                                    context=context,
                                                    ctx_index=ctx_index.ravel())
            total += resp
            views += sees
            hidden += hid
            covs.append(cov)
            side.append(not self.ceiling[name])
        covs = np.asarray(covs).reshape(len(covs), n)
        xy = states[:, [X, Y]]
        vetoed, _ = _vetoes(covs, np.asarray(side, bool), cfg.veto_coverage,
                            self._excusable(xy, self._in_entry(xy), track_xy),
                            cfg.min_views + 1)
        total = np.where(self._enough_views(views, hidden) & ~vetoed, total, -np.inf)
        return total, views, covs

    def coarse(self, evidence: Mapping[str, FrameEvidence], *,
               track_xy: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Coarse level: (M,) log coverage response and (M,) mean coverage of the grid."""
        cfg = self.config
        m = len(self.coarse_states)
        total = np.zeros(m)
        views = np.zeros(m, np.int64)
        hidden = np.zeros(m, np.int64)
        covs, side = [], []
        for name, ev in evidence.items():
            if name not in self._coarse:
                continue
            resp, sees, cov, hid = self._view_terms(name, ev, self._coarse[name], full=False)
            total += resp
            views += sees
            hidden += hid
            covs.append(cov)
            side.append(not self.ceiling[name])
        covs = np.asarray(covs).reshape(len(covs), m)
        excusable = self._excusable(self.coarse_xy, self._coarse_in_entry, track_xy)
        vetoed, counted = _vetoes(covs, np.asarray(side, bool), cfg.veto_coverage,
                                  excusable, cfg.min_views + 1)
        mean_cov = np.where(counted, covs, 0.0).sum(axis=0) / np.maximum(counted.sum(axis=0), 1)
        ok = self._enough_views(views, hidden) & ~vetoed & (mean_cov >= cfg.coarse_coverage)
        if track_xy is not None and len(track_xy):
            d = np.linalg.norm(self.coarse_xy[:, None, :] - np.asarray(track_xy)[None], axis=2)
            ok &= d.min(axis=1) > cfg.exclusion_radius
        return np.where(ok, total, -np.inf), mean_cov

    def detect(self, evidence: Mapping[str, FrameEvidence], *,
               track_xy: np.ndarray | None = None) -> list[Detection]:
        """Single-frame detections (no confirmation), best first, NMS applied."""
        cfg = self.config
        track_xy = np.zeros((0, 2)) if track_xy is None else np.asarray(track_xy, float)
        score, _ = self.coarse(evidence, track_xy=track_xy)
        good = np.flatnonzero(np.isfinite(score))
        if good.size == 0:
            return []
        picks = good[_nms(self.coarse_xy[good], score[good], cfg.coarse_spacing * 1.5,
                          len(good))]
        if self._candidates:
            # a fixed budget of refinements per frame; neighbourhoods of the candidates
            # being confirmed go first so that a confirmation is not starved
            pend = np.array([c.xy for c in self._candidates])
            d = np.linalg.norm(self.coarse_xy[picks][:, None] - pend[None], axis=2).min(axis=1)
            picks = picks[np.argsort(d > cfg.confirm_radius + cfg.fine_radius, kind='stable')]
        picks = picks[:cfg.max_candidates]
        found: list[Detection] = []
        for p in picks:
            det = self._refine(evidence, self.coarse_xy[p], track_xy)
            if det is not None and det.score >= cfg.threshold:
                found.append(det)
        if not found:
            return []
        xy = np.array([d.xy for d in found])
        keep = _nms(xy, np.array([d.score for d in found]), cfg.nms_radius, len(found))
        return [found[i] for i in keep]

    def detect_at(self, evidence: Mapping[str, FrameEvidence], places: np.ndarray, *,
                  track_xy: np.ndarray | None = None) -> list[Detection]:
        """Detections at given floor places (K, 2), metres, in one frame: each refined
        within ``fine_radius`` of its place (:meth:`_refine`), kept when it scores at least
        ``threshold``, then ``nms_radius`` apart (best first). No confirmation over frames:
        the places come with their own evidence over several frames (the bootstrap's
        people cue, :class:`~.people.PeopleCue`)."""
        cfg = self.config
        track_xy = np.zeros((0, 2)) if track_xy is None \
            else np.asarray(track_xy, np.float64).reshape(-1, 2)
        found = []
        for place in np.asarray(places, np.float64).reshape(-1, 2):
            det = self._refine(evidence, place, track_xy)
            if det is not None and det.score >= cfg.threshold:
                det.frames = cfg.confirm_frames
                found.append(det)
        if not found:
            return []
        keep = _nms(np.array([d.xy for d in found]), np.array([d.score for d in found]),
                    cfg.nms_radius, len(found))
        return [found[i] for i in keep]

    def _refine(self, evidence: Mapping[str, FrameEvidence], centre: np.ndarray,
                track_xy: np.ndarray, *, standing: bool = False) -> Detection | None:
        """The best fine hypothesis within ``fine_radius`` of ``centre`` (position and pose,
        then size and orientation, then position again); ``standing``: standing bodies
        only. None when no hypothesis there is scored."""
        cfg = self.config
        r = cfg.fine_radius
        off = np.arange(-r, r + 1e-9, cfg.fine_spacing)
        gx, gy = np.meshgrid(off, off)
        xy = self._admissible(centre + np.stack([gx.ravel(), gy.ravel()], axis=1), track_xy)
        if xy.size == 0:
            return None
        # step 1: position and pose with the mean size
        poses = [0.0, 1.0] if cfg.sitting and not standing else [0.0]
        h0 = float(np.median(cfg.heights))
        w0 = float(np.median(cfg.widths))
        states = np.concatenate([_states(xy, 0.0, p) for p in poses])
        n = len(states)
        score, _, _ = self._score(evidence, states, np.full(n, h0), np.full(n, w0), full=True,
                                  track_xy=track_xy)
        best = int(np.argmax(score))
        if not np.isfinite(score[best]):
            return None
        if cfg.depth_range > 0:
            # step 1b: the depth along each camera's line of sight through the best place
            ray = self._sight_lines(states[best, [X, Y]], track_xy)
            if len(ray):
                rs = np.concatenate([_states(ray, 0.0, p) for p in poses])
                k = len(rs)
                rscore, _, _ = self._score(evidence, rs, np.full(k, h0), np.full(k, w0),
                                           full=True, track_xy=track_xy)
                rscore[~self._comparable(evidence, states[best], rs, track_xy, h0, w0)] = -np.inf
                rb = int(np.argmax(rscore))
                if rscore[rb] > score[best]:
                    states, score, best = rs, rscore, rb
        # step 2: size and orientation at the best position, then the position at half
        # the fine spacing with the best size (separately: 24 + 9 hypotheses, not 216)
        bx = states[best, [X, Y]]
        H, W, O = (a.ravel() for a in np.meshgrid(np.asarray(cfg.heights),
                                                   np.asarray(cfg.widths),
                                                   np.asarray(cfg.orientations),
                                                   indexing='ij'))
        states2 = _states(np.repeat(bx[None], len(H), axis=0), O, states[best, SIT])
        score2, _, _ = self._score(evidence, states2, H, W, full=True, track_xy=track_xy)
        b = int(np.argmax(score2))
        if not np.isfinite(score2[b]):
            return None
        d = np.array([-cfg.fine_spacing, 0.0, cfg.fine_spacing]) * 0.5
        sx, sy = np.meshgrid(d, d)
        pos = bx + np.stack([sx.ravel(), sy.ravel()], axis=1)
        H, W = np.full(len(pos), H[b]), np.full(len(pos), W[b])
        states2 = _states(pos, O[b], states[best, SIT])
        score2, _, covs = self._score(evidence, states2, H, W, full=True, track_xy=track_xy)
        b = int(np.argmax(score2))
        if not np.isfinite(score2[b]):
            return None
        names = [nm for nm in evidence if nm in self.calibration.cameras]
        coverage = {nm: float(covs[k, b]) for k, nm in enumerate(names)
                    if np.isfinite(covs[k, b])}
        # recent motion inside the silhouette, in the side cameras that see it (a top-down
        # camera sees little of a person's motion near the image border)
        motion = []
        side = [nm for nm in coverage if not self.ceiling[nm]] or list(coverage)
        for nm in side:
            mi = evidence[nm].motion_integral
            if mi is not None:
                sil = rasterize(self.calibration.cameras[nm], states2[b:b + 1], self.shape,
                                heights=H[b:b + 1], widths=W[b:b + 1])
                motion.append(float(mi.coverage(sil)[0][0]))
        return Detection(state=states2[b].copy(), height=float(H[b]), width=float(W[b]),
                         score=float(score2[b]), coverage=coverage,
                         motion=min(motion) if motion else float('inf'))

    def _comparable(self, evidence: Mapping[str, FrameEvidence], best: np.ndarray,
                    states: np.ndarray, track_xy: np.ndarray, height: float, width: float
                    ) -> np.ndarray:
        """(N,) bool: hypotheses ``states`` whose scores compare with that of ``best``
        (a state) on the same evidence: farther than ``beside_radius`` from every track,
        or in no camera more of their silhouette (``height``, ``width``, metres) covered
        by tracks than of ``best``'s. The coverage of a silhouette is measured on the part
        no track covers, so beside a track - whose person the hypothesis may be - a place
        that hides its misfit behind the track would score as if it fitted; a track
        farther away covers a part of a place because it stands between it and the
        camera."""
        if not len(track_xy):
            return np.ones(len(states), bool)
        d = np.linalg.norm(states[:, None, [X, Y]] - track_xy[None], axis=2).min(axis=1)
        far = d > self.beside_radius
        if far.all():
            return far
        open_ = np.ones(len(states), bool)      # no more covered than best in any camera
        both = np.concatenate([best[None], states])
        for name, ev in evidence.items():
            if name not in self.calibration.cameras or ev.tracks is None:
                continue
            sil = rasterize(self.calibration.cameras[name], both, self.shape,
                            heights=np.full(len(both), height),
                            widths=np.full(len(both), width))
            _, known, area = ev.integral.counts(sil)
            frac = np.where(area > 0, known / np.maximum(area, 1.0), 1.0)
            open_ &= frac[1:] >= frac[0]
        return far | open_

    def _admissible(self, xy: np.ndarray, track_xy: np.ndarray) -> np.ndarray:
        """The floor places (K, 2) inside the search bounds and farther than
        ``exclusion_radius`` from every track."""
        x0, y0, x1, y1 = self._bounds()
        xy = xy[(xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)]
        if len(track_xy) and len(xy):
            d = np.linalg.norm(xy[:, None] - track_xy[None], axis=2).min(axis=1)
            xy = xy[d > self.config.exclusion_radius]
        return xy

    def _sight_lines(self, place: np.ndarray, track_xy: np.ndarray) -> np.ndarray:
        """(K, 2) floor places on the lines of sight of the side cameras through ``place``
        (the floor line from the camera's foot point through it): farther than
        ``fine_radius`` (the window's reach) and within ``depth_range`` of it,
        ``fine_spacing`` apart, admissible (:meth:`_admissible`). Along such a line
        the camera's view of a body changes little (its bearing stays, its size and foot
        row change slowly), so the depth is what the other views' evidence decides, and
        their best agreement may lie farther than the window around a coarse point
        reaches."""
        cfg = self.config
        t = np.arange(-cfg.depth_range, cfg.depth_range + 1e-9, cfg.fine_spacing)
        t = t[np.abs(t) > cfg.fine_radius + 1e-9]   # nearer: within the window's reach
        lines = []
        for name, cam in self.calibration.cameras.items():
            if self.ceiling[name]:
                continue                # looking down, it sees the floor place itself
            u = np.asarray(place, np.float64) - cam.center[:2]
            norm = float(np.hypot(*u))
            if norm < 1e-6:
                continue
            lines.append(place + t[:, None] * (u / norm)[None])
        if not lines:
            return np.zeros((0, 2))
        return self._admissible(np.concatenate(lines), track_xy)

    def _bounds(self) -> tuple[float, float, float, float]:
        z = np.asarray(self.zones, dtype=np.float64)
        return (float(z[:, 0].min()), float(z[:, 1].min()), float(z[:, 2].max()),
                float(z[:, 3].max()))

    # -- over time ------------------------------------------------------------------------
    def step(self, evidence: Mapping[str, FrameEvidence], *,
             track_xy: np.ndarray | None = None, stamp_ns: int | None = None,
             still: bool = False) -> list[Detection]:
        """Detections confirmed in ``confirm_frames`` consecutive frames (then forgotten):
        those with recent motion (``min_motion``), and with ``still`` those without too
        (``Detection.motion`` below ``min_motion``; the caller must tell them from ghosts).

        With ``stamp_ns`` the positions of the confirming frames give the velocity of a
        confirmed detection (state ``vx, vy``) and, when faster than ``min_speed``, its
        body orientation (walking direction), which annotates the acquired key views; such
        a walking detection is standing (a sitting one is refined again on this frame's
        evidence with standing bodies only).
        """
        cfg = self.config
        found = self.detect(evidence, track_xy=track_xy)
        confirmed: list[Detection] = []
        survivors: list[Detection] = []
        used = set()
        for det in found:
            match = None
            for k, cand in enumerate(self._candidates):
                if k in used:
                    continue
                if np.linalg.norm(cand.xy - det.xy) <= cfg.confirm_radius:
                    match = k
                    break
            det.frames = 1 if match is None else self._candidates[match].frames + 1
            det.history = [] if match is None else list(self._candidates[match].history)
            if stamp_ns is not None:
                det.history.append((int(stamp_ns), float(det.xy[0]), float(det.xy[1])))
            if match is not None:
                used.add(match)
                det.motion = max(det.motion, self._candidates[match].motion)
            # a ghost (background change left by someone who was there while the model was
            # bootstrapped) never moves; people who appear do (``still``: the caller
            # proves a still one present by other evidence)
            if det.frames >= cfg.confirm_frames and (still or det.motion >= cfg.min_motion):
                self._velocity(det)
                if det.state[SIT] >= 0.5 and self._walking(det):
                    det = self._standing(evidence, det, track_xy)
                confirmed.append(det)
            else:
                survivors.append(det)
        self._candidates = survivors
        return confirmed

    def _velocity(self, det: Detection) -> None:
        """Least-squares floor velocity over the confirming frames -> state vx, vy, theta."""
        v = fitted_velocity(det.history)
        if v is None:
            return
        speed = float(np.hypot(*v))
        if speed > self.config.max_speed:
            # faster than anybody walks: the detection jumped between places (a neighbour,
            # the fringe of a group), not a walk; no velocity rather than one in the
            # direction of the jump
            return
        det.state[[VX, VY]] = v
        if speed >= self.config.min_speed:
            det.state[THETA] = float(np.arctan2(v[1], v[0]))

    def _walking(self, det: Detection) -> bool:
        """Whether the fitted velocity of a confirmed detection is a walk (``min_speed``
        to ``max_speed``)."""
        v = fitted_velocity(det.history)
        return v is not None and \
            self.config.min_speed <= float(np.hypot(*v)) <= self.config.max_speed

    def _standing(self, evidence: Mapping[str, FrameEvidence], det: Detection,
                  track_xy: np.ndarray | None) -> Detection:
        """A walking detection whose best hypothesis sits, refined again at its place
        with standing bodies only (nobody walks seated: a sitting body with its thighs
        forward fits a walker's spread legs, and the tallest sitting body the whole
        silhouette); its velocity, orientation and history kept. The detection itself if no
        standing hypothesis there is scored."""
        track_xy = np.zeros((0, 2)) if track_xy is None else np.asarray(track_xy, np.float64)
        up = self._refine(evidence, det.xy, track_xy.reshape(-1, 2), standing=True)
        if up is None:
            return det
        up.state[[VX, VY, THETA]] = det.state[[VX, VY, THETA]]
        up.frames, up.history, up.motion = det.frames, det.history, det.motion
        return up

    def requeue(self, detection: Detection) -> None:
        """Keep a confirmed detection that could not be acquired: it is emitted again as
        soon as it is found once more."""
        detection.frames = self.config.confirm_frames - 1
        self._candidates.append(detection)

    def reset(self) -> None:
        """Forget unconfirmed candidates."""
        self._candidates = []
