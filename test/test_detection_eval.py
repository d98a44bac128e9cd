"""The "fully visible in two cameras" clock of docs/detection_eval.py (issue #4 entering)."""
import json
import re

import numpy as np
import pytest

from conftest import load_script
from mbtrack_ros.recording.csvfiles import GroundTruthRow
from mbtrack_ros.synth.room import default_room, make_calibration


@pytest.fixture(scope='module')
def detection_eval():
    return load_script('docs/detection_eval.py', 'detection_eval')


@pytest.fixture(scope='module')
def calibration():
    return make_calibration(default_room())


def _row(frame, pid, x, y):
    return GroundTruthRow(stamp_ns=frame, frame=frame, person_id=pid, x=x, y=y, z_head=1.8,
                          sitting=False, visible_cameras=())


def _blockers(calibration, x, y, first_id):
    """People 0.6 m from (x, y) towards each corner camera: each hides the lower body."""
    out = []
    for k, name in enumerate(['cam0', 'cam1', 'cam2', 'cam3']):
        c = calibration.cameras[name].center[:2]
        d = (c - (x, y)) / np.hypot(*(c - (x, y)))
        out.append(_row(0, first_id + k, x + 0.6 * d[0], y + 0.6 * d[1]))
    return out


def test_a_person_alone_in_the_middle_is_fully_visible_in_every_camera(detection_eval,
                                                                          calibration):
    vis = detection_eval._visible_fractions(calibration, [_row(0, 1, 3.0, 2.5)], 1,
                                            whole=True)
    assert set(vis) == {'cam0', 'cam1', 'cam2', 'cam3'}   # no top view of the body model
    assert all(v >= detection_eval.FULLY_VISIBLE for v in vis.values())


def test_nearer_people_and_the_image_border_hide_part_of_the_silhouette(detection_eval,
                                                                       calibration):
    people = [_row(0, 1, 3.0, 2.5)] + _blockers(calibration, 3.0, 2.5, 2)
    vis = detection_eval._visible_fractions(calibration, people, 1, whole=True)
    assert all(vis[c] < 0.9 for c in ('cam0', 'cam1', 'cam2', 'cam3'))
    # under a corner camera the feet leave its image: hidden for `whole`, not for the
    # occlusion-only fraction (nobody in front)
    corner = calibration.cameras['cam0'].center[:2]
    near = [_row(0, 1, corner[0] + 0.5, corner[1] + 0.5)]
    assert detection_eval._visible_fractions(calibration, near, 1)['cam0'] == 1.0
    assert detection_eval._visible_fractions(calibration, near, 1, whole=True)['cam0'] < 0.9


def test_the_entering_clock_starts_when_two_cameras_see_the_whole_person(detection_eval,
                                                                         calibration):
    # frames 0-2: four people stand between person 1 and the corner cameras; from frame 3
    # on they are gone
    rows = []
    gt: dict[int, list] = {}
    for f in range(6):
        me = _row(f, 1, 3.0, 2.5)
        rows.append(me)
        others = [] if f >= 3 else [
            _row(f, b.person_id, b.x, b.y) for b in _blockers(calibration, 3.0, 2.5, 2)]
        gt[f] = [me] + others
    assert detection_eval._fully_visible_from(calibration, gt, rows) == 3
    assert detection_eval._fully_visible_from(calibration, gt, rows[:3]) is None


def test_end_class_tells_premature_from_left_and_nobody(detection_eval):
    """A track matched to person 1 in the 15 frames before its end at frame 20: premature
    when person 1 stays in the ground truth, left when they are gone; a track matched to
    no one is 'nobody'."""
    from types import SimpleNamespace

    frames = np.arange(5, 20)
    d = SimpleNamespace(track_id=np.full(15, 7), person_id=np.full(15, 1))
    stays = {(g, 1) for g in range(0, 40)}
    gone = {(g, 1) for g in range(0, 21)}
    assert detection_eval.end_class(d, frames, stays, 7, 20) == ('premature', 1)
    assert detection_eval.end_class(d, frames, gone, 7, 20) == ('left', 1)
    assert detection_eval.end_class(d, frames, stays, 8, 20) == ('nobody', -1)
    unmatched = SimpleNamespace(track_id=np.full(15, 7), person_id=np.full(15, -1))
    assert detection_eval.end_class(unmatched, frames, stays, 7, 20) == ('nobody', -1)


