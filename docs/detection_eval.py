"""Identity-switch analysis of automatic detection on a recording (docs/detection.md).

    .venv/bin/python docs/detection_eval.py run REC OUT [--seed S] [--no-people-cue]
                                                 [--params NODE.yaml] [--exit-rescue C]
    .venv/bin/python docs/detection_eval.py report OUT REC            # causes of switches
    .venv/bin/python docs/detection_eval.py table OUT REC [OUT REC]   # one row per run
    .venv/bin/python docs/detection_eval.py lag OUT REC [OUT REC]     # track-person distance
    .venv/bin/python docs/detection_eval.py decisions OUT REC [OUT REC]  # moves right?
    .venv/bin/python docs/detection_eval.py exits OUT REC [OUT REC]    # premature exits?
    .venv/bin/python docs/detection_eval.py releases OUT REC [OUT REC]  # late releases: why?
    .venv/bin/python docs/detection_eval.py suite OUT [--seeds 0 1 3] [--recordings cr1 ...]
                     [--jobs 2] [--frames N] [run options]   # the whole issue-4 benchmark

``suite`` is the one command behind the score tables of docs/detection.md: it renders the
clear-room recordings it is missing (``crS``: ``mbtrack synth clear-room --seed S``,
``crncS``: the same with ``--no-ceiling``) into OUT/rec, runs every recording with every
tracker seed into OUT/runs/REC_sS (``--jobs`` at a time, with progress; runs that finished
before are kept, so an interrupted suite resumes), and writes OUT/table.md (``table`` and
``totals``), OUT/scores.json and OUT/scores.png (MOTA and identity switches per person of
each run against the issue's targets).

``run`` steps :class:`~mbtrack_ros.core.tracker.Tracker` with ``detection=True`` exactly as
``mbtrack replay REC --out OUT --eval REC/ground_truth.csv --seed S`` does (same
configuration, same random generator, so the same tracks.csv) and also writes
OUT/events.json: every birth, every release with its reason (exit, support, spare,
existence, duplicate), every decision on a confirmed detection next to a track
(``AutoDetection.decisions``: birth / move / drop, with the appearance gain) and every
move of the opt-in ``catch_up`` (``AutoDetection.catch_ups``: id, place, gain).
``report`` lists, per identity switch of the CLEAR MOT matching, the person, the old and
new track, where the old track was, how it ended and where the new one was born; the
false births (farther than 0.5 m from every person; door and screen flagged) and the
entering / release latencies. ``table`` prints the rows of docs/detection.md. ``lag`` gives
the distance from each ground-truth person to the nearest reported track (all frames, and
for people walking faster than 1 m/s the lag along the walking direction) and, per switch,
whether the old track was reported at the switch frame (not: hidden or ended).
``decisions`` checks each move, hidden move, id reuse (``reuse before a move``: a lost
track's id given back instead of a move, ``reuse_before_moving``) and drop of the identity
check, and each ``catch_up`` move, against the ground truth: was the person at the
detection the one the track (for a reuse: the released track) was matched to in the 15
matched frames before (same / other / unmatched: the track followed nobody)? With
``reuse_time`` it also gives the appearance distance (``appearance.model_distance``) of
every released track a detection could have taken the id of, by whether that track had
been the same person, and lists each one of another person (or of nobody) within 0.05 of
the ``reuse_distance`` gate or under it (run, frame, floor distance, appearance distance,
what the detection became), the appearance distances of the tracks near each birth or
reuse by whether they had followed the detected person, and each track ``move_distance``
kept from a move (whether it had followed the detected person, its gain and appearance
distance, what the detection became); the appearance distances of the moves and kept-back
tracks whose gain lay in the doubtful band of ``move_distance``, by label; and each move
of the opt-in beside rule (``beside_support``) with how far the track was from the
detection, by label.
``exits`` tells, per release by the exit rule, whether the track's person was still in
the room afterwards (premature).
"""
from __future__ import annotations

import argparse
from concurrent.futures import ThreadPoolExecutor, as_completed
import contextlib
from dataclasses import replace
import io
import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection.background import BackgroundBank
from mbtrack_ros.core.detection.detector import is_ceiling
from mbtrack_ros.core.detection import release as release_module
from mbtrack_ros.core.detection.manager import AutoDetectionConfig
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.commands.replay import tracker_values_from_params
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.evaluation.clear_mot import clear_mot
from mbtrack_ros.recording.bag import RecordingReader
from mbtrack_ros.recording.csvfiles import (
    CsvFormatError, GroundTruthRow, TrackRow, read_ground_truth, read_tracks, write_tracks)

FPS = 15.0
FLOOR = (0.3, 0.3, 5.7, 4.7)          # the clear-room walkable floor (calibration.yaml)


def _door(x: float, y: float) -> bool:
    return y > 4.2 and 4.0 < x < 5.3


def _screen(x: float, y: float) -> bool:
    return x > 5.2 and 1.4 < y < 3.6


def run(rec: Path, out: Path, seed: int, no_people_cue: bool = False,
        release: dict[str, float] | None = None, params: Path | None = None,
        exit_rescue: float | None = None,
        detection: dict[str, float] | None = None, frames: int | None = None) -> None:
    """Track ``rec`` with automatic detection (the tracker settings of a tracker_node
    parameter file ``params`` if given, as ``mbtrack replay --params``) into ``out``
    (``exit_rescue`` and ``detection``: those ``AutoDetectionConfig`` fields instead of
    their defaults, e.g. ``{'beside_support': 0.25}``; ``frames``: only the first frame
    sets, scored against the ground truth of those frames)."""
    out.mkdir(parents=True, exist_ok=True)
    cal = RoomCalibration.load(rec / 'calibration.yaml')
    events: list[dict] = []
    frame = {'index': 0}
    update, duplicates = release_module.Releaser.update, release_module.Releaser.duplicates
    exited = release_module.Releaser.exited

    def logged_exited(self, ids, xy):
        ended = exited(self, ids, xy)
        events.extend({'kind': 'end', 'frame': frame['index'], 'id': int(t),
                       'reason': 'exit'} for t in ended)
        return ended

    def logged_update(self, stamp, ids, supported, existence=None, doorway=None, spare=None):
        ended = update(self, stamp, ids, supported, existence, doorway, spare)
        flags = self.spare if spare is None else spare      # aligned with ids when given
        for tid in ended:
            k = list(ids).index(tid)
            was_spare = k < len(flags) and flags[k]
            events.append({'kind': 'end', 'frame': frame['index'], 'id': int(tid),
                           'reason': 'spare' if was_spare else 'support' if not supported[k]
                           else 'existence',
                           'doorway': bool(doorway is not None and doorway[k])})
        return ended

    def logged_duplicates(self, stamp, ids, xy, *args, **kwargs):
        ended = duplicates(self, stamp, ids, xy, *args, **kwargs)
        events.extend({'kind': 'end', 'frame': frame['index'], 'id': int(t),
                       'reason': 'duplicate'} for t in ended)
        return ended

    release_module.Releaser.update = logged_update
    release_module.Releaser.duplicates = logged_duplicates
    release_module.Releaser.exited = logged_exited
    rows: list[TrackRow] = []
    seen: list[str] = []            # OUT/visibility.csv: the posterior xi_v per camera
    with RecordingReader(rec / 'bag') as reader:
        cal = cal.subset([n for n in cal.names if n in reader.cameras])
        values = tracker_values_from_params(params) if params is not None else {}
        tracker = Tracker(cal, TrackerConfig.from_dict({**values, 'seed': seed,
                                                        'detection': True}))
        if exit_rescue is not None:
            det = tracker.detection
            det.config = replace(det.config, exit_rescue=exit_rescue)
        if detection:  # opt-in identity rules of AutoDetectionConfig, e.g. beside_support
            det = tracker.detection
            det.config = replace(det.config, **detection)
        if release:  # ReleaseConfig fields overridden, e.g. spare_support=0 (no spare rule)
            det = tracker.detection
            det.releaser = release_module.Releaser(tracker.calibration,  # the working size
                                                   replace(det.releaser.config, **release))
        if no_people_cue:  # the bootstrap before issue 6: every pixel learnt, 10 x 4 frames
            bg = replace(tracker.detection.config.background, people=None,
                         bootstrap_frames=10, bootstrap_stride=4)
            tracker.detection.background = BackgroundBank(bg, calibration=tracker.calibration)
        live: set[int] = set()
        for fs in reader.frames():
            if frames is not None and fs.index >= frames:
                break
            frame['index'] = fs.index
            result = tracker.step(fs.stamp_ns, {c: im for c, im in fs.images.items()
                                                if c in cal.cameras})
            for d in tracker.detection.decisions:
                events.append({'kind': 'decision', 'frame': fs.index, **d})
            for a in getattr(tracker.detection, 'adaptations', []):  # h-adapt's decisions
                events.append({'kind': 'adapt', 'frame': fs.index, **a})
            for c in getattr(tracker.detection, 'duplicate_checks', []):
                events.append({'kind': 'duplicate_check', 'frame': fs.index, **c})
            for c in getattr(tracker.detection, 'catch_ups', []):   # catch_up's moves
                events.append({'kind': 'catch_up', 'frame': fs.index, **c})
            for c in getattr(tracker.detection, 'exit_checks', []):  # h-reid's exit rescue
                events.append({'kind': 'exit_check', 'frame': fs.index, **c})
                if c['rescued']:      # the exit rule named it, the rescue kept it
                    events[:] = [e for e in events if not (
                        e['kind'] == 'end' and e['frame'] == fs.index and e['id'] == c['id']
                        and e['reason'] == 'exit')]
            for tid in sorted(set(tracker.track_ids) - live):   # new, or a released id reused
                events.append({'kind': 'birth', 'frame': fs.index, 'id': int(tid)})
            live = set(tracker.track_ids)
            seen.extend(f'{fs.index},{t.track_id},{n},{v:.4f}' for t in result.tracks
                        for n, v in sorted(t.visibility.items()))
            rows.extend(TrackRow(stamp_ns=fs.stamp_ns, frame=fs.index, track_id=t.track_id,
                                 x=float(t.mean[0]), y=float(t.mean[1]),
                                 existence=t.existence) for t in result.tracks)
    write_tracks(out / 'tracks.csv', rows)
    (out / 'visibility.csv').write_text('\n'.join(['frame,track_id,camera,visibility', *seen])
                                        + '\n', encoding='utf-8')
    (out / 'events.json').write_text(json.dumps(events), encoding='utf-8')
    truth = read_ground_truth(rec / 'ground_truth.csv')
    if frames is not None:
        truth = [g for g in truth if g.frame < frames]
    res = clear_mot(rows, truth)
    print(f'MOTA {100 * res.mota:.1f} % MOTP {res.motp_mm:.0f} mm mismatches '
          f'{res.mismatches} people {res.persons} tracks {res.tracks}')


