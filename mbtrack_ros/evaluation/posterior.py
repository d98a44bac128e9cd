"""Posterior mass around the ground truth as a function of distance (000, Fig. 6).

Particle-set file (written by ``mbtrack replay --save-particles``), a NumPy ``.npz`` archive
with one row per (frame, track)::

    stamp_ns  (M,)       int64    frame stamp, nanoseconds
    track_id  (M,)       int64    track id (as in the tracks CSV)
    xy        (M, N, 2)  float32  particle floor positions x, y, metres, room frame
    weights   (M, N)     float32  normalised particle weights (each row sums to 1)

Tracks with fewer than ``N`` particles are padded with zero-weight particles at (0, 0).

The curve: for every ground-truth person-frame, take the track matched to that person by the
CLEAR-MOT matching at that frame (:func:`~mbtrack_ros.evaluation.clear_mot.clear_mot`); the
mass of its particles within distance ``d`` of the true position is the weighted fraction of
particles closer than ``d`` (000 §VII: fraction of resampled particles within a distance of the
true position). A missed person-frame, or a matched track without a particle row, has mass 0.
The curve is the average over all ground-truth person-frames.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mbtrack_ros.core.state import X, Y, FrameResult
from mbtrack_ros.evaluation.clear_mot import ClearMotResult, clear_mot
from mbtrack_ros.evaluation.errors import EvaluationError
from mbtrack_ros.recording.csvfiles import GroundTruthRow, TrackRow

__all__ = [
    'DEFAULT_DISTANCES', 'PARTICLE_KEYS', 'ParticleRecorder', 'ParticleSet',
    'PosteriorMassResult', 'load_particles', 'posterior_mass', 'posterior_mass_curve',
    'save_particles',
]

#: (101,) distances 0, 0.01, ..., 1.0 metres
DEFAULT_DISTANCES = np.linspace(0.0, 1.0, 101)
PARTICLE_KEYS = ('stamp_ns', 'track_id', 'xy', 'weights')
_CHUNK_ROWS = 2048  # particle rows per distance batch


@dataclass(frozen=True)
class ParticleSet:
    """Particle floor positions per (frame, track); see the module docstring for shapes."""

    stamp_ns: np.ndarray
    track_id: np.ndarray
    xy: np.ndarray
    weights: np.ndarray

    def __post_init__(self) -> None:
        m = self.stamp_ns.shape[0] if self.stamp_ns.ndim == 1 else -1
        if (m < 0 or self.track_id.shape != (m,) or self.xy.ndim != 3
                or self.xy.shape[0] != m or self.xy.shape[2] != 2
                or self.weights.shape != self.xy.shape[:2]):
            raise EvaluationError(
                'particle set shapes must be stamp_ns (M,), track_id (M,), xy (M, N, 2), '
                f'weights (M, N); got {self.stamp_ns.shape}, {self.track_id.shape}, '
                f'{self.xy.shape}, {self.weights.shape}')

    def __len__(self) -> int:
        return int(self.stamp_ns.shape[0])


def save_particles(path: str | Path, particles: ParticleSet) -> Path:
    """Write a particle set as ``.npz`` (float32 positions and weights); returns the path."""
    path = Path(path)
    try:
        with path.open('wb') as handle:
            np.savez_compressed(
                handle, stamp_ns=particles.stamp_ns.astype(np.int64),
                track_id=particles.track_id.astype(np.int64),
                xy=particles.xy.astype(np.float32), weights=particles.weights.astype(np.float32))
    except OSError as err:
        raise EvaluationError(f'cannot write {path}: {err.strerror or err}') from err
    return path


def load_particles(path: str | Path) -> ParticleSet:
    """Read and check a particle file; weights are renormalised per row in float64."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in PARTICLE_KEYS if k not in data.files]
            if missing:
                raise EvaluationError(f'{path}: missing array(s) {", ".join(missing)} '
                                      f'(expected {", ".join(PARTICLE_KEYS)})')
            arrays = {k: data[k] for k in PARTICLE_KEYS}
    except EvaluationError:
        raise
    except OSError as err:
        raise EvaluationError(f'cannot read {path}: {err.strerror or err}') from err
    except (ValueError, EOFError) as err:
        raise EvaluationError(f'{path}: not a particle .npz file ({err})') from err
    for k in ('stamp_ns', 'track_id'):
        if not np.issubdtype(arrays[k].dtype, np.integer):
            raise EvaluationError(f'{path}: {k} must be integer, got {arrays[k].dtype}')
    try:
        ps = ParticleSet(stamp_ns=arrays['stamp_ns'].astype(np.int64),
                         track_id=arrays['track_id'].astype(np.int64),
                         xy=arrays['xy'].astype(np.float32, copy=False),
                         weights=arrays['weights'].astype(np.float64))
    except EvaluationError as err:
        raise EvaluationError(f'{path}: {err}') from err
    w = ps.weights
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise EvaluationError(f'{path}: weights must be finite and non-negative')
    if not np.all(np.isfinite(ps.xy[w > 0])):
        raise EvaluationError(f'{path}: particle positions with weight must be finite')
    total = w.sum(axis=1)
    if np.any(total <= 0):
        raise EvaluationError(f'{path}: a particle row has zero total weight '
                              f'(row {int(np.flatnonzero(total <= 0)[0])})')
    return ParticleSet(stamp_ns=ps.stamp_ns, track_id=ps.track_id, xy=ps.xy,
                       weights=w / total[:, None])


