"""The appearance likelihood ratio calibrated on the tracks (:mod:`.detection.likeness`)."""
from __future__ import annotations

import numpy as np
import pytest

from mbtrack_ros.core.detection import likeness
from mbtrack_ros.core.detection.likeness import PRIOR_SAMPLES, WINDOW, AppearanceRatio


def _gauss_loglik(u, mean, sd):
    return -0.5 * ((u - mean) / sd) ** 2 - np.log(sd * np.sqrt(2 * np.pi))


@pytest.mark.parametrize('a, sigma', [(0.5, 0.12), (0.3, 0.1), (1.0, 0.2)])
def test_without_samples_the_ratio_is_the_clutter_likelihood_ratio(a, sigma):
    """No sample: ``(a^2 - d^2) / (2 sigma^2)`` (000 Eq. 19 against the clutter likelihood at
    ``a``, 001 Eq. 23) at every distance, 0 at ``a``, positive below it."""
    ratio = AppearanceRatio(a, sigma)
    d = np.linspace(0.0, 1.0, 41)
    np.testing.assert_allclose(ratio.llr(d), (a * a - d * d) / (2 * sigma ** 2), atol=1e-9)
    assert ratio.alike_distance() == pytest.approx(a)
    assert ratio.looks_alike(0.9 * a) and not ratio.looks_alike(1.1 * a)
    assert isinstance(ratio.llr(0.3), float)
    assert ratio.counts.tolist() == [0, 0]


def test_the_learnt_ratio_is_the_closed_form_gaussian_ratio_of_the_shrunk_estimates():
    """Known samples: means and pooled variance of the squared distances, shrunk towards the
    prior by ``PRIOR_SAMPLES`` each, written out; the ratio is the log ratio of the two
    Gaussian densities (brute force with the densities), and with many samples it is the
    ratio of the samples' own Gaussians."""
    a, sigma = 0.5, 0.12
    rng = np.random.default_rng(1)
    same = np.sqrt(np.clip(rng.normal(0.14, 0.05, 60), 0, None))
    diff = np.sqrt(np.clip(rng.normal(0.45, 0.07, 90), 0, None))
    ratio = AppearanceRatio(a, sigma)
    ratio.add(same=same[:30], different=diff[:50])
    ratio.add(same=same[30:])
    for d in diff[50:]:
        ratio.add(different=float(d))
    k = PRIOR_SAMPLES
    us, ud = same ** 2, diff ** 2
    m_s = (k * 0.0 + us.sum()) / (k + us.size)
    m_d = (k * 2 * a * a + ud.sum()) / (k + ud.size)
    var = (2 * k * (2 * a * sigma) ** 2 + ((us - us.mean()) ** 2).sum()
           + ((ud - ud.mean()) ** 2).sum()) / (2 * k + us.size + ud.size)
    got = ratio.parameters()
    assert got == pytest.approx((m_s, m_d, np.sqrt(var)))
    d = np.linspace(0.0, 1.0, 21)
    want = _gauss_loglik(d ** 2, m_s, np.sqrt(var)) - _gauss_loglik(d ** 2, m_d, np.sqrt(var))
    np.testing.assert_allclose(ratio.llr(d), want, atol=1e-9)
    assert ratio.alike_distance() == pytest.approx(np.sqrt(0.5 * (m_s + m_d)))
    # many samples: the means are the samples' (the prior's weight is small against
    # WINDOW), the variance the samples' with the prior's weight
    big = AppearanceRatio(a, sigma)
    s2 = np.sqrt(0.2 + 0.04 * np.tile([-1.0, 1.0], WINDOW // 2))
    d2 = np.sqrt(0.4 + 0.04 * np.tile([-1.0, 1.0], WINDOW // 2))
    for _ in range(3):
        big.add(same=s2, different=d2)
    m_s, m_d, s = big.parameters()
    assert m_s == pytest.approx(0.2, abs=0.01) and m_d == pytest.approx(0.4, abs=0.01)
    v0, n = (2 * a * sigma) ** 2, 2 * WINDOW
    assert s == pytest.approx(np.sqrt((2 * k * v0 + n * 0.04 ** 2) / (2 * k + n)), rel=1e-6)
    assert big.alike_distance() == pytest.approx(np.sqrt(0.3), abs=0.01)


def test_the_window_keeps_the_latest_samples_and_ignores_non_finite_ones(monkeypatch):
    """Only the last ``WINDOW`` samples per class count (bounded memory), in whatever
    batches they came; nan and inf are dropped."""
    monkeypatch.setattr(likeness, 'WINDOW', 8)
    ratio = AppearanceRatio(0.5, 0.12)
    ratio.add(same=np.full(5, 0.9), different=[np.nan, np.inf])
    ratio.add(same=np.arange(1, 11) / 20)          # 10 more: the first 5 and 2 of these go
    assert ratio.counts.tolist() == [8, 0]
    alone = AppearanceRatio(0.5, 0.12)
    alone.add(same=np.arange(3, 11) / 20)
    assert ratio.parameters() == pytest.approx(alone.parameters())
    assert alone._u.shape == (2, 8)


def test_a_distance_that_tells_nothing_gives_no_ratio():
    """Learnt "different" distances no larger than the "same" ones: the ratio is 0 at every
    distance (appearance says nothing) and every pair looks alike."""
    ratio = AppearanceRatio(0.5, 0.12)
    ratio.add(same=np.full(400, 0.8), different=np.full(400, 0.3))
    assert np.all(ratio.llr(np.linspace(0, 1, 11)) == 0.0)
    assert ratio.alike_distance() == 1.0 and ratio.looks_alike(1.0)


def test_bad_prior_values_are_refused():
    for a, s in ((0.0, 0.12), (0.5, -1.0), (np.nan, 0.12), (0.5, np.inf)):
        with pytest.raises(ValueError):
            AppearanceRatio(a, s)
