"""How much two appearance models' distance says about whether they show one person: the
appearance likelihood ratio, calibrated online from the tracks themselves.

The association (:mod:`.association`) weighs "the detection is this track's person" against
"it is somebody else" by the log-likelihood ratio of the distance ``d`` between the two
models (003 Eq. 4, :func:`~mbtrack_ros.core.appearance.model_distance`)::

    LLR(d) = log p(d^2 | same person) - log p(d^2 | different people)

on the squared distance ``u = d^2`` (the quantity of the appearance likelihood
``exp(-u / (2 sigma^2))``, 000 Eq. 19 / 003 Eq. 3). Each density is a 1-D Gaussian, the two
sharing one variance (so the ratio is linear in ``u`` and falls monotonically with the
distance), whose means and variance are estimated from samples the tracker collects
(:meth:`~.manager.AutoDetection._calibrate`): while a track is followed confidently with
another within its gate a model is acquired again at its estimate (003 §4.1) and its
distance to the track's own model is a "same" sample, its distances to the models of the
confident tracks within the gate (other people by construction: two tracks at once) are
"different" samples.

The estimates are shrunk towards a prior worth :data:`PRIOR_SAMPLES` samples per class that
reproduces the fixed ratio of the clutter likelihood (001 Eq. 23)::

    LLR_0(d) = (a^2 - d^2) / (2 sigma^2)

with ``a`` the clutter distance and ``sigma`` the tracker's appearance likelihood width: the
"same" Gaussian at mean 0, the "different" at ``2 a^2``, both of standard deviation
``2 a sigma`` (their ratio is then ``LLR_0`` exactly). With no samples the ratio is
``LLR_0``; with many it is what this room's people and cameras show. Only the last
:data:`WINDOW` samples per class are kept (bounded memory; a slowly changing room).
"""
from __future__ import annotations

import numpy as np

__all__ = ['AppearanceRatio', 'PRIOR_SAMPLES', 'WINDOW']

PRIOR_SAMPLES = 20   # weight of the prior means and variance, in samples per class
WINDOW = 400         # samples kept per class (the most recent)


class AppearanceRatio:
    """Online-calibrated log-likelihood ratio (nats) of "same person" over "different
    people" for two appearance models a distance ``d`` (003 Eq. 4, in [0, 1]) apart (see the
    module).

    Args:
        clutter_distance: Bhattacharyya distance ``a`` at which the prior ratio is 0 (the
            clutter likelihood's distance, 001 Eq. 23), > 0.
        sigma: the tracker's appearance likelihood width (000 Eq. 19), > 0.
    """

    def __init__(self, clutter_distance: float, sigma: float) -> None:
        a, s = float(clutter_distance), float(sigma)
        if not (a > 0 and s > 0 and np.isfinite(a) and np.isfinite(s)):
            raise ValueError(f'clutter_distance and sigma must be > 0, got {a}, {s}')
        # prior on u = d^2: same ~ N(0, (2 a s)^2), different ~ N(2 a^2, (2 a s)^2)
        self.prior_means = np.array([0.0, 2.0 * a * a])
        self.prior_var = (2.0 * a * s) ** 2
        self._u = np.zeros((2, WINDOW))          # ring buffers: row 0 same, row 1 different
        self._n = np.zeros(2, np.int64)          # samples added per class (ever)
        self._fit: tuple[float, float, float] | None = None   # parameters(), until add()

    def add(self, same: np.ndarray | float = (), different: np.ndarray | float = ()) -> None:
        """Add distances (003 Eq. 4) of models known to show one person (``same``) and of
        models known to show two (``different``); non-finite values are ignored."""
        for c, d in enumerate((same, different)):
            d = np.asarray(d, np.float64).ravel()
            d = d[np.isfinite(d)]
            if not d.size:
                continue
            d = d[-WINDOW:]
            slots = (self._n[c] + np.arange(d.size)) % WINDOW
            self._u[c, slots] = d * d
            self._n[c] += d.size
            self._fit = None

    @property
    def counts(self) -> np.ndarray:
        """(2,) samples held: same, different (at most :data:`WINDOW` each)."""
        return np.minimum(self._n, WINDOW)

    def parameters(self) -> tuple[float, float, float]:
        """(mean of u = d^2 for one person, mean for different people, shared standard
        deviation), shrunk towards the prior: ``mean_c = (k m0_c + sum u) / (k + n_c)``,
        ``var = (2 k v0 + sum_c sum (u - mean(u_c))^2) / (2 k + n_same + n_different)``
        with ``k`` = :data:`PRIOR_SAMPLES`; computed once per change of the samples (the
        association asks for every pair it weighs)."""
        if self._fit is not None:
            return self._fit
        k = float(PRIOR_SAMPLES)
        n = self.counts
        means = np.empty(2)
        scatter = 0.0
        for c in range(2):
            u = self._u[c, :n[c]]
            means[c] = (k * self.prior_means[c] + u.sum()) / (k + n[c])
            if n[c]:
                scatter += float(((u - u.mean()) ** 2).sum())
        var = (2.0 * k * self.prior_var + scatter) / (2.0 * k + n.sum())
        self._fit = (float(means[0]), float(means[1]), float(np.sqrt(var)))
        return self._fit

    def llr(self, unlike: np.ndarray | float) -> np.ndarray | float:
        """``log N(d^2; m_same, s) - log N(d^2; m_diff, s)`` (nats) for distances ``unlike``
        (any shape; a float for a float): positive for models likelier one person; 0
        everywhere when the learnt "different" mean is not above the "same" one (the
        distance then tells nothing)."""
        m_same, m_diff, s = self.parameters()
        u = np.asarray(unlike, np.float64) ** 2
        out = (m_diff - m_same) / s ** 2 * (0.5 * (m_same + m_diff) - u) \
            if m_diff > m_same else np.zeros_like(u)
        return float(out) if np.ndim(out) == 0 else out

    def alike_distance(self) -> float:
        """The distance at which :meth:`llr` is 0 (models nearer look like one person);
        1.0 (the largest distance) when the distance tells nothing."""
        m_same, m_diff, _ = self.parameters()
        return float(np.sqrt(0.5 * (m_same + m_diff))) if m_diff > m_same else 1.0

    def looks_alike(self, unlike: float) -> bool:
        """Whether two models ``unlike`` apart are at least as likely one person as two."""
        return self.llr(unlike) >= 0.0

    def describe(self) -> dict:
        """The learnt state for logs: samples held and the distances (not squared) of the
        two means, the standard deviation of u, and the alike distance."""
        m_same, m_diff, s = self.parameters()
        return {'same': int(self.counts[0]), 'different': int(self.counts[1]),
                'd_same': round(float(np.sqrt(max(m_same, 0.0))), 3),
                'd_different': round(float(np.sqrt(max(m_diff, 0.0))), 3),
                'sd_u': round(s, 4), 'alike': round(self.alike_distance(), 3)}
