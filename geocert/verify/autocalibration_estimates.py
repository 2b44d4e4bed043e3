"""An autocalibration stage's estimate walked again from the data, not taken at its word.

The stages' determinacy (autocalibration.determinacy) proves nothing, but it is a claim about the
data ("K fixed to 1%", no ``orbital_motion`` warning). Its values, level, tolerances and
redundancy are tied elsewhere (estimates.check_plane, check_intrinsics, check_stage_level); without
this module an orbital motion's undetermined K, its intervals collapsed onto their values and its
warning dropped, verified as determined (review 41). Here, at the returned plane and K:

- **Widths.** The writer's walks (``affine_walk``, ``metric_walk``: numpy only) are made again.
  The affine stage's intervals are that walk's ranges; a K stage's hold its walk's ranges (the
  plane's family widens them, in quadrature), so each stated interval must contain the
  recomputed one, to ``WALK_SLACK`` of its width, and be unbounded where the walk is. In a
  document written before the walk (its intervals state no tolerance) a K stage's end may instead
  hold the local curvature's (Gauss-Newton, the level's own words), as such documents state: each
  end is held to the nearer of the two to the value, unbounded only where both are. With one focal length a view (``varying_focal_stage``,
  curvature only) the curvature's alone.
- **Motions.** The DIAC's family (``motion_warnings``, numpy only) is judged again with the
  returned K's DIAC; where it finds a critical motion at thresholds just either side of
  ``RELATIVE_WIDTH`` (no rounding of the same sums could turn the judgement), the stage must carry
  a critical-motion warning (its code the writer's geometry names; any of CRITICAL_CODES is read
  as one). The plane family's own warning needs the writer's scipy refits and is not demanded.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from geocert.solvers.autocalibration import determinacy as writer
from geocert.solvers.autocalibration import metric_relaxation
from geocert.solvers.autocalibration.problem import w_of_K
from geocert.core.determinacy import certified_gap, clip, safely
from geocert.core.strict import Invalid
from geocert.verify import estimates

# Of a recomputed interval's width: how far a stated end may lie inside it. The walk bisects each
# ray 30 times after doubling; another machine's rounding of the same cost can turn one comparison
# at the limit, moving an end by one bisection step (2^-30 of the ray). Documents written before
# the walk took its present form state ends up to 0.26% of the width inside today's (the stored
# five-view document's plane, measured): a hundredth holds them, while a collapsed interval, or one
# narrowed by a tenth on a side, moves an end by five times that or more.
WALK_SLACK = 1e-2
JUDGEMENT_MARGIN = 1e-4  # relative, either side of RELATIVE_WIDTH: a motion judged critical at both


def check_stratified(problem, p: np.ndarray | None, K: Any, stages: list, centres: np.ndarray | None) -> None:
    """The affine stage's intervals are its modulus walk's; the metric stage's hold its metric
    walk's (scoped to the intrinsics ranges); both stages' motions judged again."""
    if p is None:
        return
    affine = _analysed(stages[0])
    if affine is not None:
        walk = _walked(writer.affine_walk, problem, p, certified_gap(_cost(stages[0], "cost"),
                                                                      _cost(stages[0], "lower_bound")))
        if walk is not None:
            _check_holds(affine, walk["intervals"], "stages/0/determinacy")
    metric = _analysed(stages[1])
    if metric is None or not isinstance(K, list):
        return
    w = w_of_K(problem, np.asarray(K, dtype=float))
    walk = _walked(writer.metric_walk, problem, p, w,
                   certified_gap(_cost(stages[1], "cost"), _cost(stages[1], "lower_bound")))
    if walk is not None:
        _check_holds(metric, _held(walk, problem, metric), "stages/1/determinacy")
    H = metric_relaxation.homographies(problem.norm.cameras, problem.norm.reference, p)
    omega = metric_relaxation.omega_of(w)
    for number, stated in ((0, affine), (1, metric)):
        if stated is not None:
            _check_motion(stated, H, centres, omega, f"stages/{number}/determinacy")


def check_direct(problem, p: np.ndarray | None, K: Any, Ks: Any, stage: dict, centres: np.ndarray | None) -> None:
    """The direct stage's estimate: one K's metric walk (clipped to the intrinsics ranges, as the
    stratified metric stage's) or one focal length a view's curvature intervals, and its
    motion judged again."""
    stated = _analysed(stage)
    if p is None or stated is None:
        return
    H = metric_relaxation.homographies(problem.norm.cameras, problem.norm.reference, p)
    if isinstance(Ks, list):
        again = _walked(writer.varying_focal_stage, problem, p, Ks, None)
        if again is not None:
            _check_holds(stated, again["intervals"], "stages/0/determinacy")
        omega = None  # the writer judges the motion with the DIAC the H fit best
    elif isinstance(K, list):
        w = w_of_K(problem, np.asarray(K, dtype=float))
        walk = _walked(writer.metric_walk, problem, p, w, None)
        if walk is not None:
            _check_holds(stated, _held(walk, problem, stated), "stages/0/determinacy")
        omega = metric_relaxation.omega_of(w)
    else:
        return
    _check_motion(stated, H, centres, omega, "stages/0/determinacy")


def _held(walk: dict, problem, stated: dict) -> list[dict]:
    """What a K stage's stated intervals must hold: the walk's; in a document written before the
    walk (its intervals state no tolerance: estimates.check_intrinsics reads the same), each end
    the walk's or the local curvature's, whichever lies nearer the value (None only where both
    are unbounded). Read so for today's documents, the curvature's bounded ends stood for a
    critical motion's unbounded K (review 43)."""
    intervals = stated.get("intervals")
    if any(isinstance(i, dict) and "tolerance" in i for i in intervals or []):
        return walk["intervals"]
    bounds = writer.scope_of(problem)
    out = []
    for own, curved, (lowest, highest) in zip(walk["intervals"], walk["estimate"].intervals, bounds):
        curved = clip(dict(curved), lowest, highest)
        ends = {}
        for end, nearer in (("lower", max), ("upper", min)):
            found = [e for e in (own[end], curved[end]) if e is not None]
            ends[end] = nearer(found) if found else None
        out.append({**own, **ends})
    return out


def _analysed(stage: Any) -> dict | None:
    """The stage's determinacy when it states an analysis (not absent, not stopped at its clock)."""
    determinacy = stage.get("determinacy") if isinstance(stage, dict) else None
    if not isinstance(determinacy, dict) or estimates.stopped(determinacy):
        return None
    return determinacy


def _cost(stage: dict, name: str) -> float | None:
    value = stage.get(name)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def _walked(function, *args) -> dict | None:
    """The writer's analysis made again, or None where the data defeat its linear algebra (the
    writer then states none either: estimates.check reads that absence)."""
    return safely(function, *args)


def _check_holds(stated: dict, recomputed: list[dict], where: str) -> None:
    intervals = stated.get("intervals")
    if not isinstance(intervals, list) or len(intervals) != len(recomputed):
        raise Invalid("returned", f"{where}/intervals must be the {len(recomputed)} its writer states")
    for number, (given, own) in enumerate(zip(intervals, recomputed)):
        if not isinstance(given, dict):
            raise Invalid("returned", f"{where}/intervals/{number} must be an interval")
        lo, hi = own["lower"], own["upper"]
        width = (hi - lo) if lo is not None and hi is not None else 0.0
        slack = WALK_SLACK * width + estimates.VALUE_SLACK * max(abs(own["value"] or 0.0), 1.0)
        for end, mine, inside in (("lower", lo, lambda a, b: a <= b + slack), ("upper", hi, lambda a, b: a >= b - slack)):
            theirs = given.get(end)
            if theirs is None:
                continue  # unbounded holds anything
            if mine is None or not (isinstance(theirs, (int, float)) and math.isfinite(theirs) and inside(theirs, mine)):
                raise Invalid("returned", f"{where}/intervals/{number} ({own['name']}) states {end} {theirs!r:.30}; "
                                          f"the cost walked again from the returned solution reaches "
                                          f"{'an unbounded end' if mine is None else repr(mine)[:30]} at its level")


def _check_motion(stated: dict, H: np.ndarray, centres: np.ndarray | None, omega: np.ndarray | None,
                  where: str) -> None:
    judged = [safely(writer.motion_warnings, H, centres, omega=omega,
                     threshold=writer.RELATIVE_WIDTH * (1 + sign * JUDGEMENT_MARGIN)) for sign in (-1, 1)]
    if not all(judged):
        return  # not critical, or critical only at a threshold rounding could turn
    warnings = stated.get("warnings")
    codes = [w.get("code") for w in warnings if isinstance(w, dict)] if isinstance(warnings, list) else []
    if not any(code in writer.CRITICAL_CODES for code in codes):
        raise Invalid("returned", f"{where}/warnings state no critical motion; judged again at the returned K, "
                                  f"{judged[1][0]['code']}: {judged[1][0]['detail'][:160]}")
