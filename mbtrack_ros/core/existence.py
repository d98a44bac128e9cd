"""Visibility and existence of a track as auxiliary binary processes (001 §2-3).

Each track carries, beside its particle set, a binary **existence** process ``e`` (birth /
death) and, per camera ``c``, a binary **visibility** process ``v_c`` (desocclusion /
occlusion). They are filtered with the auxiliary-process recursion of 001 Eq. 12-16 while
sampling only in the person's state space (001 §2.3): the state dynamics do not depend on
``v`` (001 Eq. 22), so the single particle set of the tracker serves both visibility
hypotheses and the predictive data likelihood of each hypothesis is a particle average
(001 Eq. 18-19):

* ``v_c = 1``: ``p_1(y_c | y^{t-1}) ~ sum_n pi_n p(y_c | s_n)``, the appearance likelihood
  of the predicted particles in camera ``c`` (003 Eq. 3-4);
* ``v_c = 0``: ``p_0(y_c)``, a state-independent background/clutter likelihood (001 Eq. 23),
  here the appearance likelihood at a fixed clutter distance.

The posterior ``xi_{i,t} ∝ p_i(y_t | y^{t-1}) sum_j alpha_{ji} xi_{j,t-1}`` (001 Eq. 16) is
computed in log space. Existence follows 001 §3.2: non-existence forces the state into the
void state ``u`` (Eq. 27, 30), so only the existing branch needs particles; its data
likelihood relative to "no person" combines (a) the foreground support of the track's
rendered silhouette (coverage ``f_c``, truncated-exponential densities on [0, 1] giving the
log ratio ``2 k (f_c - f_s)`` per camera, neutral at the support coverage ``f_s``) and (b)
the visibility evidence, the likelihood of camera ``c`` under ``e = 1`` being the visibility
mixture ``xi_v p_1 + (1 - xi_v) p_0`` against ``p_0`` under ``e = 0`` (the joint (v, e)
chain of the conclusion of 001 with states (0, 0), (0, 1), (1, 1)).

**Relation to the HJS occlusion maps.** The HJS likelihood (000 Eq. 34) already weights the
pixels of a target by ``w*``, the probability that no other target is in front of it under
the *prior*; the expected visible fraction ``visible_fraction[c]`` derived from ``w*`` tells
how much of the silhouette *should* be seen. The visibility process answers a different
question: the *posterior* probability that the target *is* seen in camera ``c`` given the
data. ``w*`` is used here to weight the evidence of each camera (a camera in which the
target is expected to be hidden contributes neither support nor its absence), and the
predicted ``xi_v`` can be fed back as a mixture weight of the per-camera likelihood
(:func:`mixture_loglik`, 001 Eq. 14) so that a wrongly hidden view does not drag the
particles.

A track is reported while ``existence >= report_threshold`` and released when it stays
below ``release_threshold`` (see :mod:`mbtrack_ros.core.detection.release`).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from mbtrack_ros.core.resampling import logsumexp

__all__ = ['AuxiliaryConfig', 'ExistenceError', 'TrackAuxiliary', 'binary_step',
           'coverage_log_ratio', 'mixture_loglik', 'predictive_loglik', 'transition']


class ExistenceError(ValueError):
    """Bad input to the visibility/existence filters."""


def transition(p_on: float, p_off: float, dt: float) -> np.ndarray:
    """Transition matrix ``A[j, i] = p(a_t = i | a_{t-1} = j)`` of a binary chain, (2, 2).

    ``p_on`` (0 -> 1: desocclusion / birth) and ``p_off`` (1 -> 0: occlusion / death) are
    probabilities per second; they are converted to continuous-time rates and integrated
    exactly over ``dt`` seconds so that the filter does not depend on the frame rate.
    """
    if not (0.0 <= p_on < 1.0 and 0.0 <= p_off < 1.0):
        raise ExistenceError(f'transition probabilities must be in [0, 1): {p_on}, {p_off}')
    if not np.isfinite(dt) or dt < 0:
        raise ExistenceError(f'time step must be finite and >= 0, got {dt}')
    lam_on, lam_off = -np.log1p(-p_on), -np.log1p(-p_off)
    total = lam_on + lam_off
    if total <= 0.0:
        return np.eye(2)
    decay = 1.0 - np.exp(-total * dt)
    a01 = lam_on / total * decay
    a10 = lam_off / total * decay
    return np.array([[1.0 - a01, a01], [a10, 1.0 - a10]])


def binary_step(xi: float, A: np.ndarray, loglik0: float, loglik1: float
                ) -> tuple[float, float]:
    """One step of 001 Eq. 16 for a binary auxiliary process.

    Args:
        xi: previous posterior ``p(a_{t-1} = 1 | y^{t-1})``.
        A: (2, 2) transition matrix ``A[j, i]``.
        loglik0, loglik1: predictive data log-likelihoods ``log p_i(y_t | y^{t-1})``.

    Returns:
        (posterior ``p(a_t = 1 | y^t)``, predicted prior ``p(a_t = 1 | y^{t-1})``).
    """
    # scalar arithmetic (this runs per track and camera every frame: numpy's per-call
    # overhead on 2-vectors cost more than the rest of the existence update)
    xi = float(xi)
    prior0 = (1.0 - xi) * float(A[0, 0]) + xi * float(A[1, 0])   # 001 Eq. 16: sum_j alpha_ji xi_j
    prior1 = (1.0 - xi) * float(A[0, 1]) + xi * float(A[1, 1])
    logp0 = _add(_log(prior0), float(loglik0))
    logp1 = _add(_log(prior1), float(loglik1))
    top = max(logp0, logp1)
    if not math.isfinite(top):                         # no information: keep the prior
        return prior1, prior1
    norm = top + math.log(math.exp(logp0 - top) + math.exp(logp1 - top))
    if not math.isfinite(norm):
        return prior1, prior1
    return math.exp(logp1 - norm), prior1


def _log(x: float) -> float:
    return math.log(x) if x > 0.0 else (-math.inf if x == 0.0 else math.nan)


def _add(a: float, b: float) -> float:
    """a + b with NaN (e.g. -inf + inf) read as -inf, the impossible outcome."""
    out = a + b
    return -math.inf if out != out else out


def _logaddexp(x: float, y: float) -> float:
    """``log(exp(x) + exp(y))`` of two floats, as ``np.logaddexp``."""
    if x == y:
        return x + math.log(2.0)
    tmp = x - y
    if tmp > 0:
        return x + math.log1p(math.exp(-tmp))
    if tmp <= 0:
        return y + math.log1p(math.exp(tmp))
    return tmp                                         # NaN


def predictive_loglik(loglik: np.ndarray, log_weights: np.ndarray | None = None) -> float:
    """``log sum_n pi_n p(y | s_n)`` of predicted particles (001 Eq. 18-19).

    Args:
        loglik: (N,) per-particle log-likelihoods (NaN -> -inf).
        log_weights: (N,) log predictive weights (uniform when None).
    """
    ll = np.asarray(loglik, dtype=np.float64)
    if ll.ndim != 1 or ll.size == 0:
        raise ExistenceError(f'loglik must be a non-empty (N,) array, got {ll.shape}')
    ll = np.where(np.isnan(ll), -np.inf, ll)
    if log_weights is None:
        lw = np.full(ll.size, -np.log(ll.size))
    else:
        lw = np.asarray(log_weights, dtype=np.float64)
        if lw.shape != ll.shape:
            raise ExistenceError('loglik and log_weights differ in shape')
        lw = np.where(np.isnan(lw), -np.inf, lw)
        lw = lw - logsumexp(lw)
    return float(logsumexp(ll + lw))


def mixture_loglik(loglik_visible: np.ndarray, loglik_hidden: np.ndarray,
                   prior_visible: np.ndarray) -> np.ndarray:
    """Per-particle likelihood under uncertain visibility (001 Eq. 14, 23-24), (N,).

    ``log sum_c log(xi_c p_1(y_c | x) + (1 - xi_c) p_0(y_c))`` with per-camera
    ``loglik_visible`` (N, C), ``loglik_hidden`` (C,) and predicted visibility (C,).
    """
    lv = np.asarray(loglik_visible, dtype=np.float64)
    lh = np.asarray(loglik_hidden, dtype=np.float64)
    pv = np.clip(np.asarray(prior_visible, dtype=np.float64), 0.0, 1.0)
    if lv.ndim != 2 or lh.shape != (lv.shape[1],) or pv.shape != lh.shape:
        raise ExistenceError(
            f'expected (N, C), (C,), (C,) arrays, got {lv.shape}, {lh.shape}, {pv.shape}')
    with np.errstate(divide='ignore'):
        a = np.log(pv)[None, :] + lv
        b = np.log1p(-pv)[None, :] + lh[None, :]
    out = np.logaddexp(a, b).sum(axis=1)
    return np.where(np.isnan(out), -np.inf, out)


def coverage_log_ratio(coverage: Mapping[str, float], weights: Mapping[str, float],
                       gain: float, total: float = 0.0, neutral: float = 0.5) -> float:
    """Existence evidence of the foreground coverage ``f_c`` of a track's silhouettes:
    ``sum_c w_c 2 k (f_c - f_s)``, each camera weighted by ``weights`` (1 when omitted;
    NaN coverage counts as 0), added to ``total``.

    ``p(f | e=1) ∝ exp(k f)`` and ``p(f | e=0) ∝ exp(-k f)`` on [0, 1] (truncated
    exponentials) give the slope ``2 k``; their ratio is 1 at ``f = 0.5``. The coverage at
    which a camera's view is neutral, ``f_s`` (``neutral``, in [0, 1]), is instead the
    coverage that counts as a person's support (``ReleaseConfig.min_coverage``): a person
    seen only in part (cut by a wall or a nearer person, or in a posture the body model
    renders larger, such as sitting down) covers well under half of the rendered
    silhouette, an empty place almost none of it, so the crossover at 0.5 would count
    the former as evidence of absence."""
    out = total
    for cam, f in coverage.items():
        w = _unit(weights.get(cam, 1.0))
        f = _unit(f) if math.isfinite(f) else 0.0
        out += w * gain * 2.0 * (f - neutral)
    return out


@dataclass(frozen=True)
class AuxiliaryConfig:
    """Parameters of the visibility and existence processes.

    Attributes:
        occlusion, desocclusion: per-second probabilities of the visibility chain
            (001 §3.1 alpha_10, alpha_01).
        death, birth: per-second probabilities of the existence chain (001 §3.2).
        initial_visibility, initial_existence: values at track creation.
        support_gain: ``k`` of the coverage evidence ``2 k (f - f_s)`` per camera.
        appearance_weight: tempering of the visibility evidence in the existence update.
        visibility_cap: largest visibility prior used in that evidence: a wrong appearance
            model in every camera at once then costs at most ``log(1 - cap)`` per camera
            instead of killing an existing, well-supported track.
        report_threshold: a track is reported while its existence is at least this.
    """

    occlusion: float = 0.3
    desocclusion: float = 0.6
    death: float = 0.3
    birth: float = 0.05
    initial_visibility: float = 0.8
    initial_existence: float = 0.9
    support_gain: float = 4.0
    appearance_weight: float = 0.3
    visibility_cap: float = 0.7
    report_threshold: float = 0.5

    def __post_init__(self) -> None:
        for name in ('occlusion', 'desocclusion', 'death', 'birth'):
            v = getattr(self, name)
            if not 0.0 <= v < 1.0:
                raise ExistenceError(f'{name} probability must be in [0, 1), got {v}')
        for name in ('initial_visibility', 'initial_existence', 'report_threshold',
                     'visibility_cap'):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ExistenceError(f'{name} must be in [0, 1], got {v}')


@dataclass
class TrackAuxiliary:
    """Visibility (per camera) and existence posteriors of one track.

    Attributes:
        visibility: camera -> ``p(v_c = 1 | y^t)``.
        existence: ``p(e = 1 | y^t)``.
        prior_visibility: camera -> predicted ``p(v_c = 1 | y^{t-1})`` of the last step.
    """

    config: AuxiliaryConfig = field(default_factory=AuxiliaryConfig)
    visibility: dict[str, float] = field(default_factory=dict)
    existence: float = -1.0
    prior_visibility: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.existence < 0:
            self.existence = self.config.initial_existence

    @property
    def reported(self) -> bool:
        return self.existence >= self.config.report_threshold

    def predicted_visibility(self, camera: str, dt: float) -> float:
        """``p(v_c = 1 | y^{t-1})`` after ``dt`` seconds (001 Eq. 16, sum over j)."""
        cfg = self.config
        xi = self.visibility.get(camera, cfg.initial_visibility)
        A = transition(cfg.desocclusion, cfg.occlusion, dt)
        return float(np.array([1.0 - xi, xi]) @ A[:, 1])

    def update(self, dt: float, *, loglik_visible: Mapping[str, float],
               loglik_hidden: Mapping[str, float],
               coverage: Mapping[str, float] | None = None,
               visible_fraction: Mapping[str, float] | None = None,
               coverage_weights: Mapping[str, float] | None = None,
               neutral_coverage: float = 0.5) -> None:
        """One filtering step of all auxiliary processes of the track.

        Args:
            dt: seconds since the previous step.
            loglik_visible: camera -> ``log p_1(y_c | y^{t-1})`` (see
                :func:`predictive_loglik`); cameras that do not see the track are omitted.
            loglik_hidden: camera -> ``log p_0(y_c)`` clutter log-likelihood.
            coverage: camera -> foreground coverage of the track's silhouette in [0, 1].
            visible_fraction: camera -> expected visible fraction under the prior (w*);
                weights the camera's evidence (1 when omitted).
            coverage_weights: camera -> weight of its coverage evidence, when it differs
                from ``visible_fraction`` (the share of the silhouette whose pixels are
                evidence of this track alone).
            neutral_coverage: the coverage at which a camera's coverage evidence is
                neutral (:func:`coverage_log_ratio`).
        """
        cfg = self.config
        coverage = coverage or {}
        visible_fraction = visible_fraction or {}
        missing = set(loglik_visible) ^ set(loglik_hidden)
        if missing:
            raise ExistenceError(
                f'visible/hidden log-likelihoods must name the same cameras: {sorted(missing)}')
        A_v = transition(cfg.desocclusion, cfg.occlusion, dt)
        log_ratio_e = 0.0
        self.prior_visibility = {}
        for cam in loglik_visible:
            l1, l0 = float(loglik_visible[cam]), float(loglik_hidden[cam])
            l1 = -math.inf if math.isnan(l1) else l1
            l0 = -math.inf if math.isnan(l0) else l0
            xi_prev = self.visibility.get(cam, cfg.initial_visibility)
            xi, prior = binary_step(xi_prev, A_v, l0, l1)    # 001 Eq. 16 per camera
            self.visibility[cam] = xi
            self.prior_visibility[cam] = prior
            w = _unit(visible_fraction.get(cam, 1.0))
            # e = 1: visibility mixture xi p_1 + (1 - xi) p_0 against p_0 for e = 0
            if math.isfinite(l0):
                pv = min(prior, cfg.visibility_cap)
                mix = _logaddexp(_log(pv) + l1 - l0, _log1p_neg(pv))
                log_ratio_e += cfg.appearance_weight * w * mix
        log_ratio_e = coverage_log_ratio(coverage, coverage_weights if coverage_weights
                                         is not None else visible_fraction, cfg.support_gain,
                                         log_ratio_e, neutral_coverage)
        A_e = transition(cfg.birth, cfg.death, dt)
        self.existence, _ = binary_step(self.existence, A_e, 0.0, log_ratio_e)


def _unit(x: float) -> float:
    """x clipped to [0, 1] (NaN stays NaN, as np.clip)."""
    return min(max(float(x), 0.0), 1.0) if x == x else float(x)


def _log1p_neg(p: float) -> float:
    """``log(1 - p)``, -inf at p = 1."""
    return math.log1p(-p) if p < 1.0 else (-math.inf if p == 1.0 else math.nan)
