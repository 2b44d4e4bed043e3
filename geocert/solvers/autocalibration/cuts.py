"""What both stages' searches share: a box's bound from its relaxation (a safe dual bound, a
Farkas vector, or no domain point at all), and tightening a box before it is split (each
coordinate minimised and maximised over the box's relaxation with the cost capped at the
incumbent's). What remains is halved; the slabs cut off are leaves closed by a cut proof (a safe
dual bound), which the verifier rebuilds (proofs.check_leaves)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from geocert.core.bnb import Box, BoxBound, BoxStatus
from geocert.core.certificates import LeafProof
from geocert.core.conic import ConicStatus, ReusableConicProgram
from geocert.core.coverage import SIDE_TOLERANCE
from geocert.core.cones import proves_infeasible, safe_lower_bound, safe_lower_bounds_and_margins

# Where the solves of both stages' searches stop (node bounds and tightening), instead of 1e-9:
# every bound taken is the safe bound of whatever dual a solve returns, so a looser solve moves a
# bound by about this much of the cost scale (about 1 at the incumbent), far below the stages'
# gaps (1e-5, 1e-4), and programs that stall short of 1e-9 (AlmostSolved: 24 to 36 of some 230
# solves on 20 views) are not solved again. Measured on 20 views: the same nodes, 0.57 to 0.59
# times the CPU per stage (docs/benchmarks.md).
SOLVE_TOLERANCE = 1e-7


@dataclass
class CutProof(LeafProof):
    """Every point of ``box`` costing at most ``upper_bound`` has sign * x[axis] >= value (a
    safe dual bound over the relaxation with the cost capped): the slab of the box beyond that
    value holds no such point."""

    axis: int = 0
    sign: float = 1.0
    value: float = 0.0


def side_bounds(program, dims: int, stop: Callable[[], bool] | None = None) -> list[tuple[int, float, float, np.ndarray]]:
    """(k, sign, value, z) for each of the first ``dims`` variables and each sign whose solve
    returned a dual with a finite safe bound: sign * x_k >= value over the program's feasible
    set, a safe dual bound by z.
    ``stop()`` is asked before each solve: once true, the bounds found so far are returned."""
    solver = ReusableConicProgram(lean=False, tolerance=SOLVE_TOLERANCE)
    solved = []
    for k, sign in ((k, sign) for k in range(dims) for sign in (1.0, -1.0)):
        if stop is not None and stop():
            break
        q = np.zeros_like(program.q)
        q[k] = sign
        result = solver.solve(q, program.A, program.b, program.cones) if not (k or sign < 0) \
            else solver.solve_objective(q)
        if result.z is None or result.status in (ConicStatus.INFEASIBLE, ConicStatus.UNBOUNDED):
            continue  # (any other dual iterate gives a safe bound, as in BoxSearch.bound)
        solved.append((k, sign, q, result.z))
    if not solved:
        return []
    # one projection and one product for all the duals (they share the feasible set)
    values = reproducible_bounds(np.array([q for _, _, q, _ in solved]), program,
                                 np.array([z for _, _, _, z in solved]))
    return [(k, sign, float(value), z) for (k, sign, _, z), value in zip(solved, values) if math.isfinite(value)]


def reproducible_bounds(Q: np.ndarray, program, Z: np.ndarray) -> np.ndarray:
    """Each row's safe bound less twice its rounding margin: what the verifier computes at least,
    whatever the order of its sums. A safe bound is its computed value less the margin its
    rounding may have moved it by; computed in another order (the verifier rebuilds each cut alone,
    another machine sums otherwise) it lies within twice that margin of this one. A side placed at
    the bound as computed here held only to that order: on a box whose cut took a dual of 1e6 to
    1e10 (the capped program nearly empty), the margin was up to 17 of the verifier's tolerances
    and the cut, rebuilt alone, fell short of its own slab by 0.07 of one. Below the margin the
    move is nothing (1e-4 of a tolerance on most cuts)."""
    values, margins = safe_lower_bounds_and_margins(Q, program.A, program.b, program.cones, Z, program.lower,
                                                    program.upper)
    return values - 2.0 * margins


def verifier_growth(lo: np.ndarray, hi: np.ndarray) -> float:
    """How far the verifier may grow a box of a search over [lo, hi] before it recomputes a bound
    over it: twice its tolerance for rounding, SIDE_TOLERANCE of the box's size (its largest
    coordinate and width: coverage.widened, proofs.check_leaves)."""
    size = float(np.max(np.abs(np.concatenate([lo, hi, hi - lo]))))
    return 2.0 * SIDE_TOLERANCE * size if math.isfinite(size) else 0.0


def grown_values(build_capped: Callable, box: Box, cap: float, growth: float, program,
                  found: list[tuple[int, float, float, np.ndarray]]) -> list[float]:
    """Each cut's value recomputed with its own dual over the box grown by ``growth`` on every
    side, the cut's own where that program has another shape (or none)."""
    try:
        grown = build_capped(box.lo - growth, box.hi + growth, cap)
    except ValueError:
        grown = None
    if grown is None or grown.A.shape != program.A.shape:
        return [value for _, _, value, _ in found]
    values = reproducible_bounds(np.array([np.eye(len(grown.q))[k] * sign for k, sign, _, _ in found]), grown,
                                 np.array([z for _, _, _, z in found]))
    return [min(value, float(again)) if math.isfinite(again) else value
            for (_, _, value, _), again in zip(found, values)]


