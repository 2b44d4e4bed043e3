"""Certified N-view triangulation under the (L2,L2), (L2,L1) and (L1,L1) norms (thesis chapter 5).

Each track is a fractional program ``sum_i f_i(X) / g_i(X)`` (numerator convex, depth affine).
The search space is a projective chart where a reference camera's depth is 1, so that camera's
term is convex and points at infinity are ordinary points (inverse depth 0). Boxes live on
well-conditioned depth functionals, as many as the other views' depths vary along (one for two
views, up to three); the lower bound on a box is one SOCP with the convex envelope of ``t/s`` per
view (see docs/algorithms.md, section 4). Costs are scaled so the incumbent costs 1.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from geocert.core.bnb import Progress
from geocert.formulations.fractional.charts import Chart, camera_centres
from geocert.formulations.fractional.convexity_path import track_sublevel
from geocert.formulations.fractional.options import NORMS, TriangulationOptions
from geocert.formulations.fractional.results import SearchCertificate, TrackResult, claim_of
from geocert.solvers.fractional.search import Early, Reasons, depth_subspace, prepare, recomputed_status, search
from geocert.core.certificates import residual_rounding
from geocert.core.geometry import normalised_cameras, reprojection_residuals
from geocert.formulations.fractional.items import (TrackItem, discounted, refused_by_verifier, stated_residuals,
                                              stated_tolerance)
from geocert.core.self_check import checked_solve



AT_INFINITY = 1e-12  # |X[3]| of a unit-norm X below which the point is returned at infinity

_REASONS = Reasons(
    no_domain_found="no point in front of every camera was found (the cameras' signs may need orienting)",
    degenerate="the rays are (nearly) parallel: the points within the residual bound form an unbounded set",
)


def prepare_track(cameras: np.ndarray, points: np.ndarray, options: TriangulationOptions):
    """The track's chart and prepared search (fractional.Prepared), or a TrackResult when it ends
    before any search."""
    cameras = np.asarray(cameras, dtype=float)
    points = np.asarray(points, dtype=float)
    chart = Chart.build(cameras, points, options.norm)
    if chart.constant_depth_behind:  # exact: a depth that is a non-positive constant
        return chart, TrackResult("infeasible", False, reason="no point is in front of every camera")
    # Branch only where the depths vary: one direction for two views, two for three (most of a
    # turntable's tracks), three from four views on.
    prepared = prepare(chart.program, chart.dlt(), depth_subspace(chart.program), options.abs_gap,
                       options.max_residual, _REASONS)
    if isinstance(prepared, Early):
        if prepared.incumbent is None:
            return chart, TrackResult(prepared.status, False, reason=prepared.reason)
        result = track_result(chart, cameras, points, prepared.incumbent, options, prepared.status,
                               0.0 if prepared.status == "optimal" else None, 0, None)
        result.reason = result.reason or prepared.reason
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
    cameras = normalised_cameras(cameras)
    points = np.asarray(points, dtype=float)
    return checked_solve("triangulation", (cameras, points), options,
                         lambda run: _triangulate(cameras, points, run, callback, start),
                         lambda result: claim_of(result, point=result.point, at_infinity=result.at_infinity))


def _triangulate(cameras, points, options: TriangulationOptions, callback, start: float) -> TrackResult:
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
        result = TrackResult(searched.status, False, nodes=searched.nodes, reason=searched.reason)
    else:
        result = track_result(chart, cameras, points, searched.solution, options, searched.status,
                               searched.lower_bound, searched.nodes, searched.certificate, prepared.scale)
    result.elapsed_s = time.perf_counter() - start
    return result


def track_result(chart: Chart, cameras, points, y, options, status, lower, nodes, certificate,
                 scale: float | None = None, checked: bool = True) -> TrackResult:
    """The result of chart point ``y``. ``scale``: the residual factor of a search's proof (its
    program is checked against the data as the verifier checks it); None for the trivial bound.
    ``checked=False``: the caller checks the result as the verifier would (batched, many at once)."""
    X = chart.T @ np.append(y, 1.0)
    X = X / np.linalg.norm(X)
    # The chart keeps X[3] >= 0 up to round-off (the domain allows a relative 1e-12 below); a
    # point this close to the plane at infinity, or just beyond it, is returned on it with X[3]
    # exactly 0, so that solver and verifier read one point, signed so that its depths are
    # positive (X and -X differ there). Divided by a negative X[3], it would be the point behind
    # every camera.
    at_infinity = X[3] <= AT_INFINITY
    if at_infinity:
        X[3] = 0.0
    solution = X if at_infinity else np.append(X[:3] / X[3], 1.0)
    point = solution.tolist() if at_infinity else solution[:3].tolist()
    # The cost of the point as returned (what anyone recomputing it gets, to the last bit).
    item = TrackItem((cameras, points), options.norm, chart)
    # recomputed in pixels from the original data (exactly where the floats' rounding could move it)
    residuals, cost = stated_residuals(item, solution, reprojection_residuals(cameras, solution, points), options.norm)
    undiscountable = None
    if lower is not None:
        lower, undiscountable = discounted(item, solution, residuals, min(lower, cost), scale)
    rounding = residual_rounding(residuals + points, points)  # the verifier's (image - points = residuals)
    status, reason = recomputed_status(status, residuals, cost, lower, options, rounding)
    if undiscountable:  # the proof's bound is not the data's (the verifier reads it as -inf)
        status, reason = "not_certified", undiscountable
    if status == "optimal" and checked:
        reason = refused_by_verifier(item, solution, residuals, cost, options, scale)
        status = "not_certified" if reason else status
    certified = status == "optimal" and lower is not None
    stated_tolerance(certificate, status, lower, cost, options)
    if certified and certificate is not None and not at_infinity and "full" in (options.detail, options.certificate):
        sublevel = track_sublevel(cameras, points, solution[:3], cost, lower, options.norm)
        certificate.sublevel = sublevel
        if certificate.proof is not None and sublevel is not None:
            certificate.proof["sublevel"] = sublevel
    return TrackResult(status=status, certified=certified, point=point, reason=reason,
                       at_infinity=bool(at_infinity), cost=cost, lower_bound=lower,
                       gap=cost - lower if lower is not None else None, nodes=nodes,
                       certificate=certificate, residuals=residuals.tolist())


__all__ = ["NORMS", "TriangulationOptions", "TrackResult", "SearchCertificate", "triangulate", "prepare_track",
           "camera_centres"]
