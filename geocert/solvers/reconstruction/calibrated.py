"""The K-known path: tracks and each view's calibration K to a metric reconstruction (issue 14).

Used when the user gives K (then no projective stage and no autocalibration are needed: the
essential matrix fixes the pair's geometry up to scale). The steps, incremental as in COLMAP
(Schönberger and Frahm 2016) and Hartley and Zisserman's chapters 9-12 and 18:

1. Initial pair: among the pairs sharing the most tracks, an essential matrix by RANSAC (five
   points, Nistér 2004; ``cv2.findEssentialMat`` on normalised coordinates) and the relative pose
   that puts the points in front of both cameras (``cv2.recoverPose``). The pair kept has the most
   inliers whose rays meet at ``init_min_angle_deg`` or more: many matches and a baseline wide
   enough to place them.
2. Triangulation of the tracks seen by the registered views (linear, then refined by the bundle
   adjustments), kept when the rays' widest angle is at least ``min_triangulation_angle_deg``,
   every used observation reprojects within ``max_reprojection_px`` and the point lies in front of
   every camera that sees it (chirality).
3. Views added one at a time, the one seeing the most triangulated points first, by PnP RANSAC
   (``cv2.solvePnPRansac``) on those points, then the tracks they complete triangulated.
4. Metric bundle adjustment (``scipy.optimize.least_squares``, rotations as rotation vectors,
   sparse Jacobian, robust loss) after each view and at the end; observations that reproject
   farther than ``max_reprojection_px`` or lie behind their camera are then marked outliers and
   counted, and a point left with fewer than two inlier observations is dropped.

The gauge: the first camera of the initial pair stays at R = I, t = 0 and the pair's baseline has
length 1 (the bundle adjustment keeps the first camera fixed; the scale is free). Cameras are
x_cam = R X + t, pixels x ~ K x_cam.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix
from scipy.spatial.transform import Rotation


@dataclass
class CalibratedOptions:
    min_pair_tracks: int = 30  # tracks two views must share to be tried as the initial pair
    init_candidates: int = 12  # initial pairs tried (those sharing the most tracks)
    essential_threshold_px: float = 1.0  # RANSAC threshold of the essential matrix (pixels)
    init_min_angle_deg: float = 2.0  # an initial-pair inlier counts when its rays meet at least this wide
    min_triangulation_angle_deg: float = 1.0
    max_reprojection_px: float = 4.0  # an observation farther than this from its point's image is an outlier
    pnp_threshold_px: float = 4.0
    pnp_min_inliers: int = 15
    pnp_iterations: int = 2000
    essential_min_tracks: int = 15  # fallback registration: tracks linking the view to a registered one
    essential_min_points: int = 3  # and triangulated points it sees (to fix the translation's length)
    ba_loss: str = "soft_l1"  # least_squares' robust loss
    ba_f_scale_px: float = 1.0  # residual (pixels) where the robust loss starts to flatten
    ba_max_nfev: int = 30  # per bundle adjustment after a view is added
    final_ba_max_nfev: int = 200
    final_rounds: int = 3  # final bundle adjustment / outlier removal rounds
    seed: int = 0  # OpenCV's RANSAC generator


@dataclass
class CalibratedReconstruction:
    rotations: list[np.ndarray | None]  # per view, None when not registered
    translations: list[np.ndarray | None]  # x_cam = R X + t
    reasons: list[str | None]  # why a view is not registered (None when it is)
    points: np.ndarray  # (T, 3), NaN rows for tracks without a point
    inliers: list[np.ndarray]  # per track, bool per observation
    stats: dict = field(default_factory=dict)
    status: str = "ok"  # "ok", "failed" (no initial pair: every view unregistered) or "cancelled"


# ---------------------------------------------------------------------------------------------
# Geometry helpers


def triangulate(Rs: np.ndarray, ts: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Linear (DLT) triangulation from normalised image points ``rays`` (k, 2) seen by cameras
    [R | t] (k, 3, 3), (k, 3); rows scaled to unit norm so each view weighs alike."""
    P = np.concatenate([Rs, ts[:, :, None]], axis=2)
    A = np.concatenate([rays[:, 0:1] * P[:, 2] - P[:, 0], rays[:, 1:2] * P[:, 2] - P[:, 1]], axis=0)
    A /= np.linalg.norm(A, axis=1, keepdims=True)
    _, _, vt = np.linalg.svd(A)
    X = vt[-1]
    if abs(X[3]) < 1e-12:
        return np.full(3, np.nan)
    return X[:3] / X[3]