def _matching(tracks, truth):
    """The CLEAR-MOT matching detail and the frame index of each of its rows."""
    d = clear_mot(tracks, truth).matches_detail
    s0 = min(r.stamp_ns for r in truth)
    return d, np.round((d.stamp_ns.astype(np.int64) - s0) / (1e9 / FPS)).astype(int)


def _load(out: Path, rec: Path):
    tracks = read_tracks(out / 'tracks.csv')
    truth = read_ground_truth(rec / 'ground_truth.csv')
    last = max(t.frame for t in tracks)
    truth = [r for r in truth if r.frame <= last]
    events = json.loads((out / 'events.json').read_text(encoding='utf-8'))
    return tracks, truth, events, last


def _analyse(out: Path, rec: Path) -> dict:
    tracks, truth, events, last = _load(out, rec)
    res = clear_mot(tracks, truth)
    d = res.matches_detail
    ends: dict[int, list] = {}          # id -> its end events (an id can be reused)
    for e in events:
        if e['kind'] == 'end':
            ends.setdefault(e['id'], []).append(e)

    def end_after(tid, f):
        return next((e for e in ends.get(tid, []) if e['frame'] >= f), None)
    gt: dict[int, list] = {}
    for r in truth:
        gt.setdefault(r.frame, []).append(r)
    by_track: dict[int, list] = {}
    for t in tracks:
        by_track.setdefault(t.track_id, []).append(t)
    s0 = min(r.stamp_ns for r in truth)

    def frame_of(stamp):
        return int(round((int(stamp) - s0) / (1e9 / FPS)))

    def nearest(f, x, y, exclude=None):
        best = (np.inf, None)
        for r in gt.get(f, []):
            if r.person_id != exclude and np.hypot(r.x - x, r.y - y) < best[0]:
                best = (float(np.hypot(r.x - x, r.y - y)), r.person_id)
        return best

    cal = RoomCalibration.load(rec / 'calibration.yaml')
    switches, births, enter, enter_seen, leave, causes = [], [], [], [], [], {}
    leave_detail: list[dict] = []      # per release: person, track, frames, end event
    per_person: dict[int, list] = {}
    for r in truth:
        per_person.setdefault(r.person_id, []).append(r)
    for p, prow in per_person.items():
        sel = d.person_id == p
        tid, st = d.track_id[sel], d.stamp_ns[sel]
        prev, prev_f = -1, None
        for k in range(len(tid)):
            if tid[k] < 0:
                continue
            if prev >= 0 and tid[k] != prev:
                f = frame_of(st[k])
                old = [t for t in by_track[prev] if t.frame <= f][-1]
                me = [r for r in gt.get(old.frame, []) if r.person_id == p]
                other = nearest(old.frame, old.x, old.y, exclude=p)
                new0 = by_track[int(tid[k])][0]
                e = end_after(prev, prev_f)
                if f - prev_f > 20 and not me:
                    cause = 'person absent from the ground truth in between'
                elif e is not None and e['frame'] < f - 3:
                    cause = f'old track released ({e["reason"]}) while the person was there'
                elif new0.frame >= f - 30:
                    cause = 'new track born beside the live old track'
                else:
                    cause = 'swap between two live tracks'
                causes[cause] = causes.get(cause, 0) + 1
                switches.append(
                    f'person {p} frame {f}: track {prev} -> {tid[k]}; old track '
                    f'{np.hypot(me[0].x - old.x, me[0].y - old.y) if me else np.nan:.2f} m '
                    f'from the person, {other[0]:.2f} m from person {other[1]}, '
                    f'{"ended f%d (%s)" % (e["frame"], e["reason"]) if e else "alive"}; '
                    f'new track born f{new0.frame} [{cause}]')
            prev, prev_f = int(tid[k]), frame_of(st[k])
        prow.sort(key=lambda r: r.frame)
        m = np.flatnonzero(tid >= 0)
        if prow[0].frame > 0 and m.size:
            enter.append((frame_of(st[m[0]]) - prow[0].frame) / FPS)
            # the issue's wording: from the first frame the person is fully visible in two
            # cameras (people who never are, e.g. in a crowd at the door, are left out)
            seen = _fully_visible_from(cal, gt, prow)
            if seen is not None:
                enter_seen.append((frame_of(st[m[0]]) - seen) / FPS)
        # the synth generator before h-exit wrote one last row of a person who left at the
        # floor edge about 2 s after they crossed the wall (a frame gap before it): not
        # where the person left the floor
        walked = prow[:-1] if len(prow) > 1 and prow[-1].frame - prow[-2].frame > 1 else prow
        floor = [r.frame for r in walked if FLOOR[0] <= r.x <= FLOOR[2]
                 and FLOOR[1] <= r.y <= FLOOR[3]]
        if prow[-1].frame < last - 30 and floor:
            tail = tid[-30:]
            tail = tail[tail >= 0]
            follower = int(np.bincount(tail).argmax()) if tail.size else -1
            e = end_after(follower, frame_of(st[-30:][0])) if tail.size else None
            if e:
                leave.append((e['frame'] - floor[-1]) / FPS)
                leave_detail.append({'person': int(p), 'track': follower, 'left': floor[-1],
                                     'gone': walked[-1].frame + 1, 'end': e})
    for tid, rows in sorted(by_track.items()):
        r0 = rows[0]
        dist, pid = nearest(r0.frame, r0.x, r0.y)
        if dist > 0.5:
            e = end_after(tid, r0.frame)
            births.append({'track': tid, 'frame': r0.frame, 'xy': (r0.x, r0.y),
                           'person': pid, 'distance': dist, 'life': rows[-1].frame
                           - r0.frame + 1, 'end': e['reason'] if e else 'alive',
                           'door': _door(r0.x, r0.y), 'screen': _screen(r0.x, r0.y)})
    moves = sum(1 for e in events if e['kind'] == 'decision'
                and e['action'].startswith('move'))
    return {'result': res, 'switches': switches, 'false_births': births, 'enter': enter,
            'enter_seen': enter_seen, 'leave': leave, 'leave_detail': leave_detail, 'moves': moves,
            'causes': causes}


