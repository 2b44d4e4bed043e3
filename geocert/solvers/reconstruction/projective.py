"""Stage 2: a projective reconstruction from tracks alone (no calibration): a robust initial
pair, views added by resection of the points already triangulated (RANSAC, DLT), new tracks
triangulated as their views register, projective bundle adjustments as the reconstruction
grows, outlier observations removed and counted, and the signs and frame fixed so that every
point lies in front of every camera that sees it (geocert.solvers.orientation).

Work happens in each view's Hartley-normalised coordinates; cameras are returned in pixels."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from geocert.solvers.orientation import orient
from geocert.solvers.reconstruction import bundle, linear
from geocert.solvers.reconstruction.tracks import Observations, apply, hartley


@dataclass
class ProjectiveOptions:
    threshold_px: float = 2.0  # an observation farther than this from its reprojection is an outlier
    min_inliers: int = 12  # 3D-2D inliers a view needs to register
    min_pair: int = 16  # matches the initial pair needs
    seed: int = 0


@dataclass
class Projective:
    cameras: list[np.ndarray | None]  # pixels, 3x4 (None: not registered)
    reasons: list[str | None]
    points: np.ndarray  # (T, 4) homogeneous, NaN for tracks not reconstructed
    inlier: np.ndarray  # (M,) bool per observation (Observations order)
    initial_pair: tuple[int, int] | None
    stats: dict = field(default_factory=dict)


def _report(callback, done: int, total: int) -> bool:
    """Progress; True when the callback asks to stop (a cancel)."""
    return bool(callback is not None and callback("projective", done, total))


def choose_pair(obs: Observations, xn: np.ndarray, scales: np.ndarray, options: ProjectiveOptions,
                candidates: int = 8):
    """Among the pairs sharing the most tracks, the one whose fundamental matrix explains most
    matches while a homography explains fewest (a pair related by a homography, rotation only
    or a plane, does not fix the structure). Returns (i, j, F, shared tracks, inlier mask)."""
    pairs = obs.pairs()
    lookup = obs.lookup()
    ranked = sorted(pairs.items(), key=lambda item: -len(item[1]))[:candidates]
    best, best_score = None, -1.0
    for (i, j), shared in ranked:
        if len(shared) < options.min_pair:
            continue
        x1 = xn[[lookup[(t, i)] for t in shared]]
        x2 = xn[[lookup[(t, j)] for t in shared]]
        threshold = options.threshold_px * math.sqrt(scales[i] * scales[j])
        F, mask = linear.fundamental_ransac(x1, x2, threshold, options.seed)
        if F is None or mask.sum() < options.min_pair:
            continue
        h = linear.homography_inliers(x1[mask], x2[mask], threshold)
        score = mask.sum() * (1.0 - 0.9 * h / mask.sum())
        if score > best_score:
            best, best_score = (i, j, F, shared, mask), score
    return best


def reconstruct(tracks: list[tuple[np.ndarray, np.ndarray]], n_views: int, options: ProjectiveOptions,
                callback=None) -> Projective:
    """``callback("projective", done, total)`` sees each view registered and each iteration of
    an adjustment; when it returns True (a cancel) no more views are added and the adjustment
    running ends where it is, and the views registered so far are finished as usual but for the
    final adjustment (the last triangulation and orientation), with ``stats["cancelled"]`` True."""
    obs = Observations.from_tracks(tracks, n_views)
    T = np.array([hartley(obs.pixel[obs.view == v]) if np.sum(obs.view == v) >= 2 else np.eye(3)
                  for v in range(n_views)])
    scales = T[:, 0, 0].copy()
    xn = np.empty_like(obs.pixel)
    for v in range(n_views):
        where = obs.view == v
        xn[where] = apply(T[v], obs.pixel[where])
    reasons: list[str | None] = [None] * n_views
    seen_views = set(obs.view.tolist())
    for v in range(n_views):
        if v not in seen_views:
            reasons[v] = "no track observes this view"
    start = choose_pair(obs, xn, scales, options)
    if start is None:
        return Projective([None] * n_views, [r or "no pair of views has enough consistent matches" for r in reasons],
                          np.full((obs.n_tracks, 4), np.nan), np.zeros(len(obs.view), dtype=bool), None,
                          {"reason": "no pair of views shares enough matches consistent with one fundamental matrix"})
    i, j, F, shared, mask = start
    lookup = obs.lookup()
    P = np.full((n_views, 3, 4), np.nan)
    registered = np.zeros(n_views, dtype=bool)
    P[i], P[j] = linear.cameras_from_fundamental(F)
    registered[[i, j]] = True
    X = np.full((obs.n_tracks, 4), np.nan)
    inlier = np.ones(len(obs.view), dtype=bool)  # observations not (yet) rejected
    good = shared[mask]
    m1 = np.array([lookup[(t, i)] for t in good])
    m2 = np.array([lookup[(t, j)] for t in good])
    X[good] = linear.triangulate_pairs(P[i], P[j], xn[m1], xn[m2])
    for t in shared[~mask]:  # the pair's outliers: these two observations disagree
        inlier[lookup[(t, i)]] = inlier[lookup[(t, j)]] = False
    stats = {"initial_pair": [int(i), int(j)], "initial_inliers": int(mask.sum()), "bundle_adjustments": 0}
    last_ba = 2
    stopped = _report(callback, 2, n_views)

    def stopping() -> bool:  # asked by the adjustments, once an iteration
        nonlocal stopped
        stopped = stopped or _report(callback, int(registered.sum()), n_views)
        return stopped

    while not stopped:
        state = _adjust_if_grown(P, X, registered, obs, xn, scales, inlier, options, last_ba, stats, stopping)
        last_ba = state
        if stopped:
            break
        candidates = _resection_candidates(obs, X, registered, inlier, reasons)
        if not candidates:
            break
        added = False
        for v, count in candidates:
            where = np.flatnonzero((obs.view == v) & inlier & np.isfinite(X[obs.track, 0]))
            threshold = 2 * options.threshold_px * scales[v]  # rough points yet: judged again after adjusting
            camera, ok = linear.resect_ransac(X[obs.track[where]], xn[where], threshold, seed=options.seed + v)
            if camera is None or ok.sum() < options.min_inliers:
                reasons[v] = (f"resection found {int(ok.sum())} inliers among {len(where)} points "
                              f"(at least {options.min_inliers} needed)")
                continue
            P[v] = camera
            registered[v] = True
            reasons[v] = None
            inlier[where[~ok]] = False
            _triangulate_new(P, X, registered, obs, xn, scales, inlier, options)
            added = True
            stopped = _report(callback, int(registered.sum()), n_views)
            break
        if not added:
            break
    # Tracks still without a point get a second chance at the final reconstruction (an early pair
    # or resection may have rejected their observations), then one adjustment over everything.
    untriangulated = ~np.isfinite(X[obs.track, 0])
    inlier[untriangulated] = True
    _triangulate_new(P, X, registered, obs, xn, scales, inlier, options)
    if not stopped:
        _adjust(P, X, registered, obs, xn, scales, inlier, options, stats, final=True, should_stop=stopping)
    finite = np.isfinite(X[:, 0])
    # Tracks left with fewer than two inlier views are not reconstructed.
    counts = np.bincount(obs.track[inlier & registered[obs.view] & finite[obs.track]], minlength=obs.n_tracks)
    X[counts < 2] = np.nan
    cameras_px = np.array([np.linalg.solve(T[v], P[v]) if registered[v] else np.full((3, 4), np.nan)
                           for v in range(n_views)])
    oriented_cameras, oriented_points = _orient(cameras_px, X, obs, inlier, registered)
    kept = inlier & registered[obs.view] & np.isfinite(oriented_points[obs.track, 0])
    # Every observation is counted once: kept, an outlier (farther than the threshold from its
    # reprojection, or a pair no signs put in front), one of a track dropped (its point left with
    # fewer than two inlier views: its other observations are inliers, not kept), or of a view
    # not registered.
    seen_by = registered[obs.view]
    stats.update({"views_registered": int(registered.sum()), "points": int(np.isfinite(oriented_points[:, 0]).sum()),
                  "observations": int(len(obs.view)), "observations_kept": int(kept.sum()),
                  "outliers_removed": int((~inlier & seen_by).sum()),
                  "observations_of_dropped_tracks": int((inlier & seen_by & ~kept).sum()),
                  "observations_of_unregistered_views": int((~seen_by).sum())})
    if stopped:
        stats["cancelled"] = True
    for v in range(n_views):
        if not registered[v] and reasons[v] is None:
            reasons[v] = "the job was cancelled before this view was tried" if stopped else \
                "too few of its tracks were triangulated"
    return Projective([oriented_cameras[v] if registered[v] else None for v in range(n_views)], reasons,
                      oriented_points, kept, (int(i), int(j)), stats)


def _resection_candidates(obs, X, registered, inlier, reasons) -> list[tuple[int, int]]:
    have = inlier & np.isfinite(X[obs.track, 0]) & ~registered[obs.view]
    counts = np.bincount(obs.view[have], minlength=len(registered))
    order = np.argsort(-counts, kind="stable")
    return [(int(v), int(counts[v])) for v in order if counts[v] >= 6 and not registered[v]]


def _triangulate_new(P, X, registered, obs, xn, scales, inlier, options) -> None:
    """DLT points for tracks not yet triangulated that two registered views now see; an
    observation off by more than the threshold is rejected (and the point with it, when fewer
    than two remain)."""
    usable = inlier & registered[obs.view] & ~np.isfinite(X[obs.track, 0])
    counts = np.bincount(obs.track[usable], minlength=obs.n_tracks)
    order = np.argsort(obs.track[usable], kind="stable")
    rows = np.flatnonzero(usable)[order]
    starts = np.searchsorted(obs.track[rows], np.arange(obs.n_tracks))
    for t in np.flatnonzero(counts >= 2):
        m = rows[starts[t]:starts[t] + counts[t]]
        views = obs.view[m]
        point = linear.triangulate(P[views], xn[m])
        image = np.einsum("kij,j->ki", P[views], point)
        errors = np.linalg.norm(image[:, :2] / image[:, 2:3] - xn[m], axis=1) / scales[views]
        ok = errors < options.threshold_px
        if ok.sum() >= 2:
            if not ok.all():
                point = linear.triangulate(P[views[ok]], xn[m[ok]])
                inlier[m[~ok]] = False
            X[t] = point


def _adjust_if_grown(P, X, registered, obs, xn, scales, inlier, options, last: int, stats, should_stop=None) -> int:
    """Bundle adjust when the registered views have grown by a half (and at 3 views) since the
    last adjustment: a few adjustments in all, each over everything."""
    n = int(registered.sum())
    if n >= max(3, math.ceil(1.5 * last)) or (n == 2 and last == 2 and stats["bundle_adjustments"] == 0):
        _adjust(P, X, registered, obs, xn, scales, inlier, options, stats, final=False, should_stop=should_stop)
        return n
    return last


def _adjust(P, X, registered, obs, xn, scales, inlier, options, stats, final: bool, should_stop=None) -> None:
    """Bundle adjust every registered view and triangulated point over the inlier observations
    (Huber's loss first, then plain least squares), then judge every observation again.
    ``should_stop()``, asked each iteration, ends it where it is."""
    views = np.flatnonzero(registered)
    view_index = -np.ones(len(registered), dtype=int)
    view_index[views] = np.arange(len(views))
    rounds = 3 if final else 1
    for round_ in range(rounds):
        used = inlier & registered[obs.view] & np.isfinite(X[obs.track, 0])
        # A point left with fewer than two inlier observations is dropped (its track may come back).
        counts = np.bincount(obs.track[used], minlength=len(X))
        X[(counts < 2) & np.isfinite(X[:, 0])] = np.nan
        used &= np.isfinite(X[obs.track, 0])
        points = np.flatnonzero(np.isfinite(X[:, 0]))
        if len(points) == 0:
            return
        point_index = -np.ones(len(X), dtype=int)
        point_index[points] = np.arange(len(points))
        use = np.flatnonzero(used)
        cams, pts, _ = bundle.projective(P[views], X[points], view_index[obs.view[use]], point_index[obs.track[use]],
                                         xn[use], scales[views],
                                         f_scale=options.threshold_px / 2 if round_ == 0 else None,
                                         max_iterations=50 if final else 10, should_stop=should_stop)
        P[views], X[points] = cams, pts
        stats["bundle_adjustments"] += 1
        # Every observation of a registered view and a triangulated point is judged again at the
        # adjusted reconstruction: one rejected by an early, rough estimate comes back.
        judged = np.flatnonzero(registered[obs.view] & (point_index[obs.track] >= 0))
        image = np.einsum("mij,mj->mi", P[obs.view[judged]], X[obs.track[judged]])
        with np.errstate(divide="ignore", invalid="ignore"):
            errors = np.linalg.norm(image[:, :2] / image[:, 2:3] - xn[judged], axis=1) / scales[obs.view[judged]]
        was = inlier[judged].copy()
        inlier[judged] = errors < options.threshold_px
        if np.array_equal(was, inlier[judged]) and round_ > 0:
            break


def _orient(cameras, X, obs, inlier, registered):
    """Signs (and, when needed, the frame) so that every kept observation has positive depth."""
    views_idx = np.flatnonzero(registered)
    points_idx = np.flatnonzero(np.isfinite(X[:, 0]))
    if len(points_idx) == 0:
        return cameras, X
    vmap = {int(v): k for k, v in enumerate(views_idx)}
    pmap = {int(t): k for k, t in enumerate(points_idx)}
    seen: list[list[int]] = [[] for _ in points_idx]
    for m in np.flatnonzero(inlier & registered[obs.view] & np.isfinite(X[obs.track, 0])):
        seen[pmap[int(obs.track[m])]].append(vmap[int(obs.view[m])])
    result = orient(cameras[views_idx], X[points_idx], seen)
    # A pair no choice of signs puts in front (noise, or an outlier the threshold let through)
    # is an outlier observation of the chirality test.
    for camera, point in result.negative_depths + result.undetermined:
        where = (obs.view == views_idx[camera]) & (obs.track == points_idx[point])
        inlier[where] = False
    cams = cameras.copy()
    cams[views_idx] = np.asarray(result.cameras)
    points = X.copy()
    points[points_idx] = np.asarray(result.points)
    return cams, points
