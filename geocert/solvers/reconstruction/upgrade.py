"""Stage 3: the metric upgrade of the projective reconstruction by the stratified
autocalibration solver (thesis chapter 6; geocert.solvers.autocalibration), then, optionally,
a metric bundle adjustment with one K shared by every view.

The autocalibration stage solves for the plane at infinity and the DIAC over every plane
chirality allows and every K within the intrinsics ranges; its certificate is for the upgrade
it returns (H), before any adjustment moves the cameras."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.linalg import rq

from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.solvers.reconstruction import schur
from geocert.formulations.reconstruction import calibration_claim, motion_claim


@dataclass
class Metric:
    K: np.ndarray | None  # shared calibration (pixels, K[2, 2] = 1)
    rotations: list[np.ndarray | None]
    translations: list[np.ndarray | None]
    points: np.ndarray  # (T, 3), NaN where not reconstructed
    stages: list[dict]  # the autocalibration stages' figures (affine, metric)
    certified: bool  # both autocalibration stages certified
    reason: str | None = None
    ranges: dict = field(default_factory=dict)
    autocalibration_points: int = 0
    Ks: list | None = None  # one K per view (the "varying" adjustment), else K for every view
    alternative: tuple | None = None  # (H, K) of the linear estimate: a second start for the adjustment
    skipped: str | None = None  # why the certified search was not run (a critical motion), if it was not
    # "auto" with the direct method's upgrade found: why the stratified method was not tried first,
    # when it was not (the registered views spread too far for its frame)
    stratified_not_run: str | None = None
    # What a certificate of the stratified upgrade is built from (Proven), when one was solved
    proven: "Proven | None" = None
    k1: float = 0.0  # radial distortion about K's principal point (bundle model "radial"), of the pixels fit


@dataclass
class Proven:
    """A stratified solve as an autocalibration job would state it: its data (the registered
    views' projective cameras, the points used, the image size), the options it ran with, the
    prepared problem and stratified.solve's result (proofs recorded when the options ask a full
    certificate)."""
    cameras: np.ndarray
    points: np.ndarray
    image_size: tuple | None
    views: list  # the view of each camera
    tracks: list  # the track of each point
    options: autocalibration_problem.AutocalibrationOptions
    problem: autocalibration_problem.Problem
    result: object


def decompose(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """K (K[2, 2] = 1, positive diagonal), R (a rotation) and t of a camera Q ~ K [R | t] whose
    depths keep Q's sign (t is then negated with R when det R < 0: the mirrored solution)."""
    K, R = rq(Q[:, :3])
    D = np.diag(np.sign(np.diag(K)))
    K, R = K @ D, D @ R
    scale = K[2, 2]
    t = np.linalg.solve(K, Q[:, 3])
    if np.linalg.det(R) < 0:  # -K [R | t] is the same camera
        R, t = -R, -t
    return K / scale, R, t


def choose_points(points: np.ndarray, limit: int, observed: tuple[np.ndarray, np.ndarray] | None = None,
                  per_view: int = 0) -> np.ndarray:
    """Indices of about ``limit`` reconstructed points spread over the track list (the
    autocalibration's chirality rows; every point is not needed to bound the plane), with at least
    ``per_view`` seen by each view that sees that many (``observed``: the observations' views and
    tracks), added where the spread left a view short: a calibration certificate ties each of its
    cameras to the result through the points it shares with it."""
    finite = np.flatnonzero(np.isfinite(points[:, 0]))
    if len(finite) <= limit:
        return finite
    chosen = finite[np.linspace(0, len(finite) - 1, limit).round().astype(int)]
    if observed is None or per_view <= 0:
        return chosen
    view, track = observed
    usable = np.isfinite(points[track, 0])
    extra = []
    for v in np.unique(view[usable]):
        seen = np.unique(track[usable & (view == v)])
        short = per_view - np.count_nonzero(np.isin(seen, chosen))
        if short > 0:
            missing = seen[~np.isin(seen, chosen)]
            extra.append(missing[np.linspace(0, len(missing) - 1, min(short, len(missing))).round().astype(int)])
    return np.unique(np.concatenate([chosen, *extra])) if extra else chosen


