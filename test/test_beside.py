"""Births beside a live track (AutoDetectionConfig.beside_support): a confirmed detection next to a reported track that fell
behind its person moves that track instead of starting a second one on the person; a
newcomer next to a track on a person of its own is born."""
from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest

from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.detector import Detection, FrameEvidence
from mbtrack_ros.core.detection.manager import AutoDetection, AutoDetectionConfig
from mbtrack_ros.core.shape import BodyShape, render_labels
from mbtrack_ros.core.state import TrackEstimate
from mbtrack_ros.core.tracker import TrackerConfig, TrackerError

from test_detection import (FPS, H, W, _detecting_tracker, _track_painted, backgrounds,
                            make_room, paint, person)

SHAPE = BodyShape(1.8, 0.5)


class _Model:
    """What _exclusive_support reads of a person model: its shape."""
    shape = SHAPE


def _state(x, y):
    return np.array([x, y, 0.0, 0.0, 0.0, 0.0])


def _supports(people_xy, track_xy, det_xy, ghosts=0):
    """Exclusive support of one track alone and with the detection as one more track, and
    whether it is spare, on a foreground painted from ``people_xy`` (corner cameras); the
    first ``ghosts`` people are possible people of the bootstrap (``FrameEvidence.ghost``)."""
    calib = make_room(ceiling=False)
    auto = AutoDetection(calib, AutoDetectionConfig())
    evidence = {}
    for n, cam in calib.cameras.items():
        fg = np.zeros((H, W), bool)
        ghost = np.zeros((H, W), bool)
        for j, xy in enumerate(people_xy):
            fg |= render_labels(cam, _state(*xy), SHAPE) > 0
            if j < ghosts:
                ghost |= render_labels(cam, _state(*xy), SHAPE) > 0
        evidence[n] = FrameEvidence(np.zeros((H, W, 3), np.uint8), fg, ghost=ghost)
    track = TrackEstimate(1, _state(*track_xy), np.eye(4), 1.8)
    det = Detection(_state(*det_xy), 1.8, 0.5, 5.0)
    alone, beside, spare = auto._exclusive_support(
        det, _Model(), [track], [0], track.mean[None], {1: _Model()}, evidence)
    return float(alone[0]), float(beside[0]), bool(spare[0])


def test_a_lagging_track_loses_its_exclusive_support_to_the_detection_of_its_person():
    """A track 0.6 m behind its person, on the diagonal the corner cameras cam0 and cam2
    look along, keeps part of their foreground (0.34 of its silhouette); with the
    detection of the person as one more track that part is shared, and what is left is
    below the release's spare level. A track on a person of its own, next to a newcomer
    0.7 m away, keeps nearly all of its support."""
    alone, beside, spare = _supports([(2.6, 2.6)], (2.18, 2.18), (2.6, 2.6))
    assert beside < 0.25 <= alone and not spare, (alone, beside)
    alone, beside, spare = _supports([(2.0, 2.6), (2.0, 3.3)], (2.0, 2.6), (2.0, 3.3))
    assert beside > 0.5 and alone > 0.8 and not spare, (alone, beside)


def test_a_bootstrap_ghost_is_no_support_of_a_track():
    """A track on a person who stood there in the bootstrap frames (the background's
    possible-person pixels): those pixels are nobody's support, so the track has none to
    lose to a detection beside it (and the rule, which needs support before, keeps it);
    the same person not a ghost supports it fully."""
    alone, beside, _ = _supports([(2.0, 2.6), (2.0, 3.3)], (2.0, 2.6), (2.0, 3.3), ghosts=1)
    assert alone < 0.05 and beside < 0.05, (alone, beside)
    alone, _, _ = _supports([(2.0, 2.6), (2.0, 3.3)], (2.0, 2.6), (2.0, 3.3), ghosts=0)
    assert alone > 0.8


