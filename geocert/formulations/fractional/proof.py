"""The verifier's check of a branch-and-bound proof of a fractional program (docs/certificate.md):
the program rebuilt from the raw data, the root region's bounds with their witness, each
bound-tightening round, exact coverage of the searched box by the leaves, and each leaf's safe
bound. Linear algebra only: no conic solver is imported."""

from __future__ import annotations

from dataclasses import dataclass
import functools
import math
from typing import Any, Callable

import numpy as np

from geocert.core.bnb import Box
from geocert.core.certificates import BOUND_TOLERANCE, TERMS_ROUNDING
from geocert.core.geometry import cost_rounding
from geocert.core.cones import proves_infeasible, rounding_counted, safe_lower_bound
from geocert.core.coverage import extended, uncovered_part, widened
from geocert.core.strict import (Invalid, box as _box, charge, dual_vector, informational, number as _number,
                                 numbers as _numbers, record)
from geocert.formulations.fractional.relaxation import (Relaxation, cost_unit, gamma_for, residual_region, root_bounds,
                                                   tightening_objective, with_cost_cap)

MAX_ROUNDS = 16  # bound-tightening rounds (the solver makes at most 4)
# A dual proof's recorded ``bound`` may exceed the bound the verifier recomputes by this fraction:
# the recomputed one is what counts (the leaves' smallest is the proven bound), the recorded one
# only has to be the solver's. Its relaxation may be built on boxes and caps widened by their
# proofs' rounding (coverage.widened), which moves a bound by up to about 2e-9 of it.
LEAF_CLAIM_TOLERANCE = 1e-6
SCALE_RANGE = (1e-15, 1e3)  # the solver's residual factor lies in it (search.MAX_SCALE above)


def verify_search(item, options: dict, proof: dict, lower_claimed: float, solution,
                   passed: list[str]) -> float:
    """The lower bound (caller's units) the search's proof establishes."""
    # Only points costing less than the claimed lower bound need excluding: every proof must
    # hold for them, so its cost cap may be anything not below that bound (less the relative
    # tolerance: a cap of 0 would prove nothing of a positive bound, whatever the scale).
    checked = checked_leaves(item, options, proof, lambda unit, discount: max(
        0.0, lower_claimed * unit * (1 - BOUND_TOLERANCE)), solution, passed)
    if not checked.bounds:
        return math.inf
    # The program's bound, for the data's problem: lowered by the program's distance from it.
    return min(checked.bounds) / checked.unit - (checked.discount if math.isfinite(checked.discount) else math.inf)


@dataclass
class CheckedLeaves:
    """What a checked search proof proves, in the program's scaled units: every point of the
    scope costing at most ``cap`` lies in a leaf; leaf i (``lo[i]``..``hi[i]`` in the branched
    functionals ``F[:k]``, extended to the proven searched box) holds no point costing less than
    ``bounds[i]`` (inf: none costing at most cap). ``discount``: the program's distance from the
    data's problem at the solution (caller's units; inf where an observation is not compared)."""

    bounds: list[float]
    lo: np.ndarray
    hi: np.ndarray
    F: np.ndarray
    k: int
    unit: float
    cap: float
    discount: float


