"""Multi-person filters behind one interface: HJS (000 Algorithm 1), separable and joint.

The filter interface
--------------------
Every tracking algorithm the :class:`~mbtrack_ros.core.tracker.Tracker` can run implements
:class:`TrackingFilter`::

    class TrackingFilter(Protocol):
        name: str                         # 'hjs', 'separable', 'joint', 'pdaf', ...
        timings: dict[str, float]         # seconds per stage of the last step()
        stats: dict[str, float]           # diagnostics of the last step() (BP iterations ...)
        def add(self, track_id: int, model: PersonModel, state: np.ndarray,
                rng: np.random.Generator) -> None      # state (6,) valid at the last step
        def remove(self, track_id: int) -> None
        def track_ids(self) -> list[int]               # in insertion order
        def reset(self) -> None                         # forget every track
        def step(self, dt: float, measurement: MeasurementModel,
                 images: dict[str, np.ndarray],
                 rng: np.random.Generator) -> dict[int, TrackUpdate]

``step`` predicts every track over ``dt`` seconds and updates it with the current frame:
``measurement`` is the :class:`~mbtrack_ros.core.likelihood.MeasurementModel` on which
``set_images(images)`` has already been called (particle filters use its ``hjs``,
``separable`` or ``joint`` evaluation); ``images`` are the raw ``(H, W, 3) uint8`` RGB frames
by camera name for filters that extract their own measurements (PDAF/JPDAF/JLF). It returns
one :class:`TrackUpdate` per track: posterior mean ``(6,)``, covariance ``(4, 4)`` of
``x, y, vx, vy``, expected visible fraction per camera, and, for particle filters, the
posterior particles ``(N, 6)`` with normalised weights ``(N,)`` (``None`` for Kalman-based
filters).

Plugging in further algorithms
------------------------------
A factory ``factory(calibration: RoomCalibration, config: TrackerConfig) -> TrackingFilter``
is registered under a name with :func:`register_filter`. Names not registered yet are
looked up by importing the modules in :data:`PLUGIN_MODULES` (the association package of
the PDAF/JPDAF/JLF baselines registers ``'pdaf'``, ``'jpdaf'`` and ``'jlf'`` on import).
:func:`make_filter` builds a filter by name.
"""
from __future__ import annotations

import importlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from mbtrack_ros.core.dynamics import (
    MotionConfig, concatenate_noise, draw_motion_noise, move_particles, predict)
from mbtrack_ros.core.groups import interaction_groups
from mbtrack_ros.core.mrf import belief_propagation
from mbtrack_ros.core.resampling import (
    ResamplingError, normalize_log_weight_rows, normalize_log_weights, systematic_indices,
    systematic_resample)
from mbtrack_ros.core.state import STATE_DIM, THETA, VX, VY, X, Y

if TYPE_CHECKING:  # pragma: no cover - typing only
    from mbtrack_ros.core.appearance import PersonModel
    from mbtrack_ros.core.camera import RoomCalibration
    from mbtrack_ros.core.likelihood import MeasurementModel
    from mbtrack_ros.core.tracker import TrackerConfig

__all__ = [
    'PLUGIN_MODULES', 'FilterConfig', 'FilterError', 'GroupedHJSFilter', 'HJSFilter',
    'JointFilter',
    'SeparableFilter', 'TrackUpdate', 'TrackingFilter', 'available_filters', 'make_filter',
    'exclusion_log_prior', 'register_filter', 'summarize_particles',
]


class FilterError(ValueError):
    """Invalid filter configuration, unknown track or algorithm, malformed state."""


@dataclass
class TrackUpdate:
    """One track's posterior after a filter step.

    Attributes:
        mean: (6,) posterior mean state (circular mean of theta, sitting probability).
        covariance: (4, 4) posterior covariance of x, y, vx, vy (m, m/s).
        visible_fraction: per camera name, expected visible fraction of the silhouette.
        particles: (N, 6) posterior particles, or None (Kalman-based filters).
        weights: (N,) normalised posterior weights, or None.
        own: the target's own posterior where the estimate above also carries the
            spatial-exclusion prior of the other targets (HJS with the MRF, 000 Eq. 16-18):
            the same particles weighted by prior x likelihood alone, as the filter carries
            them on; None where the estimate is the target's own posterior. The track
            management reads it (see :class:`~mbtrack_ros.core.tracker.Tracker`).
    """

    mean: np.ndarray
    covariance: np.ndarray
    visible_fraction: dict[str, float] = field(default_factory=dict)
    particles: np.ndarray | None = None
    weights: np.ndarray | None = None
    own: TrackUpdate | None = None


