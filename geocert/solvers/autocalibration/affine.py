"""The affine upgrade: the plane at infinity minimising the modulus constraints over every plane
chirality allows, to certified global optimality (thesis 6.5; branch on v only, 3 dimensions)."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from geocert.formulations.autocalibration import affine_relaxation
from geocert.solvers.autocalibration import cuts
from geocert.formulations.autocalibration import frames
from geocert.core.bnb import BnbOptions, Box, branch_and_bound

MAX_RELAXATION_ROWS = 64  # chirality rows beyond this: only the hull's (the others are redundant)


@dataclass
class Region:
    """One orientation's polytope of planes, its frame and box, and the search over it."""

    delta: float
    G: np.ndarray
    rows: list[int]  # chirality rows used in the relaxation
    lo: np.ndarray
    hi: np.ndarray
    basis: list[list[int]]  # per side (v0 low, v0 high, v1 low, ...): three rows proving it
    setup: affine_relaxation.AffineSetup
    leaves: list = field(default_factory=list)
    status: str = "optimal"
    nodes: int = 0


@dataclass
class AffineStage:
    status: str  # optimal, node_limit, time_limit, cancelled, not_certified, failed
    certified: bool
    plane: np.ndarray | None  # reference-frame plane (p, 1)
    cost: float
    lower_bound: float
    nodes: int
    regions: list[Region]
    excluded: list[dict]  # orientations with no quasi-affine plane, with their exact proof
    reason: str | None = None


def relaxation_rows(a: np.ndarray, b: np.ndarray, always: int) -> list[int]:
    if len(a) <= MAX_RELAXATION_ROWS:
        return list(range(len(a)))
    from scipy.spatial import ConvexHull

    try:
        vertices = set(int(i) for i in ConvexHull(a / b[:, None]).vertices)
    except Exception:
        return list(range(len(a)))
    vertices.add(always)
    return sorted(vertices)


class AffineProblem(cuts.BoxSearch):
    """The branch-and-bound problem of one region (geocert.core.bnb.BranchProblem)."""

    def __init__(self, region: Region, all_a: np.ndarray, all_b: np.ndarray, record: bool):
        super().__init__(region.lo, region.hi, record)
        self.region = region
        self.all_a, self.all_b = all_a, all_b

    def root_box(self) -> Box:
        return Box(self.region.lo.copy(), self.region.hi.copy())

    def in_domain(self, v: np.ndarray) -> bool:
        return bool(np.all(self.all_a @ v + self.all_b >= 0))

    def objective(self, v: np.ndarray) -> float:
        if not self.in_domain(v):
            return math.inf
        return affine_relaxation.cost(self.region.setup, v)

    def improve(self, v: np.ndarray) -> tuple[np.ndarray, float]:
        setup = self.region.setup
        start = self.objective(v)

        def residuals(w):
            h = setup.M @ np.append(w, 1.0)
            if not h[3] > 0:
                return np.full(len(setup.coef), 1e6)
            return frames.modulus_residuals(setup.coef, h[:3] / h[3])

        try:
            fit = least_squares(residuals, v, bounds=(self.region.lo, self.region.hi), method="trf",
                                x_scale="jac", max_nfev=50, xtol=1e-14, ftol=1e-14, gtol=1e-14)
            value = self.objective(fit.x)
            if value < start:
                return fit.x, value
        except ValueError:
            pass
        return v, start

    def build(self, lo: np.ndarray, hi: np.ndarray, cap: float, cap_row: bool = False):
        return affine_relaxation.build(self.region.setup, lo, hi, cap, cap_row)

    @property
    def unit(self) -> float:
        return self.region.setup.unit


