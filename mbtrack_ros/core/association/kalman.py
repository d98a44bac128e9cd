"""Constant-velocity Kalman filter on the floor plane (004 Appendix).

State ``(x, y, vx, vy)`` in metres and m/s (the first four columns of the particle layout
of :mod:`mbtrack_ros.core.state`); measurements are floor positions ``(x, y)`` in metres.
All functions broadcast over leading axes, so ``(4,)`` / ``(4, 4)`` for one target and
``(K, 4)`` / ``(K, 4, 4)`` for K targets both work.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import chi2

__all__ = [
    'AssociationError', 'H', 'gain', 'gate_threshold', 'in_gate', 'innovation',
    'innovation_covariance', 'mahalanobis2', 'nees', 'predict', 'process_noise',
    'transition_matrix', 'update',
]


class AssociationError(ValueError):
    """Bad input to the data-association baselines (shapes, probabilities, densities)."""


# 004 Appendix: measurement matrix H, the measurement is the floor position.
H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])


def _check_state(mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean = np.asarray(mean, dtype=np.float64)
    cov = np.asarray(cov, dtype=np.float64)
    if mean.shape[-1:] != (4,) or cov.shape[-2:] != (4, 4) or cov.shape[:-2] != mean.shape[:-1]:
        raise AssociationError(
            f'Kalman state must be (..., 4) with covariance (..., 4, 4), got {mean.shape} '
            f'and {cov.shape}')
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
        raise AssociationError('Kalman state or covariance is not finite')
    return mean, cov


def transition_matrix(dt: float) -> np.ndarray:
    """(4, 4) constant-velocity transition F over ``dt`` seconds (004 Appendix: X = F X)."""
    dt = float(dt)
    if not np.isfinite(dt) or dt < 0.0:
        raise AssociationError(f'time step must be finite and >= 0, got {dt}')
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    return F


def process_noise(dt: float, *, accel_std: float, position_std: float = 0.0) -> np.ndarray:
    """(4, 4) process covariance Q of continuous white acceleration over ``dt`` seconds.

    ``accel_std`` is the square root of the acceleration power spectral density,
    m/s per sqrt(s) (Bar-Shalom & Fortmann's continuous white-noise acceleration model,
    the standard companion of the constant-velocity F of the 004 Appendix); it equals the
    velocity diffusion ``MotionConfig.velocity_noise`` of the particle filters' dynamics.
    ``position_std`` (m per sqrt(s)) adds independent position diffusion
    (``MotionConfig.position_noise``).
    """
    dt = float(dt)
    if not np.isfinite(dt) or dt < 0.0:
        raise AssociationError(f'time step must be finite and >= 0, got {dt}')
    if not np.isfinite(accel_std) or accel_std < 0.0:
        raise AssociationError(f'accel_std must be finite and >= 0, got {accel_std}')
    if not np.isfinite(position_std) or position_std < 0.0:
        raise AssociationError(f'position_std must be finite and >= 0, got {position_std}')
    q = float(accel_std) ** 2
    block = q * np.array([[dt ** 3 / 3.0, dt ** 2 / 2.0], [dt ** 2 / 2.0, dt]])
    block[0, 0] += float(position_std) ** 2 * dt
    Q = np.zeros((4, 4))
    Q[np.ix_([0, 2], [0, 2])] = block
    Q[np.ix_([1, 3], [1, 3])] = block
    return Q


def predict(mean: np.ndarray, cov: np.ndarray, dt: float, *, accel_std: float,
            position_std: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Predicted state and covariance (004 Appendix: X^ = F X, P^ = F P F' + Q).

    Args:
        mean: (..., 4) state, metres and m/s.
        cov: (..., 4, 4) state covariance.
        dt: prediction interval, seconds.
        accel_std, position_std: noise levels, see :func:`process_noise`.
    Returns:
        ((..., 4), (..., 4, 4)) predicted mean and covariance.
    """
    mean, cov = _check_state(mean, cov)
    F = transition_matrix(dt)
    Q = process_noise(dt, accel_std=accel_std, position_std=position_std)
    return mean @ F.T, F @ cov @ F.T + Q  # 004 Appendix: X^ = F X, P^ = F P F' + Q


