"""The convexity path of triangulate_many: every L2L2 track's local optimum (fractional.flat) and
its convexity bound (fractional.convexity) at once, and the results of the tracks it certifies.

A track is certified here when its bound is proven with the solver's strictness (each test
passing with twice its round-off allowances, so that the verifier's own computation of them,
whose sums may differ in their last bits, passes too) and the bound is within the tolerance of
the cost as the verifier recomputes it: the cost plus its rounding slack (the verifier's
residual_rounding), with the data determining it to within half the tolerance (the verifier's
residual uncertainty). Every other track is left to the branch and bound (None).

A certified track also gets a proven interval of every point of the scope within a cost
increase of the optimum (fractional.convexity.sublevel_radii): the increase is the one its
determinacy estimate uses (SIGMAS^2 times the fit's residual variance, at least the certified
gap), so the estimate and the proof speak of one set. A job of many tracks reads its estimates at
the noise pooled over its tracks when that is higher (determinacy.pooled_increase: a 2-view
track's own residual is one degree of freedom's estimate of it), and raise_sublevels proves its
intervals again at that level.
"""

from __future__ import annotations

import numpy as np

from geocert.core import exact
from geocert.core.certificates import OBJECTIVE_TOLERANCE, ROUNDING
from geocert.core.determinacy import SIGMAS
from geocert.formulations.fractional.columns import LocalColumns, TrackResults, sublevels
from geocert.formulations.fractional.convexity import (ball_bounds, ball_intervals, convexity_bounds, convexity_terms,
                                                  sublevel_radii)
from geocert.formulations.fractional.flat import FlatTracks, linear, refine
from geocert.formulations.fractional.options import TriangulationOptions
from geocert.formulations.fractional.proof import image_uncertainty

STRICTNESS = 2.0  # the solver's allowances over the verifier's
CLAIM_MARGIN = 1e-12  # the bound claimed below the bound computed (relative)


def _stated(flat: FlatTracks, x: np.ndarray, y: np.ndarray, r: np.ndarray, cost: np.ndarray,
            spread: np.ndarray) -> np.ndarray:
    """The residuals (2, m) the results state, ``cost`` updated in place: where the floats' rounding
    could move a track's cost past exact.FLOAT_SHARE of OBJECTIVE_TOLERANCE (far-off data, a
    near-exact fit), its residuals computed exactly, as the verifier then reads them
    (items.stated_residuals)."""
    exactly = np.flatnonzero(~(spread <= exact.FLOAT_SHARE * OBJECTIVE_TOLERANCE * np.abs(cost)) & np.isfinite(cost))
    if not len(exactly):
        return r
    r = r.copy()
    for i in exactly:
        a, b = flat.starts[i], flat.starts[i + 1]
        r[:, a:b] = -exact.residuals(flat.rows[:, :, a:b].transpose(2, 0, 1), np.append(x[i], 1.0), y[:, a:b].T).T
        cost[i] = exact.cost(r[:, a:b].T, "L2L2")
    return r


def certify_tracks(cameras: np.ndarray, tracks: list, options: TriangulationOptions) -> TrackResults:
    """The results of the tracks the convexity bound certifies (L2L2, no max_residual), as
    columns (TrackResults.local), None for the others. ``cameras`` as normalised_cameras gives
    them; tracks as triangulate_many takes them (validated)."""
    if options.norm != "L2L2" or options.max_residual is not None or not tracks:
        return TrackResults(len(tracks))
    flat = FlatTracks.build(cameras, tracks)
    start, ok = linear(flat)
    with np.errstate(all="ignore"):
        x, _ = refine(flat, start)
        terms = convexity_terms(flat, x)
        lower, radius, _ = convexity_bounds(flat, x, strictness=STRICTNESS, terms=terms)
        y, image, r, depth = flat.points, terms.image, terms.r, terms.w
        rounding = ROUNDING * (np.abs(image) + np.abs(y))  # the verifier's residual_rounding
        uncertainty = image_uncertainty(image, depth, terms.size[:2], terms.size[2])
        sums = flat.per_track(np.stack([
            (r * r).sum(axis=0), (2 * np.abs(r) * rounding + rounding * rounding).sum(axis=0),
            (2 * np.abs(r) * uncertainty + uncertainty * uncertainty).sum(axis=0), (~(depth > 0)).astype(float)]))
    cost, slack, spread, behind = sums
    r = _stated(flat, x, y, r, cost, spread)
    tolerance = np.maximum(options.abs_gap, options.rel_gap * np.abs(cost))
    claimed = np.minimum(lower - CLAIM_MARGIN * np.abs(lower), cost)
    # A cost within abs_gap of 0 is certified by the trivial bound (the search's first step).
    certified = ok & np.isfinite(lower) & (behind == 0) & np.isfinite(cost) & (cost > options.abs_gap) \
        & (cost + slack * (1 + 1e-6) - claimed <= tolerance * (1 - 1e-9)) & (spread <= 0.5 * tolerance)
    rows = np.flatnonzero(certified)
    observations = np.repeat(certified, flat.sizes)
    starts = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(flat.sizes[rows], out=starts[1:])
    local = LocalColumns(index=rows, point=x[rows], cost=cost[rows], lower_bound=claimed[rows],
                         tolerance=tolerance[rows], radius=radius[rows], residuals=r.T[observations],
                         starts=starts, proof=options.certificate == "full")
    if options.certificate == "full" or options.detail == "full":  # proven intervals, as columns
        increase, reach = _sublevels(flat, x, cost, claimed, certified, terms)
        reach = reach[rows]
        local.sublevel_increase, local.sublevel_radius = increase[rows], reach
        local.sublevel_bounds = ball_bounds(x[rows], np.where(np.isfinite(reach), reach, 0.0))
    return TrackResults(len(tracks), local)


