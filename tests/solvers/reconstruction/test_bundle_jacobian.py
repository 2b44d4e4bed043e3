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


def _own_K_scene(seed: int = 0):
    """Five views, each with its own K, of 40 points, the pixels 0.3 px off their projections."""
    rng = np.random.default_rng(seed)
    views, points = 5, 40
    R = Rotation.random(views, random_state=seed + 1).as_matrix()
    t = rng.normal(size=(views, 3)) * 0.3 + [0.0, 0.0, 8.0]
    X = rng.normal(size=(points, 3))
    K = np.array([[[800.0 + 10 * v, 1.0, 320.0 + v], [0.0, 795.0 + 10 * v, 240.0 - v], [0.0, 0.0, 1.0]]
                  for v in range(views)])
    view, track = np.repeat(np.arange(views), points), np.tile(np.arange(points), views)
    cam = np.einsum("mij,mj->mi", R[view], X[track]) + t[view]
    h = np.einsum("mij,mj->mi", K[view], cam)
    pixels = h[:, :2] / h[:, 2:] + rng.normal(scale=0.3, size=(len(view), 2))
    return K, R, t, X, view, track, pixels


@pytest.mark.parametrize("intrinsics", ["given", "focal_scale"])
def test_each_views_own_K_jacobian_is_the_residuals_derivative(intrinsics, monkeypatch):
    """bundle.adjust's Schur problem with each view's own K (the K-known path's adjustment), a
    camera held: its analytic Jacobian against central differences, the held camera's columns zero."""
    K, R, t, X, view, track, pixels = _own_K_scene()
    held = np.array([False, True, False, False, False])
    solve, compared = schur.solve, []

    def compare(residual, A, S, B, view, track, *args, jacobian=None, **kwargs):
        analytic = jacobian(A[view], S, B[track])
        numeric = list(schur._jacobians(residual, A, S, B, view, track))
        numeric[0][held[view]] = 0.0
        for a, n in zip(analytic, numeric):
            assert a.shape == n.shape
            if n.size:
                assert np.abs(a - n).max() <= 1e-6 * np.abs(n).max()
        compared.append(intrinsics)
        return solve(residual, A, S, B, view, track, *args, jacobian=jacobian, **kwargs)

    monkeypatch.setattr(schur, "solve", compare)
    out = bundle.adjust(K, R, t * 1.01, X, view, track, pixels, bundle.Free(intrinsics, held=held),
                        bundle.Schur(max_iterations=1))
    assert compared == [intrinsics]
    assert np.abs(out.t[1] - t[1] * 1.01).max() <= 1e-15 and np.abs(out.R[1] - R[1]).max() <= 1e-12


def test_the_two_strategies_reach_the_same_minimum():
    """The Schur strategy and least squares (plain losses, view 0 held) from the same perturbed
    start end at the same reprojection cost, below the start's, the held camera where it was."""
    K, R, t, X, view, track, pixels = _own_K_scene(3)
    rng = np.random.default_rng(5)
    start = (R, t + rng.normal(scale=0.02, size=t.shape), X + rng.normal(scale=0.02, size=X.shape))
    start[1][0] = t[0]

    def cost(Rs, ts, Xs):
        h = np.einsum("mij,mj->mi", K[view], np.einsum("mij,mj->mi", Rs[view], Xs[track]) + ts[view])
        return float(np.sum((h[:, :2] / h[:, 2:] - pixels) ** 2))

    held = np.arange(5) == 0
    exact = bundle.adjust(K, *start, view, track, pixels, bundle.Free("given", held=held),
                          bundle.Schur(max_iterations=50))
    lsq = bundle.adjust(K, *start, view, track, pixels, bundle.Free("given", held=held),
                        bundle.LeastSquares(max_nfev=200, loss="linear", ftol=1e-12))
    before, a, b = cost(*start), cost(exact.R, exact.t, exact.X), cost(lsq.R, lsq.t, lsq.X)
    assert a < 0.5 * before and b < 0.5 * before
    assert abs(a - b) <= 1e-6 * a
    for out in (exact, lsq):
        assert np.abs(out.t[0] - t[0]).max() <= 1e-12 and np.abs(out.R[0] - R[0]).max() <= 1e-12


