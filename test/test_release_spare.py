"""Spare tracks: a track whose silhouette explains no foreground that the other tracks do
not is released (release.spare_tracks, ReleaseConfig.spare_support)."""
from __future__ import annotations

import numpy as np
import pytest

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.detector import FrameEvidence
from mbtrack_ros.core.detection.release import ReleaseConfig, Releaser, spare_tracks
from mbtrack_ros.core.shape import BodyShape, rasterize

from conftest import make_room

FPS = 15
SHAPE = BodyShape(1.75, 0.5)


def _states(xy) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.c_[xy, np.zeros((len(xy), 4))]


def _scene(room, people, tracks):
    """Per camera: the foreground of the people's silhouettes, the tracks' silhouettes."""
    fgs, sils = [], []
    for cam in room.cameras.values():
        bodies = rasterize(cam, _states(people), SHAPE)
        fgs.append(np.any([bodies.mask(i) > 0 for i in range(len(people))], axis=0))
        sils.append(rasterize(cam, _states(tracks), SHAPE))
    return fgs, sils


def _straightforward_support(fgs, sils, k):
    """Exclusive support of every track with per-track masks (no spans arithmetic)."""
    total, seen = np.zeros(k), np.zeros(k)
    for fg, sil in zip(fgs, sils):
        masks = np.array([sil.mask(i) > 0 for i in range(k)])
        alone = masks & (masks.sum(axis=0) == 1)[None]
        area = masks.sum(axis=(1, 2))
        sees = area >= 1
        total += np.where(sees, (alone & fg[None]).sum(axis=(1, 2)) / np.maximum(area, 1), 0)
        seen += sees
    return total / np.maximum(seen, 1)


def test_exclusive_support_equals_the_per_pixel_count():
    room = make_room(160, 120, 4)
    people = [(2.0, 2.0), (2.45, 2.2), (4.0, 3.0)]
    tracks = [(2.0, 2.05), (2.5, 2.2), (2.3, 1.9), (4.1, 3.0), (1.0, 4.0)]
    fgs, sils = _scene(room, people, tracks)
    spare, support = spare_tracks(fgs, sils, min_support=0.0)
    assert not spare.any()
    assert np.allclose(support, _straightforward_support(fgs, sils, len(tracks)))


def test_the_existence_evidence_per_camera_counts_the_pixels_no_other_kept_track_covers():
    """Releaser.exclusive_views against per-track masks: a track's exclusive pixels are
    those of its silhouette that no other track covers, a spare track not counted among
    the others; the share of the silhouette and the foreground among them."""
    room = make_room(160, 120, 4)
    people = [(2.0, 2.0), (2.45, 2.2), (4.0, 3.0)]
    tracks = [(2.0, 2.05), (2.5, 2.2), (2.3, 1.9), (4.1, 3.0), (1.0, 4.0), (2.05, 2.1)]
    fgs, sils = _scene(room, people, tracks)
    image = np.zeros((120, 160, 3), np.uint8)
    evidence = {n: FrameEvidence(image, fg) for n, fg in zip(room.cameras, fgs)}
    rel = Releaser(room, ReleaseConfig())
    rel.support(evidence, dict(zip(room.cameras, sils)))
    assert rel.spare.any() and not rel.spare.all()
    assert set(rel.exclusive_views) == set(room.cameras)
    k = len(tracks)
    for name, fg, sil in zip(room.cameras, fgs, sils):
        masks = np.array([sil.mask(i) > 0 for i in range(k)])
        share, cov = rel.exclusive_views[name]
        for i in range(k):
            others = masks[[j for j in range(k) if j != i and not rel.spare[j]]].any(axis=0)
            own = masks[i] & ~others
            area = masks[i].sum()
            if area < ReleaseConfig().min_area * 160 * 120 / (320 * 240):
                assert np.isnan(share[i]) and np.isnan(cov[i])
                continue
            assert share[i] == pytest.approx(own.sum() / area)
            if own.any():
                assert cov[i] == pytest.approx((own & fg).sum() / own.sum())
            else:
                assert np.isnan(cov[i])