def tighten_box(build_capped: Callable, box: Box, cap: float, record: bool, stop: Callable[[], bool] | None = None,
                growth: float = 0.0) -> tuple[list[tuple[Box, CutProof]], Box | None]:
    """The slabs of the box its tightening cuts off, each with its cut, in a guillotine order
    (they and what remains partition the box), and what remains (None when nothing does).
    ``build_capped(lo, hi, cap)`` is the relaxation with the cost capped; its first variables are
    the box's coordinates. ``stop()`` ends the tightening early (side_bounds): the cuts found so
    far stand, and what remains is only less tight.

    ``growth``: how far the verifier may grow the box before it recomputes a cut over it (it
    extends leaves over the slivers a cut's rounding leaves, proofs._moved_faces, up to
    coverage.SIDE_TOLERANCE of the root box). The cut's safe bound over a grown box can drop far
    more than the growth (measured: a box grown by 2.3e-14 moved a cut by 4.7e-9, its leaf then
    refused as "not beyond the cut"): each slab ends at the smaller of the values over the box and
    over the box grown on every side, so that it stays beyond its cut as the verifier reads it."""
    try:
        program = build_capped(box.lo, box.hi, cap)
    except ValueError:
        return [], box
    if program is None:
        return [], box
    current_lo, current_hi = box.lo.copy(), box.hi.copy()
    slabs: list[tuple[Box, CutProof]] = []
    found = side_bounds(program, len(box.lo), stop)
    if growth > 0 and found:
        found = [(k, sign, value, z) for (k, sign, _, z), value
                 in zip(found, grown_values(build_capped, box, cap, growth, program, found))]
    for k, sign, value, z in found:
        side = value if sign > 0 else -value  # points costing <= cap: x_k >= side (or <= side)
        if sign > 0 and side > current_lo[k]:
            slab_hi = current_hi.copy()
            slab_hi[k] = min(side, current_hi[k])
            slab = Box(current_lo.copy(), slab_hi)
            current_lo[k] = side
        elif sign < 0 and side < current_hi[k]:
            slab_lo = current_lo.copy()
            slab_lo[k] = max(side, current_lo[k])
            slab = Box(slab_lo, current_hi.copy())
            current_hi[k] = side
        else:
            continue
        slabs.append((slab, CutProof(box, cap, "cut", z.copy() if record else None, cap,
                                     axis=k, sign=sign, value=value)))
        if current_lo[k] >= current_hi[k]:
            return slabs, None  # nothing of the box costs at most cap
    return slabs, Box(current_lo, current_hi)


