"""The search behind an L1 resection's proven intervals (fractional.resection_leaves): after the
certified search, a second one over the same program at the level U = (cost + cost_increase) plus
the program's distance from the data (scaled units), every part of it proven for the cameras
costing at most U: a root region of residual bound gamma_for(U), rounds of tightening at U, then
boxes of the branched functionals bounded at U (with node tightening), a box closed once its
bound exceeds U (it holds no such camera) and split otherwise, widest first, until MAX_NODES
boxes or the clock (which leaves the open boxes as kept leaves: wider intervals, never none). The
leaves not closed bound the set; the intervals are read off them as the
verifier reads them (resection_leaves.hull), stated a little wider (STATED_PAD)."""

from __future__ import annotations

import math
import time

import numpy as np

from geocert.core.bnb import Box, BoxStatus
from geocert.core.certificates import SearchProof, encode
from geocert.formulations.fractional.charts import MapChart
from geocert.formulations.fractional.relaxation import gamma_for
from geocert.formulations.fractional.resection_leaves import STATED_PAD, depth_row_map, hull
from geocert.solvers.fractional.search import BoxProblem, Prepared, root_region

# Boxes bounded at the level (each a few small SOCPs with node tightening). Measured on two
# cameras (12 points L1L1, 40 points L2L1): 30, 120 and 500 boxes gave intervals within 6% of
# one another (the relaxation's looseness at the level, not the boxes' size, sets their width).
MAX_NODES = 40
TIGHTEN_ROUNDS = 4
LEVEL_MARGIN = 1e-7  # the solver's level lies this much (relative) above the verifier's
KEEP_MARGIN = 1e-5  # a leaf is kept unless its recorded bound exceeds the level by this much (relative):
# the verifier's recomputed bound may lie below the recorded one by proof.LEAF_CLAIM_TOLERANCE


def leaves_sublevel(prepared: Prepared, chart: MapChart, v: np.ndarray, cost: float, increase: float,
                    discount: float, deadline: float) -> dict | None:
    """The proof/sublevel of an L1 resection certified by a search (``prepared``: its program,
    scaled, and branched functionals) at the camera of chart point ``v``, whose cost (caller's
    units) is ``cost``; None when no interval is proven (a root region not proven, the clock)."""
    if not (math.isfinite(cost) and math.isfinite(increase) and math.isfinite(discount)):
        return None
    problem0 = prepared.problem
    program, B, unit = problem0.program, problem0.B, prepared.unit
    level = ((cost + increase) * (1 + LEVEL_MARGIN) + 2 * discount) * unit
    gamma = gamma_for(level, program.norm)
    if program.max_residual is not None:
        gamma = min(gamma, program.max_residual)
    state, root, root_proof = root_region(program, B, gamma)
    if root is None:
        return None
    problem = BoxProblem(program, B, root, root_proof)
    problem.interior = v
    problem.node_tightening = True
    problem.deadline = deadline
    problem.relaxation.quadratic = False
    problem.root = problem.tighten(root, level, TIGHTEN_ROUNDS)
    search_box = problem.root
    scale = np.maximum(search_box.width, 1e-300)
    leaves: list = []  # (box, proof, kept)
    open_boxes: list = []  # (box, bound, proof, result)

    def consider(box: Box, parent_bound: float, parent_proof) -> None:
        result = problem.bound(box, level)
        for part, proof in result.excluded:
            leaves.append((part, proof, False))
        if result.box is not None:
            box = result.box
        elif result.excluded and result.status == BoxStatus.EMPTY:
            return
        if result.status == BoxStatus.EMPTY:
            leaves.append((box, result.proof, False))
            return
        if result.status == BoxStatus.BOUNDED and result.lower_bound >= parent_bound:
            bound, proof = result.lower_bound, result.proof
        else:
            bound, proof = parent_bound, parent_proof
        if bound > level * (1 + KEEP_MARGIN):
            leaves.append((box, proof, False))
        else:
            open_boxes.append((box, bound, proof, result))

    consider(search_box, 0.0, None)
    nodes = 1
    while open_boxes and nodes < MAX_NODES and time.perf_counter() < deadline:
        widest = max(range(len(open_boxes)), key=lambda i: float(np.max(open_boxes[i][0].width / scale)))
        box, bound, proof, result = open_boxes.pop(widest)
        if float(np.max(box.width / scale)) <= 1e-9:
            leaves.append((box, proof, True))
            continue
        for child in problem.split(box, result):
            consider(child, bound, proof)
            nodes += 1
    leaves.extend((box, proof, True) for box, _, proof, _ in open_boxes)  # kept: the clock only widens
    lo = np.array([box.lo for box, _, _ in leaves])
    hi = np.array([box.hi for box, _, _ in leaves])
    kept = np.array([flag for _, _, flag in leaves])
    c, G = depth_row_map(chart, root_proof.functionals[:len(B)])
    intervals = hull(c, G, lo, hi, kept, STATED_PAD)
    if intervals is None:
        return None
    encoded = encode(SearchProof(prepared.scale, root_proof, problem.tightening, search_box,
                                 [(box, proof) for box, proof, _ in leaves], problem.caps, False))
    return {"cost_increase": float(increase), "reference": int(chart.reference),
            "intervals": intervals.tolist(), "search": encoded}
