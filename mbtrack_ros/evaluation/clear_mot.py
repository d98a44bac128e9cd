"""CLEAR MOT scores of floor-position tracks, computed with py-motmetrics.

As in the CLEAR'07 3D person tracking task (the scores of paper 003, Table 1): a track and a
ground-truth person are matched at a frame when their floor positions are at most
``threshold_m`` apart (500 mm), correspondences are kept from frame to frame while they stay
within the threshold, the remaining pairs are assigned with the Hungarian algorithm, and

* MOTP = mean Euclidean distance of the matched pairs (reported in **millimetres**),
* MOTA = 1 - (misses + false positives + mismatches) / ground-truth objects,
* miss rate, false-positive rate, mismatch rate = the counts / ground-truth objects,
* IDF1 = 2 IDTP / (2 IDTP + IDFP + IDFN) (Ristani et al. 2016): the share of person-frames
  matched to the one track assigned to that person over the whole sequence (a global
  one-to-one assignment of tracks to people), which, unlike MOTA, counts every frame an
  identity is wrong, not only the frame it switches.

Frames are the ground-truth stamps plus the empty frames (nobody present) where tracks were
reported. Track rows are matched to ground-truth rows by ``stamp_ns``; track rows at stamps
off the frame grid (within half a period of a ground-truth stamp) are ignored and counted in
:attr:`ClearMotResult.ignored_track_rows`. The distance matrix given to motmetrics is built here
(plain Euclidean metres, NaN beyond the threshold) because some motmetrics helpers return
squared distances.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from mbtrack_ros.evaluation.errors import EvaluationError
from mbtrack_ros.recording.csvfiles import GroundTruthRow, TrackRow

__all__ = [
    'ClearMotResult', 'PersonFrameMatches', 'PersonStats', 'SequenceTable', 'TrackStats',
    'clear_mot', 'coalescence', 'combine_results', 'evaluate_many',
]

_MM_METRICS = ('mota', 'motp', 'num_misses', 'num_false_positives', 'num_switches',
               'num_objects', 'num_frames', 'num_detections', 'num_predictions',
               'num_unique_objects', 'idtp', 'idfp', 'idfn')


@dataclass(frozen=True)
class PersonFrameMatches:
    """The matching outcome of every ground-truth person-frame, sorted by (stamp, person).

    Attributes:
        stamp_ns: (G,) int64 frame stamps, nanoseconds.
        person_id: (G,) int64 ground-truth ids.
        x, y: (G,) float64 true floor position, metres.
        track_id: (G,) int64 matched track id, -1 where the person was missed.
        error_m: (G,) float64 distance to the matched track, metres; NaN where missed.
    """

    stamp_ns: np.ndarray
    person_id: np.ndarray
    x: np.ndarray
    y: np.ndarray
    track_id: np.ndarray
    error_m: np.ndarray

    @property
    def matched(self) -> np.ndarray:
        """(G,) bool, True where the person-frame has a matched track."""
        return self.track_id >= 0

    def __len__(self) -> int:
        return int(self.stamp_ns.shape[0])

    def time_to_track(self) -> tuple[np.ndarray, np.ndarray]:
        """How long each ground-truth person waited for a track: (Q,) int64 person ids
        (ascending) and (Q,) float64 seconds from the person's first ground-truth frame to
        his first matched one (0 when matched from the start, ``inf`` when never).

        The acceptance of an occupied start ("everyone tracked within 1 s") reads it."""
        persons = np.unique(self.person_id)
        wait = np.full(persons.shape[0], np.inf)
        for k, p in enumerate(persons):
            sel = self.person_id == p
            stamps = self.stamp_ns[sel]
            hit = stamps[self.track_id[sel] >= 0]
            if hit.shape[0]:
                wait[k] = (int(hit.min()) - int(stamps.min())) * 1e-9
        return persons.astype(np.int64), wait


@dataclass(frozen=True)
class PersonStats:
    """Per ground-truth person: how it was tracked."""

    person_id: int
    frames: int
    matches: int
    misses: int
    mismatches: int
    motp_mm: float
    track_ids: tuple[int, ...]


@dataclass(frozen=True)
class TrackStats:
    """Per reported track (rows at ground-truth stamps only)."""

    track_id: int
    rows: int
    matches: int
    false_positives: int
    person_ids: tuple[int, ...]


@dataclass(frozen=True)
class ClearMotResult:
    """CLEAR MOT scores of one sequence (or the sum of several, see :func:`combine_results`).

    Rates are fractions (0.25 = 25 %); ``motp_mm`` is in millimetres (NaN without matches).
    ``matches`` counts every matched person-frame, mismatched ones included (CLEAR's c_t; what
    motmetrics calls ``num_detections``); ``track_rows`` the track rows at ground-truth stamps.
    """

    name: str
    mota: float
    motp_mm: float
    miss_rate: float
    false_positive_rate: float
    mismatch_rate: float
    misses: int
    false_positives: int
    mismatches: int
    gt_objects: int
    frames: int
    matches: int
    track_rows: int
    tracks: int
    persons: int
    ignored_track_rows: int
    threshold_m: float
    id_true_positives: int = 0
    id_false_positives: int = 0
    id_false_negatives: int = 0
    per_person: tuple[PersonStats, ...] = ()
    per_track: tuple[TrackStats, ...] = ()
    matches_detail: PersonFrameMatches | None = field(default=None, repr=False)

    @property
    def idf1(self) -> float:
        """IDF1 = 2 IDTP / (2 IDTP + IDFP + IDFN), a fraction; NaN with neither tracks nor
        truth."""
        den = 2 * self.id_true_positives + self.id_false_positives + self.id_false_negatives
        return 2 * self.id_true_positives / den if den else float('nan')

    @property
    def summed_error_mm(self) -> float:
        """Sum of the matched distances, millimetres (MOTP times matches)."""
        return 0.0 if self.matches == 0 else self.motp_mm * self.matches

    def to_dict(self, *, details: bool = True) -> dict:
        """JSON-ready scores and counts; ``details`` adds per-person and per-track tables."""
        out = {k: getattr(self, k) for k in (
            'name', 'mota', 'motp_mm', 'miss_rate', 'false_positive_rate', 'mismatch_rate',
            'misses', 'false_positives', 'mismatches', 'gt_objects', 'frames', 'matches',
            'track_rows', 'tracks', 'persons', 'ignored_track_rows', 'threshold_m', 'idf1')}
        for k in ('mota', 'motp_mm', 'miss_rate', 'false_positive_rate', 'mismatch_rate',
                  'idf1'):
            out[k] = _json_float(out[k])
        if details:
            out['per_person'] = [_json_clean(asdict(p)) for p in self.per_person]
            out['per_track'] = [_json_clean(asdict(t)) for t in self.per_track]
        return out


@dataclass(frozen=True)
class SequenceTable:
    """Scores of several sequences and their overall (summed) scores."""

    sequences: dict[str, ClearMotResult]
    overall: ClearMotResult

    def rows(self) -> list[ClearMotResult]:
        """The per-sequence results followed by the overall one."""
        return [*self.sequences.values(), self.overall]

    def to_dict(self, *, details: bool = False) -> dict:
        return {'sequences': {k: v.to_dict(details=details) for k, v in self.sequences.items()},
                'overall': self.overall.to_dict(details=False)}


def _json_float(value: float) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


def _json_clean(d: dict) -> dict:
    return {k: (list(v) if isinstance(v, tuple) else
                _json_float(v) if isinstance(v, float) else v) for k, v in d.items()}


def _truth_arrays(truth: Sequence[GroundTruthRow]) -> tuple[np.ndarray, ...]:
    stamp = np.fromiter((r.stamp_ns for r in truth), np.int64, len(truth))
    pid = np.fromiter((r.person_id for r in truth), np.int64, len(truth))
    x = np.fromiter((r.x for r in truth), np.float64, len(truth))
    y = np.fromiter((r.y for r in truth), np.float64, len(truth))
    return stamp, pid, x, y


def _track_arrays(tracks: Sequence[TrackRow]) -> tuple[np.ndarray, ...]:
    stamp = np.fromiter((r.stamp_ns for r in tracks), np.int64, len(tracks))
    tid = np.fromiter((r.track_id for r in tracks), np.int64, len(tracks))
    x = np.fromiter((r.x for r in tracks), np.float64, len(tracks))
    y = np.fromiter((r.y for r in tracks), np.float64, len(tracks))
    return stamp, tid, x, y


def _sort_unique(stamp: np.ndarray, ident: np.ndarray, what: str,
                 id_name: str) -> np.ndarray:
    """Order by (stamp, id); raise on a repeated (stamp, id) pair."""
    order = np.lexsort((ident, stamp))
    s, i = stamp[order], ident[order]
    dup = np.flatnonzero((s[1:] == s[:-1]) & (i[1:] == i[:-1]))
    if dup.size:
        k = dup[0]
        raise EvaluationError(f'{what}: {id_name} {int(i[k])} appears twice at stamp '
                              f'{int(s[k])} ns')
    return order


def _evaluation_frames(gt_frames: np.ndarray, t_stamp: np.ndarray,
                       frame_stamps: Sequence[int] | None) -> np.ndarray:
    """The stamps scored: ground-truth frames plus the frames where nobody was present.

    The ground-truth CSV has rows only for people, so a frame with nobody in the room has
    none; a track reported there is a false positive all the same. Without an explicit
    ``frame_stamps`` list, a track stamp counts as such an empty frame unless it lies within
    half a frame period of a ground-truth stamp without being equal to it (a stamping
    mismatch, which is ignored and counted instead).
    """
    if frame_stamps is not None:
        return np.union1d(gt_frames, np.asarray(frame_stamps, dtype=np.int64))
    extra = np.setdiff1d(np.unique(t_stamp), gt_frames)
    if extra.size == 0:
        return gt_frames
    period = float(np.median(np.diff(gt_frames))) if gt_frames.size > 1 else np.inf
    idx = np.clip(np.searchsorted(gt_frames, extra), 1, max(gt_frames.size - 1, 1))
    near = np.minimum(np.abs(extra - gt_frames[idx - 1]), np.abs(extra - gt_frames[
        np.minimum(idx, gt_frames.size - 1)]))
    return np.union1d(gt_frames, extra[near >= period / 2])


def coalescence(tracks: Sequence[TrackRow], truth: Sequence[GroundTruthRow], *,
                threshold_m: float = 0.5) -> float:
    """Share of the ground-truth frames in which two or more tracks are on one person: the
    coalescence of 000 §VI-C (trackers of people who look alike locking onto one of them).

    A track is on the person nearest to it at that frame, if at most ``threshold_m``
    (metres) away; frames are the ground-truth stamps, track rows are matched to them by
    ``stamp_ns``. 0.0 without ground truth."""
    g_stamp, _, gx, gy = _truth_arrays(truth)
    t_stamp, _, tx, ty = _track_arrays(tracks)
    frames = np.unique(g_stamp)
    if frames.size == 0:
        return 0.0
    g_order, t_order = np.argsort(g_stamp, kind='stable'), np.argsort(t_stamp, kind='stable')
    g_bounds = np.searchsorted(g_stamp[g_order], frames, side='left'), \
        np.searchsorted(g_stamp[g_order], frames, side='right')
    t_bounds = np.searchsorted(t_stamp[t_order], frames, side='left'), \
        np.searchsorted(t_stamp[t_order], frames, side='right')
    merged = 0
    for f in range(frames.size):
        g = g_order[g_bounds[0][f]:g_bounds[1][f]]
        t = t_order[t_bounds[0][f]:t_bounds[1][f]]
        if t.size < 2:
            continue
        d = np.hypot(tx[t, None] - gx[None, g], ty[t, None] - gy[None, g])   # (tracks, people)
        nearest = np.argmin(d, axis=1)
        on = nearest[d[np.arange(t.size), nearest] <= threshold_m]
        merged += int(on.size > np.unique(on).size)
    return merged / frames.size


def clear_mot(tracks: Sequence[TrackRow], truth: Sequence[GroundTruthRow], *,
              threshold_m: float = 0.5, name: str = 'sequence',
              frame_stamps: Sequence[int] | None = None) -> ClearMotResult:
    """CLEAR MOT scores of ``tracks`` against ``truth`` (floor positions, metres).

    Args:
        tracks: tracker output rows (any order).
        truth: ground-truth rows (any order); must not be empty.
        threshold_m: match threshold, metres (CLEAR'07: 0.5).
        name: label of the sequence in tables.
        frame_stamps: every frame stamp of the recording, if known; frames without
            ground-truth rows are frames where nobody is present (see
            :func:`_evaluation_frames` for the default).
    Raises:
        EvaluationError: empty ground truth, bad threshold, a repeated (stamp, id) pair.
    """
    import motmetrics as mm  # slow import; only needed here

    threshold_m = float(threshold_m)
    if not (np.isfinite(threshold_m) and threshold_m > 0):
        raise EvaluationError(f'match threshold must be a positive number, got {threshold_m}')
    if len(truth) == 0:
        raise EvaluationError('ground truth is empty: nothing to score')

    g_stamp, g_pid, g_x, g_y = _truth_arrays(truth)
    order = _sort_unique(g_stamp, g_pid, 'ground truth', 'person')
    g_stamp, g_pid, g_x, g_y = g_stamp[order], g_pid[order], g_x[order], g_y[order]
    t_stamp, t_tid, t_x, t_y = _track_arrays(tracks)
    order = _sort_unique(t_stamp, t_tid, 'tracks', 'track')
    t_stamp, t_tid, t_x, t_y = t_stamp[order], t_tid[order], t_x[order], t_y[order]

    for what, arr in (('ground truth', g_x), ('ground truth', g_y), ('tracks', t_x),
                      ('tracks', t_y)):
        if not np.all(np.isfinite(arr)):
            raise EvaluationError(f'{what}: positions must be finite')
    frames = _evaluation_frames(np.unique(g_stamp), t_stamp, frame_stamps)
    keep = np.isin(t_stamp, frames)
    ignored = int(np.count_nonzero(~keep))
    t_stamp, t_tid, t_x, t_y = t_stamp[keep], t_tid[keep], t_x[keep], t_y[keep]
    n_frames = frames.shape[0]
    g_bounds = np.searchsorted(g_stamp, frames, side='left').tolist() + [g_stamp.shape[0]]
    t_bounds = np.searchsorted(t_stamp, frames, side='left').tolist() + [t_stamp.shape[0]]

    acc = mm.MOTAccumulator(auto_id=False)
    for f in range(n_frames):
        g = slice(g_bounds[f], g_bounds[f + 1])
        t = slice(t_bounds[f], t_bounds[f + 1])
        # Euclidean floor distance in metres (not squared); NaN = may not be paired
        dist = np.hypot(g_x[g, None] - t_x[None, t], g_y[g, None] - t_y[None, t])
        dist[dist > threshold_m] = np.nan
        acc.update(g_pid[g], t_tid[t], dist, frameid=f)

    summary = mm.metrics.create().compute(acc, metrics=list(_MM_METRICS), name=name)
    s = {k: summary[k].iloc[0] for k in _MM_METRICS}

    # matched pairs and per-id statistics from the event log
    ev = acc.mot_events
    ev_type = ev['Type'].to_numpy().astype(str)
    ev_frame = ev.index.get_level_values('FrameId').to_numpy().astype(np.int64)
    ev_oid = ev['OId'].to_numpy(dtype=np.float64)
    ev_hid = ev['HId'].to_numpy(dtype=np.float64)
    ev_d = ev['D'].to_numpy(dtype=np.float64)
    is_match = (ev_type == 'MATCH') | (ev_type == 'SWITCH')

    row_of = {(int(f), int(p)): i for i, (f, p) in
              enumerate(zip(np.searchsorted(frames, g_stamp), g_pid))}
    m_tid = np.full(g_stamp.shape[0], -1, np.int64)
    m_err = np.full(g_stamp.shape[0], np.nan)
    for f, o, h, d in zip(ev_frame[is_match], ev_oid[is_match], ev_hid[is_match],
                          ev_d[is_match]):
        i = row_of[(int(f), int(o))]
        m_tid[i], m_err[i] = int(h), d
    detail = PersonFrameMatches(stamp_ns=g_stamp, person_id=g_pid, x=g_x, y=g_y,
                                track_id=m_tid, error_m=m_err)

    switches = ev_oid[ev_type == 'SWITCH'].astype(np.int64)
    per_person = []
    for p in np.unique(g_pid):
        sel = g_pid == p
        ok = sel & (m_tid >= 0)
        per_person.append(PersonStats(
            person_id=int(p), frames=int(sel.sum()), matches=int(ok.sum()),
            misses=int(sel.sum() - ok.sum()),
            mismatches=int(np.count_nonzero(switches == p)),
            motp_mm=float(m_err[ok].mean() * 1000.0) if ok.any() else float('nan'),
            track_ids=tuple(int(t) for t in np.unique(m_tid[ok]))))
    fp_ids = ev_hid[ev_type == 'FP'].astype(np.int64)
    per_track = []
    for t in np.unique(t_tid):
        ok = m_tid == t
        per_track.append(TrackStats(
            track_id=int(t), rows=int(np.count_nonzero(t_tid == t)),
            matches=int(ok.sum()), false_positives=int(np.count_nonzero(fp_ids == t)),
            person_ids=tuple(int(p) for p in np.unique(g_pid[ok]))))

    gt_objects = int(s['num_objects'])
    misses, fps, mme = int(s['num_misses']), int(s['num_false_positives']), int(
        s['num_switches'])
    return ClearMotResult(
        name=name, mota=float(s['mota']),
        motp_mm=float(s['motp']) * 1000.0 if int(s['num_detections']) else float('nan'),
        miss_rate=misses / gt_objects, false_positive_rate=fps / gt_objects,
        mismatch_rate=mme / gt_objects, misses=misses, false_positives=fps, mismatches=mme,
        gt_objects=gt_objects, frames=n_frames, matches=int(s['num_detections']),
        track_rows=int(s['num_predictions']), tracks=int(np.unique(t_tid).shape[0]),
        persons=int(s['num_unique_objects']), ignored_track_rows=ignored,
        threshold_m=threshold_m, id_true_positives=int(s['idtp']),
        id_false_positives=int(s['idfp']), id_false_negatives=int(s['idfn']),
        per_person=tuple(per_person), per_track=tuple(per_track),
        matches_detail=detail)


def combine_results(results: Sequence[ClearMotResult], *,
                    name: str = 'overall') -> ClearMotResult:
    """Overall scores of several sequences: counts summed, MOTP weighted by matches.

    Per-person and per-track tables are not merged (ids are per sequence); the IDF1 counts
    are summed (each sequence's identities assigned on their own).
    """
    if not results:
        raise EvaluationError('no sequences to combine')
    thresholds = {r.threshold_m for r in results}
    if len(thresholds) != 1:
        raise EvaluationError(f'sequences scored with different thresholds {sorted(thresholds)}')
    tot = {k: sum(getattr(r, k) for r in results) for k in (
        'misses', 'false_positives', 'mismatches', 'gt_objects', 'frames', 'matches',
        'track_rows', 'tracks', 'persons', 'ignored_track_rows', 'id_true_positives',
        'id_false_positives', 'id_false_negatives')}
    g = tot['gt_objects']
    err = sum(r.summed_error_mm for r in results)
    return ClearMotResult(
        name=name, mota=1.0 - (tot['misses'] + tot['false_positives'] + tot['mismatches']) / g,
        motp_mm=err / tot['matches'] if tot['matches'] else float('nan'),
        miss_rate=tot['misses'] / g, false_positive_rate=tot['false_positives'] / g,
        mismatch_rate=tot['mismatches'] / g, threshold_m=thresholds.pop(), **tot)


def evaluate_many(sequences: Mapping[str, tuple[Sequence[TrackRow], Sequence[GroundTruthRow]]],
                  *, threshold_m: float = 0.5, overall_name: str = 'overall') -> SequenceTable:
    """Score several sequences ``{name: (tracks, truth)}``; one row each plus the overall."""
    if not sequences:
        raise EvaluationError('no sequences to evaluate')
    results = {}
    for seq_name, (tracks, truth) in sequences.items():
        try:
            results[seq_name] = clear_mot(tracks, truth, threshold_m=threshold_m,
                                          name=seq_name)
        except EvaluationError as err:
            raise EvaluationError(f'{seq_name}: {err}') from err
    return SequenceTable(sequences=results,
                         overall=combine_results(list(results.values()), name=overall_name))
