"""An autocalibration stage's estimate walked again from the data, not taken at its word.

The stages' determinacy (autocalibration.determinacy) proves nothing, but it is a claim about the
data ("K fixed to 1%", no ``orbital_motion`` warning). Its values, level, tolerances and
redundancy are tied elsewhere (estimates.check_plane, check_intrinsics, check_stage_level); without
this module an orbital motion's undetermined K, its intervals collapsed onto their values and its
warning dropped, verified as determined (review 41). Here, at the returned plane and K:

- **Widths.** The writer's analyses are made again. The affine stage's intervals are its modulus
  walk's ranges (``affine_walk``); a K stage's are the metric walk's and the plane family's added
  in quadrature (``metric_intervals``: the family's metric refits are the writer's scipy
  least-squares, as an autocalibration's check already reads scipy); with one focal length a view
  the curvature's (``varying_focal_stage``). Each stated interval must contain the recomputed one,
  to ``WALK_SLACK`` of its width, and be unbounded where it is. In a document hashed before the
  estimates' form was declared (the stored ones) a K stage's end may instead hold the metric
  walk's or the local curvature's (Gauss-Newton, the level's own words), whichever lies nearer the
  value, and its plane family is not judged.
- **Motions.** The DIAC's family (``motion_warnings``) is judged again with the returned K's
  DIAC, and each stage's plane family (the planes the modulus cost cannot tell apart, the metric
  fit redone on each); where either moves K by more than ``RELATIVE_WIDTH``, clear of it by
  ``JUDGEMENT_MARGIN`` either side (no rounding of the same sums could turn the judgement), the
  stage must carry a critical-motion warning (its code the writer's geometry names; any of
  CRITICAL_CODES is read as one), whatever its analysis came to: the writer states the DIAC's
  judgement even in an analysis stopped at its clock or defeated by the data (with_motion).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from geocert.formulations.autocalibration import determinacy as writer
from geocert.formulations.autocalibration import metric_relaxation
from geocert.formulations.autocalibration.problem import w_of_K
from geocert.core.determinacy import ASPECT_EDGE_FORM, RANGE_EDGE_FORM, certified_gap, clip, form, safely
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


def check_stratified(problem, p: np.ndarray | None, K: Any, stages: list, centres: np.ndarray | None,
                     earlier: bool = True) -> None:
    """The affine stage's intervals are its modulus walk's; the metric stage's hold its writer's
    (metric_intervals); both stages' motions judged again. ``earlier``: whether the document's
    hash lets its estimates be of the earlier form (checks._check_hashes)."""
    if p is None:
        return
    affine = _analysed(stages[0])
    w = w_of_K(problem, np.asarray(K, dtype=float)) if isinstance(K, list) else None
    if affine is not None:
        gap = certified_gap(_cost(stages[0], "cost"), _cost(stages[0], "lower_bound"))
        walk = _walked(writer.affine_walk, problem, p, gap)
        if walk is not None:
            _check_holds(affine, walk["intervals"], "stages/0/determinacy")
            if w is not None and not earlier:
                family = _walked(writer.plane_family, problem, p, w, gap, None, walk)
                _check_plane_motion(affine, family, "stages/0/determinacy")
    metric = _analysed(stages[1])
    if w is None:
        return
    if metric is not None:
        _check_K_stage(problem, p, w, certified_gap(_cost(stages[1], "cost"), _cost(stages[1], "lower_bound")),
                       metric, "stages/1/determinacy", earlier)
    H = metric_relaxation.homographies(problem.norm.cameras, problem.norm.reference, p)
    omega = metric_relaxation.omega_of(w)
    # the affine stage states an estimate where its cost is finite (the writer's condition)
    analysed = (0, 1) if math.isfinite(_cost(stages[0], "cost") or math.inf) else (1,)
    for number in analysed:
        _check_motion(stages[number].get("determinacy") if isinstance(stages[number], dict) else None,
                      H, centres, omega, f"stages/{number}/determinacy")


def check_direct(problem, p: np.ndarray | None, K: Any, Ks: Any, stage: dict, centres: np.ndarray | None,
                 earlier: bool = True) -> None:
    """The direct stage's estimate: one K's metric walk (clipped to the intrinsics ranges, as the
    stratified metric stage's) or one focal length a view's curvature intervals, and its
    motion judged again."""
    stated = _analysed(stage)
    if p is None:
        return
    H = metric_relaxation.homographies(problem.norm.cameras, problem.norm.reference, p)
    if isinstance(Ks, list):
        again = _walked(writer.varying_focal_stage, problem, p, Ks, None) if stated is not None else None
        if again is not None:
            _check_holds(stated, again["intervals"], "stages/0/determinacy")
        omega = None  # the writer judges the motion with the DIAC the H fit best
    elif isinstance(K, list):
        w = w_of_K(problem, np.asarray(K, dtype=float))
        if stated is not None:
            _check_K_stage(problem, p, w, None, stated, "stages/0/determinacy", earlier, direct=True)
        omega = metric_relaxation.omega_of(w)
    else:
        return
    _check_motion(stage.get("determinacy") if isinstance(stage, dict) else None, H, centres, omega,
                  "stages/0/determinacy")


def _check_K_stage(problem, p: np.ndarray, w: np.ndarray, gap: float | None, stated: dict, where: str,
                   earlier: bool, direct: bool = False) -> None:
    """Today's K stage (``earlier`` False: the document's hash declares the estimates' form) holds
    the writer's intervals made again (metric_intervals: the metric walk and the plane family in
    quadrature) and states the plane family's critical motion. One of a document hashed before
    (the stored ones) is read in the earlier form whatever its intervals state (tolerances were
    stated before the walks were): it holds its walk or its curvature (_nearer). ``direct``: the
    direct method's stage, clipped to its own scope (determinacy.direct_scope_of)."""
    if not earlier:
        found = _walked(writer.metric_intervals, problem, p, w, gap, direct)
        if found is not None:
            _check_holds(stated, found["intervals"], where)
            _check_plane_motion(stated, found["family"], where)
            _check_range_edge(stated, found, where)
        return
    walk = _walked(writer.metric_walk, problem, p, w, gap)
    if walk is not None:
        _check_holds(stated, _nearer(walk, problem), where)