def autocalibrate(cameras: list[np.ndarray | None], points: np.ndarray, image_size, intrinsics: dict,
                  options: autocalibration_problem.AutocalibrationOptions, max_points: int, method: str = "stratified",
                  callback=None, skip_critical: bool = False, observed: tuple[np.ndarray, np.ndarray] | None = None,
                  per_view: int = 0) -> Metric:
    """The metric upgrade by the stratified method (thesis ch. 6), the direct one (ch. 7), or
    "auto": stratified, and the direct method when the stratified one finds no upgrade or cannot
    be run (the registered views spread too far for its frame: ``stratified_not_run`` says so). With
    ``skip_critical``, the certified search is not run when the linear estimate's motion is
    critical (motion(): a turntable, an orbit, a translating camera): there the tracks do not
    determine constant intrinsics, and a certified optimum would be one of many equally good
    upgrades; ``skipped`` then says why, and the linear estimate is the adjustment's start.
    ``observed`` and ``per_view``: choose_points'."""
    views = [v for v, P in enumerate(cameras) if P is not None]
    n_tracks = len(points)
    empty = Metric(None, [None] * len(cameras), [None] * len(cameras), np.full((n_tracks, 3), np.nan), [], False)
    if len(views) < 3:
        empty.reason = f"autocalibration needs at least 3 registered views ({len(views)} registered)"
        return empty
    chosen = choose_points(points, max_points, observed, per_view)
    P = np.array([cameras[v] for v in views])
    X = points[chosen]
    problem = autocalibration_problem.prepare(P, X, image_size, intrinsics)
    empty.ranges, empty.autocalibration_points = problem.ranges, len(chosen)
    linear = _linear(P, X, image_size)  # the adjustment's second start, and the motion's first judge
    empty.alternative = linear
    if skip_critical and linear is not None:
        warnings, critical = motion(metric_from(cameras, points, *linear))
        if critical is not None:
            detail = next(w["detail"] for w in warnings if w["code"] == critical)
            empty.skipped = (f"the linear estimate's motion is critical ({critical}: {detail}): the certified "
                             "search was not run, since it could only certify one of many upgrades these tracks "
                             "fit equally well (options.autocalibration_on_critical_motion: \"search\" runs it)")
            empty.reason = empty.skipped
            return empty
    stages: list[dict] = []
    H = K = None
    proven = None
    # review 55: views near the reference outvote the world scale's median and leave the others
    # far, where a wrong K can be certified; the verifier refuses such a frame, so the stratified
    # stages are not run on it ("auto": the direct method alone, its reason saying so)
    spread = None if frames.world_frame_bounded(problem.norm) else (
        f"the registered views' distances from the reference spread too far for the stratified frame: the "
        f"farthest lies {problem.norm.world_scale * problem.norm.world_ratio_highest:.3g} away, beyond "
        f"2^{frames.EARLIER_WORLD_HIGHEST} (frames.world_frame_bounded)")
    if method == "stratified" and spread is not None:
        empty.reason = f"autocalibration found no metric upgrade ({spread})"
        return empty
    if method in ("stratified", "auto") and spread is None:
        H, K, found, solved = _stratified(problem, options, intrinsics, callback)
        stages += found
        if H is not None:
            proven = Proven(P, X, None if image_size is None else tuple(image_size), list(views),
                            [int(t) for t in chosen],
                            replace(options, intrinsics=intrinsics), problem, solved)
    if H is None and method in ("direct", "auto"):
        # the direct method's own frame (the reference as given), as its kind poses it; the
        # stratified stages above took the unit reference frame (prepare's default)
        direct_problem = autocalibration_problem.prepare(P, X, image_size, intrinsics, unit_reference=False)
        H, K, found = _direct(direct_problem, P, X, options)
        stages += found
    empty.stages = stages
    if H is None:
        reasons = "; ".join([f"stratified: not run, {spread}"] * (spread is not None)
                            + [f"{stage['name']}: {stage['reason']}" for stage in stages if stage.get("reason")])
        empty.reason = f"autocalibration found no metric upgrade ({reasons or 'no answer'})"
        return empty
    certified = bool(stages) and all(stage["certified"] for stage in stages if stage["status"] != "skipped")
    out = metric_from(cameras, points, H, K)
    out.stages, out.certified, out.ranges, out.autocalibration_points = stages, certified, problem.ranges, len(chosen)
    out.proven = proven
    out.alternative = linear
    if method == "auto" and spread is not None:  # the upgrade is the direct method's, the stratified one never tried
        out.stratified_not_run = (f"the stratified method was not run ({spread}): the upgrade is the direct "
                                  "method's")
    return out


