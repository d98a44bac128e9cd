"""Motion model of the synthetic people (see README_SYNTH.md, "Motion model").

Every person is a unicycle on the floor: position ``p`` (the floor point under the pelvis),
heading ``theta`` (= body orientation, so the body always faces the walking direction) and
speed ``v``. Each person executes a list of tasks:

* ``goto(point, v_des)``: turn towards the point (at most 3 rad/s) and walk; the target
  speed is ``min(v_des, sqrt(2 a (d - 0.02)))`` (smooth stop at the waypoint,
  ``a = 0.8 m/s^2``) and is reduced while the heading error is large; the speed itself
  follows the target with acceleration at most ``a`` (smooth speed changes, 0 .. 1.5 m/s);
* ``pause(seconds)``: stand still;
* ``sit(chair, seconds)``: walk in front of a free chair, turn round, sit down (1.2 s blend of
  the pose, pelvis moving back over the seat), stay, stand up;
* ``leave``: walk to the door, through it into the corridor, disappear.

When a person's task list is empty a new task is drawn from the person's behaviour:
``room`` (random free-area waypoints, pauses, sitting; leaves after its visit time),
``area`` (random waypoints and pauses inside a rectangle, never leaves) or ``patrol``
(back and forth between given points with pauses).

Avoidance: other people within 1.2 m (0.8 m in the lanz presets) push a walking person
away (``(1/d - 1/1.2)`` repulsion plus a sideways term so that people pass each other on
the right); a person
waits (target speed 0, at most 2.5 s) while another *moving* person is less than 0.75 m
ahead within +-60 deg. A hard constraint keeps walking people 0.42 m apart (``patrol``
walkers follow their lines and only keep this hard gap). People still
pass close enough to occlude each other in the cameras. Furniture footprints (inflated by
0.25 m) push people out, except the chair a person is using.

The door opens (2 rad/s, up to 1.6 rad) while someone is within 1.3 m of it and closes
(1 rad/s) otherwise. All randomness comes from the generator passed in.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mbtrack_ros.synth.body import Clothing, random_clothing
from mbtrack_ros.synth.errors import SynthError
from mbtrack_ros.synth.room import Room

__all__ = ['Crowd', 'PersonState', 'Walker']

ACCEL = 0.8       # m/s^2, speed changes
TURN_RATE = 3.0   # rad/s, heading changes while walking
MAX_SPEED = 1.5   # m/s
SIT_TIME = 1.2    # s, sitting down / standing up
MIN_GAP = 0.42    # m, hard distance between walking people
SIDESTEP = 0.6    # m/s, sideways step into the doorway of someone leaving beside it


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2 * np.pi) - np.pi)


@dataclass
class PersonState:
    """A person's pose at one frame (everything the renderer and ground truth need)."""

    person_id: int
    height: float
    clothing: Clothing
    x: float
    y: float
    theta: float
    phase: float
    stride: float
    sit: float


@dataclass
class Walker:
    """One simulated person (internal state of :class:`Crowd`)."""

    person_id: int
    height: float
    clothing: Clothing
    pos: np.ndarray
    theta: float
    behaviour: str
    area: tuple[float, ...] | None = None
    patrol: list[np.ndarray] = field(default_factory=list)
    patrol_pause: tuple[float, float] = (0.5, 2.0)
    patrol_pauses: list[tuple[float, float]] | None = None  # per patrol point, if given
    speed_range: tuple[float, float] = (0.5, 1.5)
    personal_space: float = 1.2  # m, range of the soft repulsion
    leave_time: float = np.inf
    speed: float = 0.0
    phase: float = 0.0
    stride: float = 0.0
    sit: float = 0.0
    tasks: list[list] = field(default_factory=list)
    chair: int | None = None
    waited: float = 0.0
    stuck: float = 0.0
    in_door: bool = False
    gone: bool = False
    patrol_index: int = 0
    sat_before: bool = False
    door: int = 0  # index into Room.doors of the door it entered by or leaves through

    def state(self) -> PersonState:
        return PersonState(self.person_id, self.height, self.clothing, float(self.pos[0]),
                           float(self.pos[1]), self.theta, self.phase, self.stride, self.sit)


