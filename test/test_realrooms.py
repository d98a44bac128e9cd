"""Real-room conditions: free-running cameras end to end (synth -> bag -> frame sets ->
per-camera capture times in the likelihood), illumination normalisation."""
from __future__ import annotations

import numpy as np
import pytest

from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.core.likelihood import LikelihoodConfig, LikelihoodError, MeasurementModel
from mbtrack_ros.core.state import THETA, VX, VY, X, Y
from mbtrack_ros.synth.conditions import Conditions
from mbtrack_ros.synth.generator import Synthesizer, generate


def _cameras():
    cams = {}
    for name, eye in (('a', (3.0, 0.0, 2.5)), ('b', (0.0, 3.0, 2.5))):
        R, t = look_at(eye, (0.0, 0.0, 0.9))
        cams[name] = Camera(name, 40, 30, [[50.0, 0, 19.5], [0, 50.0, 14.5], [0, 0, 1]],
                            np.zeros(5), R, t)
    return RoomCalibration(cams, (-3.0, -3.0, 3.0, 3.0))


def test_capture_offsets_evaluate_each_camera_at_its_capture_time():
    """Brute force: with camera b's image taken dt before the particles' time, the HJS
    log-likelihood equals camera a's at the particles plus camera b's at the particles
    moved by v dt."""
    from test_likelihood import _random_image, _random_model  # noqa: PLC0415

    rng = np.random.default_rng(5)
    room = _cameras()
    images = {n: _random_image(rng, 30, 40) for n in room.cameras}
    models = [_random_model(rng, 1.7), _random_model(rng, 1.6)]
    parts = []
    for centre in ((0.3, 0.2), (-0.4, -0.3)):
        p = np.zeros((12, 6))
        p[:, X] = centre[0] + rng.uniform(-0.2, 0.2, 12)
        p[:, Y] = centre[1] + rng.uniform(-0.2, 0.2, 12)
        p[:, VX], p[:, VY] = rng.uniform(-1.5, 1.5, (2, 12))
        p[:, THETA] = rng.uniform(-np.pi, np.pi, 12)
        parts.append(p)
    prior = [np.full(12, 1 / 12)] * 2
    dt = -0.05
    mm = MeasurementModel(room, LikelihoodConfig(threads=1))
    mm.set_images(images)
    mm.set_capture_offsets({'b': dt})
    got = mm.hjs(parts, prior, models).loglik

    def one(name, particles):
        single = MeasurementModel(room.subset([name]), LikelihoodConfig(threads=1))
        single.set_images({name: images[name]})
        return single.hjs(particles, prior, models).loglik

    moved = [p.copy() for p in parts]
    for p, q in zip(moved, parts):
        p[:, X:Y + 1] += q[:, VX:VY + 1] * dt
    want = [la + lb for la, lb in zip(one('a', parts), one('b', moved))]
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, atol=1e-9)
    # set_images clears the offsets; a bad camera or value is refused
    mm.set_images(images)
    plain = mm.hjs(parts, prior, models).loglik
    np.testing.assert_allclose(plain[0], (np.array(one('a', parts)) + one('b', parts))[0])
    with pytest.raises(LikelihoodError, match='unknown camera'):
        mm.set_capture_offsets({'z': 0.1})
    with pytest.raises(LikelihoodError, match='finite'):
        mm.set_capture_offsets({'a': float('nan')})


def test_free_running_synth_recording_groups_into_complete_sets(tmp_path):
    """Capture times spread over a whole frame period: the recording's own stamps, and the
    replay reader makes one complete set per frame whose stamp is the latest capture (the
    ground-truth time)."""
    from mbtrack_ros.recording.bag import RecordingReader

    out = generate('clear-room-short', tmp_path / 'rec', seed=3, frames=8, width=80,
                   height=60, conditions=Conditions(capture_spread=1.0))
    synth = Synthesizer('clear-room-short', seed=3, frames=1, width=80, height=60,
                        conditions=Conditions(capture_spread=1.0))
    leads = sorted(synth.capture_leads_ns.values())
    assert leads[0] == 0 and leads[-1] > 0.7 * synth.period_ns
    with RecordingReader(out) as reader:
        sets = list(reader.frames())
        truth = sorted({r.stamp_ns for r in reader.ground_truth()})
    assert len(sets) == 8 and all(not fs.missing for fs in sets)
    assert [fs.stamp_ns for fs in sets] == truth
    for fs in sets:
        assert {fs.stamp_ns - s for s in fs.stamps.values()} == set(leads)
    # with the old fixed 10 ms grouping, no set would have been complete
    with RecordingReader(out, tolerance_ns=5_000_000) as reader:
        assert all(fs.missing for fs in reader.frames())