def motion(metric: Metric, noise: float | None = None, plane_noise: float | None = None
           ) -> tuple[list[dict], str | None]:
    """motion_claim.motion of a metric reconstruction's cameras."""
    return motion_claim.motion(metric.rotations, metric.translations, noise, plane_noise)


def rotation_noise(metric: Metric, obs_view: np.ndarray, obs_track: np.ndarray, pixels: np.ndarray,
                   keep: np.ndarray) -> float | None:
    """motion_claim.rotation_noise of a metric reconstruction (its points, each view's K)."""
    Ks = [None if R is None else K_of(metric, v) for v, R in enumerate(metric.rotations)]
    return motion_claim.rotation_noise(Ks, metric.rotations, metric.translations, metric.points, obs_view, obs_track,
                                       pixels, keep)


def _linear(P: np.ndarray, X: np.ndarray, image_size):
    """(H, K) of the linear estimate (linear_daq.py), or None."""
    from geocert.formulations.autocalibration import direct
    from geocert.solvers.reconstruction import linear_daq

    if image_size is None:
        return None
    try:
        Q = linear_daq.quadric(P, image_size)
        if Q is None:
            return None
        H, _ = direct.upgrade(P, X, Q)
        K = direct.mean_calibration(P, Q)
    except (np.linalg.LinAlgError, ValueError):
        return None
    return None if K is None else (H, K / K[2, 2])


def metric_from(cameras: list[np.ndarray | None], points: np.ndarray, H: np.ndarray, K: np.ndarray) -> Metric:
    """The metric reconstruction an upgrade H gives: rotations and translations of every
    registered camera P H ~ K_i [R | t] (K is the shared estimate), points H^-1 X."""
    views = [v for v, P in enumerate(cameras) if P is not None]
    n_tracks = len(points)
    rotations: list = [None] * len(cameras)
    translations: list = [None] * len(cameras)
    for v in views:
        _, R, t = decompose(cameras[v] @ H)
        rotations[v], translations[v] = R, t
    finite = np.isfinite(points[:, 0])
    Xm = np.full((n_tracks, 3), np.nan)
    Xh = np.linalg.solve(H, points[finite].T).T
    with np.errstate(divide="ignore", invalid="ignore"):
        Xm[finite] = Xh[:, :3] / Xh[:, 3:4]
    # The upgrade may return the mirrored reconstruction (every depth negative: K [R | t] with
    # det R = 1 is -P H there); (R, -t, -X) projects the same and puts the points in front.
    signs = np.concatenate([np.sign((Xm[finite] @ rotations[v].T + translations[v])[:, 2]) for v in views])
    if np.nanmean(signs) < 0:
        Xm = -Xm
        translations = [None if t is None else -t for t in translations]
    return Metric(K, rotations, translations, Xm, [], False)