def test_undecided_pixels_count_at_the_neutral_coverage_in_the_existence_evidence():
    """The background bootstrap's possible-person pixels (FrameEvidence.undecided) are
    foreground until seen without a track over them; a track standing on them keeps them
    undecided. The coverage and the exclusive views count each such pixel as f_s of a
    foreground pixel, against per-track masks; a track whose silhouette lies wholly on
    undecided foreground (the place a person stood when the tracker started) has neutral
    evidence, not the full coverage it has when they are taken for foreground."""
    room = make_room(160, 120, 4)
    people = [(2.0, 2.0), (4.0, 3.0)]
    tracks = [(2.0, 2.05), (2.3, 1.9), (4.0, 3.0)]
    fgs, sils = _scene(room, people, tracks)
    f_s = ReleaseConfig().min_coverage
    image = np.zeros((120, 160, 3), np.uint8)
    undecided = []
    for fg, sil in zip(fgs, sils):       # the third person's place, and a stripe elsewhere
        unsure = sil.mask(2) > 0
        unsure[:, 70:80] = True
        undecided.append(unsure)
    evidence = {n: FrameEvidence(image, fg, undecided=u)
                for n, fg, u in zip(room.cameras, fgs, undecided)}
    rel = Releaser(room, ReleaseConfig(spare_support=0.0))
    _, coverage = rel.support(evidence, dict(zip(room.cameras, sils)))
    least = ReleaseConfig().min_area * 160 * 120 / (320 * 240)
    k = len(tracks)
    for name, fg, sil, unsure in zip(room.cameras, fgs, sils, undecided):
        masks = np.array([sil.mask(i) > 0 for i in range(k)])
        share, cov = rel.exclusive_views[name]
        for i in range(k):
            area = masks[i].sum()
            if area < least:
                assert np.isnan(coverage[name][i]) and np.isnan(cov[i])
                continue
            counted = (masks[i] & fg & ~unsure).sum() + f_s * (masks[i] & unsure).sum()
            assert coverage[name][i] == pytest.approx(counted / area)
            own = masks[i] & ~masks[[j for j in range(k) if j != i]].any(axis=0)
            assert share[i] == pytest.approx(own.sum() / area)
            if own.any():
                counted = (own & fg & ~unsure).sum() + f_s * (own & unsure).sum()
                assert cov[i] == pytest.approx(counted / own.sum())
        assert coverage[name][2] == pytest.approx(f_s)
    plain = Releaser(room, ReleaseConfig(spare_support=0.0))
    _, taken = plain.support({n: FrameEvidence(image, fg) for n, fg in zip(room.cameras, fgs)},
                             dict(zip(room.cameras, sils)))
    assert all(cov[2] > 0.9 for cov in taken.values())


def test_a_track_in_front_of_a_tracked_person_along_a_line_of_sight_has_evidence_against_it():
    """Two cameras 90 degrees apart; a person with her track, and a second track 0.5 m
    nearer to cam0 on cam0's line of sight through her. In cam0 the second track's
    silhouette lies on her foreground, but those pixels are hers (her track explains them);
    in cam2 it stands on empty floor. The whole silhouettes' evidence sum_c (f_c - f_s)
    favours the second track; the exclusive evidence sum_c share_c (f_c - f_s) is against
    it and for her track."""
    full = make_room(160, 120, 3)
    room = RoomCalibration({n: full.cameras[n] for n in ('cam0', 'cam2')}, full.floor)
    person = np.array([3.0, 2.5])
    eye = np.array([0.1, 0.1])
    ahead = person - 0.5 * (person - eye) / np.linalg.norm(person - eye)
    fgs, sils = _scene(room, [person], [person, ahead])
    image = np.zeros((120, 160, 3), np.uint8)
    evidence = {n: FrameEvidence(image, fg) for n, fg in zip(room.cameras, fgs)}
    rel = Releaser(room, ReleaseConfig(spare_support=0.0))
    _, coverage = rel.support(evidence, dict(zip(room.cameras, sils)))
    f_s = ReleaseConfig().min_coverage
    assert sum(cov[1] - f_s for cov in coverage.values()) > 0.0
    evidence_sum = sum(np.nan_to_num(share * (cov - f_s))
                       for share, cov in rel.exclusive_views.values())
    assert evidence_sum[0] > 0.0 > evidence_sum[1]


