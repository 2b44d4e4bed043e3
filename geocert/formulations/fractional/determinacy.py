"""How well a track or a map is fixed by its data (core/determinacy.py): intervals for what a user
reads off the answer, and the degeneracies recognised.

- A track: the point's coordinates and its distance from the first view's centre (depth along
  that ray); warned when the rays meet at a near-zero angle (parallax), or the point is at
  infinity (no interval then).
- A resection: the camera centre; warned when the 3D points are nearly coplanar, or when the
  points and the centre lie near a critical configuration (the camera is not fixed: a direction
  of the data's curvature is singular). A certified L2L2 resection's centre also has proven
  intervals at the estimate's level (prove_map, fractional.resection_sublevel).
- A homography: the image of the source points' centroid; warned when the source or the target
  points are nearly collinear (coplanar, for maps of P^3). Computed in a fixed order of operations
  (fractional.homography_estimate): the same floats on every machine.

The curvature is that of the squared reprojection errors whatever the norm solved for (for the
L1 norms, an estimate of the same kind: the intervals say how flat the fit is, not a confidence).
Maps are fixed up to scale: their parameters are the directions orthogonal to the answer."""

from __future__ import annotations

import math

import numpy as np

from geocert.core.determinacy import (SIGMAS, SINGULAR, Determinacy, certified_gap, curvature_intervals,
                                      few_degrees, interval, level_sigmas, not_analysed, numeric_jacobian,
                                      proven_document, safely, spread)
from geocert.core.exact import exact_centroid_image, exact_squared_residuals  # noqa: F401 (callers read them here)
from geocert.formulations.fractional import fixed_order
from geocert.formulations.fractional.normalisation import complement, normalised_map
from geocert.formulations.fractional.columns import solutions, sublevels

PARALLAX_DEGREES = 1.0  # rays meeting at less than this: near-zero parallax
# The test reads the rays' cosines against this (no arccos: its last bit is the CPU's vector unit's)
PARALLAX_COSINE = math.cos(math.radians(PARALLAX_DEGREES))
FLAT = 1e-2  # points whose centred spread along a direction is below this fraction: (nearly) flat


def stated_lower_bound(result) -> float | None:
    """The lower bound an item's document states: a certified result's, none for one not certified
    (documents.outcome_document). An estimate's level reads this one, so that the verifier, which
    sees only the document, recomputes the same level."""
    return result.lower_bound if result.certified else None


def _centres(cameras: np.ndarray) -> np.ndarray:
    """Euclidean centres (NaN for a camera whose centre is at infinity), computed in a fixed order
    (the writer's batched path and the verifier's single track, on any machine, read one float)."""
    C = fixed_order.camera_centres(cameras)
    finite = np.abs(C[:, 3:4]) > 1e-12 * np.abs(C).max(axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(finite, C[:, :3] / C[:, 3:4], np.nan)


def _length(ray: np.ndarray) -> np.ndarray | float:
    """|ray| over the last axis, its squares summed in order: the single track's and the batched
    tracks' depth, one float (np.linalg.norm's dot may fuse its products under one kernel)."""
    squares = ray[..., 0] * ray[..., 0] + ray[..., 1] * ray[..., 1] + ray[..., 2] * ray[..., 2]
    return float(np.sqrt(squares)) if np.ndim(squares) == 0 else np.sqrt(squares)


def _cosines(unit: np.ndarray) -> np.ndarray:
    """|cos| of every pair of unit rays (..., n, 3) -> (..., n, n), each a sum in one order, as
    the single track and the batched tracks both read them (a matmul's and an einsum's sums
    differed in the last bit, and a track at 1 degree got its warning from one and not the other:
    review 40)."""
    a, b = unit[..., :, None, :], unit[..., None, :, :]
    return np.minimum(np.abs(a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]), 1.0)


