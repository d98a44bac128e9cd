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

__all__: list[str] = []

N_BINS = 512
N_PARTS = 3


# -- rasterisation ----------------------------------------------------------------------------
@njit(cache=True)
def _row_interval(y, qx, qy):
    """Scanline ``y`` against the convex quad (4,) -> (xl, xr, hit).

    Edges are taken half-open in y (``ya <= y < yb`` after sorting the end points), and the
    crossing of an edge is computed from its sorted end points, so that two quads sharing an
    edge get bit-identical crossings: with the pixel rule ``ceil(xl) <= c < ceil(xr)`` the
    quads then never claim the same pixel.
    """
    xl = np.inf
    xr = -np.inf
    hit = False
    for e in range(4):
        ax = qx[e]
        ay = qy[e]
        bx = qx[(e + 1) % 4]
        by = qy[(e + 1) % 4]
        if ay > by or (ay == by and ax > bx):
            ax, bx = bx, ax
            ay, by = by, ay
        if ay <= y < by:
            x = ax + (y - ay) * (bx - ax) / (by - ay)
            if x < xl:
                xl = x
            if x > xr:
                xr = x
            hit = True
    return xl, xr, hit


@njit(cache=True)
def _quad_rows(i, j, left, right, qx, qy):
    """Vertices into qx, qy (4,) of the quad of segment j of particle i; its y range."""
    qx[0] = left[i, j, 0]
    qy[0] = left[i, j, 1]
    qx[1] = right[i, j, 0]
    qy[1] = right[i, j, 1]
    qx[2] = right[i, j + 1, 0]
    qy[2] = right[i, j + 1, 1]
    qx[3] = left[i, j + 1, 0]
    qy[3] = left[i, j + 1, 1]
    ylo = min(min(qy[0], qy[1]), min(qy[2], qy[3]))
    yhi = max(max(qy[0], qy[1]), max(qy[2], qy[3]))
    return ylo, yhi


