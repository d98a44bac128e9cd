"""Measurement sampling (004 §4.1) and minimum-separation thinning (004 §5.1.1).

Candidate floor positions of one person are drawn around the Kalman prediction, scored with
the appearance likelihood the particle filters use (a callable ``score(states (N, 6)) ->
(N,)`` log-likelihood; in the product ``MeasurementModel.separable`` for one target over all
cameras), the best kept after non-maximum suppression, and optionally hill-climbed on the
2D position with Powell's method (004 §4.1, §5.1.1).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from mbtrack_ros.core.association.kalman import AssociationError
from mbtrack_ros.core.state import SIT, STATE_DIM, THETA, VX, VY, X, Y

__all__ = ['Measurements', 'ScoreFn', 'clean_loglik', 'measurement_sampling', 'posture_loglik',
           'posture_update', 'refine_state', 'sample_states', 'suppress']

ScoreFn = Callable[[np.ndarray], np.ndarray]
"""``score(states (N, 6)) -> (N,)`` log-likelihood of single-person states."""


@dataclass(frozen=True)
class Measurements:
    """Measurements of one target, best first.

    Attributes:
        states: (n, 6) full states of the kept samples (positions are the measurements).
        loglik: (n,) their log-likelihoods.
        posture_loglik: (2,) best log-likelihood of any standing / sitting sample (-inf if
            none was drawn); (K, 2), one row per target, for a joint pool.
    """

    states: np.ndarray
    loglik: np.ndarray
    posture_loglik: np.ndarray = field(default_factory=lambda: np.full(2, -np.inf))

    @property
    def positions(self) -> np.ndarray:
        """(n, 2) floor positions, metres."""
        return self.states[:, :2]


def clean_loglik(values: np.ndarray, n: int) -> np.ndarray:
    """Check a score callable's output is (n,) and map NaN to -inf."""
    values = np.asarray(values, dtype=np.float64)
    if values.shape != (n,):
        raise AssociationError(f'score returned shape {values.shape}, expected ({n},)')
    return np.where(np.isnan(values), -np.inf, values)


def sample_states(mean: np.ndarray, cov: np.ndarray, n: int, rng: np.random.Generator, *,
                  scale: float = 1.0, min_std: float = 0.05, min_speed: float = 0.2,
                  sit_explore: float = 0.0) -> np.ndarray:
    """N states around a prediction (004 §4.1: samples from N(X^, Sigma_X)).

    Positions are drawn from ``scale^2 * cov[:2, :2] + min_std^2 I`` around ``mean[:2]``;
    velocity is copied from ``mean``; the orientation is the heading of the predicted
    velocity when its speed is at least ``min_speed`` (m/s), else ``mean[THETA]``. With
    ``sit_explore`` = 0 the sitting column is copied; with ``sit_explore`` in (0, 0.5] each
    sample sits with probability ``clip(mean[SIT], sit_explore, 1 - sit_explore)`` (0 or 1),
    so both postures are always tried.

    Args:
        mean: (6,) predicted state.
        cov: (4, 4) predicted covariance of (x, y, vx, vy).
        n: number of samples.
    Returns:
        (n, 6) float64 states.
    """
    mean = np.asarray(mean, dtype=np.float64)
    cov = np.asarray(cov, dtype=np.float64)
    if mean.shape != (STATE_DIM,) or cov.shape != (4, 4):
        raise AssociationError(f'need mean (6,) and cov (4, 4), got {mean.shape}, {cov.shape}')
    if n < 1:
        raise AssociationError(f'number of samples must be >= 1, got {n}')
    if not 0.0 <= sit_explore <= 0.5:
        raise AssociationError(f'sit_explore must be in [0, 0.5], got {sit_explore}')
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
        raise AssociationError('prediction is not finite')
    sigma = scale ** 2 * cov[:2, :2] + min_std ** 2 * np.eye(2)
    sigma = 0.5 * (sigma + sigma.T)
    states = np.repeat(mean[None], n, axis=0)
    try:
        states[:, [X, Y]] = rng.multivariate_normal(mean[:2], sigma, size=n, method='cholesky')
    except np.linalg.LinAlgError as err:
        raise AssociationError(f'sampling covariance is not positive definite: {sigma.tolist()}'
                               ) from err
    speed = np.hypot(mean[VX], mean[VY])
    states[:, THETA] = np.arctan2(mean[VY], mean[VX]) if speed >= min_speed else mean[THETA]
    if sit_explore > 0.0:
        p_sit = float(np.clip(mean[SIT], sit_explore, 1.0 - sit_explore))
        states[:, SIT] = (rng.random(n) < p_sit).astype(np.float64)
    return states


def posture_loglik(sitting: np.ndarray, loglik: np.ndarray) -> np.ndarray:
    """(2,) best log-likelihood among standing (sitting < 0.5) and sitting samples."""
    sit = np.asarray(sitting) >= 0.5
    ll = np.asarray(loglik, dtype=np.float64)
    ll = np.where(np.isnan(ll), -np.inf, ll)
    return np.array([ll[~sit].max(initial=-np.inf), ll[sit].max(initial=-np.inf)])


