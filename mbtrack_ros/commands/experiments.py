"""``mbtrack experiments``: the HJS / separable / joint comparison of 000 §VI on recordings.

For every recording directory (made by ``mbtrack synth``) and every run ``ALG:N`` the
recording is replayed (``mbtrack replay --init-from ground_truth.csv --save-particles``),
scored with CLEAR MOT and the posterior-mass curve (000 Fig. 6), and the curves of each
recording are plotted into one PNG. ``--presets lanz-seq1,lanz-seq4 --recording-seeds
200-204`` renders the recordings itself (into ``OUTDIR/recordings``, reused when present)
and reports each preset over all its recordings and run seeds: one curve per preset (Fig.
6) and one table row per preset and run with its frame rate (Table I). The run
``hjs-nomrf:N`` is HJS without the spatial-exclusion MRF (the ablation of 000 §VI-C);
``--ablation`` runs it against HJS on one recording over several seeds. Results go to
``OUTDIR/results.md`` and ``OUTDIR/results.json``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ['add_parser', 'run']

_PROG = 'mbtrack experiments'
# 004 baselines (Kalman-filter based): they report no particles, so no posterior-mass curve
_NO_PARTICLES = frozenset({'pdaf', 'jpdaf', 'jlf'})
PAPER_MRF_RADIUS = 0.4   # 000 §VI-A; the tracker's default is 0.3 (TrackerConfig.mrf_radius)


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``experiments``."""
    parser = subparsers.add_parser(
        'experiments', help='compare HJS, separable and joint filters on recordings',
        description='Replay recordings with several algorithms and particle counts, score '
                    'them (CLEAR MOT, posterior mass within d of the truth) and plot the '
                    'posterior-mass curves; optional MRF ablation over seeds.')
    parser.add_argument('recordings', nargs='*', type=Path, metavar='RECORDING',
                        help='recording directories made by mbtrack synth')
    parser.add_argument('--out', type=Path, required=True, metavar='OUTDIR')
    parser.add_argument('--img', type=Path, default=None, metavar='DIR',
                        help='where to put the PNG plots (default OUTDIR)')
    parser.add_argument('--runs', default='hjs:100,hjs:500,separable:100,separable:500,'
                                          'joint:10000',
                        help='comma-separated ALG:N list (N = particles per target, or '
                             'joint particles for joint; samples per target for the 004 '
                             'baselines pdaf and jpdaf, joint samples for jlf, which have '
                             'no posterior-mass curve), e.g. hjs:100,pdaf:100,jpdaf:100,'
                             'jlf:100')
    parser.add_argument('--presets', default='', metavar='NAMES',
                        help='comma-separated mbtrack synth presets to render and evaluate '
                             '(e.g. lanz-seq1,lanz-seq2,lanz-seq3,lanz-seq4), each over the '
                             '--recording-seeds')
    parser.add_argument('--recording-seeds', default='200-204', metavar='SEEDS',
                        help='recording seeds of --presets: comma-separated, A-B ranges '
                             '(default 200-204)')
    parser.add_argument('--frames', type=int, default=None, metavar='N',
                        help="frames of each rendered recording (default: the preset's)")
    parser.add_argument('--ablation', type=Path, default=None, metavar='RECORDING',
                        help='recording for the MRF ablation (HJS N=100 with/without MRF)')
    parser.add_argument('--seeds', default='0,1,2,3,4', help='seeds of the ablation')
    parser.add_argument('--max-frames', type=int, default=None, metavar='N')
    parser.add_argument('--run-seeds', default='0',
                        help='comma-separated seeds of the comparison runs (results are '
                             'averaged; curves are the mean over seeds)')
    parser.add_argument('--d-occ', type=float, default=0.15, help='occlusion penalty d_occ')
    parser.add_argument('--sigma', type=float, default=0.12, help='likelihood width sigma')
    parser.add_argument('--tag', default='', help='suffix of the PNG names')
    parser.add_argument('--params', type=Path, default=None, metavar='NODE.yaml',
                        help='tracker settings of a tracker_node parameter file '
                             '(config/*.yaml, as mbtrack replay --params) under the ones this '
                             'command sets: d_occ, sigma, the paper\'s MRF radius and motion')
    return parser


