"""RANSAC around the line solvers (thesis 9.3.6, 9.5): minimal samples (2 or 3 lines), every
candidate motion scored by its lines' pixel errors (MSAC: the sum of min(error^2, threshold^2)),
the sample count adapted to the inlier ratio seen (``confidence``). Each new best hypothesis is
locally optimised (LO-RANSAC, Chum et al. 2003): the algebraic equations of its inliers relinearised
about it (the incremental solver started at its rotation) while that lowers the cost; with a 7.4 cm
baseline a 2-line sample's motion is rarely better than a few degrees under 0.5 px noise, and this
step is what turns it into the inliers' motion. Lines the stereo pair cannot fix in 3D (in or near an epipolar plane) are never
sampled; samples of nearly parallel lines are skipped (they do not fix the motion)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from geocert.core.declared_options import DeclaredRanges, option
from geocert.solvers.lines import incremental
from geocert.solvers.lines.geometry import LineSet, cross, directions_and_points, line_errors
from geocert.solvers.lines.results import Degenerate, Motion


@dataclass
class RansacOptions:
    # a line is an inlier when the RMS of its 8 endpoint transfer distances is within this
    threshold_px: float = option(2.0, gt=0, le=1000, description=(
        "inlier: RMS of a line's 8 endpoint transfer distances (pixels)"))
    confidence: float = option(0.99, gt=0, lt=1)
    max_iterations: int = option(200, ge=1, le=100_000)
    # sin of the angle between a line's two stereo planes, below: not sampled
    min_conditioning: float = option(0.002, ge=0, le=1, description=(
        "lines whose stereo planes meet at a smaller sine are not sampled"))
    # samples whose lines are all within this of one direction are skipped
    min_sample_angle_deg: float = option(5.0, ge=0, le=90)
    seed: int | None = option(0, description="sampling seed (null: fresh randomness)")  # reproducible sampling
    # fewer inliers than this: the pair fails (its motion is not trusted)
    min_inliers: int = option(6, ge=2, le=10_000, description=(
        "a pair with fewer inliers fails (its motion is not trusted)"))
    # rounds of refitting a new best hypothesis on its inliers (0: none)
    local_optimisation: int = option(3, ge=0, le=20, description=(
        "rounds of refitting each new best sample on its inliers"))

    OPTION_RANGES = DeclaredRanges()


@dataclass
class RansacResult:
    motion: Motion | None
    inliers: np.ndarray  # indices
    iterations: int
    degenerate: np.ndarray  # indices of the lines never sampled (not fixed by the stereo pair)
    reason: str | None = None


def required_iterations(inlier_ratio: float, sample_size: int, confidence: float) -> float:
    good = inlier_ratio ** sample_size
    if good >= 1.0:
        return 0.0
    if good <= 0.0:
        return math.inf
    return math.log(1 - confidence) / math.log(1 - good)


def _spread(directions: np.ndarray) -> float:
    """The sine of the largest angle between the sample's line directions and the first's."""
    return float(np.linalg.norm(cross(directions[0], directions[1:]), axis=1).max())


def ransac(lines: LineSet, solver: Callable[[LineSet], list[Motion]], sample_size: int,
           options: RansacOptions, should_stop: Callable[[], bool] | None = None) -> RansacResult:
    n = len(lines)
    usable = np.flatnonzero(lines.conditioning.min(axis=1) >= options.min_conditioning)
    degenerate = np.setdiff1d(np.arange(n), usable)
    if len(usable) < sample_size:
        return RansacResult(None, np.zeros(0, int), 0, degenerate,
                            f"{len(usable)} of {n} lines are fixed in 3D by the stereo pair (the rest lie in or "
                            f"near an epipolar plane: lines through the baseline); the solver needs {sample_size}")
    directions = directions_and_points(lines.planes_a)[0]
    rng = np.random.default_rng(options.seed)
    threshold2 = options.threshold_px ** 2
    min_sine = math.sin(math.radians(options.min_sample_angle_deg))
    best_cost, best_motion, best_inliers = math.inf, None, np.zeros(0, int)

    def score(motion: Motion) -> tuple[float, np.ndarray]:
        errors = line_errors(lines, motion.R, motion.t)
        errors[degenerate] = np.inf
        return float(np.minimum(errors * errors, threshold2).sum()), np.flatnonzero(errors <= options.threshold_px)

    needed = float(options.max_iterations)
    iterations = skipped = 0

    def local_optimisation() -> None:
        nonlocal best_cost, best_motion, best_inliers
        for _ in range(options.local_optimisation):
            if len(best_inliers) < 3:
                break
            try:
                motion = incremental.solve(lines.subset(best_inliers), start=best_motion.R)[0]
            except (Degenerate, np.linalg.LinAlgError):
                break
            cost, inliers = score(motion)
            if not cost < best_cost:
                break
            best_cost, best_motion, best_inliers = cost, motion, inliers

    while iterations < min(needed, options.max_iterations):
        if should_stop is not None and should_stop():
            break
        iterations += 1
        sample = rng.choice(usable, sample_size, replace=False)
        if _spread(directions[sample]) < min_sine:
            skipped += 1
            continue
        try:
            candidates = solver(lines.subset(sample))
        except (Degenerate, np.linalg.LinAlgError):
            skipped += 1
            continue
        improved = False
        for motion in candidates:
            cost, inliers = score(motion)
            if cost < best_cost:
                best_cost, best_motion, best_inliers, improved = cost, motion, inliers, True
        if improved:
            local_optimisation()
            needed = required_iterations(len(best_inliers) / len(usable), sample_size, options.confidence)
    if best_motion is None:
        return RansacResult(None, np.zeros(0, int), iterations, degenerate,
                            f"no sample of {sample_size} lines gave a motion ({skipped} degenerate: parallel "
                            "lines, or lines the stereo pair does not fix)")
    # Refit on the inliers; kept only when it is no worse than the best sample's motion.
    if len(best_inliers) > sample_size:
        try:
            for motion in solver(lines.subset(best_inliers)):
                cost, inliers = score(motion)
                if cost <= best_cost:
                    best_cost, best_motion, best_inliers = cost, motion, inliers
        except (Degenerate, np.linalg.LinAlgError):
            pass
    return RansacResult(best_motion, best_inliers, iterations, degenerate)