class ParticleRecorder:
    """Collects particle rows frame by frame and writes them as one particle file."""

    def __init__(self) -> None:
        self._rows: list[tuple[int, int, np.ndarray, np.ndarray]] = []

    def __len__(self) -> int:
        return len(self._rows)

    def add(self, stamp_ns: int, track_id: int, xy: np.ndarray, weights: np.ndarray) -> None:
        """Add one track's particles: ``xy`` (N, 2) metres, ``weights`` (N,) (normalised here)."""
        xy = np.asarray(xy, np.float64)
        w = np.asarray(weights, np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2 or w.shape != (xy.shape[0],) or xy.shape[0] == 0:
            raise EvaluationError(f'particles must be xy (N, 2) and weights (N,) with N > 0, got '
                                  f'{xy.shape} and {w.shape}')
        if not (np.all(np.isfinite(w)) and np.all(w >= 0) and w.sum() > 0):
            raise EvaluationError('particle weights must be finite, non-negative, not all 0')
        if not np.all(np.isfinite(xy)):
            raise EvaluationError('particle positions must be finite')
        self._rows.append((int(stamp_ns), int(track_id), xy.astype(np.float32),
                           (w / w.sum()).astype(np.float32)))

    def add_frame(self, result: FrameResult) -> None:
        """Add every track of a tracker result that carries particles and weights."""
        for t in result.tracks:
            if t.particles is not None and t.weights is not None:
                self.add(result.stamp_ns, t.track_id, t.particles[:, [X, Y]], t.weights)

    def particle_set(self) -> ParticleSet:
        """The rows collected so far, padded to the largest particle count."""
        m = len(self._rows)
        n = max((r[2].shape[0] for r in self._rows), default=0)
        xy = np.zeros((m, n, 2), np.float32)
        w = np.zeros((m, n), np.float32)
        for i, (_, _, p, pw) in enumerate(self._rows):
            xy[i, :p.shape[0]] = p
            w[i, :p.shape[0]] = pw
        return ParticleSet(stamp_ns=np.array([r[0] for r in self._rows], np.int64),
                           track_id=np.array([r[1] for r in self._rows], np.int64),
                           xy=xy, weights=w)

    def save(self, path: str | Path) -> Path:
        """Write the collected rows (see :func:`save_particles`)."""
        return save_particles(path, self.particle_set())


@dataclass(frozen=True)
class PosteriorMassResult:
    """A posterior-mass curve and its bookkeeping.

    Attributes:
        distances: (D,) metres.
        fraction: (D,) mean posterior mass within each distance, in [0, 1].
        person_frames: ground-truth person-frames averaged over.
        with_particles: person-frames with a matched track that has a particle row.
        missing_particle_rows: matched person-frames whose track has no particle row (mass 0).
    """

    distances: np.ndarray
    fraction: np.ndarray
    person_frames: int
    with_particles: int
    missing_particle_rows: int

    def at(self, distance_m: float) -> float:
        """Mass within ``distance_m`` (linear interpolation on the curve)."""
        return float(np.interp(distance_m, self.distances, self.fraction))

    def to_dict(self) -> dict:
        return {'distances_m': self.distances.tolist(), 'fraction': self.fraction.tolist(),
                'mass_within_0_5m': self.at(0.5), 'person_frames': self.person_frames,
                'with_particles': self.with_particles,
                'missing_particle_rows': self.missing_particle_rows}


def _as_particle_set(particles: ParticleSet | str | Path | Mapping) -> ParticleSet:
    if isinstance(particles, ParticleSet):
        return particles
    if isinstance(particles, (str, Path)):
        return load_particles(particles)
    try:
        return ParticleSet(**{k: np.asarray(particles[k]) for k in PARTICLE_KEYS})
    except (KeyError, TypeError) as err:
        raise EvaluationError(f'particles need arrays {", ".join(PARTICLE_KEYS)}') from err


def posterior_mass(particles: ParticleSet | str | Path | Mapping,
                   truth: Sequence[GroundTruthRow], tracks: Sequence[TrackRow],
                   distances: np.ndarray | Sequence[float] | None = None, *,
                   threshold_m: float = 0.5,
                   matching: ClearMotResult | None = None) -> PosteriorMassResult:
    """Posterior mass within each distance of the truth, averaged over person-frames.

    Args:
        particles: a :class:`ParticleSet`, a particle file path, or a mapping of the arrays.
        truth, tracks: the rows scored by CLEAR MOT (the matching decides which track's
            particles belong to which person at each frame).
        distances: (D,) metres, non-negative; default :data:`DEFAULT_DISTANCES`.
        matching: a precomputed :func:`clear_mot` result of the same rows (else computed).
    """
    ps = _as_particle_set(particles)
    d = DEFAULT_DISTANCES if distances is None else np.asarray(distances, np.float64)
    if d.ndim != 1 or d.size == 0 or not np.all(np.isfinite(d)) or np.any(d < 0):
        raise EvaluationError('distances must be a non-empty 1-D array of non-negative metres')
    if matching is None:
        matching = clear_mot(tracks, truth, threshold_m=threshold_m)
    m = matching.matches_detail
    if m is None:
        raise EvaluationError('the CLEAR MOT result carries no per-frame matches')
    g = len(m)

    # row of the particle set for each (stamp, track); duplicates are an error
    key_order = np.lexsort((ps.track_id, ps.stamp_ns))
    ks, kt = ps.stamp_ns[key_order], ps.track_id[key_order]
    if np.any((ks[1:] == ks[:-1]) & (kt[1:] == kt[:-1])):
        raise EvaluationError('particle set has two rows for the same (stamp, track)')
    sel = np.flatnonzero(m.matched)
    # locate (stamp, track) of the matched person-frames by a lexicographic binary search
    lo = np.searchsorted(ks, m.stamp_ns[sel], side='left')
    hi = np.searchsorted(ks, m.stamp_ns[sel], side='right')
    rows = np.full(sel.shape[0], -1, np.int64)
    for j in np.flatnonzero(hi > lo):
        k = lo[j] + np.searchsorted(kt[lo[j]:hi[j]], m.track_id[sel[j]])
        if k < hi[j] and kt[k] == m.track_id[sel[j]]:
            rows[j] = key_order[k]
    found = rows >= 0
    prow = rows[found]
    truth_xy = np.stack([m.x[sel[found]], m.y[sel[found]]], axis=1)  # (K, 2)

    # the mean over person-frames of the mass within d equals sum_{pairs, dist <= d} w / G over
    # all (person-frame, particle) pairs: bin each pair at the first grid distance >= its own
    # distance, then accumulate; chunked over rows to bound memory
    d_order = np.argsort(d, kind='stable')
    d_sorted = d[d_order]
    mass = np.zeros(d.shape[0] + 1)
    for c in range(0, prow.shape[0], _CHUNK_ROWS):
        rows_c = prow[c:c + _CHUNK_ROWS]
        diff = ps.xy[rows_c].astype(np.float64) - truth_xy[c:c + _CHUNK_ROWS, None, :]
        dist = np.hypot(diff[..., 0], diff[..., 1]).ravel()
        w = ps.weights[rows_c].astype(np.float64).ravel()
        mass += np.bincount(np.searchsorted(d_sorted, dist, side='left'), weights=w,
                            minlength=d.shape[0] + 1)
    frac = np.empty(d.shape[0])
    frac[d_order] = np.cumsum(mass[:-1]) / g
    return PosteriorMassResult(distances=d.copy(), fraction=np.clip(frac, 0.0, 1.0),
                               person_frames=g, with_particles=int(found.sum()),
                               missing_particle_rows=int((~found).sum()))


def posterior_mass_curve(particles: ParticleSet | str | Path | Mapping,
                         truth: Sequence[GroundTruthRow], tracks: Sequence[TrackRow],
                         distances: np.ndarray | Sequence[float] | None = None, *,
                         threshold_m: float = 0.5,
                         matching: ClearMotResult | None = None) -> np.ndarray:
    """(D,) mean posterior mass within each distance; see :func:`posterior_mass`."""
    return posterior_mass(particles, truth, tracks, distances, threshold_m=threshold_m,
                          matching=matching).fraction
