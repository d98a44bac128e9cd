"""CLEAR MOT, posterior-mass curve, plots, report and the ``mbtrack eval`` command."""
from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from mbtrack_ros.commands import eval as eval_cmd
from mbtrack_ros.core.state import FrameResult, TrackEstimate
from mbtrack_ros.evaluation import (
    EvaluationError, ParticleRecorder, ParticleSet, clear_mot, evaluate_many, format_table,
    load_particles, posterior_mass, posterior_mass_curve, save_particles, write_report)
from mbtrack_ros.evaluation.plots import (
    plot_localisation_error, plot_posterior_curves, plot_trajectories)
from mbtrack_ros.recording.csvfiles import (
    GroundTruthRow, TrackRow, write_ground_truth, write_tracks)

STEP = 40_000_000  # 25 fps in ns


def gt(frame: int, pid: int, x: float, y: float) -> GroundTruthRow:
    return GroundTruthRow(frame * STEP, frame, pid, x, y, 1.7, False, ('cam0',))


def tr(frame: int, tid: int, x: float, y: float) -> TrackRow:
    return TrackRow(frame * STEP, frame, tid, x, y)


def walk(pid: int, frames: range, y: float) -> list[GroundTruthRow]:
    return [gt(f, pid, 1.0 + 0.05 * f, y) for f in frames]


# ---------------------------------------------------------------- CLEAR MOT, constructed cases

def test_perfect_track_with_constant_offset_gives_motp_in_mm():
    truth = walk(1, range(10), 2.0)
    tracks = [tr(r.frame, 5, r.x + 0.1, r.y) for r in truth]  # 100 mm to the side
    r = clear_mot(tracks, truth)
    assert r.mota == pytest.approx(1.0)
    assert r.motp_mm == pytest.approx(100.0)
    assert (r.misses, r.false_positives, r.mismatches) == (0, 0, 0)
    assert (r.gt_objects, r.frames, r.matches, r.tracks, r.persons) == (10, 10, 10, 1, 1)


def test_motp_is_euclidean_millimetres_not_squared():
    truth = walk(1, range(6), 2.0)
    # 0.3 m, 0.4 m diagonal offset -> 0.5 m exactly would be the threshold; use 0.18, 0.24
    tracks = [tr(r.frame, 5, r.x + 0.18, r.y + 0.24) for r in truth]  # |d| = 0.3 m
    r = clear_mot(tracks, truth)
    assert r.motp_mm == pytest.approx(300.0)  # squared would give 90
    assert r.matches == 6


def test_track_beyond_threshold_is_a_miss_and_a_false_positive():
    truth = walk(1, range(8), 2.0)
    # 0.6 m away: its squared distance 0.36 < 0.5 would wrongly match if squared were used
    tracks = [tr(r.frame, 5, r.x + 0.6, r.y) for r in truth]
    r = clear_mot(tracks, truth)
    assert (r.misses, r.false_positives, r.matches) == (8, 8, 0)
    assert r.mota == pytest.approx(1.0 - 16 / 8)
    assert np.isnan(r.motp_mm)
    # with a 0.7 m threshold the same track matches
    r7 = clear_mot(tracks, truth, threshold_m=0.7)
    assert (r7.misses, r7.false_positives, r7.matches) == (0, 0, 8)
    assert r7.motp_mm == pytest.approx(600.0)


def test_missed_person_counts_misses_including_frames_without_tracks():
    truth = walk(1, range(10), 1.0) + walk(2, range(10), 3.0)
    tracks = [tr(r.frame, 7, r.x, r.y) for r in truth if r.person_id == 1 and r.frame < 6]
    r = clear_mot(tracks, truth)
    # person 2 missed 10 times, person 1 missed at frames 6..9 where nothing was output
    assert r.misses == 14
    assert r.miss_rate == pytest.approx(14 / 20)
    assert r.mota == pytest.approx(1 - 14 / 20)
    assert r.frames == 10 and r.matches == 6
    by_person = {p.person_id: p for p in r.per_person}
    assert (by_person[1].matches, by_person[1].misses) == (6, 4)
    assert (by_person[2].matches, by_person[2].misses, by_person[2].track_ids) == (0, 10, ())