def _error(msg: str) -> int:
    print(f'{_PROG}: error: {msg}', file=sys.stderr)
    return 2


def _parse_seeds(text: str) -> list[int]:
    """'200-202,7' -> [200, 201, 202, 7]; raises ValueError."""
    out: list[int] = []
    for item in filter(None, (s.strip() for s in text.split(','))):
        a, dash, b = item.partition('-')
        try:
            out += list(range(int(a), int(b) + 1)) if dash else [int(a)]
        except ValueError as err:
            raise ValueError(f'bad seed {item!r}: expected N or A-B') from err
    return out


def _render(presets: list[str], seeds: list[int], frames: int | None,
            root: Path) -> dict[str, list[Path]]:
    """Render (or reuse) one recording per preset and seed under ``root``; preset name ->
    recording directories. Raises SynthError for an unknown preset."""
    from mbtrack_ros.synth import generate, get_preset

    groups: dict[str, list[Path]] = {}
    for name in presets:
        preset = get_preset(name)
        groups[name] = []
        for seed in seeds:
            rec = root / f'{name}_s{seed}'
            if not (rec / 'ground_truth.csv').exists():
                print(f'{_PROG}: rendering {rec.name}', file=sys.stderr)
                generate(preset, rec, seed=seed, frames=frames, width=preset.size[0],
                         height=preset.size[1])
            groups[name].append(rec)
    return groups


def _parse_runs(text: str) -> list[tuple[str, int]]:
    runs = []
    for item in filter(None, (s.strip() for s in text.split(','))):
        alg, _, n = item.partition(':')
        try:
            runs.append((alg, int(n)))
        except ValueError as err:
            raise ValueError(f'bad run {item!r}: expected ALG:N') from err
    return runs


def _replay(recording: Path, out: Path, alg: str, n: int, seed: int, max_frames: int | None,
            *, mrf: bool = True, d_occ: float = 0.15, sigma: float = 0.12,
            params: Path | None = None) -> dict:
    from mbtrack_ros.cli import main
    from mbtrack_ros.evaluation.clear_mot import clear_mot, coalescence
    from mbtrack_ros.evaluation.posterior import posterior_mass
    from mbtrack_ros.recording.csvfiles import read_ground_truth, read_tracks

    gt = recording / 'ground_truth.csv'
    label = alg
    if alg == 'hjs-nomrf':      # 000 §VI-C: HJS without the exclusion MRF
        alg, mrf = 'hjs', False
    particles = alg not in _NO_PARTICLES
    argv = ['replay', str(recording), '--out', str(out), '--init-from', str(gt),
            '--algorithm', alg, '--seed', str(seed), '--d-occ', str(d_occ),
            '--sigma', str(sigma), '--mrf-radius', str(PAPER_MRF_RADIUS), '--paper-motion']
    argv += ['--save-particles'] if particles else []
    argv += ['--params', str(params)] if params is not None else []
    argv += ['--joint-particles', str(n)] if alg == 'joint' else ['--particles', str(n)]
    if not mrf:
        argv.append('--no-mrf')
    if max_frames is not None:
        argv += ['--max-frames', str(max_frames)]
    t0 = time.perf_counter()
    code = main(argv)
    wall = time.perf_counter() - t0
    truth = read_ground_truth(gt)
    tracks = read_tracks(out / 'tracks.csv')
    if max_frames is not None:
        stamps = sorted({r.stamp_ns for r in truth})[:max_frames]
        keep = set(stamps)
        truth = [r for r in truth if r.stamp_ns in keep]
    frames = len({r.stamp_ns for r in tracks})
    result = clear_mot(tracks, truth, name=f'{recording.name} {alg} {n}')
    if particles:
        mass = posterior_mass(out / 'particles.npz', truth, tracks, matching=result)
        at_025, at_05, curve = mass.at(0.25), mass.at(0.5), [mass.distances.tolist(),
                                                             mass.fraction.tolist()]
    else:  # baselines: no posterior samples (mass and curve not defined)
        at_025 = at_05 = float('nan')
        curve = None
    return {'recording': recording.name, 'algorithm': label, 'particles': n, 'seed': seed,
            'mrf': mrf, 'd_occ': d_occ, 'sigma': sigma,
            'params': None if params is None else str(params), 'exit_code': code,
            'frames': frames,
            'wall_s': wall,
            'frames_per_s': frames / max(wall, 1e-9), 'mota': result.mota,
            'motp_mm': result.motp_mm, 'miss_rate': result.miss_rate,
            'false_positive_rate': result.false_positive_rate,
            'mismatches': result.mismatches, 'mass_0_5': at_05,
            'coalescence': coalescence(tracks, truth),
            'mass_0_25': at_025, 'curve': curve}


