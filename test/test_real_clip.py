"""The tracker on real cameras: the pose2sim clip copied into the package (60 fps).

On shortened clips: (a) frames 45-54: a track started 42 cm away from the subject
(0.3 m in x and y) must be pulled onto him by the appearance likelihood on the real images,
and then stay within 20 cm of the reference hip midpoint, with one id; (b) frames 0-17: with
automatic detection and no initialisation the subject, who is in the room from the first
frame and never leaves it, must be detected within 15 frames (the never-empty room: the
people cue keeps him out of the bootstrap background).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from mbtrack_ros.cli import main
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection.background import BackgroundBank
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.bag import RecordingReader
from mbtrack_ros.recording.csvfiles import read_ground_truth, read_tracks, write_ground_truth

DATA = Path(__file__).resolve().parents[1] / 'mbtrack_ros' / 'data' / 'real_clip'
CAMS = ('cam01', 'cam02', 'cam03', 'cam04')
CLIP_FIRST = 45  # the copied videos are frames 45..54 of the original clip


def test_real_clip_track_converges_onto_the_subject(tmp_path, capsys):
    rec = tmp_path / 'rec'
    code = main(['import-video', str(rec), '--calibration', str(DATA / 'calibration_opencv.json'),
                 '--width', '272', '--floor=-3,-2,2,2',
                 '--reference', str(DATA / 'single_0-100.trc'),
                 '--reference-offset', str(CLIP_FIRST),
                 *[str(DATA / 'videos' / f'{c}.avi') for c in CAMS]])
    assert code == 0, capsys.readouterr().err
    truth = read_ground_truth(rec / 'ground_truth.csv')
    # the start state is displaced; the key views are still taken at the true positions
    start = [replace(r, x=r.x + 0.3, y=r.y + 0.3) if r.frame == 0 else r for r in truth]
    write_ground_truth(tmp_path / 'start.csv', start)
    out = tmp_path / 'out'
    code = main(['replay', str(rec), '--out', str(out), '--seed', '0',
                 '--init-from', str(tmp_path / 'start.csv')])
    assert code == 0, capsys.readouterr().err
    ref = {r.stamp_ns: (r.x, r.y) for r in truth}
    tracks = read_tracks(out / 'tracks.csv')
    assert {t.track_id for t in tracks} == {1}  # one id, no spurious track
    errors = np.array([np.hypot(t.x - ref[t.stamp_ns][0], t.y - ref[t.stamp_ns][1])
                       for t in tracks])
    assert len(errors) == 10
    assert errors[0] > 0.3  # it really started off the subject
    assert np.all(errors[4:] <= 0.20), errors  # pulled onto him within 4 frames (67 ms)


def _track_from_start(rec: Path, *, cue: bool) -> dict[int, list[tuple[int, float, float]]]:
    """Automatic detection over the recording: track id -> [(frame, x, y)] reported."""
    room = RoomCalibration.load(rec / 'calibration.yaml')
    tracker = Tracker(room, TrackerConfig(detection=True, seed=0),
                      rng=np.random.default_rng(0))
    if not cue:   # the same bootstrap frames, every pixel learnt (no people cue)
        cfg = replace(tracker.detection.config.background, people=None)
        tracker.detection.background = BackgroundBank(cfg, calibration=room)
    out: dict[int, list[tuple[int, float, float]]] = {}
    with RecordingReader(rec) as reader:
        for frame, fs in enumerate(reader.frames()):
            for t in tracker.step(fs.stamp_ns, fs.images).tracks:
                out.setdefault(t.track_id, []).append((frame, float(t.mean[0]),
                                                       float(t.mean[1])))
    return out


def test_real_clip_subject_detected_from_the_start_within_15_frames(tmp_path, capsys):
    rec = tmp_path / 'rec'
    code = main(['import-video', str(rec), '--calibration', str(DATA / 'calibration_opencv.json'),
                 '--width', '272', '--floor=-3,-2,2,2',
                 '--reference', str(DATA / 'single_0-100.trc'),
                 *[str(DATA / 'videos_start' / f'{c}.avi') for c in CAMS]])
    assert code == 0, capsys.readouterr().err
    ref = {r.frame: (r.x, r.y) for r in read_ground_truth(rec / 'ground_truth.csv')}
    assert len(ref) == 18
    tracks = _track_from_start(rec, cue=True)
    assert len(tracks) == 1, tracks                     # one id, nothing else
    rows = next(iter(tracks.values()))
    assert rows[0][0] < 15                              # reported within the first 15 frames
    assert [f for f, _, _ in rows] == list(range(rows[0][0], 18))   # then every frame
    errors = [np.hypot(x - ref[f][0], y - ref[f][1]) for f, x, y in rows]
    assert max(errors) <= 0.20, errors
    # the cause: without the cue he is part of the bootstrap background, nobody is found
    assert _track_from_start(rec, cue=False) == {}
