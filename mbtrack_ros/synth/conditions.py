"""Real-room conditions a synthetic recording can add to any preset (``mbtrack synth``).

:class:`Conditions` collects them; each is off by default, so a preset renders as it always
did. Their random draws come from a generator of their own (seeded by the recording's seed),
so switching a condition on leaves the people, their motion and the sensor noise as they
were: the same recording with and without a condition differs only by it.

* ``capture_spread``: free-running cameras. Camera k captures frame i at
  ``t_i - lead_k``, the leads evenly spread over ``capture_spread`` frame periods in a
  random order (the smallest is 0: the ground truth and the latest capture are at
  ``t_i``); its image shows
  the people where they were then (positions interpolated between frames) and carries that
  capture time as its stamp.
* ``light_changes``: scheduled changes of the room's light, ``(time_s, (r, g, b) factors,
  ramp_s)`` each: from ``time_s`` on, the light of every camera is multiplied by the
  factors, reached linearly over ``ramp_s`` seconds (0: in one frame, a switch). Equal
  factors dim or brighten; unequal ones change the colour of the light (a warmer white).
* ``lamps``: people cast shadows from this many ceiling lamps (in a row along the room's
  width, 0.2 m below the ceiling), each giving ``lamp_share`` of the light where it shines
  (:mod:`mbtrack_ros.synth.shadows`).
* ``calibration_error``: ``(degrees, metres)``: a perturbed calibration is written beside
  the true one (``calibration_perturbed.yaml``): every camera turned by ``degrees`` about
  a random axis through its centre and its centre moved by ``metres`` in a random
  direction (what a careful calibration in a real room gets wrong).
* ``exposure_drift``: auto exposure of each camera: its gain drifts as
  ``1 + exposure_drift sin(2 pi t / P_k + phi_k)``, periods ``P_k`` of 6-15 s.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from mbtrack_ros.synth.errors import SynthError

__all__ = ['PRESET_CONDITIONS', 'Conditions', 'conditions_rng']


@dataclass(frozen=True)
class Conditions:
    """Real-room conditions of a synthetic recording (all off by default).

    Attributes:
        capture_spread: capture times of the cameras spread over this fraction of a frame
            period (0: synchronised; 1: anywhere within a whole period).
    """

    capture_spread: float = 0.0
    light_changes: tuple[tuple[float, tuple[float, float, float], float], ...] = ()
    exposure_drift: float = 0.0
    lamps: int = 0
    lamp_share: float = 0.35
    calibration_error: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not (0 <= int(self.lamps) <= 8 and 0 < self.lamp_share * max(1, self.lamps) <= 1):
            raise SynthError(f'lamps must be 0..8 and lamps x lamp_share at most 1, got '
                             f'{self.lamps} x {self.lamp_share}')
        if not (0.0 <= float(self.capture_spread) <= 1.0):
            raise SynthError(f'capture spread must be in [0, 1] frame periods, got '
                             f'{self.capture_spread}')
        changes = []
        for change in self.light_changes:
            try:
                time_s, factors, ramp_s = change
                factors = tuple(float(f) for f in np.broadcast_to(
                    np.asarray(factors, dtype=np.float64), (3,)))
                time_s, ramp_s = float(time_s), float(ramp_s)
            except (TypeError, ValueError) as err:
                raise SynthError(f'a light change is (time_s, factors, ramp_s), got '
                                 f'{change!r}') from err
            if not (time_s >= 0 and ramp_s >= 0 and all(0.05 <= f <= 5 for f in factors)):
                raise SynthError(f'light change {change!r}: time and ramp must be >= 0 s, '
                                 'factors in 0.05..5')
            changes.append((time_s, factors, ramp_s))
        object.__setattr__(self, 'light_changes', tuple(sorted(changes)))
        deg, metres = (float(v) for v in self.calibration_error)
        if not (0 <= deg <= 20 and 0 <= metres <= 1):
            raise SynthError(f'calibration error must be 0..20 degrees and 0..1 m, got '
                             f'{self.calibration_error}')
        object.__setattr__(self, 'calibration_error', (deg, metres))
        if not 0.0 <= float(self.exposure_drift) < 0.5:
            raise SynthError(f'exposure drift must be in [0, 0.5), got {self.exposure_drift}')

    @property
    def active(self) -> bool:
        return self != Conditions()

    def capture_leads(self, cameras: int, rng: np.random.Generator) -> np.ndarray:
        """(cameras,) capture leads in frame periods: ``capture_spread k / cameras`` for
        k = 0 .. cameras - 1 in a random order (evenly spread, the smallest 0)."""
        if self.capture_spread <= 0 or cameras == 0:
            return np.zeros(cameras)
        return float(self.capture_spread) * rng.permutation(cameras) / cameras

    def lamp_positions(self, room) -> tuple[np.ndarray, np.ndarray] | None:
        """((L, 3) lamp positions, (L,) shares) of the shadow-casting lamps, or None."""
        if not self.lamps:
            return None
        xs = (np.arange(self.lamps) + 0.5) * room.width / self.lamps
        pos = np.stack([xs, np.full(self.lamps, room.depth / 2),
                        np.full(self.lamps, room.height - 0.2)], axis=1)
        return pos, np.full(self.lamps, float(self.lamp_share))

    def perturbed(self, calibration, rng: np.random.Generator):
        """``calibration`` with every camera's pose off by ``calibration_error``."""
        deg, metres = self.calibration_error
        cams = {}
        for name, cam in calibration.cameras.items():
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            rvec = (np.radians(deg) * axis).reshape(3, 1)
            turn = cv2.Rodrigues(rvec)[0]
            shift = rng.normal(size=3)
            centre = cam.center + metres * shift / np.linalg.norm(shift)
            R = turn @ cam.R          # turned about the camera's own centre
            cams[name] = replace(cam, R=R, t=-R @ centre)
        return replace(calibration, cameras=cams)

    def light(self, time_s: float) -> np.ndarray:
        """(3,) float32 factors of the room's light at ``time_s`` (1 before any change)."""
        out = np.ones(3)
        for start, factors, ramp in self.light_changes:
            if time_s < start:
                break
            share = 1.0 if ramp <= 0 else min(1.0, (time_s - start) / ramp)
            out *= 1.0 + share * (np.asarray(factors) - 1.0)
        return out.astype(np.float32)

    def exposure(self, cameras: int, rng: np.random.Generator):
        """A function ``(camera index, time_s) -> gain`` of the auto-exposure drift."""
        periods = rng.uniform(6.0, 15.0, cameras)
        phases = rng.uniform(0.0, 2 * np.pi, cameras)
        amp = float(self.exposure_drift)

        def gain(k: int, time_s: float) -> float:
            if amp == 0:
                return 1.0
            return float(1.0 + amp * np.sin(2 * np.pi * time_s / periods[k] + phases[k]))
        return gain

    def to_dict(self) -> dict:
        return {'capture_spread': float(self.capture_spread),
                'light_changes': [[t, list(f), r] for t, f, r in self.light_changes],
                'exposure_drift': float(self.exposure_drift), 'lamps': int(self.lamps),
                'lamp_share': float(self.lamp_share),
                'calibration_error': list(self.calibration_error)}


def conditions_rng(seed: int) -> np.random.Generator:
    """The generator of the conditions' draws (independent of the recording's own)."""
    return np.random.default_rng([int(seed), 0x5EA1])


#: conditions of presets that exist for them (``real-room``)
_REAL_ROOM = Conditions(
    capture_spread=1.0, exposure_drift=0.08, lamps=2, calibration_error=(1.0, 0.03),
    light_changes=((6.0, (0.7, 0.7, 0.7), 0.5),          # dimmed by 30 % over 0.5 s
                   (12.0, (1.05, 0.97, 0.8), 0.0),       # a warmer white, switched
                   (16.0, (1.4, 1.4, 1.4), 0.0)))        # +40 % in one frame
PRESET_CONDITIONS: dict[str, Conditions] = {
    'real-room': _REAL_ROOM,
    'real-room-short': replace(_REAL_ROOM, light_changes=((1.0, (0.6, 0.6, 0.6), 0.0),
                                                          (2.0, (1.05, 0.97, 0.8), 0.0))),
}
