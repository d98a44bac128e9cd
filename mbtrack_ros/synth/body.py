"""Articulated bodies of smooth volumes: 18 ellipsoids per person.

A pose is built in the body frame (x forward, y left, z up, origin on the floor under the
pelvis) from the person's height ``H`` and a gait phase, then rotated by the body
orientation and moved to its floor position. Parts: head, hair, neck, chest, abdomen,
pelvis, upper arms, forearms, hands, thighs, shins, feet. Limbs are ellipsoids spanning
two joints.

Walking: thighs swing ``+-0.45 rad`` (scaled by speed), knees flex in the swing phase,
arms swing opposite to the legs; the body drops so that the lower ankle stays at ankle
height. Sitting (``sit`` in [0, 1] blends the pose): thighs horizontal, shins vertical,
forearms on the thighs, pelvis at chair height.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbtrack_ros.synth.errors import SynthError
from mbtrack_ros.synth.raster import TEX_NOISE, TEX_SOLID, TEX_STRIPES

__all__ = ['Clothing', 'Ellipsoids', 'N_PARTS', 'PART_NAMES', 'pose_ellipsoids',
           'random_clothing']

PART_NAMES = ('thigh_l', 'shin_l', 'foot_l', 'thigh_r', 'shin_r', 'foot_r', 'pelvis', 'torso',
              'chest', 'neck', 'head', 'hair', 'upper_arm_l', 'forearm_l', 'hand_l', 'upper_arm_r',
              'forearm_r', 'hand_r')
N_PARTS = len(PART_NAMES)


@dataclass(frozen=True)
class Clothing:
    """Colours (albedo 0..1, RGB) and textures of one person.

    ``shirt_texture`` / ``trousers_texture`` are TEX_SOLID, TEX_STRIPES or TEX_NOISE with
    the second colour and frequency (stripes or noise cells per metre).
    """

    skin: tuple[float, float, float]
    hair: tuple[float, float, float]
    shirt: tuple[float, float, float]
    shirt2: tuple[float, float, float]
    shirt_texture: int
    shirt_frequency: float
    trousers: tuple[float, float, float]
    trousers2: tuple[float, float, float]
    trousers_texture: int
    trousers_frequency: float
    shoes: tuple[float, float, float]
    long_sleeves: bool


def random_clothing(rng: np.random.Generator) -> Clothing:
    """Draw a person's skin, hair and clothing colours and textures."""
    skins = ((0.93, 0.76, 0.64), (0.82, 0.62, 0.48), (0.62, 0.43, 0.3), (0.42, 0.28, 0.2))
    hairs = ((0.1, 0.07, 0.05), (0.35, 0.22, 0.1), (0.75, 0.6, 0.35), (0.5, 0.5, 0.5))

    def colour() -> tuple[float, float, float]:
        hue = rng.uniform(0, 2 * np.pi)
        sat, val = rng.uniform(0.2, 0.9), rng.uniform(0.25, 0.9)
        rgb = val * (1 - sat * (0.5 - 0.5 * np.cos(hue + np.array([0, 2.1, 4.2]))))
        return tuple(float(c) for c in rgb)

    tex = (TEX_SOLID, TEX_STRIPES, TEX_NOISE)
    return Clothing(
        skin=skins[rng.integers(len(skins))], hair=hairs[rng.integers(len(hairs))],
        shirt=colour(), shirt2=colour(), shirt_texture=int(tex[rng.integers(3)]),
        shirt_frequency=float(rng.uniform(6, 14)), trousers=colour(),
        trousers2=colour(), trousers_texture=int(tex[rng.choice(3, p=[0.6, 0.1, 0.3])]),
        trousers_frequency=float(rng.uniform(15, 30)),
        shoes=tuple(float(c) for c in rng.uniform(0.05, 0.35) * np.ones(3)),
        long_sleeves=bool(rng.random() < 0.6))