def cost_increase(cost, lower, views):
    """The increase a proven interval is stated for: SIGMAS^2 times cost / (2 views - 3) (the
    fit's residual variance, as the determinacy estimate's), at least the certified gap."""
    redundancy = np.maximum(2 * np.asarray(views) - 3, 1)
    return np.maximum(SIGMAS ** 2 * np.asarray(cost) / redundancy, np.maximum(np.asarray(cost) - lower, 0.0))


def _sublevels(flat, x: np.ndarray, cost: np.ndarray, claimed: np.ndarray, certified: np.ndarray, terms):
    """(increase, radius) of every track: the cost increase and the proven ball's radius (nan
    where none, or not certified). ``terms``: convexity_terms(flat, x), reused at the level."""
    increase = cost_increase(cost, claimed, flat.sizes)
    # Solver's strictness: the checker's sums, differing in their last bits, pass at its radius.
    reach = sublevel_radii(flat, x, np.where(certified, increase, np.nan), strictness=STRICTNESS, terms=terms)
    return increase, reach


def track_sublevel(cameras: np.ndarray, points: np.ndarray, point, cost: float, lower: float,
                   norm: str) -> dict | None:
    """One certified track's proven interval (whatever proved its bound), None where the
    enclosure test proves none: what ``proof.sublevel`` carries."""
    increase = float(cost_increase(cost, lower, len(points)))
    flat = FlatTracks.build(cameras, [(list(range(len(points))), points)])
    with np.errstate(all="ignore"):
        radius = float(sublevel_radii(flat, np.asarray(point, dtype=float).reshape(1, 3), np.array([increase]),
                                      strictness=STRICTNESS, norm=norm)[0])
    if not np.isfinite(radius):
        return None
    return {"cost_increase": increase, "radius": radius, "intervals": ball_intervals(point, radius)}


def raise_sublevels(cameras: np.ndarray, tracks: list, results, floor: float, norm: str) -> int:
    """Prove again at cost increase ``floor`` (the job's pooled one) every proven interval of
    ``results`` (a TrackResults or a list of TrackResult, tracks as triangulate_many takes them)
    stated at a lower increase, so that no interval is proven at a level below the one its track's
    determinacy is read at; one the enclosure test does not prove at ``floor`` is dropped. L2L2
    only (the pooled increase is in squared pixels, the L1 norms' costs are not). Returns how many
    were raised."""
    if norm != "L2L2":
        return 0
    found = sublevels(results)
    low = [i for i, sublevel in enumerate(found) if sublevel is not None and sublevel["cost_increase"] < floor]
    if not low:
        return 0
    rows = [results.row(i) if isinstance(results, TrackResults) else -1 for i in low]
    X = np.array([results.local.point[row] if row >= 0 else results[i].point for i, row in zip(low, rows)],
                 dtype=float)
    flat = FlatTracks.build(cameras, [tracks[i] for i in low])
    with np.errstate(all="ignore"):
        radius = sublevel_radii(flat, X, np.full(len(low), float(floor)), strictness=STRICTNESS, norm=norm)
    for k, (i, row) in enumerate(zip(low, rows)):
        proven = bool(np.isfinite(radius[k]))
        if row >= 0:
            results.local.set_sublevel(row, floor, radius[k], ball_bounds(X[k], radius[k] if proven else 0.0))
            continue
        certificate = results[i].certificate
        sublevel = {"cost_increase": float(floor), "radius": float(radius[k]),
                    "intervals": ball_intervals(X[k], radius[k])} if proven else None
        certificate.sublevel = sublevel
        if certificate.proof is not None:
            if sublevel is None:
                certificate.proof.pop("sublevel", None)
            else:
                certificate.proof["sublevel"] = sublevel
    return len(low)