class Crowd:
    """People moving in a :class:`Room` under the documented motion model.

    ``step(dt)`` advances the simulation; ``people()`` returns the present persons' states;
    ``door_angle`` is the door opening angle (rad). Person ids start at 1, never reused.
    """

    def __init__(self, room: Room, rng: np.random.Generator) -> None:
        self.room = room
        self.rng = rng
        self.walkers: list[Walker] = []
        self.time = 0.0
        self.door_angle = 0.0
        self.next_id = 1
        self.chair_taken: dict[int, int] = {}
        self.arrivals: dict | None = None
        # furniture footprints (x0, y0, x1, y1) with the chair index they belong to or -1
        self._footprints = []
        for box in room.boxes:
            if box.lo[2] < 1.0:
                chair = next((k for k, c in enumerate(room.chairs)
                              if box.lo[0] - 0.01 <= c[0] + 0.3 and abs(c[1] - 0.5 * (
                                  box.lo[1] + box.hi[1])) < 0.05), -1)
                self._footprints.append((box.lo[0], box.lo[1], box.hi[0], box.hi[1], chair))

    # -- population -----------------------------------------------------------------------
    def add(self, pos: tuple[float, float], *, behaviour: str, height: float | None = None,
            clothing: Clothing | None = None, theta: float | None = None,
            **options) -> Walker:
        """Add a person at a floor position; returns its walker (id = next free id)."""
        if behaviour not in ('room', 'area', 'patrol'):
            raise SynthError(f'unknown behaviour {behaviour!r}')
        h = float(self.rng.uniform(1.5, 2.0)) if height is None else float(height)
        if not 1.5 <= h <= 2.0:
            raise SynthError(f'person height {h} m outside 1.5..2.0 m')
        cl = random_clothing(self.rng) if clothing is None else clothing
        th = float(self.rng.uniform(-np.pi, np.pi)) if theta is None else float(theta)
        w = Walker(self.next_id, h, cl, np.array(pos, dtype=np.float64), th, behaviour,
                   phase=float(self.rng.uniform(0, 2 * np.pi)), **options)
        self.next_id += 1
        self.walkers.append(w)
        return w

    def random_free_point(self, area: tuple[float, ...] | None = None,
                          min_gap: float = 0.0) -> np.ndarray:
        """A uniform point of ``area`` (default the room's free area) away from people.

        ``area`` is ``(x0, y0, x1, y1)`` or a rotated rectangle
        ``(cx, cy, half_length, half_width, angle)`` (length along ``angle``).
        """
        area = tuple(area or self.room.free_area)
        for _ in range(50):
            if len(area) == 5:
                cx, cy, hl, hw, angle = area
                u, v = self.rng.uniform(-hl, hl), self.rng.uniform(-hw, hw)
                c, s = np.cos(angle), np.sin(angle)
                p = np.array([cx + u * c - v * s, cy + u * s + v * c])
            elif len(area) == 4:
                x0, y0, x1, y1 = area
                p = np.array([self.rng.uniform(x0, x1), self.rng.uniform(y0, y1)])
            else:
                raise SynthError(f'an area has 4 or 5 numbers, got {area}')
            if all(np.linalg.norm(p - w.pos) >= min_gap for w in self.walkers if not w.gone):
                return p
        return p

    def schedule_arrivals(self, *, gap: tuple[float, float], visit: tuple[float, float],
                          max_people: int, min_people: int, first: float = 1.0) -> None:
        """People arrive through the door every ``gap`` s and stay ``visit`` s."""
        self.arrivals = dict(gap=gap, visit=visit, max_people=max_people,
                             min_people=min_people, next=first)

    def _pick_door(self) -> int:
        """A door index, uniformly among the room's doors (no draw with a single door)."""
        n = len(self.room.doors)
        return int(self.rng.integers(n)) if n > 1 else 0

    def _spawn_at_door(self) -> None:
        a = self.arrivals
        door = self._pick_door()
        cx, depth = self.room.door_centres()[door]
        spawn = np.array([cx, depth + 1.2])
        if any(np.linalg.norm(w.pos - spawn) < 1.0 for w in self.walkers if not w.gone):
            return
        w = self.add(tuple(spawn), behaviour='room', theta=-0.5 * np.pi,
                     leave_time=self.time + float(self.rng.uniform(*a['visit'])))
        w.in_door = True
        w.door = door
        w.tasks = [['pause', 0.7], ['goto', np.array([cx, depth - 0.7]), 0.9, 'door']]
        a['next'] = self.time + float(self.rng.uniform(*a['gap']))

    # -- behaviour ------------------------------------------------------------------------
    def _new_task(self, w: Walker) -> None:
        rng = self.rng
        lo, hi = w.speed_range
        if w.behaviour == 'patrol':
            w.patrol_index = (w.patrol_index + 1) % len(w.patrol)
            pause = (w.patrol_pauses[w.patrol_index] if w.patrol_pauses is not None
                     else w.patrol_pause)
            w.tasks = [['goto', w.patrol[w.patrol_index], float(rng.uniform(lo, hi))],
                       ['pause', float(rng.uniform(*pause))]]
            return
        if w.behaviour == 'area':
            if rng.random() < 0.25:
                w.tasks = [['pause', float(rng.uniform(0.5, 3.0))]]
            else:
                w.tasks = [['goto', self.random_free_point(w.area), float(rng.uniform(lo, hi))]]
            return
        # room behaviour
        if self.time >= w.leave_time:
            w.door = self._pick_door()
            cx, depth = self.room.door_centres()[w.door]
            w.tasks = [['goto', np.array([cx, depth - 0.7]), float(rng.uniform(lo, hi))],
                       ['pause', 0.5], ['goto', np.array([cx, depth + 1.3]), 0.9, 'door'],
                       ['gone']]
            return
        free = [k for k in range(len(self.room.chairs)) if k not in self.chair_taken]
        u = rng.random()
        if free and u < (0.15 if w.sat_before else 0.35):
            k = free[int(rng.integers(len(free)))]
            cx, cy, _, facing = self.room.chairs[k]
            front = np.array([cx, cy]) + 0.45 * np.array([np.cos(facing), np.sin(facing)])
            self.chair_taken[k] = w.person_id
            w.chair = k
            w.sat_before = True
            w.tasks = [['goto', front, float(rng.uniform(lo, hi)), 'chair'],
                       ['turn', facing], ['sit', float(rng.uniform(6.0, 20.0))]]
        elif u < 0.55:
            w.tasks = [['pause', float(rng.uniform(1.0, 4.0))]]
        else:
            w.tasks = [['goto', self.random_free_point(), float(rng.uniform(lo, hi))]]

    # -- simulation -----------------------------------------------------------------------
    def step(self, dt: float) -> None:
        """Advance all people and the door by ``dt`` seconds."""
        if self.arrivals is not None:
            a = self.arrivals
            active = sum(not w.gone for w in self.walkers)
            if active < a['min_people']:
                a['next'] = min(a['next'], self.time + 2.0)
            if self.time >= a['next'] and active < a['max_people']:
                self._spawn_at_door()
        alive = [w for w in self.walkers if not w.gone]
        for w in alive:
            self._step_walker(w, alive, dt)
        self._separate(alive)
        self.walkers = [w for w in self.walkers if not w.gone]
        near = any(np.linalg.norm(w.pos - self.room.door_centre) < 1.3 for w in self.walkers)
        if near:
            self.door_angle = min(1.6, self.door_angle + 2.0 * dt)
        else:
            self.door_angle = max(0.0, self.door_angle - 1.0 * dt)
        self.time += dt

    def _step_walker(self, w: Walker, alive: list[Walker], dt: float) -> None:
        if not w.tasks:
            self._new_task(w)
        task = w.tasks[0]
        kind = task[0]
        v_target = 0.0
        heading_goal = None
        if kind == 'gone':
            w.gone = True
            if w.chair is not None:
                self.chair_taken.pop(w.chair, None)
            return
        if kind == 'pause':
            task[1] -= dt
            if task[1] <= 0:
                w.tasks.pop(0)
        elif kind == 'turn':
            err = _wrap(task[1] - w.theta)
            w.theta = _wrap(w.theta + np.clip(err, -2.5 * dt, 2.5 * dt))
            if abs(err) < 0.05:
                w.tasks.pop(0)
        elif kind == 'sit':
            self._sit(w, task, dt)
        elif kind == 'goto':
            target, v_des = task[1], min(task[2], MAX_SPEED)
            delta = target - w.pos
            dist = float(np.linalg.norm(delta))
            if dist < 0.05 or (dist < 0.3 and w.speed < 0.05 and w.stuck > 1.0):
                w.tasks.pop(0)
                w.stuck = 0.0
                if len(task) > 3 and task[3] == 'door':
                    w.in_door = False
            else:
                direction = delta / dist
                # patrol walkers follow their lines (a choreography): no soft repulsion
                push = (np.zeros(2) if w.behaviour == 'patrol'
                        else self._repulsion(w, alive, direction))
                desired = direction + push
                heading_goal = float(np.arctan2(desired[1], desired[0]))
                v_target = min(v_des, np.sqrt(2 * ACCEL * max(dist - 0.02, 0.0)))
                if self._blocked(w, alive):
                    w.waited += dt
                    if w.waited < 2.5:
                        v_target = 0.0
                else:
                    w.waited = 0.0
                w.stuck = w.stuck + dt if w.speed < 0.05 else 0.0
                if w.stuck > 10.0:  # give up an unreachable waypoint
                    w.tasks.pop(0)
                    w.stuck = 0.0
        if heading_goal is not None:
            err = _wrap(heading_goal - w.theta)
            w.theta = _wrap(w.theta + float(np.clip(err, -TURN_RATE * dt, TURN_RATE * dt)))
            v_target *= max(0.0, np.cos(err)) ** 2  # slow down while turning
        dv = float(np.clip(v_target - w.speed, -ACCEL * dt, ACCEL * dt))
        w.speed = float(np.clip(w.speed + dv, 0.0, MAX_SPEED))
        if w.sit == 0.0:
            before = w.pos
            w.pos = w.pos + w.speed * dt * np.array([np.cos(w.theta), np.sin(w.theta)])
            self._keep_inside(w, dt, before)
        # gait: one cycle (two steps) per 0.8 H metres, amplitude grows with speed
        w.phase = float((w.phase + 2 * np.pi * w.speed * dt / (0.8 * w.height)) % (2 * np.pi))
        target_stride = min(1.0, w.speed / 1.1) ** 0.7 if w.speed > 0.02 else 0.0
        w.stride += float(np.clip(target_stride - w.stride, -3 * dt, 3 * dt))

    def _sit(self, w: Walker, task: list, dt: float) -> None:
        cx, cy, _, facing = self.room.chairs[w.chair]
        front = np.array([cx, cy]) + 0.45 * np.array([np.cos(facing), np.sin(facing)])
        seat = np.array([cx, cy])
        if len(task) == 2:
            task.append('down')
        if task[2] == 'down':
            w.sit = min(1.0, w.sit + dt / SIT_TIME)
            if w.sit >= 1.0:
                task[2] = 'stay'
        elif task[2] == 'stay':
            task[1] -= dt
            if task[1] <= 0:
                task[2] = 'up'
        else:
            w.sit = max(0.0, w.sit - dt / SIT_TIME)
            if w.sit <= 0.0:
                w.tasks.pop(0)
                self.chair_taken.pop(w.chair, None)
                w.chair = None
        w.pos = front + (seat - front) * w.sit
        w.speed = 0.0

    def _repulsion(self, w: Walker, alive: list[Walker], direction: np.ndarray) -> np.ndarray:
        push = np.zeros(2)
        for o in alive:
            if o is w:
                continue
            d = w.pos - o.pos
            dist = float(np.linalg.norm(d))
            reach = w.personal_space
            if 1e-6 < dist < reach:
                strength = 0.6 * (1.0 / dist - 1.0 / reach)
                away = d / dist
                right = np.array([direction[1], -direction[0]])
                ahead = float(-away @ direction) > 0.0
                push += strength * (away + (0.8 * right if ahead else 0.0))
        return push

    def _blocked(self, w: Walker, alive: list[Walker]) -> bool:
        fwd = np.array([np.cos(w.theta), np.sin(w.theta)])
        for o in alive:
            if o is w or o.speed < 0.1:
                continue
            d = o.pos - w.pos
            dist = float(np.linalg.norm(d))
            if dist < 0.75 and d @ fwd > 0.5 * dist:
                return True
        return False

    def _keep_inside(self, w: Walker, dt: float, before: np.ndarray) -> None:
        room = self.room
        # in the doorway or corridor (entering, or leaving until gone: not pulled back to
        # the floor for its last frame)
        if w.in_door or w.tasks and (w.tasks[0][0] == 'gone' or len(w.tasks[0]) > 3
                                     and w.tasks[0][3] == 'door'):
            door = room.doors[w.door]
            x0, x1 = door[0] + 0.3, door[1] - 0.3
            if abs(w.pos[1] - room.depth) < 0.5:
                inside = float(np.clip(w.pos[0], x0, x1))
                # step sideways into the opening at SIDESTEP, not in one frame; the wall
                # holds whoever comes from the room and is not in the opening yet; beside
                # the door, a body keeps its clearance from the wall (the walkable floor's
                # edge) as everywhere else, so no body stands half inside the wall
                step = SIDESTEP * dt
                w.pos[0] += float(np.clip(inside - w.pos[0], -step, step))
                if abs(w.pos[0] - inside) > 1e-9 and before[1] < room.depth:
                    beside = not door[0] <= w.pos[0] <= door[1]
                    held = (max(room.walkable[3], min(before[1], room.depth - 1e-3))
                            if beside else room.depth - 1e-3)
                    w.pos[1] = min(w.pos[1], held)
            return
        x0, y0, x1, y1 = room.walkable
        w.pos = np.clip(w.pos, [x0, y0], [x1, y1])
        for fx0, fy0, fx1, fy1, chair in self._footprints:
            if chair >= 0 and chair == w.chair:
                continue
            m = 0.25
            gx0, gy0, gx1, gy1 = fx0 - m, fy0 - m, fx1 + m, fy1 + m
            px, py = w.pos
            if gx0 < px < gx1 and gy0 < py < gy1:
                exits = [(px - gx0, (gx0, py)), (gx1 - px, (gx1, py)),
                         (py - gy0, (px, gy0)), (gy1 - py, (px, gy1))]
                w.pos = np.array(min(exits, key=lambda e: e[0])[1])

    def _separate(self, alive: list[Walker]) -> None:
        for i, a in enumerate(alive):
            for b in alive[i + 1:]:
                if a.gone or b.gone:
                    continue
                d = a.pos - b.pos
                dist = float(np.linalg.norm(d))
                if dist < MIN_GAP:
                    n = d / dist if dist > 1e-9 else np.array([1.0, 0.0])
                    corr = 0.5 * (MIN_GAP - dist) * n
                    if a.sit == 0.0:
                        a.pos = a.pos + (corr if b.sit == 0.0 else 2 * corr)
                    if b.sit == 0.0:
                        b.pos = b.pos - (corr if a.sit == 0.0 else 2 * corr)

    def people(self) -> list[PersonState]:
        """States of the people present now, by id."""
        return [w.state() for w in self.walkers if not w.gone]
