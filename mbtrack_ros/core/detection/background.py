"""Adaptive per-camera background model in Y-Cb-Cr and foreground extraction (003 §4.2).

The model of one camera is bootstrapped as the per-pixel median of a few empty-room frames
(or of the first frames of a recording) and then follows slow scene changes with the
temporal filter of 003 §4.2, ``B_t = alpha B_{t-1} + (1 - alpha) I_t``, applied only on
*stable* pixels: pixels with persistent motion (accumulated frame differences, dilated) and
pixels covered by the current tracks (label images rendered from the track estimates,
passed in as masks) are left untouched, so that a person standing still while tracked does
not fade into the background.

**A room that is never empty.** The first frames of a recording may show people; their
median then contains them, a person who barely moves is never foreground and a "ghost" is
left where he stood. Pixels that likely hold a person at the online bootstrap (the
multi-view cue of :mod:`.people`, found without a background) are therefore *not yet
known*: they are not learnt until seen empty, i.e. outside every track after a track has
covered them (the person there was found and has left) or, when no track ever covered
them, after ``unknown_frames`` frames (nobody was found there). Meanwhile the foreground
test is void there (the model may show a person): the cue's person-sized blob counts as
foreground (a possible person), the rest of the region as neither; and the blob's core
replaces motion as the proof, required of new people, that a detection is no ghost
(:meth:`BackgroundModel.presence`). The cue's places themselves are kept
(:meth:`BootstrapCue.take_places`): the detection initialises all those people together on
the first frame with foreground.

**Ghosts.** A person who stood still while the model was learnt is part of it; when he walks
away, the place he revealed differs from the model and looks like foreground (a "ghost"),
and a track placed on it would keep the model frozen there for ever. Ghosts are recognised
by where the edges are (the border test of ghost detection): along the border of a real
object the *frame* has a colour step (the object's outline), along the border of a ghost
the *model* has it (the outline of whoever was learnt) and the frame shows the continuous
room. A component most of whose pixels became foreground under a track is a tracked person
who came there (sitting down in front of a chair whose edges are in the model), never a
ghost. A foreground component whose border gradient in the model exceeds that in the frame
by ``ghost_edge_ratio``, for ``ghost_frames`` consecutive frames, is taken as background:
the model is set to the frame there, whatever the tracks (:func:`ghost_components`).

Foreground is a Y-Cb-Cr threshold test with separate luminance and chroma thresholds. The
luminance and chroma offsets of the background are first rescaled by a global gain
(median ratio I/B of the luminance), which makes the test robust to slow global
illumination changes; optional shadow suppression drops pixels that are darker than the
background by a bounded ratio with unchanged chroma. The mask is cleaned by morphological
opening/closing and by removing connected components smaller than ``min_blob_area``
pixels.

Images are ``(H, W, 3) uint8`` RGB; masks are ``(H, W) bool``.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numba import njit

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.people import PeopleCue, PeopleCueConfig

__all__ = ['BackgroundBank', 'BackgroundConfig', 'BackgroundModel', 'BootstrapCue',
           'clean_mask', 'ghost_components']


@dataclass(frozen=True)
class BackgroundConfig:
    """Parameters of the background model (all per frame, images 8-bit).

    Attributes:
        alpha: temporal filter memory of 003 §4.2 (``B = alpha B + (1 - alpha) I``).
        bootstrap_frames: frames whose median initialises the model when none is given.
        bootstrap_stride: take every n-th frame for that median.
        luma_threshold: |Y - g B_Y| above which a pixel is foreground (0..255 scale).
        chroma_threshold: Euclidean Cb-Cr distance above which a pixel is foreground.
        shadow_ratio: (lo, hi) luminance ratio I_Y / (g B_Y) of a shadow (chroma unchanged);
            ``None`` disables shadow suppression.
        motion_threshold: frame-difference luminance above which a pixel moved.
        motion_decay: memory of the accumulated motion image (per frame).
        motion_persistent: accumulated motion above which motion counts as persistent.
        mask_dilation: pixels by which excluded regions (motion, tracks) grow.
        open_size, close_size: morphological cleaning kernels (pixels, 0 disables).
        min_blob_area: smallest connected foreground component kept, in pixels at 320x240
            (scaled with the image area).
        static_frames, static_alpha: a pixel that has been foreground without motion and
            outside every track for ``static_frames`` frames is updated with the faster
            ``static_alpha`` (absorbs "ghosts" left by people in the bootstrap frames and
            moved objects; 0 disables).
        unknown_frames: frames a not-yet-known pixel that no track has covered waits before
            it is learnt (time for the detector to find the person there).
        settle_frames: frames a not-yet-known pixel must keep a steady value other than its
            bootstrap one (no motion) to be learnt even under a track (the person who
            stood there has left, whatever a track does).
        ghost_edge_ratio: a foreground component is a ghost when the mean colour gradient
            along its border (in units of the foreground thresholds per pixel) is this many
            times larger in the model than in the frame (:func:`ghost_components`); larger
            is more cautious, 0 disables the test.
        ghost_frames: consecutive frames a component must pass that test before the model
            takes the frame there (at 15 Hz, 5 frames = 0.33 s).
        people: the person cue that marks not-yet-known pixels at the online bootstrap
            (:class:`~.people.PeopleCue`, used by :class:`BackgroundBank` when it has the
            calibration); ``None`` learns every pixel of the bootstrap frames.
    """

    alpha: float = 0.97
    bootstrap_frames: int = 6
    bootstrap_stride: int = 1
    luma_threshold: float = 28.0
    chroma_threshold: float = 10.0
    shadow_ratio: tuple[float, float] | None = (0.55, 0.92)
    motion_threshold: float = 20.0
    motion_decay: float = 0.8
    motion_persistent: float = 2.0
    mask_dilation: int = 5
    open_size: int = 3
    close_size: int = 5
    min_blob_area: int = 0
    static_frames: int = 45
    static_alpha: float = 0.9
    unknown_frames: int = 15
    settle_frames: int = 20
    ghost_edge_ratio: float = 1.5
    ghost_frames: int = 5
    people: PeopleCueConfig | None = field(default_factory=PeopleCueConfig)

    def __post_init__(self) -> None:
        if not 0.0 <= self.alpha < 1.0:
            raise DetectionError(f'background alpha must be in [0, 1), got {self.alpha}')
        if self.bootstrap_frames < 1 or self.bootstrap_stride < 1:
            raise DetectionError('bootstrap_frames and bootstrap_stride must be >= 1')
        if not 0.0 <= self.static_alpha < 1.0:
            raise DetectionError(f'static_alpha must be in [0, 1), got {self.static_alpha}')
        if self.luma_threshold <= 0 or self.chroma_threshold <= 0:
            raise DetectionError('background thresholds must be positive')
        if not 0.0 <= self.motion_decay < 1.0:
            raise DetectionError('motion_decay must be in [0, 1)')
        if self.unknown_frames < 1 or self.settle_frames < 1:
            raise DetectionError('unknown_frames and settle_frames must be >= 1')
        if self.ghost_edge_ratio < 0 or self.ghost_frames < 1:
            raise DetectionError('ghost_edge_ratio must be >= 0 and ghost_frames >= 1')


# accumulated motion (decaying count of frame differences) above which a pixel moved
# recently (a few frames at ``motion_decay`` 0.8); see BackgroundModel.recent_motion
_RECENT_MOTION = 0.3

# smallest foreground component the ghost border test judges, pixels at 320x240 (scaled
# with the image): the smallest silhouette the detector considers (DetectorConfig.min_area)
_GHOST_MIN_AREA = 60

# not-yet-known pixel flags: not learnt; counts as foreground; has been covered by a track
_UNKNOWN, _POSSIBLE, _COVERED, _CORE = 1, 2, 4, 8


def _kernel(size: int) -> np.ndarray | None:
    if size <= 1:
        return None
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))


def clean_mask(mask: np.ndarray, *, open_size: int = 3, close_size: int = 5,
               min_area: int = 0) -> np.ndarray:
    """Morphological cleaning of a binary mask (H, W) -> (H, W) bool.

    Opening removes isolated pixels, closing fills small holes, and connected components
    (8-connected) smaller than ``min_area`` pixels are dropped.
    """
    m = np.asarray(mask).astype(np.uint8)
    k = _kernel(open_size)
    if k is not None:
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, k)
    k = _kernel(close_size)
    if k is not None:
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, k)
    if min_area > 1 and m.any():
        n, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        keep = stats[:, cv2.CC_STAT_AREA] >= min_area
        keep[0] = False
        m = keep[labels].astype(np.uint8)
    return m.astype(bool)


@njit(cache=True, nogil=True)
def _median_kernel(stack: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Per-pixel median of N frames (N, H, W, C) float32 -> (H, W, C) float32, exactly as
    ``np.median(stack, axis=0)`` (mean of the two middle values for even N): each pixel's
    N values (a handful of bootstrap frames) go through a branch-free bubble sort."""
    n = stack.shape[0]
    flat = stack.reshape(n, -1)
    out = np.empty(flat.shape[1], np.float32)
    buf = np.empty(n, np.float32)
    half = n // 2
    for q in range(flat.shape[1]):
        for a in range(n):
            buf[a] = flat[a, q]
        for a in range(n):
            for b in range(n - 1 - a):
                lo = min(buf[b], buf[b + 1])
                buf[b + 1] = max(buf[b], buf[b + 1])
                buf[b] = lo
        if n % 2 == 1:
            out[q] = buf[half]
        else:
            out[q] = (buf[half - 1] + buf[half]) / np.float32(2.0)
    return out.reshape(stack.shape[1:])


