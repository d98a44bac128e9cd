"""Joint Probabilistic Data Association (004 §5.1; Bar-Shalom & Fortmann [3]).

K targets share one pool of M floor-position measurements produced jointly (004 §5.1.1:
per-target sampling, hill-climbing, minimum separation Delta over the pooled samples, so
each likelihood peak gives one measurement). A joint association event assigns each target
one gated measurement or none, no measurement to two targets (004 §5.1). Its weight is

    P(Theta) ∝ prod_{t detected} P_D N(nu_{t a_t}; 0, S_t)
               * prod_{t missed} lambda (1 - P_D P_G)

(the parametric JPDAF with gating; for K = 1 it reduces to the PDAF of :mod:`.pdaf`).

Cost: the events are enumerated target by target, each extended only by its gated,
still unused measurements, so their number is at most prod_t (1 + m_t) <= (M + 1)^K with
m_t the gated measurements of target t (e.g. K = 4, M = 8: at most 6561, in practice far
fewer because of the gates); time and memory are O(E K) for E events. ``max_events`` bounds
it and raises :class:`AssociationError` beyond.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from mbtrack_ros.core.association.kalman import (
    AssociationError, _check_state, gate_threshold, innovation, innovation_covariance,
    mahalanobis2)
from mbtrack_ros.core.association.pdaf import (
    _check_probabilities, combine_update, log_gaussian, miss_log_weight)
from mbtrack_ros.core.association.sampling import (
    Measurements, ScoreFn, measurement_sampling, suppress)

__all__ = ['JPDAResult', 'enumerate_events', 'event_log_weights', 'joint_measurements',
           'jpdaf_probabilities', 'jpdaf_update', 'marginal_associations']

MISSED = -1
"""Event entry of a target that is associated with no measurement."""


@dataclass(frozen=True)
class JPDAResult:
    """Joint association of K targets with M measurements.

    Attributes:
        events: (E, K) int, measurement index per target or -1 (missed).
        probabilities: (E,) normalised event probabilities.
        beta: (K, M) marginal association probabilities.
        beta0: (K,) probability that target t has no measurement.
        gated: (K, M) bool validation matrix.
        means: (K, 4) updated states (None if only probabilities were computed).
        covs: (K, 4, 4) updated covariances (or None).
    """

    events: np.ndarray
    probabilities: np.ndarray
    beta: np.ndarray
    beta0: np.ndarray
    gated: np.ndarray
    means: np.ndarray | None = None
    covs: np.ndarray | None = None


def enumerate_events(gated: np.ndarray, *, max_events: int = 200_000) -> np.ndarray:
    """All feasible joint association events for a (K, M) validation matrix (004 §5.1).

    Each target gets one of its gated measurements or -1; no measurement is used twice.
    Built target by target from the gated candidates only (the depth-first pruning written
    as array operations over the partial events).

    Returns:
        (E, K) int events; the all-missed event is row 0.
    """
    gated = np.asarray(gated, dtype=bool)
    if gated.ndim != 2:
        raise AssociationError(f'validation matrix must be (K, M), got {gated.shape}')
    n_targets, n_meas = gated.shape
    events = np.full((1, 0), MISSED, dtype=np.intp)
    used = np.zeros((1, n_meas), dtype=bool)
    for t in range(n_targets):
        parts_e = [np.hstack([events, np.full((events.shape[0], 1), MISSED, np.intp)])]
        parts_u = [used]
        for j in np.flatnonzero(gated[t]):
            free = ~used[:, j]  # 004 §5.1: no measurement for two targets
            if not free.any():
                continue
            ext = np.hstack([events[free], np.full((int(free.sum()), 1), j, np.intp)])
            u = used[free].copy()
            u[:, j] = True
            parts_e.append(ext)
            parts_u.append(u)
        events = np.vstack(parts_e)
        used = np.vstack(parts_u)
        if events.shape[0] > max_events:
            raise AssociationError(
                f'{events.shape[0]} joint events exceed max_events={max_events} '
                f'({n_targets} targets, {n_meas} measurements); tighten the gate')
    return events


def event_log_weights(events: np.ndarray, log_assoc: np.ndarray,
                      log_miss: np.ndarray) -> np.ndarray:
    """Unnormalised log weights of joint events.

    Args:
        events: (E, K) from :func:`enumerate_events`.
        log_assoc: (K, M) log(P_D N(nu_tj; 0, S_t)) (-inf where not gated).
        log_miss: (K,) log(lambda (1 - P_D P_G)) per target.
    Returns:
        (E,) log weights (NaN -> -inf).
    """
    events = np.asarray(events)
    n_targets = events.shape[1]
    padded = np.hstack([np.asarray(log_assoc, dtype=np.float64),
                        np.asarray(log_miss, dtype=np.float64)[:, None]])  # column M = miss
    cols = np.where(events == MISSED, padded.shape[1] - 1, events)
    logw = padded[np.arange(n_targets)[None, :], cols].sum(axis=1)
    return np.where(np.isnan(logw), -np.inf, logw)


def marginal_associations(events: np.ndarray, probabilities: np.ndarray,
                          n_meas: int) -> tuple[np.ndarray, np.ndarray]:
    """Marginals beta_tj = sum of P(Theta) over events with a_t = j, and beta_t0.

    Returns:
        (beta (K, M), beta0 (K,)).
    """
    events = np.asarray(events)
    n_targets = events.shape[1]
    beta = np.zeros((n_targets, n_meas + 1))
    cols = np.where(events == MISSED, n_meas, events)
    for t in range(n_targets):
        beta[t] = np.bincount(cols[:, t], weights=probabilities, minlength=n_meas + 1)
    return beta[:, :n_meas], beta[:, n_meas]


def jpdaf_probabilities(nu: np.ndarray, S: np.ndarray, *, p_detect: float, p_gate: float,
                        clutter_density: float, max_events: int = 200_000) -> JPDAResult:
    """Joint event and marginal association probabilities (004 §5.1).

    Args:
        nu: (K, M, 2) innovations of every measurement for every target, metres.
        S: (K, 2, 2) innovation covariances.
    """
    _check_probabilities(p_detect, p_gate, clutter_density)
    nu = np.asarray(nu, dtype=np.float64)
    S = np.asarray(S, dtype=np.float64)
    if nu.ndim != 3 or nu.shape[2] != 2 or S.shape != (nu.shape[0], 2, 2):
        raise AssociationError(f'need nu (K, M, 2) and S (K, 2, 2), got {nu.shape}, {S.shape}')
    n_targets, n_meas = nu.shape[:2]
    gated = mahalanobis2(nu, S) <= gate_threshold(p_gate, 2)
    log_assoc = np.where(gated, np.log(p_detect) + log_gaussian(nu, S), -np.inf)
    log_miss = np.full(n_targets, miss_log_weight(
        p_detect=p_detect, p_gate=p_gate, clutter_density=clutter_density))
    events = enumerate_events(gated, max_events=max_events)
    logw = event_log_weights(events, log_assoc, log_miss)  # 004 §5.1: P(Theta)
    if not np.any(np.isfinite(logw)):
        # lambda = 0 and no event explains every target: in the limit lambda -> 0 only the
        # events with the most detections keep weight (each miss costs a factor lambda).
        detected = (events != MISSED).sum(axis=1)
        logw = np.where(detected == detected.max(),
                        event_log_weights(events, log_assoc, np.zeros(n_targets)), -np.inf)
    probs = np.exp(logw - logsumexp(logw))
    beta, beta0 = marginal_associations(events, probs, n_meas)
    return JPDAResult(events, probs, beta, beta0, gated)


def jpdaf_update(means: np.ndarray, covs: np.ndarray, measurements: np.ndarray,
                 R: np.ndarray, *, p_detect: float, p_gate: float, clutter_density: float,
                 max_events: int = 200_000) -> JPDAResult:
    """JPDAF update of K predicted Kalman states with a shared pool of measurements.

    Args:
        means: (K, 4) predicted states.
        covs: (K, 4, 4) predicted covariances.
        measurements: (M, 2) floor positions, metres (M may be 0).
        R: (2, 2) measurement covariance, m^2.
    Returns:
        :class:`JPDAResult` with ``means`` / ``covs`` set; each target is updated
        PDAF-style with its marginal betas (004 §5.1).
    """
    means, covs = _check_state(means, covs)
    if means.ndim != 2:
        raise AssociationError(f'means must be (K, 4), got {means.shape}')
    z = np.asarray(measurements, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] != 2 or not np.all(np.isfinite(z)):
        raise AssociationError(f'measurements must be finite (M, 2), got {z.shape}')
    S = innovation_covariance(covs, R)
    nu = innovation(means, np.broadcast_to(z, (means.shape[0],) + z.shape))
    result = jpdaf_probabilities(nu, S, p_detect=p_detect, p_gate=p_gate,
                                 clutter_density=clutter_density, max_events=max_events)
    new_means = np.empty_like(means)
    new_covs = np.empty_like(covs)
    for t in range(means.shape[0]):
        new_means[t], new_covs[t], _ = combine_update(
            means[t], covs[t], nu[t], result.beta[t], float(result.beta0[t]), R)
    return JPDAResult(result.events, result.probabilities, result.beta, result.beta0,
                      result.gated, new_means, new_covs)


def joint_measurements(means: np.ndarray, covs: np.ndarray, scores: list[ScoreFn],
                       rng: np.random.Generator, *, n_samples: int = 50, n_keep: int = 10,
                       radius: float = 0.05, separation: float = 0.3, refine: bool = True,
                       refine_evals: int = 40, scale: float = 1.0, min_std: float = 0.05,
                       min_speed: float = 0.2, sit_explore: float = 0.0) -> Measurements:
    """Joint measurement generation for K targets (004 §5.1.1, Fig. 16 'JPDAF' column).

    Each target samples ``n_samples`` states around its prediction, keeps its ``n_keep``
    best (after a small ``radius`` suppression), hill-climbs them with its own likelihood;
    the pooled samples are then thinned jointly with the minimum separation Delta =
    ``separation`` metres, best first, so each peak of p(I|X) yields one measurement.
    Scores of different targets' models are compared directly in the pooled thinning
    (the JPDAF assumes one likelihood shared by all targets, 004 §5.2).

    Args:
        means: (K, 6) predicted states; covs: (K, 4, 4).
        scores: K log-likelihood callables, one per target.
    Returns:
        :class:`Measurements` of the pool, best first; ``posture_loglik`` is (K, 2), each
        target's best standing / sitting score.
    """
    means = np.asarray(means, dtype=np.float64)
    if len(scores) != means.shape[0]:
        raise AssociationError(f'{len(scores)} score functions for {means.shape[0]} targets')
    pooled = [measurement_sampling(means[t], covs[t], scores[t], rng, n_samples=n_samples,
                                   n_keep=n_keep, radius=radius, refine=refine,
                                   refine_evals=refine_evals, scale=scale, min_std=min_std,
                                   min_speed=min_speed, sit_explore=sit_explore)
              for t in range(means.shape[0])]
    states = np.vstack([m.states for m in pooled]) if pooled else np.zeros((0, 6))
    loglik = np.concatenate([m.loglik for m in pooled]) if pooled else np.zeros(0)
    keep = suppress(states[:, :2], loglik, radius=separation)  # 004 §5.1.1: minimum separation
    posture = np.array([m.posture_loglik for m in pooled]).reshape(-1, 2)
    return Measurements(states[keep], loglik[keep], posture)
