"""Single-view detection features of person hypotheses (003 §4.1-4.2).

A hypothesis is a person at a floor position with height, width, orientation and pose; its
projection into one camera is given as row spans (the output of the shape model's
rasteriser, see :class:`Spans`). Three features are computed per hypothesis and camera:

1. **coverage** - fraction of the silhouette pixels that are foreground. Computed from row
   prefix sums of the foreground mask (one lookup per span), so scoring thousands of fixed
   hypotheses per frame costs a few array operations. Pixels explained by current tracks
   can be declared *unknown*: they are dropped from numerator and denominator, and the
   known fraction is returned as well (a hypothesis mostly hidden behind a track is not
   judged in that view);
2. **contour likelihood** (003 Eq. 5) - Canny edges validated by connected components and
   restricted to the foreground neighbourhood, their distance transform ``D`` with the
   gradient ``G`` of the nearest edge pixel, and the silhouette outline ``C`` with normals
   ``N``: ``log L = -1/|C| sum_u [min(1, D(u) / (0.3 Delta)) - 0.5 |<N(u), G(u)>|]``;
3. **colour symmetry** of the upper body - L1 distance between the colour histograms of the
   left and right halves of the torso region (low = symmetric = person-like).

Spans use half-open pixel intervals ``[x0, x1)`` on image row ``row``; rows and columns
outside the image are clipped.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from mbtrack_ros.core.appearance import quantize
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.shape import TORSO

__all__ = ['EdgeMap', 'ForegroundIntegral', 'Outline', 'Spans', 'TORSO', 'colour_symmetry',
           'contour_loglik', 'contour_loglik_spans', 'outline', 'span_count', 'span_counts',
           'span_coverage', 'span_owner']


@dataclass(frozen=True)
class Spans:
    """Row spans of N silhouettes in one image (same fields as ``shape.Silhouettes``, which
    every function here accepts as well).

    Attributes:
        row: (S,) int32 image rows.
        x0, x1: (S,) int32 half-open column interval ``[x0, x1)`` of each span.
        part: (S,) int8 body part of each span (1 head, 2 torso, 3 legs).
        offsets: (N + 1,) int64; spans of silhouette i are ``offsets[i]:offsets[i + 1]``,
            sorted by row within a silhouette.
    """

    row: np.ndarray
    x0: np.ndarray
    x1: np.ndarray
    part: np.ndarray
    offsets: np.ndarray

    @property
    def count(self) -> int:
        """Number of silhouettes N."""
        return int(len(self.offsets) - 1)

    @property
    def owner(self) -> np.ndarray:
        """(S,) index of the silhouette each span belongs to."""
        return np.repeat(np.arange(self.count), np.diff(self.offsets))

    @staticmethod
    def from_masks(masks: list[np.ndarray], parts: list[np.ndarray] | None = None) -> Spans:
        """Spans of binary masks (H, W) (or part-label images, 0 = background).

        Meant for tests and label images; the tracker uses the shape model's rasteriser.
        """
        rows, x0s, x1s, ps, offs = [], [], [], [], [0]
        for k, m in enumerate(masks):
            lab = np.asarray(parts[k] if parts is not None else m).astype(np.int16)
            lab = np.where(np.asarray(m, bool), lab, 0)
            # run boundaries along each row: consecutive label changes delimit runs
            pad = np.pad(lab, ((0, 0), (1, 1)))
            r, c = np.nonzero(np.diff(pad, axis=1) != 0)
            same = r[:-1] == r[1:]
            r0, a, b = r[:-1][same], c[:-1][same], c[1:][same]
            v = lab[r0, a] if r0.size else np.zeros(0, np.int16)
            keep = v != 0
            rows.append(r0[keep]), x0s.append(a[keep]), x1s.append(b[keep])
            ps.append(v[keep])
            offs.append(offs[-1] + int(keep.sum()))
        cat = (lambda xs, dt: np.concatenate(xs).astype(dt) if xs else np.zeros(0, dt))
        return Spans(cat(rows, np.int32), cat(x0s, np.int32), cat(x1s, np.int32),
                     cat(ps, np.int8), np.asarray(offs, np.int64))


def span_count(spans: Spans) -> int:
    """Number of silhouettes of a :class:`Spans` or ``shape.Silhouettes`` object."""
    return int(len(spans.offsets) - 1)


def span_owner(spans: Spans) -> np.ndarray:
    """(S,) silhouette index of each span."""
    return np.repeat(np.arange(span_count(spans)), np.diff(spans.offsets))


class ForegroundIntegral:
    """Row prefix sums of a foreground mask for O(1) per-span pixel counts.

    Args:
        foreground: (H, W) bool foreground mask.
        unknown: optional (H, W) bool pixels to ignore (e.g. explained by current tracks).
    """

    def __init__(self, foreground: np.ndarray, unknown: np.ndarray | None = None) -> None:
        fg = np.ascontiguousarray(foreground, dtype=bool)
        if fg.ndim != 2:
            raise DetectionError(f'foreground mask must be (H, W), got {fg.shape}')
        self.shape = fg.shape
        known = np.ones((1, 1), bool) if unknown is None else \
            ~np.ascontiguousarray(unknown, dtype=bool)
        if unknown is not None and known.shape != fg.shape:
            raise DetectionError('unknown-pixel mask and foreground mask differ in shape')
        self._fg, self._known = _row_prefix_sums(fg, known)

    def counts(self, spans: Spans) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Raw pixel counts of N silhouettes: (foreground & known, known, area), (N,) each."""
        return _coverage_kernel(
            self._fg, self._known, np.ascontiguousarray(spans.row, np.int64),
            np.ascontiguousarray(spans.x0, np.int64), np.ascontiguousarray(spans.x1, np.int64),
            np.ascontiguousarray(spans.offsets, np.int64))

    def coverage(self, spans: Spans) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Coverage of N silhouettes.

        Returns:
            coverage: (N,) foreground fraction of the known silhouette pixels (0 if none).
            known: (N,) fraction of the silhouette pixels that are known (not ignored).
            area: (N,) silhouette pixels inside the image.
        """
        return _coverage(*self.counts(spans))


def span_counts(foreground: np.ndarray, spans: Spans, unknown: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ForegroundIntegral(foreground, unknown).counts(spans)`` by visiting the spans'
    pixels instead of summing every image row: cheaper for a few silhouettes (the tracks)
    than the prefix sums, which pay off for the detector's thousands of hypotheses."""
    fg = np.ascontiguousarray(foreground, dtype=bool)
    if fg.ndim != 2:
        raise DetectionError(f'foreground mask must be (H, W), got {fg.shape}')
    if unknown is not None and np.shape(unknown) != fg.shape:
        raise DetectionError('unknown-pixel mask and foreground mask differ in shape')
    unk = np.zeros((1, 1), bool) if unknown is None else \
        np.ascontiguousarray(unknown, dtype=bool)
    return _span_counts_kernel(
        fg, unk, np.ascontiguousarray(spans.row, np.int64),
        np.ascontiguousarray(spans.x0, np.int64), np.ascontiguousarray(spans.x1, np.int64),
        np.ascontiguousarray(spans.offsets, np.int64))