def test_false_positive_track():
    truth = walk(1, range(5), 1.0)
    tracks = [tr(r.frame, 1, r.x, r.y) for r in truth] + [tr(f, 2, 5.0, 4.0) for f in (1, 2, 3)]
    r = clear_mot(tracks, truth)
    assert (r.misses, r.false_positives, r.mismatches) == (0, 3, 0)
    assert r.false_positive_rate == pytest.approx(3 / 5)
    assert r.mota == pytest.approx(1 - 3 / 5)
    assert r.motp_mm == pytest.approx(0.0, abs=1e-9)
    by_track = {t.track_id: t for t in r.per_track}
    assert (by_track[2].rows, by_track[2].false_positives, by_track[2].matches) == (3, 3, 0)


def test_identity_switch_is_one_mismatch():
    truth = walk(1, range(10), 1.0) + walk(2, range(10), 3.0)
    tracks = [tr(r.frame, 11 if r.frame < 5 else 12, r.x + 0.05, r.y)
              for r in truth if r.person_id == 1]
    tracks += [tr(r.frame, 20, r.x, r.y + 0.05) for r in truth if r.person_id == 2]
    r = clear_mot(tracks, truth)
    assert r.mismatches == 1
    assert (r.misses, r.false_positives) == (0, 0)
    assert r.matches == 20  # the mismatched pair is still matched (CLEAR c_t)
    assert r.mota == pytest.approx(1 - 1 / 20)
    assert r.motp_mm == pytest.approx(50.0)
    by_person = {p.person_id: p for p in r.per_person}
    assert by_person[1].mismatches == 1 and by_person[1].track_ids == (11, 12)
    assert by_person[2].mismatches == 0 and by_person[2].track_ids == (20,)
    # the per-frame detail names the track actually matched at each frame
    m = r.matches_detail
    p1 = m.person_id == 1
    assert list(m.track_id[p1]) == [11] * 5 + [12] * 5
    # IDF1: person 1 keeps track 11 for 5 of its 10 frames, person 2 track 20 for all 10
    assert (r.id_true_positives, r.id_false_positives, r.id_false_negatives) == (15, 5, 5)
    assert r.idf1 == pytest.approx(30 / 40)


def test_track_rows_at_stamps_absent_from_truth_are_ignored_and_counted():
    truth = walk(1, range(4), 1.0)
    tracks = [tr(r.frame, 1, r.x, r.y) for r in truth]
    tracks += [TrackRow(r.stamp_ns + 1, r.frame, 1, r.x, r.y) for r in truth[:3]]
    r = clear_mot(tracks, truth)
    assert r.ignored_track_rows == 3
    assert (r.false_positives, r.track_rows, r.mota) == (0, 4, pytest.approx(1.0))


def test_tracks_in_frames_where_nobody_is_present_are_false_positives():
    # the person is present in frames 0-3; frames 4-5 are empty, a phantom track stays
    truth = walk(1, range(4), 1.0)
    tracks = [tr(r.frame, 1, r.x, r.y) for r in truth]
    tracks += [tr(f, 2, 4.0, 4.0) for f in (4, 5)]
    r = clear_mot(tracks, truth)
    assert (r.frames, r.false_positives, r.ignored_track_rows) == (6, 2, 0)
    assert r.mota == pytest.approx(1 - 2 / 4)
    # an explicit frame list gives the same answer
    stamps = sorted({t.stamp_ns for t in tracks})
    assert clear_mot(tracks, truth, frame_stamps=stamps).false_positives == 2


def test_bad_inputs_raise_evaluation_error():
    truth = walk(1, range(3), 1.0)
    with pytest.raises(EvaluationError, match='empty'):
        clear_mot([], [])
    with pytest.raises(EvaluationError, match='twice'):
        clear_mot([], truth + truth[:1])
    with pytest.raises(EvaluationError, match='twice'):
        clear_mot([tr(0, 1, 0, 0), tr(0, 1, 1, 1)], truth)
    with pytest.raises(EvaluationError, match='threshold'):
        clear_mot([], truth, threshold_m=0.0)
    with pytest.raises(EvaluationError, match='finite'):
        clear_mot([tr(0, 1, float('nan'), 0.0)], truth)


