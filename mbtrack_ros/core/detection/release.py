"""Release of tracks that lost their foreground support (003 §4.3).

A track is supported in a frame when the rendered silhouette of its estimate is covered by
foreground (coverage >= ``min_coverage``) in at least one camera that should see it
(silhouette at least ``min_area`` pixels in the image). When the room has a ceiling camera
only the ceiling cameras decide (003 §4.3 analyses the top-down view); otherwise the corner
cameras do. A track unsupported - or whose existence probability (001 §3.2, see
:mod:`mbtrack_ros.core.existence`) is below ``existence_threshold`` - for ``timeout``
seconds in a row is terminated.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.detector import FrameEvidence, is_ceiling

__all__ = ['ReleaseConfig', 'Releaser']


@dataclass(frozen=True)
class ReleaseConfig:
    """Parameters of the track release.

    Attributes:
        timeout: seconds without support before a track ends (003 §4.3: 1 s).
        min_coverage: foreground coverage of the silhouette that counts as support.
        min_area: pixels (at 320x240, scaled with the image) for a camera to see a track.
        use_ceiling: let top-down cameras alone decide when the room has one.
        existence_threshold: existence below this also counts as unsupported (0 disables).
    """

    timeout: float = 1.0
    min_coverage: float = 0.3
    min_area: int = 30
    use_ceiling: bool = True
    existence_threshold: float = 0.1

    def __post_init__(self) -> None:
        if not self.timeout >= 0:
            raise DetectionError(f'release timeout must be >= 0, got {self.timeout}')
        if not 0.0 <= self.min_coverage <= 1.0:
            raise DetectionError(f'min_coverage must be in [0, 1], got {self.min_coverage}')


class Releaser:
    """Keeps, per track, the time since it was last supported and ends stale tracks."""

    def __init__(self, calibration: RoomCalibration, config: ReleaseConfig | None = None
                 ) -> None:
        self.calibration = calibration
        self.config = config or ReleaseConfig()
        ceiling = [n for n, c in calibration.cameras.items() if is_ceiling(c)]
        self.deciding = ceiling if (ceiling and self.config.use_ceiling) \
            else [n for n in calibration.cameras if n not in ceiling] or ceiling
        self._since: dict[int, int] = {}

    def support(self, evidence: Mapping[str, FrameEvidence], silhouettes: Mapping[str, object]
                ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Support of K tracks from their rendered silhouettes.

        Args:
            evidence: per camera the frame's foreground.
            silhouettes: per camera the K tracks' silhouettes (``shape.rasterize`` output).

        Returns:
            supported: (K,) bool.
            coverage: camera -> (K,) coverage (NaN where the camera does not see the track);
                all cameras with evidence, not only the deciding ones.
        """
        cfg = self.config
        coverage: dict[str, np.ndarray] = {}
        supported = None
        for name, sil in silhouettes.items():
            if name not in evidence:
                continue
            cam = self.calibration.cameras[name]
            cov, _, area = evidence[name].plain.coverage(sil)
            sees = area >= cfg.min_area * cam.width * cam.height / (320.0 * 240.0)
            coverage[name] = np.where(sees, cov, np.nan)
            if supported is None:
                supported = np.zeros(cov.shape, bool)
            if name in self.deciding:
                supported |= sees & (cov >= cfg.min_coverage)
        if supported is None:
            k = len(next(iter(silhouettes.values())).offsets) - 1 if silhouettes else 0
            supported = np.zeros(k, bool)
        return supported, coverage

    def update(self, stamp_ns: int, ids: Sequence[int], supported: Sequence[bool],
               existence: Sequence[float] | None = None) -> list[int]:
        """Record one frame's support; returns the ids to release now."""
        cfg = self.config
        if len(supported) != len(ids) or (existence is not None and len(existence) != len(ids)):
            raise DetectionError('ids, supported and existence must have the same length')
        ended = []
        live = set(int(i) for i in ids)
        for tid in list(self._since):
            if tid not in live:
                del self._since[tid]
        for k, tid in enumerate(ids):
            tid = int(tid)
            bad = not bool(supported[k])
            if existence is not None and existence[k] < cfg.existence_threshold:
                bad = True
            if not bad:
                self._since.pop(tid, None)
                continue
            since = self._since.setdefault(tid, int(stamp_ns))
            if (int(stamp_ns) - since) / 1e9 >= cfg.timeout:
                ended.append(tid)
                del self._since[tid]
        return ended

    def forget(self, track_id: int) -> None:
        self._since.pop(int(track_id), None)
