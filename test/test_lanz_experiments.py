"""The Lanz sequences as 000 §VI-A records them: one corner camera at 200x150 pixels, and
appearance models acquired apart from tracking (key views from any frame)."""
from __future__ import annotations

import numpy as np

from mbtrack_ros.cli import main
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.initiation import PersonTruth, plan_key_views
from mbtrack_ros.synth.room import default_room, make_calibration


def test_lanz_presets_render_at_the_papers_200_by_150(tmp_path):
    out = tmp_path / 'rec'
    assert main(['synth', 'lanz-seq1-short', str(out), '--frames', '2']) == 0
    cam = RoomCalibration.load(out / 'calibration.yaml').cameras['cam0']
    assert (cam.width, cam.height) == (200, 150)
    other = tmp_path / 'rec2'
    assert main(['synth', 'lanz-seq1-short', str(other), '--frames', '1',
                 '--width', '160', '--height', '120']) == 0
    assert RoomCalibration.load(other / 'calibration.yaml').cameras['cam0'].width == 160


def _rows(pid, xy, frames):
    return [PersonTruth(frame=f, stamp_ns=f * 66_666_667, person_id=pid, x=float(x),
                        y=float(y), z_head=1.75, sitting=False)
            for f, (x, y) in zip(frames, xy)]


def test_a_person_hidden_through_the_first_frames_gets_key_views_from_later_ones():
    """Person 2 stands straight behind person 1 (seen from cam0) for the first frames, then
    steps aside: searching only the first frames finds no view of them, the fallback
    over the whole recording does, and nobody else's views change."""
    cal = make_calibration(default_room(), width=200, height=150, cameras=('cam0',))
    cam = cal.cameras['cam0']
    centre = np.array(cam.center[:2])
    ahead = np.array([2.9, 2.4]) / np.hypot(2.9, 2.4)
    side = np.array([-ahead[1], ahead[0]])
    frames = range(8)
    p1 = [centre + 1.8 * ahead] * 8
    p2 = [centre + 3.0 * ahead + (0.0 if f < 4 else 0.9) * side for f in frames]
    truth = _rows(1, p1, frames) + _rows(2, p2, frames)
    plan = plan_key_views(cal, truth, search_frames=4, max_views=2)
    assert plan[2] and all(v.frame >= 4 for v in plan[2])
    only_first = plan_key_views(cal, truth[:4] + truth[8:12], search_frames=4, max_views=2)
    assert only_first[2] == []
    assert [v.frame for v in plan[1]] == [v.frame for v in only_first[1]]


def test_experiments_render_presets_over_recording_seeds(tmp_path, capsys):
    """One command renders the recordings of a preset (several recording seeds), replays
    each run on all of them and reports the preset: one table row per run (with the frame
    rate of Table I) and one posterior-mass plot (Fig. 6) over all recordings."""
    import json

    out = tmp_path / 'exp'
    code = main(['experiments', '--presets', 'lanz-seq4-short', '--recording-seeds', '1-2',
                 '--frames', '5', '--runs', 'hjs:8,hjs-nomrf:8', '--out', str(out)])
    assert code == 0
    recs = sorted((out / 'recordings').iterdir())
    assert [r.name for r in recs] == ['lanz-seq4-short_s1', 'lanz-seq4-short_s2']
    assert RoomCalibration.load(recs[0] / 'calibration.yaml').cameras['cam0'].width == 200
    table = (out / 'results.md').read_text()
    assert '| lanz-seq4-short | hjs N=8 |' in table
    assert '| lanz-seq4-short | hjs-nomrf N=8 |' in table
    assert (out / 'posterior_lanz-seq4-short.png').stat().st_size > 0
    res = json.loads((out / 'results.json').read_text())
    assert len(res['runs']) == 4 and {r['mrf'] for r in res['runs']} == {True, False}
    assert all(s['recordings'] == [r.name for r in recs] for s in res['summary'])
    capsys.readouterr()
    assert main(['experiments', '--presets', 'lanz-seq4-short', '--recording-seeds', 'x',
                 '--out', str(out)]) == 2
    assert main(['experiments', '--presets', 'no-such', '--recording-seeds', '1',
                 '--out', str(out)]) == 2
    err = capsys.readouterr().err
    assert "bad seed 'x'" in err and 'unknown preset' in err
