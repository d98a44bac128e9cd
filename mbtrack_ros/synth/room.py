"""The synthetic smart room: geometry, cameras, and the per-camera static ray cast.

The room is an axis-aligned box ``[0, 6] x [0, 5] x [0, 2.8]`` metres (floor z = 0) with
tiled floor, textured walls, a poster, a table, a cabinet and three chairs along the west
wall, a wall screen on the east wall whose content changes, and a door in the north wall
that swings out into a corridor (people enter and leave through it). A room may have more
doors in the north wall (open doorways into their own corridors), another size, and wall
cameras besides the four corner cameras (see :data:`~.presets.PRESETS`).

Each camera's view of the static room is ray-cast once (:class:`CameraView`): per pixel the
world ray (from :meth:`Camera.pixel_rays`, so lens distortion is included), the radiance of
the first surface hit and its distance along the ray (depth buffer). The screen and door
pixels are remembered so that a frame only recomputes those small regions.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.synth.errors import SynthError
from mbtrack_ros.synth.raster import hash01

__all__ = ['Box', 'CameraView', 'Room', 'default_room', 'hall_room', 'large_room',
           'make_calibration', 'two_door_room']

# surface ids of the static ray cast
FLOOR, CEILING, WALL_W, WALL_E, WALL_S, WALL_N, SCREEN, DOOR, POSTER = range(1, 10)
BOX0 = 20


@dataclass(frozen=True)
class Box:
    """Axis-aligned furniture box ``lo`` .. ``hi`` (3,) metres with an albedo (3,) 0..1."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    colour: tuple[float, float, float]
    wood: bool = False


@dataclass(frozen=True)
class Room:
    """Static geometry of the smart room (all metres, room frame, floor z = 0).

    ``chairs`` are seat centres ``(x, y, seat_height, facing)``: a seated person's pelvis is
    above ``(x, y)`` and faces ``facing`` (radians). ``door`` is ``(x0, x1, height)`` of the
    opening in the north wall ``y = depth``; ``extra_doors`` are more openings there, as
    ``(x0, x1, height)``, without a door panel; ``screen`` is ``(y0, y1, z0, z1)`` on the
    east wall ``x = width``. ``wall_cameras`` are floor points ``(x, y)`` on the walls where
    cameras (2.6 m high, looking at the room centre) are mounted besides the four corners.
    """

    width: float = 6.0
    depth: float = 5.0
    height: float = 2.8
    door: tuple[float, float, float] = (4.2, 5.1, 2.1)
    corridor: float = 1.6
    screen: tuple[float, float, float, float] = (1.6, 3.4, 0.9, 2.0)
    poster: tuple[float, float, float, float] = (1.9, 2.9, 1.3, 1.9)
    light: tuple[float, float, float] = (3.0, 2.5, 2.7)
    ambient: float = 0.45
    diffuse: float = 0.6
    boxes: tuple[Box, ...] = ()
    chairs: tuple[tuple[float, float, float, float], ...] = ()
    walkable: tuple[float, float, float, float] = (0.3, 0.3, 5.7, 4.7)
    free_area: tuple[float, float, float, float] = (1.0, 1.3, 5.3, 4.3)
    extra_doors: tuple[tuple[float, float, float], ...] = ()
    wall_cameras: tuple[tuple[float, float], ...] = ()

    @property
    def doors(self) -> tuple[tuple[float, float, float], ...]:
        """All openings ``(x0, x1, height)`` in the north wall, the panelled door first."""
        return (self.door,) + tuple(self.extra_doors)

    def door_centres(self) -> np.ndarray:
        """(D, 2) floor points in the middle of each door opening, metres."""
        return np.array([[0.5 * (d[0] + d[1]), self.depth] for d in self.doors])

    @property
    def door_centre(self) -> np.ndarray:
        """(2,) floor point in the middle of the (first) door opening, metres."""
        return self.door_centres()[0]

    def entry_zone_of(self, door: tuple[float, float, float]) -> tuple[float, ...]:
        """Floor rectangle just inside a door (for the calibration's entry_zones)."""
        return (door[0] - 0.2, self.depth - 0.9, door[1] + 0.2, self.depth)

    def exit_zone_of(self, door: tuple[float, float, float]) -> tuple[float, ...]:
        """Rectangle beyond a door (for the calibration's exits): the door's x span, from
        the walkable floor's edge through the door into the corridor, 1.2 m beyond the
        wall (people who leave walk 1.3 m into the corridor before they disappear, see
        :mod:`mbtrack_ros.synth.motion`; the release margin is well inside it)."""
        return (door[0], self.walkable[3], door[1], self.depth + 1.2)

    @property
    def entry_zone(self) -> tuple[float, float, float, float]:
        """Floor rectangle just inside the first door."""
        return self.entry_zone_of(self.door)

    @property
    def exit_zone(self) -> tuple[float, float, float, float]:
        """Rectangle beyond the first door (see :meth:`exit_zone_of`)."""
        return self.exit_zone_of(self.door)

    def inside(self, xy: np.ndarray) -> np.ndarray:
        """Boolean (...,) of floor points (..., 2) strictly inside the room walls."""
        xy = np.asarray(xy, dtype=np.float64)
        return ((xy[..., 0] > 0) & (xy[..., 0] < self.width)
                & (xy[..., 1] > 0) & (xy[..., 1] < self.depth))