def test_held_cameras_and_least_squares_need_each_views_own_K():
    K, R, t, X, view, track, pixels = _own_K_scene()
    with pytest.raises(ValueError):
        bundle.adjust(K[0], R, t, X, view, track, pixels, bundle.Free("fixed", held=np.arange(5) == 0))
    with pytest.raises(ValueError):
        bundle.adjust(K[0], R, t, X, view, track, pixels, bundle.Free("fixed"), bundle.LeastSquares(max_nfev=5))


def _shuffled_scene(seed: int):
    """Five cameras, the second seeing nothing, 25 points; the observations in a random order, so
    each camera's are scattered among the others'."""
    rng = np.random.default_rng(seed)
    views, points = 5, 25
    R = Rotation.random(views, random_state=seed + 1).as_matrix()
    t = rng.normal(size=(views, 3)) * 0.3 + [0.0, 0.0, 8.0]
    X = rng.normal(size=(points, 3))
    seen = np.array([0, 2, 3, 4])
    order = rng.permutation(len(seen) * points)
    view, track = np.repeat(seen, points)[order], np.tile(np.arange(points), len(seen))[order]
    return rng, R, t, X, view, track


def test_products_by_camera_are_each_observations_own():
    """bundle._ByCamera.times (each camera's observations in one matrix product) and
    bundle._left_times (one matrix for all) equal numpy's product per observation, with the
    observations in any order and a camera without any."""
    rng, R, t, X, view, track = _shuffled_scene(6)
    cameras = bundle._ByCamera(view)
    mats = rng.normal(size=(len(cameras.rows), 3, 4))
    x = rng.normal(size=(len(view), 2, 3))
    expected = x @ mats[np.searchsorted(view[cameras.rows], view)]
    assert np.abs(cameras.times(x, mats) - expected).max() <= 1e-12 * np.abs(expected).max()
    F = rng.normal(size=(2, 2))
    y = rng.normal(size=(len(view), 2, 3))
    assert np.abs(bundle._left_times(F, y) - F @ y).max() <= 1e-12 * np.abs(F @ y).max()
    rotations = cameras.rotations(np.hstack([Rotation.from_matrix(R).as_rotvec(), t])[view])
    assert np.abs(rotations - R[view[cameras.rows]]).max() <= 1e-12


@pytest.mark.parametrize("model", bundle.MODELS + ("given", "focal_scale"))
def test_the_jacobian_in_any_observation_order_is_the_residuals_derivative(model, monkeypatch):
    """The Jacobians' products by camera (bundle._ByCamera) put each observation's rows back in its
    place: with the observations shuffled and a camera unobserved, every model's analytic Jacobian
    (the shared K's and each view's own) is still the central differences'."""
    rng, R, t, X, view, track = _shuffled_scene(7)
    own = model in ("given", "focal_scale")
    K = np.array([[800.0, 2.0, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]])
    if own:
        K = np.array([K + [[10.0 * v, 0, v], [0, 10.0 * v, -v], [0, 0, 0]] for v in range(len(R))])
    pixels = rng.uniform(0, 600, (len(view), 2))
    compared = []
    solve = schur.solve

    def compare(residual, A, S, B, view, track, *args, jacobian=None, **kwargs):
        analytic = jacobian(A[view], S, B[track])
        numeric = schur._jacobians(residual, A, S, B, view, track)
        for a, n in zip(analytic, numeric):
            assert a.shape == n.shape
            if n.size:
                assert np.abs(a - n).max() <= 1e-6 * np.abs(n).max()
        compared.append(model)
        return solve(residual, A, S, B, view, track, *args, jacobian=jacobian, **kwargs)

    monkeypatch.setattr(schur, "solve", compare)
    if own:
        bundle.adjust(K, R, t, X, view, track, pixels, bundle.Free(model), bundle.Schur(max_iterations=1))
    else:
        focals = np.array([800.0, 805.0, 810.0, 790.0, 805.0]) if model in ("varying", "focal_groups") else None
        groups = np.array([0, 1, 0, 2, 2]) if model == "focal_groups" else None
        bundle.metric(K, R, t, X, view, track, pixels, max_iterations=1, model=model, k1=0.05, focals=focals,
                      groups=groups)
    assert compared == [model]