def median_frame(frames: Sequence[np.ndarray]) -> np.ndarray:
    """Per-pixel median (H, W, C) float32 of float32 frames (H, W, C) (compiled)."""
    return _median_kernel(np.ascontiguousarray(np.stack(frames), dtype=np.float32))


@njit(cache=True, nogil=True)
def _foreground_kernel(ycc: np.ndarray, bg: np.ndarray, gain: float, luma: float,
                       chroma: float, shadow_lo: float, shadow_hi: float
                       ) -> np.ndarray:  # pragma: no cover - compiled
    """Y-Cb-Cr test per pixel: (H, W) uint8 foreground (before morphology).

    Most pixels match the background: their squared chroma distance is below
    ``(chroma (1 - 1e-9))^2``, whose square root (rounded or not) is surely below
    ``chroma``, so they are decided without the square root (the same decisions)."""
    h, w = ycc.shape[:2]
    out = np.zeros((h, w), np.uint8)
    surely_close = (chroma * (1.0 - 1e-9)) ** 2
    for i in range(h):
        for j in range(w):
            by = max(bg[i, j, 0], 1.0)
            gy = gain * by
            y = ycc[i, j, 0]
            d1 = ycc[i, j, 1] - 128.0 - gain * (bg[i, j, 1] - 128.0)
            d2 = ycc[i, j, 2] - 128.0 - gain * (bg[i, j, 2] - 128.0)
            s = d1 * d1 + d2 * d2
            if abs(y - gy) <= luma and s < surely_close:
                continue  # background: neither test fires
            dc = np.sqrt(s)
            if abs(y - gy) > luma or dc > chroma:
                r = y / gy
                if shadow_lo < shadow_hi and shadow_lo <= r <= shadow_hi \
                        and dc <= 0.5 * chroma:
                    continue  # a shadow: darker, same chroma
                out[i, j] = 1
    return out