def track(cameras: np.ndarray, points: np.ndarray, point: list[float] | None, at_infinity: bool,
          cost: float | None, lower: float | None, sublevel: dict | None = None,
          pooled: tuple[float, int] | None = None) -> dict | None:
    """``sublevel``: the proven interval its certificate carries, if any (proven_track);
    ``pooled``: the job's pooled cost increase (pooled_increase), None for the track's own."""
    if point is None:
        return None
    cameras = np.asarray(cameras, dtype=float)
    points = np.asarray(points, dtype=float)
    if at_infinity:
        out = Determinacy()
        out.warnings.append({"code": "at_infinity", "detail": "the point is at infinity: its depth is not fixed"})
        return out.document()
    X = np.asarray(point, dtype=float)

    def residuals(x):
        proj = cameras @ np.append(x, 1.0)
        return (proj[:, :2] / proj[:, 2:3] - points).ravel()

    proj = cameras @ np.append(X, 1.0)
    # d(pi)/dX = (P_1:2 - pi P_3) / y3, on the first three columns
    J = ((cameras[:, :2, :3] - (proj[:, :2] / proj[:, 2:3])[:, :, None] * cameras[:, 2:3, :3])
         / proj[:, 2:3, None]).reshape(-1, 3)
    centres = _centres(cameras)
    ray = X - centres[0]
    length = _length(ray) if np.all(np.isfinite(centres[0])) else math.nan
    scale = length if length > 0 else None  # the point is fixed when known to a tenth of its depth
    quantities = {name: (float(X[k]), np.eye(3)[k], scale) for k, name in enumerate(("x", "y", "z"))}
    if scale is not None:
        quantities["depth_view0"] = (length, ray / length, length)
    gap = certified_gap(cost, lower)
    if pooled is not None:  # a floor on delta, as the gap is
        gap = pooled[0] if gap is None else max(gap, pooled[0])
    # a pooled level carries its own Student quantile; the track's own variance is then a floor
    out = curvature_intervals(J, residuals(X), quantities, gap, small_sample=pooled is None)
    if pooled is not None and not math.isfinite(out.cost_increase):
        return no_level()
    out.level = None if pooled is None else pooled_level(pooled)
    if pooled is not None:  # a pool of one 2-view track estimates the noise from one residual
        out.warnings += few_degrees(pooled[1])
    out.proven_intervals = proven_track(sublevel)
    rays = X[None, :] - centres
    rays = rays[np.all(np.isfinite(rays), axis=1)]
    if len(rays) >= 2:
        unit = rays / _length(rays)[:, None]
        least = float(_cosines(unit).min())
        if least > PARALLAX_COSINE:
            widest = float(np.degrees(np.arccos(least)))
            out.warnings.append({"code": "near_zero_parallax",
                                 "detail": f"the rays meet at {widest:.3g} degrees at most (< {PARALLAX_DEGREES:g}): "
                                           "the depth along them is poorly fixed"})
    return out.document()


def tracks_many(cameras: np.ndarray, tracks: list, results: list, projected: tuple | None = None
                ) -> list[dict | None]:
    """``track`` for many tracks of one scene at once (``cameras`` (N, 3, 4) the scene's, each
    track ``(views, points)``, each result with ``point``, ``at_infinity``, ``cost`` and
    ``lower_bound``): the same documents, the same numbers to rounding. The centres are found once
    for the scene and the linear algebra runs on stacked arrays, a group of tracks of one length at
    a time (``track`` costs about 0.6 ms a Dinosaur track, mostly small numpy calls)."""
    cameras = np.asarray(cameras, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        centres = _centres(cameras)
    out: list[dict | None] = [None] * len(tracks)
    X, finite, cost, lower, groups, projected = projected or projected_tracks(cameras, tracks, results)
    proven = sublevels(results)
    for i in np.flatnonzero(~finite).tolist():
        result = results[i]
        if result is not None and result.point is not None:  # at infinity
            out[i] = track(cameras[tracks[i][0]], tracks[i][1], result.point, True, result.cost,
                           stated_lower_bound(result))
    pooled = _pooled(projected)
    for n, members in groups.items():
        try:
            if n not in projected:
                raise ValueError("not projected")
            with np.errstate(all="ignore"):
                documents = _finite_tracks(cameras, centres, [tracks[i] for i in members], X[members], cost[members],
                                           lower[members], [proven[i] for i in members], n, projected[n], pooled)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):  # as safely(): never fails a solve
            documents = [safely(track, cameras[tracks[i][0]], tracks[i][1], X[i].tolist(), False, results[i].cost,
                                stated_lower_bound(results[i]), proven[i], pooled) for i in members]
        for i, document in zip(members, documents):
            out[i] = document
    return out


def pooled_for(cameras: np.ndarray, tracks: list, results: list, projected: tuple | None = None
               ) -> tuple[float, int] | None:
    """The pooled cost increase (pooled_increase) tracks_many gives the same tracks and results.
    ``projected``: projected_tracks of them, when the caller has it (tracks_many takes it too)."""
    return _pooled((projected or projected_tracks(np.asarray(cameras, dtype=float), tracks, results))[-1])


