"""schur.solve's and bundle._ByCamera's row gathers by np.take (schur._rows) and the points' damped
blocks with their diagonal alone computed (schur._damped) give the same floats as numpy's fancy
indexing and the whole expression V + lam (diag(V) I + 1e-12 I): an adjustment under every camera
model, Huber's weights on, is the same to the last bit as with the former ways."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.solvers.reconstruction import bundle, schur
from tests.solvers.reconstruction.test_camera_frame_reuse import _scene, assert_same_adjustment


def _whole(V, lam, finite):
    d = V.shape[-1]
    return V + lam * (np.einsum("pii->pi", V)[:, :, None] * np.eye(d) + 1e-12 * np.eye(d))


def _fancy(values, index):
    return values[index]


def _times_by_assignment(self, x, mats):
    """bundle._ByCamera.times as it was: the observations gathered and put back by fancy indexing."""
    M, r, k = x.shape
    gathered = x[self.order].reshape(-1, k)
    out = np.empty((M * r, mats.shape[-1]))
    for i, (b, e) in enumerate(zip(self.bounds[:-1], self.bounds[1:])):
        np.matmul(gathered[b * r:e * r], mats[i], out=out[b * r:e * r])
    scattered = np.empty((M, r, mats.shape[-1]))
    scattered[self.order] = out.reshape(M, r, mats.shape[-1])
    return scattered


def test_damped_blocks_are_the_whole_expression_bit_for_bit():
    rng = np.random.default_rng(7)
    for d in (2, 3, 4):
        jb = rng.normal(size=(600, 2, d)) * rng.choice([1e-9, 1.0, 1e6], size=(600, 1, 1))
        track = rng.integers(0, 250, 600)  # some points unobserved: all-zero blocks
        V = schur._sum_by(track, jb.transpose(0, 2, 1) @ jb, 250)
        V[3] = 0.0
        for lam in (1e-12, 1e-3, 0.37, 4e11):
            assert np.array_equal(schur._damped(V, lam, True), _whole(V, lam, True))
    # not finite: the whole expression (its nan off the diagonal of an infinite block kept)
    V = rng.normal(size=(5, 3, 3))
    V[1, 1, 1] = np.inf
    V[2, 0, 2] = np.nan
    with np.errstate(invalid="ignore"):  # inf 0
        assert np.array_equal(schur._damped(V, 1e-3, False), _whole(V, 1e-3, False), equal_nan=True)
        assert np.isnan(schur._damped(V, 1e-3, False)[1, 1, 0])  # in the row of the infinite entry


def test_rows_are_fancy_indexing():
    rng = np.random.default_rng(8)
    for shape in [(30,), (30, 3), (30, 3, 3), (30, 2, 11)]:
        values = rng.normal(size=shape)
        for index in (rng.integers(0, 30, 500), rng.integers(0, 30, (70, 9)), np.zeros(0, dtype=int)):
            assert np.array_equal(schur._rows(values, index), values[index])


@pytest.mark.parametrize("model", ["simple", "principal", "radial", "principal_per_view", "given", "focal_scale"])
@pytest.mark.parametrize("f_scale", [2.0, None])
def test_an_adjustment_is_the_same_as_with_fancy_indexing(model, f_scale, monkeypatch):
    K, R, t, X, view, track, pixels = _scene(11)
    if model in ("given", "focal_scale"):
        K = np.array([K] * len(R))
    free = bundle.Free(model, k1=0.01 if model == "radial" else 0.0)
    steps = bundle.Schur(max_iterations=15, f_scale=f_scale)
    taken = bundle.adjust(K, R, t, X, view, track, pixels, free, steps)
    monkeypatch.setattr(schur, "_rows", _fancy)
    monkeypatch.setattr(schur, "_damped", _whole)
    monkeypatch.setattr(bundle._ByCamera, "times", _times_by_assignment)
    fancy = bundle.adjust(K, R, t, X, view, track, pixels, free, steps)
    assert_same_adjustment(taken, fancy)
