"""Track initialisation from ground truth, for experiments (000 §VI: "initialized by hand").

Given the ground-truth rows of a recording (plain data; the command layer reads the CSV),
the calibration and a few frames of images:

1. :func:`plan_key_views` picks, per person, up to ``max_views`` key views (frame, camera)
   among the first ``search_frames`` ground-truth frames where the person is entirely in the
   image, large enough, and not occluded by another person. Occlusion is judged from the
   other people's ground-truth positions rendered with the shape model
   (:func:`mbtrack_ros.core.shape.rasterize`): the person is occluded if a closer person
   covers more than ``max_overlap`` of its silhouette. Views are chosen greedily to spread
   the relative viewing angle (front / side / back, 003 §2.2 key views).
2. :func:`initial_tracks` builds each person's :class:`PersonModel` from those views
   (``appearance.model_from_images``; height from ``z_head``, width 0.5 m by default) and the
   initial state at the person's first ground-truth frame: position, velocity from the next
   ground-truth frames, orientation from the velocity.
"""
from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from mbtrack_ros.core.appearance import AppearanceError, PersonModel, model_from_images
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.state import SIT, STATE_DIM, THETA, VX, VY, X, Y

__all__ = ['InitialTrack', 'InitiationError', 'KeyView', 'PersonTruth', 'body_height',
           'initial_state', 'initial_tracks', 'plan_key_views']


class InitiationError(ValueError):
    """Ground truth or images that do not allow initialising a track."""


@dataclass(frozen=True)
class PersonTruth:
    """Ground truth of one person at one frame (plain data, any source).

    Any object with these attributes works (e.g. ``recording.csvfiles.GroundTruthRow``).

    Attributes:
        frame: frame index; stamp_ns: stamp, nanoseconds; person_id: person id;
        x, y: floor position, metres; z_head: head height, metres; sitting: posture.
    """

    frame: int
    stamp_ns: int
    person_id: int
    x: float
    y: float
    z_head: float
    sitting: bool = False


@dataclass(frozen=True)
class KeyView:
    """One image of one person used to acquire its appearance model.

    Attributes:
        person_id, frame, stamp_ns, camera: where to find the image.
        state: (6,) the person's ground-truth state at that frame.
        relative_angle: body orientation relative to the camera, radians (0 = facing it).
        area: silhouette area in pixels.
    """

    person_id: int
    frame: int
    stamp_ns: int
    camera: str
    state: np.ndarray
    relative_angle: float
    area: int


@dataclass
class InitialTrack:
    """A track to start: the person, when, where, and with which model."""

    person_id: int
    frame: int
    stamp_ns: int
    state: np.ndarray
    height: float
    model: PersonModel
    views: list[KeyView]
    last_frame: int


def _by_person(truth: Sequence[PersonTruth]) -> dict[int, list[PersonTruth]]:
    out: dict[int, list[PersonTruth]] = defaultdict(list)
    for row in truth:
        out[int(row.person_id)].append(row)
    for rows in out.values():
        rows.sort(key=lambda r: r.stamp_ns)
    return dict(out)


def body_height(rows: Sequence[PersonTruth], shape: BodyShape | None = None) -> float:
    """Body height h (m) from head heights: median over standing rows, else from sitting.

    Sitting (003 §2.1, see :mod:`mbtrack_ros.core.shape`): head top at
    ``chair_height + (1 - hip_fraction) h``.
    """
    shape = shape or BodyShape()
    standing = [r.z_head for r in rows if not r.sitting]
    if standing:
        return float(np.median(standing))
    sitting = [r.z_head for r in rows]
    if not sitting:
        raise InitiationError('no ground truth rows for this person')
    h = (float(np.median(sitting)) - shape.chair_height) / (1.0 - shape.hip_fraction)
    if not h > 0:
        raise InitiationError(f'sitting head height {np.median(sitting):.2f} m is below the '
                              'chair height')
    return h


