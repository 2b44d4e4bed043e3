"""schur.solve's stopping rule (schur.StopRule, Ceres Solver's function, gradient and parameter
tolerances): where the adjustment ends is a property of the costs it went through, asserted here
as such, never as an iteration count (which depends on the BLAS's rounding)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from geocert.solvers.reconstruction import bundle, schur, upgrade


def _scene(noise_px: float, seed: int = 0):
    """A metric bundle adjustment started off the truth: 5 views of 40 points, pixels with noise."""
    rng = np.random.default_rng(seed)
    views, points = 5, 40
    R = Rotation.random(views, random_state=seed + 1).as_matrix()
    t = rng.normal(size=(views, 3)) + [0.0, 0.0, 10.0]
    X = rng.normal(size=(points, 3))
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    view, track = np.repeat(np.arange(views), points), np.tile(np.arange(points), views)
    cam = np.einsum("mij,mj->mi", R[view], X[track]) + t[view]
    pixels = cam[:, :2] / cam[:, 2:] * 800.0 + [320.0, 240.0] + rng.normal(scale=noise_px, size=(len(view), 2))
    start_R = Rotation.from_rotvec(rng.normal(scale=0.01, size=(views, 3))).as_matrix() @ R
    return K, start_R, t + rng.normal(scale=0.05, size=t.shape), X + rng.normal(scale=0.02, size=X.shape), \
        view, track, pixels


def _accepted_costs(monkeypatch, f_scale, stop, max_iterations=200, noise_px=0.5):
    """Runs bundle.metric ("fixed" K) under ``stop``; returns the cost at the start and after each
    step taken (schur._cost is evaluated once at the start and once per step tried), and the
    iterations solve reports."""
    tried = []
    cost = schur._cost
    monkeypatch.setattr(schur, "_cost", lambda r, f: tried.append(cost(r, f)) or tried[-1])
    reported = []
    solve = schur.solve
    monkeypatch.setattr(schur, "solve", lambda *a, **k: reported.append(solve(*a, **k)) or reported[-1])
    K, R, t, X, view, track, pixels = _scene(noise_px)
    bundle.metric(K, R, t, X, view, track, pixels, f_scale=f_scale, max_iterations=max_iterations, model="fixed",
                  stop=stop)
    taken = [tried[0]]
    for c in tried[1:]:
        if c < taken[-1]:
            taken.append(c)
    return taken, reported[0][4]


@pytest.mark.parametrize("f_scale", [None, 1.0])
@pytest.mark.parametrize("tolerance", [1e-2, 1e-4, 1e-6])
def test_the_adjustment_ends_at_the_first_step_whose_relative_cost_change_is_within_the_function_tolerance(
        monkeypatch, f_scale, tolerance):
    taken, iterations = _accepted_costs(monkeypatch, f_scale, schur.StopRule(tolerance, 0.0, 0.0))
    assert iterations < 200  # ended by the rule, not the cap
    changes = [(before - after) / before for before, after in zip(taken, taken[1:])]
    assert changes[-1] <= tolerance
    assert all(change > tolerance for change in changes[:-1])


def test_a_looser_function_tolerance_ends_sooner_and_higher_but_near_the_minimum(monkeypatch):
    tight, tight_iterations = _accepted_costs(monkeypatch, 1.0, schur.StopRule(1e-12, 0.0, 0.0))
    monkeypatch.undo()
    ceres, ceres_iterations = _accepted_costs(monkeypatch, 1.0, schur.CERES)
    assert ceres_iterations <= tight_iterations
    assert tight[-1] <= ceres[-1] <= tight[-1] * (1 + 1e-4)


def test_the_gradient_tolerance_ends_the_adjustment_before_a_step_at_the_minimum(monkeypatch):
    """Noise-free pixels and the true cameras and points: the gradient is zero, so no step is
    computed (the old rule tried steps, each refused, until the damping ran out)."""
    rng = np.random.default_rng(0)
    views, points = 4, 20
    R = Rotation.random(views, random_state=1).as_matrix()
    t = rng.normal(size=(views, 3)) + [0.0, 0.0, 10.0]
    X = rng.normal(size=(points, 3))
    view, track = np.repeat(np.arange(views), points), np.tile(np.arange(points), views)
    A = np.hstack([Rotation.from_matrix(R).as_rotvec(), t])

    def residual(Am, S, Bm):
        cam = Rotation.from_rotvec(Am[:, :3]).apply(Bm) + Am[:, 3:6]
        truth = Rotation.from_rotvec(A[view, :3]).apply(X[track]) + A[view, 3:6]
        return 800.0 * (cam[:, :2] / cam[:, 2:] - truth[:, :2] / truth[:, 2:])

    _, _, _, r, iterations = schur.solve(residual, A.copy(), np.zeros(0), X.copy(), view, track, None, 50,
                                         stop=schur.StopRule(0.0, 1e-10, 0.0))
    assert iterations == 0
    assert np.abs(r).max() == 0.0


def test_the_stop_rule_is_each_solvers_explicit_option():
    from geocert.solvers.reconstruction.calibrated import CalibratedOptions
    from geocert.solvers.reconstruction.upgrade import ROBUST_ROUND_STOP

    assert schur.CERES == schur.StopRule(function_tolerance=1e-6, gradient_tolerance=1e-10, parameter_tolerance=1e-8)
    assert CalibratedOptions().final_ba_stop == schur.CERES
    # The adjustments adjusted again later may stop looser, never tighter than the final ones.
    assert CalibratedOptions().ba_stop.function_tolerance >= CalibratedOptions().final_ba_stop.function_tolerance
    assert ROBUST_ROUND_STOP.function_tolerance >= schur.CERES.function_tolerance
    # K known, and the per-view principal points, move with where the first round ends: Ceres's.
    assert upgrade.robust_round_stop("fixed") == upgrade.robust_round_stop("principal_per_view") == schur.CERES
    assert upgrade.robust_round_stop("simple") == upgrade.robust_round_stop("principal") == ROBUST_ROUND_STOP


def test_a_step_within_the_parameter_tolerance_is_taken_before_the_adjustment_ends():
    """Exact pixels, the points started 1e-9 off: the first step is within the parameter
    tolerance (small against the parameters), yet it removes nearly all the error left; it is
    taken (returning without it left exact tracks' cameras 2.5e-6 degrees off in the
    reconstruction's test of exact recovery)."""
    K, R, t, X, view, track, _ = _scene(0.0)
    rng = np.random.default_rng(5)
    cam = np.einsum("mij,mj->mi", R[view], X[track]) + t[view]
    pixels = cam[:, :2] / cam[:, 2:] * 800.0 + [320.0, 240.0]
    start = X + rng.normal(scale=1e-9, size=X.shape)
    before = bundle.metric(K, R, t, start, view, track, pixels, max_iterations=0, model="fixed")[4]
    after = bundle.metric(K, R, t, start, view, track, pixels, max_iterations=50, model="fixed",
                          stop=schur.StopRule(0.0, 0.0, 1e-8))[4]
    assert np.abs(before).max() > 1e-8
    assert np.abs(after).max() < 1e-3 * np.abs(before).max()


def _ring_with_mismatched_tracks(seed: int):
    """8 views on an arc round 300 points, 0.5 px noise, 10% of the observations gross outliers
    (8 px) and a tenth of the tracks mismatched in every view (3 px): the tracks upgrade.adjust's
    Huber round fits slowly (every observation on the loss's linear branch). Returns the start
    (rotations 0.003 rad, K 1% off), the observations and the true rotations."""
    rng = np.random.default_rng(seed)
    views, points = 8, 300
    angles = np.linspace(0.0, 1.2, views)
    R = Rotation.from_rotvec(np.c_[np.zeros(views), angles, np.zeros(views)]).as_matrix()
    C = np.c_[10 * np.sin(angles), np.zeros(views), -10 * np.cos(angles)]
    t = -np.einsum("vij,vj->vi", R, C)
    X = rng.normal(size=(points, 3))
    view, track = np.repeat(np.arange(views), points), np.tile(np.arange(points), views)
    cam = np.einsum("mij,mj->mi", R[view], X[track]) + t[view]
    pixels = cam[:, :2] / cam[:, 2:] * 800.0 + [320.0, 240.0] + rng.normal(scale=0.5, size=(len(view), 2))
    bad = rng.random(len(view)) < 0.1
    pixels[bad] += rng.normal(scale=8.0, size=(bad.sum(), 2))
    wrong = track < points // 10
    pixels[wrong] += rng.normal(scale=3.0, size=(wrong.sum(), 2))
    start_R = Rotation.from_rotvec(rng.normal(scale=0.003, size=(views, 3))).as_matrix() @ R
    K = np.array([[808.0, 0.0, 320.0], [0.0, 808.0, 240.0], [0.0, 0.0, 1.0]])
    start = upgrade.Metric(K, list(start_R), list(t + rng.normal(scale=0.02, size=t.shape)),
                           X + rng.normal(scale=0.01, size=X.shape), [], False)
    return start, view, track, pixels, R


def _degrees(A, B):
    return max(np.degrees(np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1.0, 1.0))) for a, b in zip(A, B))