def report(out: Path, rec: Path) -> None:
    a = _analyse(out, rec)
    res = a['result']
    print(f'MOTA {100 * res.mota:.1f} % MOTP {res.motp_mm:.0f} mm mismatches '
          f'{res.mismatches} people {res.persons} tracks {res.tracks} moves {a["moves"]}')
    for s in a['switches']:
        print('  switch', s)
    for cause, n in sorted(a['causes'].items(), key=lambda c: -c[1]):
        print(f'  {n:3d} x {cause}')
    for b in a['false_births']:
        print(f'  false birth: track {b["track"]} f{b["frame"]} at ({b["xy"][0]:.2f}, '
              f'{b["xy"][1]:.2f}), {b["distance"]:.2f} m from person {b["person"]}, '
              f'{b["life"]} frames, {b["end"]}'
              f'{" DOOR" if b["door"] else ""}{" SCREEN" if b["screen"] else ""}')
    print('  entering (s):', ' '.join(f'{v:.2f}' for v in a['enter']))
    print('  entering, from fully visible in two cameras (s):',
          ' '.join(f'{v:.2f}' for v in a['enter_seen']))
    print('  release after leaving the floor (s):', ' '.join(f'{v:.2f}' for v in a['leave']))


def table(pairs: list[tuple[Path, Path]], analysed: list[dict] | None = None) -> None:
    """One row per run (``analysed``: the runs' :func:`_analyse` results, if at hand)."""
    print('| run | MOTA | MOTP | miss | false pos | mismatches / people | tracks | moves | '
          'false births (door, screen) | entering s | release s |')
    print('| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |')

    def span(v):
        return f'{min(v):.2f}-{max(v):.2f}' if v else '-'

    for (out, rec), a in zip(pairs, analysed or (_analyse(o, r) for o, r in pairs)):
        r = a['result']
        fb = a['false_births']
        print(f'| {out.name} | {100 * r.mota:.1f} % | {r.motp_mm:.0f} mm | '
              f'{100 * r.miss_rate:.1f} % | {100 * r.false_positive_rate:.1f} % | '
              f'{r.mismatches} / {r.persons} = {r.mismatches / r.persons:.2f} | {r.tracks} | '
              f'{a["moves"]} | {len(fb)} ({sum(b["door"] for b in fb)}, '
              f'{sum(b["screen"] for b in fb)}) | {span(a["enter"])} | {span(a["leave"])} |')


def totals(pairs: list[tuple[Path, Path]], analysed: list[dict] | None = None) -> None:
    """One line over all runs: mean MOTA, misses, false positives and mismatches summed,
    release delays (> 1.5 s, > 5 s, median) and the longest release per recording; the
    release delays again from the person's last ground-truth row; the entering delays."""
    runs = [a | {'rec': rec.name} for (_, rec), a in
            zip(pairs, analysed or [_analyse(o, r) for o, r in pairs])]
    res = [a['result'] for a in runs]
    leave = sorted(v for a in runs for v in a['leave'])
    longest: dict[str, float] = {}
    for a in runs:
        longest[a['rec']] = max([longest.get(a['rec'], -np.inf), *a['leave']])
    median = f'{np.median(leave):.2f} s' if leave else '-'
    print(f'{len(runs)} runs: mean MOTA {100 * np.mean([r.mota for r in res]):.2f} %, misses '
          f'{sum(r.misses for r in res)}, false pos {sum(r.false_positives for r in res)}, '
          f'mismatches {sum(r.mismatches for r in res)}; releases {len(leave)}: > 1.5 s '
          f'{sum(v > 1.5 for v in leave)}, > 5 s {sum(v > 5 for v in leave)}, median {median}; '
          'longest per recording ' + ', '.join(
              f'{k} {v:.1f} s' if np.isfinite(v) else f'{k} -' for k, v in longest.items()))
    # the same releases counted from the person's last ground-truth row (through the wall:
    # the exit's strip between the floor's edge and the wall is still the room)
    gone = sorted((d['end']['frame'] - (d['gone'] - 1)) / FPS
                  for a in runs for d in a['leave_detail'])
    if gone:
        print(f'releases from the last ground-truth row: {len(gone)}, > 1.5 s '
              f'{sum(v > 1.5 for v in gone)}, before it {sum(v < 0 for v in gone)}, median '
              f'{np.median(gone):.2f} s')
    for key, what in (('enter', 'from the first ground-truth row'),
                      ('enter_seen', 'from fully visible in two cameras')):
        v = sorted(x for a in runs for x in a[key])
        if v:
            print(f'entering {what}: {len(v)} people, median {np.median(v):.2f} s, '
                  f'> 0.5 s {sum(x > 0.5 for x in v)}, max {max(v):.2f} s')


def spares(pairs: list[tuple[Path, Path]]) -> None:
    """Each release by the spare-track rule against the CLEAR-MOT matching of the track in
    the second (15 frames) before: matched to a person in more than 10 of them, in some, or
    in none (a track that followed nobody, which the rule should end)."""
    total: dict[str, int] = {}
    for out, rec in pairs:
        tracks, truth, events, _ = _load(out, rec)
        d, frames = _matching(tracks, truth)
        matched = {(int(f), int(t)) for f, t, p in zip(frames, d.track_id, d.person_id)
                   if t >= 0 and p >= 0}
        found = []
        for e in events:
            if e['kind'] == 'end' and e['reason'] == 'spare':
                n = sum((g, e['id']) in matched for g in range(e['frame'] - 15, e['frame']))
                kind = 'matched' if n > 10 else 'partly matched' if n else 'unmatched'
                total[kind] = total.get(kind, 0) + 1
                found.append(f"{e['id']}@{e['frame']}: {kind}")
        print(f'{out.name}: ' + (', '.join(found) or 'no spare releases'))
    print('total:', ', '.join(f'{k} {v}' for k, v in sorted(total.items())) or 'none')


def exits(pairs: list[tuple[Path, Path]]) -> None:
    """Each release by the exit rule against the person its track was matched to in the
    second (15 frames) before: ``premature`` when that person is still in the ground truth
    in at least 10 of the 15 frames after it (they stood at the door), ``left`` when not,
    ``nobody`` when the track was matched to no one (its person had gone already)."""
    total: dict[str, int] = {}
    for out, rec in pairs:
        tracks, truth, events, _ = _load(out, rec)
        d, frames = _matching(tracks, truth)
        present = {(r.frame, r.person_id) for r in truth}
        found = []
        for e in events:
            if e['kind'] != 'end' or e['reason'] != 'exit':
                continue
            f = e['frame']
            kind, p = end_class(d, frames, present, e['id'], f)
            total[kind] = total.get(kind, 0) + 1
            if kind == 'premature':
                found.append(f"{e['id']}@{f} (person {p})")
        print(f'{out.name}: premature ' + (', '.join(found) or 'none'))
    print('total:', ', '.join(f'{k} {v}' for k, v in sorted(total.items())) or 'none')


def end_class(d, frames: np.ndarray, present: set, track_id: int, frame: int
              ) -> tuple[str, int]:
    """(class, person) of a track's end at ``frame``: the person it was matched to in the
    15 frames before (-1 for none) and ``premature`` when they are in the ground truth
    (``present``: (frame, person) pairs) in at least 10 of the 15 frames after, ``left``
    when not, ``nobody`` when the track was matched to no one."""
    sel = (d.track_id == track_id) & (frames >= frame - 15) & (frames < frame) \
        & (d.person_id >= 0)
    if not sel.any():
        return 'nobody', -1
    p = int(np.bincount(d.person_id[sel]).argmax())
    n = sum((g, p) in present for g in range(frame + 1, frame + 16))
    return ('premature' if n >= 10 else 'left'), p


RELEASE_CLASSES = ('hidden', 'on another person', 'beside a tracked person', 'alone')


