"""Certified P^n -> P^m maps (thesis 5.5.2-5.5.3): camera resectioning (n=3, m=2), 2D
homographies (n=m=2) and 3D homographies (n=m=3), under the three norms.

The unknown is the (m+1)x(n+1) matrix M. Residual j is ``x_j - (M_k . X_j / M_last . X_j)_k``:
numerators ``x_jk (M_last . X_j) - M_k . X_j`` are linear in M, depths ``M_last . X_j`` linear
in its last row. The scale is fixed by the reference point's depth being 1, so the last row
has n free parameters w; they are the only directions ever branched. Variables:
``v = (w, the other m rows of M)``; the last row is ``l0 + N w`` with N spanning the
complement of the reference point.
"""

from __future__ import annotations

from dataclasses import replace
import math
import time
from typing import Callable

import numpy as np

from geocert.core import summary_notes
from geocert.core.bnb import Progress
from geocert.core.geometry import unit_frobenius
from geocert.formulations.fractional.charts import MapChart, normaliser
from geocert.formulations.fractional.options import MapOptions
from geocert.formulations.fractional.resection_bound import resection_bound
from geocert.formulations.fractional.results import LocalCertificate, MapResult, claim_of
from geocert.solvers.fractional.search import (LARGE_BOUND_TOLERANCE, Early, Reasons, local_refine, prepare,
                                               recomputed_status, search)
from geocert.core.certificates import residual_rounding
from geocert.formulations.fractional.items import (MapItem, discounted, refused_by_verifier, stated_residuals,
                                              stated_tolerance)
from geocert.core.self_check import checked_solve
from geocert.core.determinacy import certified_gap
from geocert.formulations.fractional.proof import program_allowance, program_discount
from geocert.formulations.fractional.resection_leaves import NORMS as LEAF_NORMS, l1_cost_increase
from geocert.formulations.fractional.resection_centre_l1 import l1_centre
from geocert.solvers.fractional.sublevel_search import leaves_sublevel


