"""Track deletion evidence of the automatic detection: existence, duplicates, exits.

:class:`TrackDeleter` computes, per frame, each track's evidence for the existence and
visibility processes (001 §3: appearance likelihood of a few posterior particles against a
clutter likelihood, coverage of the rendered silhouette, also a little around the track:
its reach), judges two tracks on one person (which one the image supports), and keeps
the bookkeeping of reported and released ("lost") tracks. It is a part of
:class:`~mbtrack_ros.core.detection.manager.AutoDetection` and works on its state.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from mbtrack_ros.core import _kernels
from mbtrack_ros.core.appearance import PersonModel, key_view_loglik, key_view_stack, view_weights
from mbtrack_ros.core.detection.detector import FrameEvidence, is_ceiling
from mbtrack_ros.core.detection.features import span_counts
from mbtrack_ros.core.detection.release import blob_coverage, paint_blobs
from mbtrack_ros.core.existence import TrackAuxiliary, coverage_log_ratio, predictive_loglik
from mbtrack_ros.core.resampling import systematic_indices
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.state import X, Y, TrackEstimate

__all__ = ['TrackDeleter']

_MID = np.array([0.5])     # offset of the systematic selection of visibility particles
VISIBILITY_PARTICLES = 6   # posterior particles per track for p_1 (001 Eq. 18: their mean)
REACH_DIRECTIONS = 8       # places on each ring of a track's reach (reach_radius)


class TrackDeleter:
    """The deletion part of :class:`~.manager.AutoDetection` (see the module)."""

    def _note_reporting(self, stamp_ns: int, tracks: Sequence[TrackEstimate],
                        means: np.ndarray, ended: Sequence[int],
                        models: Mapping[int, PersonModel]) -> None:
        """After a frame's release: where the released tracks were (``reuse_time``) and
        the tracks not reported now or inside an exit (reported without a break since,
        for the duplicate rule)."""
        self._remember_released(stamp_ns, tracks, means, ended, models)
        depth = self.calibration.exit_depth(means[:, [X, Y]]) if len(tracks) \
            else np.zeros(0)
        for k, t in enumerate(tracks):
            if t.track_id not in ended and (not self.reported(t.track_id)
                                            or depth[k] > 0.0):
                self._shown_since[t.track_id] = int(stamp_ns)

    def _remember_released(self, stamp_ns: int, tracks: Sequence[TrackEstimate],
                           means: np.ndarray, ended: Sequence[int],
                           models: Mapping[int, PersonModel]) -> None:
        """Keep where and when the tracks released this frame were, for ``reuse_time``."""
        horizon = int(self.config.reuse_time * 1e9)
        expired = [t for t, v in self._released.items() if int(stamp_ns) - v[0] >= horizon]
        for t in expired:
            del self._released[t]
        self._lost_ended.extend(expired)
        if horizon <= 0:
            return
        for k, t in enumerate(tracks):
            if t.track_id not in ended:
                continue
            self._released[int(t.track_id)] = (int(stamp_ns), means[k, [X, Y]],
                                               models.get(t.track_id))

    def _duplicate_judge(self, tracks: Sequence[TrackEstimate], means: np.ndarray,
                         models: Mapping[int, PersonModel],
                         evidence: Mapping[str, FrameEvidence]
                         ) -> Callable[[int, int], int | None]:
        """The ``prefer`` of :meth:`Releaser.duplicates`: of two tracks on one place, the
        one whose model explains the image there better by ``duplicate_margin`` nats per
        side camera (003 Eq. 3, each model at the pair's midpoint with its own orientation,
        cameras where both silhouettes are at least half inside the image), or None. Each
        call is kept in ``duplicate_checks`` with both tracks' exclusive support."""
        index = {t.track_id: k for k, t in enumerate(tracks)}

        def prefer(a: int, b: int) -> int | None:
            ka, kb = index[a], index[b]
            ma, mb = models.get(a), models.get(b)
            fits = []
            if ma is not None and mb is not None and ma.view_angles.size \
                    and mb.view_angles.size:
                states = np.stack([means[ka], means[kb]]).astype(np.float64)
                states[:, [X, Y]] = 0.5 * (means[ka, [X, Y]] + means[kb, [X, Y]])
                fits = self._pair_logliks(states, (ma, mb), evidence)
            gain = float(np.mean([f[0] - f[1] for f in fits])) if fits else 0.0
            keep = (a if gain > 0 else b) if abs(gain) > self.config.duplicate_margin \
                else None
            own = self.releaser.exclusive_support()     # this frame's, all tracks present
            support = [round(float(own[k]), 3) if k < len(own) and np.isfinite(own[k])
                       else None for k in (ka, kb)]
            self.duplicate_checks.append({'ids': (int(a), int(b)), 'gain': round(gain, 3),
                                          'cameras': len(fits), 'keep': keep,
                                          'support': support})
            return keep
        return prefer

    def _reach_coverage(self, k: int, evidence: Mapping[str, FrameEvidence],
                        sils: Mapping[str, object], means: np.ndarray,
                        shapes: Sequence[BodyShape], tops: np.ndarray
                        ) -> tuple[np.ndarray, list[dict[str, float]]]:
        """The places (M, 2) of track k's reach (``REACH_DIRECTIONS`` places on each of
        the rings of radius ``reach_radius`` / 2 and ``reach_radius`` around its mean, but
        none within the detector's ``exclusion_radius`` of another track) and per place:
        camera -> coverage of its silhouette there (top-down cameras: the
        release's blob, doubled as in :meth:`Releaser.support`), counting only foreground
        that no other track's silhouette (blob) at its mean covers and that is not a
        possible person of the bootstrap (the background's not-yet-known foreground), over
        the whole area: a track beside a tracked person finds no support in that person,
        a track that lost its person at the start no support in their old place."""
        cfg = self.config
        if cfg.reach_radius <= 0:
            return np.zeros((0, 2)), []
        angle = np.tile(2.0 * np.pi * np.arange(REACH_DIRECTIONS) / REACH_DIRECTIONS, 2)
        radius = np.repeat([0.5 * cfg.reach_radius, cfg.reach_radius], REACH_DIRECTIONS)
        ring = np.repeat(means[k][None], len(angle), axis=0)
        ring[:, X] += radius * np.cos(angle)
        ring[:, Y] += radius * np.sin(angle)
        others = np.delete(np.arange(len(means)), k)
        if len(others) and cfg.detector.exclusion_radius > 0:
            # another track's neighbourhood is its own (as for the detector)
            gap = np.linalg.norm(ring[:, None, :2] - means[None, others, :2], axis=2)
            ring = ring[gap.min(axis=1) > cfg.detector.exclusion_radius]
        m = len(ring)
        if m == 0:
            return np.zeros((0, 2)), []
        out: list[dict[str, float]] = [{} for _ in range(m)]
        for n, sil in sils.items():
            if n not in evidence:
                continue
            cam = self.calibration.cameras[n]
            # pixels that are not the track's support: other tracks', bootstrap ghosts
            taken = self.background.model(n).possible_foreground_as_tested.copy()
            if taken.shape != evidence[n].foreground.shape:
                taken = np.zeros(evidence[n].foreground.shape, bool)
            if is_ceiling(cam):
                paint_blobs(taken, cam, means[others, :2], tops[others])
                cov, _ = blob_coverage(cam, evidence[n].foreground & ~taken, ring[:, :2],
                                       np.full(m, tops[k]))
                cov = np.minimum(2.0 * cov, 1.0)
            else:
                paint = taken.view(np.uint8)
                for j in others:
                    _kernels.paint_spans(paint, sil.row, sil.x0, sil.x1, sil.part,
                                         int(sil.offsets[j]), int(sil.offsets[j + 1]), 1,
                                         False)
                fg_free, _, area = span_counts(evidence[n].foreground,
                                               rasterize(cam, ring, shapes[k]), unknown=taken)
                cov = np.where(area > 0, fg_free / np.maximum(area, 1.0), 0.0)
            for i in range(m):
                out[i][n] = float(cov[i])
        return ring[:, [X, Y]], out

    def _ring_evidence(self, ring: Mapping[str, float], cov: Mapping[str, float],
                       weights: Mapping[str, float]) -> tuple[dict[str, float], float]:
        """A reach place's coverages on the track's cameras (those of ``cov``; 0 where the
        place is not seen) and their existence evidence (:func:`coverage_log_ratio`)."""
        on = {n: ring.get(n, 0.0) for n in cov}
        return on, coverage_log_ratio(on, weights, self.config.existence.support_gain,
                                      neutral=self.releaser.config.min_coverage)

    def _visibility_particles(self, tracks: Sequence[TrackEstimate],
                              models: Mapping[int, PersonModel], shapes: Sequence[BodyShape]
                              ) -> tuple[np.ndarray, np.ndarray, list[BodyShape]]:
        """A few posterior particles (P, 6) of every track with a model (001 Eq. 18: particle
        average), the index (P,) of their track and their shapes."""
        cfg = self.config
        rows, owner, part_shapes = [], [], []
        for k, t in enumerate(tracks):
            model = models.get(t.track_id)
            if model is None or not getattr(model, 'view_angles', np.zeros(0)).size:
                continue
            if t.particles is not None and len(t.particles):
                p = t.particles
                w = t.weights if t.weights is not None else np.full(len(p), 1.0 / len(p))
                # systematic selection at the weights' quantiles (no draw: a shared
                # generator would tie every track's sample to the number of tracks)
                idx = systematic_indices(w[None], np.array([w.sum()]), _MID,
                                         min(VISIBILITY_PARTICLES, len(p)))[0]
                rows.append(p[idx])
            else:
                rows.append(t.mean[None])
            owner.extend([k] * len(rows[-1]))
            part_shapes.extend([shapes[k]] * len(rows[-1]))
        parts = np.concatenate(rows) if rows else np.zeros((0, 6))
        return parts, np.asarray(owner, dtype=np.int64), part_shapes

    def _auxiliary(self, dt: float, colour: Callable[[str], np.ndarray | None],
                   tracks: Sequence[TrackEstimate],
                   models: Mapping[int, PersonModel], parts: np.ndarray, owner_arr: np.ndarray,
                   part_sils: Mapping[str, object], coverage: Mapping[str, np.ndarray],
                   reach: Callable[[int], tuple[np.ndarray, list[dict[str, float]]]] | None
                   = None) -> None:
        """Visibility and existence of every track (001) from the appearance likelihood of
        its particles ``parts`` (``owner_arr``: their track) rasterised in ``part_sils``;
        ``colour(camera)`` gives the frame's colour bins of a side camera; ``reach(k)`` the
        coverages of track k's reach ring (:meth:`_reach_coverage`)."""
        cfg = self.config
        hidden = -cfg.clutter_distance ** 2 / (2.0 * self.sigma ** 2)    # 001 Eq. 23
        has_particles = len(parts) > 0
        loglik: dict[str, np.ndarray] = {}
        if has_particles:
            cams = [n for n in self.side if n in part_sils and colour(n) is not None]
            # the tracks' key views, interpolated lazily per particle and camera at the
            # relative viewing angles (003 Eq. 1-2), as in the filter's likelihood
            with_model, target = np.unique(owner_arr, return_inverse=True)
            refs = [models[tracks[k].track_id] for k in with_model]
            key = key_view_stack(refs)
            va, vb, wa = view_weights([self.calibration.cameras[n] for n in cams], parts,
                                      target.ravel(), refs)
            for c, n in enumerate(cams):
                sil = part_sils[n]
                ll = key_view_loglik(colour(n), sil, key, target.ravel(), va[c], vb[c], wa[c],
                                     sigma=self.sigma)
                loglik[n] = np.where(sil.area > 0, ll, -np.inf)
        for k, t in enumerate(tracks):
            aux = self.aux.setdefault(t.track_id, TrackAuxiliary(cfg.existence))
            vis: dict[str, float] = {}
            hid: dict[str, float] = {}
            if has_particles:
                sel = owner_arr == k
                if sel.any():
                    for n, ll in loglik.items():
                        if np.isfinite(ll[sel]).any():
                            vis[n] = predictive_loglik(ll[sel])              # 001 Eq. 18
                            hid[n] = hidden
            cov = {n: float(c[k]) for n, c in coverage.items() if np.isfinite(c[k])}
            # evidence weights: the share w* of the track's silhouette a tracking camera
            # sees (top-down cameras are not used by the filter and weigh 1)
            weights = {n: (float(t.visible_fraction.get(n, 1.0)) if n in self.side else 1.0)
                       for n in set(cov) | set(vis)}
            # the coverage evidence of a side camera: the silhouette's pixels no other
            # track explains (Releaser.exclusive_views), weighted by their share
            cover_weights = dict(weights)
            for n, (share, excl) in self.releaser.exclusive_views.items():
                if n in cov and np.isfinite(share[k]):
                    cover_weights[n] = float(share[k])
                    cov[n] = float(excl[k]) if np.isfinite(excl[k]) else 0.0
            neutral = self.releaser.config.min_coverage     # support counts for existence
            best = (coverage_log_ratio(cov, cover_weights, cfg.existence.support_gain,
                                       neutral=neutral)
                    if reach is not None and cov else 0.0)
            if best < 0.0:
                # the track's reach: its best place counts (AutoDetectionConfig.reach_radius)
                places, rings = reach(k)
                for place, ring in zip(places, rings):
                    ring, evidence = self._ring_evidence(ring, cov, weights)
                    if evidence > best:
                        cov, best, cover_weights = ring, evidence, weights
                        if evidence > 0.0:
                            self.reach_moves[t.track_id] = place
            aux.update(dt, loglik_visible=vis, loglik_hidden=hid, coverage=cov,
                       visible_fraction=weights, coverage_weights=cover_weights,
                       neutral_coverage=neutral)
            t.visibility = dict(aux.visibility)
            t.existence = float(aux.existence)