def _aggregate(group: list[dict], name: str | None = None) -> dict:
    """Mean +- std over the runs (recordings x seeds) of one (recording or preset ``name``,
    run), as formatted strings."""
    def ms(key: str, scale: float = 1.0, digits: int = 3, unit: str = '') -> str:
        v = np.array([g[key] for g in group], np.float64) * scale
        if np.all(np.isnan(v)):  # not defined (baselines have no posterior mass)
            return '-'
        if len(v) == 1:
            return f'{v[0]:.{digits}f}{unit}'
        return f'{v.mean():.{digits}f} +- {v.std(ddof=1):.{digits}f}{unit}'

    first = group[0]
    return {'recording': name or first['recording'], 'algorithm': first['algorithm'],
            'particles': first['particles'], 'seeds': [g['seed'] for g in group],
            'recordings': sorted({g['recording'] for g in group}),
            'frames_per_s': float(np.mean([g['frames_per_s'] for g in group])),
            'mota': ms('mota', 100, 1, ' %'), 'motp_mm': ms('motp_mm', 1, 0, ' mm'),
            'miss_rate': ms('miss_rate', 100, 1, ' %'), 'mismatches': ms('mismatches', 1, 1),
            'mass_0_25': ms('mass_0_25'), 'mass_0_5': ms('mass_0_5')}


def _fmt(x: float, pct: bool = False) -> str:
    if x != x:  # NaN
        return '-'
    return f'{100 * x:.1f} %' if pct else f'{x:.3f}'


