"""A frame pair, end to end: (matching,) RANSAC around the chosen solver, the optional
refinement; and the trajectory composed from the frame pairs' motions."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from geocert.core.geometry import InputError
from geocert.core.declared_options import option, redeclared
from geocert.formulations.fractional.options import JobLimit, _describe, _within
from geocert.solvers.lines import align, incremental, linear, polynomial
from geocert.solvers.lines.geometry import LineSet, Rig, directions_and_points, in_depth_units, line_set, \
    reprojection_residuals
from geocert.solvers.lines.matching import MatchingOptions, MatchingStopped, four_view_matches
from geocert.solvers.lines.ransac import RansacOptions, ransac
from geocert.solvers.lines.refine import RefineOptions, refine
from geocert.solvers.lines.results import PairEstimate

SOLVERS = {
    "polynomial": (polynomial.solve, polynomial.MINIMUM_LINES),
    "linear": (linear.solve, linear.MINIMUM_LINES),
    "incremental": (incremental.solve, incremental.MINIMUM_LINES),
    "align": (align.solve, align.MINIMUM_LINES),
}


def _nested(cls, value, field_name: str):
    """A nested options dataclass from a dict (the job's JSON), naming a bad member."""
    if isinstance(value, cls):
        return value
    if not isinstance(value, dict):
        raise InputError(field_name, "must be an object")
    types = {f.name: str(f.type) for f in dataclasses.fields(cls)}
    defaults = cls()
    for key, given in value.items():
        if key not in types:
            raise InputError(f"{field_name}/{key}", f"unknown option (known: {', '.join(sorted(types))})")
        default = getattr(defaults, key)
        if isinstance(default, bool):
            if not isinstance(given, bool):
                raise InputError(f"{field_name}/{key}", "must be true or false")
            continue
        if given is None and "None" in types[key]:
            continue
        if isinstance(given, bool) or not isinstance(given, (int, float)):
            raise InputError(f"{field_name}/{key}", "must be a number")
        if isinstance(default, int) and not isinstance(given, int):
            raise InputError(f"{field_name}/{key}", "must be an integer")
        if not math.isfinite(given):
            raise InputError(f"{field_name}/{key}", "must be finite")
    options = cls(**value)
    for key, bounds in getattr(cls, "OPTION_RANGES", {}).items():
        x = getattr(options, key)
        if x is None:
            continue
        if ("gt" in bounds and not x > bounds["gt"]) or ("ge" in bounds and not x >= bounds["ge"]) or \
                ("lt" in bounds and not x < bounds["lt"]) or ("le" in bounds and not x <= bounds["le"]):
            raise InputError(f"{field_name}/{key}", f"must be within {bounds}")
    return options


@dataclass
class StereoLinesOptions(JobLimit):
    """The stereo_lines kind's options. Defaults: the incremental solver (frame-rate motion is
    small; the thesis's Figure 9.5 finds it the most accurate there) on samples of 3 lines (the
    thesis's real-data setting, 9.3.6: 2-line samples are minimal but far more noise-sensitive
    with a narrow baseline), and the refinement (a two-frame bundle adjustment of the inliers:
    on bench/stereo_lines.py's sequence at 0.5 px, a median rotation error of 0.26 degrees
    without it, 0.07 with it; it costs about a third of the frame pair)."""

    solver: str = option("incremental", choices=tuple(SOLVERS))
    # None: the solver's minimum (2; 3 for linear)
    sample_size: int | None = option(3, ge=2, le=10, description=(
        "lines per RANSAC sample (null: the solver's minimum, 2; linear 3)"))
    ransac: RansacOptions = option(default_factory=RansacOptions)
    refine: bool = option(True, description="refine each motion on its inliers (least squares)")
    incremental_iterations: int = option(3, ge=1, le=20, description=(
        "the incremental solver's relinearisations (1: the thesis's)"))
    matching: MatchingOptions = option(default_factory=MatchingOptions)
    # Per frame pair: RANSAC draws no sample after it and the pair keeps its best motion so far.
    time_limit_s: float = option(10.0, gt=0, le=3600, description=(
        "per frame pair: RANSAC draws no sample after it, and the pair keeps its best motion so far (its reason "
        "says so)"))
    job_time_limit_s: float = redeclared(JobLimit, "job_time_limit_s", description=(
        "the job in all: its pairs share this one clock (past it the pair running keeps its best motion so far, "
        "and the pairs not started read time_limit, not started)"))

    def __post_init__(self):
        self.ransac = _nested(RansacOptions, self.ransac, "options/ransac")
        self.matching = _nested(MatchingOptions, self.matching, "options/matching")

    def check(self) -> None:
        if self.solver not in SOLVERS:
            raise InputError("options/solver", f"unknown solver {self.solver!r} (known: {', '.join(SOLVERS)})")
        if not isinstance(self.refine, bool):
            raise InputError("options/refine", "must be true or false")
        ranges = self.OPTION_RANGES
        if self.sample_size is not None and not _within(self.sample_size, ranges["sample_size"]):
            raise InputError("options/sample_size", f"must be {_describe(ranges['sample_size'])}")
        if self.sample_size is not None and self.sample_size < self.minimum_lines:
            raise InputError("options/sample_size", f"the {self.solver} solver needs at least {self.minimum_lines} "
                                                    f"lines per sample, got {self.sample_size}")
        if not _within(self.incremental_iterations, ranges["incremental_iterations"]):
            raise InputError("options/incremental_iterations", f"must be {_describe(ranges['incremental_iterations'])}")
        if not (isinstance(self.time_limit_s, (int, float)) and math.isfinite(self.time_limit_s)
                and _within(self.time_limit_s, ranges["time_limit_s"])):
            raise InputError("options/time_limit_s", f"must be a finite number {_describe(ranges['time_limit_s'])}")
        self.check_job_limit()

    @property
    def minimum_lines(self) -> int:
        return SOLVERS[self.solver][1]

    @property
    def samples(self) -> int:
        return self.sample_size if self.sample_size is not None else self.minimum_lines

    def solver_function(self) -> Callable:
        if self.solver == "incremental":
            inner = incremental.IncrementalOptions(iterations=self.incremental_iterations)
            return lambda lines: incremental.solve(lines, inner)
        return SOLVERS[self.solver][0]


def weak_support(lines: LineSet, inliers: np.ndarray, options: StereoLinesOptions) -> str | None:
    """Why the inliers do not fix the motion, or None: too few of them (``ransac.min_inliers``),
    or all nearly parallel (their directions within ``ransac.min_sample_angle_deg`` of one line:
    the translation along them, and with it much of the motion, is then unobserved)."""
    if len(inliers) < max(options.ransac.min_inliers, options.samples):
        return (f"degenerate: {len(inliers)} inlier lines of {len(lines)}; at least {options.ransac.min_inliers} are "
                "needed to trust the motion (ransac.min_inliers)")
    directions = directions_and_points(lines.planes_a[inliers])[0]
    spread = np.linalg.svd(directions, compute_uv=False)
    if spread[1] < math.tan(math.radians(options.ransac.min_sample_angle_deg)) * spread[0]:
        return f"degenerate: the {len(inliers)} inlier lines are nearly parallel (the motion along them is not fixed)"
    return None


def estimate_motion(lines: LineSet, options: StereoLinesOptions,
                    should_stop: Callable[[], bool] | None = None) -> PairEstimate:
    """The motion of a frame pair from lines matched across its four views (t in the rig's
    units; found in units of the scene's depth: geometry.in_depth_units)."""
    n = len(lines)
    if n:
        lines, unit = in_depth_units(lines)
    if n < options.samples:
        return PairEstimate("failed", lines=n, solver=options.solver,
                            reason=f"{n} lines matched across the four views; the {options.solver} solver's samples "
                                   f"take {options.samples}")
    found = ransac(lines, options.solver_function(), options.samples, options.ransac, should_stop)
    if found.motion is None:
        return PairEstimate("failed", lines=n, iterations=found.iterations, solver=options.solver,
                            reason=found.reason, degenerate=found.degenerate.tolist())
    motion, inliers, refined = found.motion, found.inliers, False
    if options.refine and len(inliers) >= 2:
        motion = refine(lines.subset(inliers), motion, RefineOptions(loss_scale_px=options.ransac.threshold_px))
        refined = True
    # The inliers as the reprojection residuals (all four views, lines triangulated from them) say.
    errors = np.sqrt(np.mean(reprojection_residuals(lines, motion.R, motion.t) ** 2, axis=1))
    errors[found.degenerate] = np.inf
    inliers = np.flatnonzero(errors <= options.ransac.threshold_px)
    rms = float(np.sqrt(np.mean(errors[inliers] ** 2))) if len(inliers) else None
    weak = weak_support(lines, inliers, options)
    if weak is not None:
        return PairEstimate("failed", lines=n, iterations=found.iterations, solver=options.solver, reason=weak,
                            inliers=inliers.tolist(), degenerate=found.degenerate.tolist(), rms_px=rms, refined=refined)
    return PairEstimate("estimate", motion.R, motion.t * unit, inliers.tolist(), n, found.iterations, options.solver,
                        degenerate=found.degenerate.tolist(), rms_px=rms, refined=refined)


def estimate_pair(rig: Rig, frame_a: dict | None, frame_b: dict | None, matches: np.ndarray | None,
                  options: StereoLinesOptions, should_stop: Callable[[], bool] | None = None) -> tuple[PairEstimate, np.ndarray | None, float]:
    """A frame pair from segments (frames: match first) or from matched segments (N, 4, 4).
    Returns the estimate, the four-view indices matched (frames) or None, and the seconds taken."""
    start = time.perf_counter()
    if matches is not None:
        return estimate_motion(line_set(rig, matches), options, should_stop), None, time.perf_counter() - start

    def matched(rotation):
        quads = four_view_matches(rig, frame_a, frame_b, options.matching, rotation, should_stop)
        segments = np.stack([frame_a["left"][quads[:, 0]], frame_a["right"][quads[:, 1]],
                             frame_b["left"][quads[:, 2]], frame_b["right"][quads[:, 3]]], axis=1) \
            if len(quads) else np.zeros((0, 4, 4))
        return quads, line_set(rig, segments)

    try:
        quads, lines = matched(None)
    except MatchingStopped:
        return PairEstimate("failed", solver=options.solver, reason="stopped while matching segments: no lines yet"), \
            None, time.perf_counter() - start
    guided = options.matching.guided
    # Guided, the first estimate only guides the tracker (its rotation warps frame a's segments,
    # and the tracker's window is tens of pixels): no refinement, one round of local optimisation.
    guide = dataclasses.replace(options, refine=False,
                                ransac=dataclasses.replace(options.ransac,
                                                           local_optimisation=min(1, options.ransac.local_optimisation)))
    estimate = estimate_motion(lines, guide if guided else options, should_stop)
    if guided and estimate.status == "estimate" and not (should_stop and should_stop()):
        # Guided matching: the segments tracked again with the rotation found, and the motion
        # estimated again from those matches, from scratch (RANSAC seeded with the first
        # estimate kept much of its bias: 11 degrees of drift round the room against 1.3). Unguided, the tracker's preference for small image
        # motion mistracks nearby parallel segments in the direction of a smaller rotation (12% of
        # the tracks in the room walk of bench/stereo_lines.py, a consistent -0.085 degrees of yaw
        # a pair); guided, about 1%. The first matches' inlier count is no referee: the mistracked
        # lines are often within the threshold.
        try:
            quads_again, lines_again = matched(estimate.R)
        except MatchingStopped:  # the first estimate is the best so far
            return estimate, quads, time.perf_counter() - start
        again = estimate_motion(lines_again, options, should_stop)
        if again.status == "estimate":
            quads, estimate = quads_again, again
    return estimate, quads, time.perf_counter() - start


def compose(motions: list[tuple[np.ndarray, np.ndarray] | None]) -> list[dict | None]:
    """One pose per frame (X_k = R_k X_0 + t_k; frame 0 the identity), with its camera centre in
    frame 0's coordinates; after a frame pair without a motion, the poses are unknown (None)."""
    R, t = np.eye(3), np.zeros(3)
    poses: list[dict | None] = [{"R": R.tolist(), "t": t.tolist(), "center": [0.0, 0.0, 0.0]}]
    lost = False
    for motion in motions:
        if motion is None or lost:
            lost = True
            poses.append(None)
            continue
        R, t = motion[0] @ R, motion[0] @ t + motion[1]
        poses.append({"R": R.tolist(), "t": t.tolist(), "center": (-R.T @ t).tolist()})
    return poses
