"""PDAF, JPDAF and JLF trackers behind the tracker's filter interface (004 §4-5, Fig. 16).

Each track is a constant-velocity Kalman filter on ``(x, y, vx, vy)`` (:mod:`.kalman`); the
orientation follows the velocity above ``orientation_speed``. The sitting column is a
probability of a two-state filter: predicted with the flip rate of the particle filters'
dynamics, sampled as 0/1 in the measurement samples (at least ``sit_explore`` of them in the
less likely posture) and updated with the likelihood ratio of the best sitting and the best
standing sample (:func:`.sampling.posture_update`). An extension of 004, which has no
discrete state. Measurements come from the same
appearance likelihood as the particle filters (``MeasurementModel.separable`` for PDAF and
JPDAF, ``MeasurementModel.joint(..., orders=...)`` for the JLF). No particles are reported.

Registered on import as ``'pdaf'``, ``'jpdaf'`` and ``'jlf'`` in
:mod:`mbtrack_ros.core.filters`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from mbtrack_ros.core.association import kalman
from mbtrack_ros.core.association.jlf import jlf_measurement
from mbtrack_ros.core.association.jpdaf import joint_measurements, jpdaf_update
from mbtrack_ros.core.association.kalman import AssociationError
from mbtrack_ros.core.association.pdaf import pdaf_update
from mbtrack_ros.core.association.sampling import measurement_sampling, posture_update
from mbtrack_ros.core.filters import FilterError, TrackUpdate, register_filter
from mbtrack_ros.core.state import SIT, STATE_DIM, THETA, VX, VY, X, Y

if TYPE_CHECKING:  # pragma: no cover - typing only
    from mbtrack_ros.core.appearance import PersonModel
    from mbtrack_ros.core.camera import RoomCalibration
    from mbtrack_ros.core.likelihood import MeasurementModel
    from mbtrack_ros.core.tracker import TrackerConfig

__all__ = ['AssociationConfig', 'JLFFilter', 'JPDAFFilter', 'PDAFFilter']


@dataclass(frozen=True)
class AssociationConfig:
    """Parameters of the association baselines.

    Attributes:
        samples: N, samples per target (PDAF, JPDAF) or joint samples (JLF) (004 §4.1).
        kept: n, measurements kept per target after suppression (004 §4.1).
        p_detect: P_D, probability that a person yields a measurement.
        p_gate: P_G, validation gate probability (chi-square, 2 dof).
        clutter_density: lambda, false measurements per m^2.
        separation: Delta, minimum separation of the JPDAF's pooled measurements, metres
            (004 §5.1.1).
        nms_radius: suppression radius among one target's samples, metres.
        refine: hill-climb kept measurements with Powell's method (004 §4.1, §5.1.1).
        refine_evals: likelihood evaluations per refinement.
        measurement_std: std of a measured floor position, metres (R = std^2 I).
        sampling_scale: sampling covariance = scale^2 * predicted position covariance ...
        min_sampling_std: ... + min_sampling_std^2 I, metres (the 'tracking window').
        accel_std: white-acceleration noise, m/s per sqrt(s) (= MotionConfig.velocity_noise).
        position_std: extra position diffusion, m per sqrt(s).
        orientation_speed: m/s above which the orientation follows the velocity.
        init_position_std: m, initial position std of a new track.
        init_velocity_std: m/s, initial velocity std of a new track.
        visibility: report the visible fraction per camera from an HJS evaluation at the
            track means (cheap: one particle per track); False reports 1.0.
        sit_flip_rate: 1/s, rate of sitting <-> standing changes (= MotionConfig's).
        sit_explore: minimum fraction of samples in the less probable posture (0 = the
            posture stays as the track was started, as in 004).
    """

    samples: int = 100
    kept: int = 5
    p_detect: float = 0.9
    p_gate: float = 0.99
    clutter_density: float = 0.5
    separation: float = 0.3
    nms_radius: float = 0.05
    refine: bool = False
    refine_evals: int = 30
    measurement_std: float = 0.1
    sampling_scale: float = 1.0
    min_sampling_std: float = 0.1
    accel_std: float = 0.6
    position_std: float = 0.15
    orientation_speed: float = 0.2
    init_position_std: float = 0.1
    init_velocity_std: float = 0.3
    visibility: bool = True
    sit_flip_rate: float = 0.05
    sit_explore: float = 0.05

    def __post_init__(self) -> None:
        def bad(msg: str) -> None:
            raise AssociationError(f'invalid association config: {msg}')

        for name in ('samples', 'kept', 'refine_evals'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                bad(f'{name} must be an integer >= 1, got {value!r}')
        if not 0.0 < self.p_detect <= 1.0:
            bad(f'p_detect must be in (0, 1], got {self.p_detect}')
        if not 0.0 < self.p_gate < 1.0:
            bad(f'p_gate must be in (0, 1), got {self.p_gate}')
        for name in ('clutter_density', 'separation', 'nms_radius', 'sampling_scale',
                     'min_sampling_std', 'accel_std', 'position_std', 'orientation_speed',
                     'init_position_std', 'init_velocity_std'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                bad(f'{name} must be a finite number >= 0, got {value}')
        if not (np.isfinite(self.measurement_std) and self.measurement_std > 0):
            bad(f'measurement_std must be > 0, got {self.measurement_std}')
        if not (np.isfinite(self.sit_flip_rate) and self.sit_flip_rate >= 0):
            bad(f'sit_flip_rate must be a finite number >= 0, got {self.sit_flip_rate}')
        if not 0.0 <= self.sit_explore <= 0.5:
            bad(f'sit_explore must be in [0, 0.5], got {self.sit_explore}')

    @classmethod
    def from_tracker(cls, config: TrackerConfig, **overrides: Any) -> AssociationConfig:
        """Derive the shared settings from a tracker configuration.

        ``samples`` = ``config.particles`` (the same likelihood budget per target as the
        particle filters); process noise and orientation speed from ``config.motion``.
        """
        values = dict(samples=int(config.particles),
                      accel_std=float(config.motion.velocity_noise),
                      position_std=float(config.motion.position_noise),
                      orientation_speed=float(config.motion.orientation_speed),
                      sit_flip_rate=float(config.motion.sit_flip_rate))
        values.update(overrides)
        return cls(**values)

    @property
    def R(self) -> np.ndarray:
        """(2, 2) measurement covariance, m^2."""
        return self.measurement_std ** 2 * np.eye(2)


class _KalmanTracks:
    """Shared bookkeeping: one Kalman filter per track (mean (6,), covariance (4, 4))."""

    name = 'kalman'

    def __init__(self, config: AssociationConfig | None = None, *,
                 calibration: RoomCalibration | None = None) -> None:
        self.config = config or AssociationConfig()
        self.calibration = calibration
        self.camera_names = list(calibration.names) if calibration is not None else []
        self.timings: dict[str, float] = {}
        self.stats: dict[str, float] = {}
        self._means: dict[int, np.ndarray] = {}
        self._covs: dict[int, np.ndarray] = {}
        self._models: dict[int, Any] = {}

    def add(self, track_id: int, model: PersonModel, state: np.ndarray,
            rng: np.random.Generator) -> None:
        """Start a track at ``state`` (6,) with the configured initial uncertainty."""
        if track_id in self._means:
            raise FilterError(f'track {track_id} already exists')
        s = np.asarray(state, dtype=np.float64).reshape(-1)
        if s.shape != (STATE_DIM,) or not np.all(np.isfinite(s)):
            raise FilterError(f'a track state must be {STATE_DIM} finite numbers, got {state!r}')
        c = self.config
        self._means[track_id] = s.copy()
        self._covs[track_id] = np.diag([c.init_position_std ** 2] * 2
                                       + [c.init_velocity_std ** 2] * 2)
        self._models[track_id] = model

    def remove(self, track_id: int) -> None:
        if track_id not in self._means:
            raise FilterError(f'no track {track_id}')
        for store in (self._means, self._covs, self._models):
            del store[track_id]

    def track_ids(self) -> list[int]:
        return list(self._means)

    def reset(self) -> None:
        self._means.clear()
        self._covs.clear()
        self._models.clear()

    # -- shared steps ---------------------------------------------------------------------
    def _predict(self, ids: list[int], dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(K, 6) predicted means and (K, 4, 4) covariances (004 Appendix)."""
        means = np.stack([self._means[t] for t in ids])
        covs = np.stack([self._covs[t] for t in ids])
        try:
            m4, covs = kalman.predict(means[:, :4], covs, dt, accel_std=self.config.accel_std,
                                      position_std=self.config.position_std)
        except AssociationError as err:
            raise FilterError(str(err)) from err
        means = means.copy()
        means[:, :4] = m4
        if self.config.sit_explore > 0.0:  # two-state Markov chain of the posture
            flip = -np.expm1(-self.config.sit_flip_rate * dt)
            means[:, SIT] = means[:, SIT] * (1.0 - flip) + (1.0 - means[:, SIT]) * flip
        return self._orient(means), covs

    def _orient(self, means: np.ndarray) -> np.ndarray:
        speed = np.hypot(means[:, VX], means[:, VY])
        moving = speed > self.config.orientation_speed
        means[moving, THETA] = np.arctan2(means[moving, VY], means[moving, VX])
        return means

    def _store(self, ids: list[int], means: np.ndarray, covs: np.ndarray) -> None:
        if self.calibration is not None:
            x0, y0, x1, y1 = self.calibration.floor
            means[:, X] = np.clip(means[:, X], x0, x1)
            means[:, Y] = np.clip(means[:, Y], y0, y1)
        means = self._orient(means)
        for k, t in enumerate(ids):
            self._means[t] = means[k].copy()
            self._covs[t] = 0.5 * (covs[k] + covs[k].T)

    def _updates(self, ids: list[int], measurement: MeasurementModel) -> dict[int, TrackUpdate]:
        t0 = time.perf_counter()
        visible = self._visible(ids, measurement)
        self.timings['visibility'] = time.perf_counter() - t0
        return {t: TrackUpdate(mean=self._means[t].copy(), covariance=self._covs[t].copy(),
                               visible_fraction=visible[k])
                for k, t in enumerate(ids)}

    def _visible(self, ids: list[int], measurement: MeasurementModel) -> list[dict[str, float]]:
        """Visible fraction per camera at the means, from one HJS evaluation (000 Eq. 34)."""
        ones = [{name: 1.0 for name in self.camera_names} for _ in ids]
        if not self.config.visibility:
            return ones
        states = [self._means[t][None].copy() for t in ids]
        for st in states:  # the more probable posture, as a 0/1 state
            st[:, SIT] = np.round(st[:, SIT])
        result = measurement.hjs(states, [np.ones(1) for _ in ids],
                                 [self._models[t] for t in ids])
        vf = np.asarray(result.visible_fraction, dtype=np.float64)
        if vf.shape != (len(ids), len(self.camera_names)):
            raise FilterError(f'visible_fraction has shape {vf.shape}, expected '
                              f'({len(ids)}, {len(self.camera_names)})')
        return [{name: float(vf[k, c]) for c, name in enumerate(self.camera_names)}
                for k in range(len(ids))]

    def _separable_score(self, measurement: MeasurementModel, model: Any):
        def score(states: np.ndarray) -> np.ndarray:
            return measurement.separable([states], [model]).loglik[0]
        return score


class PDAFFilter(_KalmanTracks):
    """K independent PDAF trackers with measurement sampling (004 §4, Fig. 16 'PDAF')."""

    name = 'pdaf'

    def step(self, dt: float, measurement: MeasurementModel, images: dict[str, np.ndarray],
             rng: np.random.Generator) -> dict[int, TrackUpdate]:
        self.timings, self.stats = {}, {}
        ids = self.track_ids()
        if not ids:
            return {}
        c = self.config
        t0 = time.perf_counter()
        means, covs = self._predict(ids, dt)
        t1 = time.perf_counter()
        found = [measurement_sampling(
            means[k], covs[k], self._separable_score(measurement, self._models[t]), rng,
            n_samples=c.samples, n_keep=c.kept, radius=c.nms_radius, refine=c.refine,
            refine_evals=c.refine_evals, min_std=c.min_sampling_std, scale=c.sampling_scale,
            min_speed=c.orientation_speed, sit_explore=c.sit_explore)
            for k, t in enumerate(ids)]
        t2 = time.perf_counter()
        beta0 = []
        for k in range(len(ids)):
            res = pdaf_update(means[k, :4], covs[k], found[k].positions, c.R,
                              p_detect=c.p_detect, p_gate=c.p_gate,
                              clutter_density=c.clutter_density)
            means[k, :4], covs[k] = res.mean, res.cov
            if c.sit_explore > 0.0:
                means[k, SIT] = posture_update(means[k, SIT], found[k].posture_loglik)
            beta0.append(res.beta0)
        self._store(ids, means, covs)
        t3 = time.perf_counter()
        self.stats = {'measurements': float(np.mean([len(f.loglik) for f in found])),
                      'beta0': float(np.mean(beta0))}
        self.timings.update(predict=t1 - t0, measure=t2 - t1, update=t3 - t2)
        return self._updates(ids, measurement)


class JPDAFFilter(_KalmanTracks):
    """JPDAF over all tracks with joint measurement generation (004 §5.1, Fig. 16 'JPDAF')."""

    name = 'jpdaf'

    def step(self, dt: float, measurement: MeasurementModel, images: dict[str, np.ndarray],
             rng: np.random.Generator) -> dict[int, TrackUpdate]:
        self.timings, self.stats = {}, {}
        ids = self.track_ids()
        if not ids:
            return {}
        c = self.config
        t0 = time.perf_counter()
        means, covs = self._predict(ids, dt)
        t1 = time.perf_counter()
        scores = [self._separable_score(measurement, self._models[t]) for t in ids]
        pool = joint_measurements(means, covs, scores, rng, n_samples=c.samples,
                                  n_keep=c.kept, radius=c.nms_radius, separation=c.separation,
                                  refine=c.refine, refine_evals=c.refine_evals,
                                  scale=c.sampling_scale, min_std=c.min_sampling_std,
                                  min_speed=c.orientation_speed, sit_explore=c.sit_explore)
        t2 = time.perf_counter()
        try:
            res = jpdaf_update(means[:, :4], covs, pool.positions, c.R, p_detect=c.p_detect,
                               p_gate=c.p_gate, clutter_density=c.clutter_density)
        except AssociationError as err:
            raise FilterError(str(err)) from err
        means[:, :4] = res.means
        if c.sit_explore > 0.0:
            means[:, SIT] = posture_update(means[:, SIT], pool.posture_loglik)
        self._store(ids, means, res.covs)
        t3 = time.perf_counter()
        self.stats = {'measurements': float(len(pool.loglik)),
                      'events': float(len(res.events)), 'beta0': float(res.beta0.mean())}
        self.timings.update(predict=t1 - t0, measure=t2 - t1, update=t3 - t2)
        return self._updates(ids, measurement)


class JLFFilter(_KalmanTracks):
    """Joint Likelihood Filter (004 §5.2, Fig. 16 'JLF'): the best joint sample under its
    most likely depth orders is the joint measurement; one Kalman update per track."""

    name = 'jlf'

    def step(self, dt: float, measurement: MeasurementModel, images: dict[str, np.ndarray],
             rng: np.random.Generator) -> dict[int, TrackUpdate]:
        self.timings, self.stats = {}, {}
        ids = self.track_ids()
        if not ids:
            return {}
        if self.calibration is None:
            raise FilterError('the JLF needs the room calibration (cameras) for depth orders')
        c = self.config
        t0 = time.perf_counter()
        means, covs = self._predict(ids, dt)
        t1 = time.perf_counter()
        models = [self._models[t] for t in ids]
        cameras = [self.calibration.cameras[n] for n in self.camera_names]
        heights = np.array([float(m.height) for m in models])
        widths = np.array([float(m.width) for m in models])

        def joint_score(joint_states: np.ndarray, orders: np.ndarray) -> np.ndarray:
            return measurement.joint(joint_states, models, orders=orders)

        seen = set(getattr(measurement, 'active_cameras', self.camera_names))
        res = jlf_measurement(means, covs, joint_score, cameras, heights, widths, rng,
                              active=[n in seen for n in self.camera_names],
                              n_samples=c.samples, refine=c.refine,
                              refine_evals=c.refine_evals, scale=c.sampling_scale,
                              min_std=c.min_sampling_std, min_speed=c.orientation_speed,
                              sit_explore=c.sit_explore)
        t2 = time.perf_counter()
        if np.isfinite(res.loglik):  # 004 §5.2.1: component measurements -> Kalman filters
            m4, covs = kalman.update(means[:, :4], covs, res.states[:, :2], c.R)
            means[:, :4] = m4
            if c.sit_explore > 0.0:
                means[:, SIT] = posture_update(means[:, SIT], res.posture_loglik)
        self._store(ids, means, covs)
        t3 = time.perf_counter()
        self.stats = {'evaluations': float(res.evaluations), 'loglik': float(res.loglik)}
        self.timings.update(predict=t1 - t0, measure=t2 - t1, update=t3 - t2)
        return self._updates(ids, measurement)


def _factory(cls: type) -> Any:
    def factory(calibration: RoomCalibration, config: TrackerConfig) -> _KalmanTracks:
        return cls(AssociationConfig.from_tracker(config), calibration=calibration)
    return factory


register_filter('pdaf', _factory(PDAFFilter))
register_filter('jpdaf', _factory(JPDAFFilter))
register_filter('jlf', _factory(JLFFilter))