def projected_tracks(cameras: np.ndarray, tracks: list, results: list) -> tuple:
    """The results' points X, whether finite, costs and lower bounds (solutions), the tracks with
    finite points grouped by length, and each group's projections (_project; a group that does
    not project is left out). What pooled_for and tracks_many read: made once, it serves both
    (the proven intervals' raising between them changes no point)."""
    cameras = np.asarray(cameras, dtype=float)
    X, finite, cost, lower = solutions(results)  # no object made for the convexity path's columns
    groups: dict[int, list[int]] = {}
    for i in np.flatnonzero(finite).tolist():
        groups.setdefault(len(tracks[i][0]), []).append(i)
    projected = {}
    with np.errstate(all="ignore"):
        for n, members in groups.items():
            try:
                projected[n] = _project(cameras, [tracks[i] for i in members], X[members])
            except (ValueError, ArithmeticError, np.linalg.LinAlgError):
                pass
    return X, finite, cost, lower, groups, projected


def _pooled(projected: dict) -> tuple[float, int] | None:
    with np.errstate(all="ignore"):
        return pooled_increase({n: (p[-1] * p[-1]).sum(axis=1) for n, p in projected.items()})


def _project(cameras: np.ndarray, tracks: list, X: np.ndarray) -> tuple:
    """Tracks of one length: their views (G, n), cameras (G, n, 3, 4), projections (G, n, 3), image
    points (G, n, 2) and residuals (G, 2n) at the points X (G, 3)."""
    views = np.array([v for v, _ in tracks])
    cams = cameras[views]
    points = np.array([p for _, p in tracks], dtype=float)
    proj = np.einsum("gnij,gj->gni", cams, np.concatenate([X, np.ones((len(X), 1))], axis=1))
    image = proj[..., :2] / proj[..., 2:3]
    return views, cams, proj, image, (image - points).reshape(len(X), -1)


# Two-sided, as 3 standard errors of a normal estimate: the Student quantile used for a pooled
# variance of finitely many degrees of freedom covers as often.
COVERAGE = math.erf(SIGMAS / math.sqrt(2.0))
OUTLIER_TAIL = 1e-3  # a track whose squared residuals exceed their chi-square's 99.9% point is not pooled


def pooled_increase(costs_by_views: dict[int, np.ndarray]) -> tuple[float, int] | None:
    """cost_increase from the residual variance of all a job's tracks together (``costs_by_views``:
    their sums of squared residuals, by track length): the image noise is the detector's, shared
    by every track, and one track of few views estimates it from one or a few degrees of freedom
    (a 2-view track from one: 3 standard errors of such an estimate cover the truth about 85% of
    the time, not 99.7%). Robustly: the variance's first estimate is the median of each track's
    own over its chi-square's median; tracks beyond that chi-square's 99.9% point are left out;
    the rest pooled (sum of squares over degrees of freedom D), times the squared Student quantile
    of D degrees of freedom at 3 standard errors' coverage. (increase, D), or None without a
    track of 2 views or more with a finite cost."""
    from scipy.special import chdtri, stdtrit

    dof = np.concatenate([np.full(len(c), 2 * n - 3) for n, c in costs_by_views.items()]) if costs_by_views \
        else np.zeros(0)
    cost = np.concatenate(list(costs_by_views.values())) if costs_by_views else np.zeros(0)
    use = (dof > 0) & np.isfinite(cost)
    dof, cost = dof[use].astype(float), cost[use]
    if not len(cost):
        return None
    first = float(np.median(cost / chdtri(dof, 0.5)))
    if not first > 0:
        return None
    inliers = cost <= chdtri(dof, OUTLIER_TAIL) * first
    total = int(dof[inliers].sum())
    variance = float(cost[inliers].sum()) / total
    quantile = float(stdtrit(total, 0.5 + COVERAGE / 2))
    return quantile * quantile * variance, total


def pooled_dof(level) -> int | None:
    """The degrees of freedom a ``level`` written by pooled_level states, or None when it is not
    one pooled_level writes."""
    before, after = pooled_level((0.0, 987654321)).split("987654321")
    if not (isinstance(level, str) and level.startswith(before) and level.endswith(after)):
        return None
    dof = level[len(before):len(level) - len(after)]
    return int(dof) if dof.isdigit() and dof.isascii() else None


