"""Measurement model: the HJS, separable and joint likelihoods (000 §IV-B, Algorithm 1).

Per frame, :meth:`MeasurementModel.set_images` takes the camera images (each is quantised
once, by the worker thread that first evaluates its camera); the three evaluations then
work on row-span silhouettes (:mod:`mbtrack_ros.core.shape`) and part histograms
(:mod:`mbtrack_ros.core.appearance`) with numba kernels (:mod:`mbtrack_ros.core._kernels`):

* :meth:`~MeasurementModel.hjs`: all K*N particles of a camera are visited from near to
  far; occlusion maps w* (000 Eq. 34) and occlusion evidence (Eq. 36-40) are accumulated
  incrementally in per-target image buffers. Cost O(K^2 N S), linear in K when the targets'
  particle clouds do not overlap in the image (DBN shortcut, 000 §IV-B.3).
* :meth:`~MeasurementModel.separable`: each target alone (w* = 1): 003 Eq. 3.
* :meth:`~MeasurementModel.joint`: joint samples rendered with a per-pixel depth order
  (000 Eq. 20) and scored with Eq. 26 on binary visibility masks.

For ``hjs`` and ``separable`` the main thread stacks the targets once; each camera is then
one call of :func:`_kernels.update_camera` (quantising, silhouettes, key views, the update
and the camera's log-likelihoods), which holds no GIL, so the camera threads run in
parallel without waiting for each other's Python.

Log-likelihoods are ``-D^2 / (2 sigma^2)`` (000 Eq. 19) summed over cameras. Where a camera
sees little of a target it says nothing about it (``MeasurementModel._seen_by``): when the
target's silhouettes are on average (prior-weighted) less than ``min_inside_share`` inside
the image, or when it hides the target behind nearer ones (the prior-expected visible
fraction sum(w*) / area is below ``min_visible_share``), the camera adds 0 to all its
particles; otherwise a particle the camera sees fewer than ``min_visible_pixels`` of gets
the prior-weighted mean of the target's seen particles there. An unseen silhouette would
otherwise score 0, the best score any camera gives: a track beside a camera was drawn into
the part of the floor the camera does not see, away from the places it sees in part.
A camera that sees a few pixels of a hidden target still scores its
places by the occlusion penalty and the background term of the targets in front (Eq. 26,
Eq. 40), which differ by several nats between places it cannot tell apart: that pulled
the track of a person no camera saw into the crowd. With exits in the calibration (rectangles
beyond a door), a camera on the door's wall cannot see a particle
in the exit once it is level with the camera or beyond (past the wall): that particle gets
the mean of its target's other particles in that camera
(``MeasurementModel._without_hidden``), else the wall would pull every track back from the
doorway. The exit's strip between the floor's edge and the wall is in front of the
camera and scored as usual.

With automatic detection the frame's foreground masks come too
(:meth:`MeasurementModel.set_foreground`): each particle then gains ``k f`` per camera
(``k``: ``LikelihoodConfig.coverage_gain``), ``f`` its silhouette's foreground counted
pixel by pixel on the spans the camera's kernel rasterised (:func:`explained_cover`: each
pixel adds ``F_u - f_s``, per the target's mean silhouette area), so that a smaller
silhouette inside a person's blob (farther along the line of sight, sitting, partly off
the image) does not score as the person's own.

How w* enters the foreground term (000 Eq. 33): the image histogram of a part is
accumulated with per-pixel weight w*(u); the rendered (model) histogram of a part is
uniform over the part's pixels, so weighting it by w* and normalising gives back the
model part histogram itself: the model side is fixed per part and only the image side and
the part masses alpha_part = sum w* change.
"""
from __future__ import annotations

import itertools
import os
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np

from mbtrack_ros.core import _kernels
from mbtrack_ros.core.appearance import (
    PersonModel, key_view_stack, quantize, view_weights)
from mbtrack_ros.core.camera import Camera, RoomCalibration
from mbtrack_ros.core.detection.features import ForegroundIntegral, Spans
from mbtrack_ros.core.shape import BodyShape, Silhouettes, rasterize
from mbtrack_ros.core.state import STATE_DIM, VX, VY, X, Y

__all__ = ['CameraRequest', 'CameraScores', 'HJSDebug', 'LikelihoodConfig', 'LikelihoodError',
           'LikelihoodResult', 'MeasurementModel', 'Scorer', 'camera_constants',
           'explained_cover', 'score_camera']


class LikelihoodError(ValueError):
    """Bad input to the measurement model (image size, particle arrays, models)."""


@dataclass(frozen=True)
class LikelihoodConfig:
    """Parameters of the likelihood.

    Attributes:
        sigma: width of 000 Eq. 19 / 003 Eq. 3.
        d_occ: occlusion penalty of 000 Eq. 26 (000 §VI-B uses sigma 0.1, d_occ 0.15).
        min_visible_pixels: a camera seeing fewer pixels of a silhouette does not see it
            (the particle gets its target's mean there, module docstring).
        min_inside_share: a camera seeing less of a target's silhouettes inside its image
            (prior-weighted mean of the share of each inside) says nothing about the target
            (adds 0 to each of its particles; 0: never).
        min_visible_share: a camera in which a target's prior-expected visible fraction
            (sum(w*) / silhouette area, ``LikelihoodResult.visible_fraction``) is below this
            says nothing about the target: it is hidden there (0: never; in the separable
            update w* = 1 and the fraction is the share inside the image).
        subsample: use every k-th image row of the silhouettes (speed option).
        threads: cameras evaluated in parallel threads (0: one per CPU core, 1: serial).
        coverage_gain: ``k`` of the foreground-coverage term ``k f`` (nats per camera;
            ``f`` the foreground of a particle's silhouette counted per pixel, 1 for a
            silhouette of its target's mean area all on foreground, :func:`explained_cover`)
            that the frame's foreground masks add to the log-likelihood
            (:meth:`MeasurementModel.set_foreground`, module docstring); 0: colour alone.
            Larger holds tracks on the foreground more firmly (better MOTP, fewer
            identity switches) at the cost of the colour evidence's say.
    """

    sigma: float = 0.12
    d_occ: float = 0.15
    min_visible_pixels: int = 20
    min_inside_share: float = 0.5
    min_visible_share: float = 0.1
    subsample: int = 1
    threads: int = 0
    coverage_gain: float = 2.0

    def __post_init__(self) -> None:
        if not (self.sigma > 0 and np.isfinite(self.sigma)):
            raise LikelihoodError(f'sigma must be positive, got {self.sigma}')
        if not (self.d_occ >= 0 and np.isfinite(self.d_occ)):
            raise LikelihoodError(f'd_occ must be >= 0, got {self.d_occ}')
        if not 0 <= self.min_inside_share <= 1:
            raise LikelihoodError(f'min_inside_share must be in [0, 1], got '
                                  f'{self.min_inside_share}')
        if not 0 <= self.min_visible_share <= 1:
            raise LikelihoodError(f'min_visible_share must be in [0, 1], got '
                                  f'{self.min_visible_share}')
        if int(self.subsample) < 1:
            raise LikelihoodError(f'subsample must be >= 1, got {self.subsample}')
        if int(self.threads) < 0:
            raise LikelihoodError(f'threads must be >= 0, got {self.threads}')
        if not (np.isfinite(self.coverage_gain) and self.coverage_gain >= 0):
            raise LikelihoodError(f'coverage_gain must be a finite number >= 0, got '
                                  f'{self.coverage_gain}')