def _dilated_masks(moving: np.ndarray, exclude: np.ndarray | None,
                  kernel: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(dilate(moving | exclude), dilate(exclude)), (H, W) uint8 0/1 each, in one dilation.

    ``moving`` is (H, W) uint8 0/1, ``exclude`` (H, W) bool or None (no pixel), ``kernel``
    the structuring element (None: no dilation). Motion is coded 1 and excluded pixels 2;
    dilation takes the neighbourhood maximum, so the dilated code is >= 1 exactly where
    the dilation of either mask is set and >= 2 where that of ``exclude`` is."""
    code = moving if exclude is None else moving | (exclude.view(np.uint8) << 1)
    if kernel is not None and code.any():
        code = cv2.dilate(code, kernel)
    return (code >= 1).view(np.uint8), (code >= 2).view(np.uint8)


@njit(cache=True, nogil=True)
def _motion_kernel(y: np.ndarray, prev: np.ndarray, motion: np.ndarray, decay: float,
                   threshold: float, persistent: float) -> np.ndarray:  # pragma: no cover
    """Decaying accumulation of thresholded frame differences (in place); (H, W) uint8
    persistent-motion mask."""
    h, w = y.shape
    out = np.zeros((h, w), np.uint8)
    for i in range(h):
        for j in range(w):
            m = motion[i, j] * decay
            if abs(y[i, j] - prev[i, j]) > threshold:
                m += 1.0
            motion[i, j] = m
            if m >= persistent:
                out[i, j] = 1
    return out


@njit(cache=True, nogil=True)
def _blend_kernel(bg: np.ndarray, ycc: np.ndarray, frozen: np.ndarray, fg: np.ndarray,
                  static: np.ndarray, use_fg: bool, alpha: float, static_alpha: float,
                  static_frames: int, unknown: np.ndarray, occupied: np.ndarray,
                  expired: bool, raw: np.ndarray, moving: np.ndarray, changed: np.ndarray,
                  settle_frames: int) -> None:  # pragma: no cover - compiled
    """003 §4.2 temporal filter on the unfrozen pixels, in place.

    A not-yet-known pixel is learnt (set to the image) when it has shown a steady value
    other than its bootstrap one (``raw`` foreground without ``moving``) for
    ``settle_frames`` frames (whoever stood there has left it), or when it is outside the
    tracks (``occupied``) and either was covered by a track before or the wait has
    ``expired``."""
    h, w = frozen.shape
    for i in range(h):
        for j in range(w):
            if unknown[i, j]:
                static[i, j] = 0
                if raw[i, j] and not moving[i, j]:
                    changed[i, j] += 1
                else:
                    changed[i, j] = 0
                if changed[i, j] >= settle_frames:
                    unknown[i, j] = 0
                    changed[i, j] = 0
                    for c in range(3):
                        bg[i, j, c] = ycc[i, j, c]
                elif occupied[i, j]:
                    unknown[i, j] |= 4           # _COVERED
                elif (unknown[i, j] & 4) or expired:
                    unknown[i, j] = 0
                    for c in range(3):
                        bg[i, j, c] = ycc[i, j, c]
                continue
            if frozen[i, j]:
                static[i, j] = 0
                continue
            a = alpha
            if use_fg:
                if fg[i, j]:
                    if static[i, j] < 32000:
                        static[i, j] += 1
                    if static_frames > 0 and static[i, j] >= static_frames:
                        a = static_alpha
                else:
                    static[i, j] = 0
            for c in range(3):
                bg[i, j, c] = a * bg[i, j, c] + (1.0 - a) * ycc[i, j, c]


def _colour_gradient(ycc: np.ndarray, luma: float, chroma: float) -> np.ndarray:
    """(H, W) float32 colour gradient magnitude of a Y-Cb-Cr image (H, W, 3) float32: the
    Sobel magnitudes of Y, Cb and Cr, each divided by its foreground threshold, summed (one
    unit = a step the size of the foreground test per pixel)."""
    out = np.zeros(ycc.shape[:2], np.float32)
    for c, scale in ((0, 1.0 / luma), (1, 1.0 / chroma), (2, 1.0 / chroma)):
        plane = np.ascontiguousarray(ycc[..., c])
        gx = cv2.Sobel(plane, cv2.CV_32F, 1, 0, ksize=3)
        gy = cv2.Sobel(plane, cv2.CV_32F, 0, 1, ksize=3)
        out += np.float32(0.125 * scale) * cv2.magnitude(gx, gy)
    return out


def _gain_scaled(bg: np.ndarray, gain: float) -> np.ndarray:
    """A copy of model pixels (..., 3) float32 Y-Cb-Cr under the global gain, as the
    foreground test compares them: luminance times ``gain``, chroma offsets from 128 too."""
    scaled = bg.copy()
    scaled[..., 0] *= gain
    scaled[..., 1:] = 128.0 + gain * (scaled[..., 1:] - 128.0)
    return scaled


def ghost_components(fg: np.ndarray, ycc: np.ndarray, bg: np.ndarray, gain: float, *,
                     luma: float, chroma: float, ratio: float, min_area: int,
                     excluded: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool pixels of the foreground components that are ghosts (border test).

    A component (8-connected, of ``fg`` (H, W) bool) is a ghost when the summed colour
    gradient (:func:`_colour_gradient`) over its border band (dilated minus eroded by one
    pixel, 3 pixels wide across the border) is ``ratio`` times larger in the model ``bg``
    (H, W, 3) float32 Y-Cb-Cr, scaled by the global ``gain`` as in the foreground test, than
    in the frame ``ycc``: the outline is in the model, not in the frame. Border pixels in
    ``excluded`` (H, W) bool (whose model is not trusted) do not count, and a component
    with less than half of its border trusted, or of fewer than ``min_area`` pixels, is
    never a ghost. Vectorised: per-component sums by ``bincount``.
    """
    if ratio <= 0 or not fg.any():
        return np.zeros(fg.shape, bool)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(fg.view(np.uint8)
                                                           if fg.dtype == bool
                                                           else fg.astype(np.uint8),
                                                           connectivity=8)
    out = np.zeros(fg.shape, bool)
    area = stats[:, cv2.CC_STAT_AREA]
    big = np.flatnonzero(area[1:] >= min_area) + 1
    if not big.size:
        return out
    # only the bounding box of the components judged (with the border band and the
    # Sobel support around it) is looked at: the same sums, a fraction of the pixels
    h, w = fg.shape
    left, top = stats[big, cv2.CC_STAT_LEFT], stats[big, cv2.CC_STAT_TOP]
    x0, y0 = max(int(left.min()) - 3, 0), max(int(top.min()) - 3, 0)
    x1 = min(int((left + stats[big, cv2.CC_STAT_WIDTH]).max()) + 3, w)
    y1 = min(int((top + stats[big, cv2.CC_STAT_HEIGHT]).max()) + 3, h)
    win = (slice(y0, y1), slice(x0, x1))
    labels, fg = labels[win], np.ascontiguousarray(fg[win])
    k3 = np.ones((3, 3), np.uint8)
    grown = cv2.dilate(labels.astype(np.float32), k3)          # outer side of the border
    inner = fg & ~cv2.erode(fg.view(np.uint8), k3).astype(bool)
    band_label = np.where(inner, labels, np.where(fg, 0, grown.astype(np.int32)))
    band = band_label > 0
    whole = np.bincount(band_label[band], minlength=n)
    if excluded is not None and excluded.any():
        band &= ~excluded[win]
    scaled = _gain_scaled(bg[win], gain)
    g_frame = _colour_gradient(ycc[win], luma, chroma)
    g_model = _colour_gradient(scaled, luma, chroma)
    lab = band_label[band]
    frame_sum = np.bincount(lab, weights=g_frame[band], minlength=n)
    model_sum = np.bincount(lab, weights=g_model[band], minlength=n)
    trusted = np.bincount(lab, minlength=n)
    ghost = (model_sum > ratio * frame_sum) & (area >= min_area) & (2 * trusted >= whole)
    ghost[0] = False
    out[win] = ghost[labels]
    return out


def _mostly(mask: np.ndarray, flag: np.ndarray) -> np.ndarray:
    """(H, W) bool the 8-connected components of ``mask`` at least half of whose pixels
    have ``flag`` (H, W) bool set."""
    n, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
    size = np.bincount(labels[mask], minlength=n)
    hit = 2 * np.bincount(labels[mask & flag], minlength=n) >= np.maximum(size, 1)
    hit[0] = False
    return hit[labels]


def _whole_components(mask: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """(H, W) bool the 8-connected components of ``mask`` that contain a ``seeds`` pixel."""
    n, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
    hit = np.bincount(labels[seeds & mask], minlength=n) > 0
    hit[0] = False
    return hit[labels]


def _to_ycc(image: np.ndarray) -> np.ndarray:
    """RGB uint8 (H, W, 3) -> float32 (H, W, 3) with channels Y, Cb, Cr."""
    y, cr, cb = cv2.split(cv2.cvtColor(image, cv2.COLOR_RGB2YCrCb))
    # reorder the uint8 planes, then convert (the same values as fancy-indexing the float
    # image, which allocated and gathered a second float copy)
    return cv2.merge([y, cb, cr]).astype(np.float32)


def _check_image(image: np.ndarray, shape: tuple[int, int] | None, what: str) -> None:
    if not isinstance(image, np.ndarray) or image.ndim != 3 or image.shape[2] != 3 \
            or image.dtype != np.uint8:
        got = getattr(image, 'shape', type(image).__name__)
        raise DetectionError(f'{what}: expected an (H, W, 3) uint8 RGB image, got {got}')
    if shape is not None and image.shape[:2] != shape:
        raise DetectionError(
            f'{what}: image size {image.shape[1]}x{image.shape[0]} differs from the '
            f'background model {shape[1]}x{shape[0]}')


class BackgroundModel:
    """Background model of one camera.

    Call :meth:`apply` once per frame: it returns the cleaned foreground mask of the frame
    and then updates the model on the stable pixels. Until ``bootstrap_frames`` frames have
    been seen (and no :meth:`bootstrap` was called) :meth:`apply` returns ``None``.
    """

    def __init__(self, config: BackgroundConfig | None = None, *, name: str = '') -> None:
        self.config = config or BackgroundConfig()
        self.name = name
        self._bg: np.ndarray | None = None          # (H, W, 3) float32 Y, Cb, Cr
        self._pending: list[np.ndarray] = []         # bootstrap frames
        self._prev_y: np.ndarray | None = None
        self._motion: np.ndarray | None = None       # accumulated motion, float32
        self._static: np.ndarray | None = None       # frames of motionless foreground
        self._unknown: np.ndarray | None = None      # (H, W) uint8, 1 = not yet known
        self._unknown_age = 0                        # frames since pixels were marked
        self._changed: np.ndarray | None = None      # frames an unknown pixel kept a new value
        self._raw: np.ndarray | None = None          # the last foreground test before unknowns
        self._ghost_age: np.ndarray | None = None    # consecutive frames judged a ghost
        self._ghost: np.ndarray | None = None        # pixels the next update learns at once
        self._learn: np.ndarray | None = None        # ghost places found by the detection
        self._prev_fg: np.ndarray | None = None      # foreground of the last update
        self._came_tracked: np.ndarray | None = None  # foreground that arrived under a track
        self._seen = 0                               # frames offered for bootstrapping
        self.gain: float = 1.0                       # luminance gain of the last frame
        self._deferred: tuple | None = None          # (ycc, exclude, fg) of apply(defer=True)

    # -- state ----------------------------------------------------------------------------
    @property
    def ready(self) -> bool:
        """True once the model has been bootstrapped."""
        return self._bg is not None

    @property
    def shape(self) -> tuple[int, int] | None:
        return None if self._bg is None else self._bg.shape[:2]

    @property
    def background_ycc(self) -> np.ndarray:
        """The current model, (H, W, 3) float32 Y, Cb, Cr; raises if not bootstrapped."""
        self.update_pending()
        if self._bg is None:
            raise DetectionError(f'background model {self.name!r} is not bootstrapped')
        return self._bg

    @property
    def persistent_motion(self) -> np.ndarray:
        """(H, W) bool pixels with persistent motion (excluded from the update)."""
        self.update_pending()
        if self._motion is None:
            return np.zeros(self.shape or (0, 0), bool)
        return self._motion >= self.config.motion_persistent

    @property
    def unknown(self) -> np.ndarray:
        """(H, W) bool pixels not yet known (never seen empty, not learnt)."""
        return self._flagged(_UNKNOWN)

    @property
    def possible_foreground(self) -> np.ndarray:
        """(H, W) bool not-yet-known pixels that count as foreground (a possible person)."""
        return self._flagged(_POSSIBLE)

    @property
    def possible_foreground_as_tested(self) -> np.ndarray:
        """:attr:`possible_foreground` as the last foreground test used it (a deferred
        model update not applied, unlike the property)."""
        if self._unknown is None:
            return np.zeros(self.shape or (0, 0), bool)
        return (self._unknown & _POSSIBLE) > 0

    def _flagged(self, flag: int) -> np.ndarray:
        """(H, W) bool pixels carrying a not-yet-known ``flag`` (after a pending update)."""
        self.update_pending()
        if self._unknown is None:
            return np.zeros(self.shape or (0, 0), bool)
        return (self._unknown & flag) > 0

    def set_unknown(self, mask: np.ndarray, *, foreground: np.ndarray | None = None,
                    core: np.ndarray | None = None) -> None:
        """Mark pixels (H, W) bool as not yet known (in addition to those already marked).

        They are not learnt until seen empty: outside every track once a track has covered
        them (the person there was found and has left), or after ``unknown_frames`` frames
        when no track ever covered them (nobody was found there). Meanwhile the pixels of
        ``foreground`` (default: all of ``mask``) count as foreground, the others as
        neither foreground nor background (the model there may show a person); ``core``
        (default: ``foreground``) is where a person's presence is certain enough to
        replace motion (see :meth:`presence`).
        """
        self.update_pending()
        if self._bg is None:
            raise DetectionError(f'background model {self.name!r} is not bootstrapped')
        mask = np.asarray(mask, dtype=bool)
        fg = mask if foreground is None else np.asarray(foreground, dtype=bool)
        core = fg if core is None else np.asarray(core, dtype=bool) & fg
        for m, what in ((mask, 'unknown-pixel'), (fg, 'possible-foreground'),
                        (core, 'core')):
            if m.shape != self._bg.shape[:2]:
                raise DetectionError(
                    f'camera {self.name!r}: {what} mask shape {m.shape} differs from '
                    f'the background {self._bg.shape[:2]}')
        self._ensure_unknown()
        self._unknown[mask | fg] = _UNKNOWN
        self._unknown[fg] |= _POSSIBLE
        self._unknown[core] |= _CORE
        self._changed[mask | fg] = 0
        self._unknown_age = 0

    def _ensure_unknown(self) -> None:
        shape = self._bg.shape[:2]
        if self._unknown is None or self._unknown.shape != shape:
            self._unknown = np.zeros(shape, np.uint8)
            self._changed = np.zeros(shape, np.int16)

    def presence(self, level: float = _RECENT_MOTION) -> np.ndarray | None:
        """(H, W) bool pixels whose foreground cannot be a ghost (a background change left by
        someone who stood there when the model was learnt): recent motion (see
        :meth:`recent_motion`) or possible foreground never learnt; None before the model
        exists. The detector requires it of new people."""
        self.update_pending()
        moving = self.recent_motion(level)
        if moving is None or self._unknown is None:
            return moving
        return moving | ((self._unknown & _CORE) > 0)

    def recent_motion(self, level: float = _RECENT_MOTION) -> np.ndarray | None:
        """(H, W) bool pixels that moved in the last few frames (accumulated motion above
        ``level``), or None before the model exists."""
        self.update_pending()
        if self._motion is None:
            return None
        return self._motion >= level

    def bootstrap(self, frames: Sequence[np.ndarray]) -> None:
        """Initialise the model as the per-pixel median of empty-room RGB frames."""
        self.update_pending()
        frames = list(frames)
        if not frames:
            raise DetectionError('bootstrap needs at least one frame')
        for i, f in enumerate(frames):
            _check_image(f, frames[0].shape[:2], f'{self.name} bootstrap frame {i}')
        ycc = [_to_ycc(f) for f in frames]
        self._bg = median_frame(ycc)
        self._pending = []
        self._motion = np.zeros(self._bg.shape[:2], np.float32)
        self._prev_y = ycc[-1][..., 0]
        self._unknown = None

    # -- per frame ------------------------------------------------------------------------
    def foreground(self, image: np.ndarray) -> np.ndarray:
        """Cleaned foreground mask (H, W) bool of an RGB frame; does not update the model."""
        self.update_pending()
        _check_image(image, self.shape, f'camera {self.name!r}')
        return self._foreground(_to_ycc(image), judge_ghosts=False)

    def _foreground(self, ycc: np.ndarray, *, judge_ghosts: bool = True) -> np.ndarray:
        cfg = self.config
        bg = self.background_ycc
        # Global gain, robust to slow illumination changes: median I/B luminance ratio
        # (the foreground is assumed to cover less than half of the image). A gain scales
        # RGB, hence Y and the chroma offsets C - 128 alike.
        ratio = ycc[::4, ::4, 0] / np.maximum(bg[::4, ::4, 0], 1.0)
        self.gain = float(np.clip(np.median(ratio), 0.5, 2.0)) if ratio.size > 16 else 1.0
        lo, hi = cfg.shadow_ratio if cfg.shadow_ratio is not None else (1.0, 0.0)
        fg = _foreground_kernel(ycc, bg, self.gain, float(cfg.luma_threshold),
                                float(cfg.chroma_threshold), float(lo), float(hi))
        if self._unknown is not None and self._unknown.any():
            # not yet known: the model may show a person there, so the test is void; the
            # possible-person pixels are foreground, the others are not
            self._raw = fg.copy()
            fg[(self._unknown & _UNKNOWN) > 0] = 0
            fg[(self._unknown & _POSSIBLE) > 0] = 1
        h, w = fg.shape
        min_area = int(round(cfg.min_blob_area * (h * w) / (320.0 * 240.0)))
        fg = clean_mask(fg, open_size=cfg.open_size, close_size=cfg.close_size,
                        min_area=min_area)
        if not judge_ghosts:     # a look at the frame: leave the ghost counts alone
            return fg if self._ghost is None else fg & ~self._ghost
        return self._drop_ghosts(fg, ycc)

    def _drop_ghosts(self, fg: np.ndarray, ycc: np.ndarray) -> np.ndarray:
        """The foreground ``fg`` without the components that have been ghosts for
        ``ghost_frames`` frames (:func:`ghost_components`); those pixels are kept for the
        next model update, which sets the model to the frame there.

        Only the *still* foreground is tested (no recent motion, see
        :meth:`recent_motion`): a ghost does not move, and a person walking past or in
        front of it, whose outline is in the frame, would otherwise join its component.
        The border pixels that moved or are not yet known do not count."""
        cfg = self.config
        if cfg.ghost_edge_ratio <= 0:
            return fg
        h, w = fg.shape
        untrusted = np.zeros(fg.shape, bool) if self._motion is None \
            else self._motion >= _RECENT_MOTION
        if self._unknown is not None and self._unknown.any():
            untrusted |= self._unknown > 0
        still = fg & ~untrusted
        ghost = ghost_components(still, ycc, self._bg, self.gain,
                                 luma=float(cfg.luma_threshold),
                                 chroma=float(cfg.chroma_threshold),
                                 ratio=float(cfg.ghost_edge_ratio),
                                 min_area=int(round(_GHOST_MIN_AREA * (h * w)
                                                    / (320.0 * 240.0))),
                                 excluded=untrusted)
        if self._came_tracked is not None and ghost.any():
            # a component most of whose pixels arrived under a track is a tracked person
            # who came there (seated on a chair whose edges are in the model), not a ghost
            ghost &= ~_mostly(ghost, self._came_tracked)
        if self._ghost_age is None or self._ghost_age.shape != fg.shape:
            self._ghost_age = np.zeros(fg.shape, np.int16)
        self._ghost_age = np.where(ghost, np.minimum(self._ghost_age + 1, 32000), 0
                                   ).astype(np.int16)
        ripe = self._ghost_age >= cfg.ghost_frames
        if not ripe.any():
            self._ghost = None
            return fg
        # the whole (still) component goes: a ripe pixel's component is a ghost this frame
        self._ghost = _whole_components(ghost, ripe)
        return fg & ~self._ghost

    def outline_gradients(self, image: np.ndarray, foreground: np.ndarray, mask: np.ndarray,
                          *, width: int, exclude: np.ndarray | None = None
                          ) -> tuple[float, float, float]:
        """The border test of :func:`ghost_components` for the foreground of one
        silhouette: the foreground (H, W) bool within ``width`` pixels of ``mask`` (H, W)
        bool is cut out (foreground of people beside it stays outside), and the colour
        gradient (:func:`_colour_gradient`) over the border band of that cut (3 pixels
        across the border, not along the cut lines) is summed in the model (scaled by the
        global gain) and in ``image`` (H, W, 3) uint8 RGB. Band pixels in ``exclude`` (H,
        W) bool (other tracks' silhouettes) or not yet known do not count. Returns (model
        sum, frame sum, share of the band that counts); (0, 0, 0) before the model exists
        or without foreground there."""
        if self._bg is None or mask.shape != self._bg.shape[:2] or not mask.any():
            return 0.0, 0.0, 0.0
        cfg = self.config
        h, w = mask.shape
        rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
        pad = width + 3
        win = (slice(max(int(rows[0]) - pad, 0), min(int(rows[-1]) + pad + 1, h)),
               slice(max(int(cols[0]) - pad, 0), min(int(cols[-1]) + pad + 1, w)))
        k = np.ones((2 * width + 1, 2 * width + 1), np.uint8)
        region = cv2.dilate(np.ascontiguousarray(mask[win]).view(np.uint8), k)
        cut = (np.ascontiguousarray(foreground[win]).view(np.uint8) & region).astype(np.uint8)
        if not cut.any():
            return 0.0, 0.0, 0.0
        k3 = np.ones((3, 3), np.uint8)
        band = cv2.dilate(cut, k3).astype(bool) & ~cv2.erode(cut, k3).astype(bool)
        band &= cv2.erode(region, np.ones((5, 5), np.uint8)).astype(bool)   # not the cuts
        whole = int(band.sum())
        if exclude is not None and exclude.shape == mask.shape:
            band &= ~exclude[win]
        if self._unknown is not None and self._unknown.shape == mask.shape:
            band &= self._unknown[win] == 0
        if not whole or not band.any():
            return 0.0, 0.0, 0.0
        scaled = _gain_scaled(self._bg[win], self.gain)
        luma, chroma = float(cfg.luma_threshold), float(cfg.chroma_threshold)
        g_model = _colour_gradient(scaled, luma, chroma)[band].sum()
        g_frame = _colour_gradient(_to_ycc(np.ascontiguousarray(image[win])), luma,
                                   chroma)[band].sum()
        return float(g_model), float(g_frame), float(band.sum()) / whole

    def learn_next(self, mask: np.ndarray) -> None:
        """Set the model to the frame on ``mask`` (H, W) bool at the next update, as for a
        ghost (:meth:`_learn_ghosts`): a place the detection found to be a ghost."""
        if mask.shape != (self.shape or mask.shape):
            return
        self._learn = mask.copy() if self._learn is None else self._learn | mask

    def update(self, image: np.ndarray, *, exclude: np.ndarray | None = None) -> None:
        """Temporal filtering of the model on stable pixels only.

        Args:
            image: (H, W, 3) uint8 RGB frame.
            exclude: optional (H, W) bool mask of pixels not to update (e.g. rendered
                track silhouettes); persistent-motion pixels are always excluded.
        """
        self.update_pending()
        _check_image(image, self.shape, f'camera {self.name!r}')
        self._update(_to_ycc(image), exclude)

    def _update(self, ycc: np.ndarray, exclude: np.ndarray | None,
                fg: np.ndarray | None = None) -> None:
        cfg = self.config
        y = ycc[..., 0]
        if self._bg is None:
            if self._seen % cfg.bootstrap_stride == 0:
                self._pending.append(ycc)
            self._seen += 1
            if len(self._pending) >= cfg.bootstrap_frames:
                self._bg = median_frame(self._pending)
                self._pending = []
                self._motion = np.zeros(y.shape, np.float32)
            self._prev_y = y
            return
        if self._motion is None or self._prev_y is None:
            self._motion = np.zeros(y.shape, np.float32)
            self._prev_y = y
        # Persistent motion: decaying accumulation of thresholded frame differences.
        moving = _motion_kernel(y, self._prev_y, self._motion, float(cfg.motion_decay),
                                float(cfg.motion_threshold), float(cfg.motion_persistent))
        self._prev_y = y
        if exclude is not None:
            exclude = np.asarray(exclude, dtype=bool)
            if exclude.shape != y.shape:
                raise DetectionError(
                    f'camera {self.name!r}: exclusion mask shape {exclude.shape} differs '
                    f'from the image {y.shape}')
        # frozen: persistent motion or tracks; occupied: tracks alone (a not-yet-known pixel
        # is seen empty when no track covers it: motion next to a person who walks away
        # must not keep his bootstrap place unknown, a ghost); both dilated
        frozen, occupied = _dilated_masks(moving, exclude, _kernel(2 * cfg.mask_dilation + 1))
        if self._static is None or self._static.shape != y.shape:
            self._static = np.zeros(y.shape, np.int16)
        use_fg = fg is not None
        if use_fg:
            self._note_arrivals(fg, occupied)
        fgu = fg.view(np.uint8) if use_fg else frozen
        self._ensure_unknown()
        # 003 §4.2: B_t = alpha B_{t-1} + (1 - alpha) I_t on the stable pixels only.
        self._unknown_age += 1
        raw = self._raw if self._raw is not None and self._raw.shape == y.shape \
            else np.zeros(y.shape, np.uint8)
        _blend_kernel(self._bg, ycc, frozen, fgu, self._static, use_fg, float(cfg.alpha),
                      float(cfg.static_alpha), int(cfg.static_frames), self._unknown,
                      occupied, self._unknown_age >= cfg.unknown_frames, raw, moving,
                      self._changed, int(cfg.settle_frames))
        self._raw = None
        self._learn_ghosts(ycc)

    def _note_arrivals(self, fg: np.ndarray, occupied: np.ndarray) -> None:
        """Remember, per foreground pixel, whether it became foreground under a track (the
        dilated track silhouettes ``occupied``, (H, W) uint8) and has stayed under one
        since: a tracked person who walks somewhere and stands still brings his foreground
        with his track and keeps it covered; the place a learnt person reveals becomes
        foreground with no track over it, or under the track of that person walking away,
        which then leaves it (a track born on it later does not bring it)."""
        if self._came_tracked is None or self._came_tracked.shape != fg.shape:
            self._came_tracked = np.zeros(fg.shape, bool)
            self._prev_fg = np.zeros(fg.shape, bool)
        arrived = fg & ~self._prev_fg
        under = occupied.view(bool)
        self._came_tracked[arrived] = under[arrived]
        self._came_tracked &= fg & under
        self._prev_fg = fg.copy()

    def _learn_ghosts(self, ycc: np.ndarray) -> None:
        """Set the model to the frame on the ghost pixels found by the foreground test of
        this frame (dilated by ``mask_dilation``: the blurred rim of the learnt outline),
        whatever the tracks; they start afresh (no static count, no motion)."""
        ghost, self._ghost = self._ghost, None
        learn, self._learn = self._learn, None
        if learn is not None and learn.shape == ycc.shape[:2]:
            ghost = learn if ghost is None else ghost | learn
        if ghost is None or ghost.shape != ycc.shape[:2] or not ghost.any():
            return
        k = _kernel(2 * self.config.mask_dilation + 1)
        if k is not None:
            ghost = cv2.dilate(ghost.view(np.uint8), k).astype(bool)
        self._bg[ghost] = ycc[ghost]
        if self._static is not None:
            self._static[ghost] = 0
        if self._ghost_age is not None:
            self._ghost_age[ghost] = 0

    def apply(self, image: np.ndarray, *, exclude: np.ndarray | None = None,
              defer: bool = False) -> np.ndarray | None:
        """Foreground mask (H, W) bool of the frame, then the masked model update.

        With ``defer`` (and a bootstrapped model) the update is kept for
        :meth:`update_pending`, which a caller runs once the frame's result is out (lower
        latency; the foreground of the next frame is the same, since :meth:`apply` first
        runs an update still pending). Returns ``None`` while the model is still collecting
        bootstrap frames.
        """
        _check_image(image, self.shape, f'camera {self.name!r}')
        self.update_pending()
        ycc = _to_ycc(image)
        fg = self._foreground(ycc) if self._bg is not None else None
        if defer and fg is not None:
            self._deferred = (ycc, exclude, fg)
        else:
            self._update(ycc, exclude, fg)
        return fg

    @property
    def pending(self) -> bool:
        """True while the update of the last :meth:`apply` (with ``defer``) has not run."""
        return self._deferred is not None

    def update_pending(self) -> None:
        """Run the model update that :meth:`apply` deferred, if any (003 §4.2)."""
        if self._deferred is not None:
            ycc, exclude, fg = self._deferred
            self._deferred = None
            self._update(ycc, exclude, fg)

    def exclude_pending(self, exclude: np.ndarray | None) -> None:
        """Set the exclusion mask (H, W) bool of the deferred update, if one is pending.

        The foreground of a frame does not depend on the exclusion (the tracks' silhouettes
        only keep the model update off people), so a caller may run :meth:`apply` before the
        frame's tracks are known and hand their silhouettes in here afterwards."""
        if self._deferred is not None:
            ycc, _, fg = self._deferred
            self._deferred = (ycc, exclude, fg)

    def drop_pending(self) -> None:
        """Forget a deferred update (its frame was abandoned) and the foreground test it
        would have consumed."""
        self._deferred = None
        self._raw = None
        self._ghost = None


class BootstrapCue:
    """The online bootstrap's people cue over consecutive frame sets (003 §4.2 with
    :class:`~.people.PeopleCue`): keeps the last ``bootstrap_frames`` frame sets (every
    ``bootstrap_stride``-th) and gives the not-yet-known regions of the cameras whose model
    was just bootstrapped.

    The floor places (K, 2), metres, of the people it found there wait in :attr:`places`
    until the detection takes them (:meth:`take_places`) to initialise everybody present
    at once, rather than confirming them one by one over the following frames."""

    def __init__(self, calibration: RoomCalibration | None, config: BackgroundConfig) -> None:
        self.calibration = calibration
        self.config = config
        self._cue: PeopleCue | None = None
        self.frames: list[dict[str, np.ndarray]] = []
        self._seen = 0
        self.places: np.ndarray | None = None

    def take_places(self) -> np.ndarray | None:
        """The people's places (K, 2) of the last bootstrap not taken yet (then forgotten),
        or None."""
        places, self.places = self.places, None
        return places

    @property
    def enabled(self) -> bool:
        return self.calibration is not None and self.config.people is not None

    @property
    def cue(self) -> PeopleCue | None:
        """The people cue (built on first use: it rasterises a floor grid), or None."""
        if self._cue is None and self.enabled:
            self._cue = PeopleCue(self.calibration, self.config.people)
        return self._cue

    def keep(self, images: Mapping[str, np.ndarray], *, copy: bool = True) -> None:
        """Keep a frame set (camera -> (H, W, 3) uint8) for the cue."""
        cfg = self.config
        if self._seen % cfg.bootstrap_stride == 0:
            self.frames.append({n: np.array(im, copy=True) if copy else im
                                for n, im in images.items()})
        self._seen += 1
        self.frames = self.frames[-cfg.bootstrap_frames:]

    def regions(self, started: Sequence[str]
                ) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(region, body, core) masks (H, W) bool of each camera of ``started`` the cue
        places people in (:meth:`PeopleCue.regions`), from the frame sets kept."""
        places, regions = self.compute(started, self.frames)
        self.add_places(places)
        return regions

    def compute(self, started: Sequence[str], frames: Sequence[Mapping[str, np.ndarray]]
                ) -> tuple[np.ndarray | None, dict[str, tuple[np.ndarray, np.ndarray,
                                                             np.ndarray]]]:
        """(places (K, 2) m or None, regions of the cameras of ``started``) of the cue on
        the frame sets ``frames`` (those :meth:`keep` kept); changes nothing here, so it
        may run on another thread while frame sets are kept (then :meth:`add_places`)."""
        if not started or not frames or self.cue is None:
            return None, {}
        places = self.cue.places(frames)
        regions = self.cue.regions(frames, places=places)
        return places, {n: regions[n] for n in started if n in regions}

    def add_places(self, places: np.ndarray | None) -> None:
        """Add the people's places (K, 2) found by :meth:`compute` to those waiting for
        the detection (:meth:`take_places`), leaving out those within the cue's
        ``nms_radius`` of one already waiting."""
        if places is None:
            return
        self.places = places if self.places is None else np.concatenate([
            self.places, places[np.linalg.norm(places[:, None] - self.places[None], axis=2)
                                .min(axis=1, initial=np.inf) >= self.cue.config.nms_radius]])

    def clear(self) -> None:
        """Forget the frame sets kept (the places found stay until taken)."""
        self.frames = []


class BackgroundBank:
    """One :class:`BackgroundModel` per camera, created on first sight of a camera.

    Args:
        config: the models' parameters.
        calibration: the room; with it and ``config.people`` the online bootstrap marks the
            pixels of person-like places of the bootstrap frames as not yet known
            (:class:`~.people.PeopleCue`).
    """

    def __init__(self, config: BackgroundConfig | None = None, *,
                 calibration: RoomCalibration | None = None) -> None:
        self.config = config or BackgroundConfig()
        self.models: dict[str, BackgroundModel] = {}
        self.calibration = calibration
        self.bootstrap_cue = BootstrapCue(calibration, self.config)  # bootstrap frame sets

    @property
    def cue(self) -> PeopleCue | None:
        """The people cue (built on first use: it rasterises a floor grid), or None."""
        return self.bootstrap_cue.cue

    def prepare(self) -> None:
        """Build the people cue now (a node at start) rather than at the bootstrap frame."""
        _ = self.cue

    def model(self, name: str) -> BackgroundModel:
        if name not in self.models:
            self.models[name] = BackgroundModel(self.config, name=name)
        return self.models[name]

    def bootstrap(self, frames: Mapping[str, Sequence[np.ndarray]]) -> None:
        """Initialise cameras from empty-room frames ``{camera: [RGB frames]}``."""
        for name, fr in frames.items():
            self.model(name).bootstrap(fr)

    def apply(self, images: Mapping[str, np.ndarray], *,
              exclude: Mapping[str, np.ndarray] | None = None, defer: bool = False
              ) -> dict[str, np.ndarray]:
        """Foreground masks of all cameras that are bootstrapped (others are omitted).

        With ``defer`` the model updates of the bootstrapped cameras wait for
        :meth:`update_pending` (see :meth:`BackgroundModel.apply`; the same results)."""
        out: dict[str, np.ndarray] = {}
        started: list[str] = []
        for name, image in images.items():
            model = self.model(name)
            was_ready = model.ready
            fg = model.apply(image, exclude=None if exclude is None else exclude.get(name),
                             defer=defer)
            if fg is not None:
                out[name] = fg
            elif model.ready and not was_ready:
                started.append(name)
        cue = self.bootstrap_cue
        if cue.enabled and (started or not all(m.ready for m in self.models.values())):
            # keep the frame sets the models' bootstrap medians are made of
            cue.keep(images)
            for name, (region, body, core) in cue.regions(started).items():
                self.models[name].set_unknown(region, foreground=body, core=core)
            if all(m.ready for m in self.models.values()):
                cue.clear()
        return out

    def update_pending(self) -> None:
        """Run the model updates deferred by ``apply(..., defer=True)``."""
        for model in self.models.values():
            model.update_pending()

    def exclude_pending(self, exclude: Mapping[str, np.ndarray]) -> None:
        """Exclusion masks by camera for the deferred updates (see
        :meth:`BackgroundModel.exclude_pending`): ``apply(images, defer=True)`` followed by
        this gives the same models as ``apply(images, exclude=exclude, defer=True)``."""
        for name, model in self.models.items():
            model.exclude_pending(exclude.get(name))

    def drop_pending(self) -> None:
        """Forget the deferred updates (see :meth:`BackgroundModel.drop_pending`)."""
        for model in self.models.values():
            model.drop_pending()
