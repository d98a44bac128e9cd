"""The per-camera half of the detection pipeline, runnable apart from the tracker.

One camera's work of a frame (003 §4.2) needs only that camera: the one resize to the
working size, the background model's foreground test and its masked update. The rest (the
filter, the detection search, existence, release) needs all cameras. :class:`CameraStage`
is that per-camera half (what ``camera_node`` runs on a camera's host);
:class:`ReceivedForeground` stands in for the tracker's
:class:`~.background.BackgroundBank` in a fusion node and hands the detection what the
camera stages sent. Both call the same functions as the single-process tracker
(:meth:`BackgroundModel.apply`, :func:`exclusion_mask`, :class:`BootstrapCue`), so a
fusion node gives the same tracks as one process up to two differences:

* the masked model update of frame t keeps off the tracks' silhouettes of the latest track
  message the camera stage has, frame t-1 (one frame of latency; in one process, frame
  t's), rendered from the tracks' floor position, velocity and height (the orientation
  and posture are not sent: the union of two perpendicular standing silhouettes);
* the multi-view people cue of the online bootstrap (:class:`~.people.PeopleCue`) needs all
  cameras: the fusion node computes it from the bootstrap frames the stages sent and sends
  each stage its regions (:meth:`CameraStage.set_regions`), which a stage waits for before
  its next update (offline, the next frame; live, the frames until they come go out
  without foreground, :meth:`CameraStage.hold`, while the cue runs on its own thread).

A stage can also score the filter's particles in its camera (:meth:`CameraStage.score`):
the camera's share of the HJS likelihood (000 Algorithm 1 "update" and the foreground
coverage term, :func:`~mbtrack_ros.core.likelihood.score_camera`), requested by the
fusion node with the frame set's particles (:class:`~mbtrack_ros.core.likelihood
.CameraRequest`, :meth:`MeasurementModel.set_scorers`); the same call on the same image
and masks as in one process, so the scores are those of one process.

Masks travel as one ``(H, W) uint8`` image of bit planes (:func:`pack_masks`).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np

from mbtrack_ros.core import _kernels
from mbtrack_ros.core.camera import Camera, RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.illumination import IlluminationNormaliser
from mbtrack_ros.core.detection.background import (
    BackgroundConfig, BackgroundModel, BootstrapCue)
from mbtrack_ros.core.detection.features import ForegroundIntegral
from mbtrack_ros.core.likelihood import (
    CameraRequest, CameraScores, LikelihoodError, _Workspaces, camera_constants, score_camera)
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.state import SIT, THETA, VX, VY, X, Y

__all__ = ['CameraFrame', 'CameraStage', 'ReceivedForeground', 'head_heights',
           'exclusion_mask', 'pack_masks', 'pack_regions', 'unpack_masks', 'unpack_regions']

#: bit planes of a packed foreground image (values chosen to be visible as a grey image)
FOREGROUND, POSSIBLE, PRESENCE = 0x80, 0x40, 0x20
#: bit planes of packed bootstrap regions
REGION, BODY, CORE = 0x80, 0x40, 0x20


def exclusion_mask(camera: Camera, means: np.ndarray, shapes: Sequence[BodyShape],
                   tops: np.ndarray, sil=None) -> np.ndarray:
    """The pixels (H, W) bool the background update must not learn: the tracks'
    silhouettes at their means (N, 6) (003 §4.2; ``sil``: their rasterisation when the
    caller has it), and for a top-down camera the head-height blob of people whose outline
    degenerates right below it (``tops`` (N,) metres, the release's blob, 003 §4.3)."""
    from mbtrack_ros.core.detection.detector import is_ceiling
    from mbtrack_ros.core.detection.release import paint_blobs

    mask = np.zeros((camera.height, camera.width), bool)
    if len(means) == 0:
        return mask
    if sil is None:
        sil = rasterize(camera, means, list(shapes))
    _kernels.paint_spans(mask.view(np.uint8), sil.row, sil.x0, sil.x1, sil.part, 0,
                         int(sil.offsets[-1]), 1, False)
    if is_ceiling(camera):
        # the outline degenerates to a line right below a top-down camera: the model update
        # must not learn a person standing there (the release reads this camera's blob)
        paint_blobs(mask, camera, means[:, :2], tops, outline_area=sil.area)
    return mask


def head_heights(means: np.ndarray, shapes: Sequence[BodyShape]) -> np.ndarray:
    """(N,) head height, metres: sitting keeps the upper body above the chair (003 §2.1)."""
    return np.array([sh.chair_height + (1.0 - sh.hip_fraction) * sh.height
                     if m[SIT] >= 0.5 else sh.height for sh, m in zip(shapes, means)])


def pack_masks(foreground: np.ndarray, possible: np.ndarray | None = None,
               presence: np.ndarray | None = None) -> np.ndarray:
    """(H, W) uint8 bit planes of a camera stage's frame masks (each (H, W) bool)."""
    out = np.where(foreground, np.uint8(FOREGROUND), np.uint8(0))
    if possible is not None:
        out |= np.where(possible, np.uint8(POSSIBLE), np.uint8(0))
    if presence is not None:
        out |= np.where(presence, np.uint8(PRESENCE), np.uint8(0))
    return out


def unpack_masks(packed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(foreground, possible, presence), each (H, W) bool, of :func:`pack_masks`' image."""
    p = np.asarray(packed)
    if p.ndim == 3:
        p = p[..., 0]
    return (p & FOREGROUND) > 0, (p & POSSIBLE) > 0, (p & PRESENCE) > 0


def pack_regions(region: np.ndarray, body: np.ndarray, core: np.ndarray) -> np.ndarray:
    """(H, W) uint8 bit planes of one camera's bootstrap regions (:meth:`BootstrapCue
    .regions`)."""
    return pack_masks(region, body, core)


def unpack_regions(packed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(region, body, core) of :func:`pack_regions`' image."""
    return unpack_masks(packed)


@dataclass
class CameraFrame:
    """What a camera stage gives the fusion node for one frame.

    Attributes:
        image: (H, W, 3) uint8 RGB at the working size.
        foreground: (H, W) bool cleaned foreground (003 §4.2), None while bootstrapping.
        possible: (H, W) bool not-yet-known pixels that counted as foreground in the test
            (:attr:`BackgroundModel.possible_foreground_as_tested`).
        presence: (H, W) bool foreground that cannot be a ghost
            (:meth:`BackgroundModel.presence` after the frame's update).
        started: the model was bootstrapped with this frame (it wants its regions).
    """

    image: np.ndarray
    foreground: np.ndarray | None = None
    possible: np.ndarray | None = None
    presence: np.ndarray | None = None
    started: bool = False


class CameraStage:
    """The per-camera work of one camera: resize, background, foreground.

    Args:
        camera: the camera at its calibrated (full) size.
        config: the background parameters (the tracker's, ``AutoDetectionConfig.background``).
        working_pixels: the tracker's working size (``TrackerConfig.working_pixels``).
    """

    def __init__(self, camera: Camera, config: BackgroundConfig | None = None, *,
                 working_pixels: int = 76_800) -> None:
        self.full = camera
        self.camera = camera.at_most(int(working_pixels))
        self.config = config or BackgroundConfig()
        self.model = BackgroundModel(self.config, name=camera.name)
        # the tracker's global colour-gain normalisation against this camera's model
        self.illumination = IlluminationNormaliser(SimpleNamespace(models={camera.name:
                                                                          self.model}))
        self._exclude: np.ndarray | None = None
        self.awaiting_regions = False  # bootstrapped; the fusion node's cue not applied yet
        self.last: CameraFrame | None = None   # the last frame processed
        self._camera_args = camera_constants(self.camera)
        self._workspaces = _Workspaces()
        # version -> (V, 1536) key views of a target, those of the last score request
        self._views: dict[int, np.ndarray] = {}
        # (frame, its colour bins, its foreground's prefix sums) of the last frame scored
        self._scored: tuple[CameraFrame, np.ndarray, ForegroundIntegral | None] | None = None

    def resize(self, image: np.ndarray) -> np.ndarray:
        """``image`` (H, W, 3) at the working size: itself when it has that size already
        (decoded at it, ``decode_raw(..., to=stage.camera)``), else one resize
        (``Camera.fit``, area averaging) from whatever size it has."""
        return self.camera.fit(image)

    def set_tracks(self, xy: np.ndarray, velocity: np.ndarray, heights: np.ndarray) -> None:
        """The tracks the next update keeps off: floor positions (N, 2) m, velocities (N, 2)
        m/s and body heights (N,) m (``~/tracks``). Each is rendered standing with both its
        heading (velocity direction) and the perpendicular one, a silhouette that holds the
        body whatever its orientation or posture, then :func:`exclusion_mask`."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        n = len(xy)
        if n == 0:
            self._exclude = None
            return
        v = np.asarray(velocity, np.float64).reshape(n, 2)
        h = np.asarray(heights, np.float64).reshape(n)
        h = np.where(np.isfinite(h) & (h > 0.5), h, BodyShape().height)
        heading = np.arctan2(v[:, 1], v[:, 0])
        means = np.zeros((2 * n, 6))
        means[:, [X, Y]] = np.concatenate([xy, xy])
        means[:, [VX, VY]] = np.concatenate([v, v])
        means[:, THETA] = np.concatenate([heading, heading + 0.5 * np.pi])
        shapes = [BodyShape(height=float(a)) for a in np.concatenate([h, h])]
        self._exclude = exclusion_mask(self.camera, means, shapes, head_heights(means, shapes))

    def set_exclusion(self, mask: np.ndarray | None) -> None:
        """The pixels (H, W) bool the next update keeps off (None: none)."""
        self._exclude = mask

    def set_regions(self, region: np.ndarray, body: np.ndarray, core: np.ndarray) -> None:
        """The bootstrap regions of the people cue (:meth:`BootstrapCue.regions`)."""
        self.model.set_unknown(region, foreground=body, core=core)
        self.awaiting_regions = False

    def hold(self, image: np.ndarray) -> CameraFrame:
        """A frame (H, W, 3) uint8 RGB while the model waits for its bootstrap regions
        (:attr:`awaiting_regions`): the working image as :meth:`process` gives it, no
        foreground, the model not updated."""
        self.last = CameraFrame(self._working(image))
        return self.last

    def _working(self, image: np.ndarray) -> np.ndarray:
        """``image`` at the working size, its illumination normalised against the model."""
        im = self.resize(image)
        return self.illumination.normalise({self.full.name: im})[self.full.name]

    def process(self, image: np.ndarray) -> CameraFrame:
        """One frame (H, W, 3) uint8 RGB: the foreground test, then the model update kept
        off the last tracks given (:meth:`BackgroundModel.apply`)."""
        im = self._working(image)
        was_ready = self.model.ready
        fg = self.model.apply(im, defer=True)
        if fg is None:
            self.awaiting_regions = self.model.ready and not was_ready
            self.last = CameraFrame(im, started=self.awaiting_regions)
            return self.last
        possible = self.model.possible_foreground_as_tested
        self.model.exclude_pending(self._exclude)
        self.model.update_pending()
        self.last = CameraFrame(im, fg, possible, self.model.presence())
        return self.last

    def _completed(self, request: CameraRequest) -> CameraRequest | None:
        """``request`` with every target's key views (K, V, 1536): those it carries for
        ``key_targets``, the others' by version from the last request (kept in turn:
        this request's only); None when one is missing."""
        try:
            versions = np.asarray(request.versions, np.int64).reshape(-1)
            targets = np.asarray(request.key_targets, np.int64).reshape(-1)
            n_views = np.asarray(request.n_views, np.int64).reshape(-1)
            sent = np.asarray(request.key, np.float64)
            k, v = len(versions), int(np.shape(request.view_angles)[1])
            if (len(n_views) != k or sent.shape != (len(targets), v, 1536)
                    or (len(targets) and not 0 <= targets.min() <= targets.max() < k)
                    or (k and not 1 <= n_views.min() <= n_views.max() <= v)):
                raise ValueError
        except (TypeError, ValueError, IndexError) as err:
            raise DetectionError(f'camera {self.full.name!r}: malformed score request') \
                from err
        views = dict(self._views)
        for j, t in enumerate(targets.tolist()):
            views[int(versions[t])] = sent[j, :n_views[t]]
        key = np.zeros((k, v, 1536))
        for t in range(k):
            got = views.get(int(versions[t]))
            if got is None or len(got) != n_views[t]:
                self._views = {}
                return None
            key[t, :n_views[t]] = got
        self._views = {int(versions[t]): key[t, :n_views[t]] for t in range(k)}
        return replace(request, key=key, key_targets=None, versions=None)

    def score(self, request: CameraRequest, frame: CameraFrame | None = None
              ) -> CameraScores | None:
        """The particles of ``request`` scored in this camera (the camera's share of the
        fusion node's HJS likelihood, :func:`~mbtrack_ros.core.likelihood.score_camera`)
        on ``frame`` (default: the last one :meth:`process` gave; None when there is none):
        its working image, and its foreground with the possible foreground undecided
        (what the tracker's :meth:`MeasurementModel.set_foreground` takes in one
        process). A request with ``key_targets`` takes the other targets' key views from
        the last request by version (None when they are not there: a restarted stage).
        Raises :class:`DetectionError` for a malformed request."""
        frame = self.last if frame is None else frame
        if frame is None:
            return None
        if self._scored is None or self._scored[0] is not frame:
            integral = None
            if frame.foreground is not None:
                possible = frame.possible
                undecided = possible if possible is not None and possible.any() else None
                integral = ForegroundIntegral(frame.foreground, undecided)
            self._scored = (frame, np.zeros((0, 0), np.int16), integral)
        _, bins, integral = self._scored
        if request.key_targets is not None:   # key views of earlier requests completed
            request = self._completed(request)
            if request is None:
                return None
        r = _checked(request, self.full.name)
        n, k = len(r.states), len(r.key)
        out = CameraScores.empty(n, k)
        try:
            bins = score_camera(self._camera_args, frame.image, bins, lambda: integral,
                                r, self._workspaces, out)
        except LikelihoodError as err:
            raise DetectionError(f'camera {self.full.name!r}: {err}') from err
        self._scored = (frame, bins, integral)
        return out


def _checked(r: CameraRequest, name: str) -> CameraRequest:
    """``r`` with its arrays in the kernel's types, or :class:`DetectionError` when they do
    not fit together (a request from the network is checked before a kernel indexes with
    it)."""
    def arr(a, dtype, ndim):
        a = np.ascontiguousarray(a, dtype)
        if a.ndim != ndim:
            raise ValueError
        return a

    try:
        states, key = arr(r.states, np.float64, 2), arr(r.key, np.float64, 3)
        target, n_views = arr(r.target, np.int64, 1), arr(r.n_views, np.int64, 1)
        prior, heights, widths = (arr(a, np.float64, 1) for a in (r.prior, r.heights,
                                                                   r.widths))
        angles = arr(r.view_angles, np.float64, 2)
    except (TypeError, ValueError) as err:
        raise DetectionError(f'camera {name!r}: malformed score request') from err
    n, k = len(states), len(key)
    ok = (states.shape[1] == 6 and all(len(a) == n for a in (target, prior, heights, widths))
          and key.shape[2] == 1536 and len(angles) == k and len(n_views) == k
          and (k == 0 or (n_views.min() >= 1 and n_views.max() <= min(key.shape[1],
                                                                      angles.shape[1])))
          and (n == 0 or (k > 0 and target.min() >= 0 and target.max() < k))
          and int(r.row_step) >= 1 and np.isfinite([r.two_sigma_sq, r.d_occ, r.chair,
                                                   r.neutral]).all()
          and r.two_sigma_sq > 0)
    if not ok:
        raise DetectionError(f'camera {name!r}: malformed score request ({n} particles, '
                             f'{k} targets)')
    return CameraRequest(states, target, prior, heights, widths, float(r.chair), angles,
                         n_views, key, bool(r.separable), float(r.two_sigma_sq),
                         float(r.d_occ), int(r.row_step), int(r.min_visible),
                         bool(r.coverage), float(r.neutral))


class _Received:
    """One camera's masks, in the interface of a :class:`BackgroundModel` the detection
    reads: ``frame`` is the frame set's latest received, ``applied`` the one whose
    foreground the detection took last (:meth:`ReceivedForeground.apply`); the masks read
    after the foreground (possible foreground, presence) are those of ``applied``, so a
    search still running on the detection's worker (``pipeline_search``) reads its own
    frame's while the next frame set is received."""

    def __init__(self) -> None:
        self.frame: CameraFrame | None = None
        self.applied: CameraFrame | None = None

    @property
    def possible_foreground_as_tested(self) -> np.ndarray:
        f = self.applied
        if f is None or f.possible is None:
            shape = () if f is None else f.image.shape[:2]
            return np.zeros(shape or (0, 0), bool)
        return f.possible

    def presence(self, level: float = 0.3) -> np.ndarray | None:
        return None if self.applied is None else self.applied.presence

    @property
    def ready(self) -> bool:
        return self.frame is not None and self.frame.foreground is not None

    def outline_gradients(self, image, foreground, mask, *, width, exclude=None
                          ) -> tuple[float, float, float]:
        """(0, 0, 0): the model is on the camera's host, so the detection's ghost test
        (:meth:`~.background.BackgroundModel.outline_gradients`) has nothing to compare
        with here; the stage's own component test still learns ghosts."""
        return 0.0, 0.0, 0.0

    def learn_next(self, mask) -> None:
        """Nothing: the camera stage owns the model."""


class ReceivedForeground:
    """The fusion node's stand-in for the tracker's :class:`~.background.BackgroundBank`:
    the foreground of each camera comes from its :class:`CameraStage`.

    Per frame set: :meth:`receive` the cameras' :class:`CameraFrame` s, then run the
    tracker step on their images. :meth:`receive` gives the bootstrap regions the cameras
    whose model started want (the same cue as in one process).

    ``background_cue``: compute the cue on a thread of its own instead of in
    :meth:`receive` (a live fusion node: the cue takes 1-3 s of CPU with 4-12 cameras,
    which would hold up every frame set behind it); the regions then come out of the first
    :meth:`receive` after the cue is done, and its places go to the detection then. The
    cameras that wait for them send no foreground meanwhile (a bootstrapping camera)."""

    def __init__(self, calibration: RoomCalibration, config: BackgroundConfig, *,
                 background_cue: bool = False) -> None:
        self.config = config
        self.models: dict[str, _Received] = {}
        self.bootstrap_cue = BootstrapCue(calibration, config)
        self.background_cue = bool(background_cue)
        self._pool: ThreadPoolExecutor | None = None
        self._job: Future | None = None     # the cue being computed
        self._wanted: list[str] = []        # cameras started since the job began

    def receive(self, frames: Mapping[str, CameraFrame]) -> dict[str, tuple]:
        """The frame set's camera frames; returns (region, body, core) per camera that
        started its model with this frame set (to send back to its stage), or with
        ``background_cue`` with an earlier one whose cue is done now."""
        for m in self.models.values():
            m.frame = None
        for name, f in frames.items():
            self.model(name).frame = f
        if not self.bootstrap_cue.enabled:
            return {}
        cue = self.bootstrap_cue
        cue.keep({n: f.image for n, f in frames.items()}, copy=False)
        started = [n for n, f in frames.items() if f.started]
        if not self.background_cue:
            return cue.regions(started)
        out = {}
        if self._job is not None and self._job.done():
            job, self._job = self._job, None
            try:
                places, out = job.result()
            except Exception as err:  # noqa: BLE001 - the cameras go on without regions
                raise DetectionError(f'the bootstrap people cue failed: '
                                     f'{type(err).__name__}: {err}') from err
            cue.add_places(places)
        self._wanted += [n for n in started if n not in self._wanted]
        if self._wanted and self._job is None:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(1, thread_name_prefix='bootstrap_cue')
            # the frame sets kept so far (keep() appends to its list: a copy of it)
            self._job = self._pool.submit(cue.compute, list(self._wanted), list(cue.frames))
            self._wanted = []
        return out

    # -- the BackgroundBank interface AutoDetection uses -----------------------------------
    def model(self, name: str) -> _Received:
        if name not in self.models:
            self.models[name] = _Received()
        return self.models[name]

    def prepare(self) -> None:
        _ = self.bootstrap_cue.cue

    def apply(self, images: Mapping[str, np.ndarray], *, exclude=None, defer: bool = False
              ) -> dict[str, np.ndarray]:
        out = {}
        for name, image in images.items():
            model = self.model(name)
            f = model.applied = model.frame
            if f is None or f.foreground is None:
                continue
            if f.foreground.shape != image.shape[:2]:
                raise DetectionError(f'camera {name!r}: foreground {f.foreground.shape} '
                                     f'and image {image.shape[:2]} differ in size')
            out[name] = f.foreground
        return out

    def bootstrap(self, frames) -> None:
        raise DetectionError('a fusion node bootstraps no background: its camera stages do')

    def exclude_pending(self, exclude) -> None:
        """Nothing: the camera stages keep their updates off the tracks they receive."""

    def update_pending(self) -> None:
        """Nothing: the camera stages update their models."""

    def drop_pending(self) -> None:
        """Nothing to drop."""

