"""Appearance model of 003 §2.2 and §3.1: key-view part colour histograms.

Colours are quantised uniformly into 8 x 8 x 8 RGB bins (``bin = (r >> 5) * 64 +
(g >> 5) * 8 + (b >> 5)``), once per image. A person is described by one histogram per body
part (head, torso, legs) for each of a few key views, annotated with the relative viewing
angle under which the view was seen (0 = person facing the camera); histograms for a new
relative angle are interpolated from the two closest key views (003 Eq. 1-2). Histograms are
compared with the Bhattacharyya-coefficient based distance of 003 Eq. 4.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from mbtrack_ros.core import _kernels
from mbtrack_ros.core.camera import Camera, RoomCalibration
from mbtrack_ros.core.shape import BodyShape, Silhouettes, rasterize
from mbtrack_ros.core.state import STATE_DIM, THETA, X, Y

__all__ = ['N_BINS', 'N_PARTS', 'AppearanceError', 'PersonModel', 'bhattacharyya_distance_sq',
           'key_view_loglik', 'key_view_stack', 'model_distance', 'model_from_images',
           'part_histograms', 'quantize', 'relative_angle', 'single_target_loglik',
           'view_weights']

N_BINS = _kernels.N_BINS
N_PARTS = _kernels.N_PARTS
MERGE_ANGLE = np.deg2rad(20.0)


class AppearanceError(ValueError):
    """Bad input to the appearance model (image format, histogram shape, empty model)."""


def quantize(image: np.ndarray) -> np.ndarray:
    """RGB image (H, W, 3) uint8 -> (H, W) int16 colour bin indices in [0, 512)."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise AppearanceError(
            f'expected an (H, W, 3) uint8 RGB image, got {image.shape} {image.dtype}')
    return _kernels.quantize_rgb(np.ascontiguousarray(image))


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (np.asarray(angle, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi


def relative_angle(theta: np.ndarray, viewing_angle: np.ndarray) -> np.ndarray:
    """Body orientation relative to a camera, wrapped to [-pi, pi) (0 = facing it)."""
    return _wrap(np.asarray(theta) - np.asarray(viewing_angle))


def _normalise(hists: np.ndarray) -> np.ndarray:
    total = hists.sum(axis=-1, keepdims=True)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(total > 0, hists / np.where(total > 0, total, 1.0), 0.0)


def bhattacharyya_distance_sq(h: np.ndarray, k: np.ndarray) -> np.ndarray:
    """003 Eq. 4: d^2 = 1 - sum_i sqrt(h_i k_i) over the last axis (normalised histograms).

    Broadcasts over leading axes; the result is clipped to [0, 1].
    """
    h = np.asarray(h, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64)
    if h.shape[-1] != k.shape[-1]:
        raise AppearanceError(f'histogram sizes differ: {h.shape[-1]} vs {k.shape[-1]}')
    return np.clip(1.0 - np.sqrt(h * k).sum(axis=-1), 0.0, 1.0)


@dataclass(eq=False)
class PersonModel:
    """Appearance and size of one person (003 §2.1-2.2).

    Attributes:
        height, width: body size, metres.
        view_angles: (V,) relative viewing angles of the key views, radians (0 = facing the
            camera).
        histograms: (V, 3, 512) part histograms (head, torso, legs), each normalised to sum
            1 (an all-zero row means the part was never seen).
        chair_height: hip height when sitting, metres.
    """

    height: float
    width: float
    view_angles: np.ndarray = field(default_factory=lambda: np.zeros(0))
    histograms: np.ndarray = field(default_factory=lambda: np.zeros((0, N_PARTS, N_BINS)))
    chair_height: float = 0.45

    def __post_init__(self) -> None:
        if not (np.isfinite(self.height) and self.height > 0 and np.isfinite(self.width)
                and self.width > 0):
            raise AppearanceError(f'bad person size h={self.height} w={self.width}')
        self.view_angles = _wrap(np.atleast_1d(np.asarray(self.view_angles, np.float64)))
        hists = np.asarray(self.histograms, dtype=np.float64)
        if hists.ndim == 2:
            hists = hists[None]
        if hists.ndim != 3 or hists.shape[1:] != (N_PARTS, N_BINS):
            raise AppearanceError(f'histograms must be (V, 3, 512), got {hists.shape}')
        if hists.shape[0] != self.view_angles.shape[0]:
            raise AppearanceError(
                f'{hists.shape[0]} key views but {self.view_angles.shape[0]} view angles')
        if not np.all(np.isfinite(hists)) or np.any(hists < 0):
            raise AppearanceError('histograms must be finite and non-negative')
        self.histograms = _normalise(hists)

    @property
    def shape(self) -> BodyShape:
        """The body shape model of this person."""
        return BodyShape(height=float(self.height), width=float(self.width),
                         chair_height=float(self.chair_height))

    def interpolate(self, rel_angles: np.ndarray) -> np.ndarray:
        """Part histograms for relative viewing angles (N,) -> (N, 3, 512) (003 Eq. 1-2).

        The two key views closest in angle are mixed with weights linear in the angular
        offset and summing to 1: ``w_a = d_b / (d_a + d_b)``. (003 Eq. 2 as printed,
        ``w ~ 2/pi acos<o, o_v>``, lost the ``1 -``: a view must weigh more the closer it
        is; for key views 90 degrees apart both forms coincide.) One key view -> itself.
        """
        va, vb, wa = self.interpolation_weights(rel_angles)
        hists = self._completed()
        return (wa[:, None, None] * hists[va] + (1.0 - wa)[:, None, None] * hists[vb])

    def completed_histograms(self) -> np.ndarray:
        """Key views (V, 3, 512) with parts never seen in a view (e.g. the legs of a view
        acquired while sitting) taken from the angularly nearest view that has them, so
        that interpolated part histograms stay normalised."""
        return self._completed().copy()

    def _completed(self) -> np.ndarray:
        """:meth:`completed_histograms` (not to be modified), recomputed only when the key
        views changed: the views it was made from are kept and compared by value, so
        in-place edits of ``histograms`` / ``view_angles`` are seen too."""
        cache = getattr(self, '_completed_cache', None)
        if (cache is None or cache[0].shape != self.histograms.shape
                or cache[1].shape != self.view_angles.shape
                or not np.array_equal(cache[0], self.histograms)
                or not np.array_equal(cache[1], self.view_angles)):
            cache = (self.histograms.copy(), self.view_angles.copy(), self._complete())
            self._completed_cache = cache
        return cache[2]

    def _complete(self) -> np.ndarray:
        hists = self.histograms.copy()
        seen = hists.sum(axis=2) > 0                               # (V, 3)
        if seen.all() or self.view_angles.size < 2:
            return hists
        dist = np.abs(_wrap(self.view_angles[:, None] - self.view_angles[None, :]))
        for v, q in zip(*np.nonzero(~seen)):
            donors = np.flatnonzero(seen[:, q])
            if donors.size:
                hists[v, q] = self.histograms[donors[np.argmin(dist[v, donors])], q]
        return hists

    def interpolation_weights(self, rel_angles: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The two key views (N,) int64 ``va``, ``vb`` and the weight (N,) of ``va`` used by
        :meth:`interpolate` (the likelihood kernels mix histograms lazily with them)."""
        if self.view_angles.size == 0:
            raise AppearanceError('person model has no key views')
        rel = np.ascontiguousarray(np.atleast_1d(np.asarray(rel_angles, dtype=np.float64)))
        va = np.empty(rel.size, np.int64)
        vb = np.empty(rel.size, np.int64)
        wa = np.empty(rel.size)
        _kernels.nearest_two_views(rel, np.zeros(rel.size, np.int64), self.view_angles[None],
                                   np.array([self.view_angles.size]), va, vb, wa)
        return va, vb, wa

    def add_view(self, angle: float, hists: np.ndarray, *,
                 merge_angle: float = MERGE_ANGLE, rate: float = 0.5) -> None:
        """Add a key view (3, 512) seen under relative angle ``angle`` (radians).

        A view closer than ``merge_angle`` to an existing one is blended into it instead:
        histograms per part ``(1 - rate) old + rate new`` and the angle moved by ``rate``
        of the difference on the circle (``rate`` 0.5: the average, as acquisition merges
        two cameras; a part missing in one of them is taken from the other).
        """
        if not 0.0 < rate <= 1.0:
            raise AppearanceError(f'rate must be in (0, 1], got {rate}')
        hists = np.asarray(hists, dtype=np.float64)
        if hists.shape != (N_PARTS, N_BINS):
            raise AppearanceError(f'a key view is (3, 512) histograms, got {hists.shape}')
        if not np.all(np.isfinite(hists)) or np.any(hists < 0):
            raise AppearanceError('histograms must be finite and non-negative')
        hists = _normalise(hists)
        angle = float(_wrap(angle))
        if self.view_angles.size:
            dist = np.abs(_wrap(angle - self.view_angles))
            j = int(np.argmin(dist))
            if dist[j] < merge_angle:
                old = self.histograms[j]
                seen_old = old.sum(axis=1) > 0
                seen_new = hists.sum(axis=1) > 0
                both = (seen_old & seen_new)[:, None]
                merged = np.where(both, (1.0 - rate) * old + rate * hists,
                                  np.where(seen_new[:, None], hists, old))
                self.histograms[j] = _normalise(merged)
                self.view_angles[j] = float(_wrap(self.view_angles[j]
                                                  + rate * _wrap(angle - self.view_angles[j])))
                return
        self.view_angles = np.append(self.view_angles, angle)
        self.histograms = np.concatenate([self.histograms, hists[None]], axis=0)

    def adapt(self, angle: float, hists: np.ndarray, rate: float, *,
              merge_angle: float = MERGE_ANGLE) -> bool:
        """Learn part histograms (3, 512) observed under relative angle ``angle`` slowly:
        blended at ``rate`` into the key view within ``merge_angle`` (:meth:`add_view`), or,
        for an angle the model has no key view for, a new key view that starts as the
        model's interpolation there (003 Eq. 1-2) moved by ``rate`` toward the observation
        (the interpolation is what the tracker used for that angle until now). Parts
        without mass in the observation are left as they are. Returns True when a key view
        was added."""
        hists = _normalise(np.asarray(hists, dtype=np.float64))
        if hists.shape != (N_PARTS, N_BINS):
            raise AppearanceError(f'a key view is (3, 512) histograms, got {hists.shape}')
        angle = float(_wrap(angle))
        near = self.view_angles.size and \
            float(np.min(np.abs(_wrap(angle - self.view_angles)))) < merge_angle
        if near:
            self.add_view(angle, hists, merge_angle=merge_angle, rate=rate)
            return False
        start = self.interpolate(np.array([angle]))[0]
        seen = (hists.sum(axis=1) > 0)[:, None]
        self.add_view(angle, np.where(seen, (1.0 - rate) * start + rate * hists, start),
                      merge_angle=merge_angle)
        return True


def model_distance(a: PersonModel, b: PersonModel) -> float:
    """How unlike two people look: the Bhattacharyya distance (003 Eq. 4) between their
    view-averaged part histograms, averaged over the parts both models have seen (1.0, the
    largest, when they share none). Views are averaged because the two models' key views
    were taken from different angles."""
    ha, hb = a.completed_histograms(), b.completed_histograms()
    if not len(ha) or not len(hb):
        return 1.0
    ma, mb = _normalise(ha.mean(axis=0)), _normalise(hb.mean(axis=0))     # (3, 512)
    both = (ma.sum(axis=1) > 0) & (mb.sum(axis=1) > 0)
    if not both.any():
        return 1.0
    return float(np.sqrt(bhattacharyya_distance_sq(ma[both], mb[both])).mean())


def _check_bins(bins: np.ndarray, silhouettes: Silhouettes) -> np.ndarray:
    bins = np.asarray(bins)
    if bins.shape != (silhouettes.height, silhouettes.width):
        raise AppearanceError(f'bin image {bins.shape} does not match the silhouettes '
                              f'({silhouettes.height}, {silhouettes.width})')
    if bins.dtype != np.int16:
        raise AppearanceError(f'bin image must be int16 (see quantize), got {bins.dtype}')
    return bins


def part_histograms(bins: np.ndarray, silhouettes: Silhouettes, i: int,
                    weights_map: np.ndarray | None = None, *,
                    normalize: bool = True) -> np.ndarray:
    """Part colour histograms (3, 512) of particle ``i`` from its spans.

    Args:
        bins: (H, W) int16 quantised image (:func:`quantize`).
        silhouettes: rasterised particles; ``i`` indexes them.
        weights_map: optional (H, W) per-pixel weights (e.g. 1 - occlusion), default 1.
        normalize: normalise each part to sum 1 (a part without mass stays 0).
    """
    bins = _check_bins(bins, silhouettes)
    if not 0 <= i < len(silhouettes):
        raise AppearanceError(f'particle index {i} out of range [0, {len(silhouettes)})')
    s0, s1 = int(silhouettes.offsets[i]), int(silhouettes.offsets[i + 1])
    if weights_map is None:
        wmap = np.ones((1, 1, 1))
        nch = 0
    else:
        wmap = np.asarray(weights_map, dtype=np.float64)
        if wmap.shape != bins.shape:
            raise AppearanceError(f'weights map {wmap.shape} does not match {bins.shape}')
        wmap = np.ascontiguousarray(wmap[:, :, None])
        nch = 1
    hist = _kernels.histogram_of(bins, silhouettes.row, silhouettes.x0, silhouettes.x1,
                                 silhouettes.part, s0, s1, wmap, 0, 0, nch)
    return _normalise(hist) if normalize else hist


def single_target_loglik(bins: np.ndarray, silhouettes: Silhouettes,
                         model_hists: np.ndarray, *, sigma: float = 0.12,
                         min_pixels: int = 1) -> np.ndarray:
    """003 Eq. 3 for N silhouettes in one camera -> (N,) log-likelihoods.

    ``-(sum_parts a_part d^2_part) / (2 sigma^2 sum_parts a_part)`` with ``model_hists``
    (N, 3, 512) the interpolated model histograms of each particle. Particles with fewer
    than ``min_pixels`` pixels in the image contribute 0 (neutral); over several cameras
    the results add (likelihoods multiply).
    """
    n = len(silhouettes)
    model_hists = np.asarray(model_hists, dtype=np.float64)
    if model_hists.shape != (n, N_PARTS, N_BINS):
        raise AppearanceError(f'model_hists must be ({n}, 3, 512), got {model_hists.shape}')
    zero = np.zeros(n, np.int64)
    return key_view_loglik(bins, silhouettes, model_hists.reshape(n, 1, -1), np.arange(n),
                           zero, zero, np.ones(n), sigma=sigma, min_pixels=min_pixels)


def key_view_loglik(bins: np.ndarray, silhouettes: Silhouettes, key: np.ndarray,
                    target: np.ndarray, va: np.ndarray, vb: np.ndarray, wa: np.ndarray, *,
                    sigma: float = 0.12, min_pixels: int = 1) -> np.ndarray:
    """:func:`single_target_loglik` with the model histograms interpolated lazily (only at
    the bins a silhouette touches): particle i has the key views ``key[target[i]]`` (K, V,
    1536) of :func:`key_view_stack`, mixed as ``wa key[., va] + (1 - wa) key[., vb]``
    (003 Eq. 1, :func:`view_weights`). The same values as :meth:`PersonModel.interpolate`
    then :func:`single_target_loglik`, without the (N, 3, 512) histograms."""
    bins = _check_bins(bins, silhouettes)
    n = len(silhouettes)
    fc, _, _ = _kernels.hjs_camera(
        bins, silhouettes.row, silhouettes.x0, silhouettes.x1, silhouettes.part,
        silhouettes.offsets, silhouettes.area, silhouettes.bbox, np.arange(n),
        np.ascontiguousarray(target, np.int64), np.ones(n),
        np.ascontiguousarray(key, np.float64), np.ascontiguousarray(va, np.int64),
        np.ascontiguousarray(vb, np.int64), np.ascontiguousarray(wa, np.float64),
        int(key.shape[0]), 0.0, True, np.zeros(0), np.zeros(n + 1, np.int64))
    out = -fc / (2.0 * sigma ** 2)
    out[silhouettes.area < max(int(min_pixels), 1)] = 0.0
    return out


def key_view_stack(models: Sequence[PersonModel]) -> np.ndarray:
    """(K, V_max, 1536) completed key-view histograms of K models, zero padded (the form in
    which the likelihood kernels interpolate them lazily, 003 Eq. 1)."""
    vmax = max((m.view_angles.size for m in models), default=1)
    key = np.zeros((len(models), max(vmax, 1), N_PARTS * N_BINS))
    for k, m in enumerate(models):
        key[k, :m.view_angles.size] = m._completed().reshape(m.view_angles.size, -1)
    return key


def view_weights(cameras: Sequence[Camera], states: np.ndarray, target: np.ndarray,
                 models: Sequence[PersonModel]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per camera and state, the two key views and the weight of the first (va, vb, wa),
    each (C, P) (003 Eq. 1-2), for the relative viewing angles of states (P, 6) of the
    models ``models[target]`` in C cameras (one numba pass per camera, no per-model work
    beyond stacking the key-view angles)."""
    shape = (len(cameras), states.shape[0])
    va = np.zeros(shape, np.int64)
    vb = np.zeros(shape, np.int64)
    wa = np.ones(shape)
    if not shape[0] or not shape[1]:
        return va, vb, wa
    n_views = np.array([m.view_angles.size for m in models], np.int64)
    if np.any(n_views == 0):
        raise AppearanceError('person model has no key views')
    angles = np.zeros((len(models), int(n_views.max())))
    for k, m in enumerate(models):
        angles[k, :n_views[k]] = m.view_angles
    target = np.ascontiguousarray(target, np.int64)
    xy = states[:, [X, Y]]
    for c, cam in enumerate(cameras):
        rel = relative_angle(states[:, THETA], cam.viewing_angle(xy))
        _kernels.nearest_two_views(rel, target, angles, n_views, va[c], vb[c], wa[c])
    return va, vb, wa


def model_from_images(images: Mapping[str, np.ndarray], calibration: RoomCalibration,
                      state: np.ndarray, height: float, width: float, *,
                      occluded: Mapping[str, np.ndarray] | None = None,
                      min_visible: float = 0.7, chair_height: float = 0.45) -> PersonModel:
    """Acquire a person model from one synchronised frame set (003 §4, 000 Fig. 5).

    Args:
        images: camera name -> (H, W, 3) uint8 RGB image.
        calibration: the room cameras.
        state: (6,) the person's state (position, orientation, sitting).
        height, width: body size, metres.
        occluded: optional camera name -> (H, W) bool, pixels hidden by something else
            (e.g. other people).
        min_visible: a camera adds a key view only if at least this fraction of the
            (unclipped) silhouette is inside the image and not occluded.

    Returns:
        the model with one key view per usable camera (views closer than 20 degrees are
        merged); it may have no key views if no camera saw the person well enough.
    """
    state = np.asarray(state, dtype=np.float64).reshape(-1)
    if state.shape != (STATE_DIM,):
        raise AppearanceError(f'state must have {STATE_DIM} entries, got {state.shape}')
    model = PersonModel(height=height, width=width, chair_height=chair_height)
    shape = model.shape
    for name, image in images.items():
        if name not in calibration.cameras:
            raise AppearanceError(f'unknown camera {name!r}')
        cam = calibration.cameras[name]
        bins = quantize(image)
        if bins.shape != (cam.height, cam.width):
            raise AppearanceError(f'{name}: image {bins.shape[::-1]} but calibration '
                                  f'{cam.width}x{cam.height}')
        sil = rasterize(cam, state[None], shape)
        full = float(sil.full_area[0])
        if full <= 0:
            continue
        wmap = None
        visible = float(sil.area[0])
        if occluded is not None and name in occluded:
            occ = np.asarray(occluded[name], dtype=bool)
            if occ.shape != bins.shape:
                raise AppearanceError(f'{name}: occlusion mask {occ.shape} != {bins.shape}')
            wmap = (~occ).astype(np.float64)
            visible = float((sil.mask(0) > 0)[~occ].sum())
        if visible / full < min_visible:
            continue
        hists = part_histograms(bins, sil, 0, wmap)
        rel = relative_angle(state[THETA], cam.viewing_angle(state[[X, Y]]))
        model.add_view(float(rel), hists)
    return model
