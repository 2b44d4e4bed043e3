"""Stage 4: certified structure in the metric frame. Every kept track is triangulated by the
certified triangulation solver (thesis chapter 5) in the cameras returned, so its point is the
certified optimum itself; every registered camera is resected by the certified resection solver
from the points returned, and the bound that search proves (no 3x4 camera putting those points
in front fits them better) is stated for the camera returned: its own cost, the gap to that
bound, and certified when its cost is within its tolerance of the bound (camera_claim: the
allowance its fewer degrees of freedom need, and the search's gap). The certificates are for
the numbers returned."""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

import numpy as np

from geocert.core import pieces
from geocert.core.geometry import norm_cost
from geocert.formulations.fractional.options import MapOptions, TriangulationOptions
from geocert.formulations.fractional.results import MapResult, TrackResult
from geocert.formulations.reconstruction import camera_claim
from geocert.solvers.reconstruction.camera_misfit import camera_misfit, misfit_cause, misfit_words


CAMERA_THREADS = 2  # cameras resected at once (see resect_cameras)


@dataclass
class CameraBound:
    view: int
    cost: float | None  # the returned camera's, on the returned points
    optimal_cost: float | None  # the certified resection's optimum
    lower_bound: float | None
    gap: float | None
    certified: bool
    status: str
    points: int
    elapsed_s: float
    reason: str | None
    result: MapResult | None = None
    dof: int | None = None  # the returned camera's own degrees of freedom (camera_claim.degrees_of_freedom)
    tolerance: float | None = None  # certified when cost <= (1 + tolerance) lower_bound + abs_gap (camera_claim)
    beyond_tolerance: bool = False  # a 3x4 camera (found or bounded) beats it by more than its tolerance
    # What refitting it on its points (held) recovers of its excess over the free 3x4 camera, each a
    # fraction of that camera's cost (camera_misfit); None when not looked at (certified, or no free camera)
    misfit: dict | None = None
    # Observations set aside as outliers before the bound (camera_claim.outliers): 0 when certified
    # or judged on all its points; None when not judged
    set_aside: int | None = None
    # The free 3x4 camera found locally that beats it by more than its tolerance, when that is why
    # it was not searched (the verifier recomputes both costs from it); None otherwise
    free_camera: np.ndarray | None = None


