"""Log-weight normalisation, effective sample size and systematic resampling.

The one resampling routine of the package: every particle filter (HJS, separable, joint and
the detection processes) draws its indices with :func:`systematic_resample`.
Weights are handled in log space and normalised with logsumexp; NaN log-weights count as
``-inf`` (impossible). When every weight is impossible the set falls back to uniform weights
and the caller gets a flag so it can report the degeneracy.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ['ResamplingError', 'effective_sample_size', 'logsumexp', 'logsumexp_rows',
           'normalize_log_weight_rows', 'normalize_log_weights', 'normalized_weights',
           'systematic_indices', 'systematic_resample']


class ResamplingError(ValueError):
    """Weights or sizes that cannot be resampled."""


def logsumexp(a: np.ndarray) -> float:
    """``log sum exp a`` of a 1-D array; -inf entries allowed, all -inf (or empty) -> -inf.

    The package's one log-sum-exp (scipy's costs ~0.5 ms per call in per-frame loops):
    :func:`logsumexp_rows` of one row.
    """
    a = np.asarray(a, dtype=np.float64)
    if not a.size:
        return -math.inf
    return float(logsumexp_rows(a.reshape(1, -1))[0])


def logsumexp_rows(a: np.ndarray) -> np.ndarray:
    """``log sum exp`` of every row of (K, N > 0) ``a``, as ``max + log sum exp(a - max)``;
    a row whose max is not finite (all -inf, or +inf / NaN in it) gives that max."""
    a = np.asarray(a, dtype=np.float64)
    top = a.max(axis=1)
    finite = np.isfinite(top)
    if finite.all():
        return top + np.log(np.exp(a - top[:, None]).sum(axis=1))
    safe = np.where(finite, top, 0.0)
    sums = np.exp(a - safe[:, None]).sum(axis=1)
    sums[~finite] = 1.0                          # no log(0) warning; the max is returned
    return np.where(finite, safe + np.log(sums), top)


def normalize_log_weights(log_weights: np.ndarray) -> tuple[np.ndarray, bool]:
    """Normalise log-weights so that their exponentials sum to one.

    Args:
        log_weights: (N,) unnormalised log-weights; NaN is treated as -inf.

    Returns:
        ``(normalised, degenerate)``: (N,) float64 log-weights with logsumexp 0, and True if
        every input was -inf/NaN (the output is then uniform, ``-log N``).
    """
    lw = np.asarray(log_weights, dtype=np.float64)
    if lw.ndim != 1 or lw.size == 0:
        raise ResamplingError(f'log-weights must be a non-empty 1-D array, got shape {lw.shape}')
    out, degenerate = normalize_log_weight_rows(lw[None, :])
    return out[0], bool(degenerate[0])


def normalize_log_weight_rows(log_weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`normalize_log_weights` of every row of (K, N) log-weights in one pass (the
    same numbers as row by row: numpy sums each contiguous row on its own).

    Returns:
        ``(normalised (K, N), degenerate (K,) bool)``.
    """
    lw = np.asarray(log_weights, dtype=np.float64)
    if lw.ndim != 2 or lw.shape[1] == 0:
        raise ResamplingError(f'log-weight rows must be a (K, N > 0) array, got {lw.shape}')
    if np.isnan(lw).any():
        lw = np.where(np.isnan(lw), -np.inf, lw)
    if (lw == np.inf).any():
        raise ResamplingError('log-weights contain +inf')
    norm = logsumexp_rows(lw)
    degenerate = ~np.isfinite(norm)              # every weight -inf
    out = lw - np.where(degenerate, 0.0, norm)[:, None]
    if degenerate.any():
        out[degenerate] = -np.log(lw.shape[1])
    return out, degenerate


def normalized_weights(log_weights: np.ndarray) -> tuple[np.ndarray, bool]:
    """(N,) weights summing to one from log-weights, and the degeneracy flag (see above)."""
    lw, degenerate = normalize_log_weights(log_weights)
    w = np.exp(lw)
    return w / w.sum(), degenerate


def effective_sample_size(weights: np.ndarray) -> float:
    """Effective sample size ``1 / sum(w^2)`` of (N,) weights (normalised internally)."""
    w = np.asarray(weights, dtype=np.float64)
    total = w.sum()
    if w.ndim != 1 or w.size == 0 or not np.isfinite(total) or total <= 0 or np.any(w < 0):
        raise ResamplingError('weights must be a non-empty 1-D array of non-negative numbers '
                              'with a positive finite sum')
    w = w / total
    return float(1.0 / np.dot(w, w))


def systematic_resample(weights: np.ndarray, count: int,
                        rng: np.random.Generator) -> np.ndarray:
    """Systematic resampling: ``count`` indices drawn with one uniform offset.

    Args:
        weights: (N,) non-negative weights (normalised internally).
        count: number of indices to draw.
        rng: random generator (one uniform draw).

    Returns:
        (count,) int64 indices into ``weights``, sorted ascending.
    """
    w = np.asarray(weights, dtype=np.float64)
    if count < 1:
        raise ResamplingError(f'resampling needs count >= 1, got {count}')
    total = float(w.sum()) if w.ndim == 1 else math.nan
    if w.ndim != 1 or w.size == 0 or not math.isfinite(total) or total <= 0 or (w < 0).any():
        raise ResamplingError('weights must be a non-empty 1-D array of non-negative numbers '
                              'with a positive finite sum')
    return systematic_indices(w[None, :], np.array([total]), np.array([rng.random()]),
                              count)[0]


def systematic_indices(weights: np.ndarray, totals: np.ndarray, offsets: np.ndarray,
                       count: int) -> np.ndarray:
    """The indices of :func:`systematic_resample` for K weight rows at once (checked by the
    caller): rows (K, N) of non-negative weights, their sums ``totals`` (K,) and the uniform
    draws ``offsets`` (K,) in [0, 1). Returns (K, count) int64, each row sorted (the same
    numbers as one call per row: cumulative sums run along each row)."""
    cumulative = np.cumsum(weights / totals[:, None], axis=1)
    cumulative[:, -1] = 1.0  # guard against round-off leaving the last bin short
    positions = (offsets[:, None] + np.arange(count)) / count
    idx = np.empty((weights.shape[0], count), np.int64)
    for k in range(weights.shape[0]):
        idx[k] = np.searchsorted(cumulative[k], positions[k], side='right')
    return np.minimum(idx, weights.shape[1] - 1, out=idx)
