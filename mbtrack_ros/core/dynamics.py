"""First-order autoregressive motion model of one person (000 §VI-A), vectorised over particles.

Over a time step ``dt`` (seconds, from image stamps) every particle row
``x, y, vx, vy, theta, sitting`` (see :mod:`mbtrack_ros.core.state`) evolves as

* velocity random walk: ``v += N(0, (velocity_noise * sqrt(dt))^2)`` per axis;
  ``velocity_noise`` is in m/s per sqrt(second) so that the spread does not depend on the
  frame rate (000 §VI-A uses 0.6 m/s at 15 Hz; here 0.6 m/s/sqrt(s) gives 0.155 m/s per
  15 Hz frame); with ``velocity_damping`` lambda > 0 (1/s) the velocity is a mean-reverting
  AR(1) process instead, ``v <- exp(-lambda dt) v + noise`` (same noise), which keeps
  hypotheses from building up large velocities while their target is unobserved;
* constant-velocity position: ``p += v * dt + N(0, (position_noise * sqrt(dt))^2)``;
* orientation: a random walk ``theta += N(0, orientation_noise^2 dt)``; with
  ``orientation_follows_velocity`` (000 §VI: the key view is picked by the direction of the
  velocity), a particle faster than ``orientation_speed`` (m/s) faces its walking
  direction instead, ``theta = atan2(vy, vx) + N(0, orientation_noise^2 dt)``. That is
  off by default: the appearance likelihood then selects velocities through the key view
  their direction picks, and a model acquired automatically is annotated with the walking
  direction of three detection frames, often wrong, and a wrong key view then selects
  particles walking the wrong way (``test_filters`` compares both);
* sitting label: flips with probability ``1 - exp(-sit_flip_rate * dt)``;
* the floor bounds of the room reflect positions back inside; the velocity component
  into the wall is set to 0 (``wall_stops``: a person walks up to a wall and stays there;
  a bounce would send the particles that touched the wall away from it at the speed they
  came, and the cloud of a person walking along a wall drifts off it), or flipped
  without ``wall_stops``; with exits (rectangles beyond a door that share a piece of the
  floor's border, ``RoomCalibration.exits``) the
  walkable region is the floor and the exits: a particle that lands in any of them stays,
  one that lands outside all of them is reflected in the rectangle it started from (the
  floor when it started outside every rectangle).

With all noises zero the model is exact constant-velocity motion.
"""
from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from mbtrack_ros.core._kernels import wrap_angle
from mbtrack_ros.core.state import SIT, STATE_DIM, THETA, VX, VY, WALKING_SPEED, X, Y

__all__ = ['DynamicsError', 'MotionConfig', 'concatenate_noise', 'draw_motion_noise',
           'move_particles', 'predict']


class DynamicsError(ValueError):
    """Invalid motion parameters or particle arrays."""


