"""Private numba kernels of the shape, appearance and likelihood modules.

Everything here works on *row spans*: a silhouette is a list of ``(row, x0, x1, part)``
with ``x1`` exclusive and ``part`` in 1 (head), 2 (torso), 3 (legs); spans of particle ``i``
are ``[offsets[i], offsets[i + 1])``. No pixel is ever visited by a Python loop.

Histograms are flat ``(3 * 512,)`` float64 arrays (part-major). To avoid clearing 1536 bins
per particle, accumulation records the bins it touched and the distance routine resets
exactly those (``touched``/``mark`` scratch arrays).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from mbtrack_ros.core.state import SIT, THETA, X, Y

__all__: list[str] = []

N_BINS = 512
N_PARTS = 3


# -- camera and appearance helpers ------------------------------------------------------------
@njit(cache=True, nogil=True)
def _project_one(px, py, pz, rot, t, kmat, dist):
    """One world point -> distorted pixel (u, v): the arithmetic of OpenCV's
    ``projectPoints`` in its order (world -> camera with ``rot``, divide by z (1 if z == 0),
    radial k1 k2 k3 and tangential p1 p2 terms, then K), so that with ``rot`` the matrix
    OpenCV rebuilds from the Rodrigues vector the pixels are the same bits."""
    xc = rot[0, 0] * px + rot[0, 1] * py + rot[0, 2] * pz + t[0]
    yc = rot[1, 0] * px + rot[1, 1] * py + rot[1, 2] * pz + t[1]
    zc = rot[2, 0] * px + rot[2, 1] * py + rot[2, 2] * pz + t[2]
    iz = 1.0 / zc if zc != 0.0 else 1.0
    x = xc * iz
    y = yc * iz
    r2 = x * x + y * y
    r4 = r2 * r2
    r6 = r4 * r2
    a1 = 2 * x * y
    a2 = r2 + 2 * x * x
    a3 = r2 + 2 * y * y
    cdist = 1 + dist[0] * r2 + dist[1] * r4 + dist[4] * r6
    # OpenCV's rational and thin-prism terms, all zero for plumb_bob (kept for the order)
    icdist2 = 1.0 / (1 + 0.0 * r2 + 0.0 * r4 + 0.0 * r6)
    xd = x * cdist * icdist2 + dist[2] * a1 + dist[3] * a2 + 0.0 * r2 + 0.0 * r4
    yd = y * cdist * icdist2 + dist[2] * a3 + dist[3] * a1 + 0.0 * r2 + 0.0 * r4
    return xd * kmat[0, 0] + kmat[0, 2], yd * kmat[1, 1] + kmat[1, 2]


@njit(cache=True, nogil=True)
def project_points(points, rot, t, kmat, dist):
    """Pinhole projection with plumb_bob distortion of points (M, 3) -> (M, 2) pixels
    (:func:`_project_one`); points behind the camera are masked by :meth:`Camera.project`.
    """
    n = points.shape[0]
    out = np.empty((n, 2))
    for i in range(n):
        out[i, 0], out[i, 1] = _project_one(points[i, 0], points[i, 1], points[i, 2], rot, t,
                                            kmat, dist)
    return out


@njit(cache=True, nogil=True)
def quantize_rgb(image):
    """(H, W, 3) C-contiguous uint8 RGB -> (H, W) int16 bins
    ``(r >> 5) * 64 + (g >> 5) * 8 + (b >> 5)`` (one pass over the flat pixels)."""
    h, w = image.shape[0], image.shape[1]
    flat = image.reshape(h * w * 3)
    out = np.empty(h * w, np.int16)
    for i in range(h * w):
        out[i] = (flat[3 * i] >> 5) * 64 + (flat[3 * i + 1] >> 5) * 8 + (flat[3 * i + 2] >> 5)
    return out.reshape(h, w)


@njit(cache=True, nogil=True)
def wrap_angle(a):
    """An angle wrapped to [-pi, pi)."""
    return np.mod(a + np.pi, 2.0 * np.pi) - np.pi


@njit(cache=True, nogil=True, inline='always')
def relative_orientation(theta, x, y, centre):
    """Body orientation ``theta`` of a person at floor point (x, y) relative to the direction
    towards the camera centre (0 = facing it; not wrapped): ``Camera.viewing_angle`` in a
    kernel."""
    return theta - np.arctan2(centre[1] - y, centre[0] - x)


@njit(cache=True, nogil=True)
def nearest_two_views(rel, target, view_angles, n_views, va, vb, wa):
    """003 Eq. 1-2 for relative angles rel (N,) of models target (N,): the two key views of
    ``view_angles[target[i], :n_views[target[i]]]`` nearest in wrapped angle (ties to the
    lower index, as a stable sort) into va, vb (N,) int64, and the weight of va
    ``d_b / (d_a + d_b)`` (1 if both are 0) into wa (N,); a model with one key view: itself.
    """
    for i in range(rel.shape[0]):
        k = target[i]
        nv = n_views[k]
        if nv == 1:
            va[i] = 0
            vb[i] = 0
            wa[i] = 1.0
            continue
        ia = -1
        ib = -1
        da = np.inf
        db = np.inf
        for v in range(nv):
            d = np.abs(wrap_angle(rel[i] - view_angles[k, v]))
            if ia < 0 or d < da:
                ib = ia
                db = da
                ia = v
                da = d
            elif ib < 0 or d < db:
                ib = v
                db = d
        total = da + db
        va[i] = ia
        vb[i] = ib
        wa[i] = db / total if total > 0 else 1.0


# -- rasterisation ----------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def _outline_one(i, bx, by, tx, ty, d0, d1, sit, frac, half, parts, hip, width, scale, fx, fy,
                 left, right, seg_part):
    """Outline points left/right of the body axis of particle i at the profile heights
    (003 §2.1), from its projected axis ends (b: bottom, t: top) and their optical depths
    d0, d1, into left/right[i] (P, 2) and seg_part[i] (P - 1,) (0: dropped segment).

    ``frac`` (P,) profile height fractions, ``half`` (P,) half-width fractions, ``parts``
    (P - 1,) segment parts, ``hip`` the hip height fraction, ``width`` the body width
    (metres), ``scale`` s(o) (:func:`width_scale`), ``fx, fy`` the focal lengths in pixels
    (``K[0, 0], K[1, 1]``). A standing axis runs
    from the feet to the head top (height fraction f = frac); a sitting one from the hip to
    the head top, f = (frac - hip) / (1 - hip) clipped at 0, and its segments below the hip
    (the legs) are dropped. The image position of the axis point at fraction f is placed on
    the segment with the perspective-correct fraction ``f d1 / ((1 - f) d0 + f d1)`` (exact
    for a pinhole camera, depth being linear along the axis); offsets are half-width *
    f_n / depth * s, perpendicular to the bottom -> top image direction n, with
    f_n = 1 / sqrt((n_x / fx)^2 + (n_y / fy)^2) the focal length along n (fx along a
    vertical axis; every direction's f with square pixels), so that a camera with
    non-square pixels (an image resized to another aspect ratio) draws bodies as wide as
    they are.

    Returns False (nothing written but seg_part) if an end is behind the camera (depth <=
    1 mm) or its image point is not finite."""
    npts = frac.shape[0]
    for j in range(npts - 1):
        seg_part[i, j] = 0 if (sit and frac[j] < hip - 1e-12) else parts[j]
    if not (d0 > 1e-3 and d1 > 1e-3 and np.isfinite(bx) and np.isfinite(by)
            and np.isfinite(tx) and np.isfinite(ty)):
        return False
    dx = tx - bx
    dy = ty - by
    norm = np.sqrt(dx * dx + dy * dy)
    if norm > 1e-9:
        nx = -dy / norm
        ny = dx / norm
    else:                                   # camera looking straight down the axis
        nx = 1.0
        ny = 0.0
    focal = 1.0 / np.sqrt((nx / fx) ** 2 + (ny / fy) ** 2)
    for j in range(npts):
        fj = frac[j]
        if sit:
            fj = max((fj - hip) / (1.0 - hip), 0.0)
        dep = (1.0 - fj) * d0 + fj * d1
        g = fj * d1 / dep
        ax = bx + g * dx
        ay = by + g * dy
        off = half[j] * width * focal / dep * scale
        left[i, j, 0] = ax - nx * off
        left[i, j, 1] = ay - ny * off
        right[i, j, 0] = ax + nx * off
        right[i, j, 1] = ay + ny * off
    return True


@njit(cache=True, nogil=True)
def width_scale(rel):
    """003 §2.1: profile width factor s(o) = 0.7 + 0.3 |cos o| of the body orientation o
    relative to the camera (a number or an array)."""
    return 0.7 + 0.3 * np.abs(np.cos(rel))


@njit(cache=True, nogil=True)
def body_outline(ends, end_depth, theta, sitting, frac, half, parts, hip, width, rot, t, kmat,
                 dist, centre):
    """The body outlines of N particles in one camera (003 §2.1): per particle the projection
    of its axis ends (the operations of ``Camera.project``), s(o) of its orientation relative
    to the camera (``Camera.viewing_angle``, :func:`width_scale`), the outline
    (:func:`_outline_one`) and the camera distance of the body centre (``Camera.distance``).

    Args:
        ends: (N, 2, 3) world bottom / top axis points; end_depth (N, 2) their optical
            depths (``Camera.depth``); theta (N,) body orientations; rot, t, kmat, dist the
            camera (see :func:`_project_one`), centre (3,) its centre.
        sitting (N,) bool; width (N,) body widths, metres; frac, half, parts, hip as
        :func:`_outline_one` (its focal lengths are ``kmat``'s).

    Returns:
        left, right (N, P, 2) image points (zeros for invalid particles), seg_part
        (N, P - 1) int8, valid (N,) bool (:func:`_outline_one`'s result), and distance
        (N,) from the camera centre to the middle of the axis (+inf if not valid).
    """
    n = ends.shape[0]
    npts = frac.shape[0]
    left = np.zeros((n, npts, 2))
    right = np.zeros((n, npts, 2))
    seg_part = np.empty((n, npts - 1), np.int8)
    valid = np.zeros(n, np.bool_)
    distance = np.empty(n)
    for i in range(n):
        x = ends[i, 0, 0]
        y = ends[i, 0, 1]
        d0 = end_depth[i, 0]
        d1 = end_depth[i, 1]
        bx = by = tx = ty = np.nan          # Camera.project: NaN behind the camera
        if d0 > 1e-6:
            bx, by = _project_one(x, y, ends[i, 0, 2], rot, t, kmat, dist)
        if d1 > 1e-6:
            tx, ty = _project_one(ends[i, 1, 0], ends[i, 1, 1], ends[i, 1, 2], rot, t, kmat,
                                  dist)
        rel = relative_orientation(theta[i], x, y, centre)
        scale = width_scale(rel)
        valid[i] = _outline_one(i, bx, by, tx, ty, d0, d1, sitting[i], frac, half, parts, hip,
                                width[i], scale, kmat[0, 0], kmat[1, 1], left, right,
                                seg_part)
        if valid[i]:
            ex = x - centre[0]
            ey = y - centre[1]
            ez = 0.5 * (ends[i, 0, 2] + ends[i, 1, 2]) - centre[2]
            distance[i] = np.sqrt(ex * ex + ey * ey + ez * ez)
        else:
            distance[i] = np.inf
    return left, right, seg_part, valid, distance


@njit(cache=True, nogil=True, fastmath={'contract'})
def _optical_depth(px, py, pz, r2, t2):
    """``Camera.depth`` of one point: r2 . p + t2 (r2 the third row of R). Multiply-adds
    may fuse: numpy's ``points @ R[2]`` goes to OpenBLAS, whose kernel fuses them, and
    this order with fused multiply-adds gives its bits (test_shape checks it)."""
    return px * r2[0] + py * r2[1] + pz * r2[2] + t2


@njit(cache=True, nogil=True)
def axis_ends(states, heights, chair, hip, r2, t2):
    """003 §2.1: the bottom / top points of the body axes of states (N, 6) and their optical
    depths: standing from the feet (z = 0) to the head top (z = h), sitting from the hip at
    chair height to ``chair + (1 - hip) h``. Returns ends (N, 2, 3), end_depth (N, 2) and
    sitting (N,) bool."""
    n = states.shape[0]
    ends = np.empty((n, 2, 3))
    end_depth = np.empty((n, 2))
    sitting = np.empty(n, np.bool_)
    for i in range(n):
        sit = states[i, SIT] >= 0.5
        sitting[i] = sit
        zb = chair if sit else 0.0
        zt = chair + (1.0 - hip) * heights[i] if sit else heights[i]
        for j in range(2):
            ends[i, j, 0] = states[i, X]
            ends[i, j, 1] = states[i, Y]
            ends[i, j, 2] = zb if j == 0 else zt
            end_depth[i, j] = _optical_depth(states[i, X], states[i, Y], ends[i, j, 2], r2,
                                             t2)
    return ends, end_depth, sitting


@njit(cache=True, nogil=True, inline='always')
def _edge(ax, ay, bx, by):
    """One edge of a convex quad -> ``(y_top, y_bottom, x_at_top, dx/dy)`` (horizontal edges
    get y_top == y_bottom), kept in registers by the caller.

    Each edge is parametrised from its sorted end points, so two quads sharing an edge get
    bit-identical crossings: with the half-open rules ``y_top <= y < y_bottom`` and
    ``ceil(xl) <= c < ceil(xr)`` neighbouring quads never claim the same pixel.
    """
    if ay > by or (ay == by and ax > bx):
        ax, bx = bx, ax
        ay, by = by, ay
    return ay, by, ax, (bx - ax) / (by - ay) if by > ay else 0.0


@njit(cache=True, nogil=True, inline='always')
def _cross(y, edge, xl, xr, hit):
    """Scanline ``y`` against one edge: widen the interval (xl, xr); hit if it crosses."""
    if edge[0] <= y < edge[1]:
        x = edge[2] + (y - edge[0]) * edge[3]
        if x < xl:
            xl = x
        if x > xr:
            xr = x
        hit = True
    return xl, xr, hit


@njit(cache=True, nogil=True)
def rasterize_quads(left, right, seg_part, valid, width, height, row_step, row_limit):
    """Scan-convert per-particle outlines into clipped row spans.

    Every profile segment j of a particle is the convex quad left[j], right[j],
    right[j + 1], left[j + 1]; a pixel belongs to it when its centre (integer coordinates)
    is inside (half-open rules, see :func:`_edge`), so neighbouring quads never
    share a pixel. One span per quad and row.

    Args:
        left, right: (N, P, 2) float64 image points of the outline left/right of the axis at
            the P profile heights.
        seg_part: (N, P - 1) int8 part of each segment (1 head, 2 torso, 3 legs; 0 unused).
        valid: (N,) bool, particles to rasterise (others get no spans).
        width, height: image size in pixels.
        row_step: keep only rows with ``row % row_step == 0``.
        row_limit: unclipped rows are only counted within ``[-row_limit, height + row_limit)``
            (for the unclipped area of particles very close to the camera).

    Returns:
        row, x0, x1 (M,) int32, part (M,) int8, offsets (N + 1,) int64, area (N,) int64,
        part_area (N, 3) int64, full_area (N,) int64 (unclipped pixel area, same row
        sampling), bbox (N, 4) int32 ``x0, y0, x1, y1`` exclusive (zeros if empty).
    """
    n = left.shape[0]
    nseg = left.shape[1] - 1
    ub = 0                                   # rows inside the image: bounds the span count
    for i in range(n):
        if not valid[i]:
            continue
        for j in range(nseg):
            if seg_part[i, j] == 0:
                continue
            ylo = min(min(left[i, j, 1], right[i, j, 1]),
                      min(left[i, j + 1, 1], right[i, j + 1, 1]))
            yhi = max(max(left[i, j, 1], right[i, j, 1]),
                      max(left[i, j + 1, 1], right[i, j + 1, 1]))
            r0 = max(int(np.ceil(ylo)), 0)
            r1 = min(int(np.ceil(yhi)), height)
            if r1 > r0:
                ub += r1 - r0
    row = np.empty(ub, np.int32)
    x0 = np.empty(ub, np.int32)
    x1 = np.empty(ub, np.int32)
    part = np.empty(ub, np.int8)
    offsets = np.zeros(n + 1, np.int64)
    area = np.zeros(n, np.int64)
    part_area = np.zeros((n, 3), np.int64)
    full_area = np.zeros(n, np.int64)
    bbox = np.zeros((n, 4), np.int32)
    m = 0
    for i in range(n):                       # areas in locals, written once per particle
        offsets[i] = m
        if not valid[i]:
            continue
        bx0 = width
        by0 = height
        bx1 = 0
        by1 = 0
        fa = 0
        pa0 = 0
        pa1 = 0
        pa2 = 0
        for j in range(nseg):
            q = seg_part[i, j]
            if q == 0:
                continue
            # vertices in order left[j], right[j], right[j + 1], left[j + 1]
            e0 = _edge(left[i, j, 0], left[i, j, 1], right[i, j, 0], right[i, j, 1])
            e1 = _edge(right[i, j, 0], right[i, j, 1], right[i, j + 1, 0], right[i, j + 1, 1])
            e2 = _edge(right[i, j + 1, 0], right[i, j + 1, 1], left[i, j + 1, 0],
                       left[i, j + 1, 1])
            e3 = _edge(left[i, j + 1, 0], left[i, j + 1, 1], left[i, j, 0], left[i, j, 1])
            ylo = min(min(e0[0], e1[0]), min(e2[0], e3[0]))
            yhi = max(max(e0[1], e1[1]), max(e2[1], e3[1]))
            r0 = max(int(np.ceil(ylo)), -row_limit)
            r1 = min(int(np.ceil(yhi)), height + row_limit)
            if row_step > 1:
                r0 = r0 + (-r0) % row_step
            qa = 0
            for r in range(r0, r1, row_step):
                y = float(r)
                xl, xr, hit = _cross(y, e0, np.inf, -np.inf, False)
                xl, xr, hit = _cross(y, e1, xl, xr, hit)
                xl, xr, hit = _cross(y, e2, xl, xr, hit)
                xl, xr, hit = _cross(y, e3, xl, xr, hit)
                if not hit:
                    continue
                c0 = int(np.ceil(xl))
                c1 = int(np.ceil(xr))
                if c1 <= c0:
                    continue
                fa += c1 - c0
                if r < 0 or r >= height:
                    continue
                c0 = max(c0, 0)
                c1 = min(c1, width)
                if c1 <= c0:
                    continue
                row[m] = r
                x0[m] = c0
                x1[m] = c1
                part[m] = q
                m += 1
                qa += c1 - c0
                bx0 = min(bx0, c0)
                bx1 = max(bx1, c1)
                by0 = min(by0, r)
                by1 = max(by1, r + 1)
            if q == 1:
                pa0 += qa
            elif q == 2:
                pa1 += qa
            else:
                pa2 += qa
        full_area[i] = fa
        part_area[i, 0] = pa0
        part_area[i, 1] = pa1
        part_area[i, 2] = pa2
        area[i] = pa0 + pa1 + pa2
        if area[i] > 0:
            bbox[i, 0] = bx0
            bbox[i, 1] = by0
            bbox[i, 2] = bx1
            bbox[i, 3] = by1
    offsets[n] = m
    return row[:m], x0[:m], x1[:m], part[:m], offsets, area, part_area, full_area, bbox


@njit(cache=True, nogil=True)
def silhouettes(states, heights, widths, chair, frac, half, parts, hip, r2, t2, rot, t, kmat,
                dist, centre, width, height, row_step):
    """Rasterised silhouettes of states (N, 6) in one camera (003 §2.1): :func:`axis_ends`,
    :func:`body_outline` and :func:`rasterize_quads` in one call (see ``shape.rasterize``).
    heights, widths (N,) metres; r2, t2 the camera's ``depth_row``; rot ... centre as
    :func:`body_outline`. Returns :func:`rasterize_quads`' arrays and the distance (N,)."""
    ends, end_depth, sitting = axis_ends(states, heights, chair, hip, r2, t2)
    left, right, seg_part, valid, distance = body_outline(
        ends, end_depth, np.ascontiguousarray(states[:, THETA]), sitting, frac, half, parts, hip,
        widths, rot, t, kmat, dist, centre)
    row, x0, x1, part, offsets, area, part_area, full_area, bbox = rasterize_quads(
        left, right, seg_part, valid, width, height, row_step, 10 * height)
    return row, x0, x1, part, offsets, area, part_area, full_area, bbox, distance


@njit(cache=True, nogil=True)
def paint_spans(out, row, x0, x1, part, s0, s1, value, use_part):
    """Write ``value`` (or the span's part label when ``use_part``) into out (H, W)."""
    for s in range(s0, s1):
        v = part[s] if use_part else value
        for c in range(x0[s], x1[s]):
            out[row[s], c] = v


@njit(cache=True, nogil=True)
def accumulate_spans(buf, row, x0, x1, offsets, values, oy, ox):
    """buf[row - oy, c - ox] += values[i] on the spans of every particle i."""
    for i in range(offsets.shape[0] - 1):
        v = values[i]
        if v == 0.0:
            continue
        for s in range(offsets[i], offsets[i + 1]):
            r = row[s] - oy
            for c in range(x0[s] - ox, x1[s] - ox):
                buf[r, c] += v


# -- histograms (the one accumulation routine) ------------------------------------------------
@njit(cache=True, nogil=True)
def accumulate_histogram(bins, row, x0, x1, part, s0, s1, wmap, oy, ox, nch,
                         hist, touched, nt, mark):
    """Add the colours under spans [s0, s1) to flat part histograms ``hist`` (C, 1536).

    With ``nch == 0`` every pixel adds 1 to channel 0; otherwise pixel u adds
    ``wmap[ch, row - oy, c - ox]`` to channel ``ch < nch`` (several weightings of the same
    pixels in one pass). The bin is ``part * 512 + bins[u]`` (part masses are summed from
    the touched bins afterwards, cheaper than per pixel). Touched bins (shared by all
    channels) are appended to ``touched`` and flagged in ``mark`` starting at ``nt``;
    returns the new count.

    (Summing runs of equal bins in a register first was tried: 30 % faster on flat-coloured
    bench people, twice slower on the textured synthetic rooms, where half of the
    neighbouring pixels change bin and the run test mispredicts.)
    """
    for s in range(s0, s1):
        r = row[s]
        q = part[s] - 1
        base = q * N_BINS
        if nch == 0:
            for c in range(x0[s], x1[s]):
                idx = base + bins[r, c]
                hist[0, idx] += 1
                if not mark[idx]:
                    mark[idx] = True
                    touched[nt] = idx
                    nt += 1
        elif nch == 1:
            w0 = wmap[0, r - oy]
            for c in range(x0[s], x1[s]):
                idx = base + bins[r, c]
                hist[0, idx] += w0[c - ox]
                if not mark[idx]:
                    mark[idx] = True
                    touched[nt] = idx
                    nt += 1
        else:
            rr = r - oy
            for c in range(x0[s], x1[s]):
                idx = base + bins[r, c]
                cc = c - ox
                for ch in range(nch):
                    hist[ch, idx] += wmap[ch, rr, cc]
                if not mark[idx]:
                    mark[idx] = True
                    touched[nt] = idx
                    nt += 1
    return nt


@njit(cache=True, nogil=True)
def model_values(key, t, va, vb, wa, touched, nt, mt):
    """mt[j] = model histogram at touched bin j, interpolated from two key views (003 Eq.
    1): ``wa * key[t, va] + (1 - wa) * key[t, vb]``, key (T, V, 1536) normalised per part.
    Only the touched bins are ever needed, so the full histogram is never built."""
    wb = 1.0 - wa
    for j in range(nt):
        idx = touched[j]
        mt[j] = wa * key[t, va, idx] + wb * key[t, vb, idx]


@njit(cache=True, nogil=True)
def part_distances(hist, mt, touched, nt, d2):
    """Bhattacharyya distances (003 Eq. 4) of a weighted part histogram to the model.

    ``hist`` (1536,) holds unnormalised weighted counts (float64, or int32 pixel counts),
    ``mt`` the model values at the touched bins. With part mass alpha, the normalised
    histogram is hist / alpha, so sum_c sqrt(h_c m_c) = sum_c sqrt(hist_c m_c) / sqrt(alpha).
    Writes d2 (3,) (1 for a part with no mass), zeroes the touched bins of ``hist`` and
    returns the part masses.
    """
    bc0 = 0.0
    bc1 = 0.0
    bc2 = 0.0
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    for j in range(nt):
        idx = touched[j]
        v = hist[idx]
        if v > 0.0:
            x = np.sqrt(v * mt[j])
            if idx < N_BINS:
                bc0 += x
                a0 += v
            elif idx < 2 * N_BINS:
                bc1 += x
                a1 += v
            else:
                bc2 += x
                a2 += v
        hist[idx] = 0
    for q in range(3):
        bc = bc0 if q == 0 else (bc1 if q == 1 else bc2)
        a = a0 if q == 0 else (a1 if q == 1 else a2)
        if a > 0.0:
            d = 1.0 - bc / np.sqrt(a)
            d2[q] = d if d > 0.0 else 0.0
        else:
            d2[q] = 1.0
    return a0, a1, a2


@njit(cache=True, nogil=True)
def occlusion_terms(bins, row, x0, x1, part, s0, s1, wmap, oy, ox, nch, area, d_occ,
                    key, t, va, vb, wa, hist, touched, mark, mt, d2, out_l, out_vis):
    """000 Eq. 26 with soft maps w (Eq. 33) on one silhouette, for max(nch, 1) channels.

    Channel ch uses w = wmap[ch] (w = 1 when ``nch == 0``); alpha = sum of w (visible
    mass), beta = area - alpha (hidden mass): l = (sum_parts alpha_part d2_part +
    beta d_occ) / area -> out_l[ch], alpha -> out_vis[ch]. With w = 1 this is the
    area-weighted part distance of 003 Eq. 3. ``mt`` (1536,) is scratch for model values.
    ``hist`` is (C, 1536) float64 scratch, or with ``nch == 0`` an int32 (1, 1536) one:
    pixel counts are exact in integers (same results), and the integer add keeps the
    per-pixel loop short when neighbouring pixels hit the same bin (about 25 % faster on
    the synthetic rooms than a float add, whose latency chains from pixel to pixel).
    """
    m = max(nch, 1)
    nt = accumulate_histogram(bins, row, x0, x1, part, s0, s1, wmap, oy, ox, nch,
                              hist, touched, 0, mark)
    model_values(key, t, va, vb, wa, touched, nt, mt)
    for ch in range(m):
        a0, a1, a2 = part_distances(hist[ch], mt, touched, nt, d2)
        vis = a0 + a1 + a2
        beta = area - vis
        if beta < 0.0:
            beta = 0.0
        num = a0 * d2[0] + a1 * d2[1] + a2 * d2[2]
        out_l[ch] = (num + beta * d_occ) / area if area > 0 else 0.0
        out_vis[ch] = vis
    for j in range(nt):
        mark[touched[j]] = False


# -- HJS update (000 Algorithm 1, per camera) -------------------------------------------------
@njit(cache=True, nogil=True)
def _fill_outside(row, x0, x1, s0, s1, vx0, vy0, vx1, vy1, wmap, nch):
    """wmap[:nch] = 1 on the pixels of spans [s0, s1) outside the box v (exclusive)."""
    for s in range(s0, s1):
        r = row[s]
        if r < vy0 or r >= vy1:
            a = x1[s]
            b = x1[s]
        else:
            a = min(max(x0[s], vx0), x1[s])
            b = max(min(x1[s], vx1), a)
        for c in range(x0[s], a):
            for ch in range(nch):
                wmap[ch, r, c] = 1.0
        for c in range(b, x1[s]):
            for ch in range(nch):
                wmap[ch, r, c] = 1.0


@njit(cache=True, nogil=True)
def hjs_camera_ws(bins, row, x0, x1, part, offsets, area, bbox, order, target, prior,
                  key, va, vb, wa, n_targets, d_occ, separable, record, pix_offsets,
                  mfg, bbg, wmap):
    """Visit all K*N particles of one camera from near to far (000 Algorithm 1 "update").

    The image buffers are caller-owned workspaces (C, H', W') with H' >= H, W' >= W,
    C >= max(K, 1) (``mfg``: 2C, it also holds the shared part of b_bg, see below), one
    image plane per target: a span reads and writes consecutive pixels of one or two planes
    (12 % less kernel time on live1800 frames with 5-6 tracks than with the K factors of a
    pixel interleaved, whose pixels are 2K doubles apart). b_fg is
    kept as the accumulated prior mass m_fg = 1 - b_fg so that every buffer starts at zero.
    ``mfg`` and ``bbg`` must be zero on entry and are zero again on return (only the
    rectangle that was written is cleared, in the planes of the K targets); ``wmap`` is
    scratch.
    Reusing them across calls saves allocating and clearing 2 x H x W x K doubles per
    camera and frame (which cost as much as the whole update of a frame without overlap).

    Args:
        bins: (H, W) int16 colour bins of the image.
        row, x0, x1, part, offsets, area, bbox: the particles' silhouettes (see
            :func:`rasterize_quads`), P = K * N particles.
        order: (P,) particle indices sorted by increasing camera distance.
        target: (P,) target index k_p of each particle.
        prior: (P,) normalised prior weight pi_p of each particle within its target.
        key: (K, V, 1536) key-view part histograms of the targets (normalised per part).
        va, vb, wa: (P,) the two key views of each particle and the weight of ``va``.
        separable: if True, every target is scored alone (w* = 1, no background term;
            the workspaces are not touched and may be (1, 1, 1)).
        record: flat float64 array receiving w* at every span pixel (size 0: do not
            record); pixel ``pix_offsets[p]`` is the first pixel of particle p.
        mfg (2C, H', W'), bbg, wmap (C, H', W'): float64 workspaces (see above).

    Returns:
        fc (P,) foreground terms, bc (P,) background terms, alpha (P,) sum of w*.
    """
    npart = offsets.shape[0] - 1
    fc = np.zeros(npart)
    bc = np.zeros(npart)
    vis = np.zeros(npart)
    nk = max(n_targets, 1)
    hist = np.zeros((nk, 3 * N_BINS))
    counts = np.zeros((1, 3 * N_BINS), np.int32)    # unweighted histograms (w = 1)
    mark = np.zeros(3 * N_BINS, np.bool_)
    touched = np.empty(3 * N_BINS, np.int64)
    mt = np.empty(3 * N_BINS)
    d2 = np.empty(3)
    out_l = np.empty(nk)
    out_v = np.empty(nk)
    ones = np.ones((1, 1, 1))
    # plain int64 (not literal) arguments: one compiled version of the helpers
    zero = np.int64(0)
    # per target, the union boxes of its particles nearer than the current one (pre, grown
    # while visiting) and of those farther than position oi (suf[oi], precomputed backwards)
    pre = np.empty((nk, 4), np.int64)
    pre[:, 0] = 1 << 30
    pre[:, 1] = 1 << 30
    pre[:, 2] = -1
    pre[:, 3] = -1
    if separable:
        suf = np.empty((1, nk, 4), np.int64)
    else:
        suf = np.empty((npart + 1, nk, 4), np.int64)
        suf[npart, :, 0] = 1 << 30
        suf[npart, :, 1] = 1 << 30
        suf[npart, :, 2] = -1
        suf[npart, :, 3] = -1
        for oi in range(npart - 1, -1, -1):
            suf[oi] = suf[oi + 1]
            p = order[oi]
            if area[p] > 0:                         # readers, whatever their prior
                h = target[p]
                suf[oi, h, 0] = min(suf[oi, h, 0], bbox[p, 0])
                suf[oi, h, 1] = min(suf[oi, h, 1], bbox[p, 1])
                suf[oi, h, 2] = max(suf[oi, h, 2], bbox[p, 2])
                suf[oi, h, 3] = max(suf[oi, h, 3], bbox[p, 3])
    # 000 Algorithm 1: b_fg starts at "N" (here 1 with normalised priors: m_fg = 0), b_bg
    # at 0; the rectangle written to them is cleared before returning
    wx0 = 1 << 30
    wy0 = 1 << 30
    wx1 = -1
    wy1 = -1
    rel = np.empty(nk, np.int64)
    need = np.empty(nk, np.int64)
    skip = np.empty(nk, np.int64)
    todo = np.empty(nk, np.int64)
    rfc = np.empty(nk)
    vals = np.empty(nk)
    do_record = record.shape[0] > 0
    for oi in range(npart):
        p = order[oi]
        if area[p] <= 0:
            continue
        k = target[p]
        s0 = offsets[p]
        s1 = offsets[p + 1]
        pi_p = prior[p]
        ap = float(area[p])
        bx0 = bbox[p, 0]
        by0 = bbox[p, 1]
        bx1 = bbox[p, 2]
        by1 = bbox[p, 3]
        # DBN shortcut (000 IV-B.3): only targets with a nearer particle whose box meets
        # this silhouette can occlude it (m_fg^h is 0 elsewhere); only targets with such a
        # farther particle can read what this particle writes.
        nrel = 0
        nneed = 0
        if not separable:
            for h in range(n_targets):
                if h == k:
                    continue
                if (pre[h, 0] < bx1 and bx0 < pre[h, 2]
                        and pre[h, 1] < by1 and by0 < pre[h, 3]):
                    rel[nrel] = h
                    nrel += 1
                if (suf[oi + 1, h, 0] < bx1 and bx0 < suf[oi + 1, h, 2]
                        and suf[oi + 1, h, 1] < by1 and by0 < suf[oi + 1, h, 3]):
                    need[nneed] = h
                    nneed += 1
            if pi_p > 0.0:
                pre[k, 0] = min(pre[k, 0], bx0)
                pre[k, 1] = min(pre[k, 1], by0)
                pre[k, 2] = max(pre[k, 2], bx1)
                pre[k, 3] = max(pre[k, 3], by1)
        # 000 Eq. 34: occlusion map w* = Delta(x_p) prod_{h != k} b_fg^h, and in the same
        # pass the background term of Eq. 40 (the sum of b_bg^k over the silhouette)
        # m_fg^h and b_bg^k can only be non-zero inside the boxes pre[h] of the targets h
        # in rel (their nearer particles with a prior wrote there): w* is computed inside
        # the union v of these boxes and is 1 elsewhere.
        occluded = False
        acc = 0.0
        vx0 = 1 << 30
        vy0 = 1 << 30
        vx1 = -1
        vy1 = -1
        if nrel > 0:
            for j in range(nrel):
                h = rel[j]
                vx0 = min(vx0, pre[h, 0])
                vy0 = min(vy0, pre[h, 1])
                vx1 = max(vx1, pre[h, 2])
                vy1 = max(vy1, pre[h, 3])
            for s in range(s0, s1):
                r = row[s]
                if r < vy0 or r >= vy1:
                    continue
                for c in range(max(x0[s], vx0), min(x1[s], vx1)):
                    w = 1.0
                    for j in range(nrel):
                        h = rel[j]
                        w *= max(1.0 - mfg[h, r, c], 0.0)   # >= 0 despite rounding
                        acc += mfg[nk + h, r, c]             # b_bg^k, shared part
                    wmap[0, r, c] = w
                    acc += bbg[k, r, c]                      # b_bg^k, own corrections
                    if w != 1.0:
                        occluded = True
            if occluded:
                _fill_outside(row, x0, x1, s0, s1, vx0, vy0, vx1, vy1, wmap, 1)
        # 000 Eq. 33 with Eq. 26: foreground term on the w*-weighted part histograms
        if occluded:
            occlusion_terms(bins, row, x0, x1, part, s0, s1, wmap, zero, zero, np.int64(1),
                            ap, d_occ, key, k, va[p], vb[p], wa[p], hist, touched, mark, mt,
                            d2, out_l, out_v)
        else:
            occlusion_terms(bins, row, x0, x1, part, s0, s1, ones, zero, zero, zero, ap,
                            d_occ, key, k, va[p], vb[p], wa[p], counts, touched, mark, mt,
                            d2, out_l, out_v)
        fc[p] = out_l[0]
        vis[p] = out_v[0]
        f_free = out_l[0] if not occluded else -1.0   # the term with w = 1, lazily
        if do_record:
            q = pix_offsets[p]
            for s in range(s0, s1):
                r = row[s]
                for c in range(x0[s], x1[s]):
                    record[q] = wmap[0, r, c] if occluded else 1.0
                    q += 1
        if separable:
            continue
        # 000 Eq. 40: with w* = 1 no nearer particle of another target overlaps (000
        # IV-B.3): b_bg^k is 0 there, and the term is 0.
        if occluded:
            bc[p] = acc
        if nneed == 0 or pi_p == 0.0:
            continue
        # reduced terms (000 Eq. 36-39): for every other target h, the foreground term of
        # x_p ignoring h (and k_p), rfc, spread over Delta(x_p) into b_bg^h. The listing
        # writes b_bg^{k_p}, which contradicts Eq. 36-39: the receiving buffer is the one of
        # the target h whose farther particles will read it (Eq. 40).
        # A needed target h that does not occlude x_p (not in rel) has the reduced map
        # prod_{m != h, k_p} b_fg^m = w* itself: rfc = fc. Ignoring the only occluder leaves
        # the map 1: rfc = the term with w = 1. Only the other targets need their own maps.
        ntodo = 0
        for i in range(nneed):
            skip[i] = -1                            # position of h in rel, or -1
            for j in range(nrel):
                if rel[j] == need[i]:
                    skip[i] = j
            if not occluded:                        # every reduced map is 1 on Delta(x_p)
                rfc[i] = f_free
            elif skip[i] < 0:
                rfc[i] = fc[p]
            elif nrel == 1:
                if f_free < 0.0:
                    occlusion_terms(bins, row, x0, x1, part, s0, s1, ones, zero, zero, zero,
                                    ap, d_occ, key, k, va[p], vb[p], wa[p], counts, touched,
                                    mark, mt, d2, out_l, out_v)
                    f_free = out_l[0]
                rfc[i] = f_free
            else:
                todo[ntodo] = i
                ntodo += 1
        if ntodo > 0:
            # reduced maps w^_h = prod_{m != h, k_p} b_fg^m for these h in one pass
            for s in range(s0, s1):
                r = row[s]
                if r < vy0 or r >= vy1:
                    continue
                for c in range(max(x0[s], vx0), min(x1[s], vx1)):
                    for j in range(nrel):
                        vals[j] = max(1.0 - mfg[rel[j], r, c], 0.0)
                    for t in range(ntodo):
                        sk = skip[todo[t]]
                        w = 1.0
                        for j in range(nrel):
                            if j != sk:
                                w *= vals[j]
                        wmap[t, r, c] = w
            _fill_outside(row, x0, x1, s0, s1, vx0, vy0, vx1, vy1, wmap, ntodo)
            occlusion_terms(bins, row, x0, x1, part, s0, s1, wmap, zero, zero,
                            np.int64(ntodo), ap, d_occ, key, k, va[p], vb[p], wa[p], hist,
                            touched, mark, mt, d2, out_l, out_v)
            for t in range(ntodo):
                rfc[todo[t]] = out_l[t]
        # Algorithm 1: b_fg^{k_p} -= pi_p Delta(x_p). The listing's "b_fg = N, subtract
        # Delta, divide by N" is the uniform-weight case of subtracting the normalised prior
        # weight (000 Eq. 35), which is what the non-uniform BP weights need. In the same
        # pass, 000 Eq. 39: intensity pi_p * rfc_p / area(x_p) into b_bg^h on the silhouette
        # (m_fg^{k_p} is never read for this particle's own reduced maps, so the order of
        # the two updates does not matter).
        # Only farther particles of the needed targets read these pixels, and they lie in
        # those targets' boxes suf[oi + 1]: writes outside the union of the boxes are never
        # read and are skipped.
        # b_bg^h is stored in two parts: the intensity with rfc = fc (the usual value of
        # every h, see above) once per writing target, t^{k_p} = mfg[..., K + k_p], which a
        # reader of target h sums over the other targets (b_bg^h = sum_{m != h} t^m +
        # corrections); and, only for the h whose reduced term differs from fc, the
        # correction pi_p (rfc_h - fc) / area in bbg[..., h]. One write per pixel instead
        # of one per needed target.
        tval = pi_p * fc[p] / ap
        ncorr = 0
        ux0 = 1 << 30
        uy0 = 1 << 30
        ux1 = -1
        uy1 = -1
        for i in range(nneed):
            h = need[i]
            if rfc[i] != fc[p]:
                skip[ncorr] = h
                vals[ncorr] = pi_p * (rfc[i] - fc[p]) / ap
                ncorr += 1
            ux0 = min(ux0, suf[oi + 1, h, 0])
            uy0 = min(uy0, suf[oi + 1, h, 1])
            ux1 = max(ux1, suf[oi + 1, h, 2])
            uy1 = max(uy1, suf[oi + 1, h, 3])
        ux0 = max(ux0, bx0)
        uy0 = max(uy0, by0)
        ux1 = min(ux1, bx1)
        uy1 = min(uy1, by1)
        for s in range(s0, s1):
            r = row[s]
            if r < uy0 or r >= uy1:
                continue
            for c in range(max(x0[s], ux0), min(x1[s], ux1)):
                mfg[k, r, c] += pi_p
                mfg[nk + k, r, c] += tval
                for i in range(ncorr):
                    bbg[skip[i], r, c] += vals[i]
        if ux1 > ux0 and uy1 > uy0:
            wx0 = min(wx0, ux0)
            wy0 = min(wy0, uy0)
            wx1 = max(wx1, ux1)
            wy1 = max(wy1, uy1)
    if wx1 > wx0 and wy1 > wy0:                    # leave the workspaces zero
        mfg[:2 * n_targets, wy0:wy1, wx0:wx1] = 0.0
        bbg[:n_targets, wy0:wy1, wx0:wx1] = 0.0
    return fc, bc, vis


@njit(cache=True, nogil=True)
def hjs_camera(bins, row, x0, x1, part, offsets, area, bbox, order, target, prior,
               key, va, vb, wa, n_targets, d_occ, separable, record, pix_offsets):
    """:func:`hjs_camera_ws` with freshly allocated workspaces (one-off calls)."""
    if separable:
        mfg = np.zeros((1, 1, 1))
        bbg = np.zeros((1, 1, 1))
        wmap = np.zeros((1, 1, 1))
    else:
        shape = (max(n_targets, 1), bins.shape[0], bins.shape[1])
        mfg = np.zeros((2 * shape[0], shape[1], shape[2]))
        bbg = np.zeros(shape)
        wmap = np.empty(shape)
    return hjs_camera_ws(bins, row, x0, x1, part, offsets, area, bbox, order, target, prior,
                         key, va, vb, wa, n_targets, d_occ, separable, record, pix_offsets,
                         mfg, bbg, wmap)


@njit(cache=True, nogil=True)
def update_camera(image, bins, states, target, prior, heights, widths, chair, frac, half,
                  parts, hip, view_angles, n_views, key, r2, t2, rot, t, kmat, dist, centre,
                  row_step, d_occ, separable, two_sigma_sq, min_visible, mfg, bbg,
                  wmap, loglik, visible, inside):
    """One camera's whole share of ``MeasurementModel.hjs`` / ``separable`` in one call
    without the GIL: the image's colour bins (:func:`quantize_rgb`, when ``bins`` is given
    empty (0, 0)), the silhouettes (:func:`silhouettes`), the key views of each particle
    (003 Eq. 1-2, :func:`nearest_two_views` of the orientation relative to the camera),
    the near-to-far order and :func:`hjs_camera_ws`; then the camera's log-likelihoods and
    visible fractions.

    Args:
        states (P, 6), target (P,), prior (P,): the K targets' particles stacked, their
            target index and normalised prior weights; heights, widths (P,) body sizes.
        chair, frac, half, parts, hip: the body shape (``BodyShape``).
        view_angles (K, V), n_views (K,): the key-view angles of the targets; key
            (K, V, 1536) their key-view histograms (``key_view_stack``).
        r2 ... centre: the camera (``Camera.depth_row``, ``projection_parameters``);
            row_step: row sampling.
        d_occ, separable, mfg, bbg, wmap: as :func:`hjs_camera_ws`.
        two_sigma_sq: 2 sigma^2 of 000 Eq. 19; min_visible: fewer silhouette pixels (rows
            times row_step) leave a particle neutral (0) in this camera.
        loglik (P,): receives -(fc + bc) / (2 sigma^2) (000 Eq. 19), 0 where neutral.
        visible (K,): receives per target the prior-weighted mean over its particles of
            the visible fraction sum(w*) / unclipped area, clipped to [0, 1].
        inside (P,): receives the share of each silhouette inside the image (area over
            unclipped area), 0 where neutral (``MeasurementModel._seen_by`` decides what
            the camera says about such particles).

    Returns:
        bins (H, W) int16, the image's colour bins, and the particles' silhouettes as row
        spans ``row, x0, x1, part, offsets`` (:class:`~mbtrack_ros.core.shape.Silhouettes`;
        the coverage term of ``MeasurementModel.set_foreground`` counts on them).
    """
    if bins.shape[0] == 0:
        bins = quantize_rgb(image)
    n = states.shape[0]
    row, x0, x1, part, offsets, area, _, full_area, bbox, distance = silhouettes(
        states, heights, widths, chair, frac, half, parts, hip, r2, t2, rot, t, kmat, dist,
        centre, bins.shape[1], bins.shape[0], row_step)
    # 003 Eq. 1-2: orientation relative to the camera (Camera.viewing_angle), two key views
    rel = np.empty(n)
    for i in range(n):
        rel[i] = wrap_angle(relative_orientation(states[i, THETA], states[i, X],
                                                 states[i, Y], centre))
    va = np.zeros(n, np.int64)
    vb = np.zeros(n, np.int64)
    wa = np.ones(n)
    nearest_two_views(rel, target, view_angles, n_views, va, vb, wa)
    order = np.argsort(distance, kind='mergesort')          # stable: ties keep index order
    fc, bc, vis = hjs_camera_ws(
        bins, row, x0, x1, part, offsets, area, bbox, order, target, prior, key, va, vb, wa,
        key.shape[0], d_occ, separable, np.zeros(0), np.zeros(n + 1, np.int64), mfg, bbg,
        wmap)
    visible[:] = 0.0
    for p in range(n):
        # the exponent of 000 Eq. 19 is negative; Algorithm 1 as printed lost the minus sign
        if area[p] <= 0 or area[p] * row_step < min_visible:
            loglik[p] = 0.0
            inside[p] = 0.0
        else:
            loglik[p] = -(fc[p] + bc[p]) / two_sigma_sq
            inside[p] = min(area[p] / full_area[p], 1.0)      # full_area >= area > 0
        f = vis[p] / full_area[p] if full_area[p] > 0 else 0.0
        f = min(max(f, 0.0), 1.0)
        visible[target[p]] += prior[p] * f
    return bins, row, x0, x1, part, offsets


# -- joint rendering (000 Eq. 20-21, 26 with binary masks) ------------------------------------
@njit(cache=True, nogil=True)
def joint_camera(bins, row, x0, x1, part, offsets, area, order, n_targets, d_occ,
                 key, va, vb, wa, min_pixels):
    """Eq. 26 per target with binary visibility masks, per joint sample.

    Particle ``n * K + k`` is target k of joint sample n; ``order`` (N, K) lists each
    sample's targets front to back; key, va, vb, wa as in :func:`hjs_camera`. Returns (N,)
    sum over targets of l (targets with fewer than ``min_pixels`` silhouette pixels
    contribute 0).
    """
    nsamp = order.shape[0]
    out = np.zeros(nsamp)
    height = bins.shape[0]
    width = bins.shape[1]
    owner = np.zeros((height, width), np.int64)
    wmap = np.zeros((1, height, width))
    zero = np.int64(0)
    one = np.int64(1)
    hist = np.zeros((1, 3 * N_BINS))
    mark = np.zeros(3 * N_BINS, np.bool_)
    touched = np.empty(3 * N_BINS, np.int64)
    mt = np.empty(3 * N_BINS)
    d2 = np.empty(3)
    out_l = np.empty(1)
    out_v = np.empty(1)
    for n in range(nsamp):
        stamp = n + 1
        total = 0.0
        for oi in range(n_targets):
            k = order[n, oi]
            p = n * n_targets + k
            s0 = offsets[p]
            s1 = offsets[p + 1]
            # 000 Eq. 20: a pixel shows the nearest silhouette covering it
            for s in range(s0, s1):
                r = row[s]
                for c in range(x0[s], x1[s]):
                    if owner[r, c] != stamp:
                        owner[r, c] = stamp
                        wmap[0, r, c] = 1.0
                    else:
                        wmap[0, r, c] = 0.0
            if area[p] < min_pixels or area[p] <= 0:
                continue
            occlusion_terms(bins, row, x0, x1, part, s0, s1, wmap, zero, zero, one,
                            float(area[p]), d_occ, key, k, va[p], vb[p], wa[p], hist, touched,
                            mark, mt, d2, out_l, out_v)
            total += out_l[0]
        out[n] = total
    return out


@njit(cache=True, nogil=True)
def histogram_of(bins, row, x0, x1, part, s0, s1, wmap, oy, ox, nch):
    """Unnormalised part histograms (3, 512) of one silhouette (``wmap`` (H, W, 1),
    C-contiguous, used when ``nch == 1``)."""
    hist = np.zeros((1, 3 * N_BINS))
    touched = np.empty(3 * N_BINS, np.int64)
    mark = np.zeros(3 * N_BINS, np.bool_)
    plane = wmap.reshape(1, wmap.shape[0], wmap.shape[1])    # one channel: same memory
    accumulate_histogram(bins, row, x0, x1, part, s0, s1, plane, oy, ox, nch, hist, touched,
                         0, mark)
    return hist.reshape(3, N_BINS)


# -- image resizing ---------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def area_shrink(src, rows, row_w, cols, col_w, out):
    """Area-averaging shrink of ``src`` (H, W, C) uint8 C-contiguous into ``out`` (h, w, C)
    uint8, separably: each output row is the weighted sum of input rows ``rows[o]`` (h, K)
    int32 with weights ``row_w[o]`` (h, K) float32 (the overlap of the row's cell with each
    input row, divided by the cell's height; zero weights pad), then each output element
    ``j`` of that row (w * C of them) the weighted sum of the summed row's elements
    ``cols[l, j]`` (L, w * C) int32 with weights ``col_w[l, j]`` (L, w * C) float32, rounded
    to the nearest level. Float32 sums: OpenCV's ``INTER_AREA`` up to its rounding."""
    H, W, C = src.shape
    h, K = rows.shape
    L, M = cols.shape
    flat = src.reshape(H, W * C)
    dst = out.reshape(h, M)
    line = np.empty(W * C, np.float32)
    acc = np.empty(M, np.float32)
    for o in range(h):
        r = flat[rows[o, 0]]
        wt = row_w[o, 0]
        for j in range(W * C):
            line[j] = wt * r[j]
        for k in range(1, K):
            wt = row_w[o, k]
            if wt == 0.0:
                continue
            r = flat[rows[o, k]]
            for j in range(W * C):
                line[j] += wt * r[j]
        idx = cols[0]
        wl = col_w[0]
        for j in range(M):
            acc[j] = wl[j] * line[idx[j]]
        for m in range(1, L):
            idx = cols[m]
            wl = col_w[m]
            for j in range(M):
                acc[j] += wl[j] * line[idx[j]]
        d = dst[o]
        for j in range(M):
            v = np.int32(acc[j] + np.float32(0.5))
            d[j] = 255 if v > 255 else (0 if v < 0 else v)
    return out


@njit(cache=True, nogil=True)
def block_mean(src, ky, kx, rounded, out):
    """Integer-factor area shrink of ``src`` (H, W, C) uint8 C-contiguous into ``out``
    (h, w, C) uint8, h = H // ky, w = W // kx: each output element is the mean of its
    ``ky`` x ``kx`` block of input pixels (the exact area average), rounded by the table
    ``rounded`` (255 ky kx + 1,) uint8: ``rounded[s] = (s + ky kx // 2) // (ky kx)`` (a
    lookup instead of a division per element). Rows are summed into uint32 first (one
    pass over the input, contiguous), then each output's ``kx`` columns."""
    h, w, c = out.shape
    flat = src.reshape(src.shape[0], src.shape[1] * c)
    dst = out.reshape(h, w * c)
    used = w * kx * c
    acc = np.empty(used, np.uint32)
    row = np.empty(w * c, np.uint32)
    first = np.empty(w * c, np.int64)
    for x in range(w):
        for ch in range(c):
            first[x * c + ch] = x * kx * c + ch
    for o in range(h):
        line = flat[o * ky]
        for j in range(used):
            acc[j] = line[j]
        for k in range(1, ky):
            line = flat[o * ky + k]
            for j in range(used):
                acc[j] += line[j]
        for j in range(w * c):
            row[j] = acc[first[j]]
        for i in range(1, kx):
            for j in range(w * c):
                row[j] += acc[first[j] + i * c]
        d = dst[o]
        for j in range(w * c):
            d[j] = rounded[row[j]]
    return out