@dataclass
class LikelihoodResult:
    """Output of :meth:`MeasurementModel.hjs` / :meth:`MeasurementModel.separable`.

    Attributes:
        loglik: K arrays (N_k,), log p summed over the cameras.
        visible_fraction: (K, n_cameras) prior-expected visible fraction of each target's
            silhouette (weighted mean over its particles of sum(w*) / unclipped area); 0 for
            cameras without an image this frame.
        timings: seconds of the main thread's preparation (``models``), of the cameras
            summed (``camera``; they may run in parallel) and wall-clock ``total``.
    """

    loglik: list[np.ndarray]
    visible_fraction: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)


@dataclass
class HJSDebug:
    """Per-particle internals of the HJS update in one camera (for tests and debugging).

    Particles are the K targets' particles concatenated in target order.
    """

    silhouettes: Silhouettes
    target: np.ndarray      # (P,) int64 target index
    prior: np.ndarray       # (P,) normalised prior weights
    fc: np.ndarray          # (P,) foreground terms (000 Eq. 33 with Eq. 26)
    bc: np.ndarray          # (P,) background terms (000 Eq. 40)
    visible: np.ndarray     # (P,) sum of w* over the silhouette
    w_star: np.ndarray      # (P, H, W) float64 occlusion maps w* (0 off the silhouette)


def _normalised_priors(weights: np.ndarray, n: int, k: int, log_weights: bool) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    if w.shape != (n,):
        raise LikelihoodError(f'target {k}: {w.size} weights for {n} particles')
    if n == 0:
        return w
    if log_weights:
        w = np.where(np.isnan(w), -np.inf, w)
        top = np.max(w) if w.size else -np.inf
        if not np.isfinite(top):
            raise LikelihoodError(f'target {k}: all log-weights are -inf/NaN')
        w = np.exp(w - top)
    else:
        if not np.isfinite(w).all() or (w < 0).any():
            raise LikelihoodError(f'target {k}: weights must be finite and >= 0')
    total = w.sum()
    if not total > 0:
        raise LikelihoodError(f'target {k}: weights sum to zero')
    return w / total


def _normalised_prior_list(weights: Sequence[np.ndarray], parts: Sequence[np.ndarray],
                           log_weights: bool) -> list[np.ndarray]:
    """:func:`_normalised_priors` of every target; linear weights of targets with as many
    particles are checked and normalised in one pass (numpy sums each row on its own: the
    same numbers), any failure is reported by the target-by-target path."""
    sizes = {p.shape[0] for p in parts}
    if not log_weights and len(sizes) == 1 and 0 not in sizes:
        w = np.array([np.asarray(x, dtype=np.float64).reshape(-1) for x in weights]) \
            if all(np.size(x) == parts[0].shape[0] for x in weights) else None
        if w is not None and np.isfinite(w).all() and not (w < 0).any():
            total = w.sum(axis=1)
            if (total > 0).all():
                return list(w / total[:, None])
    return [_normalised_priors(w, p.shape[0], k, log_weights)
            for k, (w, p) in enumerate(zip(weights, parts))]


_CPUS = os.cpu_count() or 1   # threads of _map by default (os.cpu_count reads /sys: once)
_NO_BUFFER = np.zeros((1, 1, 1))   # workspace argument of the separable evaluation (unused)
_NO_BINS = np.zeros((0, 0), np.int16)   # bins argument of a camera not quantised yet
_BODY = BodyShape()
#: the body profile the likelihood kernels rasterise (``BodyShape``'s fractions, half
#: widths, segment parts and hip fraction)
_BODY_PROFILE = (_BODY.fractions, _BODY.half_widths, _BODY.segment_parts,
                 float(_BODY.hip_fraction))


def _with_target_mean(values: np.ndarray, known: np.ndarray, target: np.ndarray,
                      prior: np.ndarray, n_targets: int) -> np.ndarray:
    """``values`` (P,) where ``known``, elsewhere the prior-weighted mean of the known values
    of the particle's target (0 for a target with none): what a camera that says nothing
    about a particle leaves it, relative to its target's other particles."""
    mass = np.bincount(target[known], weights=prior[known], minlength=n_targets)
    total = np.bincount(target[known], weights=prior[known] * values[known],
                        minlength=n_targets)
    mean = np.divide(total, mass, out=np.zeros(n_targets), where=mass > 0)
    return np.where(known, values, mean[target])


def explained_cover(cover: np.ndarray, area: np.ndarray, target: np.ndarray,
                    prior: np.ndarray, neutral: float) -> np.ndarray:
    """Foreground coverage in the units of the coverage term, counted per pixel.

    Each pixel a silhouette covers in the image is a witness with log-ratio ``F_u - f_s``
    ("a person here" against "background here", 000 Eq. 20 with a binary observation:
    ``F_u`` 1 on foreground, ``f_s`` = ``neutral`` the coverage at which the evidence is
    neutral, the existence process's ``min_coverage``); the silhouette's evidence is their
    sum, ``area (cover - f_s)``, per reference area: the prior-weighted mean silhouette
    area ``a_k`` of the particle's target in this camera. Returned as the coverage a
    silhouette of the reference area would need for the same sum, ``f_s + (cover - f_s)
    area / a_k``, so that the term ``k f`` keeps its scale.

    A plain foreground fraction favours any silhouette lying inside a person's blob: a
    hypothesis farther along a camera's line of sight (smaller), one partly off the image
    (the pixels outside count nothing) or a sitting one all cover only foreground. Summed
    over pixels the foreground a hypothesis leaves unexplained weighs against it, and so
    does the background a nearer, larger one covers. (On background alone the sum favours
    the smaller silhouette, which a person farther away would have: a track that lost its
    person drifts away from the cameras rather than stay put.)

    Args:
        cover: (P,) foreground fraction of each silhouette's pixels in the image.
        area: (P,) those pixels; 0 for a silhouette outside the image.
        target, prior: (P,) target index and prior weight of each particle.
        neutral: ``f_s`` in [0, 1].
    """
    n_targets = int(target.max()) + 1 if len(target) else 0
    seen = area > 0
    mass = np.bincount(target, weights=prior * seen, minlength=n_targets)
    total = np.bincount(target, weights=prior * area, minlength=n_targets)
    ref = np.divide(total, mass, out=np.ones(n_targets), where=mass > 0)  # > 0 where seen
    return neutral + (cover - neutral) * area / ref[target]