def test_coalescence_counts_the_frames_with_two_tracks_on_one_person():
    from mbtrack_ros.evaluation.clear_mot import coalescence

    truth = walk(1, range(10), 2.0) + walk(2, range(10), 3.0)
    tracks = [tr(r.frame, r.person_id, r.x, r.y) for r in truth]     # one track each
    assert coalescence(tracks, truth) == 0.0
    # frames 6-9: track 2 leaves its person for person 1 (0.1 m from him): coalesced
    moved = [tr(t.frame, t.track_id, t.x + 0.1, 2.0) if t.track_id == 2 and t.frame >= 6
             else t for t in tracks]
    assert coalescence(moved, truth) == pytest.approx(4 / 10)
    # beyond the threshold of everyone it is on nobody: no coalescence, only a miss
    away = [tr(t.frame, t.track_id, t.x, 9.0) if t.track_id == 2 and t.frame >= 6 else t
            for t in tracks]
    assert coalescence(away, truth) == 0.0
    assert coalescence(moved, truth, threshold_m=0.05) == 0.0


def _reference_clear_mot(tracks, truth, threshold):
    """Brute-force CLEAR MOT (Bernardin & Stiefelhagen 2008) as py-motmetrics defines it:
    a person keeps its last matched track while that track is within the threshold (also
    after a gap), the rest is assigned optimally; a mismatch is a match to a track other than
    the person's last matched one."""
    frames = sorted({r.stamp_ns for r in truth})
    last = {}  # person -> last matched track
    misses = fps = mme = matches = 0
    dsum = 0.0
    for s in frames:
        g = sorted((r for r in truth if r.stamp_ns == s), key=lambda r: r.person_id)
        h = sorted((t for t in tracks if t.stamp_ns == s), key=lambda t: t.track_id)
        d = np.array([[np.hypot(a.x - b.x, a.y - b.y) for b in h] for a in g]).reshape(
            len(g), len(h))
        pairs = {}
        hid = [t.track_id for t in h]
        for i, a in enumerate(g):  # keep valid correspondences
            if a.person_id in last and last[a.person_id] in hid:
                j = hid.index(last[a.person_id])
                if d[i, j] <= threshold and j not in pairs.values():
                    pairs[i] = j
        kept = set(pairs)
        free_g = [i for i in range(len(g)) if i not in pairs]
        free_h = [j for j in range(len(h)) if j not in pairs.values()]
        if free_g and free_h:
            sub = d[np.ix_(free_g, free_h)]
            cost = np.where(sub <= threshold, sub, 1e6)
            rows, cols = linear_sum_assignment(cost)
            for a, b in zip(rows, cols):
                if cost[a, b] < 1e6:
                    pairs[free_g[a]] = free_h[b]
        for i, j in pairs.items():
            p, t = g[i].person_id, hid[j]
            if i not in kept and p in last and last[p] != t:
                mme += 1
            last[p] = t
            matches += 1
            dsum += d[i, j]
        misses += len(g) - len(pairs)
        fps += len(h) - len(pairs)
    n = len(truth)
    return dict(mota=1 - (misses + fps + mme) / n, motp_mm=1000 * dsum / matches,
                misses=misses, false_positives=fps, mismatches=mme, matches=matches)