def late_releases(out: Path, rec: Path, late: float = 1.5) -> list[dict]:
    """Each release of a person who left (``report``'s "release after leaving the floor")
    later than ``late`` seconds, with what its track did from the frame the person was
    gone (their last ground-truth row + 1) to its end, frame by frame (h-rel):

    * ``hidden``: the track was not reported (existence below the report level);
    * ``on another person``: the CLEAR-MOT matching gave it to another person;
    * ``beside a tracked person``: reported within 0.6 m of another person who had a
      track of their own;
    * ``alone``: reported, nobody within 0.6 m.

    The class is the most frequent of these. With OUT/probe.csv (docs/diag/release_probe.py)
    also the releaser's view over those frames: median existence, the fraction of frames
    with support and found spare, the median exclusive support and coverage per camera."""
    a = _analyse(out, rec)
    tracks, truth, _, _ = _load(out, rec)
    d, frames = _matching(tracks, truth)
    shown = {(t.frame, t.track_id): (t.x, t.y) for t in tracks}
    matched = {(int(f), int(t)): int(p) for f, t, p in zip(frames, d.track_id, d.person_id)
               if t >= 0 and p >= 0}
    tracked = {(f, p) for (f, _), p in matched.items()}
    gt: dict[int, list] = {}
    for r in truth:
        gt.setdefault(r.frame, []).append(r)
    probe = None
    if (out / 'probe.csv').exists():
        probe = np.genfromtxt(out / 'probe.csv', delimiter=',', names=True)
        s0 = min(r.stamp_ns for r in truth)
        probe_frame = np.round((probe['stamp_ns'] - s0) / (1e9 / FPS)).astype(int)
    found = []
    for ld in a['leave_detail']:
        e, tid, p = ld['end'], ld['track'], ld['person']
        delay = (e['frame'] - ld['left']) / FPS
        if delay <= late:
            continue
        count = dict.fromkeys(RELEASE_CLASSES, 0)
        places = []
        for f in range(ld['gone'], e['frame']):
            xy = shown.get((f, tid))
            if xy is None:
                count['hidden'] += 1
                continue
            places.append(xy)
            q = matched.get((f, tid))
            if q is not None and q != p:
                count['on another person'] += 1
                continue
            near = [r.person_id for r in gt.get(f, []) if r.person_id != p
                    and np.hypot(r.x - xy[0], r.y - xy[1]) < 0.6]
            count['beside a tracked person' if any((f, q) in tracked for q in near)
                  else 'alone'] += 1
        row = {'run': out.name, 'person': p, 'track': tid, 'delay': delay,
               'reason': e['reason'], 'frames': e['frame'] - ld['gone'], 'count': count,
               'kind': max(RELEASE_CLASSES, key=count.__getitem__),
               'place': np.median(places, axis=0) if places else (np.nan, np.nan)}
        if probe is not None:
            sel = ((probe['track_id'] == tid) & (probe_frame >= ld['gone'])
                   & (probe_frame < e['frame']))
            cams = [n for n in probe.dtype.names if n.startswith('coverage_')]
            row['probe'] = {
                'existence': float(np.nanmedian(probe['existence'][sel])) if sel.any() else np.nan,
                'supported': float(np.mean(probe['supported'][sel])) if sel.any() else np.nan,
                'spare': float(np.mean(probe['spare'][sel])) if sel.any() else np.nan,
                'exclusive': float(np.nanmedian(probe['exclusive'][sel]))
                if sel.any() and np.isfinite(probe['exclusive'][sel]).any() else np.nan,
                'coverage': {c[9:]: float(np.nanmedian(probe[c][sel])) if sel.any()
                             and np.isfinite(probe[c][sel]).any() else np.nan for c in cams},
                'y': float(np.median(probe['y'][sel])) if sel.any() else np.nan}
        found.append(row)
    return found


def releases(pairs: list[tuple[Path, Path]]) -> None:
    """Every release later than 1.5 s with its class (``late_releases``), then the counts."""
    rows = [r for out, rec in pairs for r in late_releases(out, rec)]
    for r in rows:
        c = r['count']
        text = (f"{r['run']} person {r['person']} track {r['track']}: {r['delay']:.2f} s "
                f"({r['reason']}), {r['kind']}; over {r['frames']} frames hidden "
                f"{c['hidden']}, on another person {c['on another person']}, beside a tracked "
                f"person {c['beside a tracked person']}, alone {c['alone']}; reported at "
                f"({r['place'][0]:.2f}, {r['place'][1]:.2f})")
        pr = r.get('probe')
        if pr:
            text += (f"; existence {pr['existence']:.2f}, supported {pr['supported']:.2f}, "
                     f"spare {pr['spare']:.2f}, exclusive {pr['exclusive']:.2f}, y "
                     f"{pr['y']:.2f}, coverage " + ' '.join(
                         f'{k} {v:.2f}' for k, v in pr['coverage'].items()))
        print(text)
    print('| class | late releases | delay median | longest | ended by (exit, spare, support, '
          'existence, duplicate) |')
    print('| --- | --- | --- | --- | --- |')
    for kind in RELEASE_CLASSES:
        k = [r for r in rows if r['kind'] == kind]
        if not k:
            continue
        by = [sum(r['reason'] == why for r in k)
              for why in ('exit', 'spare', 'support', 'existence', 'duplicate')]
        print(f"| {kind} | {len(k)} | {np.median([r['delay'] for r in k]):.2f} s | "
              f"{max(r['delay'] for r in k):.2f} s | {', '.join(map(str, by))} |")
    print(f'| all | {len(rows)} | | | |')


def lag(pairs: list[tuple[Path, Path]]) -> None:
    print('| run | person-frames | distance median | p90 | > 0.3 m | > 0.5 m | walking > 1 m/s: '
          'median | lag along | switches: old track not reported / reported > 0.5 m off |')
    print('| --- | --- | --- | --- | --- | --- | --- | --- | --- |')
    for out, rec in pairs:
        tracks, truth, _, _ = _load(out, rec)
        at: dict[int, list] = {}
        for t in tracks:
            at.setdefault(t.frame, []).append((t.x, t.y))
        people: dict[int, list] = {}
        for r in truth:
            people.setdefault(r.person_id, []).append((r.frame, r.x, r.y))
        dist, speed, along = [], [], []
        for rows in people.values():
            a = np.array(sorted(rows))
            for i in range(1, len(a) - 1):
                f = int(a[i, 0])
                if a[i + 1, 0] - a[i - 1, 0] != 2 or f not in at:
                    continue
                v = (a[i + 1, 1:] - a[i - 1, 1:]) * FPS / 2.0        # central difference
                d = np.array(at[f]) - a[i, 1:]
                k = int(np.argmin(np.hypot(d[:, 0], d[:, 1])))
                sp = float(np.hypot(*v))
                dist.append(float(np.hypot(*d[k])))
                speed.append(sp)
                along.append(-float(d[k] @ v) / sp if sp > 1.0 else np.nan)
        dist, speed, along = np.array(dist), np.array(speed), np.array(along)
        walk = speed > 1.0
        res = clear_mot(tracks, truth)
        d = res.matches_detail
        s0 = min(r.stamp_ns for r in truth)
        shown = {(t.frame, t.track_id): (t.x, t.y) for t in tracks}
        where = {(r.frame, r.person_id): (r.x, r.y) for r in truth}
        hidden = off = 0
        for p in np.unique(d.person_id):
            sel = d.person_id == p
            prev = -1
            for tid, st in zip(d.track_id[sel], d.stamp_ns[sel]):
                if tid < 0:
                    continue
                if prev >= 0 and tid != prev:
                    f = int(round((int(st) - s0) / (1e9 / FPS)))
                    o = shown.get((f, prev))
                    if o is None:
                        hidden += 1
                    elif np.hypot(o[0] - where[(f, p)][0], o[1] - where[(f, p)][1]) > 0.5:
                        off += 1
                prev = int(tid)
        print(f'| {out.name} | {len(dist)} | {np.median(dist):.3f} m | '
              f'{np.percentile(dist, 90):.3f} m | {100 * np.mean(dist > 0.3):.1f} % | '
              f'{100 * np.mean(dist > 0.5):.1f} % | {np.median(dist[walk]):.3f} m | '
              f'{np.nanmedian(along[walk]):.3f} m | {hidden} / {off} |')