@dataclass
class CameraRequest:
    """One camera's share of :meth:`MeasurementModel.hjs` / ``separable`` for a frame set:
    what a camera stage needs to score the particles in its own image
    (:func:`score_camera`; a fusion node sends it to each camera's
    :meth:`~mbtrack_ros.core.detection.camera_stage.CameraStage.score`).

    Attributes:
        states: (P, 6) the K targets' particles stacked, at the camera's capture time.
        target: (P,) int64 target index of each particle.
        prior: (P,) normalised prior weights (each target's sum to 1).
        heights, widths: (P,) body size of each particle's target, metres.
        chair: hip height when sitting, metres.
        view_angles: (K, V) key-view angles of the targets, radians (zero padded).
        n_views: (K,) int64 key views of each target.
        key: (K, V, 1536) key-view histograms (``appearance.key_view_stack``), or with
            ``key_targets`` only those targets' (M, V, 1536).
        separable: each target alone, w* = 1 (003 Eq. 3), else HJS (000 Algorithm 1).
        two_sigma_sq: 2 sigma^2 of 000 Eq. 19.
        d_occ: occlusion penalty of 000 Eq. 26.
        row_step: the silhouettes' row sampling (``LikelihoodConfig.subsample``).
        min_visible: fewer silhouette pixels leave a particle neutral in the camera
            (``LikelihoodConfig.min_visible_pixels``).
        coverage: count each silhouette's foreground coverage
            (:meth:`MeasurementModel.set_foreground`).
        neutral: the coverage an undecided pixel counts as.
        versions: (K,) int64 version of each target's key views (a new one whenever they
            change) or None; with it a camera stage keeps the key views it was sent and
            ``key_targets`` (M,) int64 names the targets whose views ``key`` holds (the
            others' came with earlier requests: the key views are most of a request's
            bytes, and only a changed model's are sent again).
    """

    states: np.ndarray
    target: np.ndarray
    prior: np.ndarray
    heights: np.ndarray
    widths: np.ndarray
    chair: float
    view_angles: np.ndarray
    n_views: np.ndarray
    key: np.ndarray
    separable: bool
    two_sigma_sq: float
    d_occ: float
    row_step: int
    min_visible: int
    coverage: bool = False
    neutral: float = 0.5
    versions: np.ndarray | None = None
    key_targets: np.ndarray | None = None

    @property
    def nbytes(self) -> int:
        """Bytes of its arrays (what a message carrying it needs, about)."""
        return sum(a.nbytes for a in (self.states, self.target, self.prior, self.heights,
                                      self.widths, self.view_angles, self.n_views, self.key,
                                      self.versions, self.key_targets)
                   if a is not None)


@dataclass
class CameraScores:
    """A camera's answer to a :class:`CameraRequest` (the rows of
    :func:`_kernels.update_camera`).

    Attributes:
        loglik: (P,) -(fc + bc) / (2 sigma^2) (000 Eq. 19), 0 where the camera sees fewer
            than ``min_visible`` pixels of the silhouette.
        visible: (K,) prior-weighted mean visible fraction of each target.
        inside: (P,) share of each silhouette inside the image (0 where neutral).
        cover: (P,) foreground coverage of each silhouette with the undecided pixels at
            ``neutral``, counted per pixel (:func:`explained_cover`; NaN outside the image
            or without a coverage term).
    """

    loglik: np.ndarray
    visible: np.ndarray
    inside: np.ndarray
    cover: np.ndarray

    @classmethod
    def empty(cls, particles: int, targets: int) -> CameraScores:
        return cls(np.empty(particles), np.empty(targets), np.empty(particles),
                   np.full(particles, np.nan))

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.loglik, self.visible, self.inside, self.cover))


#: a camera stage scoring for the tracker (:meth:`MeasurementModel.set_scorers`): sends a
#: request, returns the wait for its answer
Scorer = Callable[[CameraRequest], Callable[[], 'CameraScores | None']]


def camera_constants(cam) -> tuple:
    """A :class:`~mbtrack_ros.core.camera.Camera`'s constants as
    :func:`_kernels.update_camera` takes them (``depth_row``, ``projection_parameters``)."""
    return (*cam.depth_row, *cam.projection_parameters)


def score_camera(camera: tuple, image: np.ndarray, bins: np.ndarray,
                 integral: Callable[[], ForegroundIntegral | None], request: CameraRequest,
                 workspaces: _Workspaces, out: CameraScores) -> np.ndarray:
    """Score ``request`` in one camera into ``out`` (000 Algorithm 1 "update" and the
    coverage term, :func:`_kernels.update_camera`): the same call whether the camera is
    one of the tracker's own (:meth:`MeasurementModel.hjs`) or a camera stage's
    (:meth:`~mbtrack_ros.core.detection.camera_stage.CameraStage.score`).

    ``camera``: the camera's constants (:func:`camera_constants`);
    ``image`` (H, W, 3) uint8 and its colour bins (H, W) int16 (empty (0, 0): quantised
    here); ``integral()``: the foreground's row prefix sums, called after the colour
    update (None: no coverage term). Returns the colour bins."""
    r = request
    body = _BODY_PROFILE
    rest = (int(r.row_step), float(r.d_occ), bool(r.separable), float(r.two_sigma_sq),
            int(r.min_visible))

    def run(mfg: np.ndarray, bbg: np.ndarray, wmap: np.ndarray) -> tuple:
        return _kernels.update_camera(
            image, bins, r.states, r.target, r.prior, r.heights, r.widths, float(r.chair),
            *body, r.view_angles, r.n_views, r.key, *camera, *rest, mfg, bbg, wmap,
            out.loglik, out.visible, out.inside)

    if r.separable:                               # no image buffers
        bins, *spans = run(_NO_BUFFER, _NO_BUFFER, _NO_BUFFER)
    else:
        with workspaces.get(image.shape[0], image.shape[1], r.key.shape[0]) as ws:
            bins, *spans = run(*ws)
    fg = integral() if r.coverage else None
    if fg is not None:   # foreground coverage term on the kernel's silhouettes
        cover, known, area = fg.coverage(Spans(*spans))
        cover = known * cover + (1.0 - known) * r.neutral   # set_foreground
        out.cover[:] = np.where(area > 0, explained_cover(cover, area, r.target, r.prior,
                                                          r.neutral), np.nan)
    return bins