def initial_state(rows: Sequence[PersonTruth], index: int = 0, *,
                  lookahead: int = 3, min_speed: float = 0.2) -> np.ndarray:
    """(6,) state at ``rows[index]``: position, velocity over the next ``lookahead`` rows,
    orientation along the velocity (0 when slower than ``min_speed`` m/s), sitting flag."""
    r0 = rows[index]
    state = np.zeros(STATE_DIM)
    state[X], state[Y] = r0.x, r0.y
    j = min(index + lookahead, len(rows) - 1)
    if j > index:
        a, b = r0, rows[j]
    else:  # last row: look back instead
        a, b = rows[max(0, index - lookahead)], r0
    dt = (b.stamp_ns - a.stamp_ns) / 1e9
    if dt > 0:
        state[VX] = (b.x - a.x) / dt
        state[VY] = (b.y - a.y) / dt
    speed = np.hypot(state[VX], state[VY])
    state[THETA] = np.arctan2(state[VY], state[VX]) if speed > min_speed else 0.0
    state[SIT] = 1.0 if r0.sitting else 0.0
    return state


def plan_key_views(calibration: RoomCalibration, truth: Sequence[PersonTruth], *,
                   search_frames: int = 60, max_views: int = 6, width: float = 0.5,
                   min_area: int = 150, max_overlap: float = 0.05,
                   others: Sequence[PersonTruth] | None = None,
                   ) -> dict[int, list[KeyView]]:
    """Choose unoccluded key views per person (see the module docstring).

    Args:
        calibration: the room.
        truth: ground truth rows of all people (any order).
        search_frames: how many of each person's first ground-truth frames to consider.
        max_views: views per person.
        width: body width, metres.
        min_area: smallest silhouette area in pixels of a 320x240 image (scaled with each
            camera's pixel count).
        max_overlap: largest fraction of the silhouette a closer person may cover.
        others: ground truth rows of everybody who may hide the people of ``truth``
            (default ``truth``).

    Returns:
        person id -> key views (possibly empty when the person is never seen unoccluded).
    """
    wanted_people = {r.person_id for r in truth}
    people = _by_person(truth if others is None else others)
    heights = {pid: body_height(rows) for pid, rows in people.items()}
    states = {pid: [initial_state(rows, i) for i in range(len(rows))]
              for pid, rows in people.items()}
    by_frame: dict[int, list[tuple[int, int]]] = defaultdict(list)  # frame -> (pid, row idx)
    for pid, rows in people.items():
        for i, r in enumerate(rows):
            by_frame[int(r.frame)].append((pid, i))
    candidates: dict[int, list[KeyView]] = defaultdict(list)
    wanted = {pid: ({int(r.frame) for r in rows[:search_frames]} if pid in wanted_people
                    else set()) for pid, rows in people.items()}
    frames = sorted(f for f in by_frame if any(f in w for w in wanted.values()))
    for frame in frames:
        present = by_frame[frame]
        pids = [p for p, _ in present]
        st = np.array([states[p][i] for p, i in present])
        hs = np.array([heights[p] for p in pids])
        for cam_name, cam in calibration.cameras.items():
            smallest = min_area * cam.width * cam.height / (320 * 240)
            sil = rasterize(cam, st, BodyShape(width=width), heights=hs,
                            widths=np.full(len(pids), width))
            masks = None
            for a, pid in enumerate(pids):
                if frame not in wanted[pid]:
                    continue
                area = int(sil.area[a])
                if area < smallest or area != int(sil.full_area[a]):
                    continue  # too small or cut by the image border
                if masks is None:
                    masks = [sil.mask(b) > 0 for b in range(len(pids))]
                covered = np.zeros_like(masks[a])
                for b in range(len(pids)):
                    if b != a and sil.distance[b] < sil.distance[a]:
                        covered |= masks[b]
                overlap = np.count_nonzero(covered & masks[a]) / max(1, masks[a].sum())
                if overlap > max_overlap:
                    continue
                s = st[a]
                rel = float(np.angle(np.exp(1j * (s[THETA] - cam.viewing_angle(s[:2])))))
                row = people[pid][present[a][1]]
                candidates[pid].append(KeyView(pid, frame, int(row.stamp_ns), cam_name,
                                               s.copy(), rel, area))
    plan: dict[int, list[KeyView]] = {}
    for pid in sorted(wanted_people):
        plan[pid] = _spread_views(candidates.get(pid, []), max_views)
    unseen = [pid for pid, views in plan.items() if not views]
    longest = max((len(rows) for rows in people.values()), default=0)
    if unseen and search_frames < longest:
        # 000 §VI-A acquires the models before tracking, apart from the sequence: a person
        # partly hidden all through the first frames gets views from later ones
        rest = [r for r in truth if r.person_id in unseen]
        later = plan_key_views(calibration, rest, search_frames=longest,
                               max_views=max_views, width=width, min_area=min_area,
                               max_overlap=max_overlap, others=truth)
        plan.update(later)
    return plan


