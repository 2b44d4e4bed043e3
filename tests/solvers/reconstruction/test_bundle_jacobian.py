"""The metric bundle adjustment's analytic Jacobian (bundle.metric) against central differences
(schur._jacobians), for every camera model: the adjustment's steps are those of its residuals.
The analytic Jacobian replaced the central differences, which took about 40% of the K-unknown
path's time on the 47-photo templeRing (a residual evaluation per parameter coordinate)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from geocert.solvers.reconstruction import bundle, schur


@pytest.mark.parametrize("model", bundle.MODELS)
def test_the_analytic_jacobian_is_the_residuals_derivative(model, monkeypatch):
    rng = np.random.default_rng(0)
    views, points = 4, 20
    R = Rotation.random(views, random_state=1).as_matrix()
    t = rng.normal(size=(views, 3)) + [0.0, 0.0, 8.0]
    X = rng.normal(size=(points, 3))
    view, track = np.repeat(np.arange(views), points), np.tile(np.arange(points), views)
    K = np.array([[800.0, 2.0, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]])
    compared = []
    solve = schur.solve

    def compare(residual, A, S, B, view, track, *args, jacobian=None, **kwargs):
        assert jacobian is not None
        analytic = jacobian(A[view], S, B[track])
        numeric = schur._jacobians(residual, A, S, B, view, track)
        for a, n in zip(analytic, numeric):
            assert a.shape == n.shape
            if n.size:
                assert np.abs(a - n).max() <= 1e-6 * np.abs(n).max()
        compared.append(model)
        return solve(residual, A, S, B, view, track, *args, jacobian=jacobian, **kwargs)

    monkeypatch.setattr(schur, "solve", compare)
    focals = np.array([800.0, 810.0, 790.0, 805.0]) if model in ("varying", "focal_groups") else None
    groups = np.array([0, 1, 0, 2]) if model == "focal_groups" else None  # three focal lengths, one shared
    bundle.metric(K, R, t, X, view, track, rng.uniform(0, 600, (len(view), 2)), max_iterations=1, model=model,
                  k1=0.05, focals=focals, groups=groups)
    assert compared == [model]


@pytest.mark.parametrize("model", ["simple", "principal_per_view"])
def test_the_residuals_are_each_observations_own_camera_in_any_order(model, monkeypatch):
    """The residuals compute each view's rotation once and spread it to its observations: with the
    observations shuffled, each is still its own camera's projection of its point."""
    rng = np.random.default_rng(2)
    views, points = 4, 15
    R = Rotation.random(views, random_state=3).as_matrix()
    t = rng.normal(size=(views, 3)) + [0.0, 0.0, 8.0]
    X = rng.normal(size=(points, 3))
    order = rng.permutation(views * points)
    view, track = np.repeat(np.arange(views), points)[order], np.tile(np.arange(points), views)[order]
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    pixels = rng.uniform(0, 600, (len(view), 2))
    cam = np.einsum("mij,mj->mi", R[view], X[track]) + t[view]
    expected = cam[:, :2] / cam[:, 2:] * 800.0 + [320.0, 240.0] - pixels
    seen = []
    solve = schur.solve

    def capture(residual, A, S, B, view, track, *args, **kwargs):
        seen.append(residual(A[view], S, B[track]))
        return solve(residual, A, S, B, view, track, *args, **kwargs)

    monkeypatch.setattr(schur, "solve", capture)
    bundle.metric(K, R, t, X, view, track, pixels, max_iterations=1, model=model)
    assert np.abs(seen[0] - expected).max() <= 1e-9


def test_crossed_is_the_skew_matrix_product():
    """bundle._crossed(x, a), which the rotation columns of the Schur problems' Jacobians
    use, is -a [x]_x written out (each row of a crossed with x)."""
    from geocert.solvers.reconstruction.bundle import _crossed, _skew

    rng = np.random.default_rng(4)
    x, a = rng.normal(size=(30, 3)), rng.normal(size=(30, 2, 3))
    assert np.abs(_crossed(x, a) - (-a @ _skew(x))).max() <= 1e-14
    assert np.abs(_crossed(x, a)[:, 1] - np.cross(x, a[:, 1])).max() <= 1e-14
