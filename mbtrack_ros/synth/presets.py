"""Named scenarios of synthetic recordings (``mbtrack synth --list``).

Each preset fixes the cameras, the number of frames and how the crowd is populated; every
preset ``NAME`` also exists as ``NAME-short`` (a few dozen frames, same character) for tests.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from mbtrack_ros.synth.body import random_clothing
from mbtrack_ros.synth.errors import SynthError
from mbtrack_ros.synth.motion import Crowd
from mbtrack_ros.synth.room import Room, default_room, hall_room, large_room, two_door_room

__all__ = ['PRESETS', 'Preset', 'get_preset', 'populate']

# the single camera of the Lanz sequences sits in the corner (0.1, 0.1) looking at the centre
_CAM_XY = np.array([0.1, 0.1])
_VIEW = np.array([2.9, 2.4]) / np.hypot(2.9, 2.4)  # floor direction of its optical axis
_ACROSS = np.array([-_VIEW[1], _VIEW[0]])          # perpendicular to it on the floor


@dataclass(frozen=True)
class Preset:
    """A scenario: cameras (``None`` = all, ceiling optional), frames, crowd builder, the
    image size (width, height) in pixels ``mbtrack synth`` renders by default, the room it
    happens in and whether that room has a ceiling camera."""

    name: str
    description: str
    frames: int
    cameras: tuple[str, ...] | None
    populate: Callable[[Crowd], None]
    size: tuple[int, int] = (320, 240)
    room: Callable[[], Room] = field(default=default_room)
    ceiling: bool = True


def _lanz_area(n_people: int, area: tuple[float, float, float, float]) -> Callable:
    def populate(crowd: Crowd) -> None:
        for _ in range(n_people):
            crowd.add(tuple(crowd.random_free_point(area, min_gap=0.7)), behaviour='area',
                      area=area, speed_range=(0.4, 1.2), personal_space=0.8)
    return populate


def _lanz_seq4(crowd: Crowd) -> None:
    def at(dist: float, lateral: float) -> np.ndarray:
        return _CAM_XY + dist * _VIEW + lateral * _ACROSS

    # The occluder: tall (2.0 m), close to the camera, standing half turned away from it
    # (his legs overlap in the view, no gap between them). The camera
    # looks down from 2.6 m, so a person at distance d2 behind him is fully hidden only while
    # (2.6 - h2) / (2.6 - h1) >= d2 / d1: the twins stay within about 1.45 d1.
    crowd.add(tuple(at(1.9, 0.0)), behaviour='patrol', height=2.0,
              theta=float(np.arctan2(-_VIEW[1], -_VIEW[0])) + 0.8,
              patrol=[at(1.9, -0.04), at(1.9, 0.04)], patrol_pause=(2.0, 5.0),
              speed_range=(0.2, 0.3))
    twins = random_clothing(crowd.rng)
    base = float(crowd.rng.uniform(1.6, 1.63))
    # the twins walk back and forth behind him and stand right behind him for a while
    for k, (dist, h) in enumerate(((2.5, base), (2.92, base + 0.03))):
        ends = [at(dist, -0.6), at(dist, 0.0), at(dist, 1.1), at(dist, 0.0)]
        pauses = [(0.3, 1.0), (1.5, 4.0), (0.3, 1.0), (1.5, 4.0)]
        start = 2 * k + 1
        crowd.add(tuple(ends[start]), behaviour='patrol', height=h, clothing=twins,
                  patrol=ends[start:] + ends[:start],
                  patrol_pauses=pauses[start:] + pauses[:start], speed_range=(0.7, 1.0))


def _present_then_arriving(crowd: Crowd, present: int, leave: tuple[float, float],
                           gap: tuple[float, float], visit: tuple[float, float],
                           max_people: int, min_people: int, first: float) -> None:
    """``present`` people standing in the room from the first frame (0.9 m apart), each
    leaving after a time drawn from ``leave`` (seconds), then arrivals every ``gap``
    seconds from ``first`` on, each staying ``visit`` seconds, keeping between
    ``min_people`` and ``max_people`` in the room."""
    for _ in range(present):
        crowd.add(tuple(crowd.random_free_point(min_gap=0.9)), behaviour='room',
                  leave_time=float(crowd.rng.uniform(*leave)))
    crowd.schedule_arrivals(gap=gap, visit=visit, max_people=max_people,
                            min_people=min_people, first=first)


def _clear_room(crowd: Crowd) -> None:
    _present_then_arriving(crowd, 2, (20.0, 70.0), (6.0, 18.0), (30.0, 80.0), 5, 2, 0.3)


def _empty(crowd: Crowd) -> None:
    pass


def _crowd(crowd: Crowd) -> None:
    """A crowd of 6-10: four people present, the others arriving every few seconds."""
    top = int(crowd.rng.integers(6, 11))
    _present_then_arriving(crowd, 4, (25.0, 60.0), (1.5, 4.0), (20.0, 60.0), top, top, 0.5)


def _occupied(crowd: Crowd) -> None:
    """Four or five people in the room from the first frame; some leave early, later a
    few others come in."""
    _present_then_arriving(crowd, int(crowd.rng.integers(4, 6)), (4.0, 40.0), (6.0, 15.0),
                           (15.0, 40.0), 5, 1, 12.0)


def _full(crowd: Crowd) -> None:
    """Seven or eight people in the room from the first frame, leaving after 10-40 s;
    later others come in."""
    top = int(crowd.rng.integers(7, 9))
    _present_then_arriving(crowd, top, (10.0, 40.0), (6.0, 15.0), (15.0, 40.0), top, 1,
                           12.0)


def _large(crowd: Crowd) -> None:
    """Three people present, up to six in all over the visit."""
    _present_then_arriving(crowd, 3, (20.0, 60.0), (3.0, 10.0), (20.0, 60.0), 6, 3, 1.0)


def _hall(crowd: Crowd) -> None:
    """Four people present, four more arriving every 1-2.5 s: eight within ten seconds."""
    _present_then_arriving(crowd, 4, (40.0, 90.0), (1.0, 2.5), (40.0, 90.0), 8, 4, 0.3)


def _two_doors(crowd: Crowd) -> None:
    """Two people present; others come in through either door and leave through either
    (short visits, so that doorways see traffic)."""
    for _ in range(2):
        crowd.add(tuple(crowd.random_free_point(min_gap=0.9)), behaviour='room',
                  leave_time=float(crowd.rng.uniform(8.0, 30.0)))
    crowd.schedule_arrivals(gap=(3.0, 9.0), visit=(8.0, 25.0), max_people=5,
                            min_people=2, first=0.5)


# Lanz areas: rectangles elongated along the camera's line of sight (so that people often
# line up in depth and occlude each other), 1.5-3.7 m from the camera.
_ANGLE = float(np.arctan2(_VIEW[1], _VIEW[0]))
_MID = _CAM_XY + 2.6 * _VIEW + 0.05 * _ACROSS
_AREA_SMALL = (float(_MID[0]), float(_MID[1]), 1.1, 0.45, _ANGLE)
_AREA_WIDE = (float(_MID[0]), float(_MID[1]), 1.2, 0.75, _ANGLE)
_LANZ_SIZE = (200, 150)   # 000 §VI-A: images down-sampled to 200x150 pixels

_BASE = (
    Preset('lanz-seq1', '3 people walking randomly in a small area in front of one corner '
           'camera: frequent, long occlusions (670 frames)', 670, ('cam0',),
           _lanz_area(3, _AREA_SMALL), _LANZ_SIZE),
    Preset('lanz-seq2', '4 people walking randomly in front of one corner camera '
           '(618 frames)', 618, ('cam0',), _lanz_area(4, _AREA_SMALL), _LANZ_SIZE),
    Preset('lanz-seq3', '5 people walking randomly in front of one corner camera '
           '(341 frames)', 341, ('cam0',), _lanz_area(5, _AREA_WIDE), _LANZ_SIZE),
    Preset('lanz-seq4', '3 people, one corner camera: identically dressed twins (a few cm '
           'apart in height) walk back and forth fully occluded behind a tall third person '
           '(215 frames)', 215, ('cam0',), _lanz_seq4, _LANZ_SIZE),
    Preset('clear-room', 'four corner cameras + ceiling camera, 2-5 people entering and '
           'leaving through the door, sitting on chairs; door and screen change (1800 frames, '
           '2 min)', 1800, None, _clear_room),
    Preset('empty-room', 'all cameras, nobody in the room, the screen changing (60 frames)',
           60, None, _empty),
    Preset('real-room', 'clear-room with every real-room condition of synth/conditions.py: '
           'free-running cameras, light changes, auto exposure, shadows from two ceiling '
           'lamps, a calibration off by 1 deg and 3 cm (300 frames, 20 s)', 300, None,
           _clear_room),
    Preset('crowd', 'the clear-room room and cameras, 6-10 people: four present from the '
           'start, the others arriving every 1.5-4 s (450 frames, 30 s)', 450, None, _crowd),
    Preset('occupied', 'the clear-room room and cameras occupied from the first frame by '
           '4-5 people who move and leave (some after 4 s); others come in later '
           '(450 frames, 30 s)', 450, None, _occupied),
    Preset('full-room', 'the clear-room room and cameras occupied from the first frame by '
           '7-8 people who move and leave after 10-40 s; others come in later (450 frames, '
           '30 s)', 450, None, _full),
    Preset('two-cameras', 'clear-room with only two opposite corner cameras (300 frames)',
           300, ('cam0', 'cam2'), _clear_room),
    Preset('three-cameras', 'clear-room with three corner cameras, no ceiling camera '
           '(300 frames)', 300, ('cam0', 'cam1', 'cam2'), _clear_room),
    Preset('large-room', 'a 10 x 8 m room with six cameras (four corners, two mid-wall), '
           '3-6 people (450 frames, 30 s)', 450, None, _large, room=large_room,
           ceiling=False),
    Preset('eight-cameras', 'the 10 x 8 m large room with eight cameras (four corners, four '
           'mid-wall) at 640x480, eight people: four present, four arriving in the first '
           '10 s (300 frames, 20 s)', 300,
           ('cam0', 'cam1', 'cam2', 'cam3', 'cam5', 'cam6', 'cam7', 'cam8'), _hall,
           (640, 480), room=hall_room, ceiling=False),
    Preset('twelve-cameras', 'eight-cameras with four more wall cameras at the thirds of '
           'the long walls: twelve cameras at 640x480 (300 frames, 20 s)', 300, None, _hall,
           (640, 480), room=hall_room, ceiling=False),
    Preset('two-doors', 'the clear-room room with a second doorway in the north wall: '
           'people enter and leave through either (450 frames, 30 s)', 450, None,
           _two_doors, room=two_door_room),
)

_SHORT_FRAMES = {'lanz-seq1': 40, 'lanz-seq2': 40, 'lanz-seq3': 30, 'lanz-seq4': 45,
                 'clear-room': 45, 'empty-room': 10, 'real-room': 45, 'crowd': 45,
                 'occupied': 45, 'full-room': 45, 'two-cameras': 45, 'three-cameras': 45,
                 'large-room': 45, 'eight-cameras': 45, 'twelve-cameras': 45, 'two-doors': 45}

PRESETS: dict[str, Preset] = {}
for _p in _BASE:
    PRESETS[_p.name] = _p
    _short = _SHORT_FRAMES[_p.name]
    PRESETS[f'{_p.name}-short'] = replace(
        _p, name=f'{_p.name}-short', frames=_short,
        description=f'{_short}-frame version of {_p.name} for tests')


def get_preset(name: str) -> Preset:
    """The preset called ``name``; raises :class:`SynthError` listing the known names."""
    try:
        return PRESETS[name]
    except KeyError as err:
        raise SynthError(f'unknown preset {name!r}; known: {", ".join(PRESETS)}') from err


def populate(preset: Preset, room: Room, rng: np.random.Generator) -> Crowd:
    """A new crowd for the preset."""
    crowd = Crowd(room, rng)
    preset.populate(crowd)
    return crowd
