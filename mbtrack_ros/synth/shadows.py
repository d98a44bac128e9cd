"""Cast shadows of people from ceiling lamps (a real-room condition of ``mbtrack synth``).

A room surface point seen by a camera pixel (not a person's pixel) at ``P = C + d r``
(camera centre ``C``, unit ray ``r``, distance ``d``) is in the shadow of lamp ``l`` when the
segment from ``P`` to the lamp crosses a body ellipsoid; each lamp that is hidden takes its
share ``s_l`` of the light away: the radiance is multiplied by ``1 - sum s_l`` (a white
lamp: the shadow keeps the surface's chromaticity and texture and is darker).
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ['cast_shadows']


@njit(cache=True, nogil=True)
def _shadow_kernel(rays, origin, depth, ids, radiance, lamps, shares, to_unit, centers,
                   reach):  # pragma: no cover - compiled
    h, w = depth.shape
    n_lamps = lamps.shape[0]
    n_ell = centers.shape[0]
    for i in range(h):
        for j in range(w):
            if ids[i, j] != 0:
                continue
            d = depth[i, j]
            px = origin[0] + rays[i, j, 0] * d
            py = origin[1] + rays[i, j, 1] * d
            pz = origin[2] + rays[i, j, 2] * d
            factor = 1.0
            for lamp in range(n_lamps):
                sx = lamps[lamp, 0] - px
                sy = lamps[lamp, 1] - py
                sz = lamps[lamp, 2] - pz
                seg2 = sx * sx + sy * sy + sz * sz
                hidden = False
                for e in range(n_ell):
                    # quick reject: the segment's distance from the ellipsoid's bounding
                    # sphere centre
                    cx = centers[e, 0] - px
                    cy = centers[e, 1] - py
                    cz = centers[e, 2] - pz
                    t = (cx * sx + cy * sy + cz * sz) / seg2
                    t = min(1.0, max(0.0, t))
                    qx = cx - t * sx
                    qy = cy - t * sy
                    qz = cz - t * sz
                    if qx * qx + qy * qy + qz * qz > reach[e] * reach[e]:
                        continue
                    # exact: |o + s v|^2 = 1 in the ellipsoid's unit-sphere frame, s in (0, 1)
                    M = to_unit[e]
                    o0 = -(M[0, 0] * cx + M[0, 1] * cy + M[0, 2] * cz)
                    o1 = -(M[1, 0] * cx + M[1, 1] * cy + M[1, 2] * cz)
                    o2 = -(M[2, 0] * cx + M[2, 1] * cy + M[2, 2] * cz)
                    v0 = M[0, 0] * sx + M[0, 1] * sy + M[0, 2] * sz
                    v1 = M[1, 0] * sx + M[1, 1] * sy + M[1, 2] * sz
                    v2 = M[2, 0] * sx + M[2, 1] * sy + M[2, 2] * sz
                    a = v0 * v0 + v1 * v1 + v2 * v2
                    b = o0 * v0 + o1 * v1 + o2 * v2
                    c = o0 * o0 + o1 * o1 + o2 * o2 - 1.0
                    disc = b * b - a * c
                    if disc < 0.0:
                        continue
                    root = np.sqrt(disc)
                    s0 = (-b - root) / a
                    s1 = (-b + root) / a
                    if s1 > 1e-6 and s0 < 1.0:
                        hidden = True
                        break
                if hidden:
                    factor -= shares[lamp]
            if factor < 1.0:
                f = max(factor, 0.0)
                for ch in range(3):
                    radiance[i, j, ch] *= f


def cast_shadows(rays: np.ndarray, origin: np.ndarray, depth: np.ndarray, ids: np.ndarray,
                 radiance: np.ndarray, lamps: np.ndarray, shares: np.ndarray, ellipsoids
                 ) -> None:
    """Darken the room pixels of one camera's render in the people's shadows, in place.

    Args:
        rays: (H, W, 3) unit world rays of the pixels; origin: (3,) camera centre, metres.
        depth: (H, W) distance along the ray of the visible surface, metres.
        ids: (H, W) owner ids (0 = room: only those pixels receive shadows).
        radiance: (H, W, 3) float32 radiance (updated).
        lamps: (L, 3) lamp positions, metres; shares: (L,) share of the light of each.
        ellipsoids: the bodies (:class:`~mbtrack_ros.synth.body.Ellipsoids`).
    """
    if len(ellipsoids.centers) == 0 or len(lamps) == 0:
        return
    reach = np.asarray(ellipsoids.radii, dtype=np.float64).max(axis=1)
    _shadow_kernel(rays, np.asarray(origin, np.float64), depth, ids, radiance,
                   np.asarray(lamps, np.float64), np.asarray(shares, np.float64),
                   np.ascontiguousarray(ellipsoids.to_unit), np.ascontiguousarray(
                       ellipsoids.centers, dtype=np.float64), reach)