class _Workspaces:
    """Reusable image buffers (m_fg, b_bg, w*) of :func:`_kernels.hjs_camera_ws`.

    One set per concurrently evaluated camera: a set is taken for one call and handed back
    afterwards (the kernel leaves m_fg and b_bg zero). A set is grown to the largest image
    and target count seen; a call that fails drops its set, which may not be zero.
    """

    def __init__(self) -> None:
        self._free: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._lock = threading.Lock()

    @contextmanager
    def get(self, height: int, width: int, channels: int
            ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        with self._lock:
            ws = self._free.pop() if self._free else None
        if ws is None or (ws[1].shape[0] < channels or ws[1].shape[1] < height
                          or ws[1].shape[2] < width):
            old = ws[1].shape if ws is not None else (0, 0, 0)
            shape = (max(channels, old[0], 1), max(height, old[1]), max(width, old[2]))
            ws = (np.zeros((2 * shape[0],) + shape[1:]), np.zeros(shape), np.empty(shape))
        yield ws
        with self._lock:
            self._free.append(ws)


class MeasurementModel:
    """Per-frame image preparation and the likelihood evaluations of every filter.

    Args:
        calibration: the room cameras (images must match their sizes).
        config: likelihood parameters.
    """

    JOINT_CHUNK = 8192   # silhouettes rasterised at once by joint() (bounds memory)

    def __init__(self, calibration: RoomCalibration,
                 config: LikelihoodConfig = LikelihoodConfig()) -> None:
        self.calibration = calibration
        self.config = config
        self.camera_names: list[str] = list(calibration.cameras)
        self._images: dict[str, np.ndarray] = {}
        self._bins: dict[str, np.ndarray] = {}
        self._foreground: dict[str, ForegroundIntegral] | None = {}   # set_foreground()
        self._masks_source: Mapping[str, np.ndarray] | Callable[[], Mapping] = {}
        self._undecided_source: Mapping | Callable[[], Mapping] | None = None
        self._neutral = 0.5               # coverage of an undecided pixel (set_foreground)
        self._foreground_lock = threading.Lock()
        self._coverage_gain = 0.0
        self._pool: ThreadPoolExecutor | None = None
        self._pool_size = 0
        self._workspaces = _Workspaces()
        self._camera_cost: dict[str, float] = {}   # seconds of a camera's last HJS update
        self._camera_args: dict[str, tuple] = {}
        # camera name -> the camera stage that scores the particles in it (set_scorers)
        self._scorers: dict[str, Scorer] = {}
        # id of a model's key views -> (them, their version): a version per distinct key views
        self._versions: dict[int, tuple[np.ndarray, int]] = {}
        self._next_version = itertools.count()
        self._sent_versions: dict[str, set[int]] = {}   # camera -> key views it has
        self._offsets: dict[str, float] = {}   # set_capture_offsets()

    # -- images ---------------------------------------------------------------------------
    def set_images(self, images: Mapping[str, np.ndarray]) -> None:
        """Take the frame's images (H, W, 3) uint8 RGB; missing cameras are skipped.

        Raises :class:`LikelihoodError` for unknown cameras or images of the wrong size.
        Each image is quantised once, when its camera is first evaluated (in that camera's
        worker thread).
        """
        checked: dict[str, np.ndarray] = {}
        for name, image in images.items():
            cam = self.calibration.cameras.get(name)
            if cam is None:
                raise LikelihoodError(f'image for unknown camera {name!r}; known: '
                                      f'{", ".join(self.camera_names)}')
            image = np.asarray(image)
            if image.shape != (cam.height, cam.width, 3) or image.dtype != np.uint8:
                raise LikelihoodError(
                    f'{name}: expected ({cam.height}, {cam.width}, 3) uint8 RGB image, got '
                    f'{image.shape} {image.dtype}')
            checked[name] = image
        self._images = checked
        self._bins = {}
        self._offsets = {}
        self._foreground, self._masks_source, self._coverage_gain = {}, {}, 0.0
        self._undecided_source = None

    def set_scorers(self, scorers: Mapping[str, Scorer]) -> None:
        """Cameras whose share of :meth:`hjs` / :meth:`separable` their own stage computes:
        camera name -> a callable that sends the camera's :class:`CameraRequest` and
        returns a callable waiting for the answer: its :class:`CameraScores` (what
        :func:`score_camera` gives on that camera's image and foreground), or None when
        there is none for this frame set (no stage, no frame, too late): the camera is then
        scored here, on the images and masks of :meth:`set_images` and
        :meth:`set_foreground`, with the same result. Every request of a frame set is sent
        before the first answer is awaited. Replaces the previous mapping (empty: every
        camera scored here); kept across frames."""
        for name in scorers:
            if name not in self.calibration.cameras:
                raise LikelihoodError(f'scorer for unknown camera {name!r}')
        self._scorers = dict(scorers)
        self._sent_versions = {}

    def _key_versions(self, models: Sequence[PersonModel]) -> np.ndarray:
        """(K,) int64 version of each model's key views: the same while they stay the same
        array (``PersonModel`` recomputes them when its views change), a new one after."""
        held, out = {}, np.empty(len(models), np.int64)
        for k, m in enumerate(models):
            views = m._completed()
            entry = self._versions.get(id(views))
            if entry is None or entry[0] is not views:
                entry = (views, next(self._next_version))
            held[id(views)] = entry     # holds the array: its id is not reused meanwhile
            out[k] = entry[1]
        self._versions = held
        return out

    @staticmethod
    def _take_scores(name: str, got: CameraScores, rows: CameraScores) -> None:
        """Copy a camera stage's scores into the camera's rows; a reply of the wrong shape
        raises :class:`LikelihoodError`."""
        for field_name in ('loglik', 'visible', 'inside', 'cover'):
            src, dst = np.asarray(getattr(got, field_name)), getattr(rows, field_name)
            if src.shape != dst.shape:
                raise LikelihoodError(f'{name}: camera scores {field_name} have shape '
                                      f'{src.shape}, expected {dst.shape}')
            dst[:] = src

    def set_capture_offsets(self, offsets: Mapping[str, float]) -> None:
        """Capture time of each camera's image relative to the particles' time, seconds
        (<= 0 when the particles are at the latest capture of the frame set; cameras not
        named: 0). Call after :meth:`set_images` (which clears them).

        Unsynchronised cameras: the camera updates of the HJS filter are independent
        factors of the likelihood (000 Eq. 19 summed over cameras), so each can be applied
        at its own capture time. A camera whose image was taken ``dt`` seconds from the
        particles' time evaluates each particle at ``x + v dt`` (the constant-velocity
        part of the dynamics, 000 Eq. 15, over ``dt``; the diffusion over a fraction of a
        frame period is neglected): the particle predicted to that camera's capture time.
        """
        out = {}
        for name, dt in offsets.items():
            if name not in self.calibration.cameras:
                raise LikelihoodError(f'capture offset for unknown camera {name!r}')
            dt = float(dt)
            if not np.isfinite(dt):
                raise LikelihoodError(f'{name}: capture offset must be finite, got {dt}')
            if dt != 0.0:
                out[name] = dt
        self._offsets = out

    def _at_capture(self, camera: str, states: np.ndarray) -> np.ndarray:
        """Particle states (P, 6) moved to ``camera``'s capture time
        (:meth:`set_capture_offsets`): ``x + v dt``; the same array when dt is 0."""
        dt = self._offsets.get(camera, 0.0) if self._offsets else 0.0
        if dt == 0.0:
            return states
        moved = states.copy()
        moved[:, X:Y + 1] += states[:, VX:VY + 1] * dt     # 000 Eq. 15, deterministic part
        return moved

    def set_foreground(self, masks: Mapping[str, np.ndarray]
                       | Callable[[], Mapping[str, np.ndarray]],
                       gain: float | None = None, *,
                       undecided: Mapping[str, np.ndarray | None]
                       | Callable[[], Mapping[str, np.ndarray | None]] | None = None,
                       neutral: float = 0.5) -> None:
        """Take the frame's foreground masks (H, W) bool (003 §4.2) for a coverage term in
        the ``hjs`` and ``separable`` log-likelihoods: ``gain * f(x)`` per camera (``gain``
        None: ``config.coverage_gain``), with ``f`` the particle's foreground coverage
        ``f_c`` counted per pixel (:func:`explained_cover`, ``neutral`` its ``f_s``):
        ``p(f | x) ∝ exp(k f)``, the exponential in the coverage that the existence
        update's evidence uses (:func:`~mbtrack_ros.core.existence.coverage_log_ratio`).
        The colour likelihood alone lets a track whose person stands still drift onto
        background that resembles them.

        ``masks`` may be a callable returning them: it is called once, by the first camera
        thread that has finished its colour update, so masks still being extracted on
        another thread (the tracker's foreground worker) overlap with that update. Call
        after :meth:`set_images` (which clears the masks); cameras without an image or
        mask get no term; ``gain`` 0 disables, and so does a refused call.

        ``undecided`` (a mapping or a callable called right after ``masks``): per camera
        the (H, W) bool pixels whose mask value is a guess rather than an observation
        (None: none), such as the possible people of the online bootstrap, foreground
        where the background is not known yet (:class:`~mbtrack_ros.core.detection
        .background.BackgroundModel`). Each counts as the coverage ``neutral`` in ``f_c``:
        ``f_c = d f_d + (1 - d) neutral``, ``d`` the observed share of the silhouette and
        ``f_d`` its coverage there (the tracker gives the coverage at which the existence
        evidence is neutral, :func:`~mbtrack_ros.core.existence.coverage_log_ratio`). The
        guessed blob then neither holds a track nor repels it: a track placed a little off
        its person at the start follows her rather than stay on the blob, whose pixels it
        would keep covered, hence not yet known, once she has left.
        """
        gain = self.config.coverage_gain if gain is None else gain
        if not (np.isfinite(gain) and gain >= 0):
            raise LikelihoodError(f'coverage gain must be a finite number >= 0, got {gain}')
        if not (np.isfinite(neutral) and 0.0 <= neutral <= 1.0):
            raise LikelihoodError(f'neutral coverage must be in [0, 1], got {neutral}')
        self._foreground, self._masks_source, self._coverage_gain = {}, {}, 0.0
        self._undecided_source, self._neutral = undecided, float(neutral)
        if gain == 0:
            return
        if callable(masks):
            self._foreground, self._masks_source = None, masks
        else:
            self._foreground = self._integrals(masks)   # a bad mask is refused here
        self._coverage_gain = float(gain)

    def _foreground_integrals(self) -> dict[str, ForegroundIntegral]:
        """The row prefix sums of this frame's masks by camera (built once per frame)."""
        with self._foreground_lock:
            if self._foreground is None:
                self._foreground = self._integrals(self._masks_source())
            return self._foreground

    def _undecided_masks(self) -> Mapping[str, np.ndarray | None]:
        """The undecided pixels of :meth:`set_foreground` by camera (fetched after the
        masks, under their lock)."""
        source = self._undecided_source
        if source is None:
            return {}
        return source() if callable(source) else source

    def _integrals(self, masks: Mapping[str, np.ndarray]) -> dict[str, ForegroundIntegral]:
        """Row prefix sums of the masks of the cameras with an image this frame; raises
        :class:`LikelihoodError` for a mask of the wrong size."""
        out: dict[str, ForegroundIntegral] = {}
        undecided = self._undecided_masks() if masks else {}
        for name, mask in masks.items():
            cam = self.calibration.cameras.get(name)
            if cam is None or name not in self._images:
                continue
            mask = np.asarray(mask)
            if mask.shape != (cam.height, cam.width):
                raise LikelihoodError(f'{name}: expected a ({cam.height}, {cam.width}) '
                                      f'foreground mask, got {mask.shape}')
            unknown = undecided.get(name)
            if unknown is not None and np.shape(unknown) != mask.shape:
                raise LikelihoodError(f'{name}: expected a ({cam.height}, {cam.width}) '
                                      f'undecided-pixel mask, got {np.shape(unknown)}')
            out[name] = ForegroundIntegral(mask, unknown)
        return out

    @property
    def active_cameras(self) -> list[str]:
        """Cameras with an image this frame, in calibration order."""
        return [n for n in self.camera_names if n in self._images]

    def bins(self, camera: str) -> np.ndarray:
        """(H, W) int16 quantised image of a camera this frame."""
        out = self._bins.get(camera)
        if out is None:
            try:
                image = self._images[camera]
            except KeyError as err:
                raise LikelihoodError(f'no image for camera {camera!r} this frame') from err
            out = self._bins[camera] = quantize(image)
        return out

    def frame_bins(self) -> dict[str, np.ndarray]:
        """The quantised images of this frame computed so far, by camera (for reuse)."""
        return dict(self._bins)

    # -- silhouettes ----------------------------------------------------------------------
    def _camera(self, name: str) -> Camera:
        try:
            return self.calibration.cameras[name]
        except KeyError as err:
            raise LikelihoodError(f'unknown camera {name!r}') from err

    def silhouettes(self, camera: str, states: np.ndarray,
                    model: PersonModel | Sequence[PersonModel], *,
                    row_step: int | None = None) -> Silhouettes:
        """Rasterise states (N, 6) of one person (or one model per state) in a camera."""
        cam = self._camera(camera)
        states = self._check_states(states, 'states')
        if isinstance(model, PersonModel):
            heights = np.full(states.shape[0], float(model.height))
            widths = np.full(states.shape[0], float(model.width))
            chair = model.chair_height
        else:
            models = list(model)
            if len(models) != states.shape[0]:
                raise LikelihoodError(f'{len(models)} models for {states.shape[0]} states')
            heights = np.array([m.height for m in models], dtype=np.float64)
            widths = np.array([m.width for m in models], dtype=np.float64)
            chair = models[0].chair_height if models else 0.45
        step = self.config.subsample if row_step is None else row_step
        return rasterize(cam, states, BodyShape(chair_height=chair), heights=heights,
                         widths=widths, row_step=int(step))

    def render_labels(self, camera: str, state: np.ndarray, model: PersonModel) -> np.ndarray:
        """(H, W) int8 part labels (0 background, 1 head, 2 torso, 3 legs) of one state."""
        return self.silhouettes(camera, np.asarray(state).reshape(1, -1), model,
                                row_step=1).mask(0)

    @staticmethod
    def _check_states(states: np.ndarray, what: str) -> np.ndarray:
        arr = np.asarray(states, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != STATE_DIM:
            raise LikelihoodError(f'{what} must be (N, {STATE_DIM}), got {arr.shape}')
        if not np.isfinite(arr).all():
            raise LikelihoodError(f'{what} contain non-finite values')
        return arr

    def _check_targets(self, particles: Sequence[np.ndarray],
                       models: Sequence[PersonModel]) -> list[np.ndarray]:
        if len(particles) != len(models):
            raise LikelihoodError(f'{len(particles)} particle sets for {len(models)} models')
        out = [self._check_states(p, f'particles of target {k}')
               for k, p in enumerate(particles)]
        for k, m in enumerate(models):
            if not isinstance(m, PersonModel):
                raise LikelihoodError(f'model {k} is not a PersonModel')
            if m.view_angles.size == 0:
                raise LikelihoodError(f'model {k} has no key views')
        return out

    def _prepare(self, camera: str, states: np.ndarray, target: np.ndarray,
                 models: Sequence[PersonModel], timings: dict[str, float]) -> Silhouettes:
        """Silhouettes of the K targets' particles (states (P, 6), target index (P,)) in one
        camera."""
        cam = self._camera(camera)
        t0 = time.perf_counter()
        heights = np.array([m.height for m in models], dtype=np.float64)[target]
        widths = np.array([m.width for m in models], dtype=np.float64)[target]
        chair = models[0].chair_height if len(models) else 0.45
        sil = rasterize(cam, states, BodyShape(chair_height=chair), heights=heights,
                        widths=widths, row_step=int(self.config.subsample))
        timings['rasterize'] = timings.get('rasterize', 0.0) + time.perf_counter() - t0
        return sil

    def _views(self, cam: Camera, states: np.ndarray, target: np.ndarray,
               models: Sequence[PersonModel]) -> tuple[np.ndarray, ...]:
        """Key views (K, V, 1536) and per-particle interpolation (va, vb, wa) (P,)."""
        va, vb, wa = view_weights([cam], states, target, models)
        return key_view_stack(models), va[0], vb[0], wa[0]

    def _without_hidden(self, camera: str, loglik: np.ndarray, states: np.ndarray,
                        target: np.ndarray, prior: np.ndarray, n_targets: int) -> np.ndarray:
        """A camera's log-likelihoods (P,) with the particles it cannot see in an exit
        (``RoomCalibration.exit_hidden``: behind the wall with the door) set to the
        prior-weighted mean of their target's other particles: the camera then neither
        pulls a track back from the doorway (a person beyond the wall looks absent to it)
        nor favours the exit (an unseen silhouette would otherwise score 0, the best)."""
        if not self.calibration.exits:
            return loglik
        hidden = self.calibration.exit_hidden(camera, states[:, :2])
        if not hidden.any():
            return loglik
        return _with_target_mean(loglik, ~hidden, target, prior, n_targets)

    def _seen_by(self, loglik: np.ndarray, inside: np.ndarray, visible: np.ndarray,
                 target: np.ndarray, prior: np.ndarray, n_targets: int) -> np.ndarray:
        """A camera's log-likelihoods (P,) where it sees enough of a target: 0 for every
        particle of a target whose silhouettes are less than ``min_inside_share`` inside
        the image on average (``inside`` (P,): each one's share, 0 for one not seen,
        weighted by ``prior``) or whose expected visible fraction ``visible`` (K,) is
        below ``min_visible_share`` (hidden behind nearer targets); elsewhere a particle
        not seen gets the prior-weighted mean of its target's seen ones (module
        docstring)."""
        seen = inside > 0
        out = loglik if seen.all() else _with_target_mean(loglik, seen, target, prior,
                                                           n_targets)
        mass = np.bincount(target, weights=prior, minlength=n_targets)
        share = np.divide(np.bincount(target, weights=prior * inside, minlength=n_targets),
                          mass, out=np.zeros(n_targets), where=mass > 0)
        quiet = ((share < self.config.min_inside_share)
                 | (visible < self.config.min_visible_share))
        return np.where(quiet[target], 0.0, out)

    def _coverage_term(self, cover: np.ndarray, target: np.ndarray, prior: np.ndarray,
                       n_targets: int) -> np.ndarray:
        """``gain * f`` per particle (P,) from coverages ``cover`` (NaN: the silhouette is
        outside the image); a particle outside gets its target's prior-weighted mean term
        (the camera says nothing about it, as :meth:`_without_hidden`)."""
        return self._coverage_gain * _with_target_mean(cover, np.isfinite(cover), target,
                                                       prior, n_targets)

    # -- HJS --------------------------------------------------------------------------------
    def _hjs_camera(self, camera: str, states: np.ndarray, target: np.ndarray,
                    prior: np.ndarray, key: np.ndarray, models: Sequence[PersonModel], *,
                    separable: bool, record: bool, timings: dict[str, float]):
        """000 Algorithm 1 "update" in one camera for the stacked particles of all targets
        (states (P, 6), target (P,), normalised priors (P,), key views (K, V, 1536)), step
        by step with the silhouettes and w* kept: :meth:`hjs_debug`'s path (``hjs`` and
        ``separable`` run each camera as one :func:`_kernels.update_camera` call)."""
        t0 = time.perf_counter()
        va, vb, wa = (v[0] for v in view_weights([self._camera(camera)], states, target,
                                                 models))
        timings['models'] = timings.get('models', 0.0) + time.perf_counter() - t0
        sil = self._prepare(camera, states, target, models, timings)
        n_targets = key.shape[0]
        t0 = time.perf_counter()
        order = np.argsort(sil.distance, kind='stable')
        if record:
            owner = np.repeat(np.arange(len(sil)), np.diff(sil.offsets))
            counts = np.bincount(owner, weights=sil.x1 - sil.x0, minlength=len(sil))
            pix_offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
            rec = np.zeros(int(pix_offsets[-1]))
        else:
            pix_offsets = np.zeros(len(sil) + 1, np.int64)
            rec = np.zeros(0)
        bins = self.bins(camera)

        def kernel(mfg: np.ndarray, bbg: np.ndarray, wmap: np.ndarray):
            return _kernels.hjs_camera_ws(
                bins, sil.row, sil.x0, sil.x1, sil.part, sil.offsets, sil.area, sil.bbox,
                order, target, prior, key, va, vb, wa, n_targets, float(self.config.d_occ),
                bool(separable), rec, pix_offsets, mfg, bbg, wmap)

        if separable:                               # no image buffers
            fc, bc, vis = kernel(_NO_BUFFER, _NO_BUFFER, _NO_BUFFER)
        else:
            with self._workspaces.get(bins.shape[0], bins.shape[1], n_targets) as ws:
                fc, bc, vis = kernel(*ws)
        timings['kernel'] = timings.get('kernel', 0.0) + time.perf_counter() - t0
        return sil, fc, bc, vis, rec, pix_offsets

    def _stack(self, parts: list[np.ndarray], priors: list[np.ndarray],
               models: Sequence[PersonModel]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The K targets' particles stacked: states (P, 6), target (P,), prior (P,) and the
        key views (K, V, 1536)."""
        states = np.concatenate(parts, axis=0) if parts else np.zeros((0, STATE_DIM))
        target = np.repeat(np.arange(len(parts), dtype=np.int64),
                           [p.shape[0] for p in parts])
        prior = np.concatenate(priors) if priors else np.zeros(0)
        return states, target, prior, key_view_stack(models)

    def _camera_arguments(self, name: str) -> tuple:
        """The camera's constants as :func:`_kernels.update_camera` takes them."""
        cam = self._camera(name)
        cached = self._camera_args.get(name)
        if cached is None or cached[0] is not cam:
            cached = (cam, camera_constants(cam))
            self._camera_args[name] = cached
        return cached[1]

    def _evaluate(self, particles: Sequence[np.ndarray], weights: Sequence[np.ndarray] | None,
                  models: Sequence[PersonModel], *, separable: bool,
                  log_weights: bool) -> LikelihoodResult:
        parts = self._check_targets(particles, models)
        if weights is None:
            priors = [np.full(p.shape[0], 1.0 / max(p.shape[0], 1)) for p in parts]
        else:
            if len(weights) != len(parts):
                raise LikelihoodError(f'{len(weights)} weight sets for {len(parts)} targets')
            priors = _normalised_prior_list(weights, parts, log_weights)
        n_k = [p.shape[0] for p in parts]
        starts = np.concatenate([[0], np.cumsum(n_k)]).astype(np.int64)
        n_targets = len(parts)
        cams = [(c, name) for c, name in enumerate(self.camera_names)
                if name in self._images and parts]
        t0 = time.perf_counter()
        states, target, prior, key = self._stack(parts, priors, models)
        versions = self._key_versions(models) if self._scorers else None
        # everything a camera thread needs, prepared once: its work is then one numba call
        # that runs without the GIL (the threads do not wait for each other's Python)
        heights = np.array([m.height for m in models], dtype=np.float64)[target]
        widths = np.array([m.width for m in models], dtype=np.float64)[target]
        chair = float(models[0].chair_height) if len(models) else 0.45
        n_views = np.array([m.view_angles.size for m in models], np.int64)
        angles = np.zeros((n_targets, int(n_views.max()) if n_targets else 1))
        for k, m in enumerate(models):
            angles[k, :n_views[k]] = m.view_angles
        cam_loglik = np.empty((len(cams), states.shape[0]))
        cam_visible = np.empty((len(cams), n_targets))
        cam_inside = np.empty((len(cams), states.shape[0]))
        cam_cover = np.full((len(cams), states.shape[0]), np.nan)
        coverage = self._coverage_gain > 0
        timings: dict[str, float] = {'models': time.perf_counter() - t0}

        def request_of(name: str) -> CameraRequest:
            return CameraRequest(
                self._at_capture(name, states), target, prior, heights, widths, chair, angles,
                n_views, key, bool(separable), 2.0 * self.config.sigma ** 2,
                float(self.config.d_occ), int(self.config.subsample),
                int(self.config.min_visible_pixels), coverage, self._neutral)

        # the cameras whose stage scores them get their requests first, all at once
        asked = {}
        for _, name in cams:
            scorer = self._scorers.get(name)
            if scorer is not None:   # the key views the stage has already are not sent
                request = request_of(name)
                have = self._sent_versions.get(name, ())
                new = np.array([k for k, v in enumerate(versions.tolist()) if v not in have],
                               np.int64)
                asked[name] = (request, scorer(replace(request, key=key[new], key_targets=new,
                                                       versions=versions)))

        def one(i: int) -> float:
            name = cams[i][1]
            t1 = time.perf_counter()
            rows = CameraScores(cam_loglik[i], cam_visible[i], cam_inside[i], cam_cover[i])
            if name in asked:
                request, answer = asked[name]
                got = answer()    # the stage keeps the key views of this request only
                self._sent_versions[name] = set(versions.tolist()) if got is not None \
                    else set()
            else:
                request, got = request_of(name), None
            if got is not None:                 # the camera's own stage scored them
                self._take_scores(name, got, rows)
            else:
                self._bins[name] = score_camera(
                    self._camera_arguments(name), self._images[name],
                    self._bins.get(name, _NO_BINS),
                    lambda: self._foreground_integrals().get(name), request,
                    self._workspaces, rows)
            return time.perf_counter() - t1

        # Longest camera first (by its time in the previous call): the threads take the
        # cameras in this order, which balances them better than calibration order when a
        # few cameras see most of the people (results are still combined in camera order).
        by_cost = sorted(range(len(cams)),
                         key=lambda i: -self._camera_cost.get(cams[i][1], 0.0))
        timings['camera'] = 0.0
        for i, seconds in zip(by_cost, self._map(one, by_cost)):
            self._camera_cost[cams[i][1]] = seconds
            timings['camera'] += seconds
        loglik = np.zeros(int(starts[-1]))
        visible = np.zeros((n_targets, len(self.camera_names)))
        for i, (c, name) in enumerate(cams):
            if self._coverage_gain > 0 and name in self._foreground_integrals():
                cam_loglik[i] += self._coverage_term(cam_cover[i], target, prior, n_targets)
            cam_loglik[i] = self._seen_by(cam_loglik[i], cam_inside[i], cam_visible[i],
                                          target, prior, n_targets)
            loglik += self._without_hidden(name, cam_loglik[i],
                                           self._at_capture(name, states), target, prior,
                                           n_targets)
            visible[:, c] = cam_visible[i]
        timings['total'] = time.perf_counter() - t0
        return LikelihoodResult(
            loglik=[loglik[starts[k]:starts[k + 1]].copy() for k in range(n_targets)],
            visible_fraction=visible, timings=timings)

    def close(self) -> None:
        """Stop the camera worker threads (also done when the model is garbage collected)."""
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None
            self._pool_size = 0

    def __del__(self) -> None:
        pool = getattr(self, '_pool', None)
        if pool is not None:
            pool.shutdown(wait=False)

    def _map(self, fn, items: list) -> list:
        """fn over items, on ``config.threads`` threads when it allows (the numba kernels
        release the GIL); per-camera stage timings then overlap. The calling thread is one
        of them: it takes items in turn with the pool's threads instead of sleeping until
        they finish (one thread fewer to wake per call)."""
        workers = self.config.threads or _CPUS
        workers = min(workers, len(items))
        if workers <= 1:
            return [fn(item) for item in items]
        if self._pool is None or self._pool_size != workers - 1:
            if self._pool is not None:
                self._pool.shutdown(wait=False)
            self._pool = ThreadPoolExecutor(max_workers=workers - 1,
                                            thread_name_prefix='mbtrack-likelihood')
            self._pool_size = workers - 1
        results: list = [None] * len(items)
        taken = itertools.count()                  # next() is atomic under the GIL

        def drain() -> None:
            while (i := next(taken)) < len(items):
                results[i] = fn(items[i])

        helpers = [self._pool.submit(drain) for _ in range(workers - 1)]
        try:
            drain()
        finally:
            for helper in helpers:                  # waits; re-raises a helper's error
                helper.result()
        return results

    def hjs(self, particles: Sequence[np.ndarray], weights: Sequence[np.ndarray],
            models: Sequence[PersonModel], *, log_weights: bool = False) -> LikelihoodResult:
        """HJS marginal log-likelihoods of every particle (000 Eq. 22-40, Algorithm 1).

        Args:
            particles: K arrays (N_k, 6) of particle states.
            weights: K arrays (N_k,) of prior weights (the temporal prior after BP);
                linear and >= 0 (normalised here), or log-weights with ``log_weights``.
            models: K person models.
        """
        return self._evaluate(particles, weights, models, separable=False,
                              log_weights=log_weights)

    def separable(self, particles: Sequence[np.ndarray],
                  models: Sequence[PersonModel]) -> LikelihoodResult:
        """Each target scored alone, without occlusion reasoning (w* = 1): 003 Eq. 3."""
        return self._evaluate(particles, None, models, separable=True, log_weights=False)

    def hjs_debug(self, camera: str, particles: Sequence[np.ndarray],
                  weights: Sequence[np.ndarray], models: Sequence[PersonModel]) -> HJSDebug:
        """The HJS update of one camera with per-particle fc, bc and dense w* maps."""
        parts = self._check_targets(particles, models)
        priors = [_normalised_priors(w, p.shape[0], k, False)
                  for k, (w, p) in enumerate(zip(weights, parts))]
        states, target, prior, key = self._stack(parts, priors, models)
        sil, fc, bc, vis, rec, pix = self._hjs_camera(
            camera, states, target, prior, key, models, separable=False, record=True,
            timings={})
        w_star = np.zeros((len(sil), sil.height, sil.width))
        for p in range(len(sil)):
            q = int(pix[p])
            for s in range(int(sil.offsets[p]), int(sil.offsets[p + 1])):
                n = int(sil.x1[s] - sil.x0[s])
                w_star[p, sil.row[s], sil.x0[s]:sil.x1[s]] = rec[q:q + n]
                q += n
        return HJSDebug(silhouettes=sil, target=target, prior=prior, fc=fc, bc=bc,
                        visible=vis, w_star=w_star)

    def occlusion_maps(self, camera: str, particles: Sequence[np.ndarray],
                       weights: Sequence[np.ndarray], models: Sequence[PersonModel], *,
                       log_weights: bool = False) -> np.ndarray:
        """(K, H, W) float32 occlusion maps at infinity (000 Eq. 34, Fig. 4).

        Map k is prod_{h != k} (1 - sum of the prior weights of h's particles covering u):
        the prior probability that no other target hides pixel u.
        """
        parts = self._check_targets(particles, models)
        priors = [_normalised_priors(w, p.shape[0], k, log_weights)
                  for k, (w, p) in enumerate(zip(weights, parts))]
        cam = self._camera(camera)
        bfg = np.ones((len(parts), cam.height, cam.width))
        for k, (p, m) in enumerate(zip(parts, models)):
            sil = self.silhouettes(camera, p, m, row_step=1)
            _kernels.accumulate_spans(bfg[k], sil.row, sil.x0, sil.x1, sil.offsets,
                                      -priors[k], 0, 0)
        out = np.empty_like(bfg, dtype=np.float32)
        for k in range(len(parts)):
            others = np.delete(bfg, k, axis=0)
            out[k] = np.prod(others, axis=0) if others.size else 1.0
        return np.clip(out, 0.0, 1.0)

    # -- joint ------------------------------------------------------------------------------
    def joint(self, joint_particles: np.ndarray, models: Sequence[PersonModel], *,
              orders: np.ndarray | None = None) -> np.ndarray:
        """Joint log-likelihood (N,) of joint samples (N, K, 6) (000 Eq. 19-21, 26).

        Each sample is rendered with a per-pixel depth buffer: a pixel shows the nearest
        silhouette covering it (by camera distance of the body centres, or by ``orders``
        (N, n_cameras, K), the front-to-back target order per sample and camera, camera
        index as in :attr:`camera_names`). Every target scores Eq. 26 with its binary
        visibility mask (alpha visible, beta hidden pixels with penalty d_occ); the terms
        add over targets and cameras.
        """
        jp = np.asarray(joint_particles, dtype=np.float64)
        if jp.ndim != 3 or jp.shape[2] != STATE_DIM:
            raise LikelihoodError(f'joint particles must be (N, K, {STATE_DIM}), got {jp.shape}')
        n, k = jp.shape[:2]
        if len(models) != k:
            raise LikelihoodError(f'{k} targets per joint sample but {len(models)} models')
        if orders is not None:
            orders = np.asarray(orders)
            if orders.shape != (n, len(self.camera_names), k):
                raise LikelihoodError(f'orders must be ({n}, {len(self.camera_names)}, {k}),'
                                      f' got {orders.shape}')
            if not np.all(np.sort(orders, axis=2) == np.arange(k)):
                raise LikelihoodError('each orders[n, c] must be a permutation of the targets')
        flat = [jp[:, j] for j in range(k)]
        self._check_targets(flat, models)
        states = jp.reshape(n * k, STATE_DIM)
        out = np.zeros(n)
        if n == 0 or k == 0:
            return out
        target = np.tile(np.arange(k), n)
        heights = np.array([m.height for m in models], dtype=np.float64)[target]
        widths = np.array([m.width for m in models], dtype=np.float64)[target]
        shape = BodyShape(chair_height=models[0].chair_height)
        min_pix = int(np.ceil(self.config.min_visible_pixels / self.config.subsample))
        chunk = max(1, self.JOINT_CHUNK // k)          # joint samples rasterised at once

        def one(item: tuple[int, str]) -> np.ndarray:
            c, name = item
            cam = self._camera(name)
            total = np.empty(n)
            for a in range(0, n, chunk):
                b = min(n, a + chunk)
                sl = slice(a * k, b * k)
                sil = rasterize(cam, states[sl], shape, heights=heights[sl],
                                widths=widths[sl], row_step=int(self.config.subsample))
                key, va, vb, wa = self._views(cam, states[sl], target[sl], models)
                if orders is None:
                    order = np.argsort(sil.distance.reshape(b - a, k), axis=1, kind='stable')
                else:
                    order = orders[a:b, c, :]
                order = np.ascontiguousarray(order, dtype=np.int64)
                total[a:b] = _kernels.joint_camera(
                    self.bins(name), sil.row, sil.x0, sil.x1, sil.part, sil.offsets, sil.area,
                    order, k, float(self.config.d_occ), key, va, vb, wa, min_pix)
            return total

        cams = [(c, name) for c, name in enumerate(self.camera_names) if name in self._images]
        for total in self._map(one, cams):
            out -= total / (2.0 * self.config.sigma ** 2)
        return out