@njit(cache=True)
def rasterize_quads(left, right, seg_part, valid, width, height, row_step, row_limit):
    """Scan-convert per-particle outlines into clipped row spans.

    Every profile segment j of a particle is the convex quad left[j], right[j],
    right[j + 1], left[j + 1]; a pixel belongs to it when its centre (integer coordinates)
    is inside (half-open rules, see :func:`_row_interval`), so neighbouring quads never
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
    qx = np.empty(4)
    qy = np.empty(4)
    ub = 0
    for i in range(n):
        if not valid[i]:
            continue
        for j in range(nseg):
            if seg_part[i, j] == 0:
                continue
            ylo, yhi = _quad_rows(i, j, left, right, qx, qy)
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
    for i in range(n):
        offsets[i] = m
        if not valid[i]:
            continue
        bx0 = width
        by0 = height
        bx1 = 0
        by1 = 0
        for j in range(nseg):
            q = seg_part[i, j]
            if q == 0:
                continue
            ylo, yhi = _quad_rows(i, j, left, right, qx, qy)
            r0 = max(int(np.ceil(ylo)), -row_limit)
            r1 = min(int(np.ceil(yhi)), height + row_limit)
            if row_step > 1:
                r0 = r0 + (-r0) % row_step
            for r in range(r0, r1, row_step):
                xl, xr, hit = _row_interval(float(r), qx, qy)
                if not hit:
                    continue
                c0 = int(np.ceil(xl))
                c1 = int(np.ceil(xr))
                if c1 <= c0:
                    continue
                full_area[i] += c1 - c0
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
                area[i] += c1 - c0
                part_area[i, q - 1] += c1 - c0
                bx0 = min(bx0, c0)
                bx1 = max(bx1, c1)
                by0 = min(by0, r)
                by1 = max(by1, r + 1)
        if area[i] > 0:
            bbox[i, 0] = bx0
            bbox[i, 1] = by0
            bbox[i, 2] = bx1
            bbox[i, 3] = by1
    offsets[n] = m
    return row[:m], x0[:m], x1[:m], part[:m], offsets, area, part_area, full_area, bbox


@njit(cache=True)
def paint_spans(out, row, x0, x1, part, s0, s1, value, use_part):
    """Write ``value`` (or the span's part label when ``use_part``) into out (H, W)."""
    for s in range(s0, s1):
        v = part[s] if use_part else value
        for c in range(x0[s], x1[s]):
            out[row[s], c] = v


@njit(cache=True)
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
@njit(cache=True)
def accumulate_histogram(bins, row, x0, x1, part, s0, s1, wmap, oy, ox, use_w,
                         hist, alpha, touched, nt, mark):
    """Add the colours under spans [s0, s1) to the flat part histogram ``hist`` (1536,).

    Each pixel u adds ``w(u)`` (``wmap[row - oy, c - ox]`` when ``use_w``, else 1) to bin
    ``part * 512 + bins[u]`` and to ``alpha[part]``. Touched bins are appended to
    ``touched`` (flagged in ``mark``) starting at ``nt``; returns the new count.
    """
    for s in range(s0, s1):
        r = row[s]
        q = part[s] - 1
        base = q * N_BINS
        acc = 0.0
        for c in range(x0[s], x1[s]):
            w = wmap[r - oy, c - ox] if use_w else 1.0
            idx = base + bins[r, c]
            hist[idx] += w
            acc += w
            if not mark[idx]:
                mark[idx] = True
                touched[nt] = idx
                nt += 1
        alpha[q] += acc
    return nt


@njit(cache=True)
def part_distances(hist, alpha, sqrt_model, touched, nt, mark, d2):
    """Bhattacharyya distances (003 Eq. 4) of the weighted part histograms to the model.

    ``hist`` holds unnormalised weighted counts with part masses ``alpha`` (3,); the
    normalised histogram is hist / alpha, so sum_c sqrt(h_c m_c) = sum_c sqrt(hist_c) *
    sqrt_model_c / sqrt(alpha). Writes d2 (3,) (1 for a part with no mass) and clears the
    touched bins of ``hist`` and ``mark``.
    """
    bc0 = 0.0
    bc1 = 0.0
    bc2 = 0.0
    for j in range(nt):
        idx = touched[j]
        v = hist[idx]
        if v > 0.0:
            t = np.sqrt(v) * sqrt_model[idx]
            if idx < N_BINS:
                bc0 += t
            elif idx < 2 * N_BINS:
                bc1 += t
            else:
                bc2 += t
        hist[idx] = 0.0
        mark[idx] = False
    for q in range(3):
        bc = bc0 if q == 0 else (bc1 if q == 1 else bc2)
        if alpha[q] > 0.0:
            d = 1.0 - bc / np.sqrt(alpha[q])
            d2[q] = d if d > 0.0 else 0.0
        else:
            d2[q] = 1.0


@njit(cache=True)
def occlusion_term(bins, row, x0, x1, part, s0, s1, wmap, oy, ox, use_w, area, d_occ,
                   sqrt_model, hist, touched, mark, d2):
    """000 Eq. 26 with the soft map w of Eq. 33 on one silhouette -> (l, alpha).

    alpha = sum of w over the silhouette (visible mass), beta = area - alpha the hidden
    mass: l = (sum_parts alpha_part d2_part + beta d_occ) / area. With w = 1 this is the
    area-weighted part distance of 003 Eq. 3.
    """
    alpha = np.zeros(3)
    nt = accumulate_histogram(bins, row, x0, x1, part, s0, s1, wmap, oy, ox, use_w,
                              hist, alpha, touched, 0, mark)
    part_distances(hist, alpha, sqrt_model, touched, nt, mark, d2)
    vis = alpha[0] + alpha[1] + alpha[2]
    if area <= 0:
        return 0.0, 0.0
    beta = area - vis
    if beta < 0.0:
        beta = 0.0
    num = alpha[0] * d2[0] + alpha[1] * d2[1] + alpha[2] * d2[2] + beta * d_occ
    return num / area, vis


# -- HJS update (000 Algorithm 1, per camera) -------------------------------------------------
@njit(cache=True)
def hjs_camera(bins, row, x0, x1, part, offsets, area, bbox, order, target, prior,
               sqrt_models, n_targets, d_occ, separable, record, pix_offsets):
    """Visit all K*N particles of one camera from near to far (000 Algorithm 1 "update").

    Args:
        bins: (H, W) int16 colour bins of the image.
        row, x0, x1, part, offsets, area, bbox: the particles' silhouettes (see
            :func:`rasterize_quads`), P = K * N particles.
        order: (P,) particle indices sorted by increasing camera distance.
        target: (P,) target index k_p of each particle.
        prior: (P,) normalised prior weight pi_p of each particle within its target.
        sqrt_models: (P, 1536) square roots of the interpolated model part histograms.
        separable: if True, every target is scored alone (w* = 1, no background term).
        record: flat float64 array receiving w* at every span pixel (size 0: do not
            record); pixel ``pix_offsets[p]`` is the first pixel of particle p.

    Returns:
        fc (P,) foreground terms, bc (P,) background terms, alpha (P,) sum of w*.
    """
    npart = offsets.shape[0] - 1
    fc = np.zeros(npart)
    bc = np.zeros(npart)
    vis = np.zeros(npart)
    hist = np.zeros(3 * N_BINS)
    mark = np.zeros(3 * N_BINS, np.bool_)
    touched = np.empty(3 * N_BINS, np.int64)
    d2 = np.empty(3)
    # union bounding boxes: of all particles (buffer extent) and per target
    gx0 = 1 << 30
    gy0 = 1 << 30
    gx1 = -1
    gy1 = -1
    tb = np.empty((n_targets, 4), np.int64)
    for h in range(n_targets):
        tb[h, 0] = 1 << 30
        tb[h, 1] = 1 << 30
        tb[h, 2] = -1
        tb[h, 3] = -1
    for p in range(npart):
        if area[p] <= 0:
            continue
        h = target[p]
        tb[h, 0] = min(tb[h, 0], bbox[p, 0])
        tb[h, 1] = min(tb[h, 1], bbox[p, 1])
        tb[h, 2] = max(tb[h, 2], bbox[p, 2])
        tb[h, 3] = max(tb[h, 3], bbox[p, 3])
        gx0 = min(gx0, bbox[p, 0])
        gy0 = min(gy0, bbox[p, 1])
        gx1 = max(gx1, bbox[p, 2])
        gy1 = max(gy1, bbox[p, 3])
    if gx1 < 0:
        return fc, bc, vis
    gw = gx1 - gx0
    gh = gy1 - gy0
    if separable:
        bfg = np.ones((1, 1, 1))
        bbg = np.zeros((1, 1, 1))
    else:
        # 000 Algorithm 1: b_fg starts at "N" (here 1 with normalised priors), b_bg at 0
        bfg = np.ones((n_targets, gh, gw))
        bbg = np.zeros((n_targets, gh, gw))
    wmap = np.ones((gh, gw))
    rel = np.empty(n_targets, np.int64)
    do_record = record.shape[0] > 0
    for oi in range(npart):
        p = order[oi]
        if area[p] <= 0:
            continue
        k = target[p]
        s0 = offsets[p]
        s1 = offsets[p + 1]
        pi_p = prior[p]
        # targets whose particles can overlap this silhouette (DBN shortcut, 000 IV-B.3):
        # b_fg^h and b_bg^h are untouched outside the union bounding box of h's particles
        nrel = 0
        if not separable:
            for h in range(n_targets):
                if h == k or tb[h, 2] < 0:
                    continue
                if (tb[h, 0] < bbox[p, 2] and bbox[p, 0] < tb[h, 2]
                        and tb[h, 1] < bbox[p, 3] and bbox[p, 1] < tb[h, 3]):
                    rel[nrel] = h
                    nrel += 1
        # 000 Eq. 34: occlusion map w* = Delta(x_p) prod_{h != k} b_fg^h
        occluded = False
        if nrel > 0:
            for s in range(s0, s1):
                r = row[s] - gy0
                for c in range(x0[s] - gx0, x1[s] - gx0):
                    w = 1.0
                    for j in range(nrel):
                        w *= bfg[rel[j], r, c]
                    wmap[r, c] = w
                    if w != 1.0:
                        occluded = True
        # 000 Eq. 33 with Eq. 26: foreground term on the w*-weighted part histograms
        f, a = occlusion_term(bins, row, x0, x1, part, s0, s1, wmap, gy0, gx0, occluded,
                              float(area[p]), d_occ, sqrt_models[p], hist, touched, mark, d2)
        fc[p] = f
        vis[p] = a
        if do_record:
            q = pix_offsets[p]
            for s in range(s0, s1):
                r = row[s] - gy0
                for c in range(x0[s] - gx0, x1[s] - gx0):
                    record[q] = wmap[r, c] if occluded else 1.0
                    q += 1
        if separable:
            continue
        # 000 Eq. 40: background term = sum of b_bg^k over the silhouette. With w* = 1 no
        # nearer particle of another target overlaps (000 IV-B.3): b_bg^k is 0 there.
        if occluded:
            acc = 0.0
            for s in range(s0, s1):
                r = row[s] - gy0
                for c in range(x0[s] - gx0, x1[s] - gx0):
                    acc += bbg[k, r, c]
            bc[p] = acc
        # Algorithm 1: b_fg^{k_p} -= pi_p Delta(x_p). The listing's "b_fg = N, subtract
        # Delta, divide by N" is the uniform-weight case of subtracting the normalised prior
        # weight (000 Eq. 35), which is what the non-uniform BP weights need.
        if pi_p != 0.0:
            for s in range(s0, s1):
                r = row[s] - gy0
                for c in range(x0[s] - gx0, x1[s] - gx0):
                    bfg[k, r, c] -= pi_p
        if pi_p == 0.0:
            continue
        # reduced terms (000 Eq. 36-39): for every other target h, the foreground term of
        # x_p ignoring h (and k_p) is spread over Delta(x_p) into b_bg^h. The listing writes
        # b_bg^{k_p}, which contradicts Eq. 36-39: the receiving buffer is the one of the
        # target h whose farther particles will read it (Eq. 40).
        for j in range(nrel):
            h = rel[j]
            use = False
            if nrel > 1:
                for s in range(s0, s1):
                    r = row[s] - gy0
                    for c in range(x0[s] - gx0, x1[s] - gx0):
                        w = 1.0
                        for jj in range(nrel):
                            if jj != j:
                                w *= bfg[rel[jj], r, c]
                        wmap[r, c] = w
                        if w != 1.0:
                            use = True
            rf, _ = occlusion_term(bins, row, x0, x1, part, s0, s1, wmap, gy0, gx0, use,
                                   float(area[p]), d_occ, sqrt_models[p], hist, touched,
                                   mark, d2)
            # 000 Eq. 39: intensity pi_p * rfc_p / area(x_p) on the silhouette
            v = pi_p * rf / area[p]
            for s in range(s0, s1):
                r = row[s] - gy0
                for c in range(x0[s] - gx0, x1[s] - gx0):
                    bbg[h, r, c] += v
    return fc, bc, vis


# -- joint rendering (000 Eq. 20-21, 26 with binary masks) ------------------------------------
@njit(cache=True)
def joint_camera(bins, row, x0, x1, part, offsets, area, order, n_targets, d_occ,
                 sqrt_models, min_pixels):
    """Eq. 26 per target with binary visibility masks, per joint sample.

    Particle ``n * K + k`` is target k of joint sample n; ``order`` (N, K) lists each
    sample's targets front to back. Returns (N,) sum over targets of l (targets with
    fewer than ``min_pixels`` silhouette pixels contribute 0).
    """
    nsamp = order.shape[0]
    out = np.zeros(nsamp)
    height = bins.shape[0]
    width = bins.shape[1]
    owner = np.zeros((height, width), np.int64)
    wmap = np.zeros((height, width))
    hist = np.zeros(3 * N_BINS)
    mark = np.zeros(3 * N_BINS, np.bool_)
    touched = np.empty(3 * N_BINS, np.int64)
    d2 = np.empty(3)
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
                        wmap[r, c] = 1.0
                    else:
                        wmap[r, c] = 0.0
            if area[p] < min_pixels or area[p] <= 0:
                continue
            f, _ = occlusion_term(bins, row, x0, x1, part, s0, s1, wmap, 0, 0, True,
                                  float(area[p]), d_occ, sqrt_models[p], hist, touched,
                                  mark, d2)
            total += f
        out[n] = total
    return out


@njit(cache=True)
def histogram_of(bins, row, x0, x1, part, s0, s1, wmap, oy, ox, use_w):
    """Unnormalised part histograms (3, 512) and part masses (3,) of one silhouette."""
    hist = np.zeros(3 * N_BINS)
    alpha = np.zeros(3)
    touched = np.empty(3 * N_BINS, np.int64)
    mark = np.zeros(3 * N_BINS, np.bool_)
    accumulate_histogram(bins, row, x0, x1, part, s0, s1, wmap, oy, ox, use_w, hist, alpha,
                         touched, 0, mark)
    return hist.reshape(3, N_BINS), alpha
