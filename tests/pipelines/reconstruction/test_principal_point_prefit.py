"""pipeline._principal_point reuses a "principal" fit already made (the radial test's rival) only
when it registers the same views and tracks and explains every observation at least as well."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from geocert.pipelines.reconstruction import pipeline
from geocert.solvers.reconstruction import upgrade
from geocert.solvers.reconstruction.tracks import Observations


def _scene():
    """8 views round 80 points at several heights, each looking at the centre, the principal
    point 12 px off the image's centre, 0.3 px noise; the start has it at the centre."""
    rng = np.random.default_rng(3)
    views, points = 8, 80
    angles = np.linspace(0.0, 2.5, views)
    C = np.c_[6 * np.sin(angles), np.tile([-3.0, 3.0], views // 2), -6 * np.cos(angles)]
    R = []
    for c in C:  # rows: the camera's x, y and z (towards the origin) axes
        z = -c / np.linalg.norm(c)
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        R.append(np.array([x, np.cross(z, x), z]))
    R = np.array(R)
    t = -np.einsum("vij,vj->vi", R, C)
    X = rng.normal(size=(points, 3))
    view, track = np.repeat(np.arange(views), points), np.tile(np.arange(points), views)
    cam = np.einsum("mij,mj->mi", R[view], X[track]) + t[view]
    pixels = cam[:, :2] / cam[:, 2:] * 800.0 + [332.0, 240.0] + rng.normal(scale=0.3, size=(len(view), 2))
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    metric = upgrade.Metric(K, list(R), list(t), X.copy(), [], False)
    return metric, Observations(track, view, pixels, points, views)


@pytest.fixture(scope="module")
def fitted():
    metric, obs = _scene()
    held, held_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, 2.0, model="simple")
    free, free_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, 2.0, model="principal")
    return obs, held, held_keep, free, free_keep


def _counting(monkeypatch):
    calls = []
    adjust = upgrade.adjust
    monkeypatch.setattr(upgrade, "adjust", lambda *a, **k: calls.append(k.get("model")) or adjust(*a, **k))
    return calls


def test_a_fit_of_the_same_registration_is_used_as_it_is(monkeypatch, fitted):
    obs, held, held_keep, free, free_keep = fitted
    calls = _counting(monkeypatch)
    metric, keep, figures = pipeline._principal_point(held, obs, held_keep, 2.0, (640, 480), (free, free_keep))
    assert calls == []
    assert figures["estimated"] and metric is free and keep is free_keep
    assert abs(metric.K[0, 2] - 332.0) < 1.0


def test_a_fit_of_another_registration_or_a_worse_one_is_not_used(monkeypatch, fitted):
    obs, held, held_keep, free, free_keep = fitted
    fewer = upgrade.Metric(free.K, list(free.rotations), list(free.translations), free.points.copy(), [], False)
    fewer.rotations[5] = fewer.translations[5] = None
    worse = upgrade.Metric(free.K, list(free.rotations), list(free.translations), free.points + 0.01, [], False)
    for prefit in ((fewer, free_keep), (worse, free_keep)):
        calls = _counting(monkeypatch)
        metric, _, figures = pipeline._principal_point(held, obs, held_keep, 2.0, (640, 480), prefit)
        assert calls == ["principal"]
        assert figures["estimated"] and metric is not prefit[0]
