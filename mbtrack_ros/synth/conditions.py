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
"""
from __future__ import annotations

from dataclasses import dataclass

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

    def __post_init__(self) -> None:
        if not (0.0 <= float(self.capture_spread) <= 1.0):
            raise SynthError(f'capture spread must be in [0, 1] frame periods, got '
                             f'{self.capture_spread}')

    @property
    def active(self) -> bool:
        return self != Conditions()

    def capture_leads(self, cameras: int, rng: np.random.Generator) -> np.ndarray:
        """(cameras,) capture leads in frame periods: ``capture_spread k / cameras`` for
        k = 0 .. cameras - 1 in a random order (evenly spread, the smallest 0)."""
        if self.capture_spread <= 0 or cameras == 0:
            return np.zeros(cameras)
        return float(self.capture_spread) * rng.permutation(cameras) / cameras

    def to_dict(self) -> dict:
        return {'capture_spread': float(self.capture_spread)}


def conditions_rng(seed: int) -> np.random.Generator:
    """The generator of the conditions' draws (independent of the recording's own)."""
    return np.random.default_rng([int(seed), 0x5EA1])


#: conditions of presets that exist for them (``real-room``)
PRESET_CONDITIONS: dict[str, Conditions] = {
    'real-room': Conditions(capture_spread=1.0),
    'real-room-short': Conditions(capture_spread=1.0),
}
