"""Certified N-view triangulation under the (L2,L2), (L2,L1) and (L1,L1) norms (thesis chapter 5).

Each track is a fractional program ``sum_i f_i(X) / g_i(X)`` (numerator convex, depth affine).
The search space is a projective chart where a reference camera's depth is 1, so that camera's
term is convex and points at infinity are ordinary points (inverse depth 0). Boxes live on three
well-conditioned depth functionals; the lower bound on a box is one SOCP with the convex envelope
of ``t/s`` per view (see ALGORITHMS.md section 2). Costs are scaled so the incumbent costs 1.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.optimize

from .bnb import BnbOptions, Box, BoxBound, BoxStatus, Progress, branch_and_bound
from .conic import ConeSpec, ConicStatus, ReusableConicProgram, solve_conic
from .geometry import InputError, norm_cost

NORMS = ("L2L2", "L2L1", "L1L1")
_EPS_DEPTH = 1e-12
_MAX_SCALE = 1e3


@dataclass
class TriangulationOptions:
    norm: str = "L2L2"
    rel_gap: float = 1e-3
    # In the cost's units: squared pixels (L2L2) or pixels. Below about 1e-7 the conic solves
    # cannot resolve the bound (measured on a Dinosaur track whose optimum is 1e-6 px).
    abs_gap: float = 1e-7
    max_nodes: int = 2000
    time_limit_s: float = 30.0
    max_residual: float | None = None  # pixels; narrows the certificate's scope when given

    def check(self) -> None:
        if self.norm not in NORMS:
            raise InputError("options/norm", f"must be one of {', '.join(NORMS)}")
        for name in ("rel_gap", "abs_gap", "time_limit_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"options/{name}", "must be a finite number >= 0")
        if self.max_nodes < 1:
            raise InputError("options/max_nodes", "must be at least 1")
        if self.max_residual is not None and not (math.isfinite(self.max_residual) and self.max_residual > 0):
            raise InputError("options/max_residual", "must be a finite number > 0")


@dataclass
class Certificate:
    scope: str
    reference_view: int  # index into the track's views
    # Root region: lower <= (F X) / (d . X) <= upper for X in the caller's 3D frame, with
    # d . X > 0 exactly when X is in front of the reference view.
    functionals: list[list[float]]
    denominator: list[float]
    lower: list[float]
    upper: list[float]
    tolerance: float
    tolerance_met: bool
    leaves: int


@dataclass
class TrackResult:
    status: str  # optimal, node_limit, time_limit, cancelled, not_certified, infeasible, degenerate
    certified: bool
    point: list[float] | None = None  # [x, y, z], or a homogeneous 4-vector when at infinity
    at_infinity: bool = False
    cost: float | None = None
    lower_bound: float | None = None
    gap: float | None = None
    nodes: int = 0
    elapsed_s: float = 0.0
    reason: str | None = None
    certificate: Certificate | None = None
    residuals: list[list[float]] = field(default_factory=list)


class _Chart:
    """Per-track data in chart coordinates y (X = T [y; 1]) with image residuals scaled by ``scale``.

    View i: numerator rows ``num[i] @ [y, 1]`` (2,), depth ``den[i] @ [y, 1]``. Views whose depth
    is constant in the chart ("exact" views, the reference among them) have den = e4 after scaling.
    """

    def __init__(self, cameras: np.ndarray, points: np.ndarray, reference: int):
        self.reference = reference
        frame = _camera_frame(cameras)
        cameras = cameras @ frame
        cameras = cameras / np.linalg.norm(cameras[:, 2, :3], axis=1)[:, None, None]
        depth_row = cameras[reference, 2]
        _, _, vt = np.linalg.svd(depth_row[None, :])
        self.T = np.column_stack([vt[1], vt[2], vt[3], depth_row / (depth_row @ depth_row)])
        shifted = cameras.copy()
        shifted[:, 0] -= points[:, 0:1] * cameras[:, 2]
        shifted[:, 1] -= points[:, 1:2] * cameras[:, 2]
        M = shifted @ self.T  # (k, 3, 4)
        self.T = frame @ self.T  # from chart coordinates to the caller's frame
        grad = np.linalg.norm(M[:, 2, :3], axis=1)
        self.exact = grad <= 1e-9 * np.linalg.norm(M[:, 2], axis=1)
        self.exact[reference] = True
        norm = np.where(self.exact, M[:, 2, 3], grad)
        if np.any(self.exact & (norm <= 0)):
            self.constant_depth_behind = True
            norm = np.where(norm == 0, 1.0, np.abs(norm))
        else:
            self.constant_depth_behind = False
        M = M / norm[:, None, None]
        self.num = M[:, :2, :].copy()
        self.den = M[:, 2, :].copy()
        self.den[self.exact] = np.array([0.0, 0.0, 0.0, 1.0])
        self.x4 = self.T[3]  # last homogeneous coordinate, >= 0 in the domain
        self.scale = 1.0

    def rescale(self, factor: float) -> None:
        self.num *= factor
        self.scale *= factor

    def homogeneous(self, y: np.ndarray) -> np.ndarray:
        return self.T @ np.append(y, 1.0)

    def to_chart(self, X: np.ndarray) -> np.ndarray | None:
        Y = np.linalg.solve(self.T, X)
        if Y[3] <= 0:
            return None
        return Y[:3] / Y[3]

    def cost(self, y: np.ndarray, norm: str) -> float:
        Y = np.append(y, 1.0)
        g = self.den @ Y
        if np.any(g <= 0) or self.x4 @ Y < -1e-12 * np.linalg.norm(self.x4) * np.linalg.norm(Y):
            return math.inf
        return norm_cost((self.num @ Y) / g[:, None], norm)

    def residual_vector(self, y: np.ndarray) -> np.ndarray:
        Y = np.append(y, 1.0)
        return ((self.num @ Y) / (self.den @ Y)[:, None]).ravel()

    def residual_jacobian(self, y: np.ndarray) -> np.ndarray:
        Y = np.append(y, 1.0)
        n, g = self.num @ Y, self.den @ Y  # (k, 2), (k,)
        jac = self.num[:, :, :3] / g[:, None, None] - n[:, :, None] * self.den[:, None, :3] / (g**2)[:, None, None]
        return jac.reshape(-1, 3)


def camera_centres(cameras: np.ndarray) -> np.ndarray:
    """Null vectors of the (k, 3, 4) cameras, signed so that the last coordinate is not negative."""
    centres = np.linalg.svd(cameras)[2][:, -1, :]
    return centres * np.where(centres[:, 3:4] < 0, -1.0, 1.0)


def _camera_frame(cameras: np.ndarray) -> np.ndarray:
    """A 4x4 similarity H (X = H X') centring the camera centres with unit mean distance.

    Only conditioning: the problem is the same in any frame, and H keeps the last coordinate.
    """
    centres = camera_centres(cameras)
    finite = np.abs(centres[:, 3]) > 1e-9 * np.linalg.norm(centres, axis=1)
    H = np.eye(4)
    if np.any(finite):
        euclid = centres[finite, :3] / centres[finite, 3:4]
        middle = euclid.mean(axis=0)
        spread = float(np.mean(np.linalg.norm(euclid - middle, axis=1)))
        if not spread > 0:
            spread = 1.0
        H[:3, :3] *= spread
        H[:3, 3] = middle
    return H


def gamma_for(upper_bound: float, norm: str) -> float:
    """Largest single residual (2-norm) a point costing less than ``upper_bound`` can have."""
    return math.sqrt(upper_bound) if norm == "L2L2" else upper_bound


def _choose_reference(cameras: np.ndarray, points: np.ndarray) -> int:
    """The camera whose centre projects farthest from the other views' observations.

    A centre inside another view's residual cone makes the chart's region unbounded.
    """
    centres = camera_centres(cameras)
    proj = np.einsum("jab,rb->rja", cameras, centres)  # centre r seen by camera j
    depth = proj[:, :, 2]
    safe = np.where(depth > 1e-12 * np.linalg.norm(proj, axis=2), depth, np.nan)
    distance = np.linalg.norm(proj[:, :, :2] / safe[:, :, None] - points[None], axis=2)
    # Behind camera j (or at infinity) is outside its cone: as good as infinitely far.
    distance = np.where(np.isnan(distance), np.inf, distance)
    np.fill_diagonal(distance, np.inf)
    return int(np.argmax(distance.min(axis=1)))


def _branch_directions(chart: _Chart) -> np.ndarray:
    """Three unit rows: the best-conditioned depth gradients, completed orthogonally."""
    candidates = [chart.den[i, :3] for i in np.flatnonzero(~chart.exact)]
    chosen: list[np.ndarray] = []
    basis: list[np.ndarray] = []
    while len(chosen) < 3 and candidates:
        residuals = [c - sum((c @ b) * b for b in basis) for c in candidates]
        norms = [np.linalg.norm(r) for r in residuals]
        k = int(np.argmax(norms))
        if norms[k] < 0.25:
            break
        chosen.append(candidates.pop(k))
        basis.append(residuals[k] / norms[k])
    for e in np.eye(3):
        if len(basis) == 3:
            break
        r = e - sum((e @ b) * b for b in basis)
        if np.linalg.norm(r) > 0.5:
            basis.append(r / np.linalg.norm(r))
            chosen.append(basis[-1])
    return np.array(chosen)


class TrackProblem:
    """The branch-and-bound problem of one track, in scaled chart coordinates."""

    def __init__(self, chart: _Chart, norm: str, user_gamma: float | None, B: np.ndarray, root: Box):
        self.chart = chart
        self.norm = norm
        self.user_gamma = user_gamma
        self.B = B
        self.B_inv = np.linalg.inv(B)
        self.root = root
        self.env = np.flatnonzero(~chart.exact)  # views bounded by the envelope
        self.exact = np.flatnonzero(chart.exact)
        # Depth of envelope view j as a function of z = B y: coef[j] @ z + offset[j].
        self.coef = chart.den[self.env, :3] @ self.B_inv
        self.offset = chart.den[self.env, 3]
        self._program = ReusableConicProgram()

    # --- BranchProblem interface -------------------------------------------------------------
    def root_box(self) -> Box:
        return self.root

    def objective(self, y: np.ndarray) -> float:
        return self.chart.cost(y, self.norm)

    def improve(self, y: np.ndarray) -> tuple[np.ndarray, float]:
        return local_refine(self.chart, y, self.norm)

    def depth_range(self, box: Box) -> tuple[np.ndarray, np.ndarray]:
        pos, neg = np.clip(self.coef, 0, None), np.clip(self.coef, None, 0)
        low = self.offset + pos @ box.lo + neg @ box.hi
        high = self.offset + pos @ box.hi + neg @ box.lo
        return low, high

    def bound(self, box: Box, upper_bound: float) -> BoxBound:
        low, high = self.depth_range(box)
        if np.any(high <= _EPS_DEPTH):
            return BoxBound(BoxStatus.EMPTY)  # the whole box is behind some camera
        low = np.maximum(low, _EPS_DEPTH)
        high = np.maximum(high, low * (1 + 1e-9) + 1e-15)
        gamma = gamma_for(upper_bound, self.norm) if math.isfinite(upper_bound) else math.inf
        if self.user_gamma is not None:
            gamma = min(gamma, self.user_gamma)
        q, A, b, cones = self._relaxation(box, low, high, gamma)
        result = self._program.solve(q, A, b, cones)
        if result.status is ConicStatus.INFEASIBLE:
            return BoxBound(BoxStatus.EMPTY)
        if result.status is not ConicStatus.OPTIMAL:
            return BoxBound(BoxStatus.UNRESOLVED)
        y = result.x[:3]
        candidate = y if math.isfinite(self.chart.cost(y, self.norm)) else None
        return BoxBound(BoxStatus.BOUNDED, result.lower_bound, candidate, self.B @ y)

    def split(self, box: Box, bound: BoxBound) -> list[Box]:
        width = box.width
        if len(self.env):
            low, _ = self.depth_range(box)
            low = np.maximum(low, _EPS_DEPTH)
            score = width * np.max(np.abs(self.coef) / low[:, None], axis=0)
        else:
            score = width.copy()
        k = int(np.argmax(score))
        cut = 0.5 * (box.lo[k] + box.hi[k])
        if bound.split_hint is not None:
            cut = float(np.clip(bound.split_hint[k], box.lo[k] + 0.1 * width[k], box.hi[k] - 0.1 * width[k]))
        left_hi, right_lo = box.hi.copy(), box.lo.copy()
        left_hi[k], right_lo[k] = cut, cut
        return [Box(box.lo.copy(), left_hi), Box(right_lo, box.hi.copy())]

    # --- the relaxation ----------------------------------------------------------------------
    def _relaxation(self, box: Box, low: np.ndarray, high: np.ndarray, gamma: float):
        """Assemble ``min sum q`` over the box (ALGORITHMS.md section 2) in Clarabel's form.

        Rows are built as expressions ``c + E x`` that must lie in the cone; Clarabel wants
        ``b - A x``, so ``A = -E``. Variables: y (3), then per envelope view t, w, r, then one
        epigraph variable per exact view. Blocks are filled for all views at once.
        """
        chart, norm = self.chart, self.norm
        env, exact = self.env, self.exact
        nE, nX = len(env), len(exact)
        n = 3 + 3 * nE + nX
        t_idx = 3 + np.arange(nE)
        w_idx, r_idx = t_idx + nE, t_idx + 2 * nE
        q_idx = 3 + 3 * nE + np.arange(nX)
        finite_gamma = math.isfinite(gamma)
        u = (gamma**2 if norm == "L2L2" else gamma) * high if finite_gamma else 1e12 * high
        views = np.concatenate([env, exact])
        top_idx = np.concatenate([t_idx, q_idx])  # the variable above each view's numerator
        depth = chart.den[views]  # (V, 4); exact views have depth identically 1
        num0, num1 = chart.num[views, 0], chart.num[views, 1]
        V = len(views)

        blocks_E, blocks_c = [], []

        def block(rows: int) -> tuple[np.ndarray, np.ndarray]:
            E, c = np.zeros((rows, n)), np.zeros(rows)
            blocks_E.append(E)
            blocks_c.append(c)
            return E, c

        # Box on the branching functionals, and the last homogeneous coordinate >= 0.
        E, c = block(7)
        E[0:3, :3], c[0:3] = self.B, -box.lo
        E[3:6, :3], c[3:6] = -self.B, box.hi
        E[6, :3], c[6] = chart.x4[:3], chart.x4[3]
        # Envelope of t/s on [0, u] x [L, U], first cone vacuous since l = 0 (5 rows per view).
        E, c = block(5 * nE)
        rows = 5 * np.arange(nE)
        g = chart.den[env]
        E[rows, w_idx], E[rows, t_idx] = 1.0, -low / u
        E[rows + 1, t_idx], E[rows + 1, w_idx] = high / u, -1.0
        E[rows + 2, :3], E[rows + 2, w_idx], E[rows + 2, t_idx] = g[:, :3], -1.0, low / u
        c[rows + 2] = g[:, 3] - low
        E[rows + 3, :3], E[rows + 3, w_idx], E[rows + 3, t_idx] = -g[:, :3], 1.0, -high / u
        c[rows + 3] = high - g[:, 3]
        E[rows + 4, t_idx], c[rows + 4] = -1.0, u
        socs: list[int] = []
        if norm == "L1L1":  # top >= |n0| + |n1|, and |n0| + |n1| <= gamma * depth
            signs = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]], dtype=float)
            for with_gamma in ([False, True] if finite_gamma else [False]):
                E, c = block(4 * V)
                for k, (s0, s1) in enumerate(signs):
                    rows = 4 * np.arange(V) + k
                    E[rows, :3] = -s0 * num0[:, :3] - s1 * num1[:, :3]
                    c[rows] = -s0 * num0[:, 3] - s1 * num1[:, 3]
                    if with_gamma:
                        E[rows, :3] += gamma * depth[:, :3]
                        c[rows] += gamma * depth[:, 3]
                    else:
                        E[rows, top_idx] = 1.0
        n_lin = sum(len(cb) for cb in blocks_c)
        if norm == "L2L2":  # top * depth >= n0^2 + n1^2
            E, c = block(4 * V)
            rows = 4 * np.arange(V)
            E[rows, top_idx], E[rows, :3], c[rows] = 1.0, depth[:, :3], depth[:, 3]
            E[rows + 1, :3], c[rows + 1] = 2 * num0[:, :3], 2 * num0[:, 3]
            E[rows + 2, :3], c[rows + 2] = 2 * num1[:, :3], 2 * num1[:, 3]
            E[rows + 3, top_idx], E[rows + 3, :3], c[rows + 3] = 1.0, -depth[:, :3], -depth[:, 3]
            socs += [4] * V
        elif norm == "L2L1":  # top >= ||(n0, n1)||
            E, c = block(3 * V)
            rows = 3 * np.arange(V)
            E[rows, top_idx] = 1.0
            E[rows + 1, :3], c[rows + 1] = num0[:, :3], num0[:, 3]
            E[rows + 2, :3], c[rows + 2] = num1[:, :3], num1[:, 3]
            socs += [3] * V
        if finite_gamma and norm != "L1L1":  # every residual of a better point is below gamma
            E, c = block(3 * V)
            rows = 3 * np.arange(V)
            E[rows, :3], c[rows] = gamma * depth[:, :3], gamma * depth[:, 3]
            E[rows + 1, :3], c[rows + 1] = num0[:, :3], num0[:, 3]
            E[rows + 2, :3], c[rows + 2] = num1[:, :3], num1[:, 3]
            socs += [3] * V
        # r * (u w) >= t^2 (the envelope's second cone), written with everything divided by u.
        E, c = block(3 * nE)
        rows = 3 * np.arange(nE)
        E[rows, r_idx], E[rows, w_idx] = 1.0, 1.0 / u
        E[rows + 1, t_idx] = 2.0 / u
        E[rows + 2, r_idx], E[rows + 2, w_idx] = 1.0, -1.0 / u
        socs += [3] * nE

        q = np.zeros(n)
        q[r_idx] = 1.0
        q[q_idx] = 1.0
        return q, -np.vstack(blocks_E), np.concatenate(blocks_c), ConeSpec(nonneg=n_lin, soc=tuple(socs))


def local_refine(chart: _Chart, y: np.ndarray, norm: str) -> tuple[np.ndarray, float]:
    """A short local descent that stays in the domain (never returns a worse or infeasible point)."""
    start_cost = chart.cost(y, norm)
    best_y, best_cost = y, start_cost
    try:
        if norm == "L2L2":
            fit = scipy.optimize.least_squares(
                chart.residual_vector, y, jac=chart.residual_jacobian, method="lm", max_nfev=30)
            trial = fit.x
        else:
            # sum_i sqrt(term_i)^2 is the cost; the square roots make it a least-squares problem.
            # Zero padding: MINPACK's LM needs at least as many residuals as unknowns.
            def terms_and_jacobian(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                r = chart.residual_vector(v).reshape(-1, 2)
                J = chart.residual_jacobian(v).reshape(-1, 2, 3)
                if norm == "L2L1":
                    terms = np.linalg.norm(r, axis=1)
                    dterms = np.einsum("ka,kab->kb", r, J) / np.maximum(terms, 1e-300)[:, None]
                else:
                    terms, dterms = np.abs(r).ravel(), (np.sign(r)[:, :, None] * J).reshape(-1, 3)
                return terms, dterms

            pad = max(0, 3 - (len(chart.num) if norm == "L2L1" else 2 * len(chart.num)))

            def roots(v: np.ndarray) -> np.ndarray:
                return np.concatenate([np.sqrt(terms_and_jacobian(v)[0] + 1e-30), np.zeros(pad)])

            def roots_jacobian(v: np.ndarray) -> np.ndarray:
                terms, dterms = terms_and_jacobian(v)
                return np.vstack([dterms / (2 * np.sqrt(terms + 1e-30))[:, None], np.zeros((pad, 3))])

            trial = scipy.optimize.least_squares(roots, y, jac=roots_jacobian, method="lm", max_nfev=50).x
        trial_cost = chart.cost(trial, norm)
        if trial_cost < best_cost:
            best_y, best_cost = trial, trial_cost
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        pass
    return best_y, best_cost


def _dlt_in_chart(chart: _Chart) -> np.ndarray | None:
    rows = chart.num.reshape(-1, 4) / np.linalg.norm(chart.num.reshape(-1, 4), axis=1, keepdims=True)
    Y = np.linalg.svd(rows)[2][-1]
    if abs(Y[3]) < 1e-14 * np.linalg.norm(Y):
        return None
    return Y[:3] / Y[3]


def _residual_region(chart: _Chart, gamma: float) -> tuple[np.ndarray, np.ndarray, ConeSpec]:
    """Conic data of {y : ||residual_i(y)|| <= gamma for every view, last coordinate >= 0}.

    ``||n_i|| <= gamma * g_i`` also puts the point in front of every camera (g_i >= 0).
    """
    rows = [np.append(chart.x4[:3], chart.x4[3])]
    for view in range(len(chart.num)):
        rows += [gamma * chart.den[view], chart.num[view, 0], chart.num[view, 1]]
    E = np.array(rows)  # each row: coefficients of y, then the constant
    cones = ConeSpec(nonneg=1, soc=(3,) * len(chart.num))
    return -E[:, :3], E[:, 3].copy(), cones


def _front_point(chart: _Chart) -> np.ndarray | None:
    """A point in front of every camera with small max residual (bisection on the L-infinity cost).

    Used only when the DLT point is behind a camera; None when no point is in front of all.
    """
    def feasible(gamma: float) -> np.ndarray | None:
        res = solve_conic(np.zeros(3), *_residual_region(chart, gamma))
        if res.status is ConicStatus.OPTIMAL and math.isfinite(chart.cost(res.x, "L2L2")):
            return res.x
        return None

    hi = 1e7
    best = feasible(hi)
    if best is None:
        return None
    lo = 0.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        y = feasible(mid)
        if y is None:
            lo = mid
        else:
            hi, best = mid, y
        if hi - lo < 1e-3 * hi:
            break
    return best


def _root_region(chart: _Chart, B: np.ndarray, gamma: float) -> tuple[str, Box | None]:
    """Bound B y over {every residual <= gamma, in front of every camera}: six small SOCPs.

    An inaccurate solve is retried with gamma inflated slightly: a larger residual bound still
    gives a region holding every better point, and a different problem often solves cleanly.
    """
    for inflation in (1.0, 1.001, 1.01):
        state, box = _root_region_once(chart, B, gamma * inflation)
        if state != "not_certified":
            return state, box
    return state, box


def _root_region_once(chart: _Chart, B: np.ndarray, gamma: float) -> tuple[str, Box | None]:
    A, b, cones = _residual_region(chart, gamma)
    program = ReusableConicProgram()  # six objectives over one feasible set
    lo, hi = np.zeros(3), np.zeros(3)
    for k in range(3):
        for sign, out in ((1.0, lo), (-1.0, hi)):
            res = program.solve(sign * B[k], A, b, cones)
            if res.status is ConicStatus.UNBOUNDED:
                return "degenerate", None
            if res.status is ConicStatus.INFEASIBLE:
                return "infeasible", None
            if res.status is not ConicStatus.OPTIMAL:
                return "not_certified", None
            out[k] = sign * res.lower_bound  # min(primal, dual): the outer side for both ends
    pad = 1e-7 * (1 + np.abs(lo) + np.abs(hi))
    return "ok", Box(lo - pad, hi + pad)


def prepare_track(cameras: np.ndarray, points: np.ndarray, options: TriangulationOptions) -> "TrackProblem | TrackResult":
    """Chart, incumbent and root region of one track; a TrackResult when it ends before any search.

    The returned problem carries ``incumbent``, ``upper`` (its scaled cost) and ``unit``
    (scaled cost = unit * cost in pixels) for :func:`triangulate`, and for the property tests.
    """
    cameras = np.asarray(cameras, dtype=float)
    points = np.asarray(points, dtype=float)
    norm = options.norm
    chart = _Chart(cameras, points, _choose_reference(cameras, points))
    if chart.constant_depth_behind:
        return TrackResult("infeasible", False, reason="no point is in front of every camera")

    y0 = _dlt_in_chart(chart)
    if y0 is None or not math.isfinite(chart.cost(y0, norm)):
        y0 = _front_point(chart)
        if y0 is None:
            return TrackResult("infeasible", False, reason="no point is in front of every camera")
    y0, _ = local_refine(chart, y0, "L2L2")
    if norm != "L2L2":
        y0, _ = local_refine(chart, y0, norm)
    cost0 = chart.cost(y0, norm)
    if cost0 <= options.abs_gap:  # the incumbent is within tolerance of the trivial bound 0
        return _track_result(chart, cameras, points, y0, norm, "optimal", cost0, 0.0, 0, None)

    # Scale residuals so the incumbent costs 1 (measured: raw costs near 1e-5 cost accuracy), but
    # never by more than _MAX_SCALE: nearly exact data would otherwise make the residual rows of
    # the cones 1e6 times the depth rows, and every conic solve inaccurate.
    factor = min(_MAX_SCALE, 1.0 / math.sqrt(cost0) if norm == "L2L2" else 1.0 / cost0)
    chart.rescale(factor)
    unit = factor**2 if norm == "L2L2" else factor
    upper = chart.cost(y0, norm)
    user_gamma = options.max_residual * factor if options.max_residual is not None else None
    gamma = gamma_for(upper, norm)
    if user_gamma is not None:
        if np.max(np.linalg.norm(chart.residual_vector(y0).reshape(-1, 2), axis=1)) > user_gamma:
            upper = math.inf  # the incumbent lies outside the user's domain
        gamma = min(gamma, user_gamma)

    B = _branch_directions(chart)
    state, root = _root_region(chart, B, gamma)
    if root is None:
        reasons = {
            "degenerate": "the rays are (nearly) parallel: the points within the residual bound form an unbounded set",
            "infeasible": "no point is in front of every camera with every residual within max_residual",
            "not_certified": "the root region's bounds could not be computed accurately",
        }
        if state == "infeasible" and math.isfinite(upper):
            state = "not_certified"  # the incumbent is inside: the solve, not the data, failed
        if not math.isfinite(upper):
            return TrackResult(state, False, reason=reasons[state])
        result = _track_result(chart, cameras, points, y0, norm, state, upper / unit, None, 0, None)
        result.reason = reasons[state]
        return result

    problem = TrackProblem(chart, norm, user_gamma, B, root)
    problem.incumbent, problem.upper, problem.unit = y0, upper, unit
    return problem


def triangulate(
    cameras: np.ndarray,
    points: np.ndarray,
    options: TriangulationOptions | None = None,
    callback: Callable[[Progress], bool | None] | None = None,
) -> TrackResult:
    """Certified global optimum of one track: ``cameras`` (k, 3, 4) of its views, ``points`` (k, 2)."""
    options = options or TriangulationOptions()
    start = time.perf_counter()
    cameras = np.asarray(cameras, dtype=float)
    points = np.asarray(points, dtype=float)
    prepared = prepare_track(cameras, points, options)
    if isinstance(prepared, TrackResult):
        prepared.elapsed_s = time.perf_counter() - start
        return prepared
    problem, unit, chart = prepared, prepared.unit, prepared.chart
    bnb = branch_and_bound(
        problem, problem.incumbent, problem.upper,
        BnbOptions(rel_gap=options.rel_gap, abs_gap=options.abs_gap * unit,
                   max_nodes=options.max_nodes, time_limit_s=options.time_limit_s),
        callback=_unscaled(callback, unit) if callback else None,
    )
    if not math.isfinite(bnb.upper_bound):
        return TrackResult("infeasible", False, nodes=bnb.nodes, elapsed_s=time.perf_counter() - start,
                           reason="no point has every residual within max_residual")
    # Root region in the caller's frame: lower <= (F X) / (d . X) <= upper.
    to_chart = np.linalg.inv(chart.T)
    scope = ("every point in front of every camera" if options.max_residual is None else
             f"every point in front of every camera with every residual <= {options.max_residual} px")
    certificate = Certificate(
        scope, chart.reference, (problem.B @ to_chart[:3]).tolist(), to_chart[3].tolist(),
        problem.root.lo.tolist(), problem.root.hi.tolist(), bnb.tolerance / unit,
        bnb.upper_bound - bnb.lower_bound <= bnb.tolerance, bnb.leaves)
    result = _track_result(chart, cameras, points, bnb.candidate, options.norm, bnb.status,
                           bnb.upper_bound / unit, bnb.lower_bound / unit, bnb.nodes, certificate)
    result.elapsed_s = time.perf_counter() - start
    return result


def _unscaled(callback, unit: float):
    def report(p: Progress):
        return callback(Progress(p.nodes, p.open_boxes, p.lower_bound / unit, p.upper_bound / unit,
                                 p.gap_abs / unit, p.gap_rel, p.elapsed_s))
    return report


def _track_result(chart, cameras, points, y, norm, status, cost, lower, nodes, certificate) -> TrackResult:
    X = chart.homogeneous(y)
    X = X / np.linalg.norm(X)
    at_infinity = abs(X[3]) <= 1e-12
    point = X.tolist() if at_infinity else (X[:3] / X[3]).tolist()
    proj = cameras @ X
    residuals = proj[:, :2] / proj[:, 2:3] - points
    true_cost = norm_cost(residuals, norm)  # recomputed in pixels from the original data
    if lower is not None:
        lower = min(lower, true_cost)
    certified = status == "optimal" and lower is not None
    gap = true_cost - lower if lower is not None else None
    return TrackResult(status=status, certified=certified, point=point, at_infinity=bool(at_infinity),
                       cost=true_cost if cost is not None else None, lower_bound=lower, gap=gap, nodes=nodes,
                       certificate=certificate, residuals=residuals.tolist())