def _spread_views(cands: list[KeyView], max_views: int) -> list[KeyView]:
    """Greedy farthest-point selection on the relative angle, largest silhouette first."""
    if not cands:
        return []
    chosen = [max(cands, key=lambda v: v.area)]
    while len(chosen) < min(max_views, len(cands)):
        angles = np.array([c.relative_angle for c in chosen])

        def score(v: KeyView) -> tuple[float, int]:
            d = np.abs(np.angle(np.exp(1j * (v.relative_angle - angles)))).min()
            return float(d), v.area

        rest = [c for c in cands if all(c is not k for k in chosen)]
        best = max(rest, key=score)
        chosen.append(best)
    return chosen


def initial_tracks(calibration: RoomCalibration, truth: Sequence[PersonTruth],
                   images: Mapping[int, Mapping[str, np.ndarray]],
                   plan: Mapping[int, Sequence[KeyView]], *, width: float = 0.5,
                   skip_missing: bool = False) -> list[InitialTrack]:
    """Acquire each person's model from its key views and its initial state.

    Args:
        calibration: the room.
        truth: ground-truth rows of all people.
        images: frame index -> camera -> (H, W, 3) uint8 RGB, for the planned frames.
        plan: output of :func:`plan_key_views`.
        width: body width, metres.
        skip_missing: leave out people without a usable key view instead of raising.

    Returns:
        one :class:`InitialTrack` per person with at least one usable view, ordered by the
        first frame, then person id.

    Raises:
        InitiationError: a person has no usable key view (unless ``skip_missing``).
    """

    people = _by_person(truth)
    out = []
    for pid, rows in people.items():
        views = [v for v in plan.get(pid, []) if v.camera in images.get(v.frame, {})]
        if not views:
            if skip_missing:
                continue
            raise InitiationError(f'person {pid}: no unoccluded view in the first frames '
                                  'to acquire an appearance model')
        height = body_height(rows)
        model = PersonModel(height=height, width=width)
        for v in views:
            # 003 §4: one key view per unoccluded image; views within 20 degrees are merged
            try:
                single = model_from_images({v.camera: images[v.frame][v.camera]},
                                           calibration, v.state, height, width)
            except AppearanceError as err:
                raise InitiationError(f'person {pid}, frame {v.frame}, {v.camera}: '
                                      f'{err}') from err
            for angle, hists in zip(single.view_angles, single.histograms):
                model.add_view(float(angle), hists)
        if model.view_angles.size == 0:
            if skip_missing:
                continue
            raise InitiationError(f'person {pid}: no key view was usable for the model')
        out.append(InitialTrack(pid, int(rows[0].frame), int(rows[0].stamp_ns),
                                initial_state(rows, 0), height, model, views,
                                int(rows[-1].frame)))
    out.sort(key=lambda t: (t.stamp_ns, t.person_id))
    return out