@pytest.mark.parametrize("seed", range(3))
def test_the_huber_round_stops_sooner_than_ceres_would_and_where_a_long_one_ends(monkeypatch, seed):
    """upgrade.adjust's first round (Huber's loss) converges linearly: under Ceres's 1e-6 it runs
    on (on real rings to its cap) for gains far below the noise. By default it stops at
    ROBUST_ROUND_STOP, sooner, and the adjustment ends where one whose first round runs to 300
    iterations under Ceres's tolerance ends: rotations within 0.02 degrees (their error against
    the truth is about 0.2), the focal length within 0.1%, the observations kept within 1%."""
    start, view, track, pixels, truth = _ring_with_mismatched_tracks(seed)
    rounds = []
    solve = schur.solve
    monkeypatch.setattr(schur, "solve", lambda *a, **k: rounds.append(solve(*a, **k)) or rounds[-1])
    quick, kept, _ = upgrade.adjust(start, view, track, pixels, 2.0, model="simple")
    first_quick = rounds[0][4]
    rounds.clear()
    long, long_kept, _ = upgrade.adjust(start, view, track, pixels, 2.0, model="simple", max_iterations=300,
                                        robust_stop=schur.CERES)
    assert first_quick < rounds[0][4] < 300
    assert _degrees(quick.rotations, long.rotations) < 0.02 < 0.1 < _degrees(long.rotations, truth)
    assert abs(quick.K[0, 0] / long.K[0, 0] - 1) < 1e-3
    assert np.count_nonzero(kept != long_kept) < 0.01 * long_kept.sum()


@pytest.mark.parametrize("max_iterations", [1, 200])
def test_the_adjustment_says_whether_a_round_used_its_whole_iteration_cap(max_iterations):
    # upgrade.adjust's "capped" is what the depth-reversal check states of its twin (mirror_capped):
    # a round that used all its iterations may have stopped short of its minimum. One iteration
    # cannot meet the function tolerance from a start this far off; 200 end by the rule.
    K, R, t, X, view, track, pixels = _scene(noise_px=0.5)
    metric = upgrade.Metric(K, list(R), list(t), X, [], False)
    _, _, figures = upgrade.adjust(metric, view, track, pixels, threshold_px=5.0, max_iterations=max_iterations,
                                   model="fixed")
    assert len(figures["iterations"]) == 2 and all(1 <= n <= max_iterations for n in figures["iterations"])
    assert figures["capped"] is (max_iterations == 1)