def run(args: argparse.Namespace) -> int:
    """Run the comparison and the ablation; 0 on success, 2 on bad input."""
    try:
        runs = _parse_runs(args.runs)
        seeds = [int(s) for s in args.seeds.split(',') if s.strip()]
        run_seeds = [int(s) for s in args.run_seeds.split(',') if s.strip()]
        recording_seeds = _parse_seeds(args.recording_seeds)
    except ValueError as err:
        return _error(str(err))
    presets = [p.strip() for p in args.presets.split(',') if p.strip()]
    if presets and not recording_seeds:
        return _error('--recording-seeds is empty')
    if args.frames is not None and args.frames < 1:
        return _error(f'--frames must be >= 1, got {args.frames}')
    if not run_seeds:
        return _error('--run-seeds is empty')
    for rec in list(args.recordings) + ([args.ablation] if args.ablation else []):
        if not (rec / 'ground_truth.csv').exists() or not (rec / 'bag').exists():
            return _error(f'{rec} is not a recording directory made by mbtrack synth')
    if not args.recordings and args.ablation is None and not presets:
        return _error('nothing to do: give recordings, --presets and/or --ablation')
    if args.params is not None:
        from mbtrack_ros.commands.replay import tracker_values_from_params
        from mbtrack_ros.core.tracker import TrackerError
        try:    # a bad file is one error here, not one failed replay per run
            tracker_values_from_params(args.params)
        except (TrackerError, OSError) as err:
            return _error(f'--params: {err}')
    out = Path(args.out)
    img = Path(args.img) if args.img is not None else out
    out.mkdir(parents=True, exist_ok=True)
    img.mkdir(parents=True, exist_ok=True)
    from mbtrack_ros.evaluation.plots import plot_posterior_curves
    from mbtrack_ros.synth import SynthError

    groups = {rec.name: [rec] for rec in args.recordings}
    try:
        groups.update(_render(presets, recording_seeds, args.frames, out / 'recordings'))
    except (SynthError, OSError) as err:
        return _error(str(err).splitlines()[0] if str(err) else type(err).__name__)

    rows: list[dict] = []
    summary: list[dict] = []
    lik = {'d_occ': args.d_occ, 'sigma': args.sigma, 'params': args.params}
    for gname, recs in groups.items():
        curves = {}
        for alg, n in runs:
            name = f'{alg}_{n}'
            group = []
            for rec in recs:
                for seed in run_seeds:
                    print(f'{_PROG}: {rec.name} {name} seed {seed}', file=sys.stderr)
                    r = _replay(rec, out / rec.name / f'{name}_s{seed}', alg, n, seed,
                                args.max_frames, **lik)
                    rows.append(r)
                    group.append(r)
            summary.append(_aggregate(group, gname))
            if group[0]['curve'] is None:  # baselines: no posterior-mass curve
                continue
            d = np.array(group[0]['curve'][0])
            frac = np.mean([g['curve'][1] for g in group], axis=0)
            label = {'hjs': 'HJS', 'hjs-nomrf': 'HJS-noMRF'}.get(alg, alg[0].upper())
            curves[f'{label}_{n}p'] = (d, frac)
        if not curves:
            continue
        runs_text = f'{len(recs)} recordings x {len(run_seeds)} seeds' \
            if len(recs) > 1 else f'{len(run_seeds)} seeds'
        plot_posterior_curves(curves, img / f'posterior_{gname}{args.tag}.png',
                              title=f'{gname}: posterior mass around the truth'
                                    + (f' ({runs_text})' if len(group) > 1 else ''))
    ablation: list[dict] = []
    if args.ablation is not None:
        for mrf in (True, False):
            for seed in seeds:
                tag = f'hjs_100_{"mrf" if mrf else "nomrf"}_s{seed}'
                print(f'{_PROG}: ablation {args.ablation.name} {tag}', file=sys.stderr)
                ablation.append(_replay(args.ablation, out / 'ablation' / tag, 'hjs', 100,
                                        seed, args.max_frames, mrf=mrf, **lik))
    lines = [f'd_occ = {args.d_occ}, sigma = {args.sigma}, seeds {args.run_seeds}'
             + (f', recording seeds {args.recording_seeds}' if presets else '')
             + (f', parameters of {args.params}' if args.params is not None else '')
             + '; mean +- standard deviation over recordings and seeds; frames/s: Table I '
               '(wall clock of the whole replay)', '',
             '| recording | run | frames/s | MOTA | MOTP | miss | ID switches | '
             'mass@0.25m | mass@0.5m |',
             '| --- | --- |' + ' ---: |' * 7]
    for r in summary:
        lines.append(f'| {r["recording"]} | {r["algorithm"]} N={r["particles"]} | '
                     f'{r["frames_per_s"]:.1f} | {r["mota"]} | {r["motp_mm"]} | '
                     f'{r["miss_rate"]} | {r["mismatches"]} | {r["mass_0_25"]} | '
                     f'{r["mass_0_5"]} |')
    if ablation:
        lines += ['', '| MRF | seed | MOTA | ID switches | mass@0.5m |',
                  '| --- | ---: | ---: | ---: | ---: |']
        for r in ablation:
            lines.append(f'| {"on" if r["mrf"] else "off"} | {r["seed"]} | '
                         f'{_fmt(r["mota"], True)} | {r["mismatches"]} | '
                         f'{_fmt(r["mass_0_5"])} |')
        for mrf in (True, False):
            agg = _aggregate([r for r in ablation if r['mrf'] == mrf])
            lines.append(f'| {"on" if mrf else "off"} | mean | {agg["mota"]} | '
                         f'{agg["mismatches"]} | {agg["mass_0_5"]} |')
    table = '\n'.join(lines)
    (out / 'results.md').write_text(table + '\n', encoding='utf-8')
    (out / 'results.json').write_text(json.dumps({'runs': rows, 'summary': summary,
                                                  'ablation': ablation},
                                                 indent=1), encoding='utf-8')
    print(table)
    return 0
