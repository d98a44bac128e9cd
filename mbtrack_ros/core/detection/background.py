"""Adaptive per-camera background model in Y-Cb-Cr and foreground extraction (003 §4.2).

The model of one camera is bootstrapped as the per-pixel median of a few empty-room frames
(or of the first frames of a recording) and then follows slow scene changes with the
temporal filter of 003 §4.2, ``B_t = alpha B_{t-1} + (1 - alpha) I_t``, applied only on
*stable* pixels: pixels with persistent motion (accumulated frame differences, dilated) and
pixels covered by the current tracks (label images rendered from the track estimates,
passed in as masks) are left untouched, so that a person standing still while tracked does
not fade into the background.

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
from dataclasses import dataclass

import cv2
import numpy as np

from mbtrack_ros.core.detection import DetectionError

__all__ = ['BackgroundBank', 'BackgroundConfig', 'BackgroundModel', 'clean_mask']


@dataclass(frozen=True)
class BackgroundConfig:
    """Parameters of the background model (all per frame, images 8-bit).

    Attributes:
        alpha: temporal filter memory of 003 §4.2 (``B = alpha B + (1 - alpha) I``).
        bootstrap_frames: frames whose median initialises the model when none is given.
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
    """

    alpha: float = 0.97
    bootstrap_frames: int = 5
    luma_threshold: float = 28.0
    chroma_threshold: float = 10.0
    shadow_ratio: tuple[float, float] | None = (0.55, 0.92)
    motion_threshold: float = 20.0
    motion_decay: float = 0.8
    motion_persistent: float = 2.0
    mask_dilation: int = 5
    open_size: int = 3
    close_size: int = 5
    min_blob_area: int = 40

    def __post_init__(self) -> None:
        if not 0.0 <= self.alpha < 1.0:
            raise DetectionError(f'background alpha must be in [0, 1), got {self.alpha}')
        if self.bootstrap_frames < 1:
            raise DetectionError('bootstrap_frames must be >= 1')
        if self.luma_threshold <= 0 or self.chroma_threshold <= 0:
            raise DetectionError('background thresholds must be positive')
        if not 0.0 <= self.motion_decay < 1.0:
            raise DetectionError('motion_decay must be in [0, 1)')


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


def _to_ycc(image: np.ndarray) -> np.ndarray:
    """RGB uint8 (H, W, 3) -> float32 (H, W, 3) with channels Y, Cb, Cr."""
    ycrcb = cv2.cvtColor(image, cv2.COLOR_RGB2YCrCb).astype(np.float32)
    return ycrcb[..., [0, 2, 1]]


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
        self.gain: float = 1.0                       # luminance gain of the last frame

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
        if self._bg is None:
            raise DetectionError(f'background model {self.name!r} is not bootstrapped')
        return self._bg

    @property
    def persistent_motion(self) -> np.ndarray:
        """(H, W) bool pixels with persistent motion (excluded from the update)."""
        if self._motion is None:
            return np.zeros(self.shape or (0, 0), bool)
        return self._motion >= self.config.motion_persistent

    def bootstrap(self, frames: Sequence[np.ndarray]) -> None:
        """Initialise the model as the per-pixel median of empty-room RGB frames."""
        frames = list(frames)
        if not frames:
            raise DetectionError('bootstrap needs at least one frame')
        for i, f in enumerate(frames):
            _check_image(f, frames[0].shape[:2], f'{self.name} bootstrap frame {i}')
        stack = np.stack([_to_ycc(f) for f in frames])
        self._bg = np.median(stack, axis=0).astype(np.float32)
        self._pending = []
        self._motion = np.zeros(self._bg.shape[:2], np.float32)
        self._prev_y = stack[-1, ..., 0]

    # -- per frame ------------------------------------------------------------------------
    def foreground(self, image: np.ndarray) -> np.ndarray:
        """Cleaned foreground mask (H, W) bool of an RGB frame; does not update the model."""
        _check_image(image, self.shape, f'camera {self.name!r}')
        return self._foreground(_to_ycc(image))

    def _foreground(self, ycc: np.ndarray) -> np.ndarray:
        cfg = self.config
        bg = self.background_ycc
        by = np.maximum(bg[..., 0], 1.0)
        y = ycc[..., 0]
        # Global gain, robust to slow illumination changes: median I/B luminance ratio
        # (the foreground is assumed to cover less than half of the image). A gain scales
        # RGB, hence Y and the chroma offsets C - 128 alike.
        ratio = y / by
        sub = ratio[::4, ::4]
        self.gain = float(np.clip(np.median(sub), 0.5, 2.0)) if sub.size > 16 else 1.0
        g = self.gain
        gy = g * by
        dc = np.hypot(ycc[..., 1] - 128.0 - g * (bg[..., 1] - 128.0),
                      ycc[..., 2] - 128.0 - g * (bg[..., 2] - 128.0))
        fg = (np.abs(y - gy) > cfg.luma_threshold) | (dc > cfg.chroma_threshold)
        if cfg.shadow_ratio is not None:
            lo, hi = cfg.shadow_ratio
            r = y / gy
            shadow = (r >= lo) & (r <= hi) & (dc <= 0.5 * cfg.chroma_threshold)
            fg &= ~shadow
        h, w = fg.shape
        min_area = int(round(cfg.min_blob_area * (h * w) / (320.0 * 240.0)))
        return clean_mask(fg, open_size=cfg.open_size, close_size=cfg.close_size,
                          min_area=min_area)

    def update(self, image: np.ndarray, *, exclude: np.ndarray | None = None) -> None:
        """Temporal filtering of the model on stable pixels only.

        Args:
            image: (H, W, 3) uint8 RGB frame.
            exclude: optional (H, W) bool mask of pixels not to update (e.g. rendered
                track silhouettes); persistent-motion pixels are always excluded.
        """
        _check_image(image, self.shape, f'camera {self.name!r}')
        self._update(_to_ycc(image), exclude)

    def _update(self, ycc: np.ndarray, exclude: np.ndarray | None) -> None:
        cfg = self.config
        y = ycc[..., 0]
        if self._bg is None:
            self._pending.append(ycc)
            if len(self._pending) >= cfg.bootstrap_frames:
                stack = np.stack(self._pending)
                self._bg = np.median(stack, axis=0).astype(np.float32)
                self._pending = []
                self._motion = np.zeros(y.shape, np.float32)
            self._prev_y = y
            return
        # Persistent motion: decaying accumulation of thresholded frame differences.
        moved = np.abs(y - self._prev_y) > cfg.motion_threshold if self._prev_y is not None \
            else np.zeros(y.shape, bool)
        self._motion *= cfg.motion_decay
        self._motion += moved.astype(np.float32)
        self._prev_y = y
        frozen = (self._motion >= cfg.motion_persistent).astype(np.uint8)
        if exclude is not None:
            exclude = np.asarray(exclude, dtype=bool)
            if exclude.shape != y.shape:
                raise DetectionError(
                    f'camera {self.name!r}: exclusion mask shape {exclude.shape} differs '
                    f'from the image {y.shape}')
            frozen |= exclude.astype(np.uint8)
        k = _kernel(2 * cfg.mask_dilation + 1)
        if k is not None and frozen.any():
            frozen = cv2.dilate(frozen, k)
        # 003 §4.2: B_t = alpha B_{t-1} + (1 - alpha) I_t on the stable pixels only.
        blended = cv2.addWeighted(self._bg, cfg.alpha, ycc, 1.0 - cfg.alpha, 0.0)
        keep = frozen.astype(bool)
        blended[keep] = self._bg[keep]
        self._bg = blended

    def apply(self, image: np.ndarray, *, exclude: np.ndarray | None = None
              ) -> np.ndarray | None:
        """Foreground mask (H, W) bool of the frame, then the masked model update.

        Returns ``None`` while the model is still collecting bootstrap frames.
        """
        _check_image(image, self.shape, f'camera {self.name!r}')
        ycc = _to_ycc(image)
        fg = self._foreground(ycc) if self._bg is not None else None
        self._update(ycc, exclude)
        return fg


class BackgroundBank:
    """One :class:`BackgroundModel` per camera, created on first sight of a camera."""

    def __init__(self, config: BackgroundConfig | None = None) -> None:
        self.config = config or BackgroundConfig()
        self.models: dict[str, BackgroundModel] = {}

    def model(self, name: str) -> BackgroundModel:
        if name not in self.models:
            self.models[name] = BackgroundModel(self.config, name=name)
        return self.models[name]

    def bootstrap(self, frames: Mapping[str, Sequence[np.ndarray]]) -> None:
        """Initialise cameras from empty-room frames ``{camera: [RGB frames]}``."""
        for name, fr in frames.items():
            self.model(name).bootstrap(fr)

    def apply(self, images: Mapping[str, np.ndarray], *,
              exclude: Mapping[str, np.ndarray] | None = None
              ) -> dict[str, np.ndarray]:
        """Foreground masks of all cameras that are bootstrapped (others are omitted)."""
        out: dict[str, np.ndarray] = {}
        for name, image in images.items():
            fg = self.model(name).apply(image, exclude=None if exclude is None
                                        else exclude.get(name))
            if fg is not None:
                out[name] = fg
        return out