def test_a_spare_track_beside_a_tracked_person_is_found_and_the_tracked_one_kept():
    room = make_room(160, 120, 4)
    # one person at (2.5, 2.5) with its track; a second track 0.4 m away on the same person
    fgs, sils = _scene(room, [(2.5, 2.5)], [(2.5, 2.5), (2.9, 2.5)])
    spare, support = spare_tracks(fgs, sils, min_support=0.18)
    assert spare.tolist() == [False, True]
    assert support[0] > 0.5 and support[1] < 0.18
    # two people side by side, each with its track: neither is spare
    fgs, sils = _scene(room, [(2.5, 2.5), (2.95, 2.5)], [(2.5, 2.5), (2.95, 2.5)])
    spare, support = spare_tracks(fgs, sils, min_support=0.18)
    assert not spare.any() and np.all(support > 0.18)
    # two tracks on one spot explain nothing exclusively: one of them is spare, not both
    fgs, sils = _scene(room, [(2.5, 2.5)], [(2.5, 2.5), (2.5, 2.5)])
    spare, _ = spare_tracks(fgs, sils, min_support=0.18)
    assert spare.sum() == 1
    # a track without foreground far from the others on the floor (but overlapping one in
    # some camera's image) is left to the plain support rule when a radius is given
    far = [(2.5, 2.5), (4.5, 1.0)]
    fgs, sils = _scene(room, [(2.5, 2.5)], far)
    spare, support = spare_tracks(fgs, sils, min_support=0.18, xy=np.array(far), radius=1.0)
    assert not spare.any() and support[1] == 0.0
    assert spare_tracks(fgs, sils, min_support=0.18)[0].tolist() == [False, True]


def test_the_releaser_ends_a_spare_track_after_the_timeout_only_when_enabled():
    room = make_room(160, 120, 4)
    # 0.3 m off the person: plainly supported (coverage 0.36-0.42 >= min_coverage 0.3)
    fgs, sils = _scene(room, [(2.5, 2.5)], [(2.5, 2.5), (2.8, 2.5)])
    image = np.zeros((120, 160, 3), np.uint8)
    evidence = {n: FrameEvidence(image, fg) for n, fg in zip(room.cameras, fgs)}
    silhouettes = dict(zip(room.cameras, sils))
    default = ReleaseConfig().spare_support  # on by default
    for spare_support, expected in ((default, {2: int(np.ceil(1.0 * FPS))}), (0.0, {})):
        rel = Releaser(room, ReleaseConfig(timeout=1.0, spare_support=spare_support))
        ended = {}
        for k in range(30):
            supported, _ = rel.support(evidence, silhouettes)
            for tid in rel.update(int(round(k * 1e9 / FPS)), [1, 2], supported):
                ended.setdefault(tid, k)
        assert ended == expected
        assert rel.spare.tolist() == [False, spare_support > 0]
    with pytest.raises(DetectionError):
        ReleaseConfig(spare_support=1.5)
    with pytest.raises(DetectionError):
        ReleaseConfig(spare_radius=-1.0)


def _due_releases(room, people, tracks, own_support: bool, keep: int | None = None
                  ) -> dict[int, int]:
    """Run the releaser's support and duplicate rule over 20 frames of a still scene with
    tracks 1 and 7 (7 the younger; ``keep``: a judge that keeps that one); the frame at
    which each track was released."""
    fgs, sils = _scene(room, people, tracks)
    image = np.zeros((120, 160, 3), np.uint8)
    evidence = {n: FrameEvidence(image, fg) for n, fg in zip(room.cameras, fgs)}
    rel = Releaser(room, ReleaseConfig(merge_radius=0.35, merge_time=0.5))
    ended: dict[int, int] = {}
    for k in range(20):
        rel.support(evidence, dict(zip(room.cameras, sils)), _states(tracks),
                    np.full(len(tracks), SHAPE.height))
        for tid in rel.duplicates(int(round(k * 1e9 / FPS)), [1, 7], np.array(tracks),
                                  prefer=None if keep is None else lambda a, b: keep,
                                  own_support=rel.exclusive_support if own_support else None):
            ended.setdefault(tid, k)
    return ended


