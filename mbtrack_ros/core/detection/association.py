"""Data association of the automatic detection: what a confirmed detection is.

:class:`DetectionAssociator` decides, for each confirmed detection, whether it is a new
person (a birth), a current track's person re-found (the track is moved there), a released
("lost") track's person (its id is reused), or nothing to act on (dropped), from the
appearance gain of each nearby track's model (003 Eq. 3), appearance distances between
models (003 Eq. 4) and the exclusive support of the tracks (the release's measure). Every
decision is recorded in ``decisions`` and logged at debug level. It is a part of
:class:`~mbtrack_ros.core.detection.manager.AutoDetection` and works on its state.
"""
from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

import numpy as np

from mbtrack_ros.core.appearance import (
    PersonModel, model_distance, relative_angle, single_target_loglik)
from mbtrack_ros.core.detection.config import Birth
from mbtrack_ros.core.detection.detector import Detection, FrameEvidence
from mbtrack_ros.core.detection.release import spare_tracks
from mbtrack_ros.core.existence import TrackAuxiliary
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.state import THETA, VX, VY, X, Y, TrackEstimate

__all__ = ['DetectionAssociator']

_log = logging.getLogger(__name__)


class DetectionAssociator:
    """The association part of :class:`~.manager.AutoDetection` (see the module)."""

    def _identify(self, det: Detection, model: PersonModel, tracks: Sequence[TrackEstimate],
                  keep: Sequence[int], means: np.ndarray, models: Mapping[int, PersonModel],
                  evidence: Mapping[str, FrameEvidence], moved: set[int], stamp_ns: int
                  ) -> Birth | None:
        """A new person, or a current track that drifted off its person, re-found.

        003 §4.1 excludes the neighbourhood of each track from the search, but a track that
        lags or drifted 0.4-0.8 m off its person leaves the person outside that radius:
        the detection would start a second track on the same person (an identity switch
        when the old one is released). So a confirmed detection within ``relocate_radius``
        of a track is first checked with the track's own appearance model (003 Eq. 3, the
        tracker's likelihood): the gain, on average over the side cameras that see both, of
        ``log p(y_c | detection) - log p(y_c | track)``, a log-likelihood ratio of "the
        track's person is at the detection" over "at the track's estimate". A positive
        gain (the model explains the detection better) takes the detection for that
        track's person and the track is moved there (same id) - or, within
        ``relocate_interval`` of the track's birth or last move, the detection is dropped
        (unless its gain is positive there too: it is moved again, once); otherwise a new
        track is born. A track the detection would leave
        ``move_support`` or more of its exclusive support (foreground no other track
        covers) is not moved: it stands on a person of its own. The gain is a weak cue in
        groups (right and wrong moves both have gains of a few nats either way per camera);
        still, moving instead of a birth avoids most second tracks on one person, and the
        interval stops a track hopping through a
        group. A track that looks like the detection (``alike_distance``) may be moved by a
        gain down to ``-look_alike_margin``. Of several tracks the gain would move, the
        one whose model is nearest the detection's in appearance is. A detection scoring
        below ``beside_threshold`` needs a gain above its shortfall to move a
        track (about half of such moves with a small
        gain went to another person), and when no track takes it and it has a track
        within ``relocate_radius`` it is not born either: weak detections there are mostly
        the fringe of that track's person or a gap between people. Before a track is
        moved (by the gain or hidden), a lost track whose model is nearer the detection's
        takes its id back instead, and the track stays where it is (not instead of a track
        placed within ``relocate_interval``: its move would not happen); before a birth, a released
        track and then a hidden one within ``reuse_radius`` that look alike are given
        back their person (``reuse_time``, ``reuse_radius``; a reported track of doubtful
        existence counts as hidden, ``reuse_doubtful``); a detection that would still
        be born beside a look-alike track born or moved within ``relocate_interval`` is
        dropped: a young track lags its person for a few frames, and the detection beside
        it that looks like it (``alike_distance``) is that person - unless the young track
        keeps ``move_support`` of its exclusive support with the detection as one more
        track (it stands on a person of its own).
        """
        cfg = self.config
        state = det.state.copy()
        info = {'xy': (float(det.xy[0]), float(det.xy[1])), 'score': float(det.score),
                'v': (round(float(det.state[VX]), 2), round(float(det.state[VY]), 2))}
        near = []                   # (id, distance, gain, appearance distance) of the
        #                             tracks the check compared
        movable = []                # indices of the tracks the gain would move
        unalike = []                # (id, distance) of those alike_distance kept back
        likeness = {}               # id -> appearance distance to the detection, once each
        gains = {}                  # id -> appearance gain (nats per side camera), unrounded
        for k in keep:
            tid = tracks[k].track_id
            d = float(np.hypot(*(means[k, [X, Y]] - det.xy)))
            ref = models.get(tid)
            if d > cfg.relocate_radius or ref is None or tid in moved \
                    or not ref.view_angles.size:
                continue
            gain = gains[tid] = self._explains(ref, means[k], state, evidence)
            unlike = likeness[tid] = model_distance(ref, model)
            near.append((int(tid), round(d, 2), round(gain, 3), round(unlike, 3)))
            gate = cfg.gain_gate(det.score, gain, unlike)
            if gate == 'unlike':
                unalike.append((int(tid), round(unlike, 3)))
            elif gate == 'move':
                movable.append(k)
        if near:
            info['near'] = near
        if unalike:
            info['unalike'] = unalike
        support = None              # _exclusive_support, computed once per detection
        if movable:
            # exclusive support with the detection as one more track: a track that keeps
            # move_support of it stands on a person of its own, the detection is another
            support = self._exclusive_support(det, model, tracks, keep, means, models,
                                              evidence)
            with_det = support[1]
            left = {k: float(with_det[j]) for j, k in enumerate(keep)}
            info['support'] = [(int(tracks[k].track_id), round(left[k], 3)) for k in movable]
            movable = [k for k in movable if not left[k] >= cfg.move_support]
        # of several movable tracks, the one whose model is nearest the detection's: each
        # gain is measured against that track's own place (a track drifted off its person
        # gains most), the appearance distance against one reference for all
        best = min(((k, likeness[tracks[k].track_id]) for k in movable),
                   key=lambda kd: kd[1], default=None)
        hidden = False
        if best is None:
            best = self._nearest_hidden(det, tracks, keep, means, models, moved, stamp_ns)
            hidden = best is not None
        if best is not None and not self._placed_recently(tracks[best[0]].track_id, stamp_ns):
            # a lost track that looks more like the detection than the track about to be
            # moved takes its id back; that track stays where it is. Not instead of a
            # track placed within relocate_interval: that move would not happen (the
            # detection is dropped below), a young track lags its own person
            tid = tracks[best[0]].track_id
            unlike = likeness.get(tid)
            if unlike is None:          # a hidden track the gain check did not compare
                unlike = likeness[tid] = model_distance(models[tid], model)
            info['unlike'] = (int(tid), round(unlike, 3))
            reused = self._reusable(det, model, models, info, below=unlike)
            if reused is not None:
                info['action'] = f'reuse {reused} (not {tid})'
                self._decide(info)
                return Birth(model=model, state=state, detection=det, track_id=reused)
        if best is None and near and det.score < cfg.beside_threshold:
            info['action'] = 'drop (weak beside a track)'
            self._decide(info)
            return None
        far = doubtful = False
        if best is None:
            reused = self._reusable(det, model, models, info)
            if reused is None:
                # a hidden track within reuse_radius that looks like the detection is
                # given back its person like a lost one; so is one reported with a
                # doubtful existence (shown again moments ago, or fading)
                best = self._nearest_hidden(det, tracks, keep, means, models, moved,
                                            stamp_ns, radius=cfg.reuse_radius,
                                            like=(model, likeness),
                                            below_existence=cfg.reuse_doubtful)
                hidden = far = best is not None
                if far:
                    tid = tracks[best[0]].track_id
                    doubtful = self.reported(tid)
                    # (id, metres, appearance distance, existence) of the track moved
                    info['far'] = (int(tid), round(best[1], 2), round(likeness[tid], 3),
                                   round(float(self.aux[tid].existence), 3))
            if best is None and reused is None:
                young = [(n[1], n[0]) for n in near
                         if cfg.looks_alike(n[3]) and self._placed_recently(n[0], stamp_ns)]
                if young:
                    # ... unless the young track keeps move_support of its exclusive
                    # support with the detection as one more track: it stands on a person
                    # of its own, and the detection is somebody else
                    if support is None:
                        support = self._exclusive_support(det, model, tracks, keep, means,
                                                          models, evidence)
                    left = {int(tracks[k].track_id): float(support[1][j])
                            for j, k in enumerate(keep)}
                    young = [y for y in young if not left.get(y[1], 0.0) >= cfg.move_support]
                if young:
                    # a track born or moved moments ago lags its person: the detection
                    # beside it that looks like it is that person, not a newcomer
                    info['action'] = f'drop (young look-alike {min(young)[1]})'
                    self._decide(info)
                    return None
            if best is None:
                info['action'] = 'birth' if reused is None else f'reuse {reused}'
                self._decide(info)
                return Birth(model=model, state=state, detection=det, track_id=reused)
        tid = tracks[best[0]].track_id
        again = False
        if not hidden and self._placed_recently(tid, stamp_ns):
            again = gains[tid] > 0.0 \
                and self._moved_again.get(tid) != self._placed.get(tid)
            if not again:
                info['action'] = f'drop (track {tid} placed recently)'
                self._decide(info)
                return None
            self._moved_again[tid] = int(stamp_ns)
        info['action'] = f'move {tid}' + (' (doubtful, far)' if doubtful
                                          else ' (hidden, far)' if far
                                          else ' (hidden)' if hidden
                                          else ' (again)' if again else '')
        self._decide(info)
        self._placed[tid] = int(stamp_ns)
        self._shown_since[tid] = int(stamp_ns)
        moved.add(tid)
        self.releaser.forget(tid)
        self.aux[tid] = TrackAuxiliary(cfg.existence)
        return Birth(model=models[tid], state=state, detection=det, track_id=tid)

    def _decide(self, info: dict) -> None:
        """Record what happened to a confirmed detection (``decisions``) and log it at debug
        level: the detection's place and score, the tracks compared (id, metres, gain in
        nats per side camera, appearance distance), the support and the action taken."""
        self.decisions.append(info)
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug('detection at (%.2f, %.2f) score %.2f: %s; %s', *info['xy'],
                       info['score'], info.get('action', '?'),
                       ', '.join(f'{k}={v}' for k, v in info.items()
                                 if k not in ('xy', 'score', 'action')))

    def _placed_recently(self, track_id: int, stamp_ns: int) -> bool:
        """The track was born or moved less than ``relocate_interval`` before ``stamp_ns``."""
        since = self._placed.get(track_id)
        return since is not None \
            and (int(stamp_ns) - since) / 1e9 < self.config.relocate_interval

    def _nearest_hidden(self, det: Detection, tracks: Sequence[TrackEstimate],
                        keep: Sequence[int], means: np.ndarray,
                        models: Mapping[int, PersonModel], moved: set[int], stamp_ns: int,
                        radius: float | None = None,
                        like: tuple[PersonModel, dict[int, float]] | None = None,
                        below_existence: float = 0.0) -> tuple[int, float] | None:
        """(index, distance) of the nearest unreported track within ``radius`` (default
        ``relocate_radius``) of the detection (a track whose existence fell below the
        report threshold; or, reported, below ``below_existence``), or None; with ``like``
        (the detection's model, and the cache of appearance distances to it by track id,
        filled here) only a track whose model is within ``alike_distance`` of that model
        (the reuse of a hidden track). Not a track born or moved within
        ``relocate_interval``: hidden again so soon, its model does not explain the person
        there."""
        best = None
        for k in keep:
            tid = tracks[k].track_id
            if tid in moved or tid not in models:
                continue
            aux = self.aux.get(tid)
            if self.reported(tid) \
                    and not (aux is not None and aux.existence < below_existence):
                continue
            if self._placed_recently(tid, stamp_ns):
                continue
            d = float(np.hypot(*(means[k, [X, Y]] - det.xy)))
            if d > (self.config.relocate_radius if radius is None else radius):
                continue
            if like is not None:
                model, likeness = like
                if tid not in likeness:
                    likeness[tid] = model_distance(models[tid], model)
                if likeness[tid] > self.config.alike_distance:
                    continue
            if best is None or d < best[1]:
                best = (k, d)
        return best

    def _exclusive_support(self, det: Detection, model: PersonModel,
                           tracks: Sequence[TrackEstimate], keep: Sequence[int],
                           means: np.ndarray, models: Mapping[int, PersonModel],
                           evidence: Mapping[str, FrameEvidence]
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exclusive support (:func:`release.spare_tracks`, side cameras) of the tracks
        ``keep`` (the frame's live tracks) as they are and with the detection added as one
        more track, and whether each is spare now (the release's ``spare_support`` and
        ``spare_radius``).

        A track whose foreground is the detection's person loses it when the detection
        becomes a track: its person is the detection's (a track lagging behind them); a
        track on a person of its own keeps it.

        Returns:
            support without the detection (K,), support with it (K,), spare (K,) bool.
        """
        rel = self.config.release
        side = [n for n in self.side if n in evidence]
        k = len(keep)
        if not side or k == 0:
            nan = np.full(k, np.nan)
            return nan, nan.copy(), np.zeros(k, bool)
        states = np.concatenate([means[list(keep)], det.state[None].astype(np.float64)])
        shapes = [self._shape(models.get(tracks[j].track_id), tracks[j]) for j in keep]
        cams = [self.calibration.cameras[n] for n in side]
        sils = [rasterize(c, states, shapes + [model.shape]) for c in cams]
        fgs = [evidence[n].foreground for n in side]
        least = [rel.min_area * c.width * c.height / (320.0 * 240.0) for c in cams]
        xy = states[:, [X, Y]]
        spare, alone = spare_tracks(fgs, [s.select(0, k) for s in sils], rel.spare_support,
                                    least, xy[:k], rel.spare_radius)
        # min_support 0: nobody is spare, every track's exclusive support is returned
        _, beside = spare_tracks(fgs, sils, 0.0, least)
        return alone, beside[:k], spare

    def _reusable(self, det: Detection, model: PersonModel,
                  models: Mapping[int, PersonModel], info: dict,
                  below: float | None = None) -> int | None:
        """The id of the track released nearest the detection, within ``reuse_radius``
        metres and ``reuse_time`` seconds, not live, whose appearance model is within
        ``alike_distance`` of the detection's - or, when ``below`` is given, nearer than
        ``below`` (a lost track nearer in appearance than the track to be moved) - (and
        forgets it), or None; each candidate's distance and model distance go to
        ``info['reuse']``."""
        best = None
        for tid, (_, xy, old) in self._released.items():
            d = float(np.hypot(*(xy - det.xy)))
            if tid in models or d > self.config.reuse_radius:
                continue
            unlike = model_distance(old, model) if old is not None else 1.0
            info.setdefault('reuse', []).append((int(tid), round(d, 2), round(unlike, 3)))
            fits = unlike <= self.config.alike_distance if below is None else unlike < below
            if fits and (best is None or d < best[1]):
                best = (tid, d)
        if best is None:
            return None
        del self._released[best[0]]
        return best[0]

    def _explains(self, model: PersonModel, track: np.ndarray, candidate: np.ndarray,
                  evidence: Mapping[str, FrameEvidence]) -> float:
        """Mean over side cameras of ``log p(y_c | candidate) - log p(y_c | track)`` under
        the track's appearance model (003 Eq. 3), cameras seeing both silhouettes only."""
        states = np.stack([track, candidate]).astype(np.float64)
        states[1, THETA] = track[THETA]
        gains = [float(ll[1] - ll[0])
                 for ll in self._pair_logliks(states, (model, model), evidence)]
        return float(np.mean(gains)) if gains else float('-inf')

    def _pair_logliks(self, states: np.ndarray, models: tuple[PersonModel, PersonModel],
                      evidence: Mapping[str, FrameEvidence]) -> list[np.ndarray]:
        """(2,) log-likelihoods (003 Eq. 3) of ``models[i]`` at ``states[i]`` (2, 6), one
        per side camera whose image holds at least half of both silhouettes."""
        out = []
        for n in self.side:
            if n not in evidence:
                continue
            cam = self.calibration.cameras[n]
            sil = rasterize(cam, states, [m.shape for m in models])
            if np.any(sil.area < 0.5 * np.maximum(sil.full_area, 1)) or np.any(sil.area <= 0):
                continue
            rel = relative_angle(states[:, THETA], cam.viewing_angle(states[:, [X, Y]]))
            hists = np.stack([m.interpolate(rel[i:i + 1])[0] for i, m in enumerate(models)])
            out.append(single_target_loglik(evidence[n].bins, sil, hists,
                                            sigma=self.sigma))
        return out

    @staticmethod
    def _shape(model: PersonModel | None, track: TrackEstimate) -> BodyShape:
        if model is not None:
            return model.shape
        h = track.height if np.isfinite(track.height) and track.height > 0 else 1.75
        return BodyShape(height=float(h))
