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
gap), so the estimate and the proof speak of one set.
"""

from __future__ import annotations

import numpy as np

from geocert.solvers.core.certificates import ROUNDING
from geocert.solvers.core.determinacy import SIGMAS
from geocert.solvers.fractional.convexity import ball_intervals, convexity_bounds, sublevel_radii
from geocert.solvers.fractional.flat import FlatTracks, linear, refine
from geocert.solvers.fractional.options import TriangulationOptions
from geocert.solvers.fractional.results import LocalCertificate, TrackResult

SCOPE = "every point in front of every camera"
STRICTNESS = 2.0  # the solver's allowances over the verifier's
CLAIM_MARGIN = 1e-12  # the bound claimed below the bound computed (relative)


def certify_tracks(cameras: np.ndarray, tracks: list, options: TriangulationOptions) -> list[TrackResult | None]:
    """The results of the tracks the convexity bound certifies (L2L2, no max_residual), None
    for the others. ``cameras`` as normalised_cameras gives them; tracks as triangulate_many
    takes them (validated)."""
    out: list[TrackResult | None] = [None] * len(tracks)
    if options.norm != "L2L2" or options.max_residual is not None or not tracks:
        return out
    flat = FlatTracks.build(cameras, tracks)
    start, ok = linear(flat)
    with np.errstate(all="ignore"):
        x, _ = refine(flat, start)
        lower, radius, _ = convexity_bounds(flat, x, strictness=STRICTNESS)
        P, y = flat.rows, flat.points
        X = np.concatenate([x, np.ones((len(x), 1))], axis=1)[flat.owner].T
        proj = (P * X[None]).sum(axis=1)
        terms = (np.abs(P) * np.abs(X)[None]).sum(axis=1)
        depth = proj[2]
        image = proj[:2] / depth
        r = image - y
        rounding = ROUNDING * (np.abs(image) + np.abs(y))  # the verifier's residual_rounding
        # proof.residual_uncertainty: how far the data determine each residual coordinate.
        uncertainty = 1e-15 * (terms[:2] + np.abs(image) * terms[2]) / np.abs(depth)
        sums = flat.per_track(np.stack([
            (r * r).sum(axis=0), (2 * np.abs(r) * rounding + rounding * rounding).sum(axis=0),
            (2 * np.abs(r) * uncertainty + uncertainty * uncertainty).sum(axis=0), (~(depth > 0)).astype(float)]))
    cost, slack, spread, behind = sums
    tolerance = np.maximum(options.abs_gap, options.rel_gap * np.abs(cost))
    claimed = np.minimum(lower - CLAIM_MARGIN * np.abs(lower), cost)
    # A cost within abs_gap of 0 is certified by the trivial bound (the search's first step).
    certified = ok & np.isfinite(lower) & (behind == 0) & np.isfinite(cost) & (cost > options.abs_gap) \
        & (cost + slack * (1 + 1e-6) - claimed <= tolerance * (1 - 1e-9)) & (spread <= 0.5 * tolerance)
    full = options.certificate == "full"
    increase, reach = _sublevels(flat, x, cost, claimed, certified) if full or options.detail == "full" \
        else (None, None)
    if reach is not None:  # Python lists made once for the whole batch, as below
        balls = ball_intervals(x, np.where(np.isfinite(reach), reach, 0.0))
        proven, increases, reaches = np.isfinite(reach).tolist(), increase.tolist(), reach.tolist()
    # Python lists made once for the whole batch (one tolist each), then sliced per track.
    residuals, points, starts = r.T.tolist(), x.tolist(), flat.starts.tolist()
    costs, claims, tolerances, radii = cost.tolist(), claimed.tolist(), tolerance.tolist(), radius.tolist()
    for t in np.flatnonzero(certified).tolist():
        sublevel = None
        if reach is not None and proven[t]:
            sublevel = {"cost_increase": increases[t], "radius": reaches[t], "intervals": balls[t]}
        proof = {"type": "convexity", "radius": radii[t]} if full else None
        if proof is not None and sublevel is not None:
            proof["sublevel"] = sublevel
        out[t] = TrackResult(status="optimal", certified=True, cost=costs[t], lower_bound=claims[t],
                             gap=costs[t] - claims[t], nodes=0, point=points[t],
                             residuals=residuals[starts[t]:starts[t + 1]],
                             certificate=LocalCertificate(SCOPE, tolerances[t], radii[t], proof, sublevel=sublevel))
    return out


def cost_increase(cost, lower, views):
    """The increase a proven interval is stated for: SIGMAS^2 times cost / (2 views - 3) (the
    fit's residual variance, as the determinacy estimate's), at least the certified gap."""
    redundancy = np.maximum(2 * np.asarray(views) - 3, 1)
    return np.maximum(SIGMAS ** 2 * np.asarray(cost) / redundancy, np.maximum(np.asarray(cost) - lower, 0.0))


def _sublevels(flat, x: np.ndarray, cost: np.ndarray, claimed: np.ndarray, certified: np.ndarray):
    """(increase, radius) of every track: the cost increase and the proven ball's radius (nan
    where none, or not certified)."""
    increase = cost_increase(cost, claimed, flat.sizes)
    # Solver's strictness: the checker's sums, differing in their last bits, pass at its radius.
    reach = sublevel_radii(flat, x, np.where(certified, increase, np.nan), strictness=STRICTNESS)
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
