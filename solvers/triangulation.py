"""Certified N-view triangulation under the (L2,L2), (L2,L1) and (L1,L1) norms (thesis chapter 5).

Each track is a fractional program ``sum_i f_i(X) / g_i(X)`` (numerator convex, depth affine).
The search space is a projective chart where a reference camera's depth is 1, so that camera's
term is convex and points at infinity are ordinary points (inverse depth 0). Boxes live on three
well-conditioned depth functionals; the lower bound on a box is one SOCP with the convex envelope
of ``t/s`` per view (see ALGORITHMS.md section 2). Costs are scaled so the incumbent costs 1.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .bnb import Progress
from .fractional import NORMS, Certificate, Early, FractionalOptions, FractionalProgram, Reasons, prepare, search
from .geometry import norm_cost



@dataclass
class TriangulationOptions(FractionalOptions):
    """Residuals in pixels; limits per track."""


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


@dataclass
class Chart:
    """A track as a fractional program in chart coordinates y, with X = T [y; 1].

    The reference camera's depth is 1 on the chart, so points at infinity are ordinary points and
    "in front of the reference camera" holds by construction; views whose depth is constant on the
    chart are exact. ``constant_depth_behind``: some view's depth is a non-positive constant.
    """

    program: FractionalProgram
    T: np.ndarray
    reference: int
    constant_depth_behind: bool

    @classmethod
    def build(cls, cameras: np.ndarray, points: np.ndarray, norm: str) -> "Chart":
        reference = _choose_reference(cameras, points)
        frame = _camera_frame(cameras)
        cams = cameras @ frame
        cams = cams / np.linalg.norm(cams[:, 2, :3], axis=1)[:, None, None]
        depth_row = cams[reference, 2]
        _, _, vt = np.linalg.svd(depth_row[None, :])
        T = np.column_stack([vt[1], vt[2], vt[3], depth_row / (depth_row @ depth_row)])
        shifted = cams.copy()  # image coordinates translated to the observation
        shifted[:, 0] -= points[:, 0:1] * cams[:, 2]
        shifted[:, 1] -= points[:, 1:2] * cams[:, 2]
        M = shifted @ T  # (k, 3, 4)
        grad = np.linalg.norm(M[:, 2, :3], axis=1)
        exact = grad <= 1e-9 * np.linalg.norm(M[:, 2], axis=1)
        exact[reference] = True
        scale = np.where(exact, M[:, 2, 3], grad)
        behind = bool(np.any(exact & (scale <= 0)))
        scale = np.where(scale == 0, 1.0, np.abs(scale))
        M = M / scale[:, None, None]
        den = M[:, 2, :].copy()
        den[exact] = np.array([0.0, 0.0, 0.0, 1.0])
        T = frame @ T  # from chart coordinates to the caller's frame
        # The domain also asks for a non-negative last homogeneous coordinate.
        program = FractionalProgram(M[:, :2, :].copy(), den, exact, T[3][None, :].copy(), norm)
        return cls(program, T, reference, behind)

    def dlt(self) -> np.ndarray | None:
        rows = self.program.num.reshape(-1, 4)
        Y = np.linalg.svd(rows / np.linalg.norm(rows, axis=1, keepdims=True))[2][-1]
        if abs(Y[3]) < 1e-14 * np.linalg.norm(Y):
            return None
        return Y[:3] / Y[3]


_REASONS = Reasons(
    no_domain="no point is in front of every camera",
    degenerate="the rays are (nearly) parallel: the points within the residual bound form an unbounded set",
)


def prepare_track(cameras: np.ndarray, points: np.ndarray, options: TriangulationOptions):
    """The track's chart and prepared search (fractional.Prepared), or a TrackResult when it ends
    before any search."""
    cameras = np.asarray(cameras, dtype=float)
    points = np.asarray(points, dtype=float)
    chart = Chart.build(cameras, points, options.norm)
    if chart.constant_depth_behind:
        return chart, TrackResult("infeasible", False, reason=_REASONS.no_domain)
    prepared = prepare(chart.program, chart.dlt(), np.eye(3), options.abs_gap, options.max_residual, _REASONS)
    if isinstance(prepared, Early):
        if prepared.incumbent is None:
            return chart, TrackResult(prepared.status, False, reason=prepared.reason)
        result = _track_result(chart, cameras, points, prepared.incumbent, options.norm, prepared.status,
                               0.0 if prepared.status == "optimal" else None, 0, None)
        result.reason = prepared.reason
        return chart, result
    return chart, prepared


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
    chart, prepared = prepare_track(cameras, points, options)
    if isinstance(prepared, TrackResult):
        prepared.elapsed_s = time.perf_counter() - start
        return prepared
    # Root region in the caller's frame: lower <= (F X) / (d . X) <= upper, d . X > 0 exactly
    # in front of the reference view.
    to_chart = np.linalg.inv(chart.T)
    searched = search(prepared, options, "every point in front of every camera", chart.reference,
                      prepared.problem.B @ to_chart[:3], to_chart[3], callback)
    if searched.solution is None:
        result = TrackResult("infeasible", False, nodes=searched.nodes, reason=_REASONS.over_max_residual)
    else:
        result = _track_result(chart, cameras, points, searched.solution, options.norm, searched.status,
                               searched.lower_bound, searched.nodes, searched.certificate)
    result.elapsed_s = time.perf_counter() - start
    return result


def _track_result(chart: Chart, cameras, points, y, norm, status, lower, nodes, certificate) -> TrackResult:
    X = chart.T @ np.append(y, 1.0)
    X = X / np.linalg.norm(X)
    at_infinity = abs(X[3]) <= 1e-12
    point = X.tolist() if at_infinity else (X[:3] / X[3]).tolist()
    proj = cameras @ X
    residuals = proj[:, :2] / proj[:, 2:3] - points
    cost = norm_cost(residuals, norm)  # recomputed in pixels from the original data
    if lower is not None:
        lower = min(lower, cost)
    return TrackResult(status=status, certified=status == "optimal" and lower is not None, point=point,
                       at_infinity=bool(at_infinity), cost=cost, lower_bound=lower,
                       gap=cost - lower if lower is not None else None, nodes=nodes,
                       certificate=certificate, residuals=residuals.tolist())


__all__ = ["NORMS", "TriangulationOptions", "TrackResult", "Certificate", "triangulate", "prepare_track",
           "camera_centres"]