@runtime_checkable
class TrackingFilter(Protocol):
    """The interface every tracking algorithm implements (see the module docstring)."""

    name: str
    timings: dict[str, float]
    stats: dict[str, float]

    def add(self, track_id: int, model: PersonModel, state: np.ndarray,
            rng: np.random.Generator) -> None: ...

    def remove(self, track_id: int) -> None: ...

    def track_ids(self) -> list[int]: ...

    def reset(self) -> None: ...

    def step(self, dt: float, measurement: MeasurementModel, images: dict[str, np.ndarray],
             rng: np.random.Generator) -> dict[int, TrackUpdate]: ...


@dataclass(frozen=True)
class FilterConfig:
    """Parameters of the particle filters.

    Attributes:
        particles: particles per target (HJS, separable).
        joint_particles: joint particles (joint filter).
        motion: motion model noise (:class:`~mbtrack_ros.core.dynamics.MotionConfig`).
        use_mrf: apply the spatial-exclusion MRF prior (000 §III-B).
        mrf_radius: exclusion radius r, metres (000 §VI-A: 0.4).
        mrf_epsilon: floor of the exclusion potential (see :mod:`mbtrack_ros.core.mrf`).
        theta_bp: BP stopping threshold (000 Eq. 43: 0.01).
        max_bp_iterations: BP iteration limit.
        init_position_spread: m, std of the initial particle cloud around a new state.
        init_velocity_spread: m/s, std of the initial velocities.
    """

    particles: int = 100
    joint_particles: int = 10_000
    motion: MotionConfig = field(default_factory=MotionConfig)
    use_mrf: bool = True
    mrf_radius: float = 0.4
    mrf_epsilon: float = 1e-3
    theta_bp: float = 0.01
    max_bp_iterations: int = 20
    init_position_spread: float = 0.05
    init_velocity_spread: float = 0.1

    def __post_init__(self) -> None:
        if int(self.particles) < 1 or int(self.joint_particles) < 1:
            raise FilterError('particle counts must be >= 1')
        if not (self.mrf_radius >= 0 and 0 < self.mrf_epsilon <= 1):
            raise FilterError('mrf_radius must be >= 0 and mrf_epsilon in (0, 1]')
        if not (self.theta_bp > 0 and self.max_bp_iterations >= 1):
            raise FilterError('theta_bp must be > 0 and max_bp_iterations >= 1')
        if not (self.init_position_spread >= 0 and self.init_velocity_spread >= 0):
            raise FilterError('initial spreads must be >= 0')