def visibility(pairs: list[tuple[Path, Path]], every: int = 3) -> None:
    """The posterior visibility xi_v of each matched track (OUT/visibility.csv) against how
    much of its person the camera shows (ground truth rasterised with the tracker's shape
    model, nearer people in front, the image border cutting): per class of person-camera
    pair - ``seen`` (>= 90 % of the whole silhouette visible), ``hidden`` (<= 10 %),
    ``partly`` (between) - how often xi_v >= 0.5, standing and sitting apart; every
    ``every``-th frame."""
    total: dict[tuple[str, bool], list[int]] = {}
    for out, rec in pairs:
        tracks, truth, _, _ = _load(out, rec)
        cal = RoomCalibration.load(rec / 'calibration.yaml')
        xi: dict[tuple[int, int], dict[str, float]] = {}
        lines = (out / 'visibility.csv').read_text(encoding='utf-8').splitlines()[1:]
        for line in lines:
            f, t, n, v = line.split(',')
            xi.setdefault((int(f), int(t)), {})[n] = float(v)
        d, frames = _matching(tracks, truth)
        gt: dict[int, list] = {}
        for r in truth:
            gt.setdefault(r.frame, []).append(r)
        counts: dict[tuple[str, bool], list[int]] = {}
        for f, t, p in zip(frames, d.track_id, d.person_id):
            if t < 0 or p < 0 or f % every or (int(f), int(t)) not in xi:
                continue
            me = next(r for r in gt[int(f)] if r.person_id == p)
            shown = _visible_fractions(cal, gt[int(f)], int(p), whole=True)
            for n, v in xi[(int(f), int(t))].items():
                if n not in shown:
                    continue
                kind = 'seen' if shown[n] >= 0.9 else 'hidden' if shown[n] <= 0.1 else 'partly'
                for c in (counts, total):
                    c.setdefault((kind, bool(me.sitting)), [0, 0])
                    c[(kind, bool(me.sitting))][0] += 1
                    c[(kind, bool(me.sitting))][1] += v >= 0.5
        print(out.name, '; '.join(f'{k}{" sitting" if s else ""}: {a} pairs, xi_v >= 0.5 in '
                                  f'{100 * b / a:.0f} %' for (k, s), (a, b) in
                                  sorted(counts.items())))
    print('all', '; '.join(f'{k}{" sitting" if s else ""}: {a} pairs, xi_v >= 0.5 in '
                           f'{100 * b / a:.0f} %' for (k, s), (a, b) in sorted(total.items())))


def _followed(d, frames: np.ndarray, tid: int, f: int) -> int | None:
    """The person track ``tid`` was matched to most in its last 15 matched frames of the 60
    before frame ``f`` (None: matched to nobody); ``d, frames`` from :func:`_matching`."""
    sel = (d.track_id == tid) & (frames < f) & (frames >= f - 60)
    before = d.person_id[sel][-15:]
    return None if not before.size else int(np.bincount(before).argmax())


def nearest_row(people: list[GroundTruthRow], xy) -> GroundTruthRow:
    """The ground-truth row of ``people`` (one frame's) nearest the floor point ``xy``."""
    return min(people, key=lambda r: np.hypot(r.x - xy[0], r.y - xy[1]))


def decision_label(d, frames: np.ndarray, people: list, decision: dict, tid: int) -> str:
    """Whether a detection decision about track ``tid`` concerned the person that track had
    followed: 'same', 'other' or 'unmatched' (the track followed nobody). ``people`` are
    the ground-truth rows of the decision's frame; the detection's person is the one
    nearest its floor point."""
    at = nearest_row(people, decision['xy']).person_id
    who = _followed(d, frames, tid, decision['frame'])
    return 'same' if who == at else 'unmatched' if who is None else 'other'


def decision_track(decision: dict) -> int | None:
    """The track a detection decision of events.json concerned: the one it moved, gave
    back its id or was dropped for (a weak detection's: the nearest track compared); None
    for a birth."""
    words = decision['action'].split()
    if words[0] in ('move', 'reuse'):
        return int(words[1])
    if decision['action'].startswith('drop (weak beside'):
        return int(min(decision['near'], key=lambda n: n[1])[0])
    if decision['action'].startswith('drop (young look-alike'):
        return int(words[-1].rstrip(')'))
    if words[0] == 'drop':          # 'drop (track N placed recently)'
        return int(decision['action'].split('track ')[1].split()[0])
    return None


def _spread(values: list[float]) -> str:
    """'min / quartiles / max' of ``values``, three decimals."""
    return ' / '.join(f'{v:.3f}' for v in np.percentile(values, [0, 25, 50, 75, 100]))