@pytest.mark.parametrize('seed', [1, 2, 3, 6])
def test_clear_mot_equals_brute_force_on_random_scenes(seed):
    rng = np.random.default_rng(seed)
    n_frames, n_people = 25, 4
    pos = rng.uniform(0, 4, size=(n_people, 2)) + np.cumsum(
        rng.normal(0, 0.08, size=(n_frames, n_people, 2)), axis=0)
    truth = [gt(f, p, *pos[f, p]) for f in range(n_frames) for p in range(n_people)
             if rng.random() > 0.1]
    tracks = []
    for f in range(n_frames):
        ids = rng.permutation(n_people) if rng.random() < 0.15 else np.arange(n_people)
        for p in range(n_people):
            if rng.random() < 0.85:
                x, y = pos[f, p] + rng.normal(0, 0.25, 2)
                tracks.append(tr(f, 100 + int(ids[p]), x, y))
        if rng.random() < 0.3:
            tracks.append(tr(f, 200 + f % 3, *rng.uniform(0, 4, 2)))
    r = clear_mot(tracks, truth)
    ref = _reference_clear_mot(tracks, truth, 0.5)
    assert (r.misses, r.false_positives, r.mismatches, r.matches) == (
        ref['misses'], ref['false_positives'], ref['mismatches'], ref['matches'])
    assert r.mota == pytest.approx(ref['mota'])
    assert r.motp_mm == pytest.approx(ref['motp_mm'])
    assert ref['mismatches'] > 0 and ref['misses'] > 0 and ref['false_positives'] > 0
    # bookkeeping identities
    assert sum(p.mismatches for p in r.per_person) == r.mismatches
    assert sum(p.matches for p in r.per_person) == r.matches
    assert sum(t.false_positives for t in r.per_track) == r.false_positives
    assert r.matches + r.misses == r.gt_objects == len(truth)
    m = r.matches_detail
    assert np.nanmean(m.error_m) * 1000 == pytest.approx(r.motp_mm)
    # IDF1 by brute force: one track per person for the whole sequence, chosen to maximise
    # the frames where they are within the threshold (every one-to-one assignment tried)
    import itertools
    people = sorted({t.person_id for t in truth})
    ids = sorted({t.track_id for t in tracks})
    near = {(p, h): 0 for p in people for h in ids}
    where = {(t.stamp_ns, t.track_id): (t.x, t.y) for t in tracks}
    for g in truth:
        for h in ids:
            xy = where.get((g.stamp_ns, h))
            if xy is not None and np.hypot(g.x - xy[0], g.y - xy[1]) <= 0.5:
                near[g.person_id, h] += 1
    idtp = max(sum(near[p, h] for p, h in zip(people, chosen) if h is not None)
               for chosen in itertools.permutations(ids + [None] * len(people), len(people)))
    assert r.id_true_positives == idtp
    assert r.idf1 == pytest.approx(2 * idtp / (len(truth) + len(tracks)))


def test_evaluate_many_sums_counts_and_weights_motp():
    truth_a = walk(1, range(10), 1.0)
    tracks_a = [tr(r.frame, 1, r.x + 0.1, r.y) for r in truth_a]
    truth_b = walk(1, range(10), 1.0) + walk(2, range(10), 3.0)
    tracks_b = [tr(r.frame, 1, r.x + 0.3, r.y) for r in truth_b if r.person_id == 1]
    table = evaluate_many({'a': (tracks_a, truth_a), 'b': (tracks_b, truth_b)})
    a, b, o = table.sequences['a'], table.sequences['b'], table.overall
    assert (a.mota, b.mota) == (pytest.approx(1.0), pytest.approx(0.5))
    assert o.gt_objects == 30 and o.misses == 10 and o.matches == 20
    assert o.mota == pytest.approx(1 - 10 / 30)
    assert o.motp_mm == pytest.approx((10 * 100 + 10 * 300) / 20)
    assert (a.idf1, b.idf1) == (pytest.approx(1.0), pytest.approx(20 / 30))
    assert o.idf1 == pytest.approx(2 * 20 / (30 + 20))
    text = format_table(table.rows())
    lines = text.splitlines()
    assert len(lines) == 5 and lines[-1].startswith('overall')
    assert len({len(line) for line in lines}) == 1  # aligned
    json.dumps(table.to_dict())


def test_write_report_for_several_sequences(tmp_path):
    truth = walk(1, range(6), 1.0)
    good = [tr(r.frame, 1, r.x + 0.2, r.y) for r in truth]
    table = evaluate_many({'s1': (good, truth), 's2': (good[:3], truth)})
    ps = _particles_for(truth, [1] * 6, [[0.2, 0.2]] * 6, [[0.5, 0.5]] * 6)
    post = {'s1': posterior_mass(ps, truth, good)}
    paths = write_report(tmp_path, table.rows(), posterior=post, notes=['something odd'])
    doc = json.loads(paths['json'].read_text())
    assert [s['name'] for s in doc['sequences']] == ['s1', 's2', 'overall']
    assert doc['sequences'][2]['misses'] == 3 and doc['sequences'][2]['gt_objects'] == 12
    assert doc['posterior_mass']['s1']['mass_within_0_5m'] == pytest.approx(1.0, abs=1e-6)
    assert doc['warnings'] == ['something odd']
    md = paths['markdown'].read_text().splitlines()
    rows = [line for line in md if line.startswith(('| s1 ', '| s2 ', '| overall '))]
    assert len(rows) == 3 and rows[0].split('|')[-2].strip() == '1.000'
    assert rows[1].split('|')[2].strip() == '50.0 %'  # s2: MOTA 1 - 3/6