def max_ray_angle_deg(centres: np.ndarray, X: np.ndarray) -> float:
    """The widest angle between the rays from the camera centres to X."""
    d = X[None, :] - centres
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    cos = np.clip(d @ d.T, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos.min())))


def rotation_angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def align_rotations(estimated: list[np.ndarray], truth: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The world rotation A with R_est A closest to R_true over the given views (chordal L2 mean of
    R_est^T R_true, projected on SO(3)), and each view's angle (degrees) between R_est A and R_true.
    Rotations are invariant to the world's translation and scale, so this is the rotation part of a
    similarity alignment."""
    M = sum(Re.T @ Rt for Re, Rt in zip(estimated, truth))
    U, _, Vt = np.linalg.svd(M)
    A = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    return A, np.array([rotation_angle_deg((Re @ A).T @ Rt) for Re, Rt in zip(estimated, truth)])


# ---------------------------------------------------------------------------------------------
# State


class _State:
    """Observations flattened over tracks, with cameras and points as they are estimated."""

    def __init__(self, tracks, Ks):
        self.n_views = len(Ks)
        self.Ks = [np.asarray(K, dtype=np.float64) for K in Ks]
        self.Kinv = [np.linalg.inv(K) for K in self.Ks]
        lengths = [len(v) for v, _ in tracks]
        self.start = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        n_obs = int(self.start[-1])
        self.obs_track = np.repeat(np.arange(len(tracks)), lengths).astype(np.int64)
        self.obs_view = (np.concatenate([np.asarray(v, dtype=np.int64) for v, _ in tracks])
                         if tracks else np.zeros(0, np.int64))
        self.obs_px = (np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 2) for _, p in tracks])
                       if tracks else np.zeros((0, 2)))
        self.obs_ray = np.zeros((n_obs, 2))
        for v in range(self.n_views):
            sel = self.obs_view == v
            h = np.c_[self.obs_px[sel], np.ones(sel.sum())] @ self.Kinv[v].T
            self.obs_ray[sel] = h[:, :2] / h[:, 2:3]
        self.inlier = np.ones(n_obs, dtype=bool)
        self.R = [None] * self.n_views
        self.t = [None] * self.n_views
        self.points = np.full((len(tracks), 3), np.nan)
        self.outliers_removed = 0

    @property
    def registered(self) -> np.ndarray:
        return np.array([R is not None for R in self.R], dtype=bool)

    def centre(self, v: int) -> np.ndarray:
        return -self.R[v].T @ self.t[v]

    def reprojection(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel error and depth of observations (of registered views and triangulated points)."""
        err = np.full(len(obs), np.inf)
        depth = np.full(len(obs), -np.inf)
        for v in np.unique(self.obs_view[obs]):
            sel = self.obs_view[obs] == v
            X = self.points[self.obs_track[obs[sel]]]
            xc = X @ self.R[v].T + self.t[v]
            h = xc @ self.Ks[v].T
            with np.errstate(divide="ignore", invalid="ignore"):
                px = h[:, :2] / h[:, 2:3]
            err[sel] = np.linalg.norm(px - self.obs_px[obs[sel]], axis=1)
            depth[sel] = xc[:, 2]
        return np.nan_to_num(err, nan=np.inf), np.nan_to_num(depth, nan=-np.inf)


def _triangulate_track(state: _State, track: int, options: CalibratedOptions) -> bool:
    """Triangulate one track from its inlier observations in registered views (see step 2)."""
    registered = state.registered
    obs = np.arange(state.start[track], state.start[track + 1])
    for _ in range(2):  # once more without the observations that disagree
        obs = obs[state.inlier[obs] & registered[state.obs_view[obs]]]
        if len(obs) < 2:
            return False
        views = state.obs_view[obs]
        X = triangulate(np.array([state.R[v] for v in views]), np.array([state.t[v] for v in views]),
                        state.obs_ray[obs])
        if not np.all(np.isfinite(X)):
            return False
        centres = np.array([state.centre(v) for v in views])
        if max_ray_angle_deg(centres, X) < options.min_triangulation_angle_deg:
            return False
        state.points[track] = X
        err, depth = state.reprojection(obs)
        bad = (err > options.max_reprojection_px) | (depth <= 0)
        if not bad.any():
            return True
        state.points[track] = np.nan
        state.inlier[obs[bad]] = False
        state.outliers_removed += int(bad.sum())
    return False


def _triangulate_new(state: _State, options: CalibratedOptions) -> int:
    """Triangulate every track without a point that has two inlier observations in registered views."""
    registered = state.registered
    seen = np.bincount(state.obs_track[state.inlier & registered[state.obs_view]], minlength=len(state.points))
    made = 0
    for track in np.flatnonzero((seen >= 2) & np.isnan(state.points[:, 0])):
        made += _triangulate_track(state, int(track), options)
    return made


def _remove_outliers(state: _State, options: CalibratedOptions) -> int:
    """Mark observations that reproject too far or lie behind their camera as outliers; drop points
    left with fewer than two inlier observations. Returns the observations newly marked."""
    registered = state.registered
    valid = np.isfinite(state.points[:, 0])
    obs = np.flatnonzero(state.inlier & registered[state.obs_view] & valid[state.obs_track])
    err, depth = state.reprojection(obs)
    bad = obs[(err > options.max_reprojection_px) | (depth <= 0)]
    state.inlier[bad] = False
    state.outliers_removed += len(bad)
    seen = np.bincount(state.obs_track[state.inlier & registered[state.obs_view]], minlength=len(state.points))
    state.points[(seen < 2) & valid] = np.nan
    return len(bad)


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices of rows of v (n, 3) -> (n, 3, 3)."""
    S = np.zeros((len(v), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return S


def _left_jacobian(w: np.ndarray) -> np.ndarray:
    """SO(3)'s left Jacobian J(w) (n, 3, 3): exp(w + e) = exp(J(w) e) exp(w) to first order."""
    theta = np.linalg.norm(w, axis=1)
    W = _skew(w)
    small = theta < 1e-8
    th = np.where(small, 1.0, theta)
    a = np.where(small, 0.5, (1 - np.cos(th)) / th ** 2)
    b = np.where(small, 1.0 / 6.0, (th - np.sin(th)) / th ** 3)
    return np.eye(3)[None] + a[:, None, None] * W + b[:, None, None] * (W @ W)


def _bundle_adjust(state: _State, fixed: int, max_nfev: int, options: CalibratedOptions, ftol: float = 1e-8) -> int:
    """Metric bundle adjustment of registered cameras (all but ``fixed``) and valid points over the
    inlier observations; returns the function evaluations used.

    Each free camera's rotation is exp(w) R0 with R0 its rotation at the start and w a rotation
    vector (starting at 0); the Jacobian is analytic (pixels against w, t and the point)."""
    registered = state.registered
    valid = np.isfinite(state.points[:, 0])
    obs = np.flatnonzero(state.inlier & registered[state.obs_view] & valid[state.obs_track])
    if len(obs) == 0:
        return 0
    free_views = [int(v) for v in np.flatnonzero(registered) if v != fixed]
    cam_of_view = np.full(state.n_views, -1)
    cam_of_view[free_views] = np.arange(len(free_views))
    tracks = np.flatnonzero(valid)
    pt_of_track = np.full(len(state.points), -1)
    pt_of_track[tracks] = np.arange(len(tracks))
    o_view, o_cam, o_pt = state.obs_view[obs], cam_of_view[state.obs_view[obs]], pt_of_track[state.obs_track[obs]]
    o_px = state.obs_px[obs]
    Ks = np.array(state.Ks)[o_view]
    n_free, n_cam = len(free_views), 6 * len(free_views)
    R0 = np.array([state.R[v] for v in free_views]).reshape(-1, 3, 3)
    moving = o_cam >= 0
    m_idx = np.flatnonzero(moving)

    def cameras(x):
        """Per observation: rotation, translation (the fixed camera's where o_cam < 0), and w."""
        c = x[:n_cam].reshape(-1, 6)
        Rf = Rotation.from_rotvec(c[:, :3]).as_matrix().reshape(-1, 3, 3) @ R0 if n_free else R0
        R_obs = np.repeat(state.R[fixed][None], len(obs), axis=0)
        t_obs = np.repeat(state.t[fixed][None], len(obs), axis=0)
        R_obs[moving] = Rf[o_cam[moving]]
        t_obs[moving] = c[o_cam[moving], 3:]
        return R_obs, t_obs, c

    def project(x):
        R_obs, t_obs, c = cameras(x)
        X = x[n_cam:].reshape(-1, 3)[o_pt]
        xc = np.einsum("nij,nj->ni", R_obs, X) + t_obs
        h = np.einsum("nij,nj->ni", Ks, xc)
        z = np.where(np.abs(h[:, 2]) < 1e-12, 1e-12, h[:, 2])
        return R_obs, t_obs, c, X, xc, h, z

    def residuals(x):
        *_, h, z = project(x)
        return (h[:, :2] / z[:, None] - o_px).ravel()

    r = np.arange(len(obs))
    rows = np.concatenate([np.repeat(2 * m_idx[:, None] + np.arange(2)[None, :], 6, axis=1).ravel(),
                           np.repeat(2 * r[:, None] + np.arange(2)[None, :], 3, axis=1).ravel()])
    cam_cols = (6 * o_cam[m_idx])[:, None] + np.arange(6)[None, :]
    pt_cols = (n_cam + 3 * o_pt)[:, None] + np.arange(3)[None, :]
    cols = np.concatenate([np.tile(cam_cols, (1, 2)).reshape(-1, 2, 6).ravel(),
                           np.tile(pt_cols, (1, 2)).reshape(-1, 2, 3).ravel()])

    def jacobian(x):
        R_obs, t_obs, c, X, xc, h, z = project(x)
        dh = np.zeros((len(obs), 2, 3))  # d pixel / d h
        dh[:, 0, 0] = dh[:, 1, 1] = 1.0 / z
        dh[:, :, 2] = -h[:, :2] / (z ** 2)[:, None]
        du_dxc = dh @ Ks  # (n, 2, 3)
        d_pt = du_dxc @ R_obs
        m = m_idx
        d_w = -du_dxc[m] @ _skew(xc[m] - t_obs[m]) @ _left_jacobian(c[o_cam[m], :3])
        d_cam = np.concatenate([d_w, du_dxc[m]], axis=2)  # (k, 2, 6)
        vals = np.concatenate([d_cam.ravel(), d_pt.ravel()])
        return coo_matrix((vals, (rows, cols)), shape=(2 * len(obs), len(x))).tocsr()

    x0 = np.concatenate([np.concatenate([np.r_[np.zeros(3), state.t[v]] for v in free_views])
                         if free_views else np.zeros(0), state.points[tracks].ravel()])
    result = least_squares(residuals, x0, jac=jacobian, loss=options.ba_loss, f_scale=options.ba_f_scale_px,
                           x_scale="jac", method="trf", tr_solver="lsmr", max_nfev=max_nfev,
                           ftol=ftol, xtol=1e-10, gtol=1e-10)
    R_obs, t_obs, c = cameras(result.x)
    for k, v in enumerate(free_views):
        state.R[v] = Rotation.from_rotvec(c[k, :3]).as_matrix() @ R0[k]
        state.t[v] = c[k, 3:].copy()
    state.points[tracks] = result.x[n_cam:].reshape(-1, 3)
    return int(result.nfev)


# ---------------------------------------------------------------------------------------------
# Steps


def _initial_pair(state: _State, options: CalibratedOptions) -> tuple[int, int, np.ndarray, np.ndarray] | None:
    """The initial pair and its relative pose (R, t with |t| = 1), or None (step 1)."""
    shared: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for track in range(len(state.points)):
        obs = np.arange(state.start[track], state.start[track + 1])
        for a in range(len(obs)):
            for b in range(a + 1, len(obs)):
                i, j = state.obs_view[obs[a]], state.obs_view[obs[b]]
                key, pair = ((i, j), (obs[a], obs[b])) if i < j else ((j, i), (obs[b], obs[a]))
                shared.setdefault((int(key[0]), int(key[1])), []).append(pair)
    candidates = sorted((p for p in shared if len(shared[p]) >= max(options.min_pair_tracks, 5)),
                        key=lambda p: -len(shared[p]))[:options.init_candidates]
    best, best_score = None, 0
    for i, j in candidates:
        pairs = np.array(shared[(i, j)])
        ra, rb = state.obs_ray[pairs[:, 0]], state.obs_ray[pairs[:, 1]]
        focal = 0.5 * (state.Ks[i][0, 0] + state.Ks[j][1, 1] + state.Ks[i][1, 1] + state.Ks[j][0, 0]) / 2
        E, mask = cv2.findEssentialMat(ra, rb, np.eye(3), method=cv2.RANSAC, prob=0.9999,
                                       threshold=options.essential_threshold_px / focal)
        if E is None or mask is None:
            continue
        E = E[:3]
        _, R, t, pose_mask = cv2.recoverPose(E, ra, rb, np.eye(3), mask=mask.copy())
        inl = pose_mask.ravel() > 0
        t = t.ravel() / np.linalg.norm(t)
        # Rays' angles at the triangulated points (two-view midpoint geometry).
        c2 = -R.T @ t
        score = 0
        for a, b in zip(ra[inl], rb[inl]):
            X = triangulate(np.array([np.eye(3), R]), np.array([np.zeros(3), t]), np.array([a, b]))
            if np.all(np.isfinite(X)) and max_ray_angle_deg(np.array([np.zeros(3), c2]), X) >= options.init_min_angle_deg:
                score += 1
        if score > best_score:
            best, best_score = (i, j, R, t), score
    return best


def _register_next(state: _State, options: CalibratedOptions, last_tried: dict) -> tuple[int | None, dict]:
    """PnP RANSAC on the unregistered view seeing the most triangulated points (step 3). Views whose
    count has not grown since they last failed are skipped. Returns the view added (or None) and
    the reasons of the views that failed this round."""
    registered = state.registered
    valid = np.isfinite(state.points[:, 0])
    usable = state.inlier & valid[state.obs_track] & ~registered[state.obs_view]
    counts = np.bincount(state.obs_view[usable], minlength=state.n_views)
    reasons = {}
    for v in np.argsort(-counts, kind="stable"):
        v = int(v)
        if registered[v] or counts[v] <= last_tried.get(v, -1):
            continue
        last_tried[v] = int(counts[v])
        if counts[v] < options.pnp_min_inliers:
            reasons[v] = f"sees {counts[v]} triangulated points; PnP needs {options.pnp_min_inliers}"
            continue
        obs = np.flatnonzero(usable & (state.obs_view == v))
        X = state.points[state.obs_track[obs]]
        ok, rvec, tvec, inl = cv2.solvePnPRansac(X, state.obs_px[obs], state.Ks[v], None,
                                                 iterationsCount=options.pnp_iterations,
                                                 reprojectionError=options.pnp_threshold_px,
                                                 confidence=0.9999, flags=cv2.SOLVEPNP_EPNP)
        n_in = 0 if (not ok or inl is None) else len(inl)
        if n_in < options.pnp_min_inliers:
            reasons[v] = f"PnP RANSAC found {n_in} inliers among {counts[v]} points; {options.pnp_min_inliers} needed"
            continue
        inl = inl.ravel()
        rvec, tvec = cv2.solvePnPRefineLM(X[inl], state.obs_px[obs[inl]], state.Ks[v], None, rvec, tvec)
        state.R[v] = cv2.Rodrigues(rvec)[0]
        state.t[v] = tvec.ravel().astype(np.float64)
        err, depth = state.reprojection(obs)
        bad = (err > options.max_reprojection_px) | (depth <= 0)
        state.inlier[obs[bad]] = False
        state.outliers_removed += int(bad.sum())
        return v, reasons
    return None, reasons


def _register_by_essential(state: _State, options: CalibratedOptions) -> int | None:
    """Fallback when no view can be resected: a view linked to a registered view a by enough tracks
    takes the pair's relative pose (essential matrix, RANSAC, as for the initial pair) composed with
    a's pose; the translation's length comes from the triangulated points the view sees (the median
    of each point's scale, at least ``essential_min_points`` points reprojecting within
    ``pnp_threshold_px``). The bundle adjustment that follows refines it with the other views."""
    registered = state.registered
    valid = np.isfinite(state.points[:, 0])
    links = {}
    for track in range(len(state.points)):
        obs = np.arange(state.start[track], state.start[track + 1])
        obs = obs[state.inlier[obs]]
        views = state.obs_view[obs]
        for o_new, v in zip(obs, views):
            if registered[v]:
                continue
            for o_old, a in zip(obs, views):
                if registered[a]:
                    links.setdefault((int(v), int(a)), []).append((o_old, o_new))
    for (v, a), pairs in sorted(links.items(), key=lambda kv: -len(kv[1])):
        if len(pairs) < options.essential_min_tracks:
            break
        pairs = np.array(pairs)
        ra, rb = state.obs_ray[pairs[:, 0]], state.obs_ray[pairs[:, 1]]
        focal = 0.25 * (state.Ks[a][0, 0] + state.Ks[a][1, 1] + state.Ks[v][0, 0] + state.Ks[v][1, 1])
        E, mask = cv2.findEssentialMat(ra, rb, np.eye(3), method=cv2.RANSAC, prob=0.9999,
                                       threshold=options.essential_threshold_px / focal)
        if E is None or mask is None:
            continue
        n_in, R_rel, u, mask = cv2.recoverPose(E[:3], ra, rb, np.eye(3), mask=mask.copy())
        if n_in < options.essential_min_tracks:
            continue
        u = u.ravel() / np.linalg.norm(u)
        obs = np.flatnonzero(state.inlier & (state.obs_view == v) & valid[state.obs_track])
        if len(obs) < options.essential_min_points:
            continue
        Y = state.points[state.obs_track[obs]] @ (R_rel @ state.R[a]).T + R_rel @ state.t[a]
        x = np.c_[state.obs_ray[obs], np.ones(len(obs))]
        xu, xY = np.cross(x, u), np.cross(x, Y)
        scales = -np.einsum("ni,ni->n", xu, xY) / np.maximum(np.einsum("ni,ni->n", xu, xu), 1e-300)
        scale = float(np.median(scales))
        if not scale > 0:
            continue
        state.R[v], state.t[v] = R_rel @ state.R[a], R_rel @ state.t[a] + scale * u
        err, depth = state.reprojection(obs)
        good = (err <= options.pnp_threshold_px) & (depth > 0)
        if good.sum() < options.essential_min_points:
            state.R[v] = state.t[v] = None
            continue
        state.inlier[obs[~good]] = False
        state.outliers_removed += int((~good).sum())
        return v
    return None


def _stop(callback, progress: dict) -> bool:
    if callback is None:
        return False
    try:
        return bool(callback(progress))
    except StopIteration:
        return True


def calibrated_reconstruction(tracks: list[tuple[np.ndarray, np.ndarray]], Ks: list[np.ndarray],
                              options: CalibratedOptions | None = None, callback=None) -> CalibratedReconstruction:
    """Cameras and points from tracks (views, pixels) and each view's K (see the module docstring).

    ``callback(progress)`` gets {"stage": "registration", "done": k, "total": n} (and
    "bundle_adjustment") and may return True to stop (status "cancelled", the views so far kept)."""
    options = options or CalibratedOptions()
    cv2.setRNGSeed(options.seed)
    state = _State(tracks, Ks)
    timing = {"initial_pair": 0.0, "registration": 0.0, "triangulation": 0.0, "bundle_adjustment": 0.0}
    stats: dict = {"views": state.n_views, "tracks": len(tracks), "time_s": timing, "ba_nfev": [],
                   "registered_by": {}}
    status = "ok"

    def result() -> CalibratedReconstruction:
        registered = state.registered
        reasons = [None if registered[v] else reasons_by_view.get(v, "not reached") for v in range(state.n_views)]
        valid = np.isfinite(state.points[:, 0])
        inliers = [state.inlier[state.start[k]:state.start[k + 1]] & registered[state.obs_view[state.start[k]:state.start[k + 1]]]
                   & valid[k] for k in range(len(tracks))]
        obs = np.flatnonzero(np.concatenate(inliers)) if inliers else np.zeros(0, np.int64)
        err, _ = state.reprojection(obs)
        stats.update({"registered": int(registered.sum()), "points": int(valid.sum()),
                      "observations": int(len(obs)), "outliers_removed": state.outliers_removed,
                      "rms_reprojection_px": float(np.sqrt(np.mean(err ** 2))) if len(obs) else math.nan,
                      "ba_iterations": int(sum(stats["ba_nfev"]))})
        return CalibratedReconstruction([None if R is None else R.copy() for R in state.R],
                                        [None if t is None else t.copy() for t in state.t],
                                        reasons, state.points.copy(), inliers, stats, status)

    reasons_by_view: dict[int, str] = {}
    start = time.perf_counter()
    pair = _initial_pair(state, options)
    timing["initial_pair"] += time.perf_counter() - start
    if pair is None:
        status = "failed"
        for v in range(state.n_views):
            reasons_by_view[v] = f"no pair of views shares {options.min_pair_tracks} tracks with a valid essential matrix"
        return result()
    i, j, R, t = pair
    stats["initial_pair"] = [i, j]
    stats["registered_by"].update({i: "initial pair", j: "initial pair"})
    state.R[i], state.t[i] = np.eye(3), np.zeros(3)
    state.R[j], state.t[j] = R, t
    start = time.perf_counter()
    _triangulate_new(state, options)
    timing["triangulation"] += time.perf_counter() - start
    start = time.perf_counter()
    stats["ba_nfev"].append(_bundle_adjust(state, i, options.ba_max_nfev, options))
    _remove_outliers(state, options)
    timing["bundle_adjustment"] += time.perf_counter() - start

    last_tried: dict[int, int] = {}
    while not state.registered.all():
        if _stop(callback, {"stage": "registration", "done": int(state.registered.sum()), "total": state.n_views}):
            status = "cancelled"
            return result()
        start = time.perf_counter()
        v, failed = _register_next(state, options, last_tried)
        reasons_by_view.update(failed)
        method = "pnp"
        if v is None:
            v, method = _register_by_essential(state, options), "essential"
        if v is not None:
            stats["registered_by"][v] = method
        timing["registration"] += time.perf_counter() - start
        if v is None:
            break
        reasons_by_view.pop(v, None)
        start = time.perf_counter()
        _triangulate_new(state, options)
        timing["triangulation"] += time.perf_counter() - start
        start = time.perf_counter()
        stats["ba_nfev"].append(_bundle_adjust(state, i, options.ba_max_nfev, options))
        _remove_outliers(state, options)
        timing["bundle_adjustment"] += time.perf_counter() - start

    for _ in range(options.final_rounds):
        if _stop(callback, {"stage": "bundle_adjustment", "done": _, "total": options.final_rounds}):
            status = "cancelled"
            return result()
        start = time.perf_counter()
        stats["ba_nfev"].append(_bundle_adjust(state, i, options.final_ba_max_nfev, options))
        removed = _remove_outliers(state, options)
        timing["bundle_adjustment"] += time.perf_counter() - start
        start = time.perf_counter()
        made = _triangulate_new(state, options)  # tracks whose outliers are gone may now fit
        timing["triangulation"] += time.perf_counter() - start
        if removed == 0 and made == 0:
            break
    return result()