def checked_leaves(item, options: dict, proof: dict, cap_of: Callable[[float, float], float], solution,
                   passed: list[str]) -> CheckedLeaves:
    """verify_search's checks of a search proof, with every proof in it required to hold for the
    points costing at most ``cap_of(unit, discount)`` (scaled units; the unit and the program's
    discount at the solution are the proof's): root region, tightening, caps, coverage, leaf
    bounds. The leaves as checked (CheckedLeaves)."""
    program, norm = item.program, item.norm
    record(proof, "proof", ("type", "scale", "root", "tightening", "search_box", "proofs", "leaves"),
           ("relaxation", "caps"))
    scale = _number(proof.get("scale"), "proof/scale")
    if not SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]:
        raise Invalid("program", f"scale must lie in {SCALE_RANGE}")
    program.max_residual = options["max_residual"]
    program.rescale(scale)
    unit = cost_unit(scale, norm)
    allowed = check_program(item, solution, scale)
    with np.errstate(invalid="ignore"):  # an observation not compared: no bound beyond the program's
        discount = program_discount(item, solution, item.raw_residuals(solution)[0], allowed)
    cap = cap_of(unit, discount)
    if not (cap >= 0 and math.isfinite(cap)):
        raise Invalid("program", "the program's distance from the data is not bounded at the solution")
    passed.append("program")

    root = record(proof.get("root"), "proof/root", ("gamma", "functionals", "claim", "bounds", "duals"))
    d = program.dim
    F = _numbers(root.get("functionals"), "proof/root/functionals", (d, d))
    search_box_raw = proof.get("search_box")
    k = len(search_box_raw[0]) if isinstance(search_box_raw, list) and search_box_raw and \
        isinstance(search_box_raw[0], list) else 0
    if not 0 < k <= min(d, 3) or not np.linalg.cond(F) <= 1e6:
        raise Invalid("root_region", "functionals must be an invertible d x d matrix, at most 3 of them branched")
    search_box = _box(search_box_raw, "proof/search_box", k)
    lower, upper = _numbers(root.get("bounds"), "proof/root/bounds", (2, d))
    gamma = _number(root.get("gamma"), "proof/root/gamma")
    needed = gamma_for(cap, norm)
    if program.max_residual is not None:
        needed = min(needed, program.max_residual)
    # The bounds as proven: the claimed ones, each side widened to its proven value where that
    # lies beyond it by rounding (coverage.widened); every box below is built on proven boxes.
    proven_lower, proven_upper = _check_root(program, F, gamma, needed, root, lower, upper, item.to_program(solution))
    passed.append("root_region")

    box, proven_box = Box(lower[:k], upper[:k]), Box(proven_lower[:k], proven_upper[:k])
    form = proof.get("relaxation", "envelope")
    if form not in ("envelope", "quadratic") or (form == "quadratic" and norm != "L2L2"):
        raise Invalid("format", 'proof/relaxation must be "quadratic" (L2L2 only) or absent')
    relaxation = Relaxation(program, F[:k], (proven_lower[k:], proven_upper[k:]), F, quadratic=form == "quadratic")
    rounds = proof.get("tightening")
    if not isinstance(rounds, list):
        raise Invalid("format", "proof/tightening must be a list")
    if len(rounds) > MAX_ROUNDS:
        raise Invalid("tightening", f"{len(rounds)} tightening rounds: at most {MAX_ROUNDS}")
    for number, round_ in enumerate(rounds):
        box, proven_box = _check_round(relaxation, round_, box, proven_box, cap, number)
    if not (np.all(search_box.lo <= box.lo) and np.all(search_box.hi >= box.hi)):
        raise Invalid("tightening", "the searched box does not contain the proven root box")
    searched = Box(np.minimum(search_box.lo, proven_box.lo), np.maximum(search_box.hi, proven_box.hi))
    others = _check_caps(relaxation, proof.get("caps", []), box, proven_box, cap)
    passed.append("tightening")

    leaves, proofs = proof.get("leaves"), proof.get("proofs")
    if not isinstance(leaves, list) or not leaves or not isinstance(proofs, list):
        raise Invalid("format", "proof/leaves and proof/proofs must be lists, leaves not empty")
    for number, leaf in enumerate(leaves):
        if not (isinstance(leaf, list) and len(leaf) == 3 and (leaf[2] is None or
                                                               (type(leaf[2]) is int and 0 <= leaf[2] < len(proofs)))):
            raise Invalid("format", f"leaf {number} must be [lower corner, upper corner, proof index or null]")
    leaf_lo = _numbers([leaf[0] for leaf in leaves], "proof/leaves (lower corners)", (len(leaves), k))
    leaf_hi = _numbers([leaf[1] for leaf in leaves], "proof/leaves (upper corners)", (len(leaves), k))
    gap = uncovered_part(search_box, leaf_lo, leaf_hi)
    if gap is not None:
        raise Invalid("coverage", f"no leaf covers the box {gap[0].tolist()} .. {gap[1].tolist()}")
    passed.append("coverage")

    # The points between the claimed searched box and the proven one are answered for by the
    # leaves and proofs on its faces, extended to the proven faces (coverage.extended).
    leaf_lo, leaf_hi = extended(leaf_lo, leaf_hi, search_box, searched)
    bounds = _check_leaf_proofs(relaxation, proofs, leaves, leaf_lo, leaf_hi, cap, k, others, (search_box, searched))
    passed.append("leaf_bounds")
    return CheckedLeaves(bounds, leaf_lo, leaf_hi, F, k, unit, cap, discount)


