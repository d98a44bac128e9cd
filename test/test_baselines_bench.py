"""The 004 baselines (pdaf, jpdaf, jlf) in `mbtrack bench` and `mbtrack experiments`."""
from __future__ import annotations

import json
import math

import pytest

from mbtrack_ros.cli import main
from mbtrack_ros.commands import bench, experiments
from mbtrack_ros.recording.csvfiles import read_tracks


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp('rec') / 'seq1'
    code = main(['synth', 'lanz-seq1-short', str(out), '--frames', '12', '--width', '160',
                 '--height', '120'])
    assert code == 0
    return out


def test_grid_has_baselines_unless_left_out():
    plain = bench._grid(True, baselines=False)
    assert not any(j['algorithm'] in bench.BASELINES for j in plain)
    jobs = bench._grid(True)
    assoc = [j for j in jobs if j['group'] == 'assoc']
    keys = {(j['algorithm'], j['k'], j['occluded']) for j in assoc}
    want = {(a, k, occ) for a in ('hjs',) + bench.BASELINES for k in bench.BASELINE_KS
            for occ in (False, True)}
    assert keys == want
    assert all(j['n'] == 100 and j['n_cameras'] == 4 and j['size'] == (320, 240) for j in assoc)


def _fake(alg, k, occ, spf):
    return bench.BenchResult(alg, k, 100, 4, 320, 240, occ, spf, 1.0 / spf, 3, 0.0, 1.0, {})


def test_report_baselines_ratio_to_hjs(capsys):
    seen = {}
    times = {'hjs': 0.02, 'pdaf': 0.01, 'jpdaf': 0.015, 'jlf': 0.08}
    for alg, t in times.items():
        for occ, factor in ((False, 1.0), (True, 3.0)):
            seen[(alg, 2, 100, 4, (320, 240), occ)] = _fake(alg, 2, occ, t * factor * (
                2.0 if alg == 'jlf' and occ else 1.0))
    summary = bench._report_baselines(seen)
    out = capsys.readouterr().out
    assert summary['pdaf_k2_spread_over_hjs'] == pytest.approx(0.5)
    assert summary['jpdaf_k2_occluded_over_hjs'] == pytest.approx(0.75)
    assert summary['jlf_k2_occluded_over_hjs'] == pytest.approx(8.0)
    assert 'k3' not in ''.join(summary)  # K = 3 was not run: no row, no ratio
    assert 'spread' in out and 'occluded' in out and '8.00x' in out
    assert bench._report_baselines({}) == {}


def test_bench_times_a_baseline_on_a_small_scene():
    r = bench.run_config('jpdaf', 2, 20, 1, (80, 60), occluded=True, frames=1, seed=1)
    assert r.algorithm == 'jpdaf' and r.people == 2
    assert math.isfinite(r.seconds_per_frame) and r.seconds_per_frame > 0


def test_experiments_side_by_side_with_baselines(recording, tmp_path, capsys):
    out = tmp_path / 'exp'
    code = main(['experiments', str(recording), '--out', str(out),
                 '--runs', 'hjs:20,pdaf:20,jlf:20', '--max-frames', '6'])
    assert code == 0
    doc = json.loads((out / 'results.json').read_text())
    algs = [r['algorithm'] for r in doc['runs']]
    assert algs == ['hjs', 'pdaf', 'jlf']
    for r in doc['runs']:
        assert r['exit_code'] == 0 and r['frames'] == 6
        assert 0.0 <= r['mota'] <= 1.0 and r['frames_per_s'] > 0
        tracks = read_tracks(out / recording.name / f'{r["algorithm"]}_20_s0' / 'tracks.csv')
        assert len({t.stamp_ns for t in tracks}) == 6
    hjs, pdaf = doc['runs'][0], doc['runs'][1]
    assert hjs['curve'] is not None and 0.0 <= hjs['mass_0_5'] <= 1.0
    assert pdaf['curve'] is None and math.isnan(pdaf['mass_0_5'])
    assert not (out / recording.name / 'pdaf_20_s0' / 'particles.npz').exists()
    table = (out / 'results.md').read_text().splitlines()
    row = next(line for line in table if 'pdaf N=20' in line)
    assert row.rstrip().endswith('| - | - |')  # no posterior mass for the baselines
    assert (out / f'posterior_{recording.name}.png').exists()  # HJS curve still plotted
    capsys.readouterr()


def test_experiments_keep_the_papers_exclusion_radius(recording, tmp_path, monkeypatch,
                                                       capsys):
    """000 §VI is reproduced with its r = 0.4 m, not the tracker's default 0.3 m."""
    from mbtrack_ros.commands import replay
    from mbtrack_ros.core.tracker import TrackerConfig

    seen = []
    original = replay._config
    monkeypatch.setattr(replay, '_config', lambda args: seen.append(original(args)) or seen[-1])
    assert main(['experiments', str(recording), '--out', str(tmp_path / 'exp'),
                 '--runs', 'hjs:20', '--max-frames', '2']) == 0
    assert [c.mrf_radius for c in seen] == [0.4] and TrackerConfig().mrf_radius == 0.3
    capsys.readouterr()


def test_experiments_take_a_node_parameter_file_under_their_own_settings(
        recording, tmp_path, monkeypatch, capsys):
    """``--params`` hands a tracker_node file to every replay (its min_visible_share and
    d_occ here); the options experiments sets itself (d_occ, the paper's radius) win; a
    bad file is one error line before any replay."""
    from mbtrack_ros.commands import replay

    params = tmp_path / 'p.yaml'
    params.write_text('tracker_node:\n  ros__parameters:\n    tracker:\n'
                      '      min_visible_share: 0.0\n      d_occ: 0.4\n')
    seen = []
    original = replay._config
    monkeypatch.setattr(replay, '_config', lambda args: seen.append(original(args)) or seen[-1])
    out = tmp_path / 'exp'
    assert main(['experiments', str(recording), '--out', str(out), '--runs', 'hjs:20',
                 '--max-frames', '2', '--params', str(params)]) == 0
    assert [(c.min_visible_share, c.d_occ, c.mrf_radius) for c in seen] == [(0.0, 0.15, 0.4)]
    assert json.loads((out / 'results.json').read_text())['runs'][0]['params'] == str(params)
    assert str(params) in (out / 'results.md').read_text()
    capsys.readouterr()
    params.write_text('tracker_node:\n  ros__parameters:\n    tracker:\n      no_such: 1\n')
    seen.clear()
    assert main(['experiments', str(recording), '--out', str(out), '--runs', 'hjs:20',
                 '--params', str(params)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'no_such' in err[0] and not seen


def test_experiments_bad_run_is_one_line_error(recording, tmp_path, capsys):
    code = main(['experiments', str(recording), '--out', str(tmp_path / 'e'),
                 '--runs', 'pdaf:many'])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('mbtrack experiments: error: ')
    assert experiments._parse_runs('pdaf:100,jlf:50') == [('pdaf', 100), ('jlf', 50)]


def test_bench_parser_baselines_default_on_and_switch_off():
    import argparse
    sub = argparse.ArgumentParser().add_subparsers()
    parser = bench.add_parser(sub)
    assert parser.parse_args(['--quick']).baselines is True
    assert parser.parse_args(['--quick', '--no-baselines']).baselines is False