# ---------------------------------------------------------------- posterior-mass curve

def _particles_for(rows, tids, offsets_per_row, weights_per_row) -> ParticleSet:
    xy = np.array([[(r.x + dx, r.y) for dx in offs] for r, offs in zip(rows, offsets_per_row)],
                  np.float32)
    return ParticleSet(stamp_ns=np.array([r.stamp_ns for r in rows], np.int64),
                       track_id=np.array(tids, np.int64), xy=xy,
                       weights=np.array(weights_per_row, np.float32))


def test_posterior_mass_half_at_0_2_half_at_0_8():
    truth = walk(1, range(5), 2.0)
    tracks = [tr(r.frame, 3, r.x, r.y) for r in truth]
    ps = _particles_for(truth, [3] * 5, [[0.2, 0.2, -0.8, 0.8]] * 5,
                        [[0.25, 0.25, 0.25, 0.25]] * 5)
    d = np.array([0.0, 0.1, 0.19, 0.21, 0.5, 0.79, 0.81, 1.0])
    curve = posterior_mass_curve(ps, truth, tracks, d)
    np.testing.assert_allclose(curve, [0, 0, 0, 0.5, 0.5, 0.5, 1.0, 1.0], atol=1e-6)
    res = posterior_mass(ps, truth, tracks)
    assert res.at(0.5) == pytest.approx(0.5, abs=1e-6)
    assert res.at(0.1) == pytest.approx(0.0) and res.at(1.0) == pytest.approx(1.0, abs=1e-6)
    assert (res.person_frames, res.with_particles, res.missing_particle_rows) == (5, 5, 0)


def test_unmatched_person_frames_and_missing_particle_rows_count_as_zero_mass():
    truth = walk(1, range(4), 1.0) + walk(2, range(4), 3.0)
    # person 2 is never tracked; person 1's track has particles at frames 0..2 only
    tracks = [tr(r.frame, 9, r.x, r.y) for r in truth if r.person_id == 1]
    rows1 = [r for r in truth if r.person_id == 1][:3]
    ps = _particles_for(rows1, [9] * 3, [[0.0, 0.05]] * 3, [[0.5, 0.5]] * 3)
    res = posterior_mass(ps, truth, tracks, [0.001, 0.01, 0.5])
    # 8 person-frames, 3 of them with all mass within 0.05 m
    np.testing.assert_allclose(res.fraction, [0.5 * 3 / 8, 0.5 * 3 / 8, 3 / 8], atol=1e-6)
    assert (res.person_frames, res.with_particles, res.missing_particle_rows) == (8, 3, 1)


def test_posterior_mass_uses_the_clear_mot_association():
    # two tracks: the one matched to the person has a tight cloud, the other a wide one;
    # particle rows of an unmatched (false-positive) track must not be used
    truth = walk(1, range(3), 2.0)
    tracks = [tr(r.frame, 1, r.x, r.y) for r in truth] + [
        tr(r.frame, 2, r.x + 2.0, r.y) for r in truth]
    ps1 = _particles_for(truth, [1] * 3, [[0.0, 0.0]] * 3, [[0.5, 0.5]] * 3)
    ps2 = _particles_for(truth, [2] * 3, [[0.9, 0.9]] * 3, [[0.5, 0.5]] * 3)
    both = ParticleSet(*(np.concatenate([getattr(ps2, k), getattr(ps1, k)])
                         for k in ('stamp_ns', 'track_id', 'xy', 'weights')))
    curve = posterior_mass_curve(both, truth, tracks, [0.1, 0.95])
    np.testing.assert_allclose(curve, [1.0, 1.0], atol=1e-6)