def pool_runs(indices: list[int]) -> list[list[int]]:
    """The job's track indices pooled together as runs [first, stop) (a determinacy's
    pooled_tracks: what the verifier recomputes the pooled level from)."""
    runs: list[list[int]] = []
    for index in indices:
        if runs and runs[-1][1] == index:
            runs[-1][1] = index + 1
        else:
            runs.append([index, index + 1])
    return runs


def pooled_level(pooled: tuple[float, int]) -> str:
    """The documents' ``level`` when cost_increase comes from the pooled variance."""
    return (f"parameters whose squared residuals exceed the optimum's by at most cost_increase: the largest of the "
            f"residual variance pooled over the job's tracks ({pooled[1]} degrees of freedom, tracks beyond their "
            f"chi-square's {1 - OUTLIER_TAIL:.1%} point left out) times the squared Student quantile of "
            f"{SIGMAS:g} standard errors' coverage, {SIGMAS:g}^2 times the track's own residual variance, and the "
            "certified gap; by the local curvature (Gauss-Newton)")


def _finite_tracks(cameras, all_centres, tracks: list, X: np.ndarray, costs: np.ndarray, lowers: np.ndarray,
                   proven: list, n: int, projected: tuple, pooled: tuple[float, int] | None) -> list[dict]:
    """The documents of tracks of n views each with finite points X (G, 3), their costs and lower
    bounds (G,) (nan where none), their certificates' sublevels (proven_track), their projections
    (_project) and the job's pooled cost increase (pooled_increase)."""
    views, cams, proj, image, residuals = projected
    J = ((cams[..., :2, :3] - image[..., None] * cams[..., 2:3, :3]) / proj[..., 2:3, None]).reshape(len(X), -1, 3)
    information = np.einsum("gki,gkj->gij", J, J)
    finite = np.all(np.isfinite(J), axis=(1, 2))
    information[~finite] = np.eye(3)  # not used (its intervals are unbounded), kept finite for eigh
    values, vectors = np.linalg.eigh(0.5 * (information + information.transpose(0, 2, 1)))
    centres = all_centres[views]  # (G, n, 3)
    ray = X - centres[:, 0]
    length = _length(ray)
    has_depth = np.all(np.isfinite(centres[:, 0]), axis=1) & (length > 0)
    rays = X[:, None, :] - centres
    usable = np.all(np.isfinite(rays), axis=2)  # (G, n)
    unit = rays / _length(rays)[..., None]
    cosines = np.where(usable[:, :, None] & usable[:, None, :], _cosines(unit), np.inf)
    least = np.minimum(cosines.min(axis=(1, 2)), 1.0)
    widest = np.degrees(np.arccos(least))
    # eigen_intervals on every track at once: each quantity's gradient in J'J's eigenbasis, the
    # part along directions the data do not fix, the half-width from the rest.
    names = ("x", "y", "z", "depth_view0")
    gradients = np.concatenate([np.broadcast_to(np.eye(3), (len(X), 3, 3)),
                                np.where(has_depth[:, None], ray / np.where(has_depth, length, 1.0)[:, None], 0.0)[:, None]],
                               axis=1)  # (G, 4, 3)
    quantity = np.concatenate([X, np.where(has_depth, length, np.nan)[:, None]], axis=1)  # (G, 4)
    cost = (residuals * residuals).sum(axis=1)
    redundancy = 2 * n - 3
    factor = SIGMAS if pooled is not None else level_sigmas(redundancy)  # as track's: core.determinacy.cost_increase
    delta = factor ** 2 * cost / redundancy if redundancy > 0 else np.zeros(len(X))
    if pooled is not None:
        delta = np.maximum(delta, pooled[0])
    gaps = np.maximum(costs - lowers, 0.0)  # certified_gap: nan unless both are finite
    delta = np.where(np.isfinite(gaps), np.maximum(delta, gaps), delta)
    bounded = finite & np.isfinite(delta)
    fixed = values > SINGULAR * np.maximum(values[:, -1:], 1e-300)  # (G, 3)
    g = np.einsum("gji,gqj->gqi", vectors, gradients)  # (G, 4, 3)
    free = np.where(fixed[:, None], 0.0, np.abs(g)).max(axis=2)
    determined = bounded[:, None] & (free <= 1e-6 * np.maximum(np.abs(g).max(axis=2), 1e-300)) & np.isfinite(quantity)
    safe_values = np.where(fixed, values, 1.0)
    half = np.sqrt(delta[:, None] * np.where(fixed[:, None], g * g / safe_values[:, None], 0.0).sum(axis=2))
    documents = []
    level = None if pooled is None else pooled_level(pooled)  # one text for the job's tracks
    for i in range(len(X)):
        if pooled is not None and not math.isfinite(delta[i]):
            documents.append(no_level())
            continue
        out = Determinacy(cost_increase=float(delta[i]), redundancy=redundancy, level=level)
        # the level's own degrees of freedom, as track's: the track's, or the pool's (a job of one
        # 2-view track pools one: a lone point's noise estimate from its one residual, issue 37)
        out.warnings += few_degrees(redundancy if pooled is None else pooled[1])
        scale = float(length[i]) if has_depth[i] else None
        for k in range(4 if has_depth[i] else 3):
            value = float(quantity[i, k])
            if determined[i, k]:
                out.intervals.append(interval(names[k], value, value - half[i, k], value + half[i, k], scale))
            else:
                out.intervals.append(interval(names[k], value, None, None, scale))
        out.proven_intervals = proven_track(proven[i])
        if usable[i].sum() >= 2 and least[i] > PARALLAX_COSINE:
            out.warnings.append({"code": "near_zero_parallax",
                                 "detail": f"the rays meet at {float(widest[i]):.3g} degrees at most (< "
                                           f"{PARALLAX_DEGREES:g}): the depth along them is poorly fixed"})
        documents.append(out.document())
    return documents