@dataclass
class Ellipsoids:
    """P ellipsoids ready for :func:`raster.draw_ellipsoids` (arrays documented there)."""

    centers: np.ndarray
    axes: np.ndarray
    radii: np.ndarray
    owner: np.ndarray
    colour1: np.ndarray
    colour2: np.ndarray
    texture: np.ndarray
    frequency: np.ndarray

    @property
    def to_unit(self) -> np.ndarray:
        """(P, 3, 3) world -> unit-sphere map ``diag(1/r) A^T``."""
        return np.transpose(self.axes, (0, 2, 1)) / self.radii[:, :, None]

    def corners(self) -> np.ndarray:
        """(P, 8, 3) corners of each ellipsoid's oriented bounding box, metres."""
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)],
                         dtype=np.float64)
        local = signs[None, :, :] * self.radii[:, None, :]
        return self.centers[:, None, :] + local @ np.transpose(self.axes, (0, 2, 1))

    def top(self, mask: np.ndarray | None = None) -> float:
        """Highest z of the (selected) ellipsoids, metres."""
        reach = np.sqrt(np.sum((self.axes[:, 2, :] * self.radii) ** 2, axis=1))
        z = self.centers[:, 2] + reach
        return float(z[mask].max() if mask is not None else z.max())

    @staticmethod
    def concat(parts: list[Ellipsoids]) -> Ellipsoids:
        if not parts:
            e = np.zeros((0, 3))
            return Ellipsoids(e, np.zeros((0, 3, 3)), e, np.zeros(0, np.int16), e, e,
                              np.zeros(0, np.int64), np.zeros(0))
        return Ellipsoids(*(np.concatenate([getattr(p, f) for p in parts]) for f in (
            'centers', 'axes', 'radii', 'owner', 'colour1', 'colour2', 'texture',
            'frequency')))

    @staticmethod
    def spheres(centers: np.ndarray, radius: float, owner: int,
                colour: tuple[float, float, float] = (1.0, 0.0, 0.0)) -> Ellipsoids:
        """Plain spheres (markers) at ``centers`` (P, 3)."""
        centers = np.atleast_2d(np.asarray(centers, dtype=np.float64))
        p = centers.shape[0]
        col = np.tile(np.asarray(colour, dtype=np.float64), (p, 1))
        return Ellipsoids(centers, np.tile(np.eye(3), (p, 1, 1)), np.full((p, 3), radius),
                          np.full(p, owner, np.int16), col, col, np.zeros(p, np.int64),
                          np.zeros(p))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two (3,) vectors (np.cross is slow for single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _limb_axes(direction: np.ndarray, side: np.ndarray) -> np.ndarray:
    """(3, 3) columns: a unit vector perpendicular-ish to ``side``, ``side``, ``direction``."""
    z = direction / np.sqrt(direction @ direction)
    y = side - (side @ z) * z
    y = y / np.sqrt(y @ y)
    return np.column_stack((_cross(y, z), y, z))


def pose_ellipsoids(height: float, clothing: Clothing, *, x: float, y: float, theta: float,
                    phase: float = 0.0, stride: float = 0.0, sit: float = 0.0,
                    owner: int = 1) -> tuple[Ellipsoids, float]:
    """The person's 18 ellipsoids (order PART_NAMES) in world coordinates and the top of the head.

    Args:
        height: standing height ``H``, metres (1.0 .. 2.5).
        x, y: floor position under the pelvis, metres; ``theta`` body orientation, rad.
        phase: gait phase, rad; ``stride`` swing amplitude 0..1 (0 = standing still).
        sit: 0 standing .. 1 seated.
    Returns:
        (ellipsoids, z_head) with z_head the highest point of head/hair, metres.
    """
    if not 1.0 <= height <= 2.5:
        raise SynthError(f'body height {height} m outside 1.0..2.5 m')
    H = float(height)
    s = H / 1.75
    sit = float(np.clip(sit, 0.0, 1.0))
    amp = float(np.clip(stride, 0.0, 1.0)) * (1.0 - sit)
    thigh_len, shin_len, ankle_h = 0.245 * H, 0.235 * H, 0.04 * H
    hip_w = 0.085 * s
    ex, ey, _ = np.eye(3)
    centers, axes, radii, cols1, cols2, texs, freqs = [], [], [], [], [], [], []
    cl = clothing

    def add(center, ax, r, c1, c2=None, tex=TEX_SOLID, freq=0.0):
        centers.append(np.asarray(center, dtype=np.float64))
        axes.append(ax)
        radii.append(np.asarray(r, dtype=np.float64) * s)
        cols1.append(c1)
        cols2.append(c1 if c2 is None else c2)
        texs.append(tex)
        freqs.append(freq)

    def limb(a, b, r_side, r_front, c1, c2=None, tex=TEX_SOLID, freq=0.0, overlap=0.02):
        d = b - a
        half = 0.5 * np.linalg.norm(d) + overlap * s
        add(0.5 * (a + b), _limb_axes(d, ey), (r_front, r_side, half / s), c1, c2, tex, freq)

    # legs: hip flexion alpha (forward positive), knee flexion kappa
    legs = []
    for side, sign in ((1.0, 1.0), (-1.0, -1.0)):  # left leg swings with +sin
        alpha = (1 - sit) * 0.45 * amp * sign * np.sin(phase) + sit * 0.5 * np.pi
        kappa = (1 - sit) * amp * 0.9 * max(0.0, sign * np.cos(phase))
        kappa += sit * 0.5 * np.pi
        legs.append((side, alpha, kappa))
    ankles_rel = []
    for side, alpha, kappa in legs:
        knee = thigh_len * np.array([np.sin(alpha), 0.0, -np.cos(alpha)])
        beta = alpha - kappa
        ankle = knee + shin_len * np.array([np.sin(beta), 0.0, -np.cos(beta)])
        ankles_rel.append((knee, ankle))
    hip_z = ankle_h - min(a[1][2] for a in ankles_rel)  # lower ankle at ankle height
    # the seated pelvis moves back over the seat: the floor position stays the pelvis
    for (side, alpha, kappa), (knee, ankle) in zip(legs, ankles_rel):
        hip = np.array([0.0, side * hip_w, hip_z])
        kn, an = hip + knee, hip + ankle
        limb(hip, kn, 0.068, 0.072, cl.trousers, cl.trousers2, cl.trousers_texture,
             cl.trousers_frequency)
        limb(kn, an, 0.05, 0.055, cl.trousers, cl.trousers2, cl.trousers_texture,
             cl.trousers_frequency, overlap=0.035)
        foot_dir = np.array([np.cos(0.3 * (alpha - kappa) * (1 - sit)), 0.0,
                             np.sin(0.3 * (alpha - kappa) * (1 - sit))])
        add(an + 0.045 * s * foot_dir - np.array([0, 0, 0.017 * H]),
            np.column_stack((foot_dir, ey, _cross(foot_dir, ey))),
            (0.125, 0.048, 0.04), cl.shoes)
    lean = 0.08 * sit
    up = np.array([np.sin(lean), 0.0, np.cos(lean)])
    pelvis_c = np.array([0.0, 0.0, hip_z + 0.02 * H])

    def trunk(h_rel: float) -> np.ndarray:  # point on the spine at standing height h_rel*H
        return pelvis_c + (h_rel * H - 0.54 * H) * up

    upright = _limb_axes(up, ey)
    add(pelvis_c, upright, (0.1, 0.17, 0.1), cl.trousers, cl.trousers2, cl.trousers_texture,
        cl.trousers_frequency)
    add(trunk(0.665), upright, (0.11, 0.16, 0.15), cl.shirt, cl.shirt2, cl.shirt_texture,
        cl.shirt_frequency)  # abdomen
    add(trunk(0.765), upright, (0.115, 0.195, 0.12), cl.shirt, cl.shirt2, cl.shirt_texture,
        cl.shirt_frequency)  # chest and shoulders
    add(trunk(0.855), upright, (0.05, 0.05, 0.06), cl.skin)
    head_c = trunk(1.0) - 0.12 * s * up
    head_index = len(centers)
    add(head_c, upright, (0.1, 0.08, 0.115), cl.skin)
    hair_c = head_c + s * (-0.018 * ex + 0.02 * up)
    add(hair_c, upright, (0.095, 0.086, 0.095), cl.hair)
    # arms: shoulder flexion phi (forward positive) opposite to the legs, elbow flexion
    sleeve = cl.shirt if cl.long_sleeves else cl.skin
    for side, sign in ((1.0, -1.0), (-1.0, 1.0)):
        phi = (1 - sit) * 0.35 * amp * sign * np.sin(phase) + sit * 0.1
        elbow = (1 - sit) * (0.15 + 0.25 * amp) + sit * 0.9
        shoulder = trunk(0.81) + side * 0.2 * s * ey
        e_dir = np.array([np.sin(phi), 0.0, -np.cos(phi)])
        el = shoulder + 0.17 * H * e_dir
        w_dir = np.array([np.sin(phi + elbow), 0.0, -np.cos(phi + elbow)])
        wr = el + 0.15 * H * w_dir
        limb(shoulder, el, 0.045, 0.047, cl.shirt)
        limb(el, wr, 0.036, 0.038, sleeve)
        hand_end = wr + 0.09 * H * w_dir
        limb(wr, hand_end, 0.022, 0.04, cl.skin, overlap=0.0)
    c = np.cos(theta)
    sn = np.sin(theta)
    rot = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    centers_w = np.array(centers) @ rot.T + np.array([x, y, 0.0])
    axes_w = rot[None] @ np.array(axes)
    ell = Ellipsoids(centers=centers_w, axes=axes_w, radii=np.array(radii),
                     owner=np.full(len(centers), owner, np.int16), colour1=np.array(cols1),
                     colour2=np.array(cols2), texture=np.array(texs, dtype=np.int64),
                     frequency=np.array(freqs))
    head_parts = np.zeros(len(centers), dtype=bool)
    head_parts[[head_index, head_index + 1]] = True  # head and hair
    return ell, ell.top(head_parts)