def camera_matrix(K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    return K @ np.hstack([R, t[:, None]])


TRACK_CHUNK = 500  # tracks triangulated at once: progress is told between chunks


def triangulate_tracks(cameras: dict[int, np.ndarray], tracks: list[tuple[np.ndarray, np.ndarray]],
                       options: TriangulationOptions, progress=None, should_stop=None) -> list[TrackResult | None]:
    """One certified triangulation per track (views, pixels) over the given cameras; None for a
    track with fewer than two views. Tracks are solved in chunks by the batched solver
    (fractional.many_tracks.triangulate_many: each track's result is what the certified solver
    returns for it alone, its root relaxations solved many at a time; 4,952 Dinosaur tracks in
    19.7 s one by one)."""
    from geocert.solvers.fractional.many_tracks import triangulate_many

    views = sorted(cameras)
    index = {view: i for i, view in enumerate(views)}
    stacked = np.array([cameras[view] for view in views], dtype=float).reshape(-1, 3, 4)
    out: list[TrackResult | None] = [None] * len(tracks)
    solvable = [i for i, (seen, _) in enumerate(tracks) if len(seen) >= 2]
    for first in range(0, len(solvable), TRACK_CHUNK):
        chunk = solvable[first:first + TRACK_CHUNK]
        if should_stop is not None and should_stop():
            for i in solvable[first:]:
                out[i] = TrackResult("cancelled", False, reason="the job was cancelled")
            break
        # should_stop is asked by the searches too (between nodes), so a chunk of tracks that
        # each search to their own time limit stops with the rest: those read cancelled, with the
        # best point found.
        found = triangulate_many(stacked, [([index[int(v)] for v in tracks[i][0]], np.asarray(tracks[i][1], float))
                                           for i in chunk], options,
                                 None if should_stop is None else lambda progress: should_stop())
        for i, result in zip(chunk, found):
            out[i] = result
        if progress is not None:
            progress(first + len(chunk), len(solvable))
    return out


def free_camera_cost(P: np.ndarray, X: np.ndarray, x: np.ndarray, norm: str) -> float | None:
    """The cost (under ``norm``) of a 3x4 camera refined locally from P with all 12 entries free
    (Levenberg-Marquardt on the pixel residuals), when it puts every point in front; else None.
    Any camera putting every point in front costs at least the certified resection's optimum, so
    this cost is an upper bound on it (and on any lower bound the resection could prove)."""
    found = free_camera(P, X, x, norm)
    return None if found is None else found[1]


def free_camera(P: np.ndarray, X: np.ndarray, x: np.ndarray, norm: str) -> tuple[np.ndarray, float] | None:
    """free_camera_cost's camera (its sign chosen so that every point has a positive depth) and
    cost; None when it puts a point behind it."""
    from scipy.optimize import least_squares

    Xh = np.hstack([X, np.ones((len(X), 1))])

    def residual(m):
        proj = Xh @ m.reshape(3, 4).T
        return (proj[:, :2] / proj[:, 2:3] - x).ravel()

    try:
        found = least_squares(residual, (P / np.linalg.norm(P)).ravel(), method="lm", x_scale="jac", max_nfev=200)
    except (ValueError, np.linalg.LinAlgError):
        return None
    M = found.x.reshape(3, 4)
    proj = Xh @ M.T
    if not (np.all(proj[:, 2] > 0) or np.all(proj[:, 2] < 0)) or not np.all(np.isfinite(proj)):
        return None
    if proj[0, 2] < 0:  # -M is the same camera with every depth of the other sign
        M, proj = -M, -proj
    cost = norm_cost(x - proj[:, :2] / proj[:, 2:3], norm)
    return (M, cost) if np.isfinite(cost) else None


def resect_cameras(cameras: dict[int, np.ndarray], sources: dict[int, tuple[np.ndarray, np.ndarray]],
                   options: MapOptions, progress=None, should_stop=None,
                   bound_every_camera: bool = False, threads: int | None = None,
                   dof: int = camera_claim.PROJECTIVE_DOF) -> dict[int, CameraBound]:
    """For each view: its points (3D) and pixels; the certified resection's bound, stated for
    the camera returned, which has ``dof`` degrees of freedom of its own (its tolerance:
    camera_claim.tolerance). Unless ``bound_every_camera``, the search is not run for a camera
    that cannot be certified whatever it proves: one with a point behind it, too few points for a
    tolerance, or one a free 3x4 camera found locally beats by more than its tolerance (the bound
    is at most that camera's cost); such a camera is reported with its cost and the reason, and
    no bound.

    Cameras are resected ``threads`` at a time (None: CAMERA_THREADS, at most the processors):
    the conic solver, most of a resection's time, releases the interpreter's lock. Each camera's
    search is the same as alone; the largest start first, so the last to finish is a small one."""
    threads = max(1, min(CAMERA_THREADS, os.cpu_count() or 1) if threads is None else threads)
    order = sorted(cameras, key=lambda view: (-len(sources.get(view, ((),))[0]), view))
    out: dict[int, CameraBound] = {}

    def points(view: int):
        return sources.get(view, (np.zeros((0, 3)), np.zeros((0, 2))))

    if pieces.spreading():  # a caller spreads each camera's search over processes (core.pieces)
        def stop(k: int) -> bool:
            if k and progress is not None:
                progress(k, len(cameras))
            return bool(should_stop is not None and should_stop())

        found = pieces.mapped(bound_camera, (options, bound_every_camera, dof),
                              [(view, cameras[view], *points(view)) for view in order], stop, pieces.in_order)
        out = {bound.view: bound for bound in found or []}
        if progress is not None and len(out) == len(cameras):
            progress(len(out), len(cameras))
    else:
        # At most ``threads`` cameras in flight, progress reported as each ends, and a cancel
        # looked for once a camera has ended: the cameras in flight finish, the rest never start.
        def ended(k: int, bound: CameraBound) -> None:
            out[bound.view] = bound
            if progress is not None:
                progress(len(out), len(cameras))

        def stop(k: int) -> bool | None:
            return None if out and should_stop is not None and should_stop() else False

        pieces.in_threads(lambda view: _bound_camera(view, cameras[view], *points(view), options, bound_every_camera,
                                                     dof), order, stop, threads, done=ended)
    for view in order:
        if view not in out:
            out[view] = CameraBound(view, None, None, None, None, False, "cancelled", len(points(view)[0]), 0.0,
                                    "the job was cancelled")
    return dict(sorted(out.items()))


@pieces.piece
def bound_camera(shared: tuple, camera: tuple) -> CameraBound:
    """_bound_camera of one camera (view, P, its points, its pixels): a piece of the cameras
    stage, ``shared`` (options, bound_every_camera, dof)."""
    options, bound_every_camera, dof = shared
    return _bound_camera(*camera, options, bound_every_camera, dof)


def _bound_camera(view: int, P: np.ndarray, X: np.ndarray, x: np.ndarray, options: MapOptions,
                  bound_every_camera: bool, dof: int = camera_claim.PROJECTIVE_DOF) -> CameraBound:
    """One camera's figures and bound (see resect_cameras): on all its points, and when that does
    not certify it, again without the observations camera_claim.outliers sets aside (the claim is
    then about the points kept, and says how many were set aside); the first when neither does."""
    whole = _bound_on(view, P, X, x, options, bound_every_camera, dof)
    whole.set_aside = 0 if whole.status != "cancelled" else None
    if whole.certified or whole.status == "degenerate":
        return whole
    beyond = camera_claim.outliers(X, x, P)
    if beyond is None:
        return whole
    inliers = _bound_on(view, P, X[~beyond], x[~beyond], options, bound_every_camera, dof)
    if not inliers.certified:
        return whole
    inliers.set_aside = int(beyond.sum())
    inliers.elapsed_s += whole.elapsed_s
    return inliers


def _bound_on(view: int, P: np.ndarray, X: np.ndarray, x: np.ndarray, options: MapOptions,
              bound_every_camera: bool, dof: int = camera_claim.PROJECTIVE_DOF) -> CameraBound:
    """One camera's figures and bound on this map (see resect_cameras)."""
    from geocert.solvers.fractional.maps import fit_map

    start = time.perf_counter()
    if len(X) < camera_claim.MIN_POINTS:
        return CameraBound(view, None, None, None, None, False, "degenerate", len(X), 0.0,
                           f"{len(X)} points: a camera needs at least {camera_claim.MIN_POINTS}", dof=dof)
    proj = np.hstack([X, np.ones((len(X), 1))]) @ P.T
    depths_positive = bool(np.all(proj[:, 2] > 0))
    residuals = x - proj[:, :2] / proj[:, 2:3]
    cost = norm_cost(residuals, options.norm)
    tolerance = camera_claim.tolerance(len(X), dof, options.norm, options.rel_gap)
    kept_cost = cost if math.isfinite(cost) else None

    def unbounded(reason: str, beyond: bool = False, misfit: dict | None = None) -> CameraBound:
        return CameraBound(view, kept_cost, None, None, None, False, "not_certified", len(X),
                           time.perf_counter() - start, reason, dof=dof, tolerance=tolerance, beyond_tolerance=beyond,
                           misfit=misfit)

    if tolerance is None:
        return unbounded(f"camera_rel_gap {options.rel_gap:g} leaves no tolerance")
    model = camera_claim.model_allowance(len(X), dof, options.norm)
    withheld = camera_claim.allowance(len(X), dof, options.norm) != model
    # A camera beyond what its degrees of freedom explain (allowance withheld or not) is flagged:
    # a 3x4 camera beats it by more than the noise allows a sound one to be beaten.
    flag_tolerance = (1.0 + model) / (1.0 - options.rel_gap) - 1.0
    why = (f"; {len(X)} points are too few for an allowance for its {dof} degrees of freedom (it would exceed "
           f"{camera_claim.MAX_ALLOWANCE:g}), so it is held to the bound as a 3x4 camera is" if withheld else "")
    if not bound_every_camera:
        if not depths_positive:
            return unbounded("a point is behind the camera returned: outside the bound's scope")
        found = free_camera(P, X, x, options.norm)
        free = None if found is None else found[1]
        # beaten with JUDGED_MARGIN to spare (so that the verifier's recomputation agrees); else searched
        if free is not None and not camera_claim.within(cost, free * (1 + camera_claim.JUDGED_MARGIN), tolerance,
                                                        options.abs_gap):
            excess = (cost - free) / max(free, 1e-300)
            misfit = camera_misfit(P, X, x, options.norm, free)
            if misfit is not None:
                misfit["cause"] = misfit_cause(misfit, excess, len(X), dof, options.norm, options.rel_gap)
            judged = unbounded(f"the camera returned costs {cost:.4g}, {excess:.2%} above a "
                               f"free 3x4 camera found locally ({free:.4g}), more than its tolerance {tolerance:.2%}: "
                               "no bound can certify it, so the certified resection was not run "
                               "(options.bound_every_camera runs it)" + why + misfit_words(misfit),
                               beyond=not camera_claim.within(cost, free, flag_tolerance, options.abs_gap),
                               misfit=misfit)
            judged.free_camera = found[0]
            return judged
    result = fit_map(X, x, options)
    lower = result.lower_bound if result.certified else None
    gap = None if lower is None else max(0.0, cost - lower)
    certified = bool(result.certified and depths_positive and lower is not None
                     and camera_claim.within(cost, lower, tolerance, options.abs_gap))
    if certified:
        status, reason = "optimal", None
    elif not result.certified:
        status, reason = result.status, f"the resection was not certified: {result.reason}"
    elif not depths_positive:
        status, reason = "not_certified", "a point is behind the camera returned: outside the bound's scope"
    else:
        status, reason = "not_certified", (f"the camera returned costs {cost:.4g}, {gap / max(lower, 1e-300):.2%} "
                                           f"above the certified bound, more than its tolerance {tolerance:.2%} "
                                           f"(what its {dof} degrees of freedom against 11 allow on {len(X)} points)"
                                           + why)
    beyond = bool(result.certified and depths_positive and lower is not None
                  and not camera_claim.within(cost, lower, flag_tolerance, options.abs_gap))
    return CameraBound(view, kept_cost, result.cost, lower, gap, certified, status, len(X),
                       time.perf_counter() - start, reason, result, dof=dof, tolerance=tolerance,
                       beyond_tolerance=beyond)
