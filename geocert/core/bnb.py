"""One branch-and-bound engine for every problem kind (thesis 4.3, Algorithms 1 and 2).

A problem supplies a root box, an incumbent, a bound on a box (a convex relaxation), the true
objective at a candidate, and how to split a box. The engine owns the queue, pruning, stopping
rules and the anytime result. Progress goes to a callback after every node; the callback may
stop the search by returning True or raising StopIteration (scipy.optimize's pattern).
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np


def asks_to_stop(callback: Callable[[Any], Any] | None, progress: Any) -> bool:
    """Report progress to a callback; True when it asks to stop, by returning a true value or
    raising StopIteration (scipy.optimize's pattern). Every solver's progress goes through here."""
    if callback is None:
        return False
    try:
        return bool(callback(progress))
    except StopIteration:
        return True


class BoxStatus:
    BOUNDED = "bounded"  # a trustworthy lower bound
    EMPTY = "empty"  # no point of the box can beat the incumbent (or no point at all)
    UNRESOLVED = "unresolved"  # the convex solve was not clean: keep the parent's bound


@dataclass
class Box:
    lo: np.ndarray
    hi: np.ndarray

    @property
    def width(self) -> np.ndarray:
        return self.hi - self.lo


@dataclass
class BoxBound:
    status: str
    lower_bound: float = -math.inf
    candidate: Any = None  # a point of the domain to try as incumbent (problem-specific)
    split_hint: Any = None  # e.g. the relaxation's point, for the split rule
    proof: Any = None  # what proves lower_bound (or emptiness) to a third party, when asked for
    # Node tightening: the problem may shrink the box it was asked to bound. ``box`` is then the
    # part the bound is for, and ``excluded`` the rest as (box, proof) pairs, each proven to hold
    # no point cheaper than the incumbent of the moment; together they cover the asked box. EMPTY
    # with ``excluded`` and no ``box``: the excluded parts are the whole box.
    box: Box | None = None
    excluded: list = field(default_factory=list)


class BranchProblem(Protocol):
    def root_box(self) -> Box: ...

    def bound(self, box: Box, upper_bound: float) -> BoxBound: ...

    def objective(self, candidate: Any) -> float: ...

    def improve(self, candidate: Any) -> tuple[Any, float]: ...

    def split(self, box: Box, bound: BoxBound) -> list[Box]: ...


@dataclass
class BnbOptions:
    rel_gap: float = 1e-3
    abs_gap: float = 1e-9
    max_nodes: int = 10_000
    time_limit_s: float = 60.0
    min_box_width: float = 1e-12  # an unresolved box smaller than this is left as an open leaf


@dataclass
class Progress:
    nodes: int
    open_boxes: int
    lower_bound: float
    upper_bound: float
    gap_abs: float
    gap_rel: float
    elapsed_s: float


@dataclass
class BnbResult:
    status: str  # optimal, node_limit, time_limit, cancelled, not_certified
    candidate: Any
    upper_bound: float
    lower_bound: float
    nodes: int
    leaves: int  # boxes closed by their bound (pruned or empty) plus open ones at the stop
    unresolved: int
    elapsed_s: float
    tolerance: float


def tolerance(upper_bound: float, options: BnbOptions) -> float:
    if not math.isfinite(upper_bound):
        return options.abs_gap
    return max(options.abs_gap, options.rel_gap * abs(upper_bound))


def relative_gap(upper_bound: float, lower_bound: float) -> float:
    if not math.isfinite(upper_bound) or not math.isfinite(lower_bound):
        return math.inf
    if upper_bound == 0:
        return 0.0 if lower_bound >= 0 else math.inf
    return max(0.0, (upper_bound - lower_bound) / abs(upper_bound))


def branch_and_bound(
    problem: BranchProblem,
    incumbent: Any,
    upper_bound: float,
    options: BnbOptions,
    callback: Callable[[Progress], bool | None] | None = None,
    trivial_lower_bound: float = 0.0,
    leaves: list | None = None,
) -> BnbResult:
    """Minimise the problem's objective over its root box, returning an anytime certified result.

    ``trivial_lower_bound`` is a bound valid everywhere (0 for sums of residual norms); an
    unresolved box that cannot be split further falls back to it, never to a guess.
    ``leaves``, when given, receives ``(box, proof)`` for every leaf of the tree: together the
    boxes cover the root, and each proof is the one behind the bound the box was closed with
    (its own relaxation's, or an ancestor's when that was higher or its own solve failed; None
    for the trivial bound).
    """
    start = time.perf_counter()
    counter = itertools.count()
    heap: list[tuple[float, int, Box, BoxBound, Any]] = []
    closed_min = math.inf  # smallest bound among boxes closed by pruning
    closed_count = 0
    unresolved = 0
    nodes = 0
    stuck: list[Box] = []  # unresolved and too small to split: only the trivial bound holds

    def close(box: Box, bound: float, proof: Any) -> None:
        nonlocal closed_min, closed_count
        closed_min = min(closed_min, bound)
        closed_count += 1
        if leaves is not None:
            leaves.append((box, proof))

    def consider(box: Box, parent_bound: float, parent_proof: Any) -> None:
        nonlocal nodes, incumbent, upper_bound, unresolved
        nodes += 1
        asked = upper_bound
        result = problem.bound(box, upper_bound)
        for part, part_proof in result.excluded:
            close(part, max(parent_bound, asked), part_proof)
        if result.box is not None:
            box = result.box
        elif result.excluded and result.status == BoxStatus.EMPTY:
            return  # the excluded parts are the whole box
        if result.candidate is not None:
            value = problem.objective(result.candidate)
            if value < upper_bound - tolerance(upper_bound, options):
                result.candidate, value = problem.improve(result.candidate)
            if value < upper_bound:
                incumbent, upper_bound = result.candidate, value
        if result.status == BoxStatus.EMPTY:
            # Nothing in this box beats the incumbent of the moment: that value bounds it.
            close(box, max(parent_bound, upper_bound), result.proof)
            return
        if result.status == BoxStatus.UNRESOLVED:
            unresolved += 1
            if float(np.max(box.width)) <= options.min_box_width:
                # Cannot be bounded and too small to split: it keeps only the trivial bound.
                stuck.append(box)
                return
            bound, proof = parent_bound, parent_proof
        elif result.lower_bound >= parent_bound:
            bound, proof = result.lower_bound, result.proof
        else:
            bound, proof = parent_bound, parent_proof
        if bound >= upper_bound - tolerance(upper_bound, options):
            close(box, bound, proof)
        else:
            heapq.heappush(heap, (bound, next(counter), box, result, proof))

    def global_lower_bound() -> float:
        open_min = heap[0][0] if heap else math.inf
        stuck_min = trivial_lower_bound if stuck else math.inf
        value = min(open_min, closed_min, stuck_min)
        return value if math.isfinite(value) else upper_bound

    status = "optimal"
    consider(problem.root_box(), trivial_lower_bound, None)
    while True:
        lower = global_lower_bound()
        if upper_bound - lower <= tolerance(upper_bound, options):
            status = "optimal"
            break
        if not heap:
            status = "not_certified"
            break
        elapsed = time.perf_counter() - start
        if callback is not None and asks_to_stop(callback, Progress(
                nodes, len(heap), lower, upper_bound, upper_bound - lower, relative_gap(upper_bound, lower), elapsed)):
            status = "cancelled"
            break
        if nodes >= options.max_nodes:
            status = "node_limit"
            break
        if elapsed >= options.time_limit_s:
            status = "time_limit"
            break
        bound, _, box, box_bound, proof = heapq.heappop(heap)
        if bound >= upper_bound - tolerance(upper_bound, options):
            close(box, bound, proof)
            continue
        for child in problem.split(box, box_bound):
            consider(child, bound, proof)

    if leaves is not None:
        leaves.extend((entry[2], entry[4]) for entry in heap)
        leaves.extend((box, None) for box in stuck)
    lower = global_lower_bound()
    lower = max(lower, trivial_lower_bound)
    return BnbResult(
        status=status,
        candidate=incumbent,
        upper_bound=upper_bound,
        lower_bound=min(lower, upper_bound),
        nodes=nodes,
        leaves=closed_count + len(heap) + len(stuck),
        unresolved=unresolved,
        elapsed_s=time.perf_counter() - start,
        tolerance=tolerance(upper_bound, options),
    )