def test_run_takes_scalar_detection_fields_and_refuses_others(detection_eval, monkeypatch,
                                                               tmp_path):
    """``run --detection FIELD=VALUE`` hands scalar AutoDetectionConfig fields to run();
    an unknown field or a nested config is a usage error (exit 2) before any tracking."""
    seen = {}
    monkeypatch.setattr(detection_eval, 'run', lambda *a: seen.setdefault('args', a))
    argv = ['run', str(tmp_path / 'rec'), str(tmp_path / 'out')]
    detection_eval.main(argv + ['--detection', 'beside_support=0.25',
                                '--detection', 'exit_rescue=0.5', '--frames', '30'])
    assert seen['args'][-2:] == ({'beside_support': 0.25, 'exit_rescue': 0.5}, 30)
    # a switch (bool field) takes 0 or 1 and reaches run() as a bool
    seen.clear()
    detection_eval.main(argv + ['--detection', 'duplicate_own_support=0'])
    assert seen['args'][-2] == {'duplicate_own_support': False}
    for bad in ('no_such_field=1', 'background=1', 'beside_support=high',
                'duplicate_own_support=0.5'):
        with pytest.raises(SystemExit) as err:
            detection_eval.main(argv + ['--detection', bad])
        assert err.value.code == 2
    # --release takes the scalar ReleaseConfig fields the same way (the spare-track
    # recovery rule off: recover_time=0; the ceiling camera off: use_ceiling=0; min_area
    # a whole number) and refuses the others
    seen.clear()
    detection_eval.main(argv + ['--release', 'recover_time=0', '--release', 'use_ceiling=0',
                                '--release', 'min_area=40'])
    assert seen['args'][4] == {'recover_time': 0.0, 'use_ceiling': False, 'min_area': 40}
    assert type(seen['args'][4]['min_area']) is int
    for bad in ('no_such_field=1', 'use_ceiling=0.5', 'min_area=2.5', 'timeout=soon'):
        with pytest.raises(SystemExit) as err:
            detection_eval.main(argv + ['--release', bad])
        assert err.value.code == 2


def test_suite_recording_names_map_to_synth_arguments(detection_eval):
    assert detection_eval.synth_args('cr3') == ['clear-room', '--seed', '3']
    assert detection_eval.synth_args('crnc12') == ['clear-room', '--seed', '12',
                                                   '--no-ceiling']
    for bad in ('cr', 'crx1', 'lanz1', 'cr1 '):
        with pytest.raises(ValueError, match='crS or crncS'):
            detection_eval.synth_args(bad)


