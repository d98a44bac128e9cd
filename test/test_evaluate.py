"""``mbtrack evaluate``: the benchmark registry and the quick run CI makes."""
from __future__ import annotations

import json

import numpy as np
import pytest

from mbtrack_ros.cli import main
from mbtrack_ros.commands.benchmarks import BENCHMARKS, get_benchmark


def test_every_benchmark_has_unique_jobs_in_both_modes():
    names = [b.name for b in BENCHMARKS]
    assert len(names) == len(set(names))
    for bench in BENCHMARKS:
        for quick in (True, False):
            jobs = bench.jobs(quick)
            assert jobs, (bench.name, quick)
            assert all(j.benchmark == bench.name for j in jobs)
            assert len({j.name for j in jobs}) == len(jobs), bench.name
    with pytest.raises(KeyError, match='known: clear_room'):
        get_benchmark('nope')


def test_the_full_run_renders_fresh_recordings_only():
    """The published tables use recording seeds from 200, not the development seeds; the
    one exception is #51's regression suite, exactly its six recordings."""
    from mbtrack_ros.commands.benchmarks import SUITE_RECORDINGS

    for bench in BENCHMARKS:
        for job in bench.jobs(False):
            assert job.params.get('seed', 200) >= 200, (bench.name, job.name)
            if bench.name != 'clear_room_suite':
                assert 'recording_seed' not in job.params, (bench.name, job.name)
    suite = get_benchmark('clear_room_suite').jobs(False)
    assert [(j.name, j.params['recording_seed'], j.params['ceiling'], j.params['frames'])
            for j in suite] == [(name, int(name[-1]), not name.startswith('crnc'), None)
                                for name in SUITE_RECORDINGS]
    assert all(j.params['tracker_seeds'] == [0, 1, 2, 3, 4] for j in suite)


def test_quick_evaluate_writes_a_table_and_plots_per_benchmark(tmp_path, capsys):
    out = tmp_path / 'results'
    assert main(['evaluate', '--quick', '--out', str(out), '--jobs', '2']) == 0, \
        capsys.readouterr().err
    raw = json.loads((out / 'results.json').read_text())
    for bench in BENCHMARKS:
        text = (out / f'{bench.name}.md').read_text()
        assert text.startswith(f'# {bench.title}\n')
        assert f'`mbtrack evaluate --quick --only {bench.name}`' in text
        rows = [line for line in text.splitlines() if line.startswith('| ')]
        assert len(rows) >= 3, text          # header, rule, at least one result row
        plots = [line[line.index('](') + 2:-1] for line in text.splitlines()
                 if line.startswith('![')]
        assert plots and all((out / p).stat().st_size > 1000 for p in plots)
        assert len(raw[bench.name]) == len(bench.jobs(True))
    clear = raw['clear_room'][0]
    assert clear['persons'] >= 1 and 0.0 < clear['mota'] <= 1.0
    real = {r['clip']: r for r in raw['real_clip']}
    assert real['started_off']['ids'] == 1
    room = raw['rooms'][0]   # HJS and the separable filter on one recording, with IDF1
    assert 0.0 < room['idf1'] <= 1.0 and room['ghosts'] >= 0
    assert set(room['separable']) == {'mota', 'motp_mm', 'idf1', 'mismatches'}
    conditions = [row['condition'] for r in raw['real_room'] for row in r['rows']]
    assert conditions.count('none') == 1 and 'calibration error' in conditions
    curve = [(row['degrees'], row['metres']) for r in raw['real_room'] for row in r['rows']
             if row['condition'] == 'curve']
    assert sorted(curve) == [(0.0, 0.0), (0.5, 0.0)]
    table = (out / 'real_room.md').read_text()   # the calibration-error curve as a table
    assert '| 0 deg | 0 cm |' in table and '| 0.5 deg | 0 cm |' in table

    # --report-only writes the same tables from results.json; --fill quotes them in a page
    before = {b.name: (out / f'{b.name}.md').read_text() for b in BENCHMARKS}
    for b in BENCHMARKS:
        (out / f'{b.name}.md').unlink()
    page = tmp_path / 'page.md'
    page.write_text('intro\n<!-- results: clear_room -->\nold\n<!-- /results -->\n'
                    '<!-- results: rooms -->\n<!-- /results -->\nend\n')
    assert main(['evaluate', '--quick', '--report-only', '--out', str(out),
                 '--fill', str(page)]) == 0, capsys.readouterr().err
    assert {b.name: (out / f'{b.name}.md').read_text() for b in BENCHMARKS} == before
    filled = page.read_text()
    assert 'old' not in filled and filled.startswith('intro\n') and filled.endswith('end\n')
    assert '| worst: `clear-room --seed 200` |' in filled
    assert '`mbtrack evaluate --quick --only clear_room`' in filled
    # the notes under a table (the targets) come with it, the plots do not
    rooms = filled[filled.index('<!-- results: rooms -->'):]
    assert '| `clear-room` | 1 |' in rooms and '\nTargets: MOTA >= 92 %' in rooms
    assert '![' not in rooms and '`mbtrack evaluate --quick --only rooms`' in rooms


