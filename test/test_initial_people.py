"""The people present when the background is bootstrapped are initialised together, on the
first frame set with foreground, from the bootstrap's people cue (one step over its places)
rather than confirmed one by one over ``confirm_frames`` frames by the detector."""
from __future__ import annotations

import numpy as np

from mbtrack_ros.core.detection.config import AutoDetectionConfig
from mbtrack_ros.core.detection.manager import AutoDetection
from mbtrack_ros.synth.generator import Synthesizer


def _births_by_frame(config: AutoDetectionConfig | None = None, *, frames: int = 9
                     ) -> tuple[dict[int, np.ndarray], np.ndarray, int]:
    """Births (K, 2) per frame index of an AutoDetection given no tracks, over the first
    frames of ``mbtrack synth occupied --seed 101`` (four people standing in the room, all
    of them moving a little during the bootstrap); the people's places at the last frame;
    the bootstrap length."""
    synth = Synthesizer('occupied', seed=101, frames=frames)
    auto = AutoDetection(synth.calibration, config)
    out, truth = {}, None
    for frame in synth:
        _, births = auto.step(frame.stamp_ns, frame.images, [], {})
        if births:
            out[frame.index] = np.array([b.state[:2] for b in births])
        truth = np.array([[g.x, g.y] for g in frame.ground_truth])
    return out, truth, auto.config.background.bootstrap_frames


def test_everybody_present_is_born_on_the_first_frame_with_foreground():
    births, truth, boot = _births_by_frame()
    assert len(truth) == 4
    first = boot            # frames 0..boot-1 bootstrap the model; foreground from frame boot
    assert min(births) == first
    found = births[first]
    assert len(found) == len(truth)
    # one birth per person, each on its person
    d = np.linalg.norm(found[:, None] - truth[None], axis=2)
    assert (d.min(axis=0) < 0.35).all() and (d.min(axis=1) < 0.35).all()


def test_without_the_joint_step_the_detector_confirms_them_frames_later(monkeypatch):
    """The same frames with the cue's places never handed to the detection (the not-yet-
    known regions still marked): the detector's confirmation over ``confirm_frames``
    frames finds the people ``confirm_frames - 1`` frames later, at most
    ``max_candidates`` a frame."""
    from mbtrack_ros.core.detection.background import BootstrapCue

    monkeypatch.setattr(BootstrapCue, 'take_places', lambda self: None)
    births, _, boot = _births_by_frame(frames=10)
    cfg = AutoDetectionConfig().detector
    assert min(births) == boot + cfg.confirm_frames - 1
    assert len(births[min(births)]) <= cfg.max_candidates


def test_places_of_cameras_started_apart_are_kept_once_until_taken():
    """Cameras whose models start on different frame sets each ask the cue; the places it
    gives are kept once (a place within ``nms_radius`` of a kept one is the same person)
    and handed out once."""
    from conftest import make_room
    from mbtrack_ros.core.detection.background import BackgroundConfig, BootstrapCue

    class _Cue:
        config = BackgroundConfig().people
        answers = [np.array([[1.0, 1.0], [3.0, 2.0]]), np.array([[3.2, 2.1], [5.0, 4.0]])]

        def places(self, frames):
            return self.answers.pop(0)

        def regions(self, frames, *, places):
            return {'cam0': places, 'cam1': places}

    cue = BootstrapCue(make_room(), BackgroundConfig())
    cue._cue = _Cue()
    cue.frames = [{}]
    assert cue.take_places() is None
    assert set(cue.regions(['cam0'])) == {'cam0'}
    cue.regions(['cam1'])
    np.testing.assert_allclose(cue.take_places(), [[1.0, 1.0], [3.0, 2.0], [5.0, 4.0]])
    assert cue.take_places() is None


def test_the_existence_evidence_counts_the_bootstrap_possible_people_as_undecided(monkeypatch):
    """While the people present at the start are tracked, their places are still the
    bootstrap's possible foreground (not yet seen without a track over them): the frame
    evidence the release and existence weigh carries exactly those pixels as undecided
    (FrameEvidence.undecided, counted at the neutral coverage), not as foreground."""
    from mbtrack_ros.core.detection.release import Releaser
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig

    synth = Synthesizer('occupied', seed=101, frames=12)
    tracker = Tracker(synth.calibration, TrackerConfig(detection=True, particles=50, seed=1),
                      rng=np.random.default_rng(1))
    seen = []
    support = Releaser.support

    def recording(self, evidence, *args, **kwargs):
        for name, ev in evidence.items():
            expected = tracker.detection.background.model(name).possible_foreground_as_tested
            seen.append((ev.undecided, expected))
        return support(self, evidence, *args, **kwargs)

    monkeypatch.setattr(Releaser, 'support', recording)
    for frame in synth:
        tracker.step(frame.stamp_ns, frame.images)
    assert seen and any(undecided is not None for undecided, _ in seen)
    for undecided, expected in seen:
        if undecided is None:
            assert not expected.any()
        else:
            assert np.array_equal(undecided, expected)