def default_room() -> Room:
    """The 6 x 5 x 2.8 m room with its furniture (table, cabinet, three chairs)."""
    boxes = [
        Box((2.4, 0.1, 0.72), (4.0, 0.9, 0.77), (0.55, 0.38, 0.22), wood=True),  # table top
        Box((5.45, 0.25, 0.0), (5.95, 1.15, 1.25), (0.62, 0.6, 0.55)),  # cabinet
    ]
    for lx, ly in ((2.45, 0.15), (3.9, 0.15), (2.45, 0.8), (3.9, 0.8)):  # table legs
        boxes.append(Box((lx, ly, 0.0), (lx + 0.05, ly + 0.05, 0.72), (0.4, 0.28, 0.16)))
    chairs = []
    seat_colours = ((0.18, 0.24, 0.52), (0.55, 0.16, 0.14), (0.2, 0.42, 0.22))
    for k, y in enumerate((1.7, 2.5, 3.3)):
        colour = seat_colours[k]
        boxes.append(Box((0.2, y - 0.22, 0.0), (0.64, y + 0.22, 0.45), colour))  # seat block
        boxes.append(Box((0.12, y - 0.22, 0.0), (0.2, y + 0.22, 0.95), colour))  # backrest
        chairs.append((0.45, y, 0.45, 0.0))
    return Room(boxes=tuple(boxes), chairs=tuple(chairs))


def large_room() -> Room:
    """A 10 x 8 x 2.8 m room with the default furniture, two cameras at the middle of the
    long walls besides the four corners (six cameras, no ceiling camera needed)."""
    base = default_room()
    return replace(base, width=10.0, depth=8.0, door=(7.2, 8.1, 2.1),
                   screen=(3.0, 4.8, 0.9, 2.0), light=(5.0, 4.0, 2.7),
                   walkable=(0.3, 0.3, 9.7, 7.7), free_area=(1.0, 1.3, 9.3, 7.3),
                   wall_cameras=((5.0, 0.1), (5.0, 7.9)))


def hall_room() -> Room:
    """The 10 x 8 x 2.8 m room of :func:`large_room` with eight wall cameras besides the
    four corners: first the middle of each wall (south, north, west, east), then the thirds
    of the long walls (south, then north); twelve cameras in all, no ceiling camera."""
    return replace(large_room(), wall_cameras=(
        (5.0, 0.1), (5.0, 7.9), (0.1, 4.0), (9.9, 4.0),
        (3.3, 0.1), (6.7, 0.1), (3.3, 7.9), (6.7, 7.9)))


def two_door_room() -> Room:
    """The default room with a second (open) doorway at the west end of the north wall."""
    return replace(default_room(), extra_doors=((1.2, 2.1, 2.1),))