def innovation_covariance(cov: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(..., 2, 2) measurement prediction covariance S = H P^ H' + R (004 Appendix)."""
    cov = np.asarray(cov, dtype=np.float64)
    return cov[..., :2, :2] + np.asarray(R, dtype=np.float64)


def innovation(mean: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Innovations nu = Z - H X^ (004 Appendix).

    ``mean`` (..., 4) and ``z`` (..., M, 2) give (..., M, 2); ``z`` (..., 2) gives (..., 2).
    """
    mean = np.asarray(mean, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    if z.ndim == mean.ndim:
        return z - mean[..., :2]
    return z - mean[..., None, :2]


def gain(cov: np.ndarray, S: np.ndarray) -> np.ndarray:
    """(..., 4, 2) filter gain W = P^ H' S^-1 (004 Appendix)."""
    PHt = np.asarray(cov, dtype=np.float64)[..., :, :2]
    # W = PHt S^-1  <=>  S' W' = (PHt)'; S is symmetric.
    return np.swapaxes(np.linalg.solve(S, np.swapaxes(PHt, -1, -2)), -1, -2)


def update(mean: np.ndarray, cov: np.ndarray, z: np.ndarray,
           R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Standard Kalman update with one measurement per target (004 Appendix).

    Args:
        mean: (..., 4) predicted state.
        cov: (..., 4, 4) predicted covariance.
        z: (..., 2) measured floor position, metres.
        R: (2, 2) or (..., 2, 2) measurement covariance, m^2.
    Returns:
        ((..., 4), (..., 4, 4)) updated mean and covariance (Joseph form, stays symmetric).
    """
    mean, cov = _check_state(mean, cov)
    z = np.asarray(z, dtype=np.float64)
    if z.shape != mean.shape[:-1] + (2,):
        raise AssociationError(f'measurement must be {mean.shape[:-1] + (2,)}, got {z.shape}')
    S = innovation_covariance(cov, R)
    W = gain(cov, S)
    nu = innovation(mean, z)
    new_mean = mean + np.einsum('...ij,...j->...i', W, nu)  # 004 Appendix: X = X^ + W nu
    IKH = np.eye(4) - W @ H  # 004 Appendix: P = (I - W H) P^, here in Joseph form
    new_cov = IKH @ cov @ np.swapaxes(IKH, -1, -2) + W @ np.asarray(R) @ np.swapaxes(W, -1, -2)
    return new_mean, 0.5 * (new_cov + np.swapaxes(new_cov, -1, -2))


def mahalanobis2(nu: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distances nu' S^-1 nu.

    ``nu`` (..., d) with ``S`` (..., d, d) (one vector per matrix) gives (...);
    ``nu`` (..., M, d) with ``S`` (..., d, d) (M vectors per matrix) gives (..., M).
    """
    nu = np.asarray(nu, dtype=np.float64)
    S = np.asarray(S, dtype=np.float64)
    if nu.ndim == S.ndim - 1:  # one vector per covariance matrix
        return np.einsum('...i,...i->...', nu, np.linalg.solve(S, nu[..., None])[..., 0])
    if nu.ndim != S.ndim:
        raise AssociationError(f'innovations {nu.shape} do not match covariances {S.shape}')
    sol = np.linalg.solve(S[..., None, :, :], nu[..., None])[..., 0]
    return np.einsum('...i,...i->...', nu, sol)


def nees(error: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared e' P^-1 e of (..., d) errors -> (...)."""
    return mahalanobis2(error, cov)


def gate_threshold(p_gate: float, dof: int = 2) -> float:
    """Validation gate gamma with P(chi2_dof <= gamma) = p_gate (004 §4.2, [3])."""
    if not 0.0 < p_gate < 1.0:
        raise AssociationError(f'gate probability must be in (0, 1), got {p_gate}')
    return float(chi2.ppf(p_gate, dof))


def in_gate(nu: np.ndarray, S: np.ndarray, p_gate: float) -> np.ndarray:
    """Boolean (..., M) mask of innovations inside the chi-square validation gate."""
    d2 = mahalanobis2(nu, S)
    with np.errstate(invalid='ignore'):
        return d2 <= gate_threshold(p_gate, np.asarray(nu).shape[-1])