def decisions(pairs: list[tuple[Path, Path]]) -> None:
    total: dict[tuple[str, str], int] = {}
    reuse_distances: dict[str, list[float]] = {}     # label -> appearance distances
    near_gate: list[str] = []       # other people's candidates close to the reuse gate
    gate = AutoDetectionConfig().reuse_distance + 0.05
    compared = 0                    # decisions that reached reuse_before_moving's comparison
    rule_lines: list[str] = []      # those with a lost track near, and reuse_hidden's moves
    kept_back: list[str] = []       # tracks move_distance kept from a move (labelled)
    birth_near: dict[str, list[float]] = {}     # label -> appearance distances
    doubtful: dict[tuple[str, str], list[float]] = {}   # (moved / kept back, label) -> ...
    beside_gaps: dict[str, list[float]] = {}    # label -> metres, beside_support's moves
    beside_lines: list[str] = []    # each of those moves (run, frame, track, label)
    band_low = AutoDetectionConfig().relocate_margin
    weak_below = AutoDetectionConfig().beside_threshold   # moves split at the default
    for out, rec in pairs:
        tracks, truth, events, _ = _load(out, rec)
        d, frames = _matching(tracks, truth)
        gt: dict[int, list] = {}
        for r in truth:
            gt.setdefault(r.frame, []).append(r)
        counts: dict[tuple[str, str], int] = {}
        for e in events:
            if e['kind'] == 'decision' and ('unlike' in e or 'far)' in e['action']):
                compared += 'unlike' in e
                if e.get('reuse') or 'unlike' not in e:
                    moved = (f", track {e['unlike'][0]}'s model {e['unlike'][1]:.3f}, lost "
                             + ', '.join(f'{t} ({m:.2f} m, {u:.3f})' for t, m, u in e['reuse'])
                             if 'unlike' in e else
                             ', {:.2f} m, appearance distance {:.3f}, existence {:.3f}'.format(
                                 *e['far'][1:]) if 'far' in e else '')
                    rule_lines.append(f"  {out.name} frame {e['frame']}: {e['action']}, score "
                                      f"{e['score']:.2f}{moved}")
            # the gain of each track the identity check compared (id -> nats)
            gains = {int(n[0]): n[2] for n in e.get('near', [])}
            if e['kind'] == 'decision' and gt.get(e['frame']) \
                    and e['score'] >= weak_below and gains:
                # every move by a gain in the doubtful band (relocate_margin, 0] and every
                # track move_distance kept back there, with the appearance distance
                # (the moved track's: 'unlike'; a kept-back one's: 'unalike')
                words = e['action'].split()
                cands = [(int(t), u, 'kept back') for t, u in e.get('unalike', [])]
                if words[0] == 'move' and '(' not in e['action'] and 'unlike' in e:
                    cands.append((int(e['unlike'][0]), e['unlike'][1], 'moved'))
                for tid, unlike, what in cands:
                    if band_low < gains.get(tid, np.nan) <= 0.0:
                        label = decision_label(d, frames, gt[e['frame']], e, tid)
                        doubtful.setdefault((what, label), []).append(float(unlike))
            if e['kind'] == 'decision' and e.get('unalike') and gt.get(e['frame']):
                # move_distance kept these tracks from a move in the doubtful gain band
                for tid, unlike in e['unalike']:
                    label = decision_label(d, frames, gt[e['frame']], e, int(tid))
                    kept_back.append(f"  {out.name} frame {e['frame']}: track {tid} ({label}), "
                                     f"gain {gains.get(int(tid), float('nan')):.2f}, "
                                     f"appearance {unlike:.3f} -> {e['action']}")
            if e['kind'] == 'decision' and e['action'].startswith(('birth', 'reuse')) \
                    and gt.get(e['frame']):
                # appearance distance of each track near a birth (logged since the
                # twenty-fifth session), by whether it had followed the detected person
                for n in e.get('near', []):
                    if len(n) > 3:
                        label = decision_label(d, frames, gt[e['frame']], e, int(n[0]))
                        birth_near.setdefault(label, []).append(float(n[3]))
            if e['kind'] == 'decision' and e.get('reuse') and gt.get(e['frame']):
                # every released track a detection could have taken the id of (reuse_time):
                # its appearance distance to the detection, labelled by who it was
                for tid, dist, unlike in e['reuse']:
                    label = decision_label(d, frames, gt[e['frame']], e, int(tid))
                    reuse_distances.setdefault(label, []).append(float(unlike))
                    if label != 'same' and unlike <= gate:
                        near_gate.append(f"  {out.name} frame {e['frame']}: track {tid} "
                                         f"({label}) {dist:.2f} m from its release, "
                                         f"appearance {unlike:.3f} -> {e['action']}")
            if e['kind'] == 'catch_up' and gt.get(e['frame']):  # catch_up's moves, labelled
                key = ('catch up', decision_label(d, frames, gt[e['frame']], e, int(e['id'])))
                counts[key] = counts.get(key, 0) + 1
                total[key] = total.get(key, 0) + 1
                continue
            words = e['action'].split() if e['kind'] == 'decision' else []
            if not words or words[0] not in ('move', 'drop', 'reuse') or not gt.get(e['frame']):
                continue
            f = e['frame']
            weak = e['action'].startswith('drop (weak beside')
            young = e['action'].startswith('drop (young look-alike')
            tid = decision_track(e)
            label = decision_label(d, frames, gt[f], e, tid)
            kind = words[0] + (' weak' if weak else ' young' if young else
                               ' hidden' if 'hidden' in e['action'] else
                               ' doubtful' if '(doubtful' in e['action'] else
                               ' beside' if 'beside' in e['action'] else
                               ' again' if '(again)' in e['action'] else
                               ' before a move' if '(not' in e['action'] else '')
            if kind == 'move beside':   # how far the moved track was (beside_radius)
                gap = next(n[1] for n in e['near'] if int(n[0]) == tid)
                beside_gaps.setdefault(label, []).append(float(gap))
                beside_lines.append(f'  {out.name} frame {f}: track {tid} ({label}), '
                                    f'{gap:.2f} m, score {e["score"]:.2f}')
            if words[0] == 'move' and kind == 'move':   # the identity check's moves by score
                kind += f' (score < {weak_below:g})' if e['score'] < weak_below \
                    else f' (score >= {weak_below:g})'
            key = (kind, label)
            counts[key] = counts.get(key, 0) + 1
            total[key] = total.get(key, 0) + 1
        print(out.name, ', '.join(f'{k} {v}: {n}' for (k, v), n in sorted(counts.items())))
    print('all', ', '.join(f'{k} {v}: {n}' for (k, v), n in sorted(total.items())))
    for label, values in sorted(reuse_distances.items()):
        print(f'reuse candidates, released track was the {label} person: {len(values)}, '
              f'appearance distance min / quartiles / max {_spread(values)}')
    for label, values in sorted(birth_near.items()):
        print(f'tracks near a birth or reuse that had followed the {label} person: '
              f'{len(values)}, appearance distance min / quartiles / max {_spread(values)}')
    for (what, label), values in sorted(doubtful.items()):
        print(f'gain in ({band_low:g}, 0], {what}, track had followed the {label} person: '
              f'{len(values)}, appearance distances '
              + ', '.join(f'{v:.3f}' for v in sorted(values)))
    for label, values in sorted(beside_gaps.items()):
        print(f'moves beside a track (beside_support), track had followed the {label} person: '
              f'{len(values)}, metres from the detection '
              + ', '.join(f'{v:.2f}' for v in sorted(values)))
    if beside_lines:
        print('\n'.join(beside_lines))
    print(f'{compared} decisions compared the model of the track to be moved with the lost '
          f"tracks' (reuse_before_moving); those with a lost track within reuse_radius, and "
          f'the far hidden and doubtful moves (reuse_hidden, reuse_doubtful):')
    print('\n'.join(rule_lines))
    if kept_back:
        print(f'{len(kept_back)} tracks kept from a move by move_distance (label: the person '
              f'the track had followed, against the detection\'s):')
        print('\n'.join(kept_back))
    if near_gate:
        print(f'reuse candidates of another person (or nobody) at appearance distance '
              f'<= {gate:.2f}:')
        print('\n'.join(near_gate))


def _visible_fractions(cal: RoomCalibration, people: list, person: int, *,
                       whole: bool = False) -> dict[str, float]:
    """Per corner camera, the fraction of ``person``'s silhouette (ground-truth position,
    head height, sitting) not covered by a nearer person's silhouette.

    With ``whole`` the fraction is of the whole silhouette, the part outside the image
    counting as hidden (``full_area``): 1.0 means the person is fully visible in that
    camera. The ceiling camera is left out: the body model has no view from above."""
    states = np.array([[r.x, r.y, 0.0, 0.0, 0.0, float(r.sitting)] for r in people])
    heights = np.array([r.z_head if np.isfinite(r.z_head) else 1.75 for r in people])
    me = [r.person_id for r in people].index(person)
    out = {}
    for name, cam in cal.cameras.items():
        if is_ceiling(cam):
            continue
        sil = rasterize(cam, states, BodyShape(), heights=heights)
        mine = sil.mask(me) > 0
        if not mine.any():
            if whole:
                out[name] = 0.0
            continue
        nearer = np.zeros_like(mine)
        for k in range(len(people)):
            if k != me and sil.distance[k] < sil.distance[me]:
                nearer |= sil.mask(k) > 0
        seen = (mine & ~nearer).sum()
        out[name] = float(seen / (sil.full_area[me] if whole else mine.sum()))
    return out


FULLY_VISIBLE = 0.9   # fraction of the whole silhouette that counts as "fully visible"


def _fully_visible_from(cal: RoomCalibration, gt: dict[int, list], rows: list) -> int | None:
    """The first frame of a person's ground-truth ``rows`` (in frame order) at which they are
    fully visible (>= FULLY_VISIBLE of the silhouette inside the image and not behind a nearer
    person) in at least two corner cameras: issue #4 times entering from there. None if
    never."""
    for r in rows:
        vis = _visible_fractions(cal, gt[r.frame], r.person_id, whole=True)
        if sum(v >= FULLY_VISIBLE for v in vis.values()) >= 2:
            return r.frame
    return None


