"""Proven intervals of an L1-norm resection (L1L1, L2L1), read off the leaves of a search at a
stated level: every camera of the scope (every point at positive depth) costing at most the
returned camera's cost plus ``cost_increase`` has its depth row within the intervals. Numpy only:
the solver states them (fractional.sublevel_search runs the search), the verifier recomputes them.

What the leaves bound is what a map's search branches on: the camera's last row, scaled so that
the reference point's depth is 1 (the chart's scale). That row is the camera's depth function
relative to the reference point's depth: a point X lies at depth_x X + depth_y Y + depth_z Z +
depth_0 times the reference point's depth (the principal plane, and the viewing direction, of the
camera). The other two rows are not branched, and the leaves say nothing of them: the camera
centre (which lies on that plane) is bounded beside them at the same level, when proven
(``sublevel.centre``: fractional.resection_centre_l1, checked here).

The proof is a branch-and-bound proof of the search's form (proof.checked_leaves), with every part
(root region, tightening rounds, caps, leaves) proven for the points costing at most the level
U = (cost + cost_increase + discount) * unit (scaled units; discount: the program's distance from
the data's problem at the camera, proof.program_discount). A leaf whose recomputed bound exceeds
U holds no camera costing at most U; the others bound the set. On each kept leaf's box of the
branched functionals z (the depth row is affine in them: depth row = c + G z), each entry's range
is its value at the box's centre plus or minus |G| times the half-widths; the intervals are the
hull of those ranges over the kept leaves, widened by ROUNDING of their size (the map z -> depth
row is computed in floating point; the stated ones must hold the recomputed hull).
"""

from __future__ import annotations

import math

import numpy as np

from geocert.core.determinacy import level_sigmas, proven_document
from geocert.core.geometry import norm_cost
from geocert.core.strict import Invalid, number, numbers, record
from geocert.formulations.fractional.charts import MapChart
from geocert.formulations.fractional.proof import checked_leaves
from geocert.formulations.fractional.resection_centre_l1 import NAMES as CENTRE_NAMES, verify_l1_centre

NAMES = ("depth_x", "depth_y", "depth_z", "depth_0")
NORMS = ("L1L1", "L2L1")
ROUNDING = 1e-9  # the verifier's allowance for its own rounding of c + G z, relative to the terms' size
STATED_PAD = 1e-7  # the solver states its intervals this much wider (relative to the terms' size)


def l1_cost_increase(norm: str, cost: float, points: int, gap: float | None) -> float:
    """The cost increase an L1 resection's intervals are proven at: the L1 counterpart of the
    L2L2 level (the squared level factor times the residual variance, at least the certified gap).
    Near the optimum an L1 cost grows by the squared-residual increase times the noise density at 0:
    1 / (sigma sqrt(2 pi)) per coordinate (L1L1), sqrt(pi / 2) / (2 sigma) per point (L2L1);
    with sigma estimated from the cost over 2k - 11 (respectively k - 5.5) residuals, s^2 sigma^2
    becomes s^2 cost / (2 (2k - 11)) (L1L1) and s^2 cost / (2k - 11) (L2L1). The factor s is the
    estimate's (level_sigmas of the 2k - 11 degrees of freedom: the Student quantile in the
    estimates' form 2, SIGMAS in earlier forms, so a document of those is read at their level):
    at SIGMAS whatever the degrees of freedom, 7-point resections of real cameras had proven centre
    boxes missing the truth where the estimate beside them held it (issue 37)."""
    redundancy = 2 * points - 11
    s2 = level_sigmas(redundancy) ** 2
    factor = s2 / 2 if norm == "L1L1" else s2
    delta = factor * cost / redundancy if redundancy > 0 else 0.0
    if gap is not None and math.isfinite(gap):
        delta = max(delta, gap)
    return float(delta)


def depth_row_map(chart: MapChart, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c, G): the caller's depth row is c + G z for z the branched functionals F (k = 3 rows,
    each over the last row's n = 3 chart coordinates w alone). The chart's last row is l0 + N w
    in the normalised frame, the caller's its product with the source normaliser S."""
    n = chart.last_row_basis.shape[1]
    if F.shape[0] != n or np.any(F[:, n:] != 0):
        raise Invalid("proven_interval", "the branched functionals must be the last row's chart coordinates alone "
                                         f"({n} of them, 0 elsewhere)")
    S = chart.source_norm
    return S.T @ chart.last_row_origin, S.T @ chart.last_row_basis @ np.linalg.inv(F[:, :n])


