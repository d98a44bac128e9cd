"""The tracker on real cameras: the pose2sim clip copied into the package (10 frames, 60 fps).

Issue 6 on a shortened clip: a track started 42 cm away from the subject (0.3 m in x and y)
must be pulled onto him by the appearance likelihood on the real images, and then stay
within 20 cm of the reference hip midpoint, with one id. Automatic detection on this clip is
documented in docs/real_data.md (the room is never empty, so a 10-frame clip cannot
bootstrap a background model).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from mbtrack_ros.cli import main
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
