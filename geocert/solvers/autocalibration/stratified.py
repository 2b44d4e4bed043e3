"""Stratified autocalibration end to end (thesis chapter 6): the affine stage, then the metric
stage with the plane it found, the thesis's linear baseline beside it, and the metric
reconstruction. Proofs are recorded when a full certificate is asked for."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from geocert.solvers.autocalibration import metric
from geocert.solvers.autocalibration import affine
from geocert.formulations.autocalibration import metric_relaxation
from geocert.formulations.autocalibration.problem import (AutocalibrationOptions, Problem, StageProgress, bnb_options,
                                                     plane_from_input, plane_in_input, stage_callback,
                                                     upper_triangular_root)
from geocert.core.bnb import asks_to_stop


@dataclass
class Stratified:
    problem: Problem
    affine: affine.AffineStage
    affine_s: float
    metric: metric.MetricStage | None
    metric_s: float
    baseline: dict | None
    K_unit: np.ndarray | None  # preconditioned calibration (K0^-1 K)
    p: np.ndarray | None = None  # the plane the metric stage used (the affine answer as returned)


def announce(callback, stage: str, upper: float = math.inf) -> bool:
    """Progress at a stage's start (a search that certifies at its root reports nothing else)."""
    return asks_to_stop(callback, StageProgress(0, 0, -math.inf, upper, math.inf, math.inf, 0.0, stage=stage))


def solve(problem: Problem, options: AutocalibrationOptions, callback=None) -> Stratified:
    record = options.certificate == "full"
    if announce(callback, "affine"):
        stage = affine.AffineStage("cancelled", False, None, math.inf, -math.inf, 0, [], [], "cancelled")
        return Stratified(problem, stage, 0.0, None, 0.0, None, None)
    start = time.perf_counter()
    stage = affine.solve_affine(problem.norm, bnb_options(options, options.rel_gap), record,
                                stage_callback(callback, "affine"))
    affine_s = time.perf_counter() - start
    # The plane as returned (in the input frame): what the metric stage starts from and what the
    # affine stage is judged at, so that what a verifier reads back is exactly what was solved.
    # Every way out below keeps it (a job cancelled keeps the stage it finished).
    p = None if stage.plane is None else plane_from_input(problem, plane_in_input(problem, stage.plane[:3]))
    if p is None or stage.status == "cancelled":  # a cancelled stage keeps the plane it had
        return Stratified(problem, stage, affine_s, None, 0.0, None, None, p)
    if announce(callback, "metric"):
        cancelled = metric.MetricStage("cancelled", False, None, math.inf, -math.inf, 0, np.zeros(5), np.zeros(5),
                                       reason="the job was cancelled")
        return Stratified(problem, stage, affine_s, cancelled, 0.0, None, None, p)
    start = time.perf_counter()
    baseline = None
    try:
        setup = metric.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
        lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
        if not np.all(setup.q_lower > 0):
            raise ValueError("a view's scale is not bounded away from 0 over the intrinsics ranges")
        # the linear estimate exists whenever the metric stage can be set up (what the verifier
        # recomputes), whether or not its search then succeeds
        w, psd = metric.linear_baseline(setup)
        baseline = {"w": w, "psd": psd, "cost": metric_relaxation.cost(setup, w)}
        result = metric.solve_metric(setup, lo, hi, bnb_options(options, options.metric_rel_gap), record,
                                     stage_callback(callback, "metric"))
    except (ValueError, np.linalg.LinAlgError) as exc:
        result = metric.MetricStage("failed", False, None, math.inf, -math.inf, 0, np.zeros(5), np.zeros(5),
                                    reason=str(exc))
        setup = None
    metric_s = time.perf_counter() - start
    K_unit = None
    if result.w is not None:
        K_unit = upper_triangular_root(metric_relaxation.omega_of(result.w))
    return Stratified(problem, stage, affine_s, result, metric_s, baseline, K_unit, p)
