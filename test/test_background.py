"""Background model (003 §4.2): bootstrap, masked temporal filtering, foreground test."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.background import (
    BackgroundBank, BackgroundConfig, BackgroundModel, _to_ycc, clean_mask)
from mbtrack_ros.core.detection.people import PeopleCueConfig

H, W = 120, 160


def scene(rng: np.random.Generator) -> np.ndarray:
    """A smooth textured empty room image (H, W, 3) uint8."""
    base = rng.integers(50, 180, size=(6, 8, 3)).astype(np.uint8)
    return cv2.resize(base, (W, H), interpolation=cv2.INTER_CUBIC)


def scene_with_person(bg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``bg`` with a red 70 x 25 pixel "person" painted at rows 30-99, columns 60-84, and
    that region as an (H, W) bool mask."""
    person = bg.copy()
    person[30:100, 60:85] = (200, 30, 40)
    region = np.zeros((H, W), bool)
    region[30:100, 60:85] = True
    return person, region


def noisy(image: np.ndarray, rng: np.random.Generator, amp: int = 4) -> np.ndarray:
    return np.clip(image.astype(np.int16) + rng.integers(-amp, amp + 1, image.shape),
                   0, 255).astype(np.uint8)


def test_bootstrap_is_median_and_noise_is_background():
    rng = np.random.default_rng(0)
    bg = scene(rng)
    frames = [noisy(bg, rng) for _ in range(5)]
    model = BackgroundModel(BackgroundConfig(bootstrap_frames=5, bootstrap_stride=1))
    for f in frames:
        assert model.apply(f) is None          # still collecting bootstrap frames
    assert model.ready
    expected = np.median(np.stack([_to_ycc(f) for f in frames]), axis=0)
    np.testing.assert_allclose(model.background_ycc, expected, atol=1e-4)
    for _ in range(5):
        fg = model.apply(noisy(bg, rng))
        assert fg.dtype == bool and fg.shape == (H, W)
        assert fg.mean() < 0.002


def test_strided_bootstrap_removes_a_walking_person():
    rng = np.random.default_rng(6)
    bg = scene(rng)
    model = BackgroundModel(BackgroundConfig(bootstrap_frames=7, bootstrap_stride=3))
    for k in range(19):                        # a person walking across while bootstrapping
        frame = noisy(bg, rng)
        x = 5 + 7 * k
        frame[30:100, x:x + 20] = (200, 30, 40)
        assert model.apply(frame) is None
    assert model.ready
    assert model.foreground(noisy(bg, rng)).mean() < 0.002


def test_ghost_of_a_static_untracked_blob_is_absorbed():
    rng = np.random.default_rng(7)
    bg = scene(rng)
    ghost = bg.copy()
    ghost[30:100, 60:85] = (200, 30, 40)       # in the bootstrap frames, then gone
    cfg = BackgroundConfig(alpha=0.99, static_frames=10, static_alpha=0.7)
    fast, slow = BackgroundModel(cfg), BackgroundModel(
        BackgroundConfig(alpha=0.99, static_frames=0, ghost_edge_ratio=0.0))
    fast.bootstrap([ghost])
    slow.bootstrap([ghost])
    for _ in range(30):
        f = noisy(bg, rng)
        fg_fast = fast.apply(f)
        fg_slow = slow.apply(f)
    assert fg_fast[30:100, 60:85].mean() < 0.05
    assert fg_slow[30:100, 60:85].mean() > 0.9


