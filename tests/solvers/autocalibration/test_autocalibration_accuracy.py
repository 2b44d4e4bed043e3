"""Stratified autocalibration against many-start local minimisation of the same costs (issue 12):
on seeded synthetic scenes with noise, each certified stage's cost is never above what 50 random
starts of scipy's least_squares find, and its lower bound is never above any end they reach in
the stage's domain."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.solvers.autocalibration import metric, scenes, stratified
from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import metric_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem

STARTS = 50
SCENES = [(5, 0.2, 3), (10, 0.1, 4), (10, 0.5, 11)]  # views, noise (% of the image side), seed


def affine_ends(problem, regions, rng):
    """The modulus cost over p from starts uniform in the solver's chirality boxes: (cost, allowed)."""
    coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
    ends = []
    while len(ends) < STARTS:
        region = regions[rng.integers(len(regions))]
        h = region.setup.M @ np.append(rng.uniform(region.lo, region.hi), 1.0)
        if not (h[3] > 0 and autocalibration_problem.allowed_by_chirality(problem, h[:3] / h[3])):
            continue
        fit = frames_fit(coef, h[:3] / h[3])
        ends.append((autocalibration_problem.affine_cost(problem, fit),
                     autocalibration_problem.allowed_by_chirality(problem, fit)))
    return ends


def frames_fit(coef, p0):
    from scipy.optimize import least_squares

    return least_squares(lambda p: frames.modulus_residuals(coef, p), p0, method="lm", xtol=1e-15, ftol=1e-15,
                         gtol=1e-15, max_nfev=2000).x


def metric_ends(problem, p, rng):
    """The metric cost of omega's five entries, parametrised by K = [[f, s, u], [0, aspect f, v],
    [0, 0, 1]] within the intrinsics ranges (so every end is in the stage's domain), from starts
    uniform there: (cost, True)."""
    from scipy.optimize import least_squares

    setup = metric.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
    names = ("focal", "aspect", "skew", "u", "v")
    lo = np.array([problem.unit_ranges[n][0] for n in names], float)
    hi = np.array([problem.unit_ranges[n][1] for n in names], float)

    def w_of(k):
        f, aspect, s, u, v = k
        K = np.array([[f, s, u], [0.0, aspect * f, v], [0.0, 0.0, 1.0]])
        omega = K @ K.T
        return np.array([omega[a, b] for a, b in metric_relaxation.ENTRIES])

    ends = []
    for _ in range(STARTS):
        fit = least_squares(lambda k: metric_relaxation.residuals(setup, w_of(k)), rng.uniform(lo, hi), bounds=(lo, hi),
                            method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
        ends.append((metric_relaxation.cost(setup, w_of(fit.x)), True))
    return ends


def check(stage, ends, rel_gap):
    inside = [c for c, ok in ends if ok]
    assert inside, "no local minimisation ended in the stage's domain"
    best = min(inside)
    slack = 1e-9 * abs(stage.cost) + 1e-12
    # a lower bound is a claim whether or not the stage finished
    assert all(stage.lower_bound <= c + slack for c in inside), (stage.lower_bound, best)
    if stage.certified:
        assert stage.cost <= best + max(rel_gap * stage.cost, slack), (stage.cost, best)
    return stage.certified


@pytest.mark.slow
@pytest.mark.parametrize("views,noise,seed", SCENES)
def test_certified_stages_against_fifty_local_starts(views, noise, seed):
    scene = scenes.make_scene(views, noise, seed=seed)
    problem = autocalibration_problem.prepare(scene.cameras, scene.points, scene.image_size, {})
    result = stratified.solve(problem, autocalibration_problem.AutocalibrationOptions(
        rel_gap=1e-5, metric_rel_gap=1e-4, time_limit_s=60))
    rng = np.random.default_rng(seed)
    assert check(result.affine, affine_ends(problem, result.affine.regions, rng), 1e-5), result.affine.status
    assert result.metric is not None and result.metric.w is not None
    check(result.metric, metric_ends(problem, result.p, rng), 1e-4)