def _check_plane_motion(stated: dict, family: dict | None, where: str) -> None:
    """The plane family's warning (determinacy._plane_warning): where the planes the modulus cost
    cannot tell apart move K by more than RELATIVE_WIDTH, clear of it by JUDGEMENT_MARGIN, the
    stage states a critical-motion warning (review 43: dropped, with the intervals narrowed to the
    metric walk's, a loose plane's K read as fixed to 10%)."""
    if family is None or not np.all(np.isfinite(family["K"])):
        return
    if not family["largest_move"] > writer.RELATIVE_WIDTH * (1 + JUDGEMENT_MARGIN):
        return
    warnings = stated.get("warnings")
    codes = [w.get("code") for w in warnings if isinstance(w, dict)] if isinstance(warnings, list) else []
    if not any(code in writer.CRITICAL_CODES for code in codes):
        raise Invalid("returned", f"{where}/warnings state no critical motion; the planes at infinity the modulus "
                                  f"cost cannot tell from the returned one, walked again, move K by "
                                  f"{family['largest_move']:.3g} of its focal length")


def _check_range_edge(stated: dict, found: dict, where: str) -> None:
    """In today's form (RANGE_EDGE_FORM on), where the scope cuts a K interval the stage states
    ``at_range_edge`` (determinacy.clipped_to_scope, range_edge): without it a K pinned on its
    range's end, or an interval the range cut short, reads as fixed by the data (review 62: f =
    984.8 in [929.6, 990] under the range [300, 990], the truth 1000, restated determined). Only a
    cut that holds beyond the walk's slack is required: each interval's ends moved in by it (and,
    for a range no wider than the tolerance allows, out by it before asking whether the interval
    spans the range), its value within half the writer's EDGE of the end; and K's aspect within
    half the writer's EDGE of its range's end (determinacy.aspect_cut: review 63, a range no box
    holds); a cut the writer's rounding may not have seen is left to its word."""
    if form() < RANGE_EDGE_FORM:
        return
    warnings = stated.get("warnings")
    if isinstance(warnings, list) and "at_range_edge" in [w.get("code") for w in warnings if isinstance(w, dict)]:
        return
    for interval, (lowest, highest) in zip(found["unclipped"], found["scope"]):
        if _surely_cut(interval, lowest, highest):
            raise Invalid("returned", f"{where}/warnings state no at_range_edge: the intrinsics ranges cut the "
                                      f"interval of {interval['name']} (value {interval['value']:.6g}, range "
                                      f"[{lowest}, {highest}]), made again")
    aspect = _surely_on_aspect_end(found["walk"]["value"], found.get("aspect"))
    if aspect is not None:
        raise Invalid("returned", f"{where}/warnings state no at_range_edge: K's aspect focal_y / focal_x "
                                  f"{aspect:.6g} lies on its range's end {list(found['aspect'])} (review 63)")


def _surely_on_aspect_end(value, bounds: tuple[float, float] | None) -> float | None:
    """K's aspect where determinacy.aspect_cut reports it however the writer's rounding went: the
    range surely wider than two tolerances, the aspect within half the writer's EDGE of an end (or
    beyond); else None."""
    if bounds is None or form() < ASPECT_EDGE_FORM:
        return None
    fx, fy = float(value[0]), float(value[1])
    if not (fx > 0 and math.isfinite(fx) and math.isfinite(fy)):
        return None
    aspect, (lowest, highest) = fy / fx, bounds
    if highest - lowest <= 2.0 * writer.RELATIVE_WIDTH * abs(aspect) * (1.0 + WALK_SLACK):  # maybe narrow
        return None
    for edge, sign in ((lowest, -1.0), (highest, 1.0)):
        if sign * (aspect - edge) >= -0.5 * writer.EDGE * max(abs(edge), 1.0):
            return aspect
    return None


