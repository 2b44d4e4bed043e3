"""The convexity path of triangulate_many: every L2L2 track's local optimum (fractional.flat) and
its convexity bound (fractional.convexity) at once, and the results of the tracks it certifies.

A track is certified here when its bound is proven with the solver's strictness (each test
passing with twice its round-off allowances, so that the verifier's own computation of them,
whose sums may differ in their last bits, passes too) and the bound is within the tolerance of
the cost as the verifier recomputes it: the cost plus its rounding slack (the verifier's
residual_rounding), with the data determining it to within half the tolerance (the verifier's
residual uncertainty). Every other track is left to the branch and bound (None).
"""

from __future__ import annotations

import numpy as np

from geocert.solvers.core.certificates import ROUNDING
from geocert.solvers.fractional.columns import LocalColumns, TrackResults
from geocert.solvers.fractional.convexity import convexity_bounds, convexity_terms
from geocert.solvers.fractional.flat import FlatTracks, linear, refine
from geocert.solvers.fractional.options import TriangulationOptions

STRICTNESS = 2.0  # the solver's allowances over the verifier's
CLAIM_MARGIN = 1e-12  # the bound claimed below the bound computed (relative)


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
        # proof.residual_uncertainty: how far the data determine each residual coordinate.
        uncertainty = 1e-15 * (terms.size[:2] + np.abs(image) * terms.size[2]) / np.abs(depth)
        sums = flat.per_track(np.stack([
            (r * r).sum(axis=0), (2 * np.abs(r) * rounding + rounding * rounding).sum(axis=0),
            (2 * np.abs(r) * uncertainty + uncertainty * uncertainty).sum(axis=0), (~(depth > 0)).astype(float)]))
    cost, slack, spread, behind = sums
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
    return TrackResults(len(tracks), local)
