"""``mbtrack evaluate``: regenerate the results tables (``docs/results/*.md``) and plots.

Runs every benchmark of :data:`mbtrack_ros.commands.benchmarks.BENCHMARKS` (or those named
with ``--only``): their jobs in a pool of ``--jobs`` worker processes with a progress bar,
then the exclusive ones (timings) alone. Each benchmark writes ``OUT/NAME.md`` (a heading,
what was run, the table, the command that regenerates it) and its PNG plots; ``OUT/
results.json`` keeps every job's raw result. ``--quick`` runs a reduced version of every
benchmark (seconds, for CI); its numbers are not the published ones. ``--report-only``
writes the tables and plots again from ``OUT/results.json`` without running anything, and
``--fill FILE.md`` copies each table into the ``<!-- results: NAME -->`` block of a page
(the README and docs/evaluation.md quote the tables that way, never by hand).
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

__all__ = ['add_parser', 'run', 'table_of']

_PROG = 'mbtrack evaluate'


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``evaluate``."""
    parser = subparsers.add_parser(
        'evaluate', help='run the benchmarks and write the results tables and plots',
        description='Render fresh recordings, track them, score them and write one markdown '
                    'table per benchmark (OUT/NAME.md) with its PNG plots: the synthetic '
                    'clear room, the HJS paper\'s experiments, the association baselines, '
                    'the real clip, the room calibration and the speed.')
    parser.add_argument('--out', type=Path, default=Path('docs/results'), metavar='DIR',
                        help='where the tables and plots go (default docs/results)')
    parser.add_argument('--quick', action='store_true',
                        help='a reduced run of every benchmark (about a minute; for CI)')
    parser.add_argument('--only', action='append', default=None, metavar='NAME',
                        help='run only this benchmark (repeatable)')
    parser.add_argument('--jobs', type=int, default=2, metavar='N',
                        help='worker processes (default 2)')
    parser.add_argument('--work', type=Path, default=None, metavar='DIR',
                        help='keep the recordings and replays here (default: a temporary '
                             'directory, removed at the end)')
    parser.add_argument('--report-only', action='store_true',
                        help='run nothing: write the tables and plots again from '
                             'OUT/results.json')
    parser.add_argument('--fill', action='append', default=[], type=Path, metavar='FILE.md',
                        help='also copy each table into the block between '
                             '"<!-- results: NAME -->" and "<!-- /results -->" of this markdown '
                             'file (repeatable; e.g. README.md, docs/evaluation.md)')
    parser.add_argument('--list', action='store_true', help='list the benchmarks and exit')
    return parser


def _error(message: str) -> int:
    print(f'{_PROG}: error: {message}', file=sys.stderr)
    return 2


def _command(args: argparse.Namespace, name: str) -> str:
    words = ['mbtrack evaluate'] + (['--quick'] if args.quick else []) + [f'--only {name}']
    return ' '.join(words)


def run(args: argparse.Namespace) -> int:
    """Run the benchmarks; 0 on success, 2 on bad arguments, 1 when a job failed."""
    from mbtrack_ros.commands.benchmarks import BENCHMARKS, get_benchmark

    if args.list:
        for b in BENCHMARKS:
            print(f'{b.name:<12} {b.title}')
        return 0
    if args.jobs < 1:
        return _error(f'--jobs must be at least 1, got {args.jobs}')
    try:
        chosen = [get_benchmark(n) for n in args.only] if args.only else list(BENCHMARKS)
    except KeyError as err:
        return _error(err.args[0])
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        return _error(f'cannot create {args.out}: {err.strerror or err}')
    path = args.out / 'results.json'
    old = {}
    if path.exists():   # the benchmarks not run this time keep their results
        try:
            old = json.loads(path.read_text(encoding='utf-8'))
        except (OSError, ValueError) as err:
            if args.report_only:
                return _error(f'cannot read {path}: {err}')
    started = time.perf_counter()
    if args.report_only:
        missing = [b.name for b in chosen if b.name not in old]
        if missing:
            return _error(f'{path} has no results of {", ".join(missing)}')
        for bench in chosen:
            _write_report(args, bench, old[bench.name])
    else:
        work = args.work or Path(tempfile.mkdtemp(prefix='mbtrack-evaluate-'))
        try:
            results = _run_jobs(chosen, args.quick, args.jobs, work)
            for bench in chosen:   # before the work directory goes: reports copy from it
                _write_report(args, bench, results[bench.name])
                old[bench.name] = [{k: v for k, v in r.items() if k != 'picture'}
                                   for r in results[bench.name]]
        except RuntimeError as err:
            return _error_run(str(err))
        finally:
            if args.work is None:
                shutil.rmtree(work, ignore_errors=True)
        path.write_text(json.dumps(old, indent=1) + '\n', encoding='utf-8')
    for target in args.fill:
        try:
            _fill(target, args.out)
        except (OSError, ValueError) as err:
            return _error(f'--fill {target}: {err}')
    print(f'{_PROG}: {len(chosen)} benchmark(s) in {time.perf_counter() - started:.0f} s; '
          f'tables and plots in {args.out}/', file=sys.stderr)
    return 0