def dlt(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The linear estimate of M (normalised DLT); sign chosen so most depths are positive."""
    S, T = normaliser(source), normaliser(target)
    X = (S @ np.hstack([source, np.ones((len(source), 1))]).T).T
    x = (T @ np.hstack([target, np.ones((len(target), 1))]).T).T
    n1, m = X.shape[1], target.shape[1]
    # Per point j and image coordinate k: -X_j in row k of M, x_jk X_j in its last row.
    blocks = np.zeros((len(X), m, m + 1, n1))
    for k in range(m):
        blocks[:, k, k] = -X
        blocks[:, k, m] = x[:, k:k + 1] * X
    rows = blocks.reshape(len(X) * m, (m + 1) * n1)
    # The thin SVD when there are at least as many rows as unknowns (its last right singular
    # vector is the same; the full one also builds a square U of side 2k: 0.045 s of CPU against
    # 0.002 s for a 581-point camera); the full one otherwise, whose last row spans part of the
    # null space.
    Mn = np.linalg.svd(rows, full_matrices=rows.shape[0] < rows.shape[1])[2][-1].reshape(m + 1, n1)
    M = np.linalg.inv(T) @ Mn @ S
    depths = M[m] @ np.hstack([source, np.ones((len(source), 1))]).T
    return M if np.sum(depths > 0) >= np.sum(depths < 0) else -M


UNREPRESENTABLE = ("the map in the data's own units is not representable in floating point: its entries span more "
                   "than the floats do (coordinates near the smallest normal number, 2.2e-308); rescale the coordinates")

_REASONS = Reasons(
    no_domain_found="no map putting every point at positive depth was found",
    degenerate="the correspondences do not determine the map: the maps within the residual bound form an unbounded set",
)


def fit_map(
    source: np.ndarray,
    target: np.ndarray,
    options: MapOptions | None = None,
    callback: Callable[[Progress], bool | None] | None = None,
) -> MapResult:
    """Certified global optimum of one map from correspondences ``source`` (k, n) -> ``target`` (k, m)."""
    options = options or MapOptions()
    start = time.perf_counter()
    source = np.asarray(source, dtype=float)
    target = np.asarray(target, dtype=float)
    kind = "resection" if (source.shape[1], target.shape[1]) == (3, 2) else "homography"
    return checked_solve(kind, (source, target), options, lambda run: _fit_map(source, target, run, callback, start),
                         lambda result: claim_of(result, matrix=result.matrix))


# Rounds of bound tightening on the root box (search.BoxProblem.tighten), ended early once the
# root's bound is within CLOSING_SHARE of the gap asked for (a share, so that the rounding the
# verifier allows the returned cost does not take a just-closed root outside the tolerance): for
# L2L2 only, whose quadratic envelope closes 1000-point homographies' roots after one round (2% to
# 5% before it, 1e-5 after). The L1 norms' roots left 44% to 48% before tightening and 5e-4 to
# 1.2e-3 after three rounds: a check before each round would be one wasted solve in five.
TIGHTEN_ROUNDS = 4
CLOSING_SHARE = 0.5
# Maps of at least this many correspondences tighten every node's box (search.BoxProblem.bound).
# Measured on the Dinosaur's cameras (100 to 1,000 points, rel_gap 1e-3): 3-5 times fewer nodes,
# 1.1-1.6 times less processor time where the search branches; on 7-point maps the solves are
# cheap and the extra ones cost more than the nodes they save.
NODE_TIGHTENING_POINTS = 50
# Such maps cap their costliest terms (search.BoxProblem.cap_terms) when a child of the root left a
# gap of at least this many times rel_gap. Measured gaps of the root's children at rel_gap 1e-3
# (Dinosaur): 0.0011-0.0016 for the L2L1 cameras that close in 5-9 nodes (where caps cost 0.8-1.2 s
# CPU for nothing), 0.004-0.03 for the L2L2 cameras of 31-217 nodes (where caps cut nodes 4-10x).
CAP_GAP = 2.0


# The second search behind an L1 resection's proven intervals (_prove_leaves) stops, within the
# item's clock, after this many seconds or this many times the solve's own, whichever is more;
# its open boxes are then kept leaves (wider intervals, never none).
LEAVES_MIN_S = 10.0
LEAVES_SHARE = 2.0
SCOPE = "every map that puts every point at positive depth"
CLAIM_MARGIN = 1e-12  # the bound claimed below the bound computed (relative), as convexity_path's


def _fit_map(source, target, options: MapOptions, callback, start: float) -> MapResult:
    chart = MapChart.build(source, target, options.norm)
    n = source.shape[1]
    guess = chart.from_matrix(dlt(source, target))
    local = _sublevel_certified(chart, source, target, guess, options)
    if local is not None:
        local.elapsed_s = time.perf_counter() - start
        return local
    prepared = prepare(chart.program, guess, np.eye(chart.program.dim)[:n],
                       options.abs_gap, options.max_residual, _REASONS)
    if isinstance(prepared, Early):
        if prepared.incumbent is None:
            result = MapResult(prepared.status, False, reason=prepared.reason)
        else:
            result = _map_result(chart, source, target, prepared.incumbent, options, prepared.status,
                                 0.0 if prepared.status == "optimal" else None, 0, None)
            result.reason = result.reason or prepared.reason
    else:
        # Maps branch (triangulation mostly closes at the root, batched: fractional.stacked builds
        # its relaxations row for row with the envelope of t / s).
        prepared.problem.relaxation.quadratic = options.norm == "L2L2"
        prepared.problem.node_tightening = len(source) >= NODE_TIGHTENING_POINTS
        if len(source) >= NODE_TIGHTENING_POINTS:
            prepared.problem.use_bound_tolerance(LARGE_BOUND_TOLERANCE)
            prepared.problem.capping = True
            prepared.problem.cap_gap = CAP_GAP * options.rel_gap
        # The item's clock covers the tightening before the search, whose clock is what is left.
        prepared.problem.deadline = start + options.time_limit_s
        if math.isfinite(prepared.upper):  # with the settings above, so that the root's bound is the search's
            closing = CLOSING_SHARE * options.rel_gap if options.norm == "L2L2" else None
            prepared.problem.root = prepared.problem.tighten(prepared.problem.root, prepared.upper, TIGHTEN_ROUNDS,
                                                             closing_gap=closing)
        # Root region on the caller's last row l: z = B w with w = N' S^-T l / (l . X_ref).
        functionals = prepared.problem.B[:, :n] @ chart.last_row_basis.T @ np.linalg.inv(chart.source_norm).T
        left = replace(options, time_limit_s=max(0.0, prepared.problem.deadline - time.perf_counter()))
        searched = search(prepared, left, SCOPE, chart.reference,
                          functionals, np.append(source[chart.reference], 1.0), callback)
        if searched.solution is None:
            result = MapResult(searched.status, False, nodes=searched.nodes, reason=searched.reason)
        else:
            result = _map_result(chart, source, target, searched.solution, options, searched.status,
                                 searched.lower_bound, searched.nodes, searched.certificate, prepared.scale)
            _prove_leaves(result, chart, source, target, prepared, options, start)
    result.elapsed_s = time.perf_counter() - start
    return result


def _prove_leaves(result: MapResult, chart: MapChart, source, target, prepared, options: MapOptions,
                  start: float) -> None:
    """An L1 resection certified by a search, with a full certificate: its proven intervals
    (fractional.resection_leaves), read off a second search at the level l1_cost_increase gives,
    set as its proof's sublevel, with its camera centre's at that level when proven
    (fractional.resection_centre_l1); none when not proven within the item's clock."""
    proof = result.certificate.proof if result.certificate is not None else None
    if not (result.certified and options.norm in LEAF_NORMS and (source.shape[1], target.shape[1]) == (3, 2)
            and isinstance(proof, dict) and proof.get("type") == "branch_and_bound"):
        return
    M = np.array(result.matrix)
    item = MapItem((source, target), options.norm, chart)
    v = item.to_program(M)
    if v is None:
        return
    with np.errstate(all="ignore"):
        discount = program_discount(item, M, np.array(result.residuals), program_allowance(item, M, prepared.scale))
        increase = l1_cost_increase(options.norm, result.cost, len(source), certified_gap(result.cost, result.lower_bound))
        try:
            now = time.perf_counter()
            deadline = min(start + options.time_limit_s, now + max(LEAVES_MIN_S, LEAVES_SHARE * (now - start)))
            sublevel = leaves_sublevel(prepared, chart, v, result.cost, increase, discount, deadline)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            sublevel = None
    if sublevel is None:
        return
    try:  # the centre at the same level (resection_centre_l1), when proven
        with np.errstate(all="ignore"):
            centre = l1_centre(source, target, M, options.norm, increase, sublevel["reference"])
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        centre = None
    if centre is not None:
        sublevel["centre"] = centre
    proof["sublevel"] = sublevel


def _sublevel_certified(chart: MapChart, source, target, guess, options: MapOptions) -> MapResult | None:
    """An L2L2 resection certified with no search (fractional.resection_bound: the quadratic bound
    over the ball proven to hold every camera costing as little) at its local optimum, when that
    bound is within the tolerance as the verifier recomputes it; None otherwise (the search runs)."""
    if options.norm != "L2L2" or (source.shape[1], target.shape[1]) != (3, 2) or guess is None:
        return None
    with np.errstate(all="ignore"):
        v, cost = local_refine(chart.program, guess, "L2L2")
        if not math.isfinite(cost):
            return None
        M = chart.matrix(v)
        M = unit_frobenius(M)  # the matrix _map_result returns, which the bound is about
        try:
            found = resection_bound(source, target, M)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            found = None
    if found is None:
        return None
    bound, proof = found
    claimed = bound - CLAIM_MARGIN * abs(bound)  # the verifier's sums may differ in their last bits
    certificate = LocalCertificate(SCOPE, math.nan, proof["radius"], proof,
                                   note=summary_notes.sublevel(proof["radius"], proof["rounds"]))
    result = _map_result(chart, source, target, v, options, "optimal", claimed, 0, certificate)
    if not result.certified or result.cost <= options.abs_gap:  # the trivial bound's (prepare's first step)
        return None
    certificate.tolerance = max(options.abs_gap, options.rel_gap * abs(result.cost))
    return result


def _map_result(chart: MapChart, source, target, v, options, status, lower, nodes, certificate,
                scale: float | None = None) -> MapResult:
    """The result of chart point ``v``. ``scale``: the residual factor of a search's proof (its
    program is checked against the data as the verifier checks it); None for the trivial bound."""
    with np.errstate(over="ignore", invalid="ignore"):
        M = unit_frobenius(chart.matrix(v))  # positive scale: the reference depth stays positive
    if not np.all(np.isfinite(M)):
        # Data at the edge of the floats (source coordinates near or below 2.2e-308): the map's
        # entries in the caller's units span more than the floats do, so no camera can be stated.
        return MapResult("not_certified", False, nodes=nodes, reason=UNREPRESENTABLE)
    homogeneous = np.hstack([source, np.ones((len(source), 1))])
    proj = homogeneous @ M.T
    item = MapItem((source, target), options.norm, chart)
    # recomputed from the caller's data, exactly (one number on every machine; a map has few points)
    residuals, cost = stated_residuals(item, M, target - proj[:, :-1] / proj[:, -1:], options.norm, always=True)
    undiscountable = None
    if lower is not None:
        lower, undiscountable = discounted(item, M, residuals, min(lower, cost), scale)
    rounding = residual_rounding(target - residuals, target)  # the verifier's (target - image = residuals)
    status, reason = recomputed_status(status, residuals, cost, lower, options, rounding)
    if undiscountable:  # the proof's bound is not the data's (the verifier reads it as -inf)
        status, reason = "not_certified", undiscountable
    if status == "optimal":
        reason = refused_by_verifier(item, M, residuals, cost, options, scale)
        status = "not_certified" if reason else status
    stated_tolerance(certificate, status, lower, cost, options)
    return MapResult(status=status, certified=status == "optimal" and lower is not None, matrix=M.tolist(), reason=reason,
                     residuals=residuals.tolist(), cost=cost, lower_bound=lower,
                     gap=cost - lower if lower is not None else None, nodes=nodes, certificate=certificate)