def no_level() -> dict:
    """A track read at a pooled level whose own level is not finite: its residuals at the point
    returned are not (the point on a camera's centre, where a projection has depth 0: cameras
    sharing one centre leave the depth free and the solver may return it there) or their squares
    overflow. Its intervals have no level to be read at, so it is stated not analysed (claiming
    nothing), not with a null cost_increase beside the pooled level's words, which its verifier
    refused (review 62). A track with no pool keeps its own level's form (cost_increase null,
    unbounded intervals), which verifies as it did."""
    return not_analysed("the track's determinacy", "its residuals at the point returned are not finite (the point "
                        "on a camera's centre, or residuals beyond float range), so it has no level of its own "
                        f"({SIGMAS:g}^2 times its residual variance) to read intervals at", code="not_analysed")


def proven_track(sublevel: dict | None) -> dict | None:
    """The proven intervals of a certified track from its certificate's ``sublevel`` (None: none)."""
    if sublevel is None:
        return None
    return proven_document(sublevel["cost_increase"], ("x", "y", "z"), sublevel["intervals"],
                           f"a ball of radius {sublevel['radius']:.6g} about the point, proven by the enclosure "
                           "test at that level (fractional.convexity)")


def proven_map(sublevel: dict | None) -> dict | None:
    """The proven intervals of a certified resection's camera centre from its certificate's
    ``sublevel`` (fractional.resection_sublevel; None: none)."""
    if sublevel is None:
        return None
    if "search" in sublevel:  # an L1 resection's, read off a search's leaves
        from geocert.formulations.fractional.resection_leaves import proven_leaves_document
        return proven_leaves_document(sublevel)
    return proven_document(sublevel["cost_increase"], ("centre_x", "centre_y", "centre_z"), sublevel["intervals"],
                           f"the cameras enclosed in a ball of radius {sublevel['radius']:.6g} (whitened by the "
                           f"Gauss-Newton information at the camera), narrowed by {sublevel['rounds']} rounds bounding "
                           "the cost below by a quadratic, the centre bounded over what remains "
                           "(fractional.resection_sublevel)")


def prove_map(source: np.ndarray, target: np.ndarray, matrix, cost: float, lower: float | None,
              document: dict | None = None) -> dict | None:
    """A certified L2L2 resection's proven interval (None where none is proven) at the level its
    determinacy estimate is read at (map_level: 3^2 times the exact squared residuals / (2k - 11),
    at least the gap), computed from the data and the matrix so that a result without determinacy
    (detail brief) proves the same; set in ``document`` (the determinacy) too when given."""
    from geocert.formulations.fractional.resection_sublevel import resection_sublevel

    if matrix is None or cost is None or not math.isfinite(cost):
        return None
    increase = map_level(source, target, matrix, cost, lower)
    try:  # as safely(): a proof not found never fails a solve
        with np.errstate(all="ignore"):
            sublevel = resection_sublevel(source, target, matrix, increase)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        sublevel = None
    if sublevel is not None and document is not None:
        document["proven_intervals"] = proven_map(sublevel)
        document["proven"] = True
    return sublevel