def leaf_ranges(c: np.ndarray, G: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each leaf's (rows of lo, hi) range of each depth-row entry, and the size of the terms
    behind it (what its rounding is relative to)."""
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    value = c[None, :] + mid @ G.T
    spread = half @ np.abs(G).T
    size = np.abs(c)[None, :] + np.abs(mid) @ np.abs(G).T + spread
    return np.stack([value - spread, value + spread], axis=-1), size


def hull(c, G, lo, hi, kept: np.ndarray, pad: float) -> np.ndarray | None:
    """The (4, 2) hull of the kept leaves' ranges, each side widened by ``pad`` of its terms'
    size; None when no leaf is kept."""
    if not np.any(kept):
        return None
    ranges, size = leaf_ranges(c, G, lo[kept], hi[kept])
    low = (ranges[..., 0] - pad * size).min(axis=0)
    high = (ranges[..., 1] + pad * size).max(axis=0)
    return np.stack([low, high], axis=-1)


def depth_row(matrix: np.ndarray, reference: int, source: np.ndarray) -> np.ndarray:
    """A camera's depth row: its last row over the reference point's depth."""
    last = np.asarray(matrix, dtype=float)[2]
    return last / (last @ np.append(source[reference], 1.0))


def proven_leaves_document(sublevel: dict) -> dict:
    """What a result's determinacy states of a leaves sublevel (determinacy.proven_map): the depth
    row, and the camera centre when the sublevel proves it (its ``centre``)."""
    centre = sublevel.get("centre")
    if centre is None:
        return proven_document(sublevel["cost_increase"], NAMES, sublevel["intervals"],
                               f"these are the camera's depth row (its last row over the depth of point "
                               f"{sublevel['reference']}: a point X lies at depth_x X + depth_y Y + depth_z Z + "
                               "depth_0 times that point's depth), read off the leaves of a search at that level (the "
                               "leaves whose proven bound exceeds it excluded, the rest bounding the set); the camera "
                               "centre is not bounded by them (fractional.resection_leaves)")
    return proven_document(sublevel["cost_increase"], NAMES + CENTRE_NAMES,
                           list(sublevel["intervals"]) + list(centre["intervals"]),
                           f"depth_x to depth_0 are the camera's depth row (its last row over the depth of point "
                           f"{sublevel['reference']}: a point X lies at depth_x X + depth_y Y + depth_z Z + depth_0 "
                           "times that point's depth), read off the leaves of a search at that level (the leaves "
                           "whose proven bound exceeds it excluded, the rest bounding the set; "
                           "fractional.resection_leaves); the centre's from the cameras enclosed in a ball of radius "
                           f"{centre['radius']:.6g} (whitened by the Gauss-Newton information at the camera), "
                           f"narrowed by {centre['rounds']} rounds, its first-order terms bounded over them by "
                           "stated multipliers (fractional.resection_centre_l1)")


def verify_resection_leaves(fresh, options: dict, sublevel, solution: np.ndarray, passed: list[str]) -> None:
    """A leaves sublevel (an L1 resection's proven intervals) of the map ``fresh`` (items.MapItem,
    its program not yet used: checked_leaves rescales it): its search proof checked as a search's
    (proof.checked_leaves) with every part holding for the cameras costing at most the level, and
    the stated intervals holding the hull its kept leaves prove. Refused: a narrower interval, a
    level the proofs do not reach, a reference that is not the chart's."""
    record(sublevel, "proof/sublevel", ("cost_increase", "reference", "intervals", "search"), ("centre",))
    norm = options["norm"]
    if norm not in NORMS:
        raise Invalid("proven_interval", "proof/sublevel with a search is for the L1 norms (L1L1, L2L1)")
    increase = number(sublevel.get("cost_increase"), "proof/sublevel/cost_increase")
    intervals = numbers(sublevel.get("intervals"), "proof/sublevel/intervals", (len(NAMES), 2))
    if not (increase >= 0 and math.isfinite(increase)):
        raise Invalid("proven_interval", "proof/sublevel/cost_increase must be a finite number >= 0")
    search = sublevel.get("search")
    if not isinstance(search, dict) or search.get("type") != "branch_and_bound":
        raise Invalid("proven_interval", "proof/sublevel/search must be a branch_and_bound proof")
    if sublevel.get("reference") != fresh.chart.reference or type(sublevel.get("reference")) is not int:
        raise Invalid("proven_interval", f"proof/sublevel/reference must be the chart's reference point "
                                         f"{fresh.chart.reference}")
    with np.errstate(all="ignore"):
        residuals, depths, _ = fresh.raw_residuals(solution)
        cost = norm_cost(residuals, norm)
    if not math.isfinite(cost):
        raise Invalid("proven_interval", "the camera has no finite cost on its points")
    sub_passed: list[str] = []
    checked = checked_leaves(fresh, options, search, lambda unit, discount: (cost + increase + discount) * unit,
                             solution, sub_passed)
    c, G = depth_row_map(fresh.chart, checked.F[:checked.k])
    kept = np.array([not bound > checked.cap for bound in checked.bounds])
    proven = hull(c, G, checked.lo, checked.hi, kept, ROUNDING)
    if proven is None:
        raise Invalid("proven_interval", "no leaf holds a camera costing at most the level: the camera returned "
                                         "lies in none, the proof is not the set's")
    if not (np.all(intervals[:, 0] <= proven[:, 0]) and np.all(intervals[:, 1] >= proven[:, 1])):
        raise Invalid("proven_interval", "proof/sublevel/intervals are narrower than what the search's leaves prove "
                                         f"({proven.tolist()})")
    if "centre" in sublevel:  # the camera centre's, at the same level (resection_centre_l1)
        verify_l1_centre(fresh.source, fresh.target, sublevel["centre"], solution, norm, increase,
                         sublevel["reference"])
    passed.append("proven_interval")