def _lagging(monkeypatch, beside_support, lag=0.42, frames=14, tracked=36, until='decision',
             beside_threshold=0.0, decisions=None, relocate_margin=1e9,
             weak_relocate_margin=1e9, young_look_alike=True):
    """A person walking at 0.3 m/s along y = 2.6 m, tracked as track 1 for ``tracked``
    frames (36: longer than ``relocate_interval``); then, before each step (until the first
    decision, or always with ``until=None``), track 1
    is put ``lag`` metres behind them in x and in y (0.6 m off, on the diagonal the corner
    cameras cam0 and cam2 look along: a track that fell behind its person and keeps part
    of their foreground). The appearance gain cannot
    move it (``relocate_margin`` and ``weak_relocate_margin`` huge unless given), the
    reach is off, and it stays reported (on the
    recordings such tracks had existence 0.99-1.0 when the birth came; in this painted
    room its existence falls, and a hidden track is the other rule's,
    ``relocate_hidden``; so is a reported one of doubtful existence, ``reuse_doubtful``,
    off here). ``beside_threshold`` 0: any detection beside it may be born.
    Returns the tracker and the decisions' actions (the whole records are appended to
    ``decisions`` when given); ``young_look_alike``: the config's switch."""
    monkeypatch.setattr(AutoDetection, 'reported', lambda self, tid: True)
    rng = np.random.default_rng(3)
    calib = make_room(ceiling=False)
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=2)
    det = tracker.detection
    det.config = replace(det.config, reach_radius=0.0, relocate_margin=relocate_margin,
                         weak_relocate_margin=weak_relocate_margin, relocate_hidden=False,
                         reuse_doubtful=0.0, beside_support=beside_support,
                         beside_threshold=beside_threshold,
                         young_look_alike=young_look_alike)

    def walker(k):
        return [person(2.0 + 0.02 * k, 2.6, theta=0.0)]
    _track_painted(tracker, calib, bgs, rng, tracked, walker)
    assert tracker.track_ids == [1]
    actions = []
    for k in range(tracked, tracked + frames):
        if 1 in tracker.track_ids and not (actions and until == 'decision'):
            tracker.relocate_track(1, _state(2.0 + 0.02 * (k - 1) - lag, 2.6 - lag))
        tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, walker(k), rng))
        actions += [d['action'] for d in det.decisions]
        if decisions is not None:
            decisions += det.decisions
    return tracker, actions


@pytest.mark.parametrize('beside_support', [0.25, 0.0])
def test_a_detection_beside_a_lagging_reported_track_moves_it(monkeypatch, beside_support):
    """With the rule the person's detection moves the lagging track (same id, no second
    track); without it a second track is born on the person (and one of the two is
    released later as a duplicate)."""
    tracker, actions = _lagging(monkeypatch, beside_support)
    if beside_support > 0:
        assert 'move 1 (beside)' in actions and 'birth' not in actions, actions
        assert tracker.track_ids == [1]
    else:
        assert 'birth' in actions and not any(a.startswith('move') for a in actions)


def test_a_young_track_lagging_since_its_birth_is_moved_once(monkeypatch):
    """A track 0.5 s old (born, never moved) that lags its person is moved by their
    detection (a track left on its person's bootstrap place); moved, it is not moved again
    within ``relocate_interval`` (it would hop through a group): the next detection beside
    it while it is kept lagging is dropped (``young_look_alike``: the young track's own
    person), or born without that rule."""
    for young_rule, after in ((True, 'drop (young look-alike 1)'), (False, 'birth')):
        tracker, actions = _lagging(monkeypatch, 0.25, tracked=8, frames=30, until=None,
                                    young_look_alike=young_rule)
        beside = [a for a in actions if a.endswith('(beside)')]
        assert beside == ['move 1 (beside)'], actions
        assert actions.index('move 1 (beside)') < actions.index(after), actions
        assert 'birth' not in actions or not young_rule, actions


def test_a_newcomer_beside_a_tracked_person_is_born(caplog):
    """A second person, dressed like the first, walks up to 0.7 m beside a person tracked
    for 2.4 s: the tracked person's exclusive support stays above ``beside_support`` with
    the newcomer's detection as a track, so the newcomer is born and track 1 stays put.
    (The appearance gain, which would move track 1 onto a person dressed alike, is
    switched off: ``relocate_margin`` huge.)"""
    rng = np.random.default_rng(4)
    calib = make_room(ceiling=False)
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=3)
    tracker.detection.config = replace(tracker.detection.config, relocate_margin=1e9,
                                       beside_support=0.25)
    a = person(2.5, 2.5, theta=0.0)

    def b(k):
        return person(2.5 + 0.02 * (k - 36), 3.2, theta=0.0)
    res = _track_painted(tracker, calib, bgs, rng, 36, lambda k: [a])
    assert tracker.track_ids == [1]
    decisions = []
    caplog.set_level(logging.DEBUG, logger='mbtrack_ros.core.detection.association')
    for k in range(36, 52):
        res = tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, [a, b(k)], rng))
        decisions += tracker.detection.decisions
    assert [d['action'] for d in decisions] == ['birth'], decisions
    assert decisions[0]['beside'][0][0] == 1 and decisions[0]['beside'][0][2] >= 0.25
    # one debug line per decision, with the detection's place, the action and the terms
    lines = [r.getMessage() for r in caplog.records if r.name.endswith('association')]
    assert len(lines) == 1 and ': birth;' in lines[0] and 'beside=' in lines[0], lines
    assert tracker.track_ids == [1, 2]
    final = {t.track_id: t.mean[:2] for t in res.tracks}
    assert np.linalg.norm(final[1] - [2.5, 2.5]) < 0.25