def summarize_particles(particles: np.ndarray,
                        weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean (6,) and covariance (4, 4) of x, y, vx, vy of particles (N, 6).

    theta is averaged on the circle; the sitting column becomes the sitting probability.
    """
    w = weights / weights.sum()
    mean = w @ particles
    mean[THETA] = np.arctan2(w @ np.sin(particles[:, THETA]), w @ np.cos(particles[:, THETA]))
    d = particles[:, X:VY + 1] - mean[X:VY + 1]
    cov = (d * w[:, None]).T @ d
    return mean, cov


def _check_state(state: np.ndarray) -> np.ndarray:
    s = np.asarray(state, dtype=np.float64).reshape(-1)
    if s.shape != (STATE_DIM,) or not np.all(np.isfinite(s)):
        raise FilterError(f'a track state must be {STATE_DIM} finite numbers, got {state!r}')
    return s


def _initial_cloud(state: np.ndarray, n: int, config: FilterConfig,
                   rng: np.random.Generator) -> np.ndarray:
    """(n, 6) particles around a state: Gaussian position and velocity spread."""
    cloud = np.repeat(state[None, :], n, axis=0)
    cloud[:, [X, Y]] += rng.normal(0.0, config.init_position_spread, size=(n, 2))
    cloud[:, [VX, VY]] += rng.normal(0.0, config.init_velocity_spread, size=(n, 2))
    return cloud


def _visible_rows(result: Any, count: int, names: list[str]) -> list[dict[str, float]]:
    """Per target k < ``count``, camera name -> expected visible fraction from the
    likelihood result's (K, C) ``visible_fraction`` (all empty when it has none or another
    shape)."""
    vf = getattr(result, 'visible_fraction', None)
    if vf is None:
        return [{} for _ in range(count)]
    vf = np.asarray(vf)
    if vf.ndim != 2 or vf.shape[1] != len(names):
        return [{} for _ in range(count)]
    rows = vf[:count].tolist()
    return [dict(zip(names, rows[k])) if k < len(rows) else {} for k in range(count)]


def exclusion_log_prior(joint: np.ndarray, radius: float, epsilon: float) -> np.ndarray:
    """Log of the joint spatial-exclusion prior of joint samples (000 Eq. 16).

    Args:
        joint: (N, K, 6) joint samples of K targets.
        radius: exclusion radius r, metres.
        epsilon: floor of the potential (as :func:`~mbtrack_ros.core.mrf.exclusion_potential`).

    Returns:
        (N,) ``sum_{h<k} log max(delta(|x^h - x^k| > r), epsilon)`` over the target pairs.
    """
    n, k_count = joint.shape[:2]
    out = np.zeros(n)
    r2 = radius ** 2
    log_eps = np.log(epsilon)
    for h in range(k_count):
        for k in range(h + 1, k_count):
            d2 = ((joint[:, h, X:Y + 1] - joint[:, k, X:Y + 1]) ** 2).sum(axis=1)
            out += np.where(d2 > r2, 0.0, log_eps)
    return out


class _MarginalParticleFilter:
    """Shared bookkeeping of filters that keep one particle set per target."""

    name = 'marginal'

    def __init__(self, config: FilterConfig | None = None, *,
                 floor: tuple[float, float, float, float] | None = None,
                 exits: tuple[tuple[float, float, float, float], ...] = (),
                 camera_names: list[str] | None = None) -> None:
        self.config = config or FilterConfig()
        self.floor = floor
        self.exits = tuple(exits)
        self.camera_names = list(camera_names or [])
        self.timings: dict[str, float] = {}
        self.stats: dict[str, float] = {}
        self._particles: dict[int, np.ndarray] = {}
        self._logw: dict[int, np.ndarray] = {}
        self._models: dict[int, Any] = {}
        self._streams: dict[int, np.random.Generator] = {}

    def add(self, track_id: int, model: PersonModel, state: np.ndarray,
            rng: np.random.Generator) -> None:
        """Start a track with N particles around ``state`` (6,).

        ``rng`` draws the initial cloud and stays the track's generator: :meth:`step` draws
        the track's resampling and motion noise from it (the generator given to ``step``
        is not used for tracks). Given the same generator as ``step`` the filter runs as
        with one shared stream; given a stream of its own per track (what
        :class:`~mbtrack_ros.core.tracker.Tracker` does), a track's draws do not depend on
        how many other tracks there are or what they drew."""
        if track_id in self._particles:
            raise FilterError(f'track {track_id} already exists')
        s = _check_state(state)
        n = int(self.config.particles)
        self._particles[track_id] = _initial_cloud(s, n, self.config, rng)
        self._logw[track_id] = np.full(n, -np.log(n))
        self._models[track_id] = model
        self._streams[track_id] = rng

    def remove(self, track_id: int) -> None:
        if track_id not in self._particles:
            raise FilterError(f'no track {track_id}')
        for store in (self._particles, self._logw, self._models, self._streams):
            del store[track_id]

    def track_ids(self) -> list[int]:
        return list(self._particles)

    def cloud(self, track_id: int) -> tuple[np.ndarray, np.ndarray, PersonModel]:
        """A track's particles (N, 6), normalised log-weights (N,) and appearance model as
        the next :meth:`step` starts from them (copies of the arrays; for diagnostics that
        score a track's surroundings with the filter's own clouds)."""
        if track_id not in self._particles:
            raise FilterError(f'no track {track_id}')
        return (self._particles[track_id].copy(), self._logw[track_id].copy(),
                self._models[track_id])

    def reset(self) -> None:
        self._particles.clear()
        self._logw.clear()
        self._models.clear()
        self._streams.clear()

    def _propagate(self, ids: list[int], dt: float) -> list[np.ndarray]:
        """Algorithm 1 predict, first loop: resample by weight, sample the 1-body dynamics.

        Per track, from the track's generator (see :meth:`add`), the draws of
        :func:`systematic_resample` then those of :func:`predict`; the particles of all
        tracks then move in one pass (the same numbers as one ``predict`` per track).
        Returns views of one (K N, 6) array."""
        n = int(self.config.particles)
        if not ids:
            return []
        logw = [self._logw[tid] for tid in ids]
        noise = []
        if len({lw.shape[0] for lw in logw}) == 1:
            # all tracks' weights at once (rows: the same numbers as one track at a time)
            w = np.exp(np.stack(logw))
            totals = w.sum(axis=1)
            if not (np.isfinite(totals).all() and (totals > 0).all()):
                raise ResamplingError('track weights must have a positive finite sum')
            offsets = np.empty(len(ids))
            for k, tid in enumerate(ids):     # systematic_resample's draw, then predict's
                stream = self._streams[tid]
                offsets[k] = stream.random()
                noise.append(draw_motion_noise(n, dt, self.config.motion, stream))
            idx = systematic_indices(w, totals, offsets, n)
            chosen = [self._particles[tid][idx[k]] for k, tid in enumerate(ids)]
        else:
            chosen = []
            for tid, lw in zip(ids, logw):
                stream = self._streams[tid]
                chosen.append(self._particles[tid][systematic_resample(np.exp(lw), n, stream)])
                noise.append(draw_motion_noise(n, dt, self.config.motion, stream))
        return self._move(chosen, noise, dt)

    def _move(self, chosen: list[np.ndarray], noise: list, dt: float) -> list[np.ndarray]:
        """The resampled particles ``chosen`` (K arrays (N_k, 6), left as they are) moved
        by the 1-body dynamics with their drawn ``noise`` in one pass (000 Eq. 15):
        views of one (sum N_k, 6) array."""
        moved = np.concatenate(chosen)
        move_particles(moved, dt, self.config.motion, concatenate_noise(noise),
                       floor=self.floor, exits=self.exits)
        ends = np.cumsum([c.shape[0] for c in chosen])
        return [moved[e - c.shape[0]:e] for c, e in zip(chosen, ends)]

    def _finish(self, ids: list[int], particles: list[np.ndarray],
                log_prior: list[np.ndarray], loglik: list[np.ndarray],
                result: Any) -> dict[int, TrackUpdate]:
        lls = []
        for k, tid in enumerate(ids):
            ll = np.asarray(loglik[k], dtype=np.float64)
            if ll.shape != (particles[k].shape[0],):
                raise FilterError(f'likelihood for track {tid} has shape {ll.shape}, '
                                  f'expected ({particles[k].shape[0]},)')
            lls.append(ll)
        # Algorithm 1 / 000 Eq. 41: posterior weight = prior weight x likelihood, normalised
        # for all tracks at once when they have as many particles (the usual case)
        if len({ll.shape[0] for ll in lls}) == 1:
            rows, flat = normalize_log_weight_rows(np.stack(log_prior) + np.stack(lls))
            posterior = list(zip(rows, flat.tolist(), np.exp(rows)))
        else:
            posterior = []
            for lp, ll in zip(log_prior, lls):
                lw, degenerate_k = normalize_log_weights(lp + ll)
                posterior.append((lw, degenerate_k, np.exp(lw)))
        updates = {}
        visible = _visible_rows(result, len(ids), self.camera_names)
        for k, tid in enumerate(ids):
            lw, _, w = posterior[k]
            self._particles[tid] = particles[k]
            self._logw[tid] = lw
            mean, cov = summarize_particles(particles[k], w)
            updates[tid] = TrackUpdate(mean=mean, covariance=cov, visible_fraction=visible[k],
                                       particles=particles[k], weights=w)
        degenerate = sum(int(p[1]) for p in posterior)
        self.stats['degenerate_tracks'] = float(degenerate)
        return updates


class HJSFilter(_MarginalParticleFilter):
    """Hybrid Joint-Separable particle filter (000 Algorithm 1).

    Predict: per target resample + 1-body dynamics (000 Eq. 15), then belief propagation of
    the spatial-exclusion MRF on the particle weights (000 Eq. 16-18, 43) unless
    ``config.use_mrf`` is False (the ablation of 000 §VI-C). Update: the HJS likelihood
    ``measurement.hjs`` (000 Eq. 26-40) with the independently propagated priors as the
    other targets' occluder weights (000 Eq. 34). The step's estimate (``TrackUpdate``)
    weighs the particles by BP belief x likelihood; the particles go on to the next step
    weighted by the likelihood alone, so that every estimate carries one copy of the
    exclusion and the particles none (see the comments in :meth:`step`;
    docs/hjs_fidelity.md). ``TrackUpdate.own`` is the estimate without the exclusion,
    the posterior the particles carry on.
    """

    name = 'hjs'

    def _exclusion_prior(self, ids: list[int], particles: list[np.ndarray],
                         prior: list[np.ndarray]) -> list[np.ndarray]:
        """BP beliefs (000 Eq. 16-18, 43) of the spatial-exclusion MRF on the propagated
        particles with prior weights ``prior`` (K arrays (N,), normalised)."""
        cfg = self.config
        if len(ids) < 2:
            return prior
        bp = belief_propagation(
            [p[:, X:Y + 1] for p in particles], prior, radius=cfg.mrf_radius,
            epsilon=cfg.mrf_epsilon, theta=cfg.theta_bp, max_iterations=cfg.max_bp_iterations)
        self.stats['bp_iterations'] = float(bp.iterations)
        self.stats['bp_kl'] = float(bp.kl)
        return bp.weights

    def _predict(self, ids: list[int], dt: float) -> list[np.ndarray]:
        """Resampled and moved particles of each target (000 Eq. 15); a hook for
        :class:`GroupedHJSFilter`."""
        return self._propagate(ids, dt)

    def _joint_weights(self, ids: list[int], particles: list[np.ndarray], models: list,
                       measurement: MeasurementModel, dt: float, loglik: list[np.ndarray],
                       log_prior: list[np.ndarray]) -> set[int]:
        """Replace, in place, the log-likelihood and log-prior of the targets weighed
        jointly; their positions in ``ids`` (none here: a hook for
        :class:`GroupedHJSFilter`)."""
        return set()

    def step(self, dt: float, measurement: MeasurementModel, images: dict[str, np.ndarray],
             rng: np.random.Generator) -> dict[int, TrackUpdate]:
        self.timings = {}
        self.stats = {}
        ids = self.track_ids()
        if not ids:
            return {}
        t0 = time.perf_counter()
        particles = self._predict(ids, dt)
        t1 = time.perf_counter()
        n = [p.shape[0] for p in particles]
        independent = [np.full(m, 1.0 / m) for m in n]
        prior = independent
        if self.config.use_mrf:
            prior = self._exclusion_prior(ids, particles, independent)
        t2 = time.perf_counter()
        models = [self._models[t] for t in ids]
        # 000 Eq. 34: the occlusion map of target h weighs the other targets' particles by
        # their prior. Their BP beliefs would carry the messages h sent them (000 Eq. 17:
        # target k's particles near h's cloud down-weighted), so h's own cloud would move
        # its occluders away from itself and the h-k exclusion would enter h's weights a
        # second time, through its likelihood, which the particles carry on to the next
        # frame. For two targets the prior of k without h's message is the independently
        # propagated one; the occluders are weighed by it, and the exclusion acts once, in
        # the estimate below.
        result = measurement.hjs(particles, independent, models)
        loglik = [np.asarray(ll, dtype=np.float64) for ll in result.loglik]
        log_prior = [np.log(p) for p in independent]
        joint = self._joint_weights(ids, particles, models, measurement, dt, loglik,
                                    log_prior)
        t3 = time.perf_counter()
        # the targets' own posteriors, prior x likelihood, which the particles carry on
        updates = self._finish(ids, particles, log_prior, loglik, result)
        if self.config.use_mrf and len(ids) > 1:
            # The exclusion is a constraint on the joint state at every time step (000
            # Eq. 13); a hard one is idempotent, delta^T = delta, so the exact joint filter
            # applies it once however many frames pass. The HJS belief is a product of
            # marginals: resampled by the beliefs above, the particles would carry this
            # frame's messages into the next frame, which multiplies in new ones on top,
            # m^T. Where the other target's position is uncertain (depth seen by one or
            # two cameras) its message is a smooth ramp, and the repeated ramps push the
            # tracks apart frame after frame. The particles are therefore carried on with
            # the weights of the independently propagated prior times the likelihood
            # (prior to BP: uniform), and every step's estimate carries one copy of the
            # exclusion, BP belief x likelihood, the exact marginal of 000 Eq. 16 for two
            # targets; the target's own posterior stays with it (TrackUpdate.own).
            # Targets weighed jointly carry the exclusion in their joint weights.
            for k, tid in enumerate(ids):
                if k in joint:
                    continue
                with np.errstate(divide='ignore'):
                    lw, _ = normalize_log_weights(np.log(prior[k]) + loglik[k])
                w = np.exp(lw)
                mean, cov = summarize_particles(particles[k], w)
                own = updates[tid]
                updates[tid] = TrackUpdate(mean=mean, covariance=cov,
                                           visible_fraction=own.visible_fraction,
                                           particles=particles[k], weights=w, own=own)
        self.timings = {'predict': t1 - t0, 'mrf': t2 - t1, 'update': t3 - t2,
                        'posterior': time.perf_counter() - t3}
        return updates


class GroupedHJSFilter(HJSFilter):
    """HJS with joint sampling of the targets the exclusion prior couples (000 §III, §II-A).

    Each step starts by finding the groups of targets whose particle clouds come within the
    exclusion radius r of each other (:func:`~mbtrack_ros.core.groups.interaction_groups`,
    at most :attr:`MAX_GROUP` targets): on them the product of marginals is not exact for
    000 Eq. 16. The targets of a group share their particle rows: row i of every member is
    one joint particle (N = G x the particles per target for a group of G, not N^G),
    resampled with one set of indices from one weight vector, each component moved by the
    1-body dynamics (000 Eq. 15). A group newly formed pairs rows drawn independently from
    the members' clouds in random order (a sample of the product of marginals); members
    that already shared rows keep them.

    A group is weighted by partitioned sampling (MacCormick & Blake 1999,
    :meth:`_partitioned`), so that the joint particles need not be as many as the product
    of the members' clouds: the first member's rows are weighted by its HJS likelihood
    with the targets outside the group as occluders (000 Eq. 22-40) and resampled, then
    the second member's components of the chosen rows are moved and weighted by its own
    HJS likelihood, the members' occlusion of each other in the depth-buffered joint
    likelihood of the joint filter (000 Eq. 19-21, 26; ``J(a, b) - J(a) - J(b)``, the
    targets outside the group at their predicted means) and the exclusion prior of 000
    Eq. 16 (:class:`JointFilter`). The joint particles go on to the next step with that
    weight: the exclusion is carried in them as in the joint filter, and a hidden pair
    keeps its order. All other targets are updated as by :class:`HJSFilter` (their
    occlusion maps, 000 Eq. 34, include the members' clouds); groups form and dissolve
    at every step, and members of a dissolved group go on with the marginals of their
    joint particles. Without ``config.use_mrf`` there is no coupling, no group, and the
    filter is :class:`HJSFilter` without the MRF.
    """

    name = 'hjs-groups'
    #: largest group: a group of G costs G HJS and G + 1 joint evaluations of its rows
    MAX_GROUP = 2

    def __init__(self, config: FilterConfig | None = None, **kwargs: Any) -> None:
        super().__init__(config, **kwargs)
        self._groups: list[tuple[int, ...]] = []
        self._step_groups: list[list[int]] = []     # this step's groups, positions in ids
        self._unmoved: dict[int, np.ndarray] = {}   # this step's resampled rows, unmoved

    def groups(self) -> list[tuple[int, ...]]:
        """The track ids of each group of the last step (members share particle rows)."""
        return list(self._groups)

    def remove(self, track_id: int) -> None:
        super().remove(track_id)
        kept = [tuple(t for t in g if t != track_id) for g in self._groups]
        self._groups = [g for g in kept if len(g) > 1]

    def reset(self) -> None:
        super().reset()
        self._groups = []
        self._unmoved = {}

    def _find_groups(self, ids: list[int]) -> list[list[int]]:
        """Positions in ``ids`` of the groups of this step, from the clouds it starts from."""
        cfg = self.config
        if not cfg.use_mrf or len(ids) < 2:
            return []
        return interaction_groups(
            [self._particles[t][:, X:Y + 1] for t in ids],
            [np.exp(self._logw[t]) for t in ids], cfg.mrf_radius, self.MAX_GROUP)

    def _propagate_groups(self, ids: list[int], groups: list[list[int]],
                          dt: float) -> list[np.ndarray]:
        """Resample (shared indices for rows shared before and after) and predict; keeps
        the resampled rows before the motion in ``_unmoved`` for :meth:`_partitioned`."""
        n = int(self.config.particles)
        new = {ids[k]: g for g, members in enumerate(groups) for k in members}
        rows = {ids[k]: n * len(members) for members in groups for k in members}
        old = {tid: g for g, members in enumerate(self._groups) for tid in members}
        indices: dict[tuple, np.ndarray] = {}
        chosen, noise = [], []
        for tid in ids:
            stream = self._streams[tid]
            m = rows.get(tid, n)
            unit = (('joint', old[tid], new[tid]) if tid in old and tid in new
                    else ('single', tid))
            if unit not in indices:
                indices[unit] = systematic_resample(np.exp(self._logw[tid]), m, stream)
                if tid in new:     # rows of a group in random order: pairs them at random
                    indices[unit] = indices[unit][stream.permutation(m)]
            chosen.append(self._particles[tid][indices[unit]])
            noise.append(draw_motion_noise(m, dt, self.config.motion, stream))
        self._unmoved = dict(zip(ids, chosen))
        return self._move(chosen, noise, dt)

    def _member_loglik(self, k: int, members: list[int], particles: list[np.ndarray],
                       models: list[Any], measurement: MeasurementModel) -> np.ndarray:
        """(N,) HJS log-likelihood (000 Eq. 22-40) of member k's rows with the targets
        outside its group as occluders."""
        keep = [j for j in range(len(particles)) if j == k or j not in members]
        result = measurement.hjs([particles[j] for j in keep],
                                 [np.full(particles[j].shape[0], 1.0) for j in keep],
                                 [models[j] for j in keep])
        return np.asarray(result.loglik[keep.index(k)], dtype=np.float64)

    def _partitioned(self, ids: list[int], members: list[int], particles: list[np.ndarray],
                     models: list[Any], measurement: MeasurementModel,
                     dt: float) -> np.ndarray:
        """Partitioned sampling of a group (MacCormick & Blake 1999, "A probabilistic
        exclusion principle for tracking multiple objects"): the first member's rows,
        moved, are weighted by its own likelihood and resampled (the rows stay joint); the
        next member's components of the chosen rows, resampled at the start of the step
        and not moved yet, are then moved by its dynamics and weighted by its likelihood;
        the last weight also carries the members' occlusion of each other in the joint
        likelihood and the exclusion prior. Replaces the members' rows in ``particles``
        (K arrays (N_k, 6)); returns the group's final (N,) log-weights."""
        first, rest = members[0], members[1:]
        m = particles[first].shape[0]
        stream = self._streams[ids[first]]
        ll = self._member_loglik(first, members, particles, models, measurement)
        for j, k in enumerate(rest):
            lw, _ = normalize_log_weights(ll)          # NaN and all -inf: flat
            idx = systematic_resample(np.exp(lw), m, stream)
            for done in members[:j + 1]:
                particles[done] = particles[done][idx]
            base = self._unmoved[ids[k]][idx].copy()
            own = self._streams[ids[k]]
            move_particles(base, dt, self.config.motion,
                           draw_motion_noise(m, dt, self.config.motion, own),
                           floor=self.floor, exits=self.exits)
            particles[k] = base
            ll = self._member_loglik(k, members, particles, models, measurement)
        total = ll + self._joint_terms(members, members, particles, models, measurement)
        for k in members:
            total -= self._joint_terms([k], members, particles, models, measurement)
        joint = np.stack([particles[k] for k in members], axis=1)
        return total + exclusion_log_prior(joint, self.config.mrf_radius,
                                           self.config.mrf_epsilon)

    def _joint_terms(self, members: list[int], group: list[int], particles: list[np.ndarray],
                     models: list[Any], measurement: MeasurementModel) -> np.ndarray:
        """(N,) depth-buffered joint log-likelihood (000 Eq. 19-21, 26) of the rows of
        ``members`` (some of ``group``) rendered with every target outside ``group`` at its
        predicted mean state."""
        joint = np.stack([particles[k] for k in members], axis=1)
        others = [k for k in range(len(particles)) if k not in group]
        full = joint
        if others:
            fixed = np.empty((len(others), STATE_DIM))
            for j, k in enumerate(others):
                m = particles[k].shape[0]
                # the mean's SIT is p(sitting): rasterised as sitting from 0.5 on
                fixed[j], _ = summarize_particles(particles[k], np.full(m, 1.0 / m))
            full = np.concatenate(
                [joint, np.broadcast_to(fixed, (joint.shape[0],) + fixed.shape)], axis=1)
        return np.asarray(measurement.joint(full, [models[k] for k in members + others]),
                          dtype=np.float64)

    def _predict(self, ids: list[int], dt: float) -> list[np.ndarray]:
        """This step's groups (:meth:`_find_groups`), then their shared-row resampling and
        the motion (:meth:`_propagate_groups`)."""
        self._step_groups = self._find_groups(ids)
        return self._propagate_groups(ids, self._step_groups, dt)

    def _joint_weights(self, ids: list[int], particles: list[np.ndarray], models: list,
                       measurement: MeasurementModel, dt: float, loglik: list[np.ndarray],
                       log_prior: list[np.ndarray]) -> set[int]:
        """Each group's members weighed by partitioned sampling (:meth:`_partitioned`):
        their joint log-weight as the log-likelihood, a flat log-prior."""
        grouped: set[int] = set()
        for members in self._step_groups:
            lw = self._partitioned(ids, members, particles, models, measurement, dt)
            for k in members:
                loglik[k], log_prior[k] = lw, np.zeros(particles[k].shape[0])
                grouped.add(k)
        self._groups = [tuple(ids[k] for k in members) for members in self._step_groups]
        self.stats['groups'] = float(len(self._step_groups))
        self.stats['grouped_tracks'] = float(len(grouped))
        return grouped


class SeparableFilter(_MarginalParticleFilter):
    """K independent particle filters (000 §II-A): same dynamics, blind likelihood, no MRF."""

    name = 'separable'

    def step(self, dt: float, measurement: MeasurementModel, images: dict[str, np.ndarray],
             rng: np.random.Generator) -> dict[int, TrackUpdate]:
        self.timings = {}
        self.stats = {}
        ids = self.track_ids()
        if not ids:
            return {}
        t0 = time.perf_counter()
        particles = self._propagate(ids, dt)
        t1 = time.perf_counter()
        models = [self._models[t] for t in ids]
        result = measurement.separable(particles, models)
        t2 = time.perf_counter()
        log_prior = [np.full(p.shape[0], -np.log(p.shape[0])) for p in particles]
        updates = self._finish(ids, particles, log_prior, result.loglik, result)
        self.timings = {'predict': t1 - t0, 'update': t2 - t1,
                        'posterior': time.perf_counter() - t2}
        return updates


class JointFilter:
    """One particle filter over the joint state of all K targets (000 §II-A).

    ``N = config.joint_particles`` joint particles ``(N, K, 6)``; joint resampling, 1-body
    dynamics per component, optional spatial-exclusion prior ``prod p(x^h, x^k)`` as a joint
    weight factor (000 Eq. 13, 16 without the BP approximation), ``measurement.joint``
    likelihood with a per-pixel depth buffer. Marginal means/covariances per target.
    """

    name = 'joint'

    def __init__(self, config: FilterConfig | None = None, *,
                 floor: tuple[float, float, float, float] | None = None,
                 exits: tuple[tuple[float, float, float, float], ...] = (),
                 camera_names: list[str] | None = None) -> None:
        self.config = config or FilterConfig()
        self.floor = floor
        self.exits = tuple(exits)
        self.camera_names = list(camera_names or [])
        self.timings: dict[str, float] = {}
        self.stats: dict[str, float] = {}
        self._ids: list[int] = []
        self._models: list[Any] = []
        n = int(self.config.joint_particles)
        self._joint = np.zeros((n, 0, STATE_DIM))
        self._logw = np.full(n, -np.log(n))

    def add(self, track_id: int, model: PersonModel, state: np.ndarray,
            rng: np.random.Generator) -> None:
        """Append a target: each joint particle gets its own sample around ``state``."""
        if track_id in self._ids:
            raise FilterError(f'track {track_id} already exists')
        s = _check_state(state)
        cloud = _initial_cloud(s, self._joint.shape[0], self.config, rng)
        self._joint = np.concatenate([self._joint, cloud[:, None, :]], axis=1)
        self._ids.append(track_id)
        self._models.append(model)

    def remove(self, track_id: int) -> None:
        if track_id not in self._ids:
            raise FilterError(f'no track {track_id}')
        k = self._ids.index(track_id)
        self._joint = np.delete(self._joint, k, axis=1)
        del self._ids[k]
        del self._models[k]
        if not self._ids:
            self.reset()

    def track_ids(self) -> list[int]:
        return list(self._ids)

    def reset(self) -> None:
        n = int(self.config.joint_particles)
        self._ids, self._models = [], []
        self._joint = np.zeros((n, 0, STATE_DIM))
        self._logw = np.full(n, -np.log(n))

    def step(self, dt: float, measurement: MeasurementModel, images: dict[str, np.ndarray],
             rng: np.random.Generator) -> dict[int, TrackUpdate]:
        self.timings = {}
        self.stats = {}
        if not self._ids:
            return {}
        t0 = time.perf_counter()
        n, k_count = self._joint.shape[:2]
        idx = systematic_resample(np.exp(self._logw), n, rng)
        flat = predict(self._joint[idx].reshape(n * k_count, STATE_DIM), dt,
                       self.config.motion, rng, floor=self.floor, exits=self.exits)
        joint = flat.reshape(n, k_count, STATE_DIM)
        log_prior = np.zeros(n)
        if self.config.use_mrf and k_count > 1:
            log_prior = exclusion_log_prior(joint, self.config.mrf_radius,
                                            self.config.mrf_epsilon)
        t1 = time.perf_counter()
        ll = np.asarray(measurement.joint(joint, list(self._models)), dtype=np.float64)
        if ll.shape != (n,):
            raise FilterError(f'joint likelihood has shape {ll.shape}, expected ({n},)')
        t2 = time.perf_counter()
        self._joint = joint
        self._logw, flat_w = normalize_log_weights(log_prior + ll)
        self.stats['degenerate_tracks'] = float(flat_w)
        w = np.exp(self._logw)
        updates = {}
        for k, tid in enumerate(self._ids):
            mean, cov = summarize_particles(joint[:, k, :], w)
            updates[tid] = TrackUpdate(mean=mean, covariance=cov, particles=joint[:, k, :],
                                       weights=w)
        self.timings = {'predict': t1 - t0, 'update': t2 - t1,
                        'posterior': time.perf_counter() - t2}
        return updates


# -- registry --------------------------------------------------------------------------------
FilterFactory = Callable[['RoomCalibration', 'TrackerConfig'], TrackingFilter]
_REGISTRY: dict[str, FilterFactory] = {}
#: modules imported to find algorithms that are not registered yet (they self-register)
PLUGIN_MODULES: tuple[str, ...] = ('mbtrack_ros.core.association',)


def register_filter(name: str, factory: FilterFactory) -> None:
    """Make ``factory(calibration, tracker_config)`` available as algorithm ``name``."""
    _REGISTRY[name] = factory


def available_filters() -> list[str]:
    """Names of the registered algorithms (after importing the plug-in modules)."""
    _load_plugins()
    return sorted(_REGISTRY)


def _load_plugins() -> None:
    for module in PLUGIN_MODULES:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as err:
            if err.name is None or not module.startswith(err.name):
                raise


def make_filter(name: str, calibration: RoomCalibration,
                config: TrackerConfig) -> TrackingFilter:
    """Build the algorithm ``name`` for a room; raises :class:`FilterError` if unknown."""
    if name not in _REGISTRY:
        _load_plugins()
    if name not in _REGISTRY:
        raise FilterError(f'unknown algorithm {name!r}; available: '
                          f'{", ".join(sorted(_REGISTRY))}')
    return _REGISTRY[name](calibration, config)


def _particle_factory(cls: type) -> FilterFactory:
    def factory(calibration: RoomCalibration, config: TrackerConfig) -> TrackingFilter:
        return cls(config.filter_config(), floor=calibration.floor, exits=calibration.exits,
                   camera_names=list(calibration.names))
    return factory


register_filter('hjs', _particle_factory(HJSFilter))
register_filter('separable', _particle_factory(SeparableFilter))
register_filter('joint', _particle_factory(JointFilter))
register_filter('hjs-groups', _particle_factory(GroupedHJSFilter))