def map_level(source: np.ndarray, target: np.ndarray, matrix, cost: float | None, lower: float | None) -> float:
    """An L2L2 resection's level, the one its estimate, its proven interval and the verifier read:
    3^2 times the exact squared residuals over 2k - 11, at least the certified gap."""
    from geocert.core.determinacy import cost_increase

    squared = exact_squared_residuals(source, target, np.asarray(matrix, dtype=float))
    return float(cost_increase(squared, 2 * len(source) - 11, certified_gap(cost, lower)))


def map_(source: np.ndarray, target: np.ndarray, matrix: list[list[float]] | None, cost: float | None,
         lower: float | None) -> dict | None:
    """A map's estimate at ``matrix``, its level from the squared residuals' sum computed exactly
    (exact_squared_residuals): a function of the data and the matrix alone, on every machine."""
    if matrix is None:
        return None
    source = np.asarray(source, dtype=float)
    target = np.asarray(target, dtype=float)
    M = np.asarray(matrix, dtype=float)
    m, n1 = M.shape
    if not (m == 3 and n1 == 4):  # a homography: in a fixed order of operations (review 38 class 4)
        from geocert.formulations.fractional.homography_estimate import homography
        return homography(source, target, M, cost, lower)
    # Parameters in normalised coordinates (centroid 0, mean distance sqrt 2 on both sides), where
    # the map's entries are of one size: in pixels they span orders of magnitude, and J'J's
    # smallest eigenvalue would look singular for that reason alone. The residuals and the centre
    # are read in that frame too (the normalised points against the normalised map, computed
    # exactly: fractional.normalisation), so the width does not depend on where the data sit: read
    # in the world's coordinates, a central difference of residuals rounded at eps of the data's
    # offset moved the width by multiples of itself 1e8 off the origin over a spread of 1e-3
    # (review 59 class 6).
    (cs, ss), (ct, st), normalised = normalised_map(source, target, M)
    basis = complement(normalised.ravel())
    xs = np.hstack([ss * (source - cs), np.ones((len(source), 1))])  # the normalised source points
    ts = st * (target - ct)  # and targets

    def residuals(theta):
        # the pixel residuals, (normalised image - normalised target) / st
        image = xs @ (normalised + (basis @ theta).reshape(M.shape)).T
        return ((image[:, :-1] / image[:, -1:] - ts) / st).ravel()

    zero = np.zeros(basis.shape[1])
    J = numeric_jacobian(residuals, zero)
    quantities = {}

    def offset(theta):
        # the centre's offset from the source centroid, in the world's units: the null vector of the
        # normalised map (entries of one size) over the source's scale (the pixel-world camera's SVD
        # rounds its centre at 1e-10 of itself far out)
        C = np.linalg.svd(normalised + (basis @ theta).reshape(M.shape))[2][-1]
        return C[:3] / (C[3] * ss)

    local = offset(zero)
    value = cs + local
    gradient = numeric_jacobian(offset, zero)
    # the centre known to a tenth of it; math.hypot scales as it sums, where norm's squares
    # underflow for a centre in a tiny world unit (1e-300) and gave a tolerance of 0
    distance = math.hypot(*map(float, local))
    for k, name in enumerate(("centre_x", "centre_y", "centre_z")):
        quantities[name] = (float(value[k]), gradient[k], distance)
    out = curvature_intervals(J, residuals(zero), quantities, certified_gap(cost, lower),
                              squared_sum=exact_squared_residuals(source, target, M))
    flat = spread(source)
    if flat[-1] < FLAT:
        out.warnings.append({"code": "near_coplanar_points",
                             "detail": f"the 3D points are nearly coplanar (spread {flat[-1]:.2g} of their extent): "
                                       "the camera is poorly fixed off their plane"})
    if any(interval["lower"] is None for interval in out.intervals):  # a direction the data do not fix
        out.warnings.append({"code": "near_critical_configuration",
                             "detail": "the points and the camera centre are near a configuration that does not fix "
                                       "the camera (coplanar points, or a twisted cubic through the centre)"})
    return out.document()
