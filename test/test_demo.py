"""mbtrack demo end to end (offline mode: same tracker, no DDS, so it stays fast)."""
from __future__ import annotations

import json

from mbtrack_ros.cli import main


def test_demo_offline_writes_scores_and_pictures(tmp_path, capsys):
    out = tmp_path / 'demo'
    code = main(['demo', '--offline', '--init-from-ground-truth', '--frames', '30',
                 '--out', str(out)])
    assert code == 0
    for name in ('views.png', 'trajectories.png', 'error.png', 'scores.md', 'scores.json',
                 'tracks.csv', 'recording/bag/metadata.yaml'):
        assert (out / name).exists(), name
    seq = json.loads((out / 'scores.json').read_text())['sequences'][0]
    # two people standing in view, tracks started from ground truth: tracked all along
    assert seq['gt_objects'] == 60 and seq['mota'] >= 0.9 and seq['motp_mm'] < 150
    assert 'MOTA' in capsys.readouterr().out
    # a second run reuses the recording instead of generating it again
    assert main(['demo', '--offline', '--init-from-ground-truth', '--frames', '30',
                 '--out', str(out)]) == 0
    assert 'reusing the recording' in capsys.readouterr().err


def test_demo_rejects_bad_arguments(tmp_path, capsys):
    assert main(['demo', '--frames', '0', '--out', str(tmp_path)]) == 2
    assert capsys.readouterr().err.count('\n') == 1