@functools.lru_cache(maxsize=32)
def _sample_steps(d: int) -> tuple[np.ndarray, ...]:
    """Eight fixed pseudo-random steps (scales 1e-4 to 1) for the points the program is compared
    at: the same on every machine and every run."""
    rng = np.random.default_rng(0)
    return tuple(rng.normal(size=d) * 10.0 ** rng.uniform(-4, 0) for _ in range(8))


def raw_sizes(cameras: np.ndarray, points: np.ndarray, solutions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For cameras (..., N, 3, 4), observations (..., N, 2) and points (..., n, 4): the sizes
    (..., n, N, 2) and (..., n, N) of the terms of each ``row . X - x * depth`` and depth, the sums
    of their products' magnitudes (a dot product rounds by a few 1e-16 of that sum)."""
    terms = np.einsum("...Nij,...sj->...sNi", np.abs(cameras), np.abs(solutions))  # (..., n, N, 3)
    return terms[..., :2] + np.abs(points)[..., None, :, :] * terms[..., 2:3], terms[..., 2]


# The least subnormal float (not convexity.UNDERFLOW, a test's allowance). A product below the
# normal range rounds by up to half of it, not by a share of itself: a solution written in
# subnormal numbers (review 39) rounded every product behind its projection by up to a third of
# itself while 1e-15 of the terms' size underflowed to 0, so the float cost of a forged solution
# (0) was taken as determined.
LEAST_SUBNORMAL = 2.0 ** -1074


def residual_uncertainty(proj: np.ndarray, terms: np.ndarray) -> np.ndarray:
    """How far the data determine each residual coordinate ``proj[..., :-1] / proj[..., -1]`` (a
    projection, its depth last) given ``terms``, the sums of the magnitudes of the products behind
    each of proj's entries (image_uncertainty)."""
    depth = proj[..., -1:]
    image = proj[..., :-1] / np.where(depth != 0, depth, 1.0)
    return image_uncertainty(image, depth, terms[..., :-1], terms[..., -1:])


def image_uncertainty(image: np.ndarray, depth: np.ndarray, numerator_size: np.ndarray,
                      depth_size: np.ndarray) -> np.ndarray:
    """How far the data determine an image coordinate ``image`` = numerator / ``depth``, given the
    sums of the magnitudes of the products behind the numerator and the depth: 1e-15 of the terms'
    size over the depth (a 4-term product rounds by under 5e-16 of it), and for products below the
    normal range 4 LEAST_SUBNORMAL each of numerator and depth over the depth (four products, each
    rounded by half of it; twice that for the division's second order) and the quotient's own
    LEAST_SUBNORMAL. Tiny unless a point is nearly on a principal plane, or the data lie far from the
    origin (a residual is then a difference of numbers far larger than itself, and no frame
    computes it better), or the solution's numbers are subnormal; infinite at depth 0."""
    depth = np.abs(depth)
    size = 1e-15 * (numerator_size + np.abs(image) * depth_size) + 4 * LEAST_SUBNORMAL * (1 + np.abs(image))
    return np.where(depth > 0, size / np.where(depth > 0, depth, 1.0) + LEAST_SUBNORMAL, np.inf)


def track_uncertainty(cameras: np.ndarray, solution: np.ndarray) -> np.ndarray:
    """residual_uncertainty of a track's solution (..., 4) in its cameras (..., N, 3, 4)."""
    return residual_uncertainty(np.einsum("...nij,...j->...ni", cameras, solution),
                                np.einsum("...nij,...j->...ni", np.abs(cameras), np.abs(solution)))


def check_program(item, solution, scale: float, strictness: float = 1.0) -> np.ndarray:
    """The program rebuilt from the data is the data's problem: at the solution and at points
    around it, its residuals and depth signs are the raw data's. A program is a ratio of affine
    maps, so agreement at generic points means agreement everywhere. All the points are compared
    at once (arrays over points, observations and residual coordinates).

    ``strictness`` scales the tolerances: the solvers ask this of their own results with 0.5
    before certifying them, so that a verifier whose rebuilt program differs in its last bits
    (the batched path builds its charts on stacked arrays) still accepts every claim made.
    Returns the allowance at the solution (what program_discount reads)."""
    v0 = item.to_program(solution)
    if v0 is None:
        raise Invalid("program", "the solution lies outside the program's chart")
    charge(9 * len(item.program.den), "the program check")
    samples = np.vstack([v0] + [v0 + step * (1 + np.abs(v0)) for step in _sample_steps(len(v0))])
    numerators, depths = item.raw_parts_many(samples)  # (n, N, m), (n, N)
    V = np.hstack([samples, np.ones((len(samples), 1))])
    program = item.program
    ours = np.einsum("Nmk,nk->nNm", program.num, V) / scale
    ours_depth = V @ program.den.T
    # Each observation on its own (a camera is defined up to its scale): where a point is (nearly)
    # on a view's principal plane, or its centre (a map's point, on the map's), the depth is
    # round-off, and that observation is compared at the other points.
    numerator_size, depth_size = item.raw_sizes_many(samples)
    clear = np.abs(depths) > 1e-6 * depth_size
    safe_depths, safe_ours_depth = np.where(clear, depths, 1.0), np.where(clear, ours_depth, 1.0)
    theirs = np.where(clear[..., None], numerators / safe_depths[..., None], 0.0)
    ours = np.where(clear[..., None], ours / safe_ours_depth[..., None], 0.0)
    # np.allclose's test, |ours - theirs| <= atol + rtol |theirs|, without its overhead; atol
    # scaled by each point's largest residual.
    largest = np.max(np.abs(theirs), axis=(1, 2), keepdims=True)
    # A ratio whose terms are far larger than itself (a point near a principal plane, data far
    # from the origin) is known in either frame only to the round-off of those terms.
    tolerance = 1e-9 * (1 + largest) + 1e-6 * np.abs(theirs) + TERMS_ROUNDING * (
        numerator_size + np.abs(theirs) * depth_size[..., None]) / np.abs(safe_depths)[..., None]
    if not (np.abs(ours - theirs) <= strictness * tolerance).all():
        raise Invalid("program", "the program's residuals differ from the data's")
    varying = ~program.exact & clear
    relative = np.sign(ours_depth) * np.sign(depths)
    for row, mask in zip(relative, varying):
        if mask.any() and not item.depths_agree(row[mask]):
            raise Invalid("program", "the program's depth signs differ from the data's")
    return allowance(ours[0], theirs[0], numerator_size[0], depth_size[0], depths[0], clear[0])


# How far a residual computed from the raw data in floating point may lie from its exact value:
# this fraction of its terms' size over its depth (a dot product of a few terms rounds by a few
# units in the last place of their magnitudes' sum; 1e-15 is some 9).
RAW_ROUNDING = 1e-15


def allowance(ours, theirs, numerator_size, depth_size, depths, clear) -> np.ndarray:
    """How far the program's residuals (``ours``, caller's units) may lie from the data's exact
    ones at a point: their distance from the raw residuals (``theirs``) plus the raw ones'
    rounding (RAW_ROUNDING); infinite for an observation whose depth is round-off there."""
    safe = np.where(clear, np.abs(depths), 1.0)[..., None]
    rounding = RAW_ROUNDING * (numerator_size + np.abs(theirs) * depth_size[..., None]) / safe
    return np.where(clear[..., None], np.abs(ours - theirs) + rounding, np.inf)


# The solvers lower their claimed bound by this many times the discount they measure: the
# discount is a measured rounding difference between program and data, and the verifier measures
# it again on the program it rebuilds (on another machine's kernels, seen 1.09 times the solver's).
SOLVER_DISCOUNT_FACTOR = 2.0


def program_discount(item, solution, residuals: np.ndarray, allowed: np.ndarray) -> float:
    """What the bound a proof establishes for the program is lowered by, for the data's problem
    (caller's units): the cost's change at the solution when each residual moves by its
    ``allowed`` distance between program and data (allowance). A bound holds for the program
    the verifier builds, which is the data's problem only up to its rounding: for data far from
    the origin (a homography's source at 1e6 times its spread) that reaches 1e-8 of the cost."""
    if not rounding_counted():  # as certificates written before it was counted computed a bound
        return 0.0
    return cost_rounding(residuals, allowed, item.norm)


def program_allowance(item, solution, scale: float) -> np.ndarray:
    """allowance at the solution alone (what the solvers lower their claimed bound by, as the
    verifier does: program_discount)."""
    v0 = item.to_program(solution)
    V = np.append(v0, 1.0)[None]
    numerators, depths = item.raw_parts_many(v0[None])
    numerator_size, depth_size = item.raw_sizes_many(v0[None])
    ours = np.einsum("Nmk,nk->nNm", item.program.num, V)[0] / scale
    ours = ours / (item.program.den @ V[0])[:, None]
    clear = np.abs(depths[0]) > 1e-6 * depth_size[0]
    theirs = numerators[0] / np.where(clear, depths[0], 1.0)[:, None]
    return allowance(ours, theirs, numerator_size[0], depth_size[0], depths[0], clear)


# How far a root's stated bounds may lie beyond the proven ones the verifier recomputes
# (_check_stated_root), as a share of their size: the solver pads them by 1e-7 (search.prove_root).
ROOT_AGREEMENT = 1e-6


def _check_root(program, F: np.ndarray, gamma: float, needed: float, root: dict, lower, upper,
                witness: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The root region's bounds, as proven (the claimed ones widened by rounding: coverage.
    widened). Dual bounds hold on R ∩ claim; they hold on all of R (R convex) only when R meets
    the inside of ``claim``: the returned solution (``witness``, in the program's variables)
    must be a point of R well inside ``claim``."""
    if not gamma >= needed:
        raise Invalid("root_region", f"gamma {gamma!r} is below the residual bound {needed!r} of the claimed lower bound")
    charge(len(program.den), "the root region")
    region = residual_region(program, gamma)
    claim_lo, claim_hi = _numbers(root.get("claim"), "proof/root/claim", (2, len(F)))
    V = np.append(witness, 1.0)
    numerators, depths = program.num @ V, program.den @ V
    linear = program.linear @ V
    inside_region = (np.all(np.sqrt((numerators * numerators).sum(axis=1)) <= gamma * depths)
                     and np.all(linear >= -1e-12 * np.abs(program.linear) @ np.abs(V)))
    y = F @ witness
    margin = 1e-9 * (1 + np.abs(claim_lo) + np.abs(claim_hi))
    if not (inside_region and np.all(claim_lo + margin < y) and np.all(y < claim_hi - margin)):
        raise Invalid("root_region", "the solution is not a point of the residual region inside the claimed box: "
                                     "the region's bounds may be vacuous")
    texts = root.get("duals")
    if not isinstance(texts, list) or len(texts) != 2 * len(F):
        raise Invalid("root_region", f"{len(F)} functionals need {2 * len(F)} dual vectors")
    duals = [dual_vector(text, len(region[1])) for text in texts]
    proven_lower, proven_upper = root_bounds(region, F, duals, claim_lo, claim_hi)
    for j, (low, high) in enumerate(zip(proven_lower, proven_upper)):
        if not (claim_lo[j] < low <= high < claim_hi[j]):
            raise Invalid("root_region", f"functional {j}: proven range [{low}, {high}] not inside the claimed box")
    proven = widened(lower, upper, proven_lower, proven_upper)
    if proven is None:
        raise Invalid("root_region", f"bounds {lower.tolist()}, {upper.tolist()} are tighter than the proven "
                                     f"{proven_lower.tolist()}, {proven_upper.tolist()}")
    _check_stated_root(claim_lo, claim_hi, lower, upper, proven_lower, proven_upper)
    return proven


def _check_stated_root(claim_lo, claim_hi, lower, upper, proven_lower, proven_upper) -> None:
    """The root's stated bounds agree with what is recomputed, not only enclose it: they are the
    proven ones (padded by the solver by 1e-7 of their size), not looser by more than
    ROOT_AGREEMENT of it. A looser bound would still be sound (the search must cover what is
    stated), but it is not the proof the solver wrote: a document edited there is refused. (The
    claimed box is the solver's choice around its own estimates, which a batched solve's barrier
    makes inexact: it is held only to enclose the proven range strictly, above.)"""
    if not np.all(stated_root_agrees(claim_lo, claim_hi, lower, upper, proven_lower, proven_upper)):
        raise Invalid("root_region", f"bounds {lower.tolist()}, {upper.tolist()} are looser than the proven "
                                     f"{proven_lower.tolist()}, {proven_upper.tolist()} by more than "
                                     f"{ROOT_AGREEMENT:g} of their size: they are not the proof's")


def stated_root_agrees(claim_lo, claim_hi, lower, upper, proven_lower, proven_upper) -> np.ndarray:
    """_check_stated_root's test, per functional (the arrays' last axis; stacked.py's too)."""
    size = 1 + np.abs(proven_lower) + np.abs(proven_upper)
    return (lower >= proven_lower - ROOT_AGREEMENT * size) & (upper <= proven_upper + ROOT_AGREEMENT * size)


def _finite_bounds(data, where: str) -> None:
    """Every variable of a relaxation bounded on both sides: no term of a safe bound is dropped."""
    if not (np.all(np.isfinite(data.lower)) and np.all(np.isfinite(data.upper))):
        raise Invalid("leaf_bounds", f"{where}: a relaxation variable has an infinite bound")


def _check_round(relaxation: Relaxation, round_: Any, box: Box, proven_box: Box, cap: float,
                 number: int) -> tuple[Box, Box]:
    """A tightening round from the previous round's box (``box`` as claimed, ``proven_box`` as
    proven): its box_out as claimed, and as proven (its relaxation is built on the proven box in,
    and each side claimed is widened to the proven one: coverage.widened)."""
    record(round_, f"tightening round {number}", ("upper_bound", "box_in", "box_out", "duals"))
    k = len(box.lo)
    ub = _number(round_.get("upper_bound"), f"tightening/{number}/upper_bound")
    box_in = _box(round_.get("box_in"), f"tightening/{number}/box_in", k)
    box_out = _box(round_.get("box_out"), f"tightening/{number}/box_out", k)
    if not (np.array_equal(box_in.lo, box.lo) and np.array_equal(box_in.hi, box.hi)):
        raise Invalid("tightening", f"round {number} starts from a box that is not the previous one")
    if not ub >= cap:
        raise Invalid("tightening", f"round {number} assumed a cost cap below the claimed lower bound")
    duals = round_.get("duals")
    if not isinstance(duals, list) or len(duals) != 2 * k:
        raise Invalid("tightening", f"round {number}: {k} functionals need {2 * k} dual vectors")
    if all(z is None for z in duals):  # nothing proven: every side must stay as it was
        if not (np.array_equal(box_out.lo, box_in.lo) and np.array_equal(box_out.hi, box_in.hi)):
            raise Invalid("tightening", f"round {number}: sides moved without a dual vector")
        return box_out, proven_box
    low, high = _proven_sides(relaxation, proven_box, ub, duals, f"tightening round {number}", "tightening")
    proven_lo, proven_hi = np.maximum(proven_box.lo, low), np.minimum(proven_box.hi, high)
    sides = widened(box_out.lo, box_out.hi, proven_lo, proven_hi)
    if sides is None:
        raise Invalid("tightening", f"round {number}: sides [{box_out.lo.tolist()}, {box_out.hi.tolist()}] are "
                                    f"beyond the proven [{proven_lo.tolist()}, {proven_hi.tolist()}]")
    return box_out, Box(*sides)


MAX_CAP_ROUNDS = 8  # rounds of per-term caps (the solver makes 2)


def _check_caps(relaxation: Relaxation, rounds: Any, box: Box, proven_box: Box, cap: float) -> list[np.ndarray | None]:
    """Rounds of per-term caps (maps): each proves, over a box holding the proven root box and
    for every point costing at most its upper_bound, a lower bound on the sum of the terms other
    than each of its observations'. Returns the bounds in force after each round (the first,
    None: no caps), which the relaxations of the leaves that name that round are built with."""
    if not isinstance(rounds, list):
        raise Invalid("format", "proof/caps must be a list")
    if len(rounds) > MAX_CAP_ROUNDS:
        raise Invalid("tightening", f"{len(rounds)} rounds of caps: at most {MAX_CAP_ROUNDS}")
    count = len(relaxation.program.den)
    in_force: list[np.ndarray | None] = [None]
    others = np.zeros(count)
    for number, round_ in enumerate(rounds):
        where = f"caps round {number}"
        record(round_, where, ("upper_bound", "box", "observations", "duals"))
        ub = _number(round_.get("upper_bound"), f"caps/{number}/upper_bound")
        if not ub >= cap:
            raise Invalid("tightening", f"{where} assumed a cost cap below the claimed lower bound")
        round_box = _box(round_.get("box"), f"caps/{number}/box", len(box.lo))
        # Every point the leaves must answer for lies in the proven root box.
        if not (np.all(round_box.lo <= box.lo) and np.all(round_box.hi >= box.hi)):
            raise Invalid("tightening", f"{where}: its box does not contain the proven root box")
        round_box = Box(np.minimum(round_box.lo, proven_box.lo), np.maximum(round_box.hi, proven_box.hi))
        observations, duals = round_.get("observations"), round_.get("duals")
        if not (isinstance(observations, list) and all(type(i) is int and 0 <= i < count for i in observations)
                and len(set(observations)) == len(observations)):
            raise Invalid("format", f"{where}: observations must be distinct indices of observations")
        if not isinstance(duals, list) or len(duals) != len(observations):
            raise Invalid("tightening", f"{where}: one dual vector (or null) per observation")
        relaxation.others = in_force[-1]
        charge(len(relaxation.program.den), where)
        data = relaxation.conic_data(round_box, ub)
        if data is None:
            raise Invalid("tightening", f"{where}: no depth is positive on its box")
        _finite_bounds(data, where)
        data = with_cost_cap(data, ub)
        others = others.copy()
        for i, index, z in zip(observations, relaxation.term_variables(np.array(observations, dtype=int)), duals):
            if z is None:
                continue
            objective = data.q.copy()
            objective[index] = 0.0  # the sum of the other terms
            value = safe_lower_bound(objective, data.A, data.b, data.cones, dual_vector(z, len(data.b)),
                                     data.lower, data.upper, data.transform)
            others[i] = max(others[i], value)
        in_force.append(others)
    relaxation.others = None
    return in_force


def _proven_sides(relaxation: Relaxation, box: Box, ub: float, duals: list, where: str,
                  check: str) -> tuple[np.ndarray, np.ndarray]:
    """The range of each ``B_i v`` over the relaxation's points of ``box`` costing at most
    ``ub``, as the dual vectors prove it (``duals[2 i]`` the low side, ``duals[2 i + 1]`` the
    high one); a side without a dual is unbounded."""
    k = len(box.lo)
    charge(len(relaxation.program.den), where)
    data = relaxation.conic_data(box, ub, envelope=False)
    if data is None:
        raise Invalid(check, f"{where}: no depth is positive on its box")
    _finite_bounds(data, where)
    data = with_cost_cap(data, ub)
    low, high = np.full(k, -np.inf), np.full(k, np.inf)
    for i in range(k):
        for side, sign in ((0, 1.0), (1, -1.0)):
            z = duals[2 * i + side]
            if z is None:
                continue
            objective = tightening_objective(data, relaxation.B[i], sign)
            value = sign * safe_lower_bound(objective, data.A, data.b, data.cones, dual_vector(z, len(data.b)),
                                            data.lower, data.upper, data.transform)
            if sign > 0:
                low[i] = value
            else:
                high[i] = value
    return low, high


def _check_leaf_proofs(relaxation: Relaxation, proofs: list, leaves: list, leaf_lo, leaf_hi,
                       cap: float, k: int, others: list[np.ndarray | None], faces: tuple[Box, Box]) -> list[float]:
    """Each proof's bound, recomputed (its relaxation with the caps in force after the round it
    names, ``others``) on its box extended to the proven searched box (``faces``: the searched
    box as claimed and as proven, coverage.extended); each leaf's box inside its proof's box."""
    proven: list[float] = []
    boxes: list[Box] = []
    ranges: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # tightened proofs' proven ranges
    for number, proof in enumerate(proofs):
        record(proof, f"proofs/{number}", ("box", "upper_bound", "kind", "z", "bound"),
               ("duals", "caps") if proof.get("kind") == "tightened" else ("caps",))
        # Read only for a dual proof (its bound) or with a dual vector (z): otherwise informational.
        informational(proof.get("bound"), f"proofs/{number}/bound")
        informational(proof.get("z"), f"proofs/{number}/z", "text")
        box = _box(proof.get("box"), f"proofs/{number}/box", k)
        box = Box(*extended(box.lo, box.hi, *faces))
        boxes.append(box)
        # null: no cost cap (a box closed before any incumbent): the relaxation of every point
        # of the scope, valid whatever the cap; unbounded variables without max_residual are refused.
        raw = proof.get("upper_bound")
        ub = math.inf if raw is None else _number(raw, f"proofs/{number}/upper_bound")
        if not ub >= cap:
            raise Invalid("leaf_bounds", f"proof {number} assumed a cost cap below the claimed lower bound")
        kind = proof.get("kind")
        charge(len(relaxation.program.den), f"proof {number}")
        rounds = proof.get("caps", 0)
        if not (type(rounds) is int and 0 <= rounds < len(others)):
            raise Invalid("format", f"proof {number}: caps must name a round of caps (0: none)")
        relaxation.others = others[rounds]
        if kind == "tightened":  # node tightening: its leaves lie outside the range it proves
            duals = proof.get("duals")
            if not isinstance(duals, list) or len(duals) != 2 * k:
                raise Invalid("leaf_bounds", f"proof {number}: {k} functionals need {2 * k} dual vectors")
            ranges[number] = _proven_sides(relaxation, box, ub, duals, f"proof {number}", "leaf_bounds")
            proven.append(math.inf)
            continue
        if kind == "depth":  # the depth ranges alone decide it (what conic_data tests first)
            if not np.any(relaxation.depth_range(box)[1] <= 0):
                raise Invalid("leaf_bounds", f"proof {number}: the depths are not all negative on its box")
            proven.append(math.inf)
            continue
        data = relaxation.conic_data(box, ub)
        if data is None:
            raise Invalid("leaf_bounds", f"proof {number}: no relaxation on a box without positive depths")
        _finite_bounds(data, f"proof {number}")
        z = dual_vector(proof.get("z"), len(data.b))
        if kind == "farkas":
            if not proves_infeasible(data.A, data.b, data.cones, z, data.lower, data.upper, data.transform):
                raise Invalid("leaf_bounds", f"proof {number}: its Farkas vector does not prove infeasibility")
            proven.append(math.inf)
            continue
        if kind != "dual":
            raise Invalid("format", f"proof {number}: unknown kind {kind!r}")
        bound = safe_lower_bound(data.q, data.A, data.b, data.cones, z, data.lower, data.upper, data.transform)
        claimed = _number(proof.get("bound"), f"proofs/{number}/bound")
        if not bound >= claimed - LEAF_CLAIM_TOLERANCE * (abs(claimed) + abs(bound)):
            raise Invalid("leaf_bounds", f"proof {number}: its dual proves {bound!r}, it claims {claimed!r}")
        proven.append(bound)
    bounds = []
    for number, leaf in enumerate(leaves):
        index = leaf[2]
        if index is None:
            bounds.append(0.0)  # the trivial bound: every cost is a sum of norms
            continue
        box = boxes[index]
        if not (np.all(box.lo <= leaf_lo[number]) and np.all(box.hi >= leaf_hi[number])):
            raise Invalid("leaf_bounds", f"leaf {number} is not inside the box of its proof {index}")
        if index in ranges:
            low, high = ranges[index]
            # Strictly outside: a point on a proven side may cost at most the proof's upper_bound.
            if not np.any((leaf_hi[number] < low) | (leaf_lo[number] > high) | (low > high)):
                raise Invalid("leaf_bounds", f"leaf {number} is not outside the range its proof {index} proves")
        bounds.append(proven[index])
    return bounds