def switch_classes(out: Path, rec: Path) -> list[dict]:
    """Each identity switch of the CLEAR-MOT matching (person p at frame f: old track O ->
    new track N), classified by what happened (h-ident):

    * ``a released (REASON)`` / ``a hidden``: O was not reported at f, ended by the releaser
      (support, existence, duplicate, spare) or hidden (existence below the report level);
    * ``b swap``: O reported at f and N older than 2 s: two running tracks exchanged people;
    * ``c relocate``: N was moved onto p, or O moved off p, by the identity check in the
      second before f;
    * ``d birth beside``: O reported at f and N born in the 2 s before f;
    * ``e absent``: p missing from the ground truth in between (a synth artefact).

    With each: how far the old track was from p at its last reported frame, how long p
    went unmatched before the switch, p's walking speed, door (p in the door region), p
    sitting, nearest other person, and the corner cameras where less than half of p's
    silhouette is visible (nearer people in front)."""
    tracks, truth, events, _ = _load(out, rec)
    cal = RoomCalibration.load(rec / 'calibration.yaml')
    d, frames = _matching(tracks, truth)
    gt: dict[int, list] = {}
    for r in truth:
        gt.setdefault(r.frame, []).append(r)
    shown = {(t.frame, t.track_id): (t.x, t.y) for t in tracks}
    where = {(r.frame, r.person_id): (r.x, r.y) for r in truth}
    born = {}
    for e in events:
        if e['kind'] == 'birth':
            born.setdefault(e['id'], []).append(e['frame'])
    moves = [(e['frame'], int(e['action'].split()[1]), e['xy']) for e in events
             if e['kind'] == 'decision' and e['action'].startswith('move')]
    ends = [(e['frame'], e['id'], e['reason']) for e in events if e['kind'] == 'end']
    found = []
    for p in np.unique(d.person_id):
        sel = (d.person_id == p) & (d.track_id >= 0)
        tid, fr = d.track_id[sel], frames[sel]
        for k in range(1, len(tid)):
            if tid[k] == tid[k - 1]:
                continue
            old, new, f, f0 = int(tid[k - 1]), int(tid[k]), int(fr[k]), int(fr[k - 1])
            here = {r.person_id: r for r in gt[f]}
            me = here[p]
            b_new = max([g for g in born.get(new, []) if g <= f], default=-10**6)
            end = next((e for e in ends if e[1] == old and f0 <= e[0] <= f), None)
            moved = [m for m in moves if f - 15 <= m[0] <= f and (
                m[1] == new and np.hypot(m[2][0] - me.x, m[2][1] - me.y) < 0.5
                or m[1] == old and np.hypot(m[2][0] - me.x, m[2][1] - me.y) >= 0.5)]
            if f - f0 > 20 and not any(r.person_id == p for r in gt.get(f0 + 1, [])):
                kind = 'e absent'
            elif moved:
                kind = 'c relocate'
            elif (f, old) not in shown:
                kind = f'a released ({end[2]})' if end else 'a hidden'
            elif b_new >= f - 30:
                kind = 'd birth beside'
            else:
                kind = 'b swap'
            others = [np.hypot(r.x - me.x, r.y - me.y) for q, r in here.items() if q != p]
            seen = [g for g in range(f0, f) if (g, old) in shown and (g, p) in where]
            g = seen[-1] if seen else None       # the old track's last reported frame
            last_off = np.hypot(shown[(g, old)][0] - where[(g, p)][0],
                                shown[(g, old)][1] - where[(g, p)][1]) if g is not None else np.nan
            a = where.get((f - 3, p))
            speed = np.hypot(me.x - a[0], me.y - a[1]) * FPS / 3 if a else np.nan
            vis = _visible_fractions(cal, gt[f], int(p))
            o = shown.get((f, old))
            found.append({
                'run': out.name, 'person': int(p), 'frame': f, 'old': old, 'new': new,
                'kind': kind, 'door': _door(me.x, me.y), 'sitting': bool(me.sitting),
                'nearest': float(min(others, default=np.inf)),
                'occluded': sum(v < 0.5 for v in vis.values()), 'cameras': len(vis),
                'old_off': float(np.hypot(o[0] - me.x, o[1] - me.y)) if o else np.nan,
                'new_age': (f - b_new) / FPS, 'last_off': float(last_off),
                'speed': float(speed), 'gap': (f - f0 - 1) / FPS})
    return found


def classes(pairs: list[tuple[Path, Path]]) -> None:
    """Every switch with its class (``switch_classes``), then counts per class outside and
    at the door, with the people's situation."""
    rows = [s for out, rec in pairs for s in switch_classes(out, rec)]
    for s in rows:
        print(f"{s['run']} person {s['person']} f{s['frame']}: {s['old']} -> {s['new']} "
              f"{s['kind']}{' DOOR' if s['door'] else ''}{' sitting' if s['sitting'] else ''}"
              f", nearest person {s['nearest']:.2f} m, occluded in {s['occluded']}/"
              f"{s['cameras']} cameras, old track {s['old_off']:.2f} m off, new track "
              f"{s['new_age']:.1f} s old; old track last reported {s['last_off']:.2f} m off, "
              f"person unmatched {s['gap']:.2f} s before, walking {s['speed']:.2f} m/s")
    print('| class | switches | at the door | elsewhere: sitting | nearest person < 1 m | '
          'occluded (< 50 % visible) in >= 1 / >= 2 corner cameras |')
    print('| --- | --- | --- | --- | --- | --- |')
    for kind in sorted({s['kind'] for s in rows}):
        k = [s for s in rows if s['kind'] == kind]
        away = [s for s in k if not s['door']]
        print(f"| {kind} | {len(k)} | {sum(s['door'] for s in k)} | "
              f"{sum(s['sitting'] for s in away)} | {sum(s['nearest'] < 1 for s in away)} | "
              f"{sum(s['occluded'] >= 1 for s in away)} / "
              f"{sum(s['occluded'] >= 2 for s in away)} |")
    print(f'| all | {len(rows)} | {sum(s["door"] for s in rows)} | | | |')
    lost = [s for s in rows if s['kind'].startswith('a') and not s['door']]
    if lost:
        q = lambda key: ' / '.join(f'{v:.2f}' for v in np.nanpercentile(   # noqa: E731
            [s[key] for s in lost], [25, 50, 75]))
        print(f'class a away from the door ({len(lost)}), quartiles: old track last reported '
              f'{q("last_off")} m off the person, person unmatched {q("gap")} s before the '
              f'switch, walking {q("speed")} m/s at the switch')


SUITE_RECORDINGS = ('cr1', 'cr2', 'cr3', 'crnc1', 'crnc2', 'crnc3')
MOTA_TARGET, SWITCH_TARGET = 0.85, 0.1     # issue 4: MOTA >= 85 %, <= 0.1 switches/person


def synth_args(name: str) -> list[str]:
    """``mbtrack synth`` arguments of a suite recording: ``crS`` is clear-room with random
    seed S and the ceiling camera, ``crncS`` the same without it."""
    m = re.fullmatch(r'(crnc|cr)(\d+)', name)
    if m is None:
        raise ValueError(f'{name}: a suite recording is crS or crncS (S a seed), e.g. cr1')
    return ['clear-room', '--seed', m[2]] + (['--no-ceiling'] if m[1] == 'crnc' else [])


def suite(out: Path, seeds: list[int], recordings: list[str], jobs: int = 2,
          frames: int | None = None, run_args: list[str] = ()) -> int:
    """Render the missing recordings, run each with each seed (``run_args``: options of
    ``run``), write the tables, scores.json and scores.png; returns an exit code."""
    rec_root, runs_root = out / 'rec', out / 'runs'
    for name in recordings:
        rec = rec_root / name
        if (rec / 'ground_truth.csv').exists():
            continue
        shutil.rmtree(rec, ignore_errors=True)           # a render cut short
        print(f'rendering {name} (mbtrack synth {" ".join(synth_args(name))}) ...', flush=True)
        preset, *options = synth_args(name)
        cmd = [sys.executable, '-m', 'mbtrack_ros.cli', 'synth', preset, str(rec), *options]
        proc = subprocess.run(cmd + (['--frames', str(frames)] if frames else []),
                              capture_output=True, text=True)
        if proc.returncode:
            print(f'detection_eval suite: rendering {name} failed: '
                  f'{(proc.stderr or proc.stdout).strip().splitlines()[-1:]}', file=sys.stderr)
            return 1
    todo = [(name, seed) for seed in seeds for name in recordings]

    def one(job: tuple[str, int]) -> tuple[str, float]:
        name, seed = job
        dest = runs_root / f'{name}_s{seed}'
        if (dest / 'events.json').exists():              # written last by run()
            return 'kept', 0.0
        start = time.monotonic()
        proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), 'run',
                               str(rec_root / name), str(dest), '--seed', str(seed),
                               *run_args], capture_output=True, text=True)
        if proc.returncode:
            lines = (proc.stderr or proc.stdout).strip().splitlines()
            raise RuntimeError(lines[-1] if lines else f'exit code {proc.returncode}')
        return 'ran', time.monotonic() - start

    failed = 0
    analysed: dict[tuple[str, int], dict] = {}     # each run's _analyse, made once
    with ThreadPoolExecutor(max(1, jobs)) as pool:
        futures = {pool.submit(one, job): job for job in todo}
        for k, fut in enumerate(as_completed(futures), 1):
            name, seed = futures[fut]
            try:
                how, took = fut.result()
            except RuntimeError as err:
                failed += 1
                print(f'[{k}/{len(todo)}] {name} seed {seed}: failed: {err}', flush=True)
                continue
            analysed[name, seed] = _analyse(runs_root / f'{name}_s{seed}', rec_root / name)
            r = analysed[name, seed]['result']
            print(f'[{k}/{len(todo)}] {name} seed {seed}: {how}'
                  + (f' in {took:.0f} s' if how == 'ran' else '')
                  + f', MOTA {100 * r.mota:.1f} %, {r.mismatches} switches for '
                  f'{r.persons} people', flush=True)
    if failed:
        print(f'detection_eval suite: {failed} of {len(todo)} runs failed', file=sys.stderr)
        return 1
    pairs = [(runs_root / f'{name}_s{seed}', rec_root / name) for name, seed in todo]
    ordered = [analysed[job] for job in todo]
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        table(pairs, ordered)
        print()
        totals(pairs, ordered)
    (out / 'table.md').write_text(text.getvalue(), encoding='utf-8')
    scores = []
    for (name, seed), a in zip(todo, ordered):
        r = a['result']
        scores.append({'recording': name, 'seed': seed, 'mota': r.mota, 'motp_mm': r.motp_mm,
                       'mismatches': r.mismatches, 'people': r.persons, 'tracks': r.tracks,
                       'switches_per_person': r.mismatches / r.persons})
    (out / 'scores.json').write_text(json.dumps({'run_args': list(run_args), 'runs': scores},
                                                indent=1), encoding='utf-8')
    plot_scores(scores, out / 'scores.png')
    print(text.getvalue().rstrip())
    met = sum(s['mota'] >= MOTA_TARGET for s in scores), \
        sum(_meets_switch_target(s['switches_per_person']) for s in scores)
    print(f'targets: MOTA >= {100 * MOTA_TARGET:.0f} % on {met[0]} of {len(scores)} runs, '
          f'<= {SWITCH_TARGET} switches per person on {met[1]} of {len(scores)}; '
          f'{out / "table.md"}, {out / "scores.png"}')
    return 0