def _stratified(problem: autocalibration_problem.Problem, options, intrinsics, callback):
    from geocert.solvers.autocalibration import stratified

    result = stratified.solve(problem, replace(options, intrinsics=intrinsics), callback)
    stages = [_stage("affine", result.affine, result.affine_s), _stage("metric", result.metric, result.metric_s)]
    if (result.p is not None and stages[0]["certified"]
            and not autocalibration_problem.allowed_by_chirality(problem, result.p)):
        # As the autocalibration kind judges it: the plane as returned must be one chirality allows.
        stages[0].update(certified=False, status="not_certified",
                         reason="the plane returned is not strictly inside the chirality polytope")
    if result.K_unit is None or result.p is None:
        return None, None, stages, result
    K = problem.K0 @ result.K_unit
    K = K / K[2, 2]
    K[1, 0] = K[2, 0] = K[2, 1] = 0.0
    K[2, 2] = 1.0
    if stages[1]["certified"]:  # the K returned, as rounded, must lie in the metric stage's domain (as the kind's)
        from geocert.formulations.autocalibration import metric_relaxation

        setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, result.p, problem.unit_ranges)
        lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
        if not metric_relaxation.in_domain(setup, autocalibration_problem.w_of_K(problem, K), lo, hi):
            stages[1].update(certified=False, status="not_certified",
                             reason="the DIAC returned left its domain by rounding")
    return autocalibration_problem.upgrade(problem, result.p, np.linalg.solve(problem.K0, K)), K, stages, result


def _direct(problem: autocalibration_problem.Problem, P: np.ndarray, X: np.ndarray, options):
    from geocert.solvers.autocalibration import direct_solve
    from geocert.formulations.autocalibration import direct

    start = time.perf_counter()
    setup = direct.setup_for(problem, options.chirality)
    result = direct_solve.solve_direct(setup, options, False)
    stage = _stage("direct", result, time.perf_counter() - start)
    if result.Q is None:
        return None, None, [stage]
    try:
        Q_in = np.asarray(setup.to_input(result.Q))
        H, _ = direct.upgrade(P, X, Q_in)
        K = direct.mean_calibration(P, Q_in)
    except (np.linalg.LinAlgError, ValueError) as exc:
        stage.update(certified=False, status="not_certified", reason=f"no metric upgrade: {exc}")
        return None, None, [stage]
    if K is None:
        return None, None, [stage]
    return H, K / K[2, 2], [stage]


def _stage(name: str, stage, elapsed: float) -> dict:
    if stage is None:
        return {"name": name, "status": "failed", "certified": False, "cost": None, "lower_bound": None, "gap": None,
                "nodes": 0, "elapsed_s": elapsed, "reason": "not run"}
    cost = float(stage.cost) if stage.cost is not None and math.isfinite(stage.cost) else None
    lower = float(stage.lower_bound) if math.isfinite(stage.lower_bound) else None
    return {"name": name, "status": stage.status, "certified": bool(stage.certified), "cost": cost, "lower_bound": lower,
            "gap": None if cost is None or lower is None else max(0.0, cost - lower), "nodes": int(getattr(stage, "nodes", 0)),
            "elapsed_s": elapsed, "reason": stage.reason}


def K_of(metric: Metric, view: int) -> np.ndarray:
    return metric.K if metric.Ks is None else metric.Ks[view]


def focal_groups(metric: Metric) -> dict[int, int]:
    """{view: group} of the registered views by their focal lengths (equal ones share a group, as
    the bundle model "focal_groups" returns them): group 0 the most views' (ties: the smallest
    view's), the others numbered by their first view."""
    views = [v for v, R in enumerate(metric.rotations) if R is not None]
    focal = {v: float(K_of(metric, v)[0, 0]) for v in views}
    values = sorted(set(focal.values()), key=lambda f: (-sum(1 for v in views if focal[v] == f),
                                                         min(v for v in views if focal[v] == f)))
    order = [values[0]] + sorted(values[1:], key=lambda f: min(v for v in views if focal[v] == f))
    return {v: order.index(focal[v]) for v in views}


