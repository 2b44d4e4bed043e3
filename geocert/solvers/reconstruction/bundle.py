"""Bundle adjustments, both by Levenberg-Marquardt with the points eliminated (schur.py).

Projective: each camera's 12 entries and each point's 4 homogeneous coordinates are free (the
gauge, a 4x4 projective change of frame and each row's scale, is left to the damping).
Metric: one K shared by every view (fx, fy, skew, cx, cy), a rotation vector and a translation
per view, each point's 3 coordinates. Residuals are in pixels either way; ``f_scale`` (pixels)
makes the loss Huber's, None plain least squares; ``stop`` (schur.StopRule, Ceres's tests by
default) says when an adjustment ends before ``max_iterations``."""

from __future__ import annotations

import numpy as np
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


def metric(K: np.ndarray, rotations: np.ndarray, translations: np.ndarray, points: np.ndarray, view: np.ndarray,
           track: np.ndarray, pixels: np.ndarray, f_scale: float | None = None, max_iterations: int = 30,
           model: str = "simple", focals: np.ndarray | None = None, should_stop=None, k1: float = 0.0,
           stop: schur.StopRule = schur.CERES, centres: np.ndarray | None = None,
           groups: np.ndarray | None = None):
    """Refine one shared K (``model``: "simple" f with square pixels, no skew and cx, cy fixed; "full"
    fx, fy, skew, cx, cy; "fixed" K as given; "radial" f and the distortion term, from ``k1``;
    "fixed_radial" K as given and the distortion term),
    rotations (n, 3, 3), translations (n, 3) and points (p, 3) against pixel observations. Returns
    K, rotations, translations, points, residuals (M, 2), and k1 (``k1`` as given unless
    RADIAL_MODELS).
    "varying", "principal_per_view" and "focal_groups" return one K per view (n, 3, 3), from
    ``focals`` (n,) and ``centres`` (n, 2) (K's where not given; "focal_groups" starts each group
    from its views' mean focal length)."""
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

    # Am is A[view]: each view's rotation (and its left Jacobian) is computed once, from its first
    # observation's row, and spread to its observations.
    _, rows, inverse = np.unique(view, return_index=True, return_inverse=True)

    def rotations(Am):
        return Rotation.from_rotvec(Am[rows, :3]).as_matrix()[inverse]

    def residual(Am, S, Bm):
        k = entries(S)
        cam = np.einsum("mij,mj->mi", rotations(Am), Bm) + Am[:, 3:6]
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
        from geocert.solvers.reconstruction.calibrated import _crossed, _left_jacobian

        k = entries(S)
        m = len(Am)
        R = rotations(Am)
        cam = np.einsum("mij,mj->mi", R, Bm) + Am[:, 3:6]
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
        du_dcam = M @ dseen
        d_w = _crossed(cam - Am[:, 3:6], du_dcam) @ _left_jacobian(Am[rows, :3])[inverse]
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
        return ja, js, du_dcam @ R

    start = {"fixed": np.zeros(0), "varying": np.zeros(0), "simple": np.array([np.sqrt(abs(given[0] * given[1]))]),
             "full": given.copy(), "principal": np.array([np.sqrt(abs(given[0] * given[1])), given[3], given[4]]),
             "radial": np.array([np.sqrt(abs(given[0] * given[1])), k1]), "fixed_radial": np.array([k1]),
             "principal_per_view": np.array([np.sqrt(abs(given[0] * given[1]))]),
             "focal_groups": group_focals if model == "focal_groups" else None}[model]
    A, S, B, r, _ = schur.solve(residual, A, start, points.copy(), view, track, f_scale, max_iterations, stop=stop,
                                jacobian=jacobian, should_stop=should_stop)
    k = entries(S)
    K = np.array([[k[0], k[2], k[3]], [0.0, k[1], k[4]], [0.0, 0.0, 1.0]])
    if model == "varying":  # one K per view
        K = np.array([[[f, 0.0, k[3]], [0.0, f, k[4]], [0.0, 0.0, 1.0]] for f in A[:, 6]])
    if model == "principal_per_view":
        K = np.array([[[k[0], 0.0, u], [0.0, k[0], v], [0.0, 0.0, 1.0]] for u, v in A[:, 6:8]])
    if model == "focal_groups":
        K = np.array([[[f, 0.0, u], [0.0, f, v], [0.0, 0.0, 1.0]] for f, (u, v) in zip(S[groups], A[:, 6:8])])
    return (K, Rotation.from_rotvec(A[:, :3]).as_matrix(), A[:, 3:6], B, r,
            float(S[-1]) if model in RADIAL_MODELS else k1)


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
