"""Compiled per-pixel kernels of the renderer: hashing noise and ray-cast ellipsoids.

All kernels work on per-pixel world rays of one camera (unit directions, ``(H, W, 3)``
float64, from :meth:`Camera.pixel_rays`, so lens distortion is included) and a depth buffer
holding the Euclidean distance along the ray (metres) of the nearest surface so far.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ['TEX_NOISE', 'TEX_SOLID', 'TEX_STRIPES', 'draw_ellipsoids', 'expose', 'hash01']

TEX_SOLID, TEX_STRIPES, TEX_NOISE = 0, 1, 2


@njit(cache=True, nogil=True)
def _hash_scalar(ix: int, iy: int, iz: int, salt: int) -> float:
    """Deterministic pseudo-random value in [0, 1) of an integer lattice cell."""
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791) ^ (salt * 2654435761)
    h &= 0xFFFFFFFF
    h ^= h >> 16
    h = (h * 0x45D9F3B) & 0xFFFFFFFF
    h ^= h >> 16
    h = (h * 0x45D9F3B) & 0xFFFFFFFF
    h ^= h >> 16
    return h / 4294967296.0


@njit(cache=True)
def _hash_array(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray, salt: int) -> np.ndarray:
    out = np.empty(ix.size)
    for k in range(ix.size):
        out[k] = _hash_scalar(ix[k], iy[k], iz[k], salt)
    return out


def hash01(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray | None = None,
           salt: int = 0) -> np.ndarray:
    """Lattice hash of integer cell indices (same shapes) -> values in [0, 1), same shape."""
    ix = np.asarray(ix, dtype=np.int64)
    iy = np.broadcast_to(np.asarray(iy, dtype=np.int64), ix.shape)
    iz = np.zeros_like(ix) if iz is None else np.broadcast_to(
        np.asarray(iz, dtype=np.int64), ix.shape)
    out = _hash_array(np.ascontiguousarray(ix).ravel(), np.ascontiguousarray(iy).ravel(),
                      np.ascontiguousarray(iz).ravel(), int(salt))
    return out.reshape(ix.shape)


@njit(cache=True, nogil=True)
def draw_ellipsoids(rays: np.ndarray, origin: np.ndarray, depth: np.ndarray,
                    image: np.ndarray, ids: np.ndarray, to_unit: np.ndarray,
                    axes: np.ndarray, radii: np.ndarray, centers: np.ndarray,
                    bboxes: np.ndarray, owner: np.ndarray, colour1: np.ndarray,
                    colour2: np.ndarray, texture: np.ndarray, frequency: np.ndarray,
                    light: np.ndarray, ambient: float, diffuse: float) -> None:
    """Ray-cast P ellipsoids into one camera's buffers, z-tested, in place.

    Args:
        rays: (H, W, 3) unit world directions of the pixels.
        origin: (3,) camera centre, metres.
        depth: (H, W) float32 distance along the ray of the nearest surface (updated).
        image: (H, W, 3) float32 radiance 0..255 (updated).
        ids: (H, W) int16 owner id of each pixel, 0 = background (updated).
        to_unit: (P, 3, 3) world -> unit-sphere linear map ``diag(1/r) A^T``.
        axes: (P, 3, 3) columns = the ellipsoid's local axes in world coordinates.
        radii: (P, 3) semi-axes, metres.
        centers: (P, 3) centres, metres.
        bboxes: (P, 4) int ``u0, v0, u1, v1`` pixel window (exclusive ends) to scan.
        owner: (P,) id written into ``ids``.
        colour1, colour2: (P, 3) albedo 0..1 of the two texture colours.
        texture: (P,) TEX_SOLID / TEX_STRIPES / TEX_NOISE.
        frequency: (P,) stripes per metre along the local z axis, or noise cells per metre.
        light: (3,) point light position, metres.
        ambient, diffuse: Lambertian shading ``ambient + diffuse * max(0, n.l)``.
    """
    for p in range(centers.shape[0]):
        u0, v0, u1, v1 = bboxes[p, 0], bboxes[p, 1], bboxes[p, 2], bboxes[p, 3]
        if u1 <= u0 or v1 <= v0:
            continue
        M = to_unit[p]
        oc0 = origin[0] - centers[p, 0]
        oc1 = origin[1] - centers[p, 1]
        oc2 = origin[2] - centers[p, 2]
        o0 = M[0, 0] * oc0 + M[0, 1] * oc1 + M[0, 2] * oc2
        o1 = M[1, 0] * oc0 + M[1, 1] * oc1 + M[1, 2] * oc2
        o2 = M[2, 0] * oc0 + M[2, 1] * oc1 + M[2, 2] * oc2
        c = o0 * o0 + o1 * o1 + o2 * o2 - 1.0
        if c <= 0.0:
            continue  # camera inside the ellipsoid: not drawn
        r0, r1, r2 = radii[p, 0], radii[p, 1], radii[p, 2]
        for v in range(v0, v1):
            for u in range(u0, u1):
                d0, d1, d2 = rays[v, u, 0], rays[v, u, 1], rays[v, u, 2]
                e0 = M[0, 0] * d0 + M[0, 1] * d1 + M[0, 2] * d2
                e1 = M[1, 0] * d0 + M[1, 1] * d1 + M[1, 2] * d2
                e2 = M[2, 0] * d0 + M[2, 1] * d1 + M[2, 2] * d2
                a = e0 * e0 + e1 * e1 + e2 * e2
                b = o0 * e0 + o1 * e1 + o2 * e2
                disc = b * b - a * c
                if disc < 0.0:
                    continue
                s = (-b - np.sqrt(disc)) / a
                if s <= 0.0 or s >= depth[v, u]:
                    continue
                q0, q1, q2 = o0 + s * e0, o1 + s * e1, o2 + s * e2  # unit-sphere point
                # local normal of the ellipsoid surface is q / r; rotate to world
                m0, m1, m2 = q0 / r0, q1 / r1, q2 / r2
                n0 = axes[p, 0, 0] * m0 + axes[p, 0, 1] * m1 + axes[p, 0, 2] * m2
                n1 = axes[p, 1, 0] * m0 + axes[p, 1, 1] * m1 + axes[p, 1, 2] * m2
                n2 = axes[p, 2, 0] * m0 + axes[p, 2, 1] * m1 + axes[p, 2, 2] * m2
                nn = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
                h0 = origin[0] + s * d0
                h1 = origin[1] + s * d1
                h2 = origin[2] + s * d2
                l0, l1, l2 = light[0] - h0, light[1] - h1, light[2] - h2
                ln = np.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
                cosine = (n0 * l0 + n1 * l1 + n2 * l2) / (nn * ln)
                shade = ambient + diffuse * max(cosine, 0.0)
                # texture from the ellipsoid's local (metric) coordinates
                mix = 0.0
                kind = texture[p]
                if kind == TEX_STRIPES:
                    if np.sin(q2 * r2 * frequency[p] * 2.0 * np.pi) < 0.0:
                        mix = 1.0
                elif kind == TEX_NOISE:
                    f = frequency[p]
                    mix = _hash_scalar(int(np.floor(q0 * r0 * f)), int(np.floor(q1 * r1 * f)),
                                       int(np.floor(q2 * r2 * f)), p % 7)
                for ch in range(3):
                    col = (1.0 - mix) * colour1[p, ch] + mix * colour2[p, ch]
                    image[v, u, ch] = 255.0 * col * shade
                depth[v, u] = s
                ids[v, u] = owner[p]


@njit(cache=True, nogil=True)
def expose(radiance: np.ndarray, gain: np.ndarray, noise: np.ndarray,
           offset: int) -> np.ndarray:
    """Camera response: ``clip(radiance * gain + noise, 0, 255)`` rounded to uint8.

    Args:
        radiance: (H, W, 3) float32 scene radiance 0..255.
        gain: (3,) float32 channel gains (colour response x illumination).
        noise: (M,) float32 Gaussian noise bank; pixels use ``noise[offset:offset + H*W*3]``.
    Returns:
        (H, W, 3) uint8 image.
    """
    h, w, _ = radiance.shape
    out = np.empty((h, w, 3), dtype=np.uint8)
    k = offset
    for v in range(h):
        for u in range(w):
            for ch in range(3):
                value = radiance[v, u, ch] * gain[ch] + noise[k] + 0.5
                k += 1
                if value < 0.0:
                    value = 0.0
                elif value > 255.0:
                    value = 255.0
                out[v, u, ch] = np.uint8(value)
    return out