def _surely_cut(found: dict, lowest: float | None, highest: float | None) -> bool:
    """Whether determinacy.clipped_to_scope cuts ``found`` (unclipped) however the writer's
    rounding went (_check_range_edge)."""
    value, tolerance = found["value"], found.get("tolerance")
    if value is None or not math.isfinite(value):
        return False
    lo, hi = found["lower"], found["upper"]
    width = hi - lo if lo is not None and hi is not None and math.isfinite(hi - lo) else 0.0
    slack = WALK_SLACK * width + estimates.VALUE_SLACK * max(abs(value), 1.0)
    narrow = (lowest is not None and highest is not None and tolerance is not None
              and highest - lowest <= 2.0 * tolerance * (1.0 + WALK_SLACK))  # maybe narrow: maybe spanned
    spans = narrow and (lo is None or lo - slack <= lowest) and (hi is None or hi + slack >= highest)
    for end, edge, sign in (("lower", lowest, -1.0), ("upper", highest, 1.0)):
        if edge is None or not math.isfinite(edge):
            continue
        if not spans and sign * (value - edge) >= -0.5 * writer.EDGE * max(abs(edge), 1.0):
            return True
        reach = found[end]
        if not narrow and reach is not None and sign * (reach - edge) > slack:
            return True
    return False


def _nearer(walk: dict, problem) -> list[dict]:
    """What an earlier-form K stage's intervals must hold: each end the metric walk's or the local
    curvature's (clipped as the stage clips), whichever lies nearer the value (None only where
    both are unbounded). Read so for today's documents, the curvature's bounded ends stood for a
    critical motion's unbounded K (review 43)."""
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
        # never negative: a recomputed interval crossed (lower above upper: the clip before review 62)
        # gave a negative slack, read as a width; a stated interval crossed holds nothing, refused
        width = max(hi - lo, 0.0) if lo is not None and hi is not None else 0.0
        ends = [given.get(end) for end in ("lower", "upper")]
        if all(isinstance(e, (int, float)) and not isinstance(e, bool) for e in ends) and not ends[0] <= ends[1]:
            raise Invalid("returned", f"{where}/intervals/{number} ({own['name']}) states lower {ends[0]!r:.30} "
                                      f"above upper {ends[1]!r:.30}: an interval holds nothing so")
        slack = WALK_SLACK * width + estimates.VALUE_SLACK * max(abs(own["value"] or 0.0), 1.0)
        for end, mine, inside in (("lower", lo, lambda a, b: a <= b + slack), ("upper", hi, lambda a, b: a >= b - slack)):
            theirs = given.get(end)
            if theirs is None:
                continue  # unbounded holds anything
            if mine is None or not (isinstance(theirs, (int, float)) and math.isfinite(theirs) and inside(theirs, mine)):
                raise Invalid("returned", f"{where}/intervals/{number} ({own['name']}) states {end} {theirs!r:.30}; "
                                          f"the cost walked again from the returned solution reaches "
                                          f"{'an unbounded end' if mine is None else repr(mine)[:30]} at its level")


def _check_motion(stated: Any, H: np.ndarray, centres: np.ndarray | None, omega: np.ndarray | None,
                  where: str) -> None:
    """Whatever the stage's analysis came to (ran, stopped at its clock, defeated by the data:
    its writer states the motion in each, with_motion), a motion judged critical again needs a
    critical-motion warning: a null or stopped estimate is no place to hide one (review 43)."""
    judged = [safely(writer.motion_warnings, H, centres, omega=omega,
                     threshold=writer.RELATIVE_WIDTH * (1 + sign * JUDGEMENT_MARGIN)) for sign in (-1, 1)]
    if not all(judged):
        return  # not critical, or critical only at a threshold rounding could turn
    if not isinstance(stated, dict):
        raise Invalid("returned", f"{where} is null; judged again at the returned K the motion is critical "
                                  f"({judged[1][0]['code']}), which the stage must state")
    warnings = stated.get("warnings")
    codes = [w.get("code") for w in warnings if isinstance(w, dict)] if isinstance(warnings, list) else []
    if not any(code in writer.CRITICAL_CODES for code in codes):
        raise Invalid("returned", f"{where}/warnings state no critical motion; judged again at the returned K, "
                                  f"{judged[1][0]['code']}: {judged[1][0]['detail'][:160]}")