def test_conditions_leave_the_recording_otherwise_unchanged():
    """A condition draws from its own stream: the same people and noise without it."""
    plain = list(Synthesizer('clear-room-short', seed=4, frames=3, width=80, height=60))
    spread = list(Synthesizer('clear-room-short', seed=4, frames=3, width=80, height=60,
                              conditions=Conditions(capture_spread=0.5)))
    assert [r.x for r in plain[-1].ground_truth] == [r.x for r in spread[-1].ground_truth]
    # frame 0 has no motion to interpolate: identical images
    for name in plain[0].images:
        assert np.array_equal(plain[0].images[name], spread[0].images[name])
    with pytest.raises(Exception, match='capture spread'):
        Conditions(capture_spread=2.0)


def test_colour_gains_recover_a_light_change_despite_people():
    """Brute force: an image that is the background times known channel gains, with a
    third of its pixels replaced by 'people' (random colours), gives those gains back."""
    from mbtrack_ros.core.detection.illumination import _divide, colour_gains

    rng = np.random.default_rng(8)
    bg = rng.uniform(30, 200, (60, 80, 3))
    for gains in ([0.6, 0.6, 0.6], [1.4, 1.4, 1.4], [1.05, 0.97, 0.8]):
        image = np.clip(bg * gains + rng.normal(0, 2.0, bg.shape), 0, 255)
        people = rng.random((60, 80)) < 0.33
        image[people] = rng.uniform(0, 255, (people.sum(), 3))
        got = colour_gains(image.astype(np.uint8), bg)
        np.testing.assert_allclose(got, gains, atol=0.02)
        flat = _divide(np.full((2, 2, 3), 120, np.uint8), np.asarray(gains))
        np.testing.assert_array_equal(flat[0, 0], np.clip(np.rint(120 / np.asarray(gains)),
                                                          0, 255))
    # too few usable samples (all dark): no change
    np.testing.assert_array_equal(colour_gains(np.zeros((4, 4, 3)), np.zeros((4, 4, 3))),
                                  np.ones(3))


def test_light_switch_creates_no_track_and_keeps_the_tracks():
    """Lights down by 40 % in one frame, later a warmer white: automatic detection starts
    the same tracks as without the change and none is lost or added."""
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig

    def run(conditions):
        synth = Synthesizer('clear-room-short', seed=1, frames=60, conditions=conditions)
        tracker = Tracker(synth.calibration, TrackerConfig(detection=True, particles=40,
                                                           seed=1))
        counts, born = [], set()
        for frame in synth:
            result = tracker.step(frame.stamp_ns, frame.images)
            counts.append(len(result.tracks))
            born |= {t.track_id for t in result.tracks}
        return counts, born, len(frame.ground_truth)

    plain, plain_born, people = run(Conditions())
    switched, switched_born, _ = run(Conditions(light_changes=(
        (1.5, (0.6, 0.6, 0.6), 0.0), (2.5, (1.05, 0.97, 0.8), 0.0))))
    assert plain[-1] == people
    assert len(switched_born) == len(plain_born)      # no false birth
    assert switched[20:] == plain[20:]                # the tracks survive the switches


def test_shadow_model_brightness_chromaticity_and_texture():
    """Horprasert distortions against brute force; a scaled copy of a textured reference is
    shadow, a darker patch of another texture or colour is not; shadow pixels are not
    foreground of the background model."""
    from mbtrack_ros.core.detection.background import BackgroundConfig, BackgroundModel
    from mbtrack_ros.core.detection.shadow import _distortions, shadow_change, shadow_mask

    rng = np.random.default_rng(9)
    ref = rng.uniform(40, 220, (48, 64, 3))
    img = rng.uniform(0, 255, (48, 64, 3))
    alpha, cd, _ = _distortions(img, ref)
    for (i, j) in [(0, 0), (10, 20), (47, 63)]:
        a = img[i, j] @ ref[i, j] / (ref[i, j] @ ref[i, j])
        assert alpha[i, j] == pytest.approx(a, rel=1e-5)
        assert cd[i, j] == pytest.approx(np.linalg.norm(img[i, j] - a * ref[i, j])
                                         / np.linalg.norm(ref[i, j]), rel=1e-4)
    # a textured floor: blocks of grey with a tint
    tex = np.repeat(np.repeat(rng.uniform(60, 200, (12, 16)), 4, 0), 4, 1)
    floor = np.stack([tex, tex * 0.95, tex * 0.85], axis=2).astype(np.uint8)
    shadowed = floor.copy()
    shadowed[10:30, 10:40] = (floor[10:30, 10:40] * 0.65).astype(np.uint8)
    other = floor.copy()                          # a dark person: other texture, colour
    other[10:30, 10:40] = rng.uniform(20, 60, (20, 30, 3)).astype(np.uint8)
    inner = (slice(13, 27), slice(13, 37))
    assert shadow_mask(shadowed, floor)[inner].mean() > 0.95
    assert shadow_mask(other, floor)[inner].mean() < 0.05
    assert not shadow_mask(floor, floor).any()    # unchanged: alpha 1 is no shadow
    assert shadow_change(floor, shadowed)[inner].mean() > 0.95
    assert shadow_change(shadowed, floor)[inner].mean() > 0.95
    model = BackgroundModel(BackgroundConfig(people=None))
    model.bootstrap([floor] * 3)
    fg_shadow = model.foreground(shadowed)
    fg_person = model.foreground(other)
    assert fg_shadow[inner].mean() < 0.05 and fg_person[inner].mean() > 0.95


