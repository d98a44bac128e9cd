"""The diagnostics' shared helpers (docs/diag/_eval.py) that read the tracker's clouds."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from conftest import load_script
from mbtrack_ros.core.filters import FilterConfig, HJSFilter


@pytest.fixture(scope='module')
def diag_eval():
    return load_script('docs/diag/_eval.py', 'diag_eval')


def test_clouds_with_one_track_replaced_by_places(diag_eval):
    """``with_track_replaced`` keeps every other track's cloud, log-weights and model as
    the filter holds them and puts the given places, equally weighted, in the named
    track's slot; ``weighted_cloud`` normalises a track's weights."""
    rng = np.random.default_rng(2)
    flt = HJSFilter(FilterConfig(particles=20), floor=(-5.0, -5.0, 5.0, 5.0),
                    camera_names=['cam0'])
    models = {3: object(), 8: object(), 5: object()}
    for k, (tid, model) in enumerate(models.items()):
        flt.add(tid, model, np.r_[float(k), 0.0, 0.0, 0.0, 0.0, 0.0], rng)
    flt._logw[5] = np.log(rng.random(20))          # unnormalised, as a filter never holds
    tracker = SimpleNamespace(filter=flt)
    places = np.zeros((7, 6))
    places[:, 0] = np.linspace(0.0, 1.0, 7)
    clouds, logw, got, k = diag_eval.with_track_replaced(tracker, 8, places)
    assert k == 1 and got == list(models.values())
    np.testing.assert_array_equal(clouds[1], places)
    np.testing.assert_allclose(np.exp(logw[1]), np.full(7, 1 / 7))
    for i, tid in ((0, 3), (2, 5)):
        particles, lw, _ = flt.cloud(tid)
        np.testing.assert_array_equal(clouds[i], particles)
        np.testing.assert_array_equal(logw[i], lw)
    particles, w, model = diag_eval.weighted_cloud(tracker, 5)
    assert model is models[5] and w.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(w, np.exp(flt._logw[5]) / np.exp(flt._logw[5]).sum())