def test_beside_support_must_not_be_negative():
    with pytest.raises(DetectionError):
        AutoDetectionConfig(beside_support=-0.1)


class _KeyedModel(_Model):
    """A person model as far as the rule reads it: a shape and key views."""
    view_angles = np.zeros(1)


def _decide(tracks_xy, people_xy=((2.6, 2.6),), det_xy=(2.6, 2.6), **config):
    """``AutoDetection._lagging_beside`` on a painted foreground: the index of the track
    moved onto the detection (or None) and the decision's ``beside`` record;
    ``config``: more ``AutoDetectionConfig`` fields."""
    calib = make_room(ceiling=False)
    auto = AutoDetection(calib, AutoDetectionConfig(beside_support=0.25, **config))
    evidence = {}
    for n, cam in calib.cameras.items():
        fg = np.zeros((H, W), bool)
        for xy in people_xy:
            fg |= render_labels(cam, _state(*xy), SHAPE) > 0
        evidence[n] = FrameEvidence(np.zeros((H, W, 3), np.uint8), fg)
    tracks = [TrackEstimate(j + 1, _state(*xy), np.eye(4), 1.8)
              for j, xy in enumerate(tracks_xy)]
    means = np.array([t.mean for t in tracks])
    det = Detection(_state(*det_xy), 1.8, 0.5, 5.0)
    info: dict = {}
    best = auto._lagging_beside(det, _KeyedModel(), tracks, list(range(len(tracks))), means,
                                {t.track_id: _KeyedModel() for t in tracks}, evidence, set(),
                                0, info)
    return (None if best is None else best[0]), info['beside']


def test_only_a_single_track_losing_its_support_is_moved():
    """One lagging track beside the detection of its person is taken; two tracks that
    would both be left spare by it (a group) make it unclear whose person it is: none is
    taken. A track on a second person next to the lagging one does not stop the move."""
    lagging = (2.18, 2.18)
    assert _decide([lagging])[0] == 0
    moved, record = _decide([lagging, (2.18, 2.6)])
    assert record[0][1] >= 0.25 > record[1][1]                 # track 1 alone qualifies
    assert moved is None and all(with_det < 0.25 for _, _, with_det in record), record
    moved, record = _decide([(3.3, 2.6), lagging], people_xy=((2.6, 2.6), (3.3, 2.6)))
    assert moved == 1 and record[0][2] > 0.25, record


def test_only_a_track_within_beside_radius_is_moved():
    """The lagging track 0.59 m from the detection of its person is taken within the
    default 0.6 m; with ``beside_radius`` 0.55 it is not (it is still the one track the
    detection would leave spare: the record lists it), and a negative radius is
    refused."""
    lagging = (2.18, 2.18)
    assert np.hypot(2.6 - 2.18, 2.6 - 2.18) == pytest.approx(0.594, abs=1e-3)
    assert AutoDetectionConfig().beside_radius == 0.6
    assert _decide([lagging])[0] == 0
    moved, record = _decide([lagging], beside_radius=0.55)
    assert moved is None and record[0][1] >= 0.25 > record[0][2], record
    with pytest.raises(DetectionError, match='beside_radius'):
        AutoDetectionConfig(beside_radius=-0.1)


def test_beside_threshold_must_be_a_finite_number_not_below_zero():
    for bad in (-0.5, float('nan'), float('inf')):
        with pytest.raises(DetectionError):
            AutoDetectionConfig(beside_threshold=bad)
        with pytest.raises(TrackerError, match='beside_threshold'):
            TrackerConfig(beside_threshold=bad)
    with pytest.raises(TrackerError, match='beside_threshold'):
        TrackerConfig(beside_threshold=True)


def test_the_tracker_config_hands_beside_threshold_to_the_pipeline():
    assert TrackerConfig(beside_threshold=2.0).detection_config().beside_threshold == 2.0
    assert TrackerConfig().detection_config().beside_threshold == \
        AutoDetectionConfig().beside_threshold


def test_a_weak_detection_beside_a_track_starts_no_track(monkeypatch):
    """The person's detection beside their lagging track (moved neither by the gain nor
    by the support rule) is born with ``beside_threshold`` 0; a threshold just above its
    score drops it, and the track stays the only one."""
    decisions = []
    tracker, actions = _lagging(monkeypatch, 0.0, beside_threshold=0.0, decisions=decisions)
    assert actions == ['birth'] and decisions[0]['near'], decisions
    tracker, actions = _lagging(monkeypatch, 0.0, beside_threshold=decisions[0]['score'] + 0.01)
    assert 'birth' not in actions and 'drop (weak beside a track)' in actions, actions
    assert tracker.track_ids == [1]


