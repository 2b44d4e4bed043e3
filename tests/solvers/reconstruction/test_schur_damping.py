"""schur.solve's damping after a step taken, set by the step's gain ratio (the cost's actual
decrease over the decrease its linear model predicted), as Ceres Solver's Levenberg-Marquardt
strategy sets it: what the rule relies on is that the predicted decrease is the model's, so these
tests check that against the model itself and the ratio where it is known exactly."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.solvers.reconstruction import schur


def _problem(seed: int, n: int = 4, c: int = 3, s: int = 1, p: int = 12, d: int = 3):
    """A linear least-squares problem with the Schur structure: observation m sees view view[m] (c
    parameters), the s shared ones and point track[m] (d); r_m = P_m a_view + Q_m s + G_m b_track - y_m."""
    rng = np.random.default_rng(seed)
    view = np.repeat(np.arange(n), p)
    track = np.tile(np.arange(p), n)
    M = len(view)
    P, Q, G = rng.normal(size=(M, 2, c)), rng.normal(size=(M, 2, s)), rng.normal(size=(M, 2, d))
    y = rng.normal(size=(M, 2))

    def residual(Am, S, Bm):
        return np.einsum("mij,mj->mi", P, Am) + Q @ S + np.einsum("mij,mj->mi", G, Bm) - y

    return residual, rng.normal(size=(n, c)), rng.normal(size=s), rng.normal(size=(p, d)), view, track, (P, Q, G, y)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("lam", [1e-6, 1e-3, 0.5, 40.0])
def test_the_predicted_decrease_is_the_linear_models(seed, lam):
    """|r|^2 - |r + J h|^2 for h solving (J^T J + lam D) h = -J^T r, D the diagonal of J^T J (the
    damping schur.solve applies to U and V), is what _predicted_decrease computes from the gradient,
    the step and the two diagonals."""
    residual, A, S, B, view, track, (P, Q, G, y) = _problem(seed)
    n, c = A.shape
    p, d = B.shape
    s = len(S)
    M = len(view)
    nc = n * c + s
    J = np.zeros((2 * M, nc + p * d))
    for m in range(M):
        J[2 * m:2 * m + 2, c * view[m]:c * view[m] + c] = P[m]
        J[2 * m:2 * m + 2, n * c:nc] = Q[m]
        J[2 * m:2 * m + 2, nc + d * track[m]:nc + d * track[m] + d] = G[m]
    r = residual(A[view], S, B[track]).ravel()
    H, g = J.T @ J, J.T @ r
    h = np.linalg.solve(H + lam * np.diag(np.diag(H)), -g)
    model = r @ r - np.sum((r + J @ h) ** 2)
    diag_v = np.diag(H)[nc:].reshape(p, d)
    predicted = schur._predicted_decrease(g[:nc], h[:nc], g[nc:].reshape(p, d), h[nc:].reshape(p, d), lam,
                                          np.diag(H)[:nc], diag_v)
    assert model > 0
    assert predicted == pytest.approx(model, rel=1e-9)


def test_on_a_linear_problem_every_step_taken_has_gain_ratio_one(monkeypatch):
    """The model of a linear residual is exact, so the solve's ratio of the cost's decrease to the
    prediction is 1 at every step taken (the damping then falls to a third, the former rule's):
    the solve hands _predicted_decrease its own gradient, step and damping."""
    ratios = []
    predicted_decrease = schur._predicted_decrease

    def recorded(*args):
        ratios.append(predicted_decrease(*args))
        return ratios[-1]

    monkeypatch.setattr(schur, "_predicted_decrease", recorded)
    costs = []
    cost = schur._cost
    monkeypatch.setattr(schur, "_cost", lambda r, f: costs.append(cost(r, f)) or costs[-1])
    residual, A, S, B, view, track, _ = _problem(3)
    schur.solve(residual, A, S, B, view, track, None, 5, stop=schur.StopRule(0.0, 0.0, 0.0))
    # costs: the start's, then one per step tried; a step is taken when it lowers the cost
    taken = [costs[0]]
    for c in costs[1:]:
        if c < taken[-1]:
            taken.append(c)
    assert len(ratios) == len(taken) - 1 >= 2
    for before, after, predicted in zip(taken, taken[1:], ratios):
        if predicted > 1e-6 * before:  # (below that the decrease is the cost's rounding)
            assert (before - after) / predicted == pytest.approx(1.0, abs=1e-6)
    assert ratios[0] > 1e-6 * taken[0]


@pytest.mark.parametrize("lam", [1e-12, 1e-3, 7.0])
def test_the_damping_after_a_step_follows_its_gain_ratio(lam):
    """A third of it where the model predicted the decrease (ratio 1), as before; unchanged at
    ratio 1/2; raised, up to twice, where the cost fell by little of what was predicted; never
    below 1e-12."""
    assert schur._lowered(lam, 1.0) == pytest.approx(max(lam / 3, 1e-12))
    assert schur._lowered(lam, 0.5) == pytest.approx(lam)
    assert schur._lowered(lam, 1e-9) == pytest.approx(2 * lam, rel=1e-6)
    assert schur._lowered(lam, 3.0) == pytest.approx(max(lam / 3, 1e-12))
    ratios = np.linspace(0.0, 1.0, 11)
    assert all(schur._lowered(lam, a) >= schur._lowered(lam, b) for a, b in zip(ratios, ratios[1:]))