def _meets_switch_target(per_person):
    """At most SWITCH_TARGET switches per person (1 of 10 people counts as 0.1)."""
    return np.asarray(per_person) <= SWITCH_TARGET + 1e-9


def plot_scores(scores: list[dict], path: Path) -> None:
    """Two bar charts, one bar per run grouped by recording: MOTA and identity switches per
    person, each with the issue's target as a dashed line."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(max(6.0, 0.45 * len(scores) + 2), 5.5), dpi=100,
                 layout='constrained')
    FigureCanvasAgg(fig)
    ordered = sorted(scores, key=lambda s: (s['recording'], s['seed']))
    names = [f"{s['recording']} s{s['seed']}" for s in ordered]
    x = np.arange(len(ordered))
    for k, (key, scale, target, label) in enumerate((
            ('mota', 100.0, 100 * MOTA_TARGET, 'MOTA (%)'),
            ('switches_per_person', 1.0, SWITCH_TARGET, 'identity switches per person'))):
        ax = fig.add_subplot(2, 1, k + 1)
        v = np.array([s[key] * scale for s in ordered])
        good = v >= target if key == 'mota' else _meets_switch_target(v)
        ax.bar(x, v, color=np.where(good, 'tab:green', 'tab:red'))
        ax.axhline(target, color='k', ls='--', lw=1, label=f'target {target:g}')
        ax.set_ylabel(label)
        ax.set_xticks(x, names if k else [''] * len(x), rotation=60, ha='right', fontsize=8)
        ax.legend(loc='upper right', fontsize=8)
        if key == 'mota':
            ax.set_ylim(max(0.0, min(v.min() - 5, target - 10)), 100)
    fig.suptitle(f'automatic detection on clear-room: {len(ordered)} runs')
    fig.savefig(path)


def _scalar_fields(option: str, config: type, values: dict[str, float]) -> dict:
    """``values`` (field -> number from FIELD=VALUE) as the scalar fields of dataclass
    ``config`` take them: a number for a float field, a whole number for an int field, 0 or
    1 for a switch (bool field); ValueError naming ``option`` for any other field or
    value (nested configs, tuples, unknown names)."""
    fields = config.__dataclass_fields__
    out: dict = {}
    for k, v in values.items():
        kind = fields[k].type if k in fields else None
        if kind not in ('float', 'int', 'bool'):
            raise ValueError(f'{option}: {k} is not a scalar {config.__name__} field')
        if kind == 'bool' and v not in (0.0, 1.0):
            raise ValueError(f'{option}: {k} is a switch, give 0 or 1, got {v:g}')
        if kind == 'int' and v != int(v):
            raise ValueError(f'{option}: {k} is a whole number, got {v:g}')
        out[k] = bool(v) if kind == 'bool' else int(v) if kind == 'int' else v
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest='cmd', required=True)
    r = sub.add_parser('run')
    r.add_argument('rec', type=Path)
    r.add_argument('out', type=Path)
    r.add_argument('--seed', type=int, default=0)
    r.add_argument('--no-people-cue', action='store_true',
                   help='background bootstrap without the people cue (10 frames, stride 4)')
    s = sub.add_parser('report')
    s.add_argument('out', type=Path)
    s.add_argument('rec', type=Path)
    t = sub.add_parser('table')
    t.add_argument('pairs', type=Path, nargs='+')
    for name in ('lag', 'decisions', 'totals', 'spares', 'classes', 'exits', 'releases',
                 'visibility'):
        sub.add_parser(name).add_argument('pairs', type=Path, nargs='+')
    r.add_argument('--params', type=Path, default=None, metavar='NODE.yaml',
                   help='tracker settings of a tracker_node parameter file (config/*.yaml)')
    r.add_argument('--release', action='append', default=[], metavar='FIELD=VALUE',
                   help='override a scalar ReleaseConfig field (repeatable; a switch takes '
                        '0 or 1), e.g. spare_support=0')
    r.add_argument('--exit-rescue', type=float, default=None, metavar='COVERAGE',
                   help='AutoDetectionConfig.exit_rescue (h-reid; 0 = off, the default)')
    r.add_argument('--detection', action='append', default=[], metavar='FIELD=VALUE',
                   help='override a scalar AutoDetectionConfig field (repeatable; a switch '
                        'takes 0 or 1), e.g. beside_support=0.25')
    r.add_argument('--frames', type=int, default=None, metavar='N',
                   help='only the first N frame sets (a quick look; the other commands '
                        'read the whole ground truth)')
    r.add_argument('--check-only', action='store_true', help=argparse.SUPPRESS)
    u = sub.add_parser('suite', help='render the clear-room recordings, run them all, '
                                     'write table.md, scores.json and scores.png')
    u.add_argument('out', type=Path)
    u.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 3])
    u.add_argument('--recordings', nargs='+', default=list(SUITE_RECORDINGS),
                   metavar='crS|crncS')
    u.add_argument('--jobs', type=int, default=2, help='runs at a time (default 2)')
    u.add_argument('--frames', type=int, default=None,
                   help='frames per rendered recording (default the preset\'s 1800)')
    args, extra = p.parse_known_args(argv)
    if args.cmd == 'suite':
        for name in args.recordings:
            try:
                synth_args(name)
            except ValueError as err:
                p.error(str(err))
        if extra:       # options of run, checked by run's own parser first (exit 2)
            main(['run', 'REC', 'OUT', *extra, '--check-only'])
        return suite(args.out, args.seeds, args.recordings, args.jobs, args.frames, extra)
    if extra:
        p.error(f'unrecognized arguments: {" ".join(extra)}')
    if args.cmd == 'run':
        try:
            release = {k: float(v) for k, v in (a.split('=', 1) for a in args.release)}
            detection = {k: float(v) for k, v in (a.split('=', 1) for a in args.detection)}
        except ValueError:
            p.error(f'--release and --detection need FIELD=NUMBER, got '
                    f'{args.release + args.detection}')
        try:
            release = _scalar_fields('--release', release_module.ReleaseConfig, release)
            detection = _scalar_fields('--detection', AutoDetectionConfig, detection)
        except ValueError as err:
            p.error(str(err))
        if args.check_only:   # suite's check of the run options it passes on
            return 0
        run(args.rec, args.out, args.seed, args.no_people_cue, release, args.params,
            args.exit_rescue, detection, args.frames)
        return 0
    if args.cmd != 'report' and len(args.pairs) % 2:
        p.error(f'{args.cmd} needs OUT REC pairs')
    try:
        if args.cmd == 'report':
            report(args.out, args.rec)
        else:
            {'table': table, 'lag': lag, 'decisions': decisions, 'totals': totals,
             'spares': spares, 'classes': classes, 'exits': exits,
             'releases': releases, 'visibility': visibility}[args.cmd](
                list(zip(args.pairs[::2], args.pairs[1::2])))
    except (CsvFormatError, OSError, json.JSONDecodeError) as err:
        # OUT is not a run directory (a suite's OUT holds them in runs/) or REC no recording
        print(f'detection_eval {args.cmd}: {err}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