def posture_update(p_sit: np.ndarray, posture_ll: np.ndarray, *,
                   floor: float = 1e-4) -> np.ndarray:
    """Posterior sitting probability of a two-state filter (an extension of 004).

    logit p' = logit p + (L_sit - L_stand), the likelihood of each posture approximated by
    its best sample (``posture_ll`` (..., 2) from :func:`posture_loglik`); if a posture was
    not sampled, or neither has finite evidence, the prior is kept. Result clipped to
    [floor, 1 - floor].
    """
    p = np.clip(np.asarray(p_sit, dtype=np.float64), floor, 1.0 - floor)
    ll = np.asarray(posture_ll, dtype=np.float64)
    delta = ll[..., 1] - ll[..., 0]
    delta = np.where(np.isfinite(delta), delta, 0.0)
    logit = np.log(p) - np.log1p(-p) + delta
    return np.clip(1.0 / (1.0 + np.exp(-logit)), floor, 1.0 - floor)


def suppress(positions: np.ndarray, loglik: np.ndarray, *, radius: float,
             max_keep: int | None = None) -> np.ndarray:
    """Greedy non-maximum suppression / minimum separation (004 §5.1.1).

    Starting from the best sample, every less fit sample within ``radius`` metres is
    dropped; repeated on the next survivor. Samples with loglik -inf are never kept.

    Args:
        positions: (N, 2) floor positions.
        loglik: (N,) scores.
    Returns:
        (n,) int indices of the kept samples, best first.
    """
    positions = np.asarray(positions, dtype=np.float64)
    loglik = clean_loglik(loglik, positions.shape[0])
    if radius < 0:
        raise AssociationError(f'suppression radius must be >= 0, got {radius}')
    order = np.argsort(-loglik, kind='stable')
    order = order[np.isfinite(loglik[order])]
    alive = np.ones(positions.shape[0], dtype=bool)
    kept: list[int] = []
    limit = positions.shape[0] if max_keep is None else int(max_keep)
    while len(kept) < limit:
        candidates = order[alive[order]]
        if candidates.size == 0:
            break
        best = int(candidates[0])
        kept.append(best)
        alive &= np.hypot(*(positions - positions[best]).T) > radius
        alive[best] = False
    return np.asarray(kept, dtype=np.intp)


def refine_state(state: np.ndarray, score: ScoreFn, *, max_evals: int = 40,
                 xtol: float = 0.01) -> tuple[np.ndarray, float]:
    """Hill-climb the floor position of one state with Powell's method (004 §4.1, §5.1.1).

    Args:
        state: (6,) start state; only x, y change.
        score: log-likelihood callable.
        max_evals: maximum number of likelihood evaluations.
        xtol: position tolerance, metres.
    Returns:
        ((6,) refined state, its log-likelihood); the start state if nothing better is found.
    """
    state = np.asarray(state, dtype=np.float64)

    def cost(xy: np.ndarray) -> float:
        trial = state.copy()
        trial[[X, Y]] = xy
        value = clean_loglik(score(trial[None]), 1)[0]
        return 1e300 if not np.isfinite(value) else -float(value)

    start_cost = cost(state[[X, Y]])
    result = minimize(cost, state[[X, Y]], method='Powell',
                      options={'maxfev': int(max_evals), 'xtol': xtol, 'ftol': 1e-6})
    if not np.isfinite(result.fun) or result.fun >= start_cost:
        return state.copy(), -start_cost if start_cost < 1e300 else -np.inf
    refined = state.copy()
    refined[[X, Y]] = result.x
    return refined, -float(result.fun)


def measurement_sampling(mean: np.ndarray, cov: np.ndarray, score: ScoreFn,
                         rng: np.random.Generator, *, n_samples: int = 100,
                         n_keep: int = 5, radius: float = 0.1, refine: bool = False,
                         refine_evals: int = 40, scale: float = 1.0, min_std: float = 0.05,
                         min_speed: float = 0.2, sit_explore: float = 0.0) -> Measurements:
    """Measurement sampling for one target (004 §4.1, Fig. 16 'PDAF' column).

    ``n_samples`` states from :func:`sample_states` are scored, thinned with
    :func:`suppress` (``radius`` metres) to the ``n_keep`` best, optionally refined with
    :func:`refine_state` and thinned again (refined samples of one peak converge).

    Returns:
        :class:`Measurements` with at most ``n_keep`` rows, best first.
    """
    if n_keep < 1:
        raise AssociationError(f'n_keep must be >= 1, got {n_keep}')
    states = sample_states(mean, cov, n_samples, rng, scale=scale, min_std=min_std,
                           min_speed=min_speed, sit_explore=sit_explore)
    loglik = clean_loglik(score(states), n_samples)  # 004 §4.1: p(I|X) of every sample
    posture = posture_loglik(states[:, SIT], loglik)
    keep = suppress(states[:, :2], loglik, radius=radius, max_keep=n_keep)  # 004 §4.1: n best
    states, loglik = states[keep], loglik[keep]
    if refine and keep.size:
        for i in range(states.shape[0]):
            states[i], loglik[i] = refine_state(states[i], score, max_evals=refine_evals)
        posture = np.maximum(posture, posture_loglik(states[:, SIT], loglik))
        keep = suppress(states[:, :2], loglik, radius=radius, max_keep=n_keep)
        states, loglik = states[keep], loglik[keep]
    return Measurements(states, loglik, posture)