# When upgrade.adjust's first round (Huber's loss) ends before its iteration cap. That round only
# chooses the observations the second (plain least squares) keeps. With Huber's loss the steps are
# iteratively reweighted Gauss-Newton ones, which near the minimum converge only linearly: an
# observation on the loss's linear branch gets a curvature along its residual the loss does not
# have, so the steps undershoot, most on tracks all of whose observations are outliers (an L1-like
# fit). On every 2nd templeRing photo the gains shrank by about 5% an iteration (a relative gain
# of 4e-5 at the 30th), so Ceres's 1e-6 could not trigger and every full first round ran to its 30
# iterations; nor is the 30th converged: its kept observations still change (16,895 at 30
# iterations, 16,891 at 150) and its rotations are 0.02 degrees from the 150th's, as far as
# stopping at 1e-4 (7 to 16 iterations) leaves them; the bench's figures on every 2nd templeRing
# photo, templeSparseRing and the dinoSparseRing with K unknown are unchanged by it. So the first
# round stops at a relative gain of 1e-4, but for the models in PRECISE_ROUND_MODELS, which keep
# Ceres's (the first round's end moves them beyond the noise): K known ("fixed"; on the
# dinoSparseRing's 730 observations a few changing side of the threshold moved cameras by 0.1 to
# 0.3 degrees, and the median rotation error from 0.14 to 0.16), the per-view principal points
# (which follow the first round's end by pixels: 4.4 px at 30 iterations, 9 px more at 1e-4) and,
# as those, the per-view focal lengths ("focal_groups", not measured with 1e-4).
ROBUST_ROUND_STOP = schur.StopRule(function_tolerance=1e-4)
PRECISE_ROUND_MODELS = ("fixed", "principal_per_view", "focal_groups")


def robust_round_stop(model: str) -> schur.StopRule:
    """The first round's stopping rule for a bundle model (see ROBUST_ROUND_STOP)."""
    return schur.CERES if model in PRECISE_ROUND_MODELS else ROBUST_ROUND_STOP


