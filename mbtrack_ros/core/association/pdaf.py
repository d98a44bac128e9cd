"""Probabilistic Data Association Filter update (004 §4.2; Bar-Shalom & Fortmann [3]).

One target, M candidate floor-position measurements (from measurement sampling, 004 §4.1).
Association probabilities are computed in log space: for a gated measurement i

    log b_i = log P_D + log N(nu_i; 0, S)            (measurement i is the target's)
    log b_0 = log lambda + log(1 - P_D P_G)          (no measurement is the target's)

normalised with logsumexp (the parametric PDAF with clutter density ``lambda``, per m^2).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from mbtrack_ros.core.association.kalman import (
    AssociationError, _check_state, gain, gate_threshold, innovation, innovation_covariance,
    mahalanobis2)

__all__ = ['PDAResult', 'association_probabilities', 'combine_update', 'log_gaussian',
           'miss_log_weight', 'pdaf_update']


@dataclass(frozen=True)
class PDAResult:
    """Result of one PDAF update.

    Attributes:
        mean: (4,) updated state.
        cov: (4, 4) updated covariance.
        beta: (M,) association probability of each measurement (0 outside the gate).
        beta0: probability that no measurement is target-originated.
        gated: (M,) bool, measurement inside the validation gate.
        innovation: (2,) combined innovation sum_i beta_i nu_i, metres.
    """

    mean: np.ndarray
    cov: np.ndarray
    beta: np.ndarray
    beta0: float
    gated: np.ndarray
    innovation: np.ndarray


def _check_probabilities(p_detect: float, p_gate: float, clutter_density: float) -> None:
    if not 0.0 < p_detect <= 1.0:
        raise AssociationError(f'detection probability must be in (0, 1], got {p_detect}')
    if not 0.0 < p_gate < 1.0:
        raise AssociationError(f'gate probability must be in (0, 1), got {p_gate}')
    if not (np.isfinite(clutter_density) and clutter_density >= 0.0):
        raise AssociationError(f'clutter density must be finite and >= 0, got {clutter_density}')


def log_gaussian(nu: np.ndarray, S: np.ndarray) -> np.ndarray:
    """log N(nu; 0, S) of innovations (..., M, d) with covariance (..., d, d) -> (..., M)."""
    nu = np.asarray(nu, dtype=np.float64)
    S = np.asarray(S, dtype=np.float64)
    d = nu.shape[-1]
    _, logdet = np.linalg.slogdet(S)
    return -0.5 * (mahalanobis2(nu, S) + d * np.log(2.0 * np.pi) + logdet[..., None])


def miss_log_weight(*, p_detect: float, p_gate: float, clutter_density: float) -> float:
    """log(lambda (1 - P_D P_G)): weight of 'target not detected' relative to log b_i."""
    with np.errstate(divide='ignore'):
        return float(np.log(clutter_density) + np.log1p(-p_detect * p_gate))


def association_probabilities(nu: np.ndarray, S: np.ndarray, *, p_detect: float,
                              p_gate: float, clutter_density: float
                              ) -> tuple[np.ndarray, float, np.ndarray]:
    """PDAF association probabilities beta_i, beta_0 (004 §4.2).

    Args:
        nu: (M, 2) innovations, metres.
        S: (2, 2) innovation covariance.
        p_detect: P_D, probability that the target yields a measurement.
        p_gate: P_G, probability that the target's measurement falls in the gate.
        clutter_density: lambda, false measurements per m^2 (0 = no clutter).
    Returns:
        (beta (M,), beta0, gated (M,) bool); beta0 + beta.sum() == 1.
    """
    _check_probabilities(p_detect, p_gate, clutter_density)
    nu = np.asarray(nu, dtype=np.float64).reshape(-1, 2)
    gated = mahalanobis2(nu, S) <= gate_threshold(p_gate, 2)  # 004 §4.2 validation gate
    logw = np.full(nu.shape[0] + 1, -np.inf)
    # 004 §4.2: beta_0, no measurement is the target's
    logw[0] = miss_log_weight(p_detect=p_detect, p_gate=p_gate,
                              clutter_density=clutter_density)
    if nu.shape[0]:
        # 004 §4.2: beta_i, measurement i is the target's
        logw[1:] = np.where(gated, np.log(p_detect) + log_gaussian(nu, S), -np.inf)
    logw = np.where(np.isnan(logw), -np.inf, logw)
    if not np.any(np.isfinite(logw)):  # no clutter and nothing gated: the target is missed
        logw[0] = 0.0
    p = np.exp(logw - logsumexp(logw))
    return p[1:], float(p[0]), gated


def combine_update(mean: np.ndarray, cov: np.ndarray, nu: np.ndarray, beta: np.ndarray,
                   beta0: float, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PDAF state and covariance update from weighted innovations (004 §4.2, [3]).

    x = x^ + W nu_c with nu_c = sum_i beta_i nu_i;
    P = beta_0 P^ + (1 - beta_0) (P^ - W S W') + W (sum_i beta_i nu_i nu_i' - nu_c nu_c') W'.
    Shared by the PDAF and the JPDAF (which passes its marginal betas).

    Returns:
        (mean (4,), cov (4, 4), combined innovation (2,)).
    """
    S = innovation_covariance(cov, R)
    W = gain(cov, S)
    nu = np.asarray(nu, dtype=np.float64).reshape(-1, 2)
    beta = np.asarray(beta, dtype=np.float64)
    nu_c = beta @ nu  # 004 §4.2: combined innovation sum_i beta_i nu_i
    new_mean = mean + W @ nu_c
    P_c = cov - W @ S @ W.T  # covariance of the Kalman update with the right measurement
    spread = (nu * beta[:, None]).T @ nu - np.outer(nu_c, nu_c)  # spread of innovations
    new_cov = beta0 * cov + (1.0 - beta0) * P_c + W @ spread @ W.T
    return new_mean, 0.5 * (new_cov + new_cov.T), nu_c


def pdaf_update(mean: np.ndarray, cov: np.ndarray, measurements: np.ndarray, R: np.ndarray,
                *, p_detect: float, p_gate: float, clutter_density: float) -> PDAResult:
    """One PDAF update of a predicted Kalman state with M candidate measurements.

    Args:
        mean: (4,) predicted state (x, y, vx, vy).
        cov: (4, 4) predicted covariance.
        measurements: (M, 2) candidate floor positions, metres (M may be 0).
        R: (2, 2) measurement covariance, m^2.
    With one measurement, P_D = 1 and lambda -> 0 this is the Kalman update.
    """
    mean, cov = _check_state(mean, cov)
    if mean.shape != (4,):
        raise AssociationError(f'pdaf_update takes one target (4,), got {mean.shape}')
    z = np.asarray(measurements, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] != 2:
        raise AssociationError(f'measurements must be (M, 2), got {z.shape}')
    if not np.all(np.isfinite(z)):
        raise AssociationError('measurements contain NaN or inf')
    S = innovation_covariance(cov, R)
    nu = innovation(mean, z)
    beta, beta0, gated = association_probabilities(
        nu, S, p_detect=p_detect, p_gate=p_gate, clutter_density=clutter_density)
    new_mean, new_cov, nu_c = combine_update(mean, cov, nu, beta, beta0, R)
    return PDAResult(new_mean, new_cov, beta, beta0, gated, nu_c)
