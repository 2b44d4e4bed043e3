"""ambiguity.retriangulated (the depth-reversal check's second chance for the twin), which
triangulates the tracks of each length at once, against calibrated.triangulate track by track:
the same points, the same tracks kept (seen once, by an unregistered view, behind a camera)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from geocert.pipelines.reconstruction import ambiguity
from geocert.solvers.reconstruction import upgrade
from geocert.solvers.reconstruction.calibrated import triangulate
from geocert.solvers.reconstruction.tracks import Observations


def test_retriangulated_is_the_linear_triangulation_of_each_track():
    rng = np.random.default_rng(5)
    n, p = 6, 60
    R = Rotation.from_rotvec(rng.normal(scale=0.2, size=(n, 3))).as_matrix()
    t = rng.normal(size=(n, 3)) * 0.3 + [0.0, 0.0, 6.0]
    X = rng.normal(size=(p, 3))
    X[7] = [0.0, 0.0, -20.0]  # behind every camera: keeps its point
    K = np.array([[700.0, 0.0, 300.0], [0.0, 700.0, 200.0], [0.0, 0.0, 1.0]])
    view, track = [], []
    for j in range(p):
        seen = rng.choice(n, size=1 if j % 11 == 0 else rng.integers(2, n + 1), replace=False)
        view += seen.tolist()
        track += [j] * len(seen)
    order = rng.permutation(len(view))
    view, track = np.array(view)[order], np.array(track)[order]
    cam = np.einsum("mij,mj->mi", R[view], X[track]) + t[view]
    pixels = cam[:, :2] / cam[:, 2:] * 700.0 + [300.0, 200.0] + rng.normal(scale=0.7, size=(len(view), 2))
    rotations, translations = list(R), list(t)
    rotations[2] = translations[2] = None  # an unregistered view's observations do not count
    start = rng.normal(size=(p, 3))
    metric = upgrade.Metric(K, rotations, translations, start.copy(), [], False)
    obs = Observations(track, view, pixels, p, n)

    got = ambiguity.retriangulated(metric, obs).points

    expected = start.copy()
    Kinv = np.linalg.inv(K)
    for j in range(p):
        m = np.flatnonzero((track == j) & (view != 2))
        if len(m) < 2:
            continue
        rays = (np.c_[pixels[m], np.ones(len(m))] @ Kinv.T)[:, :2]
        Xj = triangulate(R[view[m]], t[view[m]], rays)
        if np.all(np.isfinite(Xj)) and np.all((R[view[m]] @ Xj + t[view[m]])[:, 2] > 0):
            expected[j] = Xj
    assert np.array_equal(got == start, expected == start)  # the same tracks kept their points
    assert np.abs(got - expected).max() <= 1e-9
    assert np.array_equal(got[7], start[7]) and np.array_equal(got[0], start[0])
