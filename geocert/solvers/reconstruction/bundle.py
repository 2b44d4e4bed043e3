"""Bundle adjustments: projective, and the one metric adjustment (``adjust``), whose normal
equations are solved by Levenberg-Marquardt with the points eliminated (schur.py) or by
scipy.optimize.least_squares.

Projective: each camera's 12 entries and each point's 4 homogeneous coordinates are free (the
gauge, a 4x4 projective change of frame and each row's scale, is left to the damping).
Metric: one K shared by every view (``MODELS``: which of its entries, and which per-view
intrinsics, are free) or each view's own K (held, or its focal terms scaled by one shared factor),
a rotation vector and a translation per view, each point's 3 coordinates; ``Free`` says what
moves, ``Schur`` or ``LeastSquares`` how each step is solved and when it stops. Residuals are in
pixels either way; ``f_scale`` (pixels) makes the Schur strategy's loss Huber's, None plain least
squares; ``stop`` (schur.StopRule, Ceres's tests by default) says when an adjustment ends before
``max_iterations``. ``metric`` is ``adjust`` of one shared K by the Schur strategy, as a tuple."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.spatial.transform import Rotation

from geocert.solvers.reconstruction import schur


def projective(cameras: np.ndarray, points: np.ndarray, view: np.ndarray, track: np.ndarray, pixels: np.ndarray,
               scales: np.ndarray, f_scale: float | None = None, max_iterations: int = 30, should_stop=None,
               stop: schur.StopRule = schur.CERES):
    """Refine cameras (n, 3, 4) and homogeneous points (p, 4) over observations (view, track,
    pixel): pixels are normalised image coordinates and ``scales`` each view's normalisation
    scale, so residual / scale is in pixels. Returns cameras, points, pixel residuals (M, 2)."""
    n = len(cameras)
    A = (cameras / np.linalg.norm(cameras.reshape(n, -1), axis=1)[:, None, None]).reshape(n, 12)
    B = points / np.linalg.norm(points, axis=1)[:, None]
    inv_scale = (1.0 / scales[view])[:, None]

    def residual(Am, S, Bm):
        proj = (Am.reshape(-1, 3, 4) @ Bm[:, :, None])[:, :, 0]
        return (proj[:, :2] / proj[:, 2:3] - pixels) * inv_scale

    def jacobian(Am, S, Bm):  # analytic: r = (P0 X / P2 X, P1 X / P2 X) - x, over the view's scale
        proj = (Am.reshape(-1, 3, 4) @ Bm[:, :, None])[:, :, 0]
        w = proj[:, 2:3]
        u, v = proj[:, 0:1] / w, proj[:, 1:2] / w
        ja = np.zeros((len(Am), 2, 12))
        ja[:, 0, 0:4] = Bm / w
        ja[:, 0, 8:12] = -u * Bm / w
        ja[:, 1, 4:8] = Bm / w
        ja[:, 1, 8:12] = -v * Bm / w
        rows = Am.reshape(-1, 3, 4)
        jb = np.stack([(rows[:, 0] - u * rows[:, 2]) / w, (rows[:, 1] - v * rows[:, 2]) / w], axis=1)
        scale = inv_scale[:, :, None]
        return ja * scale, np.zeros((len(Am), 2, 0)), jb * scale

    A, _, B, r, _ = schur.solve(residual, A, np.zeros(0), B, view, track, f_scale, max_iterations, stop=stop,
                                jacobian=jacobian, should_stop=should_stop)
    P = A.reshape(n, 3, 4)
    P = P / np.linalg.norm(A, axis=1)[:, None, None]
    X = B / np.linalg.norm(B, axis=1)[:, None]
    return P, X, r


# The shared K's free entries: "simple" the focal length (square pixels, no skew, the principal
# point held where K has it: the image centre, as COLMAP's default of not refining it), "full" all
# five, "fixed" none, "varying" one focal length per view (principal point held, square pixels),
# "principal" the focal length and the principal point (square pixels, no skew), "radial" the focal
# length and one radial distortion term k1 about the principal point held where K has it (COLMAP's
# SIMPLE_RADIAL: a point at normalised image coordinates n is seen at K's pixel of n (1 + k1 |n|^2)),
# "fixed_radial" K as given and that radial term k1 about its principal point (K known),
# "principal_per_view" one focal length and a principal point per view (square pixels, no skew),
# "focal_groups" a principal point per view and a focal length per group of views (``groups``:
# each view's group; one group is "principal_per_view", a group each a K per view).
MODELS = ("simple", "full", "fixed", "varying", "principal", "radial", "principal_per_view", "focal_groups",
          "fixed_radial")
RADIAL_MODELS = ("radial", "fixed_radial")  # the models with the radial term k1, the last of their S


# One metric bundle adjustment: ``adjust``. What it moves is a ``Free``; how each step's normal
# equations are solved is the ``normal_equations`` strategy: ``Schur`` (schur.solve: the points
# eliminated, the reduced camera system solved exactly, Levenberg-Marquardt with Huber's loss) or
# ``LeastSquares`` (scipy.optimize.least_squares' trust region with LSMR on the sparse Jacobian).
# The cameras' projection comes in three forms, each with its own arithmetic order, since the
# results they have given (and the tests' ambiguous rigs built on them) depend on it to the last
# bit: one shared K (MODELS), each view's own K under the Schur strategy (the focal terms
# optionally scaled by one shared factor), and each view's own K under least squares (each free
# rotation exp(w) R0 about its start, a held camera out of the parameters).


@dataclass(frozen=True)
class Free:
    """What a metric bundle adjustment moves; what it does not move stays as given.

    ``intrinsics``: one of MODELS when K is one shared (3, 3) matrix; with one K per camera (n, 3,
    3): "given" (each K held) or "focal_scale" (every K's focal terms times one shared factor,
    returned as ``Adjusted.scale``; Schur only). ``held`` (each view's own K only): per camera,
    True where it is held (Schur: its Jacobian columns zero, so its step is zero; least squares:
    out of the parameters). ``focals``, ``centres``, ``groups`` and ``k1``: the per-view models' starting
    values (see MODELS)."""
    intrinsics: str = "simple"
    held: np.ndarray | None = None
    focals: np.ndarray | None = None
    centres: np.ndarray | None = None
    groups: np.ndarray | None = None
    k1: float = 0.0


@dataclass(frozen=True)
class Schur:
    """Levenberg-Marquardt on the reduced camera system (schur.solve): at most ``max_iterations``
    steps, ended sooner by ``stop`` or ``should_stop()``; Huber's loss at ``f_scale`` pixels (None:
    plain least squares). Every camera is a rotation vector and a translation."""
    max_iterations: int = 30
    stop: schur.StopRule = schur.CERES
    f_scale: float | None = None
    should_stop: Callable[[], bool] | None = None


@dataclass(frozen=True)
class LeastSquares:
    """scipy.optimize.least_squares (trust region reflective, LSMR, ``x_scale="jac"``) with the
    robust ``loss`` at ``f_scale`` pixels, at most ``max_nfev`` evaluations, ``ftol``."""
    max_nfev: int
    loss: str = "soft_l1"
    f_scale: float = 1.0
    ftol: float = 1e-8


@dataclass
class Adjusted:
    """An adjustment's result: K (the shared one, or one per camera), rotations (n, 3, 3),
    translations (n, 3), points (p, 3), the residuals (M, 2; None under least squares), k1, the
    focal scale ("focal_scale"; 1.0 otherwise) and the iterations (Schur) or evaluations (least
    squares) used."""
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    X: np.ndarray
    residuals: np.ndarray | None
    k1: float
    scale: float
    iterations: int


def adjust(K: np.ndarray, rotations: np.ndarray, translations: np.ndarray, points: np.ndarray, view: np.ndarray,
           track: np.ndarray, pixels: np.ndarray, free: Free = Free(),
           normal_equations: Schur | LeastSquares = Schur()) -> Adjusted:
    """Refine the cameras (rotations (n, 3, 3), translations (n, 3)), the points (p, 3) and what
    ``free`` frees of K against the pixel observations (view, track, pixels (M, 2)), by the
    ``normal_equations`` strategy. Every point must be observed."""
    if isinstance(normal_equations, LeastSquares):
        if np.ndim(K) != 3 or free.intrinsics != "given":
            raise ValueError("least squares adjusts the cameras and points under each view's own K")
        return _least_squares(K, rotations, translations, points, view, track, pixels, free.held, normal_equations)
    if np.ndim(K) == 3:
        problem = _own_K(K, rotations, translations, view, pixels, free)
    elif free.held is not None:
        raise ValueError("held cameras are for each view's own K")
    else:
        problem = _shared_K(K, rotations, translations, view, pixels, free)
    residual, jacobian, A, start, finish = problem
    A, S, B, r, iterations = schur.solve(residual, A, start, points.copy(), view, track, normal_equations.f_scale,
                                         normal_equations.max_iterations, stop=normal_equations.stop,
                                         jacobian=jacobian, should_stop=normal_equations.should_stop)
    K_out, k1, scale = finish(A, S)
    return Adjusted(K_out, Rotation.from_rotvec(A[:, :3]).as_matrix(), A[:, 3:6], B, r, k1, scale, int(iterations))


class _ByCamera:
    """The observations' products with their camera's matrix (a rotation, its left Jacobian): one
    matrix product per camera over its observations' rows, gathered in camera order, rather than
    numpy's stacked product of one small matrix per observation (several times the CPU: a BLAS
    call per observation). Each row's product is the same sum either way."""

    def __init__(self, view: np.ndarray):
        _, self.rows, inverse = np.unique(view, return_index=True, return_inverse=True)
        self.inverse = inverse
        self.order = np.argsort(inverse, kind="stable")  # the observations, camera by camera
        self.position = np.empty_like(self.order)  # where each observation sits in that order
        self.position[self.order] = np.arange(len(self.order))
        self.bounds = np.searchsorted(inverse[self.order], np.arange(len(self.rows) + 1)).tolist()
        self._last = None  # the last ``frame``'s poses and points (copies) and its answer

    def frame(self, Am: np.ndarray, Bm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``rotations`` and ``camera_frame``: the last call's arrays again when Am's poses
        (Am[:, :6]) and Bm are equal to its (schur.solve asks for the Jacobian where the step it
        took was evaluated, so each iteration's camera frame is computed once, not twice)."""
        last = self._last
        if (last is not None and last[0].shape == Am[:, :6].shape and last[1].shape == Bm.shape
                and np.array_equal(last[0], Am[:, :6]) and np.array_equal(last[1], Bm)):
            return last[2], last[3]
        R = self.rotations(Am)
        cam = self.camera_frame(R, Am, Bm)
        self._last = (Am[:, :6].copy(), Bm.copy(), R, cam)
        return R, cam

    def rotations(self, Am: np.ndarray) -> np.ndarray:
        """Each camera's rotation (n, 3, 3), from its first observation's row of Am = A[view]."""
        return Rotation.from_rotvec(Am[self.rows, :3]).as_matrix()

    def times(self, x: np.ndarray, mats: np.ndarray) -> np.ndarray:
        """x[m] @ mats[camera of m] for x (M, r, k) and mats (n, k, l): (M, r, l)."""
        M, r, k = x.shape
        gathered = schur._rows(x, self.order).reshape(-1, k)
        out = np.empty((M * r, mats.shape[-1]))
        for i, (b, e) in enumerate(zip(self.bounds[:-1], self.bounds[1:])):
            np.matmul(gathered[b * r:e * r], mats[i], out=out[b * r:e * r])
        return schur._rows(out.reshape(M, r, mats.shape[-1]), self.position)  # back in the observations' order

    def camera_frame(self, R: np.ndarray, Am: np.ndarray, Bm: np.ndarray) -> np.ndarray:
        """R B + t per observation (M, 3), R the cameras' rotations (``rotations``); by einsum over
        the rotations spread to the observations (its sums are not a matrix product's bit for bit,
        and a vector per observation is einsum's fast case)."""
        return np.einsum("mij,mj->mi", schur._rows(R, self.inverse), Bm) + Am[:, 3:6]

    def rotation_columns(self, Am: np.ndarray, cam: np.ndarray, du_dcam: np.ndarray) -> np.ndarray:
        """d pixel / d w (M, 2, 3) for cam = exp(w) B + t, du_dcam = d pixel / d cam."""
        return self.times(_crossed(cam - Am[:, 3:6], du_dcam), _left_jacobian(Am[self.rows, :3]))


def _shared_K(K, rotations, translations, view, pixels, free: Free):
    """The Schur problem of one shared K under ``free.intrinsics`` (MODELS)."""
    model, focals, centres, groups, k1 = free.intrinsics, free.focals, free.centres, free.groups, free.k1
    A = np.hstack([Rotation.from_matrix(rotations).as_rotvec(), translations])
    given = np.array([K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]])
    if model == "varying":
        A = np.hstack([A, (np.full(len(A), K[0, 0]) if focals is None else focals)[:, None]])
    if model in ("principal_per_view", "focal_groups"):
        A = np.hstack([A, np.tile(given[3:5], (len(A), 1)) if centres is None else np.asarray(centres, dtype=float)])
    if model == "focal_groups":
        groups = np.zeros(len(A), dtype=int) if groups is None else np.asarray(groups, dtype=int)
        seen_focals = np.full(len(A), given[0]) if focals is None else np.asarray(focals, dtype=float)
        group_focals = np.array([seen_focals[groups == g].mean() for g in range(int(groups.max()) + 1)])
        obs_group = groups[view]  # each observation's focal length: S[obs_group]

    def entries(S):
        if model in ("fixed", "fixed_radial"):
            return given
        if model == "simple":
            return np.array([S[0], S[0], 0.0, given[3], given[4]])
        if model == "principal":
            return np.array([S[0], S[0], 0.0, S[1], S[2]])
        if model in ("principal_per_view", "focal_groups"):  # the principal points are each view's (Am[:, 6:8])
            return np.array([S[0], S[0], 0.0, 0.0, 0.0])
        if model == "radial":
            return np.array([S[0], S[0], 0.0, given[3], given[4]])
        if model == "varying":
            return given
        return S

    cameras = _ByCamera(view)

    def residual(Am, S, Bm):
        k = entries(S)
        _, cam = cameras.frame(Am, Bm)
        u = cam[:, 0] / cam[:, 2]
        v = cam[:, 1] / cam[:, 2]
        if model == "varying":
            return np.stack([Am[:, 6] * u + k[3] - pixels[:, 0], Am[:, 6] * v + k[4] - pixels[:, 1]], axis=1)
        if model == "principal_per_view":
            return np.stack([k[0] * u + Am[:, 6] - pixels[:, 0], k[0] * v + Am[:, 7] - pixels[:, 1]], axis=1)
        if model == "focal_groups":
            f = S[obs_group]
            return np.stack([f * u + Am[:, 6] - pixels[:, 0], f * v + Am[:, 7] - pixels[:, 1]], axis=1)
        if model in RADIAL_MODELS:
            scale = 1.0 + S[-1] * (u * u + v * v)
            u, v = u * scale, v * scale
        return np.stack([k[0] * u + k[2] * v + k[3] - pixels[:, 0], k[1] * v + k[4] - pixels[:, 1]], axis=1)

    def jacobian(Am, S, Bm):
        """Analytic (ja, js, jb) of ``residual``: pixels = M n' + c with n = cam[:2] / cam[2],
        n' = n (1 + k1 |n|^2) (RADIAL_MODELS) or n, M = [[fx, skew], [0, fy]] (each view's f I for
        "varying"), cam = exp(w) B + t (a rotation vector's derivative by SO(3)'s left Jacobian)."""
        k = entries(S)
        m = len(Am)
        R, cam = cameras.frame(Am, Bm)
        z = cam[:, 2]
        n = cam[:, :2] / z[:, None]
        dn = np.zeros((m, 2, 3))  # d n / d cam
        dn[:, 0, 0] = dn[:, 1, 1] = 1.0 / z
        dn[:, :, 2] = -n / z[:, None]
        seen, dseen = n, dn  # n' and d n' / d cam
        if model in RADIAL_MODELS:
            r2 = np.sum(n * n, axis=1)
            scale = 1.0 + S[-1] * r2
            seen = n * scale[:, None]
            stretch = scale[:, None, None] * np.eye(2) + 2 * S[-1] * n[:, :, None] * n[:, None, :]
            dseen = stretch @ dn
        M = np.zeros((m, 2, 2))
        if model == "varying":
            M[:, 0, 0] = M[:, 1, 1] = Am[:, 6]
        elif model == "focal_groups":
            M[:, 0, 0] = M[:, 1, 1] = S[obs_group]
        else:
            M[:, 0, 0], M[:, 0, 1], M[:, 1, 1] = k[0], k[2], k[1]
        if model in ("varying", "focal_groups"):
            du_dcam = M @ dseen
        else:  # one 2x2 for every observation: one matrix product over them all, not one each
            du_dcam = _left_times(np.array([[k[0], k[2]], [0.0, k[1]]]), dseen)
        d_w = cameras.rotation_columns(Am, cam, du_dcam)
        ja = np.concatenate([d_w, du_dcam], axis=2)
        ones, zeros = np.ones(m), np.zeros(m)
        if model == "varying":
            ja = np.concatenate([ja, seen[:, :, None]], axis=2)
        if model in ("principal_per_view", "focal_groups"):
            ja = np.concatenate([ja, np.broadcast_to(np.eye(2), (m, 2, 2))], axis=2)
        if model in ("simple", "principal", "radial", "principal_per_view"):  # d / d f: both focal terms move with f
            columns = [seen]
            if model == "principal":
                columns += [np.stack([ones, zeros], axis=1), np.stack([zeros, ones], axis=1)]
            if model == "radial":
                columns.append(np.einsum("mij,mj->mi", M, n * np.sum(n * n, axis=1)[:, None]))
            js = np.stack(columns, axis=2)
        elif model == "focal_groups":  # d / d (the observation's group's f)
            js = np.zeros((m, 2, len(S)))
            js[np.arange(m), :, obs_group] = seen
        elif model == "fixed_radial":  # d / d k1 alone
            js = np.einsum("mij,mj->mi", M, n * np.sum(n * n, axis=1)[:, None])[:, :, None]
        elif model == "full":  # fx, fy, skew, cx, cy
            u, v = seen[:, 0], seen[:, 1]
            js = np.stack([np.stack([u, zeros, v, ones, zeros], axis=1),
                           np.stack([zeros, v, zeros, zeros, ones], axis=1)], axis=1)
        else:
            js = np.zeros((m, 2, 0))
        return ja, js, cameras.times(du_dcam, R)

    start = {"fixed": np.zeros(0), "varying": np.zeros(0), "simple": np.array([np.sqrt(abs(given[0] * given[1]))]),
             "full": given.copy(), "principal": np.array([np.sqrt(abs(given[0] * given[1])), given[3], given[4]]),
             "radial": np.array([np.sqrt(abs(given[0] * given[1])), k1]), "fixed_radial": np.array([k1]),
             "principal_per_view": np.array([np.sqrt(abs(given[0] * given[1]))]),
             "focal_groups": group_focals if model == "focal_groups" else None}[model]

    def finish(A, S):
        k = entries(S)
        K = np.array([[k[0], k[2], k[3]], [0.0, k[1], k[4]], [0.0, 0.0, 1.0]])
        if model == "varying":  # one K per view
            K = np.array([[[f, 0.0, k[3]], [0.0, f, k[4]], [0.0, 0.0, 1.0]] for f in A[:, 6]])
        if model == "principal_per_view":
            K = np.array([[[k[0], 0.0, u], [0.0, k[0], v], [0.0, 0.0, 1.0]] for u, v in A[:, 6:8]])
        if model == "focal_groups":
            K = np.array([[[f, 0.0, u], [0.0, f, v], [0.0, 0.0, 1.0]] for f, (u, v) in zip(S[groups], A[:, 6:8])])
        return K, (float(S[-1]) if model in RADIAL_MODELS else k1), 1.0

    return residual, jacobian, A, start, finish


def _own_K(K, rotations, translations, view, pixels, free: Free):
    """The Schur problem of each camera's own K (n, 3, 3), held ("given") or with its focal terms
    scaled by one shared factor ("focal_scale": pixels = c + s F xc[:2] / xc[2]); a camera
    ``free.held`` keeps its place (its Jacobian columns zero)."""
    if free.intrinsics not in ("given", "focal_scale"):
        raise ValueError(f"each view's own K is 'given' or 'focal_scale', not {free.intrinsics!r}")
    focal = free.intrinsics == "focal_scale"
    Ks = np.asarray(K)[view]
    F, centre = Ks[:, :2, :2], Ks[:, :2, 2]
    held = None if free.held is None else np.asarray(free.held)[view]  # observations by held cameras
    cameras = _ByCamera(view)
    F_own = np.asarray(K)[view[cameras.rows], :2, :2]  # F by camera, in ``cameras``' order

    def project(Am, S, Bm):
        R, xc = cameras.frame(Am, Bm)
        z = np.where(np.abs(xc[:, 2]) < 1e-12, 1e-12, xc[:, 2])
        seen = np.einsum("nij,nj->ni", F, xc[:, :2] / z[:, None])  # the pixel's offset at scale 1
        return R, xc, z, seen, (S[0] if focal else 1.0)

    def residual(Am, S, Bm):
        _, _, _, seen, scale = project(Am, S, Bm)
        return centre + scale * seen - pixels

    def jacobian(Am, S, Bm):
        R, xc, z, seen, scale = project(Am, S, Bm)
        dn = np.zeros((len(Am), 2, 3))  # d (xc[:2] / z) / d xc
        dn[:, 0, 0] = dn[:, 1, 1] = 1.0 / z
        dn[:, :, 2] = -xc[:, :2] / (z ** 2)[:, None]
        # (scale F_v) dn_m for each observation m of camera v: by camera, as (dn^T (scale F_v)^T)^T.
        du_dxc = cameras.times(dn.transpose(0, 2, 1), (scale * F_own).transpose(0, 2, 1)).transpose(0, 2, 1)
        d_w = cameras.rotation_columns(Am, xc, du_dxc)
        d_s = seen[:, :, None] if focal else np.zeros((len(Am), 2, 0))
        d_camera = np.concatenate([d_w, du_dxc], axis=2)
        if held is not None:
            d_camera[held] = 0.0
        return d_camera, d_s, cameras.times(du_dxc, R)

    A = np.array([np.r_[Rotation.from_matrix(R).as_rotvec(), t] for R, t in zip(rotations, translations)])

    def finish(A, S):
        return K, free.k1, (float(S[0]) if focal else 1.0)

    return residual, jacobian, A, np.ones(1) if focal else np.zeros(0), finish


def _least_squares(K, rotations, translations, points, view, track, pixels, held, solver: LeastSquares) -> Adjusted:
    """Each camera's own K held; each free camera's rotation exp(w) R0 with R0 its rotation at the
    start and w a rotation vector (starting at 0); the cameras ``held`` out of the parameters."""
    n = len(rotations)
    held = np.zeros(n, dtype=bool) if held is None else np.asarray(held, dtype=bool)
    free_cams = np.flatnonzero(~held)
    cam_of = np.full(n, -1)
    cam_of[free_cams] = np.arange(len(free_cams))
    o_cam, o_pt = cam_of[view], track
    Ks = np.asarray(K)[view]
    n_free, n_cam = len(free_cams), 6 * len(free_cams)
    R0 = np.array([rotations[c] for c in free_cams]).reshape(-1, 3, 3)
    moving = o_cam >= 0
    m_idx = np.flatnonzero(moving)
    M = len(view)
    R_all, t_all = np.asarray(rotations, dtype=float).reshape(-1, 3, 3), np.asarray(translations, dtype=float).reshape(-1, 3)

    def cameras(x):
        """Per observation: rotation, translation (a held camera's where o_cam < 0), and w."""
        c = x[:n_cam].reshape(-1, 6)
        Rf = Rotation.from_rotvec(c[:, :3]).as_matrix().reshape(-1, 3, 3) @ R0 if n_free else R0
        R_obs = R_all[view]
        t_obs = t_all[view]
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
        return (h[:, :2] / z[:, None] - pixels).ravel()

    r = np.arange(M)
    rows = np.concatenate([np.repeat(2 * m_idx[:, None] + np.arange(2)[None, :], 6, axis=1).ravel(),
                           np.repeat(2 * r[:, None] + np.arange(2)[None, :], 3, axis=1).ravel()])
    cam_cols = (6 * o_cam[m_idx])[:, None] + np.arange(6)[None, :]
    pt_cols = (n_cam + 3 * o_pt)[:, None] + np.arange(3)[None, :]
    cols = np.concatenate([np.tile(cam_cols, (1, 2)).reshape(-1, 2, 6).ravel(),
                           np.tile(pt_cols, (1, 2)).reshape(-1, 2, 3).ravel()])

    def jacobian(x):
        R_obs, t_obs, c, X, xc, h, z = project(x)
        dh = np.zeros((M, 2, 3))  # d pixel / d h
        dh[:, 0, 0] = dh[:, 1, 1] = 1.0 / z
        dh[:, :, 2] = -h[:, :2] / (z ** 2)[:, None]
        du_dxc = dh @ Ks  # (n, 2, 3)
        d_pt = du_dxc @ R_obs
        m = m_idx
        d_w = -du_dxc[m] @ _skew(xc[m] - t_obs[m]) @ _left_jacobian(c[o_cam[m], :3])
        d_cam = np.concatenate([d_w, du_dxc[m]], axis=2)  # (k, 2, 6)
        vals = np.concatenate([d_cam.ravel(), d_pt.ravel()])
        return coo_matrix((vals, (rows, cols)), shape=(2 * M, len(x))).tocsr()

    x0 = np.concatenate([np.concatenate([np.r_[np.zeros(3), translations[v]] for v in free_cams])
                         if n_free else np.zeros(0), np.asarray(points).ravel()])
    from scipy.optimize import least_squares  # here: the Schur path never imports scipy.optimize (about 0.15 s)

    result = least_squares(residuals, x0, jac=jacobian, loss=solver.loss, f_scale=solver.f_scale,
                           x_scale="jac", method="trf", tr_solver="lsmr", max_nfev=solver.max_nfev,
                           ftol=solver.ftol, xtol=1e-10, gtol=1e-10)
    _, _, c = cameras(result.x)
    R_out = [np.array(R, dtype=float, copy=True) for R in rotations]
    t_out = [np.array(t, dtype=float, copy=True) for t in translations]
    for k, v in enumerate(free_cams):
        R_out[v] = Rotation.from_rotvec(c[k, :3]).as_matrix() @ R0[k]
        t_out[v] = c[k, 3:].copy()
    return Adjusted(K, np.array(R_out).reshape(-1, 3, 3), np.array(t_out).reshape(-1, 3),
                    result.x[n_cam:].reshape(-1, 3), None, 0.0, 1.0, int(result.nfev))


def metric(K: np.ndarray, rotations: np.ndarray, translations: np.ndarray, points: np.ndarray, view: np.ndarray,
           track: np.ndarray, pixels: np.ndarray, f_scale: float | None = None, max_iterations: int = 30,
           model: str = "simple", focals: np.ndarray | None = None, should_stop=None, k1: float = 0.0,
           stop: schur.StopRule = schur.CERES, centres: np.ndarray | None = None,
           groups: np.ndarray | None = None):
    """``adjust`` of one shared K by the Schur strategy, as a tuple: refine one shared K
    (``model``: "simple" f with square pixels, no skew and cx, cy fixed; "full" fx, fy, skew, cx,
    cy; "fixed" K as given; "radial" f and the distortion term, from ``k1``; "fixed_radial" K as
    given and the distortion term), rotations (n, 3, 3), translations (n, 3) and points (p, 3)
    against pixel observations. Returns K, rotations, translations, points, residuals (M, 2), and
    k1 (``k1`` as given unless RADIAL_MODELS).
    "varying", "principal_per_view" and "focal_groups" return one K per view (n, 3, 3), from
    ``focals`` (n,) and ``centres`` (n, 2) (K's where not given; "focal_groups" starts each group
    from its views' mean focal length)."""
    out = adjust(K, rotations, translations, points, view, track, pixels,
                 Free(model, focals=focals, centres=centres, groups=groups, k1=k1),
                 Schur(max_iterations, stop, f_scale, should_stop))
    return out.K, out.R, out.t, out.X, out.residuals, out.k1


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices of rows of v (n, 3) -> (n, 3, 3)."""
    S = np.zeros((len(v), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return S


def _left_times(F: np.ndarray, x: np.ndarray) -> np.ndarray:
    """F @ x[m] for one matrix F (r, k) and x (M, k, l): (M, r, l), as (x^T F^T)^T, one product
    over every row (numpy's stacked product makes one BLAS call per observation)."""
    M, k, l = x.shape
    return (x.transpose(0, 2, 1).reshape(-1, k) @ F.T).reshape(M, l, F.shape[0]).transpose(0, 2, 1)


def _crossed(x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """-a @ [x]_x for rows x (M, 3) and a (M, r, 3): each row of a crossed with x, x × a_i
    (the skew matrix's product written out: no (M, 3, 3) matrices built and multiplied)."""
    x0, x1, x2 = x[:, 0, None], x[:, 1, None], x[:, 2, None]
    a0, a1, a2 = a[:, :, 0], a[:, :, 1], a[:, :, 2]
    out = np.empty(a.shape[:2] + (3,))  # each entry x_i a_j - x_j a_i, written in place (no stack)
    for column, (xi, aj, xj, ai) in enumerate(((x1, a2, x2, a1), (x2, a0, x0, a2), (x0, a1, x1, a0))):
        np.multiply(xi, aj, out=out[:, :, column])
        out[:, :, column] -= xj * ai
    return out


def _left_jacobian(w: np.ndarray) -> np.ndarray:
    """SO(3)'s left Jacobian J(w) (n, 3, 3): exp(w + e) = exp(J(w) e) exp(w) to first order."""
    theta = np.linalg.norm(w, axis=1)
    W = _skew(w)
    small = theta < 1e-8
    th = np.where(small, 1.0, theta)
    a = np.where(small, 0.5, (1 - np.cos(th)) / th ** 2)
    b = np.where(small, 1.0 / 6.0, (th - np.sin(th)) / th ** 3)
    return np.eye(3)[None] + a[:, None, None] * W + b[:, None, None] * (W @ W)


def undistort(pixels: np.ndarray, centre, focal: float, k1: float) -> np.ndarray:
    """The pixels (M, 2) a pinhole camera with this focal length and principal point ``centre``
    sees where the "radial" model's camera (the same K, distortion k1) saw ``pixels``: the
    normalised radius r_d = r (1 + k1 r^2) solved for r by Newton's method."""
    if k1 == 0.0 or len(pixels) == 0:
        return np.array(pixels, dtype=float, copy=True)
    centre = np.asarray(centre, dtype=float)
    n = (np.asarray(pixels, dtype=float) - centre) / focal
    return centre + n * _undistorted_ratio(n, k1)[:, None] * focal


def undistort_K(pixels: np.ndarray, K: np.ndarray, k1: float) -> np.ndarray:
    """The pixels (M, 2) the pinhole camera K sees where the "fixed_radial" model's camera (K,
    distortion k1 about K's principal point) saw ``pixels``: n_d = K^-1 pixel, the normalised
    radius r_d = r (1 + k1 r^2) solved for r by Newton's method, then K n. For K with square
    pixels and no skew, undistort's about K's principal point at K's focal length."""
    if k1 == 0.0 or len(pixels) == 0:
        return np.array(pixels, dtype=float, copy=True)
    K = np.asarray(K, dtype=float)
    M, centre = K[:2, :2], K[:2, 2]
    n = np.linalg.solve(M, (np.asarray(pixels, dtype=float) - centre).T).T
    return centre + (n * _undistorted_ratio(n, k1)[:, None]) @ M.T


def _undistorted_ratio(n: np.ndarray, k1: float) -> np.ndarray:
    """r / r_d for each normalised point n (M, 2) of radius r_d: r_d = r (1 + k1 r^2) solved for r
    by Newton's method from r = r_d (1 where r_d is 0)."""
    rd = np.linalg.norm(n, axis=1)
    r = rd.copy()
    for _ in range(20):
        step = r - (r * (1 + k1 * r * r) - rd) / (1 + 3 * k1 * r * r)
        if np.array_equal(step, r):  # a fixed point: the remaining iterations would return it as it is
            break
        r = step
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(rd > 0, r / rd, 1.0)
