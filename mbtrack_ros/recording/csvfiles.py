"""The two CSV formats every command shares: tracks and ground truth.

Tracks (written by ``mbtrack replay``, read by ``mbtrack eval``)::

    stamp_ns,frame,track_id,x,y[,visibility,existence]

Ground truth (written by ``mbtrack synth`` beside the bag)::

    stamp_ns,frame,person_id,x,y,z_head,sitting,visible_cameras

``x, y, z_head`` in metres in the room frame, ``sitting`` 0/1, ``visible_cameras`` the names
of the cameras that see at least part of the person, joined by ``;`` (empty if none).
"""
from __future__ import annotations

import csv
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = [
    'GROUND_TRUTH_COLUMNS', 'TRACK_COLUMNS', 'CsvFormatError', 'GroundTruthRow', 'TrackRow',
    'read_ground_truth', 'read_tracks', 'write_ground_truth', 'write_tracks',
]

TRACK_COLUMNS = ('stamp_ns', 'frame', 'track_id', 'x', 'y')
TRACK_OPTIONAL = ('visibility', 'existence')
GROUND_TRUTH_COLUMNS = ('stamp_ns', 'frame', 'person_id', 'x', 'y', 'z_head', 'sitting',
                        'visible_cameras')


_INT64_MIN, _INT64_MAX = -2 ** 63, 2 ** 63 - 1


class CsvFormatError(ValueError):
    """A CSV file that is unreadable or lacks the documented columns."""


@dataclass(frozen=True)
class TrackRow:
    stamp_ns: int
    frame: int
    track_id: int
    x: float
    y: float
    visibility: float = float('nan')
    existence: float = float('nan')


@dataclass(frozen=True)
class GroundTruthRow:
    stamp_ns: int
    frame: int
    person_id: int
    x: float
    y: float
    z_head: float
    sitting: bool
    visible_cameras: tuple[str, ...]


def _rows(path: Path, required: tuple[str, ...]) -> tuple[list[str], list[dict[str, str]]]:
    try:
        with path.open(newline='', encoding='utf-8') as handle:
            reader = csv.DictReader(handle)
            header = list(reader.fieldnames or [])
            missing = [c for c in required if c not in header]
            if missing:
                raise CsvFormatError(
                    f'{path}: missing column(s) {", ".join(missing)} '
                    f'(expected {",".join(required)})')
            return header, list(reader)
    except OSError as err:
        raise CsvFormatError(f'cannot read {path}: {err.strerror or err}') from err
    except (csv.Error, UnicodeDecodeError) as err:
        raise CsvFormatError(f'{path}: not a readable CSV file ({err})') from err


def _parse(path: Path, lineno: int, value: str, kind: type, column: str):
    try:
        result = kind(value)
    except (TypeError, ValueError) as err:
        raise CsvFormatError(f'{path}:{lineno}: bad {column} value {value!r}') from err
    if kind is int and not _INT64_MIN <= result <= _INT64_MAX:  # stamps and ids are int64
        raise CsvFormatError(f'{path}:{lineno}: {column} value {value:.30} is out of the '
                             '64-bit integer range')
    if kind is float and column in ('x', 'y', 'z_head') and not np.isfinite(result):
        raise CsvFormatError(f'{path}:{lineno}: {column} is not finite')
    return result


def read_tracks(path: str | Path) -> list[TrackRow]:
    """Read a tracks CSV; raises :class:`CsvFormatError` with a one-line reason."""
    path = Path(path)
    header, rows = _rows(path, TRACK_COLUMNS)
    out = []
    for lineno, row in enumerate(rows, start=2):
        opt = {c: _parse(path, lineno, row[c], float, c)
               for c in TRACK_OPTIONAL if c in header and row[c] not in ('', None)}
        out.append(TrackRow(
            stamp_ns=_parse(path, lineno, row['stamp_ns'], int, 'stamp_ns'),
            frame=_parse(path, lineno, row['frame'], int, 'frame'),
            track_id=_parse(path, lineno, row['track_id'], int, 'track_id'),
            x=_parse(path, lineno, row['x'], float, 'x'),
            y=_parse(path, lineno, row['y'], float, 'y'), **opt))
    return out


def write_tracks(path: str | Path, rows: Iterable[TrackRow]) -> None:
    """Write a tracks CSV with the optional probability columns."""
    with Path(path).open('w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(TRACK_COLUMNS + TRACK_OPTIONAL)
        for r in rows:
            writer.writerow([r.stamp_ns, r.frame, r.track_id, f'{r.x:.4f}', f'{r.y:.4f}',
                             f'{r.visibility:.4f}', f'{r.existence:.4f}'])


def read_ground_truth(path: str | Path) -> list[GroundTruthRow]:
    """Read a ground-truth CSV; raises :class:`CsvFormatError` with a one-line reason."""
    path = Path(path)
    _, rows = _rows(path, GROUND_TRUTH_COLUMNS)
    out = []
    for lineno, row in enumerate(rows, start=2):
        cams = tuple(c for c in (row['visible_cameras'] or '').split(';') if c)
        out.append(GroundTruthRow(
            stamp_ns=_parse(path, lineno, row['stamp_ns'], int, 'stamp_ns'),
            frame=_parse(path, lineno, row['frame'], int, 'frame'),
            person_id=_parse(path, lineno, row['person_id'], int, 'person_id'),
            x=_parse(path, lineno, row['x'], float, 'x'),
            y=_parse(path, lineno, row['y'], float, 'y'),
            z_head=_parse(path, lineno, row['z_head'], float, 'z_head'),
            sitting=bool(_parse(path, lineno, row['sitting'], int, 'sitting')),
            visible_cameras=cams))
    return out


def write_ground_truth(path: str | Path, rows: Iterable[GroundTruthRow]) -> None:
    """Write a ground-truth CSV."""
    with Path(path).open('w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(GROUND_TRUTH_COLUMNS)
        for r in rows:
            writer.writerow([r.stamp_ns, r.frame, r.person_id, f'{r.x:.4f}', f'{r.y:.4f}',
                             f'{r.z_head:.4f}', int(r.sitting), ';'.join(r.visible_cameras)])