@pytest.mark.parametrize('argv,message', [
    (['--only', 'nope'], "unknown benchmark 'nope'"),
    (['--jobs', '0'], '--jobs must be at least 1'),
    (['--report-only'], 'results.json'),
])
def test_bad_options_are_one_line_errors(tmp_path, capsys, argv, message):
    assert main(['evaluate', '--out', str(tmp_path), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_list_names_every_benchmark(capsys):
    assert main(['evaluate', '--list']) == 0
    listed = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert listed == [b.name for b in BENCHMARKS]


def test_ghosts_and_people_found_at_the_start():
    from mbtrack_ros.commands.benchmarks import _found_at_start, _ghosts
    from mbtrack_ros.evaluation import clear_mot
    from mbtrack_ros.recording.csvfiles import GroundTruthRow, TrackRow

    step = 100_000_000   # 10 Hz: 40 frames = 4 s
    truth = [GroundTruthRow(f * step, f, 1, 1.0, 1.0, 1.7, False, ('cam0',))
             for f in range(40)]
    tracks = [TrackRow(f * step, f, 1, 1.1, 1.0) for f in range(40)]       # the person
    tracks += [TrackRow(f * step, f, 2, 4.0, 3.0) for f in range(5, 35)]   # 2.9 s, nobody
    tracks += [TrackRow(f * step, f, 3, 2.0, 4.0) for f in range(0, 15)]   # 1.4 s, nobody
    tracks += [TrackRow(f * step, f, 4, 1.0 + 0.2 * f, 1.0) for f in range(40)]  # passes by
    # a second person, present from the start, whose track starts 2 s late
    truth += [GroundTruthRow(f * step, f, 2, 5.0, 1.0, 1.7, False, ('cam0',))
              for f in range(40)]
    tracks += [TrackRow(f * step, f, 5, 5.0, 1.1) for f in range(20, 40)]
    result = clear_mot(tracks, truth)
    assert _ghosts(tracks, result, 2.0) == 1
    assert _ghosts(tracks, result, 1.0) == 2
    assert _found_at_start(result, 1.0) == {'start_people': 2, 'start_found': 1}
    assert _found_at_start(result, 2.5) == {'start_people': 2, 'start_found': 2}


def test_the_paired_difference_of_hjs_and_separable_is_mean_and_standard_error():
    """HJS - separable MOTA over recordings as mean ± standard error of the paired
    differences (percentage points) and the recordings on which HJS is ahead and behind:
    against scipy's standard error of the mean and a count on random results; one
    recording gives its difference alone, none a dash."""
    from scipy.stats import sem

    from mbtrack_ros.commands.benchmarks import _paired_difference

    rng = np.random.default_rng(3)
    hjs, sep = rng.uniform(0.4, 1.0, 12), rng.uniform(0.4, 1.0, 12)
    runs = [{'mota': h, 'separable': {'mota': s}} for h, s in zip(hjs, sep)]
    d = 100 * (hjs - sep)
    ahead, behind = sum(x >= 0.05 for x in d), sum(x <= -0.05 for x in d)
    assert ahead + behind == 12
    assert _paired_difference(runs) == (f'{d.mean():+.1f} ± {sem(d):.1f} (HJS ahead on '
                                        f'{ahead}, behind on {behind} of 12)')
    assert _paired_difference(runs[:1]) == f'{d[0]:+.1f}'
    assert _paired_difference([]) == '-'