def test_border_test_learns_a_tracked_ghost_but_keeps_a_tracked_person():
    """A blob learnt into the model and gone from the frame (its outline is in the model) is
    background within ``ghost_frames`` frames even under a track; a person standing still
    under a track (his outline is in the frame) stays foreground."""
    rng = np.random.default_rng(8)
    bg = scene(rng)
    person, region = scene_with_person(bg)
    cfg = BackgroundConfig(alpha=0.99, static_frames=0, ghost_frames=4)
    ghost, kept = BackgroundModel(cfg), BackgroundModel(cfg)
    ghost.bootstrap([person])                  # the person was there while it was learnt
    kept.bootstrap([bg])
    seen = []
    for k in range(16):
        # a track is born on the ghost a few frames after it appeared (a confirmed
        # detection); the person is tracked from the start (he walked in tracked)
        seen.append(ghost.apply(noisy(bg, rng), exclude=region if k >= 3 else None
                                )[region].mean())
        fg_kept = kept.apply(noisy(person, rng), exclude=region)
    # the revealed place moved (the frame changed there) and is tested once still: then
    # foreground until the test has held 4 frames, then learnt although a track covers it
    assert min(seen[:3]) > 0.9
    assert max(seen[12:]) < 0.05
    assert np.abs(ghost.background_ycc - _to_ycc(bg)).mean() < 3.0
    assert fg_kept[region].mean() > 0.95


def test_a_tracked_person_in_front_of_model_edges_is_no_ghost():
    """A person who walked in under his track and stands still where the model has strong
    edges of its own (a chair's outline along his border, so that the border test alone
    calls him a ghost) stays foreground: his pixels arrived under a track. The same
    foreground arrived with no track over it is learnt."""
    rng = np.random.default_rng(11)
    bg = scene(rng)
    chair = bg.copy()
    chair[28:102, 58:87] = (20, 20, 20)        # dark frame of a chair, in the model
    chair[30:100, 60:85] = bg[30:100, 60:85]
    person = chair.copy()
    person[30:100, 60:85] = (30, 28, 26)       # dark clothes: hardly a step at the frame
    region = np.zeros((H, W), bool)
    region[30:100, 60:85] = True
    cfg = BackgroundConfig(alpha=0.99, static_frames=0, ghost_frames=4)
    tracked, untracked = BackgroundModel(cfg), BackgroundModel(cfg)
    tracked.bootstrap([chair])
    untracked.bootstrap([chair])
    for _ in range(16):
        frame = noisy(person, rng)
        fg_tracked = tracked.apply(frame, exclude=region)
        fg_untracked = untracked.apply(frame)
    assert fg_tracked[region].mean() > 0.95
    assert fg_untracked[region].mean() < 0.05   # the border test alone learns it


@pytest.mark.parametrize('track_stays', [False, True])
def test_the_place_a_learnt_person_leaves_under_his_track_is_learnt_once_the_track_left(
        track_stays):
    """A person learnt into the model walks away under his own track: the place he reveals
    becomes foreground under that track. Once the track has gone with him (and even if
    another track is born on the place later) the place is a ghost and is learnt within a
    few frames; while the track stays on it (a person who came there tracked and stands
    still) it is no ghost."""
    rng = np.random.default_rng(12)
    bg = scene(rng)
    person, region = scene_with_person(bg)
    model = BackgroundModel(BackgroundConfig(alpha=0.99, static_frames=0, ghost_frames=4))
    model.bootstrap([person])
    seen = []
    for k in range(20):
        # frames 0-2: his track over the place; then gone, a new track on it from frame 8
        over = k < 3 or track_stays or k >= 8
        seen.append(model.apply(noisy(bg, rng), exclude=region if over else None)[region]
                    .mean())
    assert min(seen[:3]) > 0.9
    if track_stays:
        assert min(seen) > 0.9, seen
    else:
        assert max(seen[12:]) < 0.05, seen


