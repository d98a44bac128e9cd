"""Shared by the diagnostics: the ``detection_eval.py`` module and the OUT REC pairs of a
command line (for those that read ``run`` outputs), and the tracker stepped over a
recording as ``run`` steps it with its tracks' particle clouds (for those that look inside
it)."""
import importlib.util
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mbtrack_ros.recording.csvfiles import read_ground_truth

_spec = importlib.util.spec_from_file_location(
    'detection_eval', Path(__file__).resolve().parents[1] / 'detection_eval.py')
detection_eval = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(detection_eval)


def pairs(usage: str) -> list[tuple[Path, Path]]:
    """The (OUT, REC) pairs of ``sys.argv``; exits with ``usage`` when there are none."""
    args = [Path(a) for a in sys.argv[1:]]
    if not args or len(args) % 2:
        sys.exit(f'usage: {usage}')
    return list(zip(args[::2], args[1::2]))


def tracked_frames(rec: Path, seed: int, last: int, **config) -> Iterator[tuple]:
    """(frame set, tracker result, tracker) per frame up to frame ``last``: the tracker
    with automatic detection as ``detection_eval.py run`` builds it (same seed; ``config``:
    TrackerConfig values on top, e.g. ``mrf_radius=0.4``)."""
    from mbtrack_ros.core.camera import RoomCalibration
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig
    from mbtrack_ros.recording.bag import RecordingReader

    cal = RoomCalibration.load(rec / 'calibration.yaml')
    with RecordingReader(rec / 'bag') as reader:
        cal = cal.subset([n for n in cal.names if n in reader.cameras])
        tracker = Tracker(cal, TrackerConfig.from_dict({'seed': seed, 'detection': True,
                                                        **config}))
        for fs in reader.frames():
            result = tracker.step(fs.stamp_ns, {c: im for c, im in fs.images.items()
                                                if c in cal.cameras})
            yield fs, result, tracker
            if fs.index >= last:
                return


def weighted_cloud(tracker, track_id: int) -> tuple:
    """A track's particles (N, 6), normalised weights (N,) and appearance model as the
    tracker's next step starts from them (``filter.cloud``; HJS and separable filters)."""
    particles, logw, model = tracker.filter.cloud(track_id)
    w = np.exp(logw - logw.max())
    return particles, w / w.sum(), model


def with_track_replaced(tracker, track_id: int, states: np.ndarray) -> tuple:
    """(clouds, log-weights, models, k): every live track's cloud as the next step starts
    from it, in the filter's order, with track ``track_id``'s (index k) replaced by
    ``states`` (M, 6) of equal weight, to score places for that track with the tracker's
    own measurement model (``hjs`` with ``log_weights=True``)."""
    ids = tracker.filter.track_ids()
    clouds, logw, models = [], [], []
    for i in ids:
        particles, lw, model = tracker.filter.cloud(i)
        if i == track_id:
            particles, lw = states, np.full(len(states), -np.log(len(states)))
        clouds.append(particles)
        logw.append(lw)
        models.append(model)
    return clouds, logw, models, ids.index(track_id)


def run_context(out: Path, rec: Path) -> tuple:
    """(events, matching detail, its frames, ground-truth rows by frame, id -> frames the
    track was born or moved at) of one ``run`` output against its recording."""
    return context(*detection_eval._load(out, rec)[:3])


def context(tracks: list, truth: list, events: list) -> tuple:
    """:func:`run_context` of a run already loaded (``detection_eval._load``'s first three
    values), for a diag that needs the tracks too."""
    detail, frames = detection_eval._matching(tracks, truth)
    people: dict[int, list] = {}
    for r in truth:
        people.setdefault(r.frame, []).append(r)
    placed: dict[int, list[int]] = {}
    for e in events:
        if e['kind'] == 'birth':
            placed.setdefault(e['id'], []).append(e['frame'])
        elif e['kind'] == 'decision' and e['action'].startswith('move '):
            placed.setdefault(int(e['action'].split()[1]), []).append(e['frame'])
    return events, detail, frames, people, placed


def places(rec: Path) -> dict[int, dict[int, np.ndarray]]:
    """Ground-truth floor places (x, y) by frame and person id of a recording."""
    out: dict[int, dict[int, np.ndarray]] = {}
    for r in read_ground_truth(rec / 'ground_truth.csv'):
        out.setdefault(r.frame, {})[r.person_id] = np.array([r.x, r.y])
    return out


def person_velocity(people: dict[int, list], frame: int, xy, *, half: int = 3,
                    within: float = 0.5):
    """(vx, vy), m/s, of the person nearest the floor point ``xy`` at ``frame`` (within
    ``within`` metres), over the ``half`` frames either side of it; None when nobody is
    that near or the person is not seen at both ends. ``people``: ground-truth rows by
    frame (:func:`run_context`)."""
    here = people.get(frame, [])
    if not here:
        return None
    near = detection_eval.nearest_row(here, xy)
    if np.hypot(near.x - xy[0], near.y - xy[1]) > within:
        return None
    ends = [next((r for r in people.get(g, []) if r.person_id == near.person_id), None)
            for g in (frame - half, frame + half)]
    if None in ends:
        return None
    dt = (ends[1].stamp_ns - ends[0].stamp_ns) / 1e9
    return ((ends[1].x - ends[0].x) / dt, (ends[1].y - ends[0].y) / dt)
