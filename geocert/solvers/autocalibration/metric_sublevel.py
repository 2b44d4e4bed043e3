"""A proven interval of each intrinsic the metric stage finds: every K within the intrinsics ranges
whose metric cost (for the plane at infinity the stage states) is at most the optimum's plus
``increase`` has its focal lengths, skew and principal point within the intervals.

Read off a search of its own: the search's leaves bound the set at that level, not the optimum's
(a leaf of the stage's own search is closed at the incumbent's cost, below the level, so says
nothing of the omega costing between them). Let c be the returned K's cost (at least the
optimum) and U = c + increase (rounded up: proofs.sublevel_level). From the root box of omega
(the ranges'), rounds of bound tightening with the cost capped at ``cap`` > U (metric.tighten:
each side a safe dual bound) shrink the box to one holding every omega costing at most U; its
halves are then bounded over the relaxation with the same cap, and a box whose safe bound exceeds
U (or that holds no domain point, or whose relaxation is infeasible) is excluded; the others are
tightened at the cap (the slabs cut off, each closed by its cut, are excluded) and halved while
the budget lasts. A leaf without a safe bound excludes nothing.

The intervals are what the verifier reads off the encoded proof (proofs.sublevel_hull, the very
function its check calls): the hull, over the leaves not excluded, of each intrinsic's range on
the leaf, in pixels, with the leaves as the verifier reads them (those on the search box's faces
reach the box its tightening proves, which rounding may make a little wider than the one the
search ran on; leaves beyond a cut's rounding end at the cut). Taken here from the leaves as the
search left them, they came out narrower than the verifier's (by some 1e-6 pixels, 1e-9 of the
omega box's size on its faces), and a genuine result was refused."""

from __future__ import annotations

import math
import time

import numpy as np

from geocert.formulations.autocalibration import metric_relaxation
from geocert.formulations.autocalibration import proofs
from geocert.solvers.autocalibration.metric import MetricProblem, tighten
from geocert.core.bnb import Box
from geocert.core.strict import Invalid

CAP_MARGIN = 1e-4  # the programs' cap, this much above U: a leaf is excluded by a bound above U
EXCLUDE_MARGIN = 1e-6  # the search closes a box only when its bound exceeds U by this much
# The intervals stated are the verifier's hull with the leaves bounded within this much above U
# kept (another machine's rounding of a bound near U then narrows nothing), padded outward by
# STATED_SLACK of their half-width (and 1e-12 of their size).
HULL_MARGIN = 1e-7
STATED_SLACK = 1e-7
MAX_BOXES = 120  # programs of the search after the tightening (conic solves, a split's ten counted)
TIGHTENING_ROUNDS = 6


def prove(problem, p: np.ndarray, unit: float, cost: float, increase: float, time_limit_s: float = 10.0
          ) -> dict | None:
    """The stage's ``sublevel`` as its proof carries it (proofs.encode_sublevel), its intervals
    the verifier's reading of it (proofs.sublevel_hull); None when nothing is proven (no finite
    level, a failed tightening, a proof its own check refuses)."""
    if not (math.isfinite(cost) and math.isfinite(increase) and increase >= 0 and cost >= 0):
        return None
    began = time.perf_counter()
    setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
    setup.unit = unit
    U = proofs.sublevel_level(cost, increase)
    cap = U * (1 + CAP_MARGIN)

    def stop() -> bool:
        return time.perf_counter() - began > time_limit_s

    root_lo, root_hi = metric_relaxation.omega_box(problem.unit_ranges)
    lo, hi, rounds = tighten(setup, root_lo, root_hi, cap, 0.0, rounds=TIGHTENING_ROUNDS, stop=stop)
    search = MetricProblem(setup, lo, hi, record=True)
    search.upper, search.deadline = cap, began + time_limit_s  # its splits tighten at the cap
    open_boxes, leaves, programs = [Box(lo.copy(), hi.copy())], [], 0
    while open_boxes:
        box = open_boxes.pop(0)
        cut = id(box) in search.cuts
        if not cut and (programs >= MAX_BOXES or stop()):
            leaves.append((box, None))  # not bounded: kept (it excludes nothing)
            continue
        programs += 0 if cut else 1
        bound = search.bound(box, cap)
        proof = bound.proof
        if proof is not None and (proof.kind in ("no_domain", "farkas", "cut")
                                  or (proof.kind == "dual" and proof.bound > U * (1 + EXCLUDE_MARGIN))):
            leaves.append((box, proof))  # a cut's slab holds no omega costing at most the cap
            continue
        if metric_relaxation.intrinsics_ranges(setup.ranges, box.lo, box.hi) is None or programs >= MAX_BOXES or stop():
            leaves.append((box, None))
            continue
        programs += 10  # the split's tightening: each side minimised and maximised at the cap
        open_boxes += search.split(box, bound)
    sublevel = proofs.encode_sublevel({"cost_increase": float(increase), "rounds": rounds, "search_lo": lo,
                                       "search_hi": hi, "leaves": leaves, "intervals": np.zeros((5, 2))})
    try:
        intervals = proofs.sublevel_hull(problem, setup, sublevel, cost, HULL_MARGIN)
    except Invalid:
        return None
    half = 0.5 * (intervals[:, 1] - intervals[:, 0])
    pad = STATED_SLACK * half + 1e-12 * np.abs(intervals).max(axis=1)
    sublevel["intervals"] = np.stack([intervals[:, 0] - pad, intervals[:, 1] + pad], axis=1).tolist()
    return sublevel
