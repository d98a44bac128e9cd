"""``mbtrack experiments``: the HJS / separable / joint comparison of 000 §VI on recordings.

For every recording directory (made by ``mbtrack synth``) and every run ``ALG:N`` the
recording is replayed (``mbtrack replay --init-from ground_truth.csv --save-particles``),
scored with CLEAR MOT and the posterior-mass curve (000 Fig. 6), and the curves of each
recording are plotted into one PNG. With ``--ablation`` the HJS filter is run with and
without the spatial-exclusion MRF over several seeds (000 §VI-C). Results go to
``OUTDIR/results.md`` and ``OUTDIR/results.json``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

__all__ = ['add_parser', 'run']

_PROG = 'mbtrack experiments'


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
                             'joint particles for joint)')
    parser.add_argument('--ablation', type=Path, default=None, metavar='RECORDING',
                        help='recording for the MRF ablation (HJS N=100 with/without MRF)')
    parser.add_argument('--seeds', default='0,1,2,3,4', help='seeds of the ablation')
    parser.add_argument('--max-frames', type=int, default=None, metavar='N')
    parser.add_argument('--seed', type=int, default=0, help='seed of the comparison runs')

    def error(message: str) -> None:
        print(f'{_PROG}: error: {message}', file=sys.stderr)
        raise SystemExit(2)

    parser.error = error
    return parser


def _error(msg: str) -> int:
    print(f'{_PROG}: error: {msg}', file=sys.stderr)
    return 2


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
            *, mrf: bool = True) -> dict:
    from mbtrack_ros.cli import main
    from mbtrack_ros.evaluation.clear_mot import clear_mot
    from mbtrack_ros.evaluation.posterior import posterior_mass
    from mbtrack_ros.recording.csvfiles import read_ground_truth, read_tracks

    gt = recording / 'ground_truth.csv'
    argv = ['replay', str(recording), '--out', str(out), '--init-from', str(gt),
            '--algorithm', alg, '--seed', str(seed), '--save-particles']
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
    mass = posterior_mass(out / 'particles.npz', truth, tracks, matching=result)
    return {'recording': recording.name, 'algorithm': alg, 'particles': n, 'seed': seed,
            'mrf': mrf, 'exit_code': code, 'frames': frames, 'wall_s': wall,
            'frames_per_s': frames / max(wall, 1e-9), 'mota': result.mota,
            'motp_mm': result.motp_mm, 'miss_rate': result.miss_rate,
            'false_positive_rate': result.false_positive_rate,
            'mismatches': result.mismatches, 'mass_0_5': mass.at(0.5),
            'mass_0_25': mass.at(0.25), 'curve': [mass.distances.tolist(),
                                                  mass.fraction.tolist()]}


def _fmt(x: float, pct: bool = False) -> str:
    if x != x:  # NaN
        return '-'
    return f'{100 * x:.1f} %' if pct else f'{x:.3f}'


def run(args: argparse.Namespace) -> int:
    """Run the comparison and the ablation; 0 on success, 2 on bad input."""
    try:
        runs = _parse_runs(args.runs)
        seeds = [int(s) for s in args.seeds.split(',') if s.strip()]
    except ValueError as err:
        return _error(str(err))
    for rec in list(args.recordings) + ([args.ablation] if args.ablation else []):
        if not (rec / 'ground_truth.csv').exists() or not (rec / 'bag').exists():
            return _error(f'{rec} is not a recording directory made by mbtrack synth')
    if not args.recordings and args.ablation is None:
        return _error('nothing to do: give recordings and/or --ablation')
    out = Path(args.out)
    img = Path(args.img) if args.img is not None else out
    out.mkdir(parents=True, exist_ok=True)
    img.mkdir(parents=True, exist_ok=True)
    from mbtrack_ros.evaluation.plots import plot_posterior_curves

    rows: list[dict] = []
    for rec in args.recordings:
        curves = {}
        for alg, n in runs:
            name = f'{alg}_{n}'
            print(f'{_PROG}: {rec.name} {name}', file=sys.stderr)
            r = _replay(rec, out / rec.name / name, alg, n, args.seed, args.max_frames)
            rows.append(r)
            curves[f'{"HJS" if alg == "hjs" else alg[0].upper()}_{n}p'] = tuple(r['curve'])
        plot_posterior_curves(curves, img / f'posterior_{rec.name}.png',
                              title=f'{rec.name}: posterior mass around the truth')
    ablation: list[dict] = []
    if args.ablation is not None:
        for mrf in (True, False):
            for seed in seeds:
                tag = f'hjs_100_{"mrf" if mrf else "nomrf"}_s{seed}'
                print(f'{_PROG}: ablation {args.ablation.name} {tag}', file=sys.stderr)
                ablation.append(_replay(args.ablation, out / 'ablation' / tag, 'hjs', 100,
                                        seed, args.max_frames, mrf=mrf))
    lines = ['| recording | run | frames | frames/s | MOTA | MOTP | miss | false pos | '
             'ID switches | mass@0.25m | mass@0.5m |',
             '| --- | --- |' + ' ---: |' * 9]
    for r in rows:
        lines.append(f'| {r["recording"]} | {r["algorithm"]} N={r["particles"]} | '
                     f'{r["frames"]} | {r["frames_per_s"]:.1f} | {_fmt(r["mota"], True)} | '
                     f'{r["motp_mm"]:.0f} mm | {_fmt(r["miss_rate"], True)} | '
                     f'{_fmt(r["false_positive_rate"], True)} | {r["mismatches"]} | '
                     f'{_fmt(r["mass_0_25"])} | {_fmt(r["mass_0_5"])} |')
    if ablation:
        lines += ['', '| MRF | seed | MOTA | ID switches | mass@0.5m |',
                  '| --- | ---: | ---: | ---: | ---: |']
        for r in ablation:
            lines.append(f'| {"on" if r["mrf"] else "off"} | {r["seed"]} | '
                         f'{_fmt(r["mota"], True)} | {r["mismatches"]} | '
                         f'{_fmt(r["mass_0_5"])} |')
    table = '\n'.join(lines)
    (out / 'results.md').write_text(table + '\n', encoding='utf-8')
    (out / 'results.json').write_text(json.dumps({'runs': rows, 'ablation': ablation},
                                                 indent=1), encoding='utf-8')
    print(table)
    return 0
