"""Cast-shadow model: a darker pixel with the reference's chromaticity and texture is shadow.

The brightness/chromaticity distortion model of Horprasert, Harwood and Davis (ICCV
FRAME-RATE workshop 1999) as used for shadow suppression by Cucchiara et al. (PAMI 2003):
a pixel ``I`` (RGB) compared with a reference ``E`` (the background, or the previous frame)
has the brightness distortion

    alpha = (I . E) / (E . E)               (the scale of E closest to I)

and the chromaticity distortion ``CD = |I - alpha E| / |E|`` (distance from the line
through E, relative to E's brightness). A cast shadow of a white lamp scales the surface's
radiance: ``alpha`` in ``[lo, hi]`` (darker, not black) and ``CD`` small. Texture is the
third test (a shadow keeps the surface's texture, a person's body has its own): the
gradients of ``I`` and ``alpha E`` agree, tested as the local normalised cross-correlation
of the two luminance images over a small window (the patch of a shadow is the reference
patch scaled). Everything is vectorised (OpenCV box filters), no Python loop over pixels.

:func:`shadow_mask` classifies pixels against a reference; :func:`shadow_change` finds the
pixels whose change between two frames is a shadow arriving or leaving (so a moving
person's shadow is no motion of a person). A change is tested by its direction in RGB: the
light a cast shadow takes away has the surface's colour, so ``I - E`` points from ``E``
towards black, and its chromaticity distortion grows with the darkening,
``CD <= tan(angle) (1 - alpha)``. A pixel on the outline of a moving body is a mixture of
the body and the surface behind it (more so in an image shrunk from a larger one), which
changes towards the body's colour: with a small coverage both ``CD`` and ``1 - alpha`` are
small, so a bound on ``CD`` alone takes a neutral body's outline for a light shadow, the
bound on the angle does not (the angle does not depend on the coverage).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from mbtrack_ros.core.detection import DetectionError

__all__ = ['ShadowConfig', 'shadow_change', 'shadow_mask']


@dataclass(frozen=True)
class ShadowConfig:
    """Parameters of the shadow model.

    Attributes:
        brightness: (lo, hi) brightness distortion alpha of a shadow (darker than the
            reference, not black).
        chromaticity: largest chromaticity distortion CD of a shadow (relative to the
            reference's brightness; 0.08: 8 %).
        texture: smallest local normalised cross-correlation of the pixel's and the
            reference's luminance over ``window`` (0: texture not tested).
        window: side of the texture window, pixels at 320x240 (odd).
        min_level: reference brightness (0..255, per channel mean) below which no pixel is
            taken for a shadow (too dark to tell).
        change_angle: for a change between two frames (:func:`shadow_change`), the tangent
            of the largest angle between the change ``I - E`` and ``-E`` (the colour of
            the light a shadow takes away against the surface's overall light; 0.3: 17
            degrees); it replaces ``chromaticity`` there.
    """

    brightness: tuple[float, float] = (0.4, 0.92)
    chromaticity: float = 0.08
    texture: float = 0.5
    window: int = 5
    min_level: float = 15.0
    change_angle: float = 0.3

    def __post_init__(self) -> None:
        lo, hi = self.brightness
        if not 0 < lo < hi < 1:
            raise DetectionError(f'shadow brightness must be 0 < lo < hi < 1, got '
                                 f'{self.brightness}')
        if self.chromaticity <= 0 or not -1 <= self.texture <= 1 or self.window < 1 \
                or self.change_angle <= 0:
            raise DetectionError('shadow chromaticity and change_angle must be > 0, texture '
                                 'in [-1, 1], window >= 1')


def _distortions(image: np.ndarray, reference: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(alpha, CD, reference brightness) per pixel, (H, W) float32 each."""
    i = np.asarray(image, dtype=np.float32)
    e = np.asarray(reference, dtype=np.float32)
    ee = np.maximum((e * e).sum(axis=2), 1.0)
    alpha = (i * e).sum(axis=2) / ee
    resid = i - alpha[..., None] * e
    cd = np.sqrt((resid * resid).sum(axis=2) / ee)
    return alpha, cd, np.sqrt(ee / 3.0)


def _texture_agrees(image: np.ndarray, reference: np.ndarray, window: int) -> np.ndarray:
    """(H, W) float32 local normalised cross-correlation of the two luminance images."""
    a = cv2.cvtColor(np.asarray(image, np.uint8), cv2.COLOR_RGB2GRAY).astype(np.float32)
    b = cv2.cvtColor(np.asarray(reference, np.uint8), cv2.COLOR_RGB2GRAY).astype(np.float32)
    k = (int(window), int(window))
    ma, mb = cv2.blur(a, k), cv2.blur(b, k)
    cov = cv2.blur(a * b, k) - ma * mb
    va = cv2.blur(a * a, k) - ma * ma
    vb = cv2.blur(b * b, k) - mb * mb
    # flat patches (no texture to compare) agree: a shadow on a plain wall
    flat = (va < 4.0) & (vb < 4.0)
    ncc = cov / np.sqrt(np.maximum(va * vb, 1e-6))
    return np.where(flat, 1.0, ncc).astype(np.float32)


def shadow_mask(image: np.ndarray, reference: np.ndarray,
                config: ShadowConfig = ShadowConfig(), *, length_scale: float = 1.0
                ) -> np.ndarray:
    """(H, W) bool pixels of ``image`` that are a cast shadow on ``reference`` (both (H, W,
    3) RGB, uint8 or float 0..255): darker by a bounded factor, same chromaticity, same
    texture (module docstring). ``length_scale`` scales the texture window (the working
    size's factor against 320x240)."""
    if image.shape != reference.shape:
        raise DetectionError(f'shadow test: image {image.shape} and reference '
                             f'{reference.shape} differ')
    alpha, cd, level = _distortions(image, reference)
    lo, hi = config.brightness
    out = (alpha >= lo) & (alpha <= hi) & (cd <= config.chromaticity) \
        & (level >= config.min_level)
    if config.texture > -1.0 and out.any():
        window = max(1, 2 * int(round((config.window - 1) / 2 * length_scale)) + 1)
        out &= _texture_agrees(np.clip(image, 0, 255), np.clip(reference, 0, 255),
                               window) >= config.texture
    return out


def shadow_change(before: np.ndarray, after: np.ndarray,
                  config: ShadowConfig = ShadowConfig()) -> np.ndarray:
    """(H, W) bool pixels whose change from ``before`` to ``after`` is a shadow arriving
    (``after`` a shadow on ``before``) or leaving (the other way round): brightness
    distortion ``alpha`` in ``config.brightness`` and the change within
    ``config.change_angle`` of the reference's colour, ``CD <= change_angle (1 - alpha)``
    (module docstring). No texture test: the pixels that change are at a moving shadow's
    edge, which lies inside the texture window (a patch half in the shadow is no scaled
    copy)."""
    if before.shape != after.shape:
        raise DetectionError(f'shadow test: image {after.shape} and reference '
                             f'{before.shape} differ')
    lo, hi = config.brightness
    out = np.zeros(before.shape[:2], bool)
    for image, reference in ((after, before), (before, after)):
        alpha, cd, level = _distortions(image, reference)
        out |= (alpha >= lo) & (alpha <= hi) & (cd <= config.change_angle * (1.0 - alpha)) \
            & (level >= config.min_level)
    return out