def test_posterior_mass_equals_brute_force(tmp_path, monkeypatch):
    import mbtrack_ros.evaluation.posterior as posterior_module
    monkeypatch.setattr(posterior_module, '_CHUNK_ROWS', 5)  # several distance batches
    rng = np.random.default_rng(7)
    truth = walk(1, range(12), 1.0) + walk(2, range(12), 2.5)
    tracks = [tr(r.frame, r.person_id + 40, r.x + rng.normal(0, 0.1), r.y) for r in truth
              if rng.random() < 0.8]
    rec = ParticleRecorder()
    for t in tracks:
        n = int(rng.integers(5, 30))  # varying particle counts: padded rows
        rec.add(t.stamp_ns, t.track_id, np.array([t.x, t.y]) + rng.normal(0, 0.4, (n, 2)),
                rng.random(n))
    path = rec.save(tmp_path / 'particles.npz')
    ps = load_particles(path)
    d = rng.permutation(np.linspace(0, 1, 21))  # any order of the distances
    got = posterior_mass_curve(path, truth, tracks, d)
    matching = clear_mot(tracks, truth)
    m = matching.matches_detail
    want = np.zeros_like(d)
    for i in range(len(m)):
        if m.track_id[i] < 0:
            continue
        k = np.flatnonzero((ps.stamp_ns == m.stamp_ns[i]) & (ps.track_id == m.track_id[i]))[0]
        dist = np.hypot(ps.xy[k, :, 0] - m.x[i], ps.xy[k, :, 1] - m.y[i])
        want += [ps.weights[k][dist <= dd].sum() for dd in d]
    want /= len(m)
    np.testing.assert_allclose(got, want, atol=1e-9)
    assert np.all(np.diff(got[np.argsort(d)]) >= 0) and 0 < got.max() < 1


def test_particle_recorder_round_trip_from_frame_results(tmp_path):
    rng = np.random.default_rng(3)
    rec = ParticleRecorder()
    all_parts = []
    for k in range(3):
        parts = [rng.normal(size=(n, 6)) for n in (4, 7)]
        all_parts += parts
        tracks = [TrackEstimate(track_id=i + 1, mean=p.mean(0), covariance=np.eye(4),
                                height=1.7, particles=p, weights=np.full(len(p), 2.0))
                  for i, p in enumerate(parts)]
        tracks.append(TrackEstimate(track_id=9, mean=np.zeros(6), covariance=np.eye(4),
                                    height=1.7))  # no particles: skipped
        rec.add_frame(FrameResult(stamp_ns=1000 * k, tracks=tracks))
    save_particles(tmp_path / 'p.npz', rec.particle_set())
    with np.load(tmp_path / 'p.npz') as raw:
        assert raw['xy'].dtype == np.float32 and raw['weights'].dtype == np.float32
        assert raw['stamp_ns'].dtype == np.int64 and raw['xy'].shape == (6, 7, 2)
    ps = load_particles(tmp_path / 'p.npz')
    assert list(ps.track_id) == [1, 2] * 3 and list(ps.stamp_ns) == [0, 0, 1000, 1000, 2000,
                                                                    2000]
    np.testing.assert_allclose(ps.weights.sum(1), 1.0)
    np.testing.assert_allclose(ps.weights[0], [0.25] * 4 + [0.0] * 3, atol=1e-7)
    for i, p in enumerate(all_parts):
        np.testing.assert_allclose(ps.xy[i, :len(p)], p[:, :2], atol=1e-6)


def test_load_particles_rejects_bad_files(tmp_path):
    np.savez(tmp_path / 'a.npz', stamp_ns=np.zeros(2, np.int64), xy=np.zeros((2, 3, 2)))
    with pytest.raises(EvaluationError, match='missing array'):
        load_particles(tmp_path / 'a.npz')
    np.savez(tmp_path / 'b.npz', stamp_ns=np.zeros(2, np.int64),
             track_id=np.zeros(2, np.int64), xy=np.zeros((2, 3, 2)), weights=np.zeros((2, 4)))
    with pytest.raises(EvaluationError, match='shapes'):
        load_particles(tmp_path / 'b.npz')
    np.savez(tmp_path / 'c.npz', stamp_ns=np.zeros(1, np.int64),
             track_id=np.zeros(1, np.int64), xy=np.zeros((1, 3, 2)), weights=np.zeros((1, 3)))
    with pytest.raises(EvaluationError, match='zero total weight'):
        load_particles(tmp_path / 'c.npz')
    (tmp_path / 'd.npz').write_text('not a zip')
    with pytest.raises(EvaluationError):
        load_particles(tmp_path / 'd.npz')
    with pytest.raises(EvaluationError, match='cannot read'):
        load_particles(tmp_path / 'missing.npz')