def span_coverage(foreground: np.ndarray, spans: Spans, unknown: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ForegroundIntegral(foreground, unknown).coverage(spans)`` from :func:`span_counts`."""
    return _coverage(*span_counts(foreground, spans, unknown))


def _coverage(fg_n: np.ndarray, kn_n: np.ndarray, area: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(coverage, known fraction, area) from the raw counts (see ForegroundIntegral)."""
    cov = np.where(kn_n > 0, fg_n / np.maximum(kn_n, 1.0), 0.0)
    known = np.where(area > 0, kn_n / np.maximum(area, 1.0), 0.0)
    return cov, known, area


@njit(cache=True, nogil=True, inline='always')
def _clipped_span(r: int, x0: int, x1: int, h: int, w: int
                  ) -> tuple[int, int, int]:  # pragma: no cover - compiled
    """A span (row r, columns [x0, x1)) clipped to an h x w image: (r, a, b), empty
    (b <= a) when the row is outside the image."""
    if r < 0 or r >= h:
        return r, 0, 0
    return r, min(max(x0, 0), w), min(max(x1, 0), w)


@njit(cache=True, nogil=True)
def _span_counts_kernel(fg: np.ndarray, unknown: np.ndarray, row: np.ndarray, x0: np.ndarray,
                        x1: np.ndarray, offsets: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    """Per silhouette: pixels that are foreground and known, known, inside the image (each
    span counted on its own, clipped to the image, as in ``_coverage_kernel``); ``unknown``
    (1, 1) means every pixel is known."""
    h, w = fg.shape
    all_known = unknown.shape[0] == 1 and unknown.shape[1] == 1 and (h != 1 or w != 1)
    n = offsets.size - 1
    fg_n = np.zeros(n)
    kn_n = np.zeros(n)
    area = np.zeros(n)
    for i in range(n):
        a_fg = 0
        a_kn = 0
        a_area = 0
        for s in range(offsets[i], offsets[i + 1]):
            r, a, b = _clipped_span(row[s], x0[s], x1[s], h, w)
            if b <= a:
                continue
            a_area += b - a
            for c in range(a, b):
                if all_known or not unknown[r, c]:
                    a_kn += 1
                    if fg[r, c]:
                        a_fg += 1
        fg_n[i] = a_fg
        kn_n[i] = a_kn
        area[i] = a_area
    return fg_n, kn_n, area


@njit(cache=True, nogil=True)
def _row_prefix_sums(fg: np.ndarray, known: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Row prefix sums (H, W + 1) int32 of ``fg & known`` and of ``known``, both in one
    pass; ``known`` (1, 1) means every pixel is known."""
    h, w = fg.shape
    all_known = known.shape[0] == 1 and known.shape[1] == 1 and (h != 1 or w != 1)
    cs_fg = np.zeros((h, w + 1), np.int32)
    cs_known = np.zeros((h, w + 1), np.int32)
    for i in range(h):
        a = 0
        b = 0
        for j in range(w):
            k = True if all_known else known[i, j]
            if k:
                b += 1
                if fg[i, j]:
                    a += 1
            cs_fg[i, j + 1] = a
            cs_known[i, j + 1] = b
    return cs_fg, cs_known


@njit(cache=True, nogil=True)
def _coverage_kernel(cs_fg: np.ndarray, cs_known: np.ndarray, row: np.ndarray, x0: np.ndarray,
                     x1: np.ndarray, offsets: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    h = cs_fg.shape[0]
    w = cs_fg.shape[1] - 1
    n = offsets.size - 1
    fg_n = np.zeros(n)
    kn_n = np.zeros(n)
    area = np.zeros(n)
    for i in range(n):
        # integer sums in registers (exact), stored once: 20 % faster than adding to the
        # output arrays span by span on the detector's coarse grid
        a_fg = 0
        a_kn = 0
        a_area = 0
        for s in range(offsets[i], offsets[i + 1]):
            r, a, b = _clipped_span(row[s], x0[s], x1[s], h, w)
            if b <= a:
                continue
            a_fg += cs_fg[r, b] - cs_fg[r, a]
            a_kn += cs_known[r, b] - cs_known[r, a]
            a_area += b - a
        fg_n[i] = a_fg
        kn_n[i] = a_kn
        area[i] = a_area
    return fg_n, kn_n, area


@dataclass(frozen=True)
class EdgeMap:
    """Validated edges of one image with their distance transform (003 §4.2, Fig. 4).

    Attributes:
        edges: (H, W) bool validated edge pixels.
        distance: (H, W) float32 distance to the nearest validated edge, pixels
            (``inf``-like large value when there is none).
        gx, gy: (H, W) float32 unit gradient direction of the nearest edge pixel.
    """

    edges: np.ndarray
    distance: np.ndarray
    gx: np.ndarray
    gy: np.ndarray

    @classmethod
    def from_image(cls, image: np.ndarray, foreground: np.ndarray | None = None, *,
                   canny: tuple[float, float] = (40.0, 120.0), min_edge_pixels: int = 12,
                   neighbourhood: int = 7) -> EdgeMap:
        """Canny edges of an RGB image (H, W, 3) validated and distance-transformed.

        Edges are kept only inside the ``neighbourhood``-pixel dilation of ``foreground``
        (when given: motion/foreground regions), and only in 8-connected components of at
        least ``min_edge_pixels`` pixels (003 §4.2: connected-component validation).
        """
        if image.ndim != 3 or image.shape[2] != 3:
            raise DetectionError(f'expected an (H, W, 3) RGB image, got {image.shape}')
        gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        gray = cv2.GaussianBlur(gray, (3, 3), 0)
        edges = cv2.Canny(gray, canny[0], canny[1], L2gradient=True)
        if foreground is not None:
            k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE,
                                          (2 * neighbourhood + 1, 2 * neighbourhood + 1))
            roi = cv2.dilate(np.asarray(foreground, np.uint8), k)
            edges &= roi * 255
        if min_edge_pixels > 1 and edges.any():
            # components only within the box of the edge pixels (the same components)
            bx, by, bw, bh = cv2.boundingRect(edges)
            box = (slice(by, by + bh), slice(bx, bx + bw))
            n, labels, stats, _ = cv2.connectedComponentsWithStats(
                (edges[box] > 0).view(np.uint8), connectivity=8)
            keep = stats[:, cv2.CC_STAT_AREA] >= min_edge_pixels
            keep[0] = False
            edges = np.zeros(edges.shape, bool)
            edges[box] = keep[labels]
        else:
            edges = edges > 0
        h, w = edges.shape
        if not edges.any():
            big = np.full((h, w), float(h + w), np.float32)
            zero = np.zeros((h, w), np.float32)
            return cls(edges, big, zero, zero)
        sx = cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3)
        sy = cv2.Sobel(gray, cv2.CV_32F, 0, 1, ksize=3)
        # Distance transform with pixel labels: label k (1-based) is the k-th zero pixel
        # of the source in raster order, i.e. the k-th validated edge pixel.
        src = (~edges).view(np.uint8)
        dist, labels = cv2.distanceTransformWithLabels(
            src, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
        ey, ex = np.nonzero(edges)
        gxe, gye = sx[ey, ex], sy[ey, ex]
        norm = np.maximum(np.hypot(gxe, gye), 1e-6)
        gxe, gye = gxe / norm, gye / norm
        idx = labels - 1
        return cls(edges, dist.astype(np.float32, copy=False),
                   gxe.astype(np.float32, copy=False)[idx],
                   gye.astype(np.float32, copy=False)[idx])


@dataclass(frozen=True)
class Outline:
    """Outline pixels of N silhouettes with outward unit normals.

    Attributes:
        x, y: (P,) int64 pixel coordinates (inside the image).
        nx, ny: (P,) float64 outward unit normals.
        owner: (P,) int64 silhouette index of each outline pixel.
        count: N.
    """

    x: np.ndarray
    y: np.ndarray
    nx: np.ndarray
    ny: np.ndarray
    owner: np.ndarray
    count: int


def outline(spans: Spans, height: int, width: int) -> Outline:
    """Outline of the union of the parts of each silhouette, with normals.

    Per silhouette and row the leftmost and rightmost pixels form the side contour; the
    normal follows from the row-to-row slope of that side. The first and last rows add a
    horizontal top/bottom contour with normals (0, -1) / (0, 1).
    """
    n = span_count(spans)
    owner = span_owner(spans).astype(np.int64)
    row = spans.row.astype(np.int64)
    if row.size == 0:
        e = np.zeros(0, np.int64)
        return Outline(e, e, e.astype(float), e.astype(float), e, n)
    key = owner * (height + 4096) + (row + 2048)
    ukey, inv = np.unique(key, return_inverse=True)
    xl = np.full(ukey.size, np.iinfo(np.int64).max)
    xr = np.full(ukey.size, np.iinfo(np.int64).min)
    np.minimum.at(xl, inv, spans.x0.astype(np.int64))
    np.maximum.at(xr, inv, spans.x1.astype(np.int64) - 1)
    own = ukey // (height + 4096)
    r = ukey % (height + 4096) - 2048
    first = np.ones(ukey.size, bool)
    first[1:] = own[1:] != own[:-1]
    last = np.ones(ukey.size, bool)
    last[:-1] = own[1:] != own[:-1]

    def slope(x: np.ndarray) -> np.ndarray:
        nxt = np.where(last, x, np.roll(x, -1))
        prv = np.where(first, x, np.roll(x, 1))
        den = np.where(first | last, 1.0, 2.0)
        den = np.where(first & last, 1.0, den)
        return (nxt - prv) / den

    dl, dr = slope(xl.astype(float)), slope(xr.astype(float))
    # left side: tangent (dl, 1), outward normal (-1, dl); right side: normal (1, -dr)
    nl = np.hypot(1.0, dl)
    nr = np.hypot(1.0, dr)
    xs = [xl, xr]
    ys = [r, r]
    nxs = [-1.0 / nl, 1.0 / nr]
    nys = [dl / nl, -dr / nr]
    owners = [own, own]
    # top and bottom rows: horizontal contour between the sides
    for sel, ny in ((first, -1.0), (last, 1.0)):
        lo, hi = xl[sel] + 1, xr[sel]
        cnt = np.maximum(hi - lo, 0)
        rep = np.repeat(np.arange(cnt.size), cnt)
        start = np.repeat(np.cumsum(cnt) - cnt, cnt)
        xs.append(lo[rep] + (np.arange(rep.size) - start))
        ys.append(r[sel][rep])
        nxs.append(np.zeros(rep.size))
        nys.append(np.full(rep.size, ny))
        owners.append(own[sel][rep])
    x = np.concatenate(xs)
    y = np.concatenate(ys)
    # pixels on the image border are where a clipped silhouette was cut, not its contour
    inside = (x >= 1) & (x < width - 1) & (y >= 1) & (y < height - 1)
    return Outline(x[inside], y[inside], np.concatenate(nxs)[inside],
                   np.concatenate(nys)[inside], np.concatenate(owners)[inside], n)


def contour_loglik(edge_map: EdgeMap, contour: Outline, body_width: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Contour log-likelihood of N hypotheses, 003 Eq. 5.

    Args:
        edge_map: validated edges of the image.
        contour: outline pixels with normals (from :func:`outline`).
        body_width: (N,) projected body width Delta(x) of each hypothesis, pixels.

    Returns:
        loglik: (N,) ``-1/|C| sum_u [min(1, D/(0.3 Delta)) - 0.5 |<N, G>|]``, in
            [-1, 0.5]; -1 for hypotheses without outline pixels in the image.
        length: (N,) outline pixels used.
    """
    n = contour.count
    width = np.maximum(np.asarray(body_width, np.float64), 1.0)
    d = edge_map.distance[contour.y, contour.x].astype(np.float64)
    scale = 0.3 * width[contour.owner]
    # 003 Eq. 5, first term: distance to the nearest edge, saturated at 30% body width.
    term = np.minimum(1.0, d / scale)
    # 003 Eq. 5, second term: alignment of the nearest edge's gradient with the contour
    # normal. The gradient sign depends on which side is brighter, hence |<N, G>|; a
    # saturated (missing) edge gets no orientation credit.
    dot = np.abs(contour.nx * edge_map.gx[contour.y, contour.x]
                 + contour.ny * edge_map.gy[contour.y, contour.x])
    term = term - 0.5 * np.where(d < scale, dot, 0.0)
    total = np.bincount(contour.owner, weights=term, minlength=n)
    length = np.bincount(contour.owner, minlength=n).astype(np.float64)
    loglik = np.where(length > 0, -total / np.maximum(length, 1.0), -1.0)
    return loglik, length


@njit(cache=True, nogil=True)
def _contour_kernel(dist: np.ndarray, gx: np.ndarray, gy: np.ndarray, row: np.ndarray,
                    x0: np.ndarray, x1: np.ndarray, offsets: np.ndarray, width: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """003 Eq. 5 straight from the spans: same outline and terms as :func:`outline` +
    :func:`contour_loglik`, without materialising the outline."""
    h, w = dist.shape
    n = offsets.size - 1
    loglik = np.full(n, -1.0)
    length = np.zeros(n)
    for i in range(n):
        s0, s1 = offsets[i], offsets[i + 1]
        if s1 <= s0:
            continue
        rmin = row[s0]
        rmax = row[s0]
        for s in range(s0, s1):
            rmin = min(rmin, row[s])
            rmax = max(rmax, row[s])
        nr = rmax - rmin + 1
        xl = np.full(nr, 1 << 40)
        xr = np.full(nr, -(1 << 40))
        for s in range(s0, s1):
            k = row[s] - rmin
            xl[k] = min(xl[k], x0[s])
            xr[k] = max(xr[k], x1[s] - 1)
        rows = np.empty(nr, np.int64)
        m = 0
        for k in range(nr):
            if xl[k] <= xr[k] + 1 and xl[k] < (1 << 40):
                rows[m] = k
                m += 1
        scale = 0.3 * max(width[i], 1.0)
        total = 0.0
        cnt = 0.0
        for j in range(m):
            k = rows[j]
            y = rmin + k
            for side in range(2):
                xs = xl if side == 0 else xr
                if m == 1:
                    sl = 0.0
                elif j == 0:
                    sl = float(xs[rows[1]] - xs[k])
                elif j == m - 1:
                    sl = float(xs[k] - xs[rows[j - 1]])
                else:
                    sl = 0.5 * float(xs[rows[j + 1]] - xs[rows[j - 1]])
                nrm = np.sqrt(1.0 + sl * sl)
                if side == 0:
                    nx, ny = -1.0 / nrm, sl / nrm
                else:
                    nx, ny = 1.0 / nrm, -sl / nrm
                x = xs[k]
                if 1 <= x < w - 1 and 1 <= y < h - 1:
                    d = dist[y, x]
                    t = min(1.0, d / scale)
                    if d < scale:
                        t -= 0.5 * abs(nx * gx[y, x] + ny * gy[y, x])
                    total += t
                    cnt += 1.0
            for top in range(2):
                if (top == 0 and j != 0) or (top == 1 and j != m - 1):
                    continue
                ny = -1.0 if top == 0 else 1.0
                if not (1 <= y < h - 1):
                    continue
                for x in range(xl[k] + 1, xr[k]):
                    if 1 <= x < w - 1:
                        d = dist[y, x]
                        t = min(1.0, d / scale)
                        if d < scale:
                            t -= 0.5 * abs(ny * gy[y, x])
                        total += t
                        cnt += 1.0
        if cnt > 0:
            loglik[i] = -total / cnt
            length[i] = cnt
    return loglik, length


def contour_loglik_spans(edge_map: EdgeMap, spans: Spans, body_width: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """003 Eq. 5 for N silhouettes given as spans (compiled; equals
    ``contour_loglik(edge_map, outline(spans, H, W), body_width)``)."""
    return _contour_kernel(edge_map.distance, edge_map.gx, edge_map.gy,
                           np.ascontiguousarray(spans.row, np.int64),
                           np.ascontiguousarray(spans.x0, np.int64),
                           np.ascontiguousarray(spans.x1, np.int64),
                           np.ascontiguousarray(spans.offsets, np.int64),
                           np.ascontiguousarray(body_width, np.float64))


@njit(cache=True, nogil=True)
def _symmetry_kernel(colour: np.ndarray, row: np.ndarray, x0: np.ndarray, x1: np.ndarray,
                     part: np.ndarray, offsets: np.ndarray, torso: int, merge: np.ndarray,
                     bins: int, min_pixels: int) -> np.ndarray:  # pragma: no cover
    """Left/right torso histogram distances; ``colour`` (H, W) are the 8x8x8 bins, merged
    to ``bins`` through the table ``merge`` (512,) at the pixels visited (not over the
    whole image). A span's pixels left of its centre column count left, right of it
    right, the centre pixel of an odd span neither."""
    n = offsets.size - 1
    out = np.full(n, np.nan)
    h, w = colour.shape
    left = np.zeros(bins)
    right = np.zeros(bins)
    for i in range(n):
        left[:] = 0.0
        right[:] = 0.0
        nl = 0.0
        nr = 0.0
        for s in range(offsets[i], offsets[i + 1]):
            if part[s] != torso:
                continue
            r = row[s]
            if r < 0 or r >= h:
                continue
            a = x0[s]
            b = x1[s]
            lo = max(a, 0)
            hi = min(b, w)
            # 2x + 1 < a + b (left of the centre), 2x + 1 > a + b (right of it)
            for x in range(lo, min(hi, (a + b) // 2)):
                left[merge[colour[r, x]]] += 1.0
                nl += 1.0
            for x in range(max(lo, (a + b + 1) // 2), hi):
                right[merge[colour[r, x]]] += 1.0
                nr += 1.0
        if nl >= min_pixels and nr >= min_pixels:
            d = 0.0
            for c in range(bins):
                d += abs(left[c] / nl - right[c] / nr)
            out[i] = d
    return out


def colour_symmetry(image: np.ndarray, spans: Spans, *, levels: int = 4,
                    min_pixels: int = 8, bins: np.ndarray | None = None) -> np.ndarray:
    """Upper-body colour symmetry of N hypotheses (003 §4.2, third feature).

    The torso spans of each silhouette are split at their centre column; the L1 distance
    between the normalised RGB histograms of the left and right halves is returned, (N,)
    float64 in [0, 2]; NaN where a half has fewer than ``min_pixels`` pixels in the image.
    Colours are the appearance model's 8x8x8 bins (:func:`appearance.quantize`, pass
    ``bins`` to reuse them) merged to ``levels`` (1, 2, 4 or 8) per channel, because half a
    torso has only a few hundred pixels.
    """
    if levels not in (1, 2, 4, 8):
        raise DetectionError(f'histogram levels must be 1, 2, 4 or 8, got {levels}')
    if bins is None:
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise DetectionError(f'expected an (H, W, 3) uint8 RGB image, got {image.shape}')
        bins = quantize(image)
    q = np.arange(512)                      # 8x8x8 bin -> levels^3 bin
    f = 8 // levels
    merge = (((q >> 6) // f) * levels + ((q >> 3) & 7) // f) * levels + (q & 7) // f
    return _symmetry_kernel(np.ascontiguousarray(bins, dtype=np.int16),
                            np.ascontiguousarray(spans.row, np.int64),
                            np.ascontiguousarray(spans.x0, np.int64),
                            np.ascontiguousarray(spans.x1, np.int64),
                            np.ascontiguousarray(spans.part, np.int64),
                            np.ascontiguousarray(spans.offsets, np.int64), TORSO,
                            merge, levels ** 3, min_pixels)