def test_a_weak_detection_moves_a_track_only_with_the_weak_margin(monkeypatch):
    """The person's detection beside their lagging track, with gain g for track 1 and
    score s: scoring at least ``beside_threshold`` it moves the track by
    ``relocate_margin`` alone; below the threshold it moves it only when g exceeds
    ``weak_relocate_margin`` (just below g: moved; just above: dropped, and neither moved
    nor born)."""
    lax = dict(relocate_margin=-1e9, weak_relocate_margin=-1e9)
    decisions = []
    _, actions = _lagging(monkeypatch, 0.0, decisions=decisions, **lax)
    assert actions == ['move 1'], decisions
    score = decisions[0]['score']
    gain = next(n[2] for n in decisions[0]['near'] if n[0] == 1)   # (id, m, gain, distance)
    weak = score + 0.01
    runs = {'strong, margin above g': dict(beside_threshold=0.0, relocate_margin=-1e9,
                                           weak_relocate_margin=gain + 0.01),
            'weak, margin below g': dict(beside_threshold=weak, relocate_margin=-1e9,
                                         weak_relocate_margin=gain - 0.01),
            'weak, margin above g': dict(beside_threshold=weak, relocate_margin=-1e9,
                                         weak_relocate_margin=gain + 0.01)}
    first = {}
    for name, kwargs in runs.items():
        tracker, actions = _lagging(monkeypatch, 0.0, **kwargs)
        first[name] = actions[0]
        if name == 'weak, margin above g':
            assert not any(a.startswith('move') or a == 'birth' for a in actions), actions
            assert tracker.track_ids == [1]
    assert first == {'strong, margin above g': 'move 1', 'weak, margin below g': 'move 1',
                     'weak, margin above g': 'drop (weak beside a track)'}, first
    for bad in (float('nan'), -float('inf')):
        with pytest.raises(DetectionError, match='weak_relocate_margin'):
            AutoDetectionConfig(weak_relocate_margin=bad)


def _newcomer(**config):
    """A person tracked at (2.5, 2.5) for 36 frames, then a newcomer walking in 0.7 m
    beside them, with the ``AutoDetectionConfig`` fields ``config``: the decisions' records
    and the live track ids at the end."""
    rng = np.random.default_rng(4)
    calib = make_room(ceiling=False)
    bgs = backgrounds(calib)
    tracker = _detecting_tracker(calib, bgs, seed=3)
    tracker.detection.config = replace(tracker.detection.config, **config)
    a = person(2.5, 2.5, theta=0.0)
    _track_painted(tracker, calib, bgs, rng, 36, lambda k: [a])
    decisions = []
    for k in range(36, 52):
        b = person(2.5 + 0.02 * (k - 36), 3.2, theta=0.0)
        tracker.step(int(round(k * 1e9 / FPS)), paint(calib, bgs, [a, b], rng))
        decisions += tracker.detection.decisions
    return decisions, tracker.track_ids


def test_a_strong_detection_of_a_newcomer_beside_a_track_is_born():
    """The newcomer 0.7 m beside a tracked person scores above the default
    ``beside_threshold`` and is born; a threshold above its score drops it."""
    scores = {}
    for threshold in (AutoDetectionConfig.beside_threshold, 1e6):
        decisions, ids = _newcomer(relocate_margin=1e9, beside_threshold=threshold)
        scores[threshold] = ([d['action'] for d in decisions], len(ids))
    default, high = scores[AutoDetectionConfig.beside_threshold], scores[1e6]
    assert default == (['birth'], 2), default
    assert 'birth' not in high[0] and high[1] == 1, high


def test_a_track_on_a_person_of_its_own_is_not_moved_onto_a_newcomer(monkeypatch):
    """With any appearance gain enough to move a track, the newcomer's detection beside a
    tracked person takes that person's track when ``move_support`` is off (above 1); with
    the default the track keeps its own exclusive support beside the detection (at least
    ``move_support``), stays on its person and the newcomer is born. The person's detection
    beside her lagging track still moves it (the detection leaves it spare)."""
    lax = dict(relocate_margin=-1e9, weak_relocate_margin=-1e9)
    off, ids_off = _newcomer(move_support=2.0, **lax)
    assert [d['action'] for d in off] == ['move 1'] and ids_off == [1], off
    on, ids_on = _newcomer(**lax)
    assert [d['action'] for d in on] == ['birth'] and ids_on == [1, 2], on
    left = dict(on[0]['support'])[1]            # the same support with the check off
    assert AutoDetectionConfig.move_support <= left <= 1 and off[0]['support'] == \
        on[0]['support'], (on[0], off[0])
    _, actions = _lagging(monkeypatch, 0.0, **lax)
    assert actions == ['move 1'], actions
    with pytest.raises(DetectionError, match='move_support'):
        AutoDetectionConfig(move_support=-0.1)
