"""Score tables: aligned text for the terminal, Markdown (``scores.md``), JSON (``scores.json``).

Columns follow paper 003, Table 1 (MOTP, miss rate, false positives, mismatches, MOTA) plus the
counts behind them and, when particles were given, the posterior mass within 0.5 m (000 Fig. 6).
"""
from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

from mbtrack_ros.evaluation.clear_mot import ClearMotResult
from mbtrack_ros.evaluation.errors import EvaluationError
from mbtrack_ros.evaluation.posterior import PosteriorMassResult

__all__ = ['format_table', 'markdown_table', 'score_rows', 'write_report']

_HEADER = ('sequence', 'MOTA', 'MOTP', 'miss', 'false pos', 'mismatches', 'GT objects',
           'frames', 'matches', 'tracks', 'mass@0.5m')


def _pct(x: float) -> str:
    return '-' if not math.isfinite(x) else f'{100.0 * x:.1f} %'


def score_rows(results: Sequence[ClearMotResult],
               posterior: Mapping[str, PosteriorMassResult] | None = None) -> list[list[str]]:
    """Header plus one row of formatted cells per result (posterior keyed by result name)."""
    posterior = posterior or {}
    rows = [list(_HEADER)]
    for r in results:
        p = posterior.get(r.name)
        rows.append([
            r.name, _pct(r.mota),
            '-' if not math.isfinite(r.motp_mm) else f'{r.motp_mm:.0f} mm',
            _pct(r.miss_rate), _pct(r.false_positive_rate),
            f'{r.mismatches} ({_pct(r.mismatch_rate)})', str(r.gt_objects), str(r.frames),
            str(r.matches), str(r.tracks), '-' if p is None else f'{p.at(0.5):.3f}'])
    return rows


def format_table(results: Sequence[ClearMotResult],
                 posterior: Mapping[str, PosteriorMassResult] | None = None) -> str:
    """Aligned plain-text table (first column left-aligned, numbers right-aligned)."""
    rows = score_rows(results, posterior)
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = []
    for k, row in enumerate(rows):
        cells = [row[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(row[1:], widths[1:])]
        lines.append('  '.join(cells))
        if k == 0:
            lines.append('  '.join('-' * w for w in widths))
    return '\n'.join(lines)


def markdown_table(results: Sequence[ClearMotResult],
                   posterior: Mapping[str, PosteriorMassResult] | None = None) -> str:
    """GitHub Markdown table of the same cells."""
    rows = score_rows(results, posterior)
    out = ['| ' + ' | '.join(rows[0]) + ' |',
           '| --- |' + ' ---: |' * (len(rows[0]) - 1)]
    out += ['| ' + ' | '.join(c.replace('|', '\\|') for c in row) + ' |' for row in rows[1:]]
    return '\n'.join(out)


def _person_table(r: ClearMotResult) -> str:
    out = ['| person | frames | matches | misses | mismatches | MOTP | tracks |',
           '| ---: | ---: | ---: | ---: | ---: | ---: | --- |']
    for p in r.per_person:
        motp = '-' if not math.isfinite(p.motp_mm) else f'{p.motp_mm:.0f} mm'
        out.append(f'| {p.person_id} | {p.frames} | {p.matches} | {p.misses} | '
                   f'{p.mismatches} | {motp} | {", ".join(map(str, p.track_ids)) or "-"} |')
    return '\n'.join(out)


def write_report(out_dir: str | Path, results: Sequence[ClearMotResult], *,
                 posterior: Mapping[str, PosteriorMassResult] | None = None,
                 images: Sequence[str | Path] = (), inputs: Mapping[str, str] | None = None,
                 notes: Sequence[str] = ()) -> dict[str, Path]:
    """Write ``scores.md`` and ``scores.json`` into ``out_dir``; returns their paths.

    ``images`` are PNG paths linked from the Markdown (relative to ``out_dir`` when inside it);
    ``inputs`` names the evaluated files; ``notes`` are warnings listed in both files.
    """
    if not results:
        raise EvaluationError('no results to report')
    out_dir = Path(out_dir)
    posterior = posterior or {}
    threshold = results[0].threshold_m
    md = ['# Tracking scores', '',
          f'CLEAR MOT on floor positions, match threshold {threshold * 1000:.0f} mm '
          '(py-motmetrics). Rates are relative to the ground-truth objects.', '']
    for key, value in (inputs or {}).items():
        md.append(f'- {key}: `{value}`')
    if inputs:
        md.append('')
    md += [markdown_table(results, posterior), '']
    for r in results:
        if r.per_person:
            md += [f'## Per person: {r.name}', '', _person_table(r), '']
    for note in notes:
        md.append(f'> warning: {note}')
    if notes:
        md.append('')
    for img in images:
        img = Path(img)
        rel = img.relative_to(out_dir) if img.is_relative_to(out_dir) else img
        md += [f'![{img.stem}]({rel.as_posix()})', '']
    doc = {
        'threshold_m': threshold,
        'inputs': dict(inputs or {}),
        'sequences': [r.to_dict() for r in results],
        'posterior_mass': {k: v.to_dict() for k, v in posterior.items()},
        'images': [Path(i).name for i in images],
        'warnings': list(notes),
    }
    paths = {'markdown': out_dir / 'scores.md', 'json': out_dir / 'scores.json'}
    try:
        paths['markdown'].write_text('\n'.join(md), encoding='utf-8')
        paths['json'].write_text(json.dumps(doc, indent=2, allow_nan=False) + '\n',
                                 encoding='utf-8')
    except OSError as err:
        raise EvaluationError(f'cannot write the report into {out_dir}: '
                              f'{err.strerror or err}') from err
    return paths