@dataclass(frozen=True)
class MotionConfig:
    """Noise levels of the motion model (all standard deviations per sqrt(second)).

    Attributes:
        velocity_noise: m/s per sqrt(s), velocity diffusion (000 §VI-A: 0.6).
        position_noise: m per sqrt(s), extra position diffusion.
        orientation_noise: rad per sqrt(s).
        orientation_speed: m/s; above it the orientation follows the velocity (only with
            ``orientation_follows_velocity``).
        sit_flip_rate: 1/s, rate of sitting <-> standing label flips.
        max_speed: m/s, velocities are clipped to this norm.
        velocity_damping: 1/s, decay rate of the velocity (0 = random walk).
        orientation_follows_velocity: a particle faster than ``orientation_speed`` faces its
            walking direction (000 §VI); off: the orientation is a random walk of its own
            (module docstring).
        wall_stops: a particle reflected at the floor's border (or its exit's) loses the
            velocity component into it; off: that component changes sign (a bounce).
    """

    velocity_noise: float = 0.6
    position_noise: float = 0.15
    orientation_noise: float = 1.0
    orientation_speed: float = WALKING_SPEED
    sit_flip_rate: float = 0.05
    max_speed: float = 3.0
    velocity_damping: float = 0.0
    orientation_follows_velocity: bool = False
    wall_stops: bool = True

    def __post_init__(self) -> None:
        for name in ('velocity_noise', 'position_noise', 'orientation_noise',
                     'orientation_speed', 'sit_flip_rate', 'velocity_damping'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise DynamicsError(f'motion {name} must be a finite number >= 0, got {value}')
        if not (np.isfinite(self.max_speed) and self.max_speed > 0):
            raise DynamicsError(f'motion max_speed must be > 0, got {self.max_speed}')


_NO_DRAWS = np.zeros((0, 2))     # a noise that is off (contiguous: one compiled version)
_NO_DRAWS_1D = np.zeros(0)
_NO_REGIONS = np.zeros((0, 4))


@njit(cache=True, nogil=True)
def _reflect(p, v, lo, hi, stop):
    """Reflect a position into [lo, hi]; a position outside sets the velocity to 0 with
    ``stop``, else flips its sign on an odd number of bounces."""
    width = hi - lo
    q = np.mod(p - lo, 2.0 * width)         # fold into one period of length 2*width
    if q > width:
        q = 2.0 * width - q
    if stop:
        if p < lo or p > hi:
            v = 0.0
    elif np.mod(np.floor((p - lo) / width), 2.0) == 1.0 and (p < lo or p > hi):
        v = v * -1.0
    return lo + q, v


@njit(cache=True, nogil=True)
def _region_of(x, y, regions):
    """Index of the first rectangle of regions (R, 4) holding (x, y), or -1."""
    for k in range(regions.shape[0]):
        if regions[k, 0] <= x <= regions[k, 2] and regions[k, 1] <= y <= regions[k, 3]:
            return k
    return -1


@njit(cache=True, nogil=True)
def _move(out, dt, decay, dv, max_speed, dp, turn, orientation_speed, dtheta, flip_u,
          flip_p, regions, stop):
    """The motion model on particles out (N, 6) in place, with the random draws made by
    :func:`predict` (empty arrays: that noise is off); one pass per particle, each
    operation the one of the former numpy version (bit-identical results). regions
    (R, 4): none (R = 0), the floor (R = 1) or the floor followed by the exits; stop:
    ``MotionConfig.wall_stops``."""
    for i in range(out.shape[0]):
        home = 0
        if regions.shape[0] > 1:
            home = max(_region_of(out[i, X], out[i, Y], regions), 0)
        vx = out[i, VX]
        vy = out[i, VY]
        if decay != 1.0:
            vx = vx * decay
            vy = vy * decay
        if dv.shape[0]:
            vx = vx + dv[i, 0]
            vy = vy + dv[i, 1]
        speed = np.hypot(vx, vy)
        if speed > max_speed:
            f = max_speed / speed
            vx = vx * f
            vy = vy * f
            speed = max_speed
        x = out[i, X] + vx * dt
        y = out[i, Y] + vy * dt
        if dp.shape[0]:
            x = x + dp[i, 0]
            y = y + dp[i, 1]
        if turn:
            base = np.arctan2(vy, vx) if speed > orientation_speed else out[i, THETA]
            if dtheta.shape[0]:
                base = base + dtheta[i]
            out[i, THETA] = wrap_angle(base)
            if flip_u.shape[0] and flip_u[i] < flip_p:
                out[i, SIT] = 1.0 - out[i, SIT]
        if regions.shape[0] == 1 or (regions.shape[0] > 1
                                     and _region_of(x, y, regions) < 0):
            x, vx = _reflect(x, vx, regions[home, 0], regions[home, 2], stop)
            y, vy = _reflect(y, vy, regions[home, 1], regions[home, 3], stop)
        out[i, X] = x
        out[i, Y] = y
        out[i, VX] = vx
        out[i, VY] = vy


def _regions(floor: tuple[float, float, float, float] | None,
             exits: Sequence[tuple[float, float, float, float]]) -> np.ndarray:
    """The (R, 4) regions argument of :func:`_move`: none, the floor, or the floor followed by
    the exits (cached per floor and exits: a filter passes the same ones every frame; the
    cached arrays are never written)."""
    try:
        return _cached_regions(floor, tuple(exits))
    except TypeError:                       # unhashable (lists): built every time
        return _build_regions(floor, exits)


def _build_regions(floor, exits) -> np.ndarray:
    regions = _NO_REGIONS
    if floor is not None:
        try:
            regions = np.asarray([floor, *exits], dtype=np.float64)
        except (TypeError, ValueError):
            regions = _NO_DRAWS_1D
        if regions.ndim != 2 or regions.shape[1] != 4:
            raise DynamicsError('floor and exits must be (x_min, y_min, x_max, y_max), got '
                                f'{floor!r}, {exits!r}')
    elif len(exits):
        raise DynamicsError('exits need a floor')
    return regions


_cached_regions = functools.lru_cache(maxsize=64)(_build_regions)


def predict(particles: np.ndarray, dt: float, config: MotionConfig,
            rng: np.random.Generator, *,
            floor: tuple[float, float, float, float] | None = None,
            exits: Sequence[tuple[float, float, float, float]] = ()) -> np.ndarray:
    """Propagate particles over ``dt`` seconds (000 Eq. 15: independent 1-body law q).

    Args:
        particles: (N, 6) float64 states (metres, m/s, radians, sitting 0/1).
        dt: time step in seconds, >= 0.
        config: noise levels.
        rng: random generator.
        floor: optional ``(x_min, y_min, x_max, y_max)`` metres; positions are reflected.
        exits: rectangles beyond the floor's border that are walkable too (module
            docstring; ``RoomCalibration.exits``, which checks them); need ``floor``.

    Returns:
        (N, 6) float64 new states (a new array).

    The random numbers are drawn first, in a fixed order (velocity, position, orientation
    noise, sitting flips), then one numba pass moves the particles (a fifth of the CPU time of
    the numpy expressions at 100 particles, same results bit for bit).
    """
    p = np.asarray(particles, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != STATE_DIM:
        raise DynamicsError(f'particles must have shape (N, {STATE_DIM}), got {p.shape}')
    if not (math.isfinite(dt) and dt >= 0):
        raise DynamicsError(f'time step must be finite and >= 0, got {dt}')
    out = p.copy()
    if out.shape[0] == 0:
        return out
    noise = draw_motion_noise(out.shape[0], dt, config, rng)
    move_particles(out, dt, config, noise, floor=floor, exits=exits)
    return out


def draw_motion_noise(n: int, dt: float, config: MotionConfig,
                      rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """The random numbers of :func:`predict` for n particles, drawn in its fixed order:
    velocity (n, 2), position (n, 2), orientation noise (n,) and sitting-flip uniforms (n,);
    a noise that is off is an empty array and draws nothing."""
    if not (math.isfinite(dt) and dt >= 0):
        raise DynamicsError(f'time step must be finite and >= 0, got {dt}')
    sq = np.sqrt(dt)
    dv = dp = _NO_DRAWS
    dtheta = flip_u = _NO_DRAWS_1D
    if config.velocity_noise > 0:
        dv = rng.normal(0.0, config.velocity_noise * sq, size=(n, 2))
    if config.position_noise > 0:
        dp = rng.normal(0.0, config.position_noise * sq, size=(n, 2))
    if dt > 0:
        if config.orientation_noise > 0:
            dtheta = rng.normal(0.0, config.orientation_noise * sq, size=n)
        if config.sit_flip_rate > 0:
            flip_u = rng.random(n)
    return dv, dp, dtheta, flip_u


def concatenate_noise(noises: Sequence[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    """The draws of several :func:`draw_motion_noise` calls (same ``dt`` and config) as the
    draws of their particle sets stacked in the same order."""
    return tuple(np.concatenate(parts) if len(parts) > 1 else parts[0]
                 for parts in zip(*noises))


def move_particles(out: np.ndarray, dt: float, config: MotionConfig,
                   noise: tuple[np.ndarray, ...], *,
                   floor: tuple[float, float, float, float] | None = None,
                   exits: Sequence[tuple[float, float, float, float]] = ()) -> None:
    """Move particles ``out`` (N, 6, C-contiguous float64) in place over ``dt`` seconds with
    the draws ``noise`` of :func:`draw_motion_noise` (N rows each, or empty): the
    deterministic part of :func:`predict`, one numba pass for any number of particle sets
    stacked (each particle moves on its own)."""
    decay = float(np.exp(-config.velocity_damping * dt)) if config.velocity_damping > 0 else 1.0
    flip_p = 0.0
    if dt > 0 and config.sit_flip_rate > 0:
        flip_p = float(-np.expm1(-config.sit_flip_rate * dt))
    dv, dp, dtheta, flip_u = noise
    # no particle is faster than infinity: the orientation is then a random walk of its own
    facing_speed = (float(config.orientation_speed) if config.orientation_follows_velocity
                    else math.inf)
    _move(out, float(dt), decay, dv, float(config.max_speed), dp, bool(dt > 0),
          facing_speed, dtheta, flip_u, flip_p, _regions(floor, exits),
          bool(config.wall_stops))