_BLOCK = re.compile(r'(<!-- results: (\w+) -->\n)(.*?)(<!-- /results -->)', re.S)


def table_of(markdown: str) -> str:
    """The tables of a results page (from its first ``|`` line, after the note that
    precedes it, with the notes and further tables that follow, up to the plots) and the
    line that regenerates it."""
    lines = markdown.splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith('|')), len(lines))
    # page: title, blank, description, blank, [note, blank,] table, [blank, notes or
    # tables,] [blank, plots,] blank, command
    note = lines[start - 2:start - 1] if start >= 6 and not lines[start - 1] else []
    stop = next((i for i in range(start, len(lines))
                 if lines[i].startswith(('![', 'Regenerate:'))), len(lines))
    body = '\n'.join(lines[start:stop]).strip('\n')
    command = [line for line in lines if line.startswith('Regenerate:')]
    return '\n'.join(note + ([''] if note else []) + [body, ''] + command)


def _fill(target: Path, out: Path) -> None:
    """Replace each ``<!-- results: NAME -->`` block of ``target`` by the table of
    ``out/NAME.md``."""
    text = target.read_text(encoding='utf-8')

    def block(m: re.Match) -> str:
        page = out / f'{m.group(2)}.md'
        if not page.exists():
            raise ValueError(f'no {page} for the block "{m.group(2)}"')
        return f'{m.group(1)}{table_of(page.read_text(encoding="utf-8"))}\n{m.group(4)}'

    target.write_text(_BLOCK.sub(block, text), encoding='utf-8')


def _write_report(args: argparse.Namespace, bench, results: list[dict]) -> None:
    """``OUT/NAME.md``: heading, description, table, plots, the regenerating command."""
    report = bench.report(results, args.out)
    lines = [f'# {bench.title}', '', bench.description, '', report.markdown, '']
    lines += [f'![{Path(png).stem}]({png})' for png in report.plots]
    lines += [''] if report.plots else []
    lines += [f'Regenerate: `{_command(args, bench.name)}` (all tables: '
              f'`mbtrack evaluate{" --quick" if args.quick else ""}`).']
    text = '\n'.join(lines) + '\n'
    (args.out / f'{bench.name}.md').write_text(text, encoding='utf-8')
    print(f'\n{text}')


def _error_run(message: str) -> int:
    print(f'{_PROG}: error: {message}', file=sys.stderr)
    return 1


def _run_jobs(chosen: list, quick: bool, jobs: int, work: Path) -> dict[str, list[dict]]:
    """Every job of ``chosen``: the shared ones in a pool of ``jobs`` processes, then the
    exclusive ones one by one; results by benchmark, in job order."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from tqdm import tqdm

    from mbtrack_ros.commands.benchmarks import run_job

    shared = [j for b in chosen if not b.exclusive for j in b.jobs(quick)]
    alone = [j for b in chosen if b.exclusive for j in b.jobs(quick)]
    done: dict = {}
    bar = tqdm(total=len(shared) + len(alone), desc='evaluate', unit='job', file=sys.stderr,
               disable=None)
    try:
        if shared:
            # spawn: a fresh interpreter per worker (no forked numba / OpenCV threads)
            context = multiprocessing.get_context('spawn')
            with ProcessPoolExecutor(max_workers=min(jobs, len(shared)),
                                     mp_context=context) as pool:
                futures = {pool.submit(run_job, j, work): j for j in shared}
                for future in as_completed(futures):
                    job = futures[future]
                    try:
                        done[job.benchmark, job.name] = future.result()
                    except Exception as err:   # one line, naming the job
                        for f in futures:
                            f.cancel()
                        raise RuntimeError(f'{job.benchmark}/{job.name}: {err}') from err
                    bar.set_postfix_str(f'{job.benchmark}/{job.name}')
                    bar.update()
        for job in alone:
            try:
                done[job.benchmark, job.name] = run_job(job, work)
            except Exception as err:
                raise RuntimeError(f'{job.benchmark}/{job.name}: {err}') from err
            bar.update()
    finally:
        bar.close()
    out: dict[str, list[dict]] = {b.name: [] for b in chosen}
    for b in chosen:
        out[b.name] = [done[j.benchmark, j.name] for j in b.jobs(quick)]
    return out