def test_shadow_change_tests_the_direction_of_the_change():
    """A change towards black along the reference's colour is a shadow arriving or leaving,
    however little of the pixel it covers (a penumbra: lit and shadowed mixed); a cream wall
    partly covered by a blue body is not, at any coverage, though at a partial one its
    chromaticity distortion is as small as a shadow's (brute force against the angle of
    ``I - E`` to ``-E``)."""
    from mbtrack_ros.core.detection.shadow import ShadowConfig, shadow_change

    cfg = ShadowConfig()
    wall = np.array([226.0, 228.0, 194.0])          # a cream wall
    body = np.array([90.0, 110.0, 160.0])           # blue clothes
    cover = np.linspace(0.1, 1.0, 19)
    for darkening in (0.35, 0.55):                  # a shadow of 65 % and 45 % brightness
        lit = np.tile(wall, (1, cover.size, 1))
        pen = (wall * (1 - cover[:, None] * darkening))[None]
        changed = shadow_change(lit, pen)
        assert changed[0, (1 - cover * darkening) <= cfg.brightness[1]].all()
        assert shadow_change(pen, lit).tolist() == changed.tolist()   # leaving, too
    mixed = (wall * (1 - cover[:, None]) + body * cover[:, None])[None]
    lit = np.tile(wall, (1, cover.size, 1))
    got = shadow_change(lit, mixed)[0]
    for k, f in enumerate(cover):                   # brute force on the change direction
        d = mixed[0, k] - wall
        tan = np.linalg.norm(np.cross(d, wall)) / max(-d @ wall, 1e-9) if d @ wall < 0 \
            else np.inf
        alpha = mixed[0, k] @ wall / (wall @ wall)
        want = cfg.brightness[0] <= alpha <= cfg.brightness[1] and tan <= cfg.change_angle
        assert got[k] == want, (f, tan, alpha)
    assert not got.any()
    # a bound on the chromaticity distortion alone takes some coverages for a light shadow
    cd = np.linalg.norm(mixed[0] - (mixed[0] @ wall / (wall @ wall))[:, None] * wall, axis=1) \
        / np.linalg.norm(wall)
    alpha = mixed[0] @ wall / (wall @ wall)
    assert ((cd <= cfg.chromaticity) & (alpha >= cfg.brightness[0])
            & (alpha <= cfg.brightness[1])).any()


def test_moving_shadows_are_no_person_at_the_bootstrap():
    """Ceiling lamps: the multi-view person cue of the never-empty room takes no place where
    nobody stands (a moving shadow's change is not a person's motion)."""
    from mbtrack_ros.core.detection.people import PeopleCue, PeopleCueConfig

    synth = Synthesizer('clear-room-short', seed=104, frames=6,
                        conditions=Conditions(lamps=2))
    frames = list(synth)
    people = np.array([[r.x, r.y] for r in frames[-1].ground_truth])
    places = PeopleCue(synth.calibration, PeopleCueConfig()).places(
        [f.images for f in frames])
    assert len(places) >= 1
    for p in places:
        assert np.min(np.linalg.norm(people - p, axis=1)) < 0.5, p


def test_debug_image_paints_shadow_pixels_in_their_own_colour():
    pytest.importorskip('rclpy')
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig
    from mbtrack_ros.nodes.debug import shadow_layer
    from mbtrack_ros.nodes.messages import SHADOW_COLOUR, debug_overlay

    rgb = np.full((60, 80, 3), 100, np.uint8)
    shadows = np.zeros((30, 40), bool)
    shadows[5:10, 5:10] = True                  # half size: resized to the image
    out = debug_overlay(rgb, shadows=shadows)
    assert tuple(out[15, 15]) != (100, 100, 100) and tuple(out[40, 60]) == (100, 100, 100)
    assert np.argmax(out[15, 15]) == int(np.argmax(SHADOW_COLOUR))
    # the layer of a tracker: shadows on its learnt background, None before it is learnt
    synth = Synthesizer('clear-room-short', seed=104, frames=10, conditions=Conditions(lamps=2))
    tracker = Tracker(synth.calibration, TrackerConfig(detection=True, particles=20, seed=0))
    frames = list(synth)
    assert shadow_layer(tracker, 'cam0', frames[0].images['cam0']) is None
    for f in frames:
        tracker.step(f.stamp_ns, f.images)
    layer = shadow_layer(tracker, 'cam0', frames[-1].images['cam0'])
    assert layer is not None and layer.shape == (240, 320)
    assert not np.any(layer & (frames[-1].id_buffers['cam0'] > 0)) or \
        np.mean(layer[frames[-1].id_buffers['cam0'] > 0]) < 0.2   # people are no shadow
