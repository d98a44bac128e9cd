"""Data association of the automatic detection: what the frame's confirmed detections are.

:class:`DetectionAssociator` decides jointly, by one optimal assignment per frame
(:func:`solve_assignment`, ``scipy.optimize.linear_sum_assignment``), whether each confirmed
detection is a new person (a birth), a current track's person re-found (the track is moved
there), a released ("lost") track's person (its id is reused), or nothing to act on
(dropped). The assignment maximises the summed log-likelihood ratios of these hypotheses
against "the detection is false" (:meth:`DetectionAssociator._hypotheses`): the appearance
gain of each nearby track's model (003 Eq. 3), appearance distances between models (003
Eq. 4), the track's existence probability (001 §3.2), the gates of where its person can
be, and the detection's own score. A track takes at most one detection and a detection one
outcome, so two detections competing for a track, or a lost track and a current one
competing for a detection, are settled by the total likelihood. Every decision is recorded
in ``decisions`` and logged at debug level with its terms. It is a part of
:class:`~mbtrack_ros.core.detection.manager.AutoDetection` and works on its state.
"""
from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from mbtrack_ros.core.appearance import (
    PersonModel, model_distance, relative_angle, single_target_loglik)
from mbtrack_ros.core.detection.config import WALK_SPEED, Birth
from mbtrack_ros.core.detection.detector import Detection, FrameEvidence
from mbtrack_ros.core.detection.release import spare_tracks
from mbtrack_ros.core.existence import TrackAuxiliary
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.state import THETA, VX, VY, X, Y, TrackEstimate

__all__ = ['BIRTH', 'DROP', 'DetectionAssociator', 'PREFER_TRACK', 'assignment_costs',
           'place_llr', 'solve_assignment']

_log = logging.getLogger(__name__)

BIRTH, DROP = -1, -2    # outcomes of solve_assignment besides a track's column
PREFER_TRACK = 1e-3     # nats: at equal likelihood a track explains a detection rather
#                         than a new person (the hypothesis with fewer people)
_INFEASIBLE = 1e9       # cost of a pair outside its gate (finite: the matrix stays feasible)


def assignment_costs(llr: np.ndarray, birth: np.ndarray) -> np.ndarray:
    """The cost matrix of the association: (N, M + 2N) for N detections and M tracks.

    Args:
        llr: (N, M) log-likelihood ratio (nats) of "detection i is track j's person" over
            "detection i is false"; -inf (or nan) outside the gate.
        birth: (N,) log-likelihood ratio of "detection i is a new person" over "it is false".

    Returns:
        costs: columns 0..M-1 the tracks (``-llr``), M..M+N-1 one birth per detection (its
        ``-birth`` on the diagonal), M+N..M+2N-1 one drop per detection (0 on the diagonal);
        every other entry, and every pair outside its gate, ``1e9``.
    """
    llr = np.asarray(llr, dtype=np.float64)
    birth = np.asarray(birth, dtype=np.float64).reshape(-1)
    n = len(birth)
    m = llr.shape[1] if llr.ndim == 2 else 0
    llr = llr.reshape(n, m)
    cost = np.full((n, m + 2 * n), _INFEASIBLE)
    ok = np.isfinite(llr)
    cost[:, :m][ok] = -llr[ok]
    rows = np.arange(n)
    cost[rows, m + rows] = np.where(np.isfinite(birth), -birth, _INFEASIBLE)
    cost[rows, m + n + rows] = 0.0
    return cost


def solve_assignment(llr: np.ndarray, birth: np.ndarray) -> np.ndarray:
    """The outcome of each detection in the assignment maximising the summed log-likelihood
    ratios (:func:`assignment_costs`; each track takes at most one detection): the track's
    column ``j >= 0``, :data:`BIRTH` or :data:`DROP`. (N,) int."""
    birth = np.asarray(birth, dtype=np.float64).reshape(-1)
    n = len(birth)
    cost = assignment_costs(llr, birth)
    m = cost.shape[1] - 2 * n
    rows, cols = linear_sum_assignment(cost)
    out = np.full(n, DROP, dtype=np.int64)
    for r, c in zip(rows, cols):
        out[r] = c if c < m else (BIRTH if c < m + n else DROP)
    return out