def make_calibration(room: Room, *, width: int = 320, height: int = 240,
                     ceiling: bool = True, cameras: tuple[str, ...] | None = None,
                     ) -> RoomCalibration:
    """Four upper-corner cameras (2.6 m, looking at the room centre), the room's wall
    cameras and a ceiling camera.

    Lens distortion is barrel (k1 < 0, k2 > 0), monotonic over the image. ``cameras``
    selects a subset by name (``cam0`` .. ``cam3`` the corners, ``cam4`` = ceiling,
    ``cam5`` ... the wall cameras in the order of ``room.wall_cameras``).
    """
    if width < 16 or height < 16 or width > 4096 or height > 4096:
        raise SynthError(f'image size {width}x{height} outside 16..4096 pixels')
    target = (0.5 * room.width, 0.5 * room.depth, 0.8)
    m = 0.1
    eyes = [(m, m), (room.width - m, m), (room.width - m, room.depth - m), (m, room.depth - m)]
    cams: dict[str, Camera] = {}
    # Nominal 320 x 240 intrinsics, scaled afterwards to the requested size.
    for k, (x, y) in enumerate(eyes):
        R, t = look_at((x, y, 2.6), target)
        f = 175.0 + 6.0 * k
        K = [[f, 0, 159.5 + 1.5 * (k - 1.5)], [0, f, 119.5 - (k - 1.5)], [0, 0, 1]]
        dist = [-0.16 - 0.01 * k, 0.025, 0.0005 * (k - 1.5), -0.0004 * (k - 1.5), 0.0]
        cams[f'cam{k}'] = Camera(f'cam{k}', 320, 240, K, dist, R, t)
    for k, (x, y) in enumerate(room.wall_cameras):
        R, t = look_at((x, y, 2.6), target)
        f = 170.0 + 4.0 * k
        K = [[f, 0, 159.5], [0, f, 119.5], [0, 0, 1]]
        cams[f'cam{5 + k}'] = Camera(f'cam{5 + k}', 320, 240, K, [-0.15, 0.02, 0.0, 0.0, 0.0],
                                     R, t)
    if ceiling:
        R, t = look_at((0.5 * room.width, 0.5 * room.depth, room.height - 0.05),
                       (0.5 * room.width, 0.5 * room.depth, 0.0), up=(0.0, 1.0, 0.0))
        K = [[120.0, 0, 159.5], [0, 120.0, 119.5], [0, 0, 1]]
        cams['cam4'] = Camera('cam4', 320, 240, K, [-0.2, 0.04, 0.0, 0.0, 0.0], R, t)
    calib = RoomCalibration(cameras=cams, floor=room.walkable,
                            entry_zones=tuple(room.entry_zone_of(d) for d in room.doors),
                            exits=tuple(room.exit_zone_of(d) for d in room.doors))
    if cameras is not None:
        calib = calib.subset(cameras)
    return calib.scaled(width, height) if (width, height) != (320, 240) else calib


# -- static textures ------------------------------------------------------------------------
def _floor_albedo(p: np.ndarray) -> np.ndarray:
    tile = 0.5
    ix, iy = np.floor(p[:, 0] / tile), np.floor(p[:, 1] / tile)
    base = np.array([0.5, 0.48, 0.44]) * (0.82 + 0.3 * hash01(ix, iy, salt=1))[:, None]
    fx, fy = p[:, 0] / tile - ix, p[:, 1] / tile - iy
    grout = (np.minimum(fx, 1 - fx) < 0.03) | (np.minimum(fy, 1 - fy) < 0.03)
    base[grout] = (0.3, 0.3, 0.3)
    fine = 0.9 + 0.2 * hash01(np.floor(p[:, 0] / 0.03), np.floor(p[:, 1] / 0.03), salt=2)
    return base * fine[:, None]


def _wall_albedo(p: np.ndarray, u: np.ndarray, tint: np.ndarray) -> np.ndarray:
    z = p[:, 2]
    smooth = 0.93 + 0.04 * np.sin(u * 2.3) * np.sin(z * 3.1 + 1.0) + 0.03 * np.sin(u * 7.1 + z)
    grain = 0.95 + 0.1 * hash01(np.floor(u / 0.04), np.floor(z / 0.04), salt=3)
    out = tint * (smooth * grain)[:, None]
    out[z < 0.1] = (0.3, 0.26, 0.22)  # skirting board
    return out


