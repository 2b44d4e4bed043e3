"""The Jacobian takes the camera frame its residual computed at the same poses and points
(bundle._ByCamera.frame), and the sums by track reuse their bincount positions (schur._SumBy): an
adjustment is the same to the last bit as with every frame computed afresh, and a frame asked at
other values (an array changed in place among them) is computed again, not the last one returned."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from geocert.solvers.reconstruction import bundle, schur


def _scene(seed: int):
    rng = np.random.default_rng(seed)
    views, points = 5, 40
    R = Rotation.random(views, random_state=seed).as_matrix()
    t = rng.normal(size=(views, 3)) + [0.0, 0.0, 8.0]
    X = rng.normal(size=(points, 3))
    order = rng.permutation(views * points)
    view, track = np.repeat(np.arange(views), points)[order], np.tile(np.arange(points), views)[order]
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    cam = np.einsum("mij,mj->mi", R[view], X[track]) + t[view]
    pixels = (cam[:, :2] / cam[:, 2:]) * 800.0 + [320.0, 240.0] + rng.normal(scale=0.5, size=(len(view), 2))
    # a start off the truth, so that the adjustment takes steps and refuses some
    R0 = Rotation.from_rotvec(Rotation.from_matrix(R).as_rotvec() + rng.normal(scale=0.01, size=(views, 3)))
    return K * [[1.05, 1, 1], [1, 1.05, 1], [1, 1, 1]], R0.as_matrix(), t + rng.normal(scale=0.05, size=t.shape), \
        X + rng.normal(scale=0.05, size=X.shape), view, track, pixels


def _afresh(self, Am, Bm):
    R = self.rotations(Am)
    return R, self.camera_frame(R, Am, Bm)


@pytest.mark.parametrize("model", ["simple", "principal", "radial", "principal_per_view", "given", "focal_scale"])
def test_an_adjustment_is_the_same_with_every_frame_computed_afresh(model, monkeypatch):
    K, R, t, X, view, track, pixels = _scene(3)
    if model in ("given", "focal_scale"):
        K = np.array([K] * len(R))
    free = bundle.Free(model, k1=0.01 if model == "radial" else 0.0)
    steps = bundle.Schur(max_iterations=15, f_scale=2.0)  # Huber's weights too
    reused = bundle.adjust(K, R, t, X, view, track, pixels, free, steps)
    monkeypatch.setattr(bundle._ByCamera, "frame", _afresh)
    afresh = bundle.adjust(K, R, t, X, view, track, pixels, free, steps)
    assert_same_adjustment(reused, afresh)


def assert_same_adjustment(one, other) -> None:
    """Two adjustments of one scene are the same to the last bit, and each took steps."""
    assert one.iterations == other.iterations > 2
    for name in ("K", "R", "t", "X", "residuals"):
        assert np.array_equal(getattr(one, name), getattr(other, name)), name
    assert one.k1 == other.k1 and one.scale == other.scale


def test_a_frame_at_other_values_is_computed_again():
    K, R, t, X, view, track, pixels = _scene(4)
    cameras = bundle._ByCamera(view)
    A = np.hstack([Rotation.from_matrix(R).as_rotvec(), t])
    Am, Bm = A[view], X[track]
    first = cameras.frame(Am, Bm)
    again = cameras.frame(Am.copy(), Bm.copy())  # equal values, other arrays: the same answer
    assert again[0] is first[0] and again[1] is first[1]
    Am[view == 2, 3] += 0.5  # the same array changed in place: a new frame
    moved = cameras.frame(Am, Bm)
    expected = _afresh(cameras, Am, Bm)
    assert np.array_equal(moved[1], expected[1]) and not np.array_equal(moved[1], first[1])
    Bm[0] += 0.1  # a point moved
    assert np.array_equal(cameras.frame(Am, Bm)[1], _afresh(cameras, Am, Bm)[1])
    Am2 = Am.copy()
    Am2[:, 6:] = 1.0 if Am2.shape[1] > 6 else 0.0  # columns past the pose do not enter the frame
    assert cameras.frame(Am2, Bm)[1] is cameras.frame(Am, Bm)[1]


def test_sums_by_track_reuse_their_positions():
    rng = np.random.default_rng(5)
    track = rng.integers(0, 30, 400)
    by_track = schur._SumBy(track, 32)
    for shape in [(400, 3, 3), (400, 3), (400, 3, 3), (400, 2, 5)]:
        values = rng.normal(size=shape)
        expected = np.zeros((32,) + shape[1:])
        np.add.at(expected, track, values)
        assert np.abs(by_track(values) - expected).max() <= 1e-12
        assert np.array_equal(by_track(values), schur._sum_by(track, values, 32))
    assert sorted(by_track.at) == [3, 9, 10]