class BoxSearch:
    """The bound and split of a stage's branch-and-bound problem (core.bnb.BranchProblem); a
    stage supplies ``build(lo, hi, cap, cap_row=False)`` (its relaxation, or None where the box
    holds no point of the domain), ``unit`` (the programs' cost scale), ``root_lo``/``root_hi``
    (the widths splits are relative to), ``record`` and ``objective``/``improve``; and
    ``deadline`` (time.perf_counter's clock), past which a split tightens no further: with many
    views a box's tightening is ten programs of a tenth of a second or more, which the engine's
    clock, read between boxes, would not stop."""

    tightening = True  # tighten a box before splitting it
    deadline = math.inf

    def __init__(self, root_lo: np.ndarray, root_hi: np.ndarray, record: bool):
        self.root_lo, self.root_hi, self.record = root_lo, root_hi, record
        # how far the verifier may grow a box before recomputing its cuts (tighten_box): twice its
        # tolerance for a cut's rounding, SIDE_TOLERANCE of the root box's size (proofs.check_leaves)
        self.growth = verifier_growth(root_lo, root_hi)
        self.program = ReusableConicProgram(lean=False, tolerance=SOLVE_TOLERANCE)
        self.upper = math.inf  # the incumbent's cost at the last bound
        self.cuts: dict[int, CutProof] = {}  # slabs cut off, by id, until the engine closes them

    def bound(self, box: Box, upper_bound: float) -> BoxBound:
        cut = self.cuts.pop(id(box), None)
        if cut is not None:  # a slab its parent's tightening showed holds no point costing <= its cap
            return BoxBound(BoxStatus.EMPTY, cut.upper_bound, proof=cut if self.record else None)
        self.upper = min(self.upper, upper_bound)
        try:
            program = self.build(box.lo, box.hi, upper_bound if math.isfinite(upper_bound) else 1e300)
        except ValueError:
            return BoxBound(BoxStatus.UNRESOLVED)
        if program is None:  # no point of the domain in the box
            proof = LeafProof(box, upper_bound, "no_domain", None, math.inf) if self.record else None
            return BoxBound(BoxStatus.EMPTY, math.inf, proof=proof)
        result = self.program.solve(program.q, program.A, program.b, program.cones)
        if result.status is ConicStatus.INFEASIBLE and result.z is not None and proves_infeasible(
                program.A, program.b, program.cones, result.z, program.lower, program.upper):
            proof = LeafProof(box, upper_bound, "farkas", result.z.copy(), math.inf) if self.record else None
            return BoxBound(BoxStatus.EMPTY, math.inf, proof=proof)
        # The safe bound holds for any dual vector (projected onto the dual cone, its residual
        # charged over the variables' bounds), so the last iterate of a solve that did not end
        # cleanly is used too: on nearly degenerate boxes Clarabel can stop with NumericalError
        # a few digits from an optimum far above the incumbent (seen at 10 views, 0.1% noise,
        # where every such box kept its parent's bound of 0). Its bound is exactly what the
        # verifier recomputes; a poor iterate only gives a weak bound (the engine keeps the parent's
        # when that is higher).
        if result.z is None or result.status in (ConicStatus.INFEASIBLE, ConicStatus.UNBOUNDED):
            return BoxBound(BoxStatus.UNRESOLVED)
        bound = safe_lower_bound(program.q, program.A, program.b, program.cones, result.z,
                                 program.lower, program.upper) / self.unit
        if not math.isfinite(bound):
            return BoxBound(BoxStatus.UNRESOLVED)
        candidate = None
        if result.x is not None and np.all(np.isfinite(result.x[:len(box.lo)])):
            candidate = np.clip(result.x[:len(box.lo)], box.lo, box.hi)
        proof = LeafProof(box, upper_bound, "dual", result.z.copy(), bound) if self.record else None
        status = BoxStatus.EMPTY if bound >= upper_bound else BoxStatus.BOUNDED
        return BoxBound(status, bound, candidate=candidate, proof=proof)

    def past_deadline(self) -> bool:
        return time.perf_counter() > self.deadline

    def split(self, box: Box, bound: BoxBound) -> list[Box]:
        """Tighten the box, then halve what remains along its widest side relative to the root's."""
        slabs: list[Box] = []
        if self.tightening and math.isfinite(self.upper):
            cut_off, box = tighten_box(lambda lo, hi, cap: self.build(lo, hi, cap, cap_row=True), box, self.upper,
                                       self.record, self.past_deadline, self.growth)
            for slab, proof in cut_off:
                self.cuts[id(slab)] = proof
            slabs = [slab for slab, _ in cut_off]
            if box is None:
                return slabs
        axis = int(np.argmax(box.width / np.maximum(self.root_hi - self.root_lo, 1e-300)))
        middle = 0.5 * (box.lo[axis] + box.hi[axis])
        left_hi, right_lo = box.hi.copy(), box.lo.copy()
        left_hi[axis] = middle
        right_lo[axis] = middle
        return slabs + [Box(box.lo.copy(), left_hi), Box(right_lo, box.hi.copy())]