def test_outline_gradients_find_a_ghost_that_touches_a_person():
    """A person learnt into the model has left (a ghost) and another stands right beside
    his place: their foreground is one component whose border holds the newcomer's outline
    in the frame, so the component test calls none of it a ghost. Cut out around the
    ghost's silhouette, the outline is in the model (sum over its border larger than in
    the frame by far); around the newcomer it is in the frame."""
    from mbtrack_ros.core.detection.background import ghost_components

    rng = np.random.default_rng(13)
    bg = scene(rng)
    learnt = bg.copy()
    learnt[30:100, 50:75] = (200, 30, 40)          # stood there while the model was learnt
    now = bg.copy()
    now[30:100, 75:100] = (40, 170, 60)            # beside the ghost, touching it
    ghost_sil = np.zeros((H, W), bool)
    ghost_sil[30:100, 50:75] = True
    person_sil = np.zeros((H, W), bool)
    person_sil[30:100, 75:100] = True
    model = BackgroundModel(BackgroundConfig(static_frames=0))
    model.bootstrap([learnt])
    frame = noisy(now, rng, amp=2)
    fg = model.foreground(frame)
    assert fg[ghost_sil].mean() > 0.9 and fg[person_sil].mean() > 0.9
    whole = ghost_components(fg, _to_ycc(frame), model.background_ycc, 1.0, luma=28.0,
                             chroma=10.0, ratio=1.5, min_area=1)
    assert not whole[ghost_sil].any()              # one component, the newcomer's outline
    g_model, g_frame, share = model.outline_gradients(frame, fg, ghost_sil, width=4)
    assert share > 0.9 and g_model > 3.0 * g_frame, (g_model, g_frame)
    g_model, g_frame, share = model.outline_gradients(frame, fg, person_sil, width=4)
    assert share > 0.9 and g_frame > 3.0 * g_model, (g_model, g_frame)
    # the learnt place goes into the model at the next update
    model.learn_next(ghost_sil)
    model.update(frame)
    assert not model.foreground(noisy(now, rng, amp=2))[ghost_sil].any()