def test_two_people_passing_close_are_not_duplicates_while_each_has_support_of_its_own():
    """Two tracks 0.3 m apart for longer than merge_time: on two people each keeps
    foreground of its own (exclusive support >= spare_support) and neither is released;
    on one person the younger one is, as without the support (the rule's first test)."""
    room = make_room(160, 120, 4)
    tracks = [(2.5, 2.5), (2.8, 2.5)]
    due = int(np.ceil(0.5 * FPS))
    assert _due_releases(room, tracks, tracks, own_support=True) == {}
    assert _due_releases(room, tracks, tracks, own_support=False) == {7: due}
    assert _due_releases(room, [(2.5, 2.5)], tracks, own_support=True) == {7: due}
    # two tracks on one spot: the spare search takes track 1 out first and then credits
    # track 7 with the person's pixels; the pair's support is judged with both present,
    # so the judge may release either, track 7 here as well as track 1
    on_one = [(2.5, 2.5), (2.5, 2.5)]
    for keep, gone in ((1, 7), (7, 1)):
        assert _due_releases(room, [(2.5, 2.5)], on_one, own_support=True,
                             keep=keep) == {gone: due}
    # the support the pair is judged by: every track present, none taken out as spare
    image = np.zeros((120, 160, 3), np.uint8)
    for people, expected in ((tracks, True), ([(2.5, 2.5)], False)):
        fgs, sils = _scene(room, people, tracks)
        rel = Releaser(room)
        assert rel.exclusive_support().size == 0             # before any frame
        rel.support({n: FrameEvidence(image, fg) for n, fg in zip(room.cameras, fgs)},
                    dict(zip(room.cameras, sils)), _states(tracks), np.full(2, SHAPE.height))
        assert np.allclose(rel.exclusive_support(), _straightforward_support(fgs, sils, 2))
        assert (rel.exclusive_support()[1] >= ReleaseConfig().spare_support) == expected
    with pytest.raises(DetectionError):
        rel.duplicates(0, [1, 7], np.zeros((2, 2)), own_support=[0.5])


def test_of_two_tracks_on_one_person_the_one_beside_the_person_goes_whatever_its_age():
    """A due pair on one person where the older track (1) stands 0.3 m beside the person
    and the younger one (7) on them: the younger one holds the person (exclusive support
    above spare_support), the older one explains no foreground of its own, so the older
    one is released (the rule's default, the younger one, would be kept by its support
    and the pair would stay); with the roles swapped the younger one goes, as before."""
    room = make_room(160, 120, 4)
    due = int(np.ceil(0.5 * FPS))
    person = [(2.5, 2.5)]
    beside_first = [(2.8, 2.5), (2.5, 2.5)]     # track 1 beside, track 7 on the person
    fgs, sils = _scene(room, person, beside_first)
    support = spare_tracks(fgs, sils, 0.0)[1]
    spare = ReleaseConfig().spare_support
    assert support[0] < spare <= support[1]
    assert _due_releases(room, person, beside_first, own_support=True) == {1: due}
    assert _due_releases(room, person, beside_first[::-1], own_support=True) == {7: due}
    # without the support the rule alone releases the younger one
    assert _due_releases(room, person, beside_first, own_support=False) == {7: due}


def test_the_duplicate_rule_weighs_the_support_over_the_frames_the_pair_was_close():
    """Of a due pair the track with too little exclusive support goes instead of the
    younger one only when its support was low while the two were close (the mean), not on
    the one frame it dips (a person passing behind another loses foreground for a moment)."""
    due = int(np.ceil(0.5 * FPS))
    xy = np.array([[2.0, 2.0], [2.2, 2.0]])

    def released(supports):
        rel = Releaser(make_room(), ReleaseConfig(merge_radius=0.35, merge_time=0.5))
        out = {}
        for k, own in enumerate(supports):
            for tid in rel.duplicates(int(round(k * 1e9 / FPS)), [1, 7], xy,
                                      own_support=own):
                out.setdefault(tid, k)
        return out

    held, low = [0.4, 0.4], [0.1, 0.4]
    assert released([low] * 20) == {1: due}                     # track 1 never held
    assert released([held] * due + [low] + [held] * (19 - due)) == {}   # a dip
    # low for longer than it held: its mean falls below spare_support, then it goes
    late = released([held] * due + [low] * (20 - due))
    assert list(late) == [1] and late[1] > due
    # one with the support of neither: the younger one goes, as without the support
    assert released([[0.1, 0.1]] * 20) == {7: due}