def _poster_albedo(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    cells = hash01(np.floor(u * 4), np.floor(v * 3), salt=4)
    palette = np.array([[0.85, 0.2, 0.15], [0.15, 0.35, 0.8], [0.95, 0.8, 0.2],
                        [0.1, 0.6, 0.3], [0.9, 0.9, 0.85]])
    return palette[(cells * len(palette)).astype(int) % len(palette)]


def _shade(room: Room, p: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Lambertian factor (M,) of hit points p (M, 3) with normals (M, 3) under the light."""
    light = np.asarray(room.light) - p
    light /= np.linalg.norm(light, axis=1, keepdims=True)
    return room.ambient + room.diffuse * np.clip(np.sum(normal * light, axis=1), 0.0, None)


SLIDE_SECONDS = 4.0


def screen_slide(uv: np.ndarray, slide: int) -> np.ndarray:
    """Radiance (M, 3) 0..255 of slide number ``slide`` at screen points ``uv`` (M, 2)."""
    cells = hash01(np.floor(uv[:, 0] * 5), np.floor(uv[:, 1] * 4), slide, salt=5)
    base = np.stack([cells, hash01(np.floor(uv[:, 0] * 5), np.floor(uv[:, 1] * 4), slide,
                                   salt=6), 1.0 - cells], axis=1)
    return 60.0 + 170.0 * base


def screen_radiance(uv: np.ndarray, time_s: float,
                    slide_image: np.ndarray | None = None) -> np.ndarray:
    """Emitted radiance (M, 3) 0..255 of screen points ``uv`` (M, 2) in [0, 1] at a time.

    Slides change every 4 s (coloured blocks), a bright bar scrolls down continuously.
    ``slide_image`` is the precomputed :func:`screen_slide` of the current slide.
    """
    slide = int(time_s // SLIDE_SECONDS)
    out = (screen_slide(uv, slide) if slide_image is None else slide_image).copy()
    bar = np.abs(((uv[:, 1] - 0.25 * time_s) % 1.0) - 0.5) < 0.05
    out[bar] = 235.0
    return out


def _door_albedo(a: np.ndarray, z: np.ndarray) -> np.ndarray:
    grain = 0.85 + 0.15 * np.sin(a * 55.0 + 2.0 * np.sin(z * 5.0))
    out = np.array([0.5, 0.32, 0.18]) * grain[:, None]
    handle = (np.abs(a - 0.8) < 0.04) & (np.abs(z - 1.0) < 0.03)
    out[handle] = (0.8, 0.8, 0.75)
    return out


@dataclass
class CameraView:
    """The static room as seen by one camera, plus the pixel sets of the dynamic parts.

    Attributes:
        camera: the camera.
        rays: (H, W, 3) float64 unit world rays of the pixel centres.
        radiance: (H, W, 3) float32 static radiance 0..255 (before camera gains).
        depth: (H, W) float32 distance along the ray to the static surface, metres.
        surface: (H, W) int16 surface id.
    """

    camera: Camera
    room: Room
    rays: np.ndarray = field(repr=False)
    radiance: np.ndarray = field(repr=False)
    depth: np.ndarray = field(repr=False)
    surface: np.ndarray = field(repr=False)
    screen_index: np.ndarray = field(repr=False)
    screen_uv: np.ndarray = field(repr=False)
    door_index: np.ndarray = field(repr=False)
    door_rays: np.ndarray = field(repr=False)
    corridor_radiance: np.ndarray = field(repr=False)
    corridor_depth: np.ndarray = field(repr=False)
    _door_cache: tuple[float, np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    _slide_cache: tuple[int, np.ndarray] | None = field(default=None, repr=False)

    @classmethod
    def build(cls, camera: Camera, room: Room) -> CameraView:
        """Ray-cast the static room for every pixel of ``camera`` (vectorised)."""
        H, W = camera.height, camera.width
        grid = np.stack(np.meshgrid(np.arange(W, dtype=np.float64),
                                    np.arange(H, dtype=np.float64)), axis=-1)
        rays = camera.pixel_rays(grid).reshape(-1, 3)
        C = camera.center
        if not (0 < C[0] < room.width and 0 < C[1] < room.depth and 0 < C[2] < room.height):
            raise SynthError(f'{camera.name}: the renderer needs cameras inside the room')
        n = rays.shape[0]
        best = np.full(n, np.inf)
        surface = np.zeros(n, dtype=np.int16)
        normal = np.zeros((n, 3))
        with np.errstate(divide='ignore', invalid='ignore'):
            planes = ((2, 0.0, FLOOR, (0, 0, 1)), (2, room.height, CEILING, (0, 0, -1)),
                      (0, 0.0, WALL_W, (1, 0, 0)), (0, room.width, WALL_E, (-1, 0, 0)),
                      (1, 0.0, WALL_S, (0, 1, 0)), (1, room.depth, WALL_N, (0, -1, 0)))
            for axis, value, sid, nrm in planes:
                s = (value - C[axis]) / rays[:, axis]
                hit = (s > 1e-6) & (s < best)
                best[hit], surface[hit] = s[hit], sid
                normal[hit] = nrm
            for k, box in enumerate(room.boxes):
                lo, hi = np.asarray(box.lo), np.asarray(box.hi)
                t0, t1 = (lo - C) / rays, (hi - C) / rays
                tnear, tfar = np.minimum(t0, t1), np.maximum(t0, t1)
                tnear = np.where(np.isnan(tnear), -np.inf, tnear)
                tfar = np.where(np.isnan(tfar), np.inf, tfar)
                enter = tnear.max(axis=1)
                hit = (enter <= tfar.min(axis=1)) & (enter > 1e-6) & (enter < best)
                face = tnear.argmax(axis=1)
                best[hit], surface[hit] = enter[hit], BOX0 + k
                nrm = np.zeros((n, 3))
                nrm[np.arange(n), face] = -np.sign(rays[np.arange(n), face])
                normal[hit] = nrm[hit]
        p = C + rays * best[:, None]
        albedo = np.zeros((n, 3))
        sel = surface == FLOOR
        albedo[sel] = _floor_albedo(p[sel])
        albedo[surface == CEILING] = (0.88, 0.88, 0.86)
        tints = {WALL_W: (0.8, 0.76, 0.66), WALL_E: (0.76, 0.78, 0.72),
                 WALL_S: (0.8, 0.74, 0.68), WALL_N: (0.78, 0.76, 0.7)}
        for sid, tint in tints.items():
            sel = surface == sid
            u = p[sel, 1] if sid in (WALL_W, WALL_E) else p[sel, 0]
            albedo[sel] = _wall_albedo(p[sel], u, np.asarray(tint))
        for k, box in enumerate(room.boxes):
            sel = surface == BOX0 + k
            col = np.broadcast_to(np.asarray(box.colour), (int(sel.sum()), 3))
            if box.wood:
                g = 0.82 + 0.18 * np.sin(p[sel, 0] * 60.0 + 3.0 * np.sin(p[sel, 1] * 7.0))
                col = col * g[:, None]
            else:
                col = col * (0.93 + 0.1 * hash01(np.floor(p[sel, 0] / 0.05),
                                                 np.floor(p[sel, 1] / 0.05),
                                                 np.floor(p[sel, 2] / 0.05), salt=7))[:, None]
            albedo[sel] = col
        # poster on the west wall
        py0, py1, pz0, pz1 = room.poster
        sel = ((surface == WALL_W) & (p[:, 1] > py0) & (p[:, 1] < py1)
               & (p[:, 2] > pz0) & (p[:, 2] < pz1))
        albedo[sel] = _poster_albedo((p[sel, 1] - py0) / (py1 - py0),
                                     (p[sel, 2] - pz0) / (pz1 - pz0))
        surface[sel] = POSTER
        radiance = 255.0 * albedo * _shade(room, p, normal)[:, None]
        # wall screen (emissive, content per frame)
        sy0, sy1, sz0, sz1 = room.screen
        sel = ((surface == WALL_E) & (p[:, 1] > sy0) & (p[:, 1] < sy1)
               & (p[:, 2] > sz0) & (p[:, 2] < sz1))
        surface[sel] = SCREEN
        screen_index = np.flatnonzero(sel)
        screen_uv = np.stack([(p[sel, 1] - sy0) / (sy1 - sy0),
                              (sz1 - p[sel, 2]) / (sz1 - sz0)], axis=1)
        # door opening in the north wall: corridor behind it
        dx0, dx1, dz = room.door
        sel = ((surface == WALL_N) & (p[:, 0] > dx0) & (p[:, 0] < dx1) & (p[:, 2] < dz))
        surface[sel] = DOOR
        door_index = np.flatnonzero(sel)
        door_rays = rays[sel]
        corr_rad, corr_depth = _corridor(room, C, door_rays)
        radiance[door_index] = corr_rad
        best[door_index] = corr_depth
        for extra in room.extra_doors:  # open doorways: their corridor is static
            ex0, ex1, ez = extra
            sel = ((surface == WALL_N) & (p[:, 0] > ex0) & (p[:, 0] < ex1) & (p[:, 2] < ez))
            surface[sel] = DOOR
            rad, dep = _corridor(room, C, rays[sel], extra)
            radiance[sel] = rad
            best[sel] = dep
        view = cls(camera=camera, room=room, rays=rays.reshape(H, W, 3),
                   radiance=radiance.reshape(H, W, 3).astype(np.float32),
                   depth=best.reshape(H, W).astype(np.float32),
                   surface=surface.reshape(H, W), screen_index=screen_index,
                   screen_uv=screen_uv, door_index=door_index, door_rays=door_rays,
                   corridor_radiance=corr_rad.astype(np.float32),
                   corridor_depth=corr_depth.astype(np.float32))
        if door_index.size:  # the closed door panel is part of the static image
            rad, dep = view.door_update(0.0)
            view.radiance.reshape(-1, 3)[door_index] = rad
            view.depth.reshape(-1)[door_index] = dep
        return view

    def screen_update(self, time_s: float) -> np.ndarray:
        """Radiance (M, 3) of the screen pixels at ``time_s`` (slide cached per camera)."""
        slide = int(time_s // SLIDE_SECONDS)
        if self._slide_cache is None or self._slide_cache[0] != slide:
            self._slide_cache = (slide, screen_slide(self.screen_uv, slide))
        return screen_radiance(self.screen_uv, time_s, self._slide_cache[1])

    def door_update(self, angle: float) -> tuple[np.ndarray, np.ndarray]:
        """Radiance (M, 3) and depth (M,) of the door pixels with the door open ``angle`` rad.

        The door panel hinges at ``(door.x0, depth)`` and swings out into the corridor.
        """
        if self._door_cache is not None and self._door_cache[0] == angle:
            return self._door_cache[1], self._door_cache[2]
        room, C, d = self.room, self.camera.center, self.door_rays
        dx0, dx1, dz = room.door
        width = dx1 - dx0
        u = np.array([np.cos(angle), np.sin(angle), 0.0])
        nrm = np.array([-np.sin(angle), np.cos(angle), 0.0])
        hinge = np.array([dx0, room.depth, 0.0])
        with np.errstate(divide='ignore', invalid='ignore'):
            s = ((hinge - C) @ nrm) / (d @ nrm)
        p = C + d * s[:, None]
        a = (p - hinge) @ u
        hit = (s > 0) & (a >= 0) & (a <= width) & (p[:, 2] >= 0) & (p[:, 2] <= dz)
        hit &= s < self.corridor_depth
        rad = self.corridor_radiance.copy()
        depth = self.corridor_depth.copy()
        if hit.any():
            face = np.where((d[hit] @ nrm)[:, None] < 0, nrm, -nrm)
            shade = _shade(room, p[hit], np.broadcast_to(face, p[hit].shape).copy())
            rad[hit] = 255.0 * _door_albedo(a[hit], p[hit, 2]) * shade[:, None]
            depth[hit] = s[hit]
        self._door_cache = (angle, rad, depth)
        return rad, depth


def _corridor(room: Room, C: np.ndarray, rays: np.ndarray,
              door: tuple[float, float, float] | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """Radiance (M, 3) and depth (M,) of rays through a door (default: the first) into the
    corridor box behind it."""
    door = room.door if door is None else door
    y0, y1 = room.depth, room.depth + room.corridor
    x0, x1, h = door[0] - 2.0, door[1] + 2.0, 2.4
    m = rays.shape[0]
    best = np.full(m, np.inf)
    kind = np.zeros(m, dtype=int)
    with np.errstate(divide='ignore', invalid='ignore'):
        for k, (axis, value) in enumerate(((2, 0.0), (2, h), (1, y1), (0, x0), (0, x1))):
            s = (value - C[axis]) / rays[:, axis]
            s = np.where((s > 0) & (C[1] + s * rays[:, 1] >= y0 - 1e-9), s, np.inf)
            better = s < best
            best[better], kind[better] = s[better], k
    p = C + rays * best[:, None]
    albedo = np.tile(np.array([0.55, 0.56, 0.6]), (m, 1))
    floor = kind == 0
    albedo[floor] = np.array([0.35, 0.3, 0.27]) * (
        0.9 + 0.2 * hash01(np.floor(p[floor, 0] / 0.3), np.floor(p[floor, 1] / 0.3),
                           salt=8))[:, None]
    # corridor light is dimmer than the room light
    return 255.0 * albedo * 0.55, best