def test_ghost_components_equals_a_loop_over_the_components():
    """The vectorised border sums equal a plain per-component computation."""
    from mbtrack_ros.core.detection.background import _colour_gradient, ghost_components

    rng = np.random.default_rng(9)
    frame, model = _to_ycc(scene(rng)), _to_ycc(scene(rng))
    fg = np.zeros((H, W), bool)
    fg[10:40, 10:30] = fg[50:90, 70:100] = fg[95:110, 120:150] = True
    fg[60:70, 80:90] = False                   # a hole
    got = ghost_components(fg, frame, model, 1.1, luma=28.0, chroma=10.0, ratio=1.0,
                           min_area=1)
    n, labels = cv2.connectedComponents(fg.astype(np.uint8), connectivity=8)
    scaled = model.copy()
    scaled[..., 0] *= 1.1
    scaled[..., 1:] = 128.0 + 1.1 * (scaled[..., 1:] - 128.0)
    gf, gm = _colour_gradient(frame, 28.0, 10.0), _colour_gradient(scaled, 28.0, 10.0)
    want = np.zeros((H, W), bool)
    excluded = np.zeros((H, W), bool)
    excluded[:, :20] = True                    # untrusted: most of the first component's border
    got_ex = ghost_components(fg, frame, model, 1.1, luma=28.0, chroma=10.0, ratio=1.0,
                              min_area=1, excluded=excluded)
    want_ex = np.zeros((H, W), bool)
    for k in range(1, n):
        comp = labels == k
        inner = comp & ~cv2.erode(comp.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        outer = cv2.dilate(comp.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & ~fg
        band = inner | outer
        want |= comp if gm[band].sum() > gf[band].sum() else False
        ok = band & ~excluded
        if 2 * ok.sum() >= band.sum() and gm[ok].sum() > gf[ok].sum():
            want_ex |= comp
    assert want.any() and (~want & fg).any()   # both outcomes occur
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(got_ex, want_ex)
    # components below min_area are never ghosts (and only the others' box is looked at)
    big = np.bincount(labels.ravel())[labels] >= 500
    got_big = ghost_components(fg, frame, model, 1.1, luma=28.0, chroma=10.0, ratio=1.0,
                               min_area=500)
    np.testing.assert_array_equal(got_big, want & big)


def test_temporal_filter_matches_formula_and_converges():
    rng = np.random.default_rng(1)
    a, b = scene(rng), scene(rng)
    cfg = BackgroundConfig(alpha=0.8, motion_threshold=255.0, mask_dilation=0)
    model = BackgroundModel(cfg)
    model.bootstrap([a])
    before = model.background_ycc.copy()
    exclude = np.zeros((H, W), bool)
    exclude[10:30, 20:50] = True
    model.update(b, exclude=exclude)
    after = model.background_ycc
    # 003 §4.2: B_t = alpha B_{t-1} + (1 - alpha) I_t on updated pixels, unchanged elsewhere
    np.testing.assert_allclose(after[~exclude], (0.8 * before + 0.2 * _to_ycc(b))[~exclude],
                               atol=1e-3)
    np.testing.assert_array_equal(after[exclude], before[exclude])
    # repeated updates converge to the new scene: error shrinks like alpha^n
    for _ in range(40):
        model.update(b)
    err = np.abs(model.background_ycc - _to_ycc(b)).max()
    assert err < 0.8 ** 40 * 255 + 1e-3
    assert model.foreground(b).mean() == 0.0


def test_tracked_person_is_not_absorbed_but_untracked_is():
    rng = np.random.default_rng(2)
    bg = scene(rng)
    person, region = scene_with_person(bg)
    cfg = BackgroundConfig(alpha=0.9)
    masked, free = BackgroundModel(cfg), BackgroundModel(cfg)
    masked.bootstrap([bg])
    free.bootstrap([bg])
    for _ in range(80):                        # a parked person, ~5 s at 15 fps
        frame = noisy(person, rng)
        fg_m = masked.apply(frame, exclude=region)
        fg_f = free.apply(frame)
    assert fg_m[region].mean() > 0.95          # still foreground while tracked
    assert fg_f[region].mean() < 0.05          # absorbed without the track mask
    assert fg_m[~region].mean() < 0.01


def test_persistent_motion_region_is_not_updated():
    rng = np.random.default_rng(3)
    bg = scene(rng)
    model = BackgroundModel(BackgroundConfig(alpha=0.5, mask_dilation=2))
    model.bootstrap([bg])
    for k in range(12):                        # a flickering rectangle
        frame = bg.copy()
        frame[20:40, 100:140] = (255, 255, 255) if k % 2 else (0, 0, 0)
        model.apply(frame)
        if k == 3:                             # motion has become persistent by now
            assert model.persistent_motion[25:35, 110:130].all()
            before = model.background_ycc.copy()
    assert model.persistent_motion[25:35, 110:130].all()
    np.testing.assert_allclose(model.background_ycc[25:35, 110:130],
                               before[25:35, 110:130])


def test_global_illumination_change_is_not_foreground():
    rng = np.random.default_rng(4)
    bg = scene(rng)
    model = BackgroundModel()
    model.bootstrap([bg])
    brighter = np.clip(bg.astype(np.float64) * 1.25, 0, 255).astype(np.uint8)
    assert model.foreground(brighter).mean() < 0.02
    assert model.gain == pytest.approx(1.25, abs=0.05)
    # without gain normalisation a 25 % change exceeds the luminance threshold
    diff = np.abs(_to_ycc(brighter)[..., 0] - _to_ycc(bg)[..., 0])
    assert (diff > model.config.luma_threshold).mean() > 0.3


def test_clean_mask_drops_small_blobs_and_keeps_large():
    m = np.zeros((H, W), bool)
    m[10:40, 10:40] = True
    m[80, 80] = True
    m[60:63, 120:123] = True
    out = clean_mask(m, open_size=3, close_size=3, min_area=20)
    assert out[15:35, 15:35].all()
    assert not out[80, 80] and not out[60:63, 120:123].any()


def test_bank_and_errors():
    rng = np.random.default_rng(5)
    bg = scene(rng)
    bank = BackgroundBank(BackgroundConfig(bootstrap_frames=2, bootstrap_stride=1))
    assert bank.apply({'a': bg, 'b': bg}) == {}
    out = bank.apply({'a': bg, 'b': bg})
    assert out == {} or set(out) == {'a', 'b'}
    out = bank.apply({'a': bg, 'b': bg})
    assert set(out) == {'a', 'b'}
    with pytest.raises(DetectionError, match='differs from the background'):
        bank.models['a'].apply(bg[:50])
    with pytest.raises(DetectionError, match='uint8 RGB'):
        bank.models['a'].apply(bg.astype(np.float32))
    with pytest.raises(DetectionError, match='exclusion mask'):
        bank.models['a'].update(bg, exclude=np.zeros((5, 5), bool))
    with pytest.raises(DetectionError, match='alpha'):
        BackgroundConfig(alpha=1.5)
    with pytest.raises(DetectionError, match='not bootstrapped'):
        BackgroundModel().foreground(bg)


def _person_scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Empty room, the same room with a person, and the person's (H, W) bool mask."""
    bg = scene(rng)
    body = np.zeros((H, W), bool)
    body[30:100, 60:85] = True
    person = bg.copy()
    person[body] = (200, 30, 40)
    return bg, person, body


def test_unknown_pixels_are_foreground_until_the_tracked_person_leaves():
    """Never-empty room: a person in every bootstrap frame is burnt into the median; his
    pixels marked not yet known are foreground while he stands there (tracked) and are
    learnt as soon as he and his track have left: no ghost."""
    rng = np.random.default_rng(8)
    bg, person, body = _person_scene(rng)
    region = np.zeros((H, W), bool)
    region[20:110, 45:100] = True
    cfg = BackgroundConfig(bootstrap_frames=3, bootstrap_stride=1, unknown_frames=4,
                           people=None)
    marked, plain = BackgroundModel(cfg), BackgroundModel(cfg)
    for _ in range(3):
        frame = noisy(person, rng)
        marked.apply(frame)
        plain.apply(frame)
    marked.set_unknown(region, foreground=body)
    for _ in range(8):                     # he stands still, a track covers him
        frame = noisy(person, rng)
        fg = marked.apply(frame, exclude=body)
        assert fg[body].mean() > 0.95                     # a possible person
        assert not fg[region & ~body].any()               # void, not foreground
        assert plain.apply(frame, exclude=body)[body].mean() < 0.01  # burnt in: invisible
    assert marked.unknown[body].all()                     # not learnt under the track
    assert marked.presence()[body].all()
    for _ in range(2):                     # he has left, and his track with him
        frame = noisy(bg, rng)
        marked.apply(frame)
        ghost = plain.apply(frame)
    assert ghost[body].mean() > 0.9                       # without marking: a ghost
    fg = marked.apply(noisy(bg, rng))
    assert fg[region].mean() < 0.01 and not marked.unknown.any()


def test_unknown_pixels_nobody_covered_are_learnt_after_the_wait():
    rng = np.random.default_rng(9)
    bg, person, body = _person_scene(rng)
    cfg = BackgroundConfig(bootstrap_frames=2, bootstrap_stride=1, unknown_frames=5,
                           people=None)
    model = BackgroundModel(cfg)
    for _ in range(2):
        model.apply(noisy(bg, rng))
    core = np.zeros((H, W), bool)
    core[30:100, 70:75] = True
    model.set_unknown(body, core=core)     # e.g. a false cue: empty floor, no track
    assert np.array_equal(model.presence(), core)         # no motion: the core only
    for k in range(5):
        fg = model.apply(noisy(bg, rng))
        assert fg[body].mean() > 0.97, k                    # possible foreground meanwhile
    fg = model.apply(noisy(bg, rng))                       # learnt with the 5th frame
    assert fg.mean() < 0.002 and not model.unknown.any()
    with pytest.raises(DetectionError, match='unknown-pixel mask'):
        model.set_unknown(np.zeros((5, 5), bool))
    with pytest.raises(DetectionError, match='unknown_frames'):
        BackgroundConfig(unknown_frames=0)
    with pytest.raises(DetectionError, match='people cue'):
        PeopleCueConfig(core_width=0.0)


def test_prepare_builds_the_people_cue_once_ahead_of_the_bootstrap(room, monkeypatch):
    """A node calls prepare() at start: the cue is built then, not again at the bootstrap."""
    import mbtrack_ros.core.detection.background as background

    built = []

    class CountingCue(background.PeopleCue):
        def __init__(self, *args, **kwargs):
            built.append(1)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(background, 'PeopleCue', CountingCue)
    bank = BackgroundBank(BackgroundConfig(bootstrap_frames=2, bootstrap_stride=1),
                          calibration=room)
    bank.prepare()
    assert len(built) == 1
    frame = np.full((room.cameras[room.names[0]].height,
                     room.cameras[room.names[0]].width, 3), 90, np.uint8)
    for _ in range(3):   # through the online bootstrap, which uses the cue
        bank.apply({n: frame for n in room.names})
    assert len(built) == 1 and all(m.ready for m in bank.models.values())
    no_cue = BackgroundBank(BackgroundConfig(people=None), calibration=room)
    no_cue.prepare()
    assert len(built) == 1


def test_deferred_update_gives_the_same_foreground_model_and_motion():
    """apply(defer=True) + update_pending() after the result equals updating in apply."""
    rng = np.random.default_rng(11)
    bg = scene(rng)
    cfg = BackgroundConfig(bootstrap_frames=3, static_frames=4)
    now, later = BackgroundBank(cfg), BackgroundBank(cfg)
    masked_later = BackgroundBank(cfg)  # exclusion handed in after the foreground
    for k in range(14):
        frame = noisy(bg, rng)
        x = 10 + 8 * k                          # a person walking, then standing still
        frame[30:100, min(x, 90):min(x, 90) + 20] = (200, 30, 40)
        exclude = np.zeros((H, W), bool)
        exclude[20:60, 100:140] = k % 3 == 0    # a track covering pixels now and then
        a = now.apply({'c': frame}, exclude={'c': exclude})
        b = later.apply({'c': frame}, exclude={'c': exclude}, defer=True)
        c = masked_later.apply({'c': frame}, defer=True)
        masked_later.exclude_pending({'c': exclude})
        assert a.keys() == b.keys() == c.keys()
        for name in a:
            np.testing.assert_array_equal(a[name], b[name])
            np.testing.assert_array_equal(a[name], c[name])
        if later.models['c'].ready and k > cfg.bootstrap_frames:
            assert later.models['c'].pending
            if k % 2:                           # else left for the next apply
                later.update_pending()
                assert not later.models['c'].pending
        m_now, m_later = now.models['c'], later.models['c']
        # reading the state runs a pending update first
        assert m_now.ready == m_later.ready
        if m_now.ready:
            np.testing.assert_array_equal(m_now.presence(), m_later.presence())
            np.testing.assert_array_equal(m_now.background_ycc, m_later.background_ycc)
            assert not m_later.pending
            m_masked = masked_later.models['c']
            np.testing.assert_array_equal(m_now.presence(), m_masked.presence())
            np.testing.assert_array_equal(m_now.background_ycc, m_masked.background_ycc)
    assert now.models['c'].ready and now.models['c'].presence().any()


def test_ycc_conversion_equals_reordered_opencv_ycrcb():
    """_to_ycc (planes reordered before the float conversion) == YCrCb -> float -> Y, Cb, Cr."""
    rng = np.random.default_rng(12)
    for shape in ((H, W, 3), (1, 1, 3), (7, 5, 3)):
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        plain = cv2.cvtColor(image, cv2.COLOR_RGB2YCrCb).astype(np.float32)[..., [0, 2, 1]]
        fast = _to_ycc(image)
        assert fast.dtype == np.float32 and fast.shape == shape
        np.testing.assert_array_equal(fast, plain)
    strided = rng.integers(0, 256, (H, 2 * W, 3), dtype=np.uint8)[:, ::2]
    np.testing.assert_array_equal(
        _to_ycc(strided),
        cv2.cvtColor(np.ascontiguousarray(strided), cv2.COLOR_RGB2YCrCb)
        .astype(np.float32)[..., [0, 2, 1]])


def test_one_dilation_gives_both_exclusion_masks():
    """_dilated_masks codes motion 1 and excluded pixels 2 and dilates once: the same
    masks as dilating motion | exclude and exclude separately (random sparse masks, with
    and without exclusion, with and without a kernel)."""
    from mbtrack_ros.core.detection.background import _dilated_masks, _kernel

    rng = np.random.default_rng(5)
    for case in range(24):
        h, w = rng.integers(5, 60, size=2)
        moving = (rng.random((h, w)) < rng.choice([0.0, 0.01, 0.1])).astype(np.uint8)
        exclude = None if case % 3 == 0 else rng.random((h, w)) < rng.choice([0.0, 0.02, 0.2])
        size = int(rng.choice([1, 3, 11]))
        k = _kernel(size)
        frozen, occupied = _dilated_masks(moving, exclude, k)
        either = moving | (np.zeros((h, w), np.uint8) if exclude is None
                           else exclude.astype(np.uint8))
        only = np.zeros((h, w), np.uint8) if exclude is None else exclude.astype(np.uint8)
        if k is not None:
            either, only = cv2.dilate(either, k), cv2.dilate(only, k)
        np.testing.assert_array_equal(frozen, either)
        np.testing.assert_array_equal(occupied, only)
        assert frozen.dtype == occupied.dtype == np.uint8


def test_foreground_kernel_equals_the_plain_colour_test():
    """_foreground_kernel (which skips the square root for pixels surely close in chroma)
    decides every pixel as the plain float64 Y-Cb-Cr test with shadows does: random
    images and backgrounds, gains, thresholds, and chroma distances on the threshold
    (3-4-5 offsets: distance exactly 5 or 10) and one step either side of it."""
    from mbtrack_ros.core.detection.background import _foreground_kernel

    def plain(ycc, bg, gain, luma, chroma, lo, hi):
        ycc, bg = ycc.astype(np.float64), bg.astype(np.float64)
        gy = gain * np.maximum(bg[..., 0], 1.0)
        d1 = ycc[..., 1] - 128.0 - gain * (bg[..., 1] - 128.0)
        d2 = ycc[..., 2] - 128.0 - gain * (bg[..., 2] - 128.0)
        dc = np.sqrt(d1 * d1 + d2 * d2)
        differs = (np.abs(ycc[..., 0] - gy) > luma) | (dc > chroma)
        r = ycc[..., 0] / gy
        shadow = (lo < hi) & (lo <= r) & (r <= hi) & (dc <= 0.5 * chroma)
        return (differs & ~shadow).astype(np.uint8)

    rng = np.random.default_rng(11)
    h, w = 40, 60
    for case in range(30):
        bg = rng.uniform(0, 255, (h, w, 3)).astype(np.float32)
        ycc = np.clip(bg + rng.normal(0, rng.choice([2.0, 8.0, 30.0]), (h, w, 3)),
                      0, 255).astype(np.float32)
        if case % 2:  # chroma offsets of exactly (3, 4) k and one float32 step around them
            k = rng.choice([1.0, 2.0], size=(h, w))
            nudge = rng.choice([-1, 0, 1], size=(h, w, 2))
            bg[..., 1:] = 128.0
            for c, base in ((1, 3.0), (2, 4.0)):
                v = (128.0 + base * k).astype(np.float32)
                ycc[..., c] = np.where(nudge[..., c - 1] < 0, np.nextafter(v, 0),
                                       np.where(nudge[..., c - 1] > 0,
                                                np.nextafter(v, 255), v))
        gain = float(rng.choice([1.0, rng.uniform(0.5, 2.0)]))
        chroma = float(rng.choice([5.0, 10.0, rng.uniform(1.0, 30.0)]))
        luma = float(rng.uniform(5.0, 40.0))
        lo, hi = (0.55, 0.92) if case % 3 else (1.0, 0.0)
        got = _foreground_kernel(ycc, bg, gain, luma, chroma, lo, hi)
        np.testing.assert_array_equal(got, plain(ycc, bg, gain, luma, chroma, lo, hi))