def test_suite_renders_runs_scores_and_resumes(detection_eval, tmp_path, capsys):
    """A one-recording suite on a 30-frame clear-room render: the scores it writes are
    those of the run's own tracks.csv, the PNG is written, and a second call keeps the run
    (same tracks.csv file, not run again)."""
    out = tmp_path / 'suite'
    assert detection_eval.main(['suite', str(out), '--seeds', '0', '--recordings', 'crnc1',
                                '--frames', '30', '--jobs', '1']) == 0
    run_dir, rec = out / 'runs' / 'crnc1_s0', out / 'rec' / 'crnc1'
    assert (rec / 'ground_truth.csv').exists() and (run_dir / 'tracks.csv').exists()
    scores = json.loads((out / 'scores.json').read_text())['runs']
    direct = detection_eval._analyse(run_dir, rec)['result']
    assert [(s['recording'], s['seed']) for s in scores] == [('crnc1', 0)]
    assert scores[0]['mota'] == pytest.approx(direct.mota)
    assert scores[0]['mismatches'] == direct.mismatches and scores[0]['people'] > 0
    assert '| crnc1_s0 |' in (out / 'table.md').read_text()
    # the posterior visibility per camera of every reported track row
    vis = (run_dir / 'visibility.csv').read_text().splitlines()
    assert vis[0] == 'frame,track_id,camera,visibility'
    rows = {(int(f), int(t)) for f, t in (line.split(',')[:2] for line in vis[1:])}
    shown = {tuple(map(int, line.split(',')[1:3])) for line in
             (run_dir / 'tracks.csv').read_text().splitlines()[1:]}
    assert rows and rows <= shown
    assert all(0.0 <= float(line.split(',')[3]) <= 1.0 for line in vis[1:])
    assert (out / 'scores.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    first = capsys.readouterr().out
    assert '[1/1] crnc1 seed 0: ran' in first and 'targets: MOTA >= 85 %' in first
    # 'visibility' counts xi_v >= 0.5 per class: all 1 -> 100 %, all 0 -> 0 %, same pairs
    shares = {}
    for value in ('1.0', '0.0'):
        (run_dir / 'visibility.csv').write_text('\n'.join(
            [vis[0]] + [line.rsplit(',', 1)[0] + ',' + value for line in vis[1:]]) + '\n')
        detection_eval.visibility([(run_dir, rec)], every=1)
        last = capsys.readouterr().out.splitlines()[-1]
        shares[value] = re.findall(r'(\w+(?: sitting)?): (\d+) pairs, xi_v >= 0.5 in (\d+) %',
                                   last)
    assert shares['1.0'] and {s for *_, s in shares['1.0']} == {'100'}
    assert {s for *_, s in shares['0.0']} == {'0'}
    assert [c[:2] for c in shares['1.0']] == [c[:2] for c in shares['0.0']]
    (run_dir / 'visibility.csv').write_text('\n'.join(vis) + '\n')
    # 'decisions' names each drop by the track it concerned, young_look_alike's too, and
    # counts move_again_gain's and reuse_doubtful's moves apart
    events = (run_dir / 'events.json').read_text()
    tid = next(iter(shown))[1]
    young = {'kind': 'decision', 'frame': 20, 'xy': [3.0, 2.5], 'score': 4.0,
             'near': [[tid, 0.6, -1.0, 0.5]], 'action': f'drop (young look-alike {tid})'}
    again = dict(young, frame=21, near=[[tid, 0.6, 5.0, 0.3]], action=f'move {tid} (again)')
    doubtful = dict(young, frame=22, near=[], action=f'move {tid} (doubtful, far)',
                    far=[tid, 1.05, 0.365, 0.609])
    (run_dir / 'events.json').write_text(json.dumps(json.loads(events)
                                                    + [young, again, doubtful]))
    detection_eval.decisions([(run_dir, rec)])
    printed = capsys.readouterr().out
    assert re.search(r'^all .*drop young (same|other|unmatched): 1\b', printed, re.M)
    assert re.search(r'^all .*move again (same|other|unmatched): 1\b', printed, re.M)
    assert re.search(r'^all .*move doubtful (same|other|unmatched): 1\b', printed, re.M)
    assert re.search(rf'frame 22: move {tid} \(doubtful, far\), score 4.00, 1.05 m, '
                     r'appearance distance 0.365, existence 0.609$', printed, re.M)
    (run_dir / 'events.json').write_text(events)
    stamp = (run_dir / 'tracks.csv').stat().st_mtime_ns
    assert detection_eval.main(['suite', str(out), '--seeds', '0', '--recordings', 'crnc1',
                                '--jobs', '1']) == 0
    assert '[1/1] crnc1 seed 0: kept' in capsys.readouterr().out
    assert (run_dir / 'tracks.csv').stat().st_mtime_ns == stamp
    # run --frames N: the first N frame sets of the same run (the tracker is causal)
    detection_eval.main(['run', str(rec), str(tmp_path / 'short'), '--frames', '12'])
    full = (run_dir / 'tracks.csv').read_text().splitlines()
    short = (tmp_path / 'short' / 'tracks.csv').read_text().splitlines()
    assert short == [line for line in full if line == full[0] or int(line.split(',')[1]) < 12]
    assert len(short) > 1 and 'MOTA' in capsys.readouterr().out


def test_suite_refuses_bad_recordings_and_run_options_before_rendering(detection_eval,
                                                                       tmp_path):
    for extra in (['--recordings', 'cr1', 'hall2'], ['--detection', 'no_such_field=1'],
                  ['--no-such-option']):
        with pytest.raises(SystemExit) as err:
            detection_eval.main(['suite', str(tmp_path / 'o'), *extra])
        assert err.value.code == 2
    assert not (tmp_path / 'o').exists()


def test_analysis_of_a_directory_without_a_run_is_a_one_line_error(detection_eval, tmp_path,
                                                                    capsys):
    """``classes`` and ``report`` given a suite's OUT instead of OUT/runs/RUN exit 1 with
    one line naming the missing file (was a traceback)."""
    rec = tmp_path / 'rec'
    rec.mkdir()
    assert detection_eval.main(['classes', str(tmp_path), str(rec)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'tracks.csv' in err and err.startswith(
        'detection_eval classes:')
    assert detection_eval.main(['report', str(tmp_path), str(rec)]) == 1
    assert 'tracks.csv' in capsys.readouterr().err