# ---------------------------------------------------------------- plots and the command

def _is_png(path) -> bool:
    return path.stat().st_size > 1000 and path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_plots_write_png_files(tmp_path):
    truth = walk(1, range(10), 1.0) + walk(2, range(10), 3.0)
    tracks = [tr(r.frame, r.person_id, r.x + 0.1, r.y) for r in truth if r.frame != 4]
    r = clear_mot(tracks, truth)
    paths = [plot_trajectories(tracks, truth, tmp_path / 't.png'),
             plot_localisation_error(r, tmp_path / 'e.png'),
             plot_posterior_curves({'HJS': (np.linspace(0, 1, 11), np.linspace(0, 1, 11)),
                                    'S': ([0, 1], [0, 0.5])}, tmp_path / 'p.png')]
    assert all(_is_png(p) for p in paths)
    with pytest.raises(EvaluationError):
        plot_posterior_curves({'bad': ([0, 1], [0, 0.5, 1])}, tmp_path / 'q.png')


def _args(tracks, truth, **kw) -> argparse.Namespace:
    base = dict(tracks=tracks, ground_truth=truth, out=None, particles=None, threshold=0.5,
                name=None, no_plots=False, calibration=None)
    base.update(kw)
    return argparse.Namespace(**base)


def _write_inputs(tmp_path):
    truth = walk(1, range(10), 1.0) + walk(2, range(10), 3.0)
    tracks = [tr(r.frame, r.person_id + 10, r.x + 0.1, r.y) for r in truth if r.frame != 4]
    write_ground_truth(tmp_path / 'ground_truth.csv', truth)
    write_tracks(tmp_path / 'tracks.csv', tracks)
    rec = ParticleRecorder()
    for t in tracks:
        rec.add(t.stamp_ns, t.track_id, [[t.x, t.y], [t.x + 0.7, t.y]], [0.5, 0.5])
    rec.save(tmp_path / 'particles.npz')
    return truth, tracks


def test_eval_command_writes_report_and_plots(tmp_path, capsys):
    _write_inputs(tmp_path)
    out = tmp_path / 'out'
    code = eval_cmd.run(_args(tmp_path / 'tracks.csv', tmp_path / 'ground_truth.csv', out=out,
                              particles=tmp_path / 'particles.npz'))
    captured = capsys.readouterr()
    assert code == 0, captured.err
    for name in ('scores.md', 'scores.json'):
        assert (out / name).is_file()
    pngs = sorted(p.name for p in out.glob('*.png'))
    assert pngs == ['error.png', 'posterior_mass.png', 'trajectories.png']
    assert all(_is_png(out / p) for p in pngs)
    doc = json.loads((out / 'scores.json').read_text())
    seq = doc['sequences'][0]
    # 2 persons x 10 frames, frame 4 missing from the tracks; tracks are 100 mm off
    assert (seq['gt_objects'], seq['misses'], seq['matches']) == (20, 2, 18)
    assert seq['motp_mm'] == pytest.approx(100.0, abs=0.1)  # CSV keeps 4 decimals
    assert seq['mota'] == pytest.approx(0.9)
    # particle at the track (0.1 m from the truth) and one 0.8 m away, 18 of 20 matched
    pm = doc['posterior_mass'][tmp_path.name]
    assert pm['mass_within_0_5m'] == pytest.approx(0.5 * 18 / 20, abs=1e-5)
    md = (out / 'scores.md').read_text()
    assert '| tracks |' in md and '90.0 %' in md and 'trajectories.png' in md
    assert '100 mm' in captured.out and 'MOTA' in captured.out