def regions_of(norm: frames.Normalised, coef: np.ndarray) -> tuple[list[Region], list[dict], str | None]:
    """Each orientation's region (frame, box proved side by side), or its exclusion proof."""
    regions, excluded = [], []
    for delta in (1.0, -1.0):
        rows = frames.chirality_rows(norm, delta)
        plane = frames.interior_plane(rows)
        if plane is None:
            chosen = frames.gordan_rows(rows)
            if chosen is None:
                return [], [], (f"the orientation {delta:+g} has no strictly quasi-affine plane, but that could "
                                "not be proved exactly (points on the boundary of chirality?)")
            excluded.append({"delta": delta, "rows": chosen})
            continue
        G = frames.centred_frame(rows, plane)
        a, b = frames.frame_rows(G, rows)
        sides = [frames.box_side(a, b, k, upper) for k in range(3) for upper in (False, True)]
        if any(side is None for side in sides):
            return [], [], ("chirality does not bound the plane at infinity (give the reconstruction's points, "
                            "or more cameras in general position)")
        lo = np.array([sides[2 * k][0] for k in range(3)])
        hi = np.array([sides[2 * k + 1][0] for k in range(3)])
        reference_row = (0 if norm.points is None else len(norm.points)) + norm.reference
        used = relaxation_rows(a, b, reference_row)
        setup = affine_relaxation.AffineSetup(coef, frames.plane_map(G, delta), a[used], b[used])
        regions.append(Region(delta, G, used, lo, hi, [side[1] for side in sides], setup))
    if not regions:
        return [], excluded, ("no plane at infinity is consistent with chirality (no quasi-affine frame); the cameras' "
                                "signs may not be oriented: orient the reconstruction with its points first "
                                "(POST /v1/orient, docs/kinds.md, \"Camera signs\")")
    return regions, excluded, None


def solve_affine(norm: frames.Normalised, bnb: BnbOptions, record: bool, callback=None) -> AffineStage:
    began = time.perf_counter()  # the stage's clock covers its set-up and first fits too
    coef, _ = frames.modulus_coefficients(norm.cameras, norm.reference)
    regions, excluded, reason = regions_of(norm, coef)
    if reason is not None:
        return AffineStage("failed", False, None, math.inf, -math.inf, 0, [], excluded, reason)
    best_v, best_region, upper = None, None, math.inf
    problems = []
    for region in regions:
        rows = frames.chirality_rows(norm, region.delta)
        all_a, all_b = frames.frame_rows(region.G, rows)
        problem = AffineProblem(region, all_a, all_b, record)
        problem.deadline = began + bnb.time_limit_s
        problems.append(problem)
        centre = np.zeros(3) if problem.in_domain(np.zeros(3)) else 0.5 * (region.lo + region.hi)
        v, value = problem.improve(centre)
        if value < upper:
            best_v, best_region, upper = v, region, value
    unit = 1.0 / upper if 0 < upper < math.inf else 1.0
    for problem in problems:
        problem.region.setup.unit = unit
    lower_bounds, nodes, statuses = [], 0, []
    for problem in problems:
        region = problem.region
        start = best_v if best_region is region else np.zeros(3)
        leaves: list | None = [] if record else None
        # One budget for the stage: each region gets what the ones before it left.
        budget = dataclasses.replace(bnb, max_nodes=max(1, bnb.max_nodes - nodes),
                                     time_limit_s=max(1e-3, bnb.time_limit_s - (time.perf_counter() - began)))
        result = branch_and_bound(problem, start, upper, budget, callback,
                                  trivial_lower_bound=0.0, leaves=leaves)
        region.leaves = leaves or []
        region.status, region.nodes = result.status, result.nodes
        nodes += result.nodes
        statuses.append(result.status)
        lower_bounds.append(result.lower_bound)
        if result.upper_bound < upper:
            best_v, best_region, upper = result.candidate, region, result.upper_bound
    lower = min(min(lower_bounds), upper)
    tolerance = max(bnb.abs_gap, bnb.rel_gap * abs(upper))
    certified = all(s == "optimal" for s in statuses) and upper - lower <= tolerance and math.isfinite(upper)
    status = "optimal" if certified else next((s for s in statuses if s != "optimal"), "not_certified")
    h = best_region.setup.M @ np.append(best_v, 1.0) if best_region is not None else None
    plane = None if h is None else np.append(h[:3] / h[3], 1.0)
    return AffineStage(status, certified, plane, upper, lower, nodes, regions, excluded)
