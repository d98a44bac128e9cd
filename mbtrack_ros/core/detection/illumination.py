"""Global illumination normalisation: per-frame colour gains against the background model.

Lights switched or dimmed, daylight, and the auto exposure and auto white balance of cheap
cameras change every pixel of an image at once. To first order such a change is a diagonal
(von Kries) transform of the colour channels: ``I_c = g_c R_c`` for the scene's radiance
``R`` under the reference illumination, one gain per channel ``c`` (R, G, B) and camera.
The gains are estimated per frame from the pixels the background model trusts (learnt,
not hidden by people) as a robust ratio of the image to the background,

    g_c = median_{u in T} I_c(u) / B_c(u),

with ``T`` the sampled, learnt, unsaturated pixels whose luminance ratio lies within
``inlier_ratio`` of the first, all-pixel median (people and other changed pixels give
scattered ratios, the background a tight cluster). Every image is then divided by its gains
before anything compares it with a model: the background test (003 §4.2), the motion
image, the appearance histograms of the likelihood (000 Eq. 33) and the models acquired
from it all see the scene under the reference illumination, so a global change creates no
foreground and leaves the people's colours where their models expect them. The background
model is updated with the normalised images and so keeps the reference illumination.

Images are ``(H, W, 3) uint8`` RGB; the background is the model's Y-Cb-Cr float image.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np

from mbtrack_ros.core.detection import DetectionError

__all__ = ['IlluminationConfig', 'IlluminationNormaliser', 'colour_gains', 'ycc_to_rgb']


@dataclass(frozen=True)
class IlluminationConfig:
    """Parameters of the colour-gain estimate.

    Attributes:
        stride: every ``stride``-th pixel of every ``stride``-th row is sampled.
        min_level: background channel value (0..255) below which a sample is not used for
            that channel (ratios of dark values are noise).
        max_level: image value at or above which a sample is saturated (not used).
        inlier_ratio: relative distance of a sample's luminance ratio from the first median
            within which it counts as background (0.25: within 25 %).
        min_samples: fewer usable samples leave the image as it is (gains 1).
        gain_range: (lo, hi) bounds of a gain (a darker or brighter change than that is
            not an illumination change a normalisation should undo).
        deadband: gains all within this of 1 leave the image as it is: the background
            test's own global luminance gain and thresholds absorb a slow drift of a few
            per cent, and the image is not requantised for it (0.05).
    """

    stride: int = 4
    min_level: float = 12.0
    max_level: float = 250.0
    inlier_ratio: float = 0.25
    min_samples: int = 64
    gain_range: tuple[float, float] = (0.25, 4.0)
    deadband: float = 0.05

    def __post_init__(self) -> None:
        if int(self.stride) < 1:
            raise DetectionError(f'illumination stride must be >= 1, got {self.stride}')
        lo, hi = self.gain_range
        if not 0 < lo < 1 < hi:
            raise DetectionError(f'gain_range must be (lo < 1 < hi), got {self.gain_range}')
        if not 0 < self.inlier_ratio < 1:
            raise DetectionError(f'inlier_ratio must be in (0, 1), got {self.inlier_ratio}')


def ycc_to_rgb(ycc: np.ndarray) -> np.ndarray:
    """Y-Cb-Cr (..., 3) float (channels Y, Cb, Cr as the background model keeps them, the
    JPEG / OpenCV YCrCb definition) to RGB (..., 3) float, 0..255 (not clipped)."""
    y = ycc[..., 0]
    cb = ycc[..., 1] - 128.0
    cr = ycc[..., 2] - 128.0
    return np.stack([y + 1.403 * cr, y - 0.714 * cr - 0.344 * cb, y + 1.773 * cb], axis=-1)


def colour_gains(image: np.ndarray, background_rgb: np.ndarray,
                 trusted: np.ndarray | None = None,
                 config: IlluminationConfig = IlluminationConfig()) -> np.ndarray:
    """The per-channel gains (3,) of ``image`` against ``background_rgb`` (module docstring).

    Args:
        image: (h, w, 3) image samples, RGB 0..255 (any numeric type).
        background_rgb: (h, w, 3) float background at the same samples.
        trusted: (h, w) bool samples the model has learnt (None: all).
        config: estimate parameters.

    Returns:
        (3,) float64 gains; ones when there are too few usable samples.
    """
    img = np.asarray(image, dtype=np.float64).reshape(-1, 3)
    bg = np.asarray(background_rgb, dtype=np.float64).reshape(-1, 3)
    usable = (bg >= config.min_level).all(axis=1) & (img < config.max_level).all(axis=1)
    if trusted is not None:
        usable &= np.asarray(trusted, dtype=bool).reshape(-1)
    if np.count_nonzero(usable) < config.min_samples:
        return np.ones(3)
    img, bg = img[usable], bg[usable]
    ratio = img / bg
    luma = ratio @ np.array([0.299, 0.587, 0.114])
    first = float(np.median(luma))
    inliers = np.abs(luma - first) <= config.inlier_ratio * first
    if np.count_nonzero(inliers) < config.min_samples:
        return np.ones(3)
    gains = np.median(ratio[inliers], axis=0)
    lo, hi = config.gain_range
    return np.clip(gains, lo, hi)


class IlluminationNormaliser:
    """Divides each camera's image by its colour gains against the background model.

    Args:
        bank: the :class:`~.background.BackgroundBank` whose models are the reference
            (read only: ``ready``, ``background_ycc``, ``unknown``).
        config: estimate parameters.
    """

    def __init__(self, bank, config: IlluminationConfig | None = None) -> None:
        self.bank = bank
        self.config = config or IlluminationConfig()
        #: camera name -> the gains (3,) of the last normalised frame
        self.gains: dict[str, np.ndarray] = {}

    def reset(self) -> None:
        self.gains.clear()

    def normalise(self, images: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``images`` divided by their cameras' gains (cameras without a ready model, or
        gains within the dead band of 1, pass as they are)."""
        out: dict[str, np.ndarray] = {}
        s = int(self.config.stride)
        for name, image in images.items():
            model = self.bank.models.get(name)
            if model is None or not model.ready or model.shape != image.shape[:2]:
                out[name] = image
                continue
            sample = image[::s, ::s]
            bg = ycc_to_rgb(model.background_ycc[::s, ::s])
            unknown = model.unknown
            trusted = None if unknown is None else ~unknown[::s, ::s]
            gains = colour_gains(sample, bg, trusted, self.config)
            self.gains[name] = gains
            if np.all(np.abs(gains - 1.0) <= self.config.deadband):
                out[name] = image
                continue
            out[name] = _divide(image, gains)
        return out


def _divide(image: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """``image / gains`` per channel, rounded and clipped to uint8 (one lookup table per
    channel)."""
    levels = np.arange(256, dtype=np.float64)
    lut = np.clip(np.rint(levels[:, None] / gains[None, :]), 0, 255).astype(np.uint8)
    # cv2.LUT with a 3-channel table maps each channel through its own column
    return cv2.LUT(np.ascontiguousarray(image), lut.reshape(256, 1, 3))