def test_eval_command_default_out_dir_and_cli_dispatch(tmp_path, capsys):
    from mbtrack_ros.cli import main
    _write_inputs(tmp_path)
    code = main(['eval', str(tmp_path / 'tracks.csv'), str(tmp_path / 'ground_truth.csv'),
                 '--no-plots', '--threshold', '0.05'])
    assert code == 0, capsys.readouterr().err
    doc = json.loads((tmp_path / 'scores.json').read_text())
    assert doc['threshold_m'] == 0.05
    assert doc['sequences'][0]['matches'] == 0  # 100 mm offsets beyond a 50 mm threshold
    assert not list(tmp_path.glob('*.png'))


def test_eval_command_draws_calibration_beside_ground_truth(tmp_path, capsys, room):
    _write_inputs(tmp_path)
    room.save(tmp_path / 'calibration.yaml')
    code = eval_cmd.run(_args(tmp_path / 'tracks.csv', tmp_path / 'ground_truth.csv'))
    captured = capsys.readouterr()
    assert code == 0 and 'warning' not in captured.err
    assert _is_png(tmp_path / 'trajectories.png')
    # the sequence is named after the directory of tracks.csv
    doc = json.loads((tmp_path / 'scores.json').read_text())
    assert doc['sequences'][0]['name'] == tmp_path.name


@pytest.mark.parametrize('case', ['missing_tracks', 'missing_truth', 'wrong_columns',
                                  'empty_truth', 'bad_particles', 'bad_threshold',
                                  'bad_calibration'])
def test_eval_command_bad_inputs_exit_2_with_one_line(tmp_path, capsys, case):
    _write_inputs(tmp_path)
    tracks, truth = tmp_path / 'tracks.csv', tmp_path / 'ground_truth.csv'
    kw = {'out': tmp_path / 'out'}
    if case == 'missing_tracks':
        tracks = tmp_path / 'nope.csv'
    elif case == 'missing_truth':
        truth = tmp_path / 'nope.csv'
    elif case == 'wrong_columns':
        (tmp_path / 'bad.csv').write_text('time,id,px,py\n1,2,3,4\n')
        tracks = tmp_path / 'bad.csv'
    elif case == 'empty_truth':
        truth.write_text(truth.read_text().splitlines()[0] + '\n')
    elif case == 'bad_particles':
        (tmp_path / 'p.npz').write_bytes(b'garbage')
        kw['particles'] = tmp_path / 'p.npz'
    elif case == 'bad_threshold':
        kw['threshold'] = -1.0
    elif case == 'bad_calibration':
        (tmp_path / 'c.yaml').write_text('cameras: [\n  - {a: 1\n')
        kw['calibration'] = tmp_path / 'c.yaml'
    code = eval_cmd.run(_args(tracks, truth, **kw))
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('mbtrack eval: error: ')
    assert 'Traceback' not in err
    assert not (tmp_path / 'out' / 'scores.json').exists()


def test_time_to_track_is_the_wait_for_the_first_matched_frame():
    """Person 1 is tracked from his 6th frame, person 2 from his first (which is the
    recording's 5th), person 3 never; a track far from everyone matches nobody."""
    truth = walk(1, range(20), 1.0) + walk(2, range(4, 20), 3.0) + walk(3, range(20), 5.0)
    tracks = [tr(r.frame, 1, r.x + 0.1, r.y) for r in truth if r.person_id == 1
              and r.frame >= 5]
    tracks += [tr(r.frame, 2, r.x, r.y - 0.2) for r in truth if r.person_id == 2]
    tracks += [tr(f, 9, 9.0, 9.0) for f in range(20)]
    persons, wait = clear_mot(tracks, truth).matches_detail.time_to_track()
    np.testing.assert_array_equal(persons, [1, 2, 3])
    np.testing.assert_allclose(wait[:2], [5 * STEP * 1e-9, 0.0])
    assert wait[2] == np.inf
    # a track beyond the match threshold does not count as found
    late = [tr(r.frame, 1, r.x + (0.1 if r.frame >= 8 else 0.8), r.y)
            for r in truth if r.person_id == 1]
    _, wait = clear_mot(late, truth).matches_detail.time_to_track()
    assert wait[0] == pytest.approx(8 * STEP * 1e-9)