def adjust(metric: Metric, obs_view: np.ndarray, obs_track: np.ndarray, pixels: np.ndarray, threshold_px: float,
           max_iterations: int = 30, model: str = "simple", should_stop=None,
           robust_stop: schur.StopRule | None = None,
           stop: schur.StopRule = schur.CERES, groups: dict | None = None) -> tuple[Metric, np.ndarray, dict]:
    """Metric bundle adjustment (one shared K): Huber's loss, then plain least squares on the
    observations within the threshold. Returns the adjusted reconstruction, the observations
    kept, and figures (among them each round's ``iterations`` and ``capped``: a round used all
    ``max_iterations``, so may have stopped short of its minimum). ``should_stop()`` (asked each
    iteration) ends it where it is;
    ``robust_stop`` and ``stop`` (schur.StopRule) end the first round and the second sooner
    (``robust_stop`` None: robust_round_stop(model)).
    ``groups`` (model "focal_groups"): each registered view's focal length group {view: group},
    the groups numbered from 0 (bundle.metric); None: focal_groups(metric), the groups its views'
    focal lengths form."""
    if robust_stop is None:
        robust_stop = robust_round_stop(model)
    from geocert.solvers.reconstruction import bundle

    start = time.perf_counter()
    views = np.array([v for v, R in enumerate(metric.rotations) if R is not None])
    vindex = -np.ones(len(metric.rotations), dtype=int)
    vindex[views] = np.arange(len(views))
    keep = (vindex[obs_view] >= 0) & np.isfinite(metric.points[obs_track, 0])
    K, R, t, X = metric.K, np.array([metric.rotations[v] for v in views]), \
        np.array([metric.translations[v] for v in views]), metric.points.copy()
    focals = None if metric.Ks is None else np.array([metric.Ks[v][0, 0] for v in views])
    # "principal_per_view" and "focal_groups": each view's principal point (the shared K's where
    # it has none of its own); "focal_groups" each view's focal length too (its group's)
    centres = None if model not in ("principal_per_view", "focal_groups") else np.array(
        [K_of(metric, v)[:2, 2] for v in views], dtype=float)
    if model == "principal_per_view":
        focals = None
    view_groups = None
    if model == "focal_groups":
        focals = np.array([K_of(metric, v)[0, 0] for v in views], dtype=float)
        groups = focal_groups(metric) if groups is None else groups
        view_groups = np.array([groups.get(int(v), 0) for v in views], dtype=int)
    rms_before = None
    k1 = metric.k1
    iterations = []  # each round's
    for round_ in range(2):
        counts = np.bincount(obs_track[keep], minlength=len(X))
        X[counts < 2] = np.nan
        keep &= np.isfinite(X[obs_track, 0])
        points = np.flatnonzero(np.isfinite(X[:, 0]))
        pindex = -np.ones(len(X), dtype=int)
        pindex[points] = np.arange(len(points))
        use = np.flatnonzero(keep)
        if len(use) == 0:  # nothing left to adjust (none within the threshold): as it is, none kept
            break
        # bundle.adjust (bundle.metric's, with the iterations it used): a round that used all
        # max_iterations may not have converged, its cost an upper bound of its minimum's
        out = bundle.adjust(K, R, t, X[points], vindex[obs_view[use]], pindex[obs_track[use]], pixels[use],
                            bundle.Free(model, focals=focals, centres=centres, groups=view_groups, k1=k1),
                            bundle.Schur(max_iterations, robust_stop if round_ == 0 else stop,
                                         threshold_px / 2 if round_ == 0 else None, should_stop))
        K, R, t, Xp, r, k1 = out.K, out.R, out.t, out.X, out.residuals, out.k1
        iterations.append(int(out.iterations))
        # (the K standing for a K per view here is the next round's start and Metric.K; the K a
        # result states is picked again among the cameras it returns: pipeline._stated_K)
        if K.ndim == 3 and model == "principal_per_view":  # one principal point per view: the middle one's K stands for them
            centres = K[:, :2, 2]
            K = K[calibration_claim.middle_centre(centres)]
        elif K.ndim == 3 and model == "focal_groups":  # one K per view: the middle principal point's stands for them
            centres, focals = K[:, :2, 2], K[:, 0, 0]
            shared = np.flatnonzero(view_groups == 0)  # group 0: the views sharing the first focal length
            K = K[shared[calibration_claim.middle_centre(centres[shared])]]
        elif K.ndim == 3:  # one K per view: the middle focal length stands for them in K
            focals = K[:, 0, 0]
            K = K[int(np.argsort(focals)[len(focals) // 2])]
        X[points] = Xp
        errors = np.linalg.norm(r, axis=1)
        if rms_before is None:
            rms_before = float(np.sqrt(np.mean(errors ** 2)))
        keep[use[~(errors < threshold_px)]] = False
    adjusted = replace(metric, K=K, points=X, k1=k1)
    if centres is not None:
        adjusted.Ks = [None] * len(metric.rotations)
        for k, v in enumerate(views):
            f = K[0, 0] if model != "focal_groups" else focals[k]
            adjusted.Ks[v] = np.array([[f, 0.0, centres[k, 0]], [0.0, f, centres[k, 1]], [0.0, 0.0, 1.0]])
    elif focals is not None:
        adjusted.Ks = [None] * len(metric.rotations)
        for k, v in enumerate(views):
            adjusted.Ks[v] = np.array([[focals[k], 0.0, K[0, 2]], [0.0, focals[k], K[1, 2]], [0.0, 0.0, 1.0]])
    adjusted.rotations = [None] * len(metric.rotations)
    adjusted.translations = [None] * len(metric.rotations)
    for k, v in enumerate(views):
        adjusted.rotations[v], adjusted.translations[v] = R[k], t[k]
    return adjusted, keep, {"elapsed_s": time.perf_counter() - start, "observations_kept": int(keep.sum()),
                            "K": K.tolist(), "iterations": iterations,
                            "capped": any(n >= max_iterations for n in iterations)}