def place_llr(metres: float, radius: float, area: float) -> float:
    """Log-likelihood ratio (nats) of "the person of a track last known ``metres`` away"
    over "a new person": a 2-D Gaussian of standard deviation ``radius / 2`` (the gate
    ``radius`` at two deviations) around the track's last place, against a person
    appearing anywhere on a floor of ``area`` square metres."""
    sd2 = (0.5 * max(float(radius), 1e-3)) ** 2
    return float(np.log(max(float(area), 1e-3) / (2.0 * np.pi * sd2))
                 - float(metres) ** 2 / (2.0 * sd2))


class DetectionAssociator:
    """The association part of :class:`~.manager.AutoDetection` (see the module)."""

    def _associate(self, acquired: Sequence[tuple[Detection, PersonModel]],
                   tracks: Sequence[TrackEstimate], keep: Sequence[int], means: np.ndarray,
                   models: Mapping[int, PersonModel], evidence: Mapping[str, FrameEvidence],
                   stamp_ns: int) -> list[Birth]:
        """What the frame's confirmed detections are, decided jointly: one optimal
        assignment (:func:`solve_assignment`) of the detections to the current tracks
        ``keep`` (reported and hidden), the lost (released) tracks, a birth each or a drop
        each, maximising the summed log-likelihood ratios of :meth:`_hypotheses`.
        Returns the births and moves (a move: ``track_id`` of a current track; a
        re-identification: ``track_id`` of a lost one); each decision is logged
        (:meth:`_decide`)."""
        lost = [(int(tid), xy, old, since)
                for tid, (since, xy, old) in self._released.items() if tid not in models]
        n, m = len(acquired), len(keep) + len(lost)
        llr = np.full((n, m), -np.inf)
        birth = np.zeros(n)
        labels, infos = [], []
        for i, (det, model) in enumerate(acquired):
            info, birth[i], row = self._hypotheses(det, model, tracks, keep, means, models,
                                                   evidence, stamp_ns, lost)
            for j, (value, _) in row.items():
                llr[i, j] = value
            labels.append(row)
            infos.append(info)
        outcome = solve_assignment(llr, birth)
        out: list[Birth] = []
        for i, (det, model) in enumerate(acquired):
            info, col = infos[i], int(outcome[i])
            state = det.state.copy()
            info['llr'] = {'birth': round(float(birth[i]), 2),
                           **{self._column_name(j, tracks, keep, lost): round(v, 2)
                              for j, (v, _) in labels[i].items()}}
            if col == BIRTH:
                info['action'] = 'birth'
                out.append(Birth(model=model, state=state, detection=det))
            elif col == DROP:
                info['action'] = ('drop (explained by the tracks)' if birth[i] == -np.inf
                                  else 'drop (weak beside a track)' if birth[i] < 0
                                  else 'drop')
            elif col >= len(keep):          # a lost track's person re-found
                tid = lost[col - len(keep)][0]
                rival = max(((v, j) for j, (v, how) in labels[i].items()
                             if j < len(keep) and how != 'young'
                             and v > max(birth[i], 0.0)),
                            default=None)
                if rival is None:
                    info['action'] = f'reuse {tid}'
                else:
                    other = tracks[keep[rival[1]]].track_id
                    info['action'] = f'reuse {tid} (not {other})'
                    info['unlike'] = (int(other), info['likeness'][other])
                del self._released[tid]
                out.append(Birth(model=model, state=state, detection=det, track_id=tid))
            else:
                tid = tracks[keep[col]].track_id
                how = labels[i][col][1]
                if how == 'young':
                    info['action'] = f'drop (young look-alike {tid})'
                elif how == 'gain' and self._placed_recently(tid, stamp_ns) and not (
                        info['gains'][tid] > 0.0
                        and self._moved_again.get(tid) != self._placed.get(tid)):
                    info['action'] = f'drop (track {tid} placed recently)'
                else:
                    if how == 'gain' and self._placed_recently(tid, stamp_ns):
                        self._moved_again[tid] = int(stamp_ns)
                        how = 'again'
                    elif how == 'far':
                        k = keep[col]
                        doubtful = self.reported(tid)
                        info['far'] = (int(tid),
                                       round(float(np.hypot(*(means[k, [X, Y]] - det.xy))), 2),
                                       info['likeness'][tid],
                                       round(float(self.aux[tid].existence), 3))
                        how = 'doubtful, far' if doubtful else 'hidden, far'
                    info['action'] = f'move {tid}' + ('' if how == 'gain' else f' ({how})')
                    self._placed[tid] = int(stamp_ns)
                    self._shown_since[tid] = int(stamp_ns)
                    self.releaser.forget(tid)
                    self.aux[tid] = TrackAuxiliary(self.config.existence)
                    out.append(Birth(model=models[tid], state=state, detection=det,
                                     track_id=tid))
            info.pop('gains')
            info.pop('likeness')
            self._decide(info)
        return out

    @staticmethod
    def _column_name(j: int, tracks: Sequence[TrackEstimate], keep: Sequence[int],
                     lost: Sequence[tuple]) -> str:
        """'track N' or 'lost N' for assignment column ``j``."""
        if j < len(keep):
            return f'track {tracks[keep[j]].track_id}'
        return f'lost {lost[j - len(keep)][0]}'

    def _hypotheses(self, det: Detection, model: PersonModel,
                    tracks: Sequence[TrackEstimate], keep: Sequence[int], means: np.ndarray,
                    models: Mapping[int, PersonModel], evidence: Mapping[str, FrameEvidence],
                    stamp_ns: int, lost: Sequence[tuple[int, np.ndarray, PersonModel | None,
                                                         int]]
                    ) -> tuple[dict, float, dict[int, tuple[float, str]]]:
        """One detection's row of the assignment: log-likelihood ratios (nats, against
        "the detection is false", a drop, whose ratio is 0) of its hypotheses.

        - birth: ``e = score - beside_threshold`` when a current track is within
          ``relocate_radius`` (a person rarely appears next to another: the prior odds of
          such a birth), else ``score`` (the detector's combined log response); none
          (``-inf``) when the detection, as one more track, would have less foreground of
          its own than a person's support: its exclusive support (the foreground in the
          pixels of its silhouettes that no current track covers, per silhouette pixel,
          over the side cameras: :func:`.release.spare_tracks`) below the coverage the
          existence process takes as neutral, f_s (``release.min_coverage``, 001 §3.2).
          The fringes of tracked people in two views meet on such places (phantoms of
          the two-view hull) and are mostly covered by those people's tracks;
        - current track (column ``keep`` index), the best of:
          'gain': the detection is the track's person, the track having drifted off them:
          ``e + move_llr`` (:meth:`AutoDetectionConfig.move_llr`: the appearance gain of
          the track's model, 003 Eq. 3, and for a strong detection the appearance ratio
          of the two models), within ``relocate_radius``;
          'hidden': a track that is not reported (existence below the report threshold,
          001 §3.2) within ``relocate_radius``: its person is somewhere near, whatever
          the gain: ``max(e, 0) + log((1 - p) / p) + A(u)`` (p the existence, A the
          appearance ratio of the two models u apart, "same person" over "somebody
          else", calibrated on the tracks: :meth:`.likeness.AppearanceRatio.llr`);
          'far': a hidden or doubtful track (existence below ``reuse_doubtful``) within
          ``reuse_radius``: ``max(e, 0) + place + A(u)`` as a lost track's, when
          positive beyond ``max(e, 0)``;
          'young': a track born or moved within ``relocate_interval`` that looks like the
          detection: it lags its person, the detection is that person, nothing is done
          (``max(e, 0)``);
          the 'gain' and 'young' hypotheses are ruled out for a track that keeps
          ``move_support`` of its exclusive support with the detection as one more track
          (it stands on a person of its own);
        - lost track (column ``len(keep) +`` index): released within ``reuse_time``, its
          person re-found within a gate of ``relocate_radius`` widened by
          :data:`WALK_SPEED` over the time since it was last supported (release timeout
          and time since the release): ``max(e, 0) + place + A(u)`` (place:
          :func:`place_llr` on the floor's area), when the sum beyond ``max(e, 0)`` is
          positive.

        Each hypothesis that explains a detection by a track gets :data:`PREFER_TRACK`
        more (at equal likelihood, fewer people). Returns (the decision's info, the birth's
        ratio, column -> (ratio, hypothesis))."""
        cfg = self.config
        state = det.state
        info: dict = {'xy': (float(det.xy[0]), float(det.xy[1])), 'score': float(det.score),
                      'v': (round(float(state[VX]), 2), round(float(state[VY]), 2))}
        near, unalike = [], []
        likeness: dict[int, float] = {}    # id -> appearance distance to the detection
        gains: dict[int, float] = {}       # id -> appearance gain (nats per side camera)
        dist = np.hypot(*(means[list(keep)][:, [X, Y]] - det.xy).T) if len(keep) \
            else np.zeros(0)
        radius = cfg.relocate_radius
        for j, k in enumerate(keep):
            tid = tracks[k].track_id
            ref = models.get(tid)
            if dist[j] > radius or ref is None or not ref.view_angles.size:
                continue
            gain = gains[tid] = self._explains(ref, means[k], state, evidence)
            unlike = likeness[tid] = model_distance(ref, model)
            near.append((int(tid), round(float(dist[j]), 2), round(gain, 3), round(unlike, 3)))
            if det.score >= cfg.beside_threshold and gain <= 0.0 \
                    and not self.likeness.looks_alike(unlike):   # a stranger, by its looks
                unalike.append((int(tid), round(unlike, 3)))
        if near:
            info['near'] = near
        if unalike:
            info['unalike'] = unalike
        e = float(det.score) - (cfg.beside_threshold if near else 0.0)
        base = max(e, 0.0) + PREFER_TRACK
        born, with_it = e, np.zeros(len(keep))
        if len(keep):       # how much of its foreground the tracks explain already
            with_it, own = self._exclusive_support(det, model, tracks, keep, means, models,
                                                   evidence)
            info['own'] = round(own, 3)
            if own < cfg.release.min_coverage:
                born = -np.inf

        def like(tid: int) -> float:
            if tid not in likeness:
                likeness[tid] = model_distance(models[tid], model)
            return likeness[tid]

        options: dict[int, list[tuple[float, str]]] = {}    # column -> hypotheses
        for j, k in enumerate(keep):
            tid = tracks[k].track_id
            if tid not in models:
                continue
            young = self._placed_recently(tid, stamp_ns)
            here = []
            if tid in gains:
                value = e + cfg.move_llr(det.score, gains[tid],
                                         self.likeness.llr(likeness[tid])) + PREFER_TRACK
                if value > max(e, 0.0):
                    here.append((value, 'gain'))
            if young:
                if dist[j] <= radius and self.likeness.looks_alike(like(tid)):
                    here.append((base, 'young'))
            elif dist[j] <= cfg.reuse_radius:
                hidden = self._hidden_hypothesis(tid, float(dist[j]), like, base)
                if hidden is not None:
                    here.append(hidden)
            if here:
                options[j] = here
        checked = [j for j, here in options.items()
                   if any(how in ('gain', 'young') for _, how in here)]
        if checked:
            # exclusive support with the detection as one more track: a track that keeps
            # move_support of it stands on a person of its own, the detection is another
            # (its 'gain' and 'young' hypotheses go; a hidden track's stays)
            info['support'] = [(int(tracks[keep[j]].track_id), round(float(with_it[j]), 3))
                               for j in checked]
            for j in checked:
                if with_it[j] >= cfg.move_support:
                    options[j] = [o for o in options[j] if o[1] not in ('gain', 'young')]
        row: dict[int, tuple[float, str]] = {j: max(here) for j, here in options.items()
                                             if here}
        since_supported = self.config.release.timeout
        x0, y0, x1, y1 = self.calibration.floor
        for i, (tid, xy, old, released) in enumerate(lost):
            d = float(np.hypot(*(xy - det.xy)))
            age = max(int(stamp_ns) - released, 0) / 1e9
            gate = radius + WALK_SPEED * (since_supported + age)
            if d > gate or old is None:
                continue
            unlike = model_distance(old, model)
            info.setdefault('reuse', []).append((int(tid), round(d, 2), round(unlike, 3)))
            # where: the lost person's place against a birth anywhere on the floor; who:
            # the two models' appearance ratio, negative for unlike ones (003 Eq. 4,
            # calibrated on the tracks: .likeness)
            value = place_llr(d, gate, (x1 - x0) * (y1 - y0)) + self.likeness.llr(unlike)
            if value > 0.0:
                row[len(keep) + i] = (base + value, 'lost')
        info['gains'] = gains
        info['likeness'] = {t: round(u, 3) for t, u in likeness.items()}
        return info, born, row

    def _hidden_hypothesis(self, track_id: int, metres: float, like, base: float
                           ) -> tuple[float, str] | None:
        """(ratio, 'hidden' or 'far') of "the detection ``metres`` from the track is the
        person of a track that lost them" (:meth:`_hypotheses`), or None for a track that is
        reported with an existence of at least ``reuse_doubtful``, or, beyond
        ``relocate_radius`` or reported, whose place and appearance ratios (as a lost
        track's, the gate ``reuse_radius``; ``like(id)``: the appearance distance) are not
        positive; ``base``: the detection's own ratio, at least 0."""
        cfg = self.config
        aux = self.aux.get(track_id)
        p = 1.0 if aux is None else float(aux.existence)
        reported = self.reported(track_id)
        if not reported and metres <= cfg.relocate_radius:
            # its person lost, and the detection beside it: who it is decides (the
            # unfloored appearance ratio, as for a lost track)
            odds = float(np.log(max(1.0 - p, 1e-9) / max(p, 1e-9)))
            unlike = like(track_id)
            return base + max(odds, 0.0) + self.likeness.llr(unlike), 'hidden'
        if not reported or p < cfg.reuse_doubtful:
            # where and who, as for a lost track (its gate: reuse_radius)
            x0, y0, x1, y1 = self.calibration.floor
            unlike = like(track_id)
            value = place_llr(metres, cfg.reuse_radius, (x1 - x0) * (y1 - y0)) \
                + self.likeness.llr(unlike)
            if value > 0.0:
                return base + value, 'far'
        return None

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

    def _exclusive_support(self, det: Detection, model: PersonModel,
                           tracks: Sequence[TrackEstimate], keep: Sequence[int],
                           means: np.ndarray, models: Mapping[int, PersonModel],
                           evidence: Mapping[str, FrameEvidence]
                           ) -> tuple[np.ndarray, float]:
        """Exclusive support (:func:`release.spare_tracks`, side cameras) of the tracks
        ``keep`` (the frame's live tracks) with the detection added as one more track, and
        the detection's own.

        A track whose foreground is the detection's person loses it when the detection
        becomes a track: its person is the detection's (a track lagging behind them); a
        track on a person of its own keeps it. A detection whose foreground the tracks
        cover has little of its own.

        Returns:
            the tracks' support with the detection (K,), NaN where no side camera sees a
            track; the detection's (``inf`` when no side camera sees it or there is no
            track).
        """
        rel = self.config.release
        side = [n for n in self.side if n in evidence]
        k = len(keep)
        if not side or k == 0:
            return np.full(k, np.nan), float('inf')
        states = np.concatenate([means[list(keep)], det.state[None].astype(np.float64)])
        shapes = [self._shape(models.get(tracks[j].track_id), tracks[j]) for j in keep]
        cams = [self.calibration.cameras[n] for n in side]
        sils = [rasterize(c, states, shapes + [model.shape]) for c in cams]
        fgs = [evidence[n].foreground for n in side]
        least = [rel.min_area * c.width * c.height / (320.0 * 240.0) for c in cams]
        # min_support 0: nobody is spare, every exclusive support is returned
        _, support = spare_tracks(fgs, sils, 0.0, least)
        own = float(support[k]) if np.isfinite(support[k]) else float('inf')
        return support[:k], own

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
