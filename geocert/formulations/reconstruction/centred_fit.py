"""The returned reconstruction re-adjusted in the camera model of an incremental registration's
cameras (numpy only; read by calibration_tie, so by the verifier).

The incremental registration (COLMAP's way) places its cameras as P = K [R | t] with one focal
length, square pixels, no skew and the principal point at each image's centre, and those cameras
are the projective reconstruction the certified upgrade starts from: the calibration certificate
proves the K they were built with. The returned cameras are adjusted afterwards in a freer model
(the principal point estimated, aspect and skew free, a focal length per view). When the tracks'
principal point is off the image's centre, the certificate's reconstruction cannot fit them as well
as the returned cameras, by what holding the principal point at the centre costs: genuinely, and
by more than the noise (36 px off on the synthetic scene: 2.36 times the returned cameras' cost).

fit() measures that cost from the result alone: the returned cameras and points, adjusted
(Levenberg-Marquardt, the points eliminated by their Schur complement) with every camera's K held
to one focal length (free), square pixels, no skew and its own image's centre, from the returned
poses. What it returns is the cost of an explicit reconstruction in that model, evaluated, not
predicted, so it is at least that model's least cost: the certificate's reconstruction (that
model's adjustment) fits no better than that least cost, and the figures fit() returns never ask
more of a genuine certificate than the model allows. The focal length stays free, and the centre is
the image's (its size is the data's), not a number the certificate states: a reconstruction
re-posed with another focal length, or another principal point, gains nothing from it.
"""

from __future__ import annotations

import numpy as np

from geocert.core import strict

ITERATIONS = 30  # Levenberg-Marquardt steps at most (the synthetic scene's 60 px shift converges in 6)
CHUNK = 200_000  # observation pairs per block of the points' Schur complement (memory: CHUNK * 81 floats at most)
# The verifier's cost bound: each solve is a dense system of 6 * views + 1 unknowns and sums a
# 7 x 7 block (9 x 9 with the principal point free) per pair of observations of one point (about 6 us a
# pair on a loaded core); beyond
# these sizes, or SOLVES solves, fit() declines (None) and the tie holds the certificate to the
# returned cameras, as it did before this fit (stricter). At 300 views and 5 million pairs one fit
# took 171 s (a document of 16,500 observations; up to 76 solves of about 30 s each allowed).
# Inside a verification, each solve is paid for from the document's work budget before it runs
# (strict.afford): a unit for each pair of observations of a point it sums and each observation
# (solve_units; the system's build, once an iteration, a unit an observation), so the fits a
# document asks for are paid by its size (a fit of 100,000 pairs took 3 to 13 s of CPU uncharged:
# review 30). A budget that cannot pay declines the fit (None), as the bounds above do: the tie
# then holds the certificate to the returned cameras (stricter), and no document is refused for it.
MAX_VIEWS = 100
MAX_PAIRS = 100_000
SOLVES = 45  # the off-centre synthetic runs' fits take 6
DAMPING_FLOOR = 1e-9  # relative to the largest diagonal entry of its block (solve)
STATIONARY, STATIONARY_DAMPING = 1e-6, 1e-6  # the stationarity test's (fit, below)


def _rq(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """M = K R, K upper triangular with a positive diagonal, R orthogonal."""
    J = np.eye(3)[::-1]
    Q, U = np.linalg.qr((J @ M).T)
    K, R = J @ U.T @ J, J @ Q.T
    D = np.diag(np.where(np.diag(K) < 0, -1.0, 1.0))
    return K @ D, D @ R


def _skew(v: np.ndarray) -> np.ndarray:
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def _rotation(w: np.ndarray) -> np.ndarray:
    """exp([w]x) for each row of w (Rodrigues)."""
    angle = np.linalg.norm(w, axis=-1)[..., None, None]
    S = _skew(w)
    with np.errstate(all="ignore"):
        a = np.where(angle > 1e-12, np.sin(angle) / angle, 1.0)
        b = np.where(angle > 1e-12, (1 - np.cos(angle)) / angle ** 2, 0.5)
    return np.eye(3) + a * S + b * S @ S


def fit(P: np.ndarray, centres: np.ndarray | None, X: np.ndarray, view: np.ndarray, point: np.ndarray,
        uv: np.ndarray) -> np.ndarray | None:
    """fit_with_intrinsics' images (M, 2), or None."""
    fitted = fit_with_intrinsics(P, centres, X, view, point, uv)
    return None if fitted is None else fitted[0]


def fit_with_intrinsics(P: np.ndarray, centres: np.ndarray | None, X: np.ndarray, view: np.ndarray,
                        point: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The images (M, 2) of the observations (camera ``view``, point ``point``, pixels ``uv``) in
    the returned cameras ``P`` (V, 3, 4) and points ``X`` (N, 4, homogeneous; w = 0 at infinity)
    re-adjusted with every K [[f, 0, cx], [0, f, cy], [0, 0, 1]], f one focal length and (cx, cy)
    the camera's ``centres`` row, or (``centres`` None) one principal point (cx, cy) for every
    camera, free like f (from the median of the returned cameras'); None when the cameras cannot
    be read so (not finite), the adjustment does not converge, or the problem is beyond MAX_VIEWS
    or MAX_PAIRS. With them, the intrinsics the cameras share in that fit: [f], or (``centres``
    None) [f, cx, cy]."""
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(X)) and np.all(np.isfinite(uv))) or len(uv) == 0:
        return None
    n_views, n_points = len(P), len(X)
    if n_views > MAX_VIEWS or int(np.sum(np.square(np.bincount(point, minlength=n_points)))) > MAX_PAIRS:
        return None
    Ks, Rs, ts = [], [], []
    for camera in P:
        K, R = _rq(camera[:, :3])
        scale = K[2, 2]
        if not (abs(scale) > 0 and np.all(np.isfinite(K))):
            return None
        K = K / scale
        t = np.linalg.solve(K, camera[:, 3]) / scale
        Ks.append(K), Rs.append(R), ts.append(t)
    Rs, ts, X = np.array(Rs), np.array(ts), np.array(X, dtype=float)
    used = np.bincount(point, minlength=n_points) > 0
    gauge = _unit_gauge(Rs, ts, X, used)
    if gauge is None:
        return None
    ts, X = gauge
    # the parameters every camera shares: f, then (centres None) the principal point
    shared = 1 if centres is not None else 3
    f = np.array([float(np.median([np.sqrt(abs(K[0, 0] * K[1, 1])) for K in Ks]))]
                 + ([] if centres is not None else list(np.median([K[:2, 2] for K in Ks], axis=0))))

    def images(Rs, ts, f, X):
        q = np.einsum("kij,kj->ki", Rs[view], X[point, :3]) + ts[view] * X[point, 3:4]
        with np.errstate(all="ignore"):
            return f[0] * q[:, :2] / q[:, 2:3] + (centres[view] if centres is not None else f[1:]), q

    def cost(Rs, ts, f, X):
        x, _ = images(Rs, ts, f, X)
        c = float(np.sum(np.square(x - uv)))
        return c if np.isfinite(c) else np.inf

    # the camera parameters of observation k: its view's rotation (3) and translation (3), then
    # the shared ones
    columns = np.concatenate([6 * view[:, None] + np.arange(6),
                              np.tile(6 * n_views + np.arange(shared), (len(view), 1))], axis=1)
    pairs = _pairs(point, n_points)
    n = 6 * n_views + shared
    solve_units = sum(len(k) for k, _ in pairs) + len(view)

    def system(Rs, ts, f, X):
        """The normal equations at (Rs, ts, f, X): the cameras' block H and gradient g, each
        point's block Vp and gradient gp, the cross terms W, with the observations' Jacobians."""
        x, q = images(Rs, ts, f, X)
        r = x - uv
        qz = q[:, 2]
        with np.errstate(all="ignore"):
            Jq = np.zeros((len(view), 2, 3))
            Jq[:, 0, 0] = Jq[:, 1, 1] = f[0] / qz
            Jq[:, 0, 2], Jq[:, 1, 2] = -f[0] * q[:, 0] / qz ** 2, -f[0] * q[:, 1] / qz ** 2
            RX = np.einsum("kij,kj->ki", Rs[view], X[point, :3])
            A = np.concatenate([Jq @ -_skew(RX), Jq * X[point, 3][:, None, None], (q[:, :2] / qz[:, None])[:, :, None]]
                               + ([] if shared == 1 else [np.broadcast_to(np.eye(2), (len(view), 2, 2))]),
                               axis=2)  # (M, 2, 6 + shared)
            B = Jq @ Rs[view]  # (M, 2, 3)
        flat = (columns[:, :, None] * n + columns[:, None, :]).ravel()
        H = np.bincount(flat, (A.transpose(0, 2, 1) @ A).ravel(), minlength=n * n).reshape(n, n)
        g = np.zeros(n)
        np.add.at(g, columns, (A.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0])
        Vp = np.zeros((n_points, 3, 3))
        np.add.at(Vp, point, B.transpose(0, 2, 1) @ B)
        gp = np.zeros((n_points, 3))
        np.add.at(gp, point, (B.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0])
        return H, g, Vp, gp, A.transpose(0, 2, 1) @ B  # W: (M, 6 + shared, 3)

    def solve(H, g, Vp, gp, W, lam):
        """The damped step (cameras, points): Marquardt's damping, lam times each diagonal entry,
        with a floor relative to its block's largest (an absolute floor froze whatever the
        gauge's units made small: a scene 1e15 times as large kept its points and translations)."""
        dH = np.diag(H)
        Hd = H + lam * np.diag(dH + DAMPING_FLOOR * max(float(np.max(dH)), 0.0))
        dV = np.einsum("pii->pi", Vp)
        Vd = Vp + lam * (dV + DAMPING_FLOOR * np.max(dV, axis=1, keepdims=True))[:, :, None] * np.eye(3)
        Vd[~used] = np.eye(3)
        Vinv = np.linalg.inv(Vd)
        S, rhs = Hd.ravel().copy(), g.copy()
        Y = W @ Vinv[point]  # W_k V_p^-1
        np.add.at(rhs, columns, -(Y @ gp[point][:, :, None])[:, :, 0])
        for k, l in pairs:
            S -= np.bincount((columns[k][:, :, None] * n + columns[l][:, None, :]).ravel(),
                             (Y[k] @ W[l].transpose(0, 2, 1)).ravel(), minlength=n * n)
        dc = np.linalg.solve(S.reshape(n, n), -rhs)
        back = np.zeros((n_points, 3))
        np.add.at(back, point, (W.transpose(0, 2, 1) @ dc[columns][:, :, None])[:, :, 0])
        return dc, -np.einsum("pij,pj->pi", Vinv, gp + back)

    current, lam, converged, solves = cost(Rs, ts, f, X), 1e-3, False, 0
    try:
        for _ in range(ITERATIONS):
            if not strict.afford(len(view)):
                return None
            normal = system(Rs, ts, f, X)
            while True:
                solves += 1
                if solves > SOLVES or not strict.afford(solve_units):
                    return None
                dc, dX = solve(*normal, lam)
                dcam = dc[:-shared].reshape(n_views, 6)
                trial = (_rotation(dcam[:, :3]) @ Rs, ts + dcam[:, 3:], f + dc[-shared:],
                         np.concatenate([X[:, :3] + np.where(used[:, None], dX, 0.0), X[:, 3:]], axis=1))
                new = cost(*trial)
                if new < current:
                    step = current - new
                    Rs, ts, f, X = trial
                    current, lam = new, max(lam / 3, 1e-9)
                    break
                lam *= 5
                if lam > 1e8:  # no step however short lowers the cost: a minimum, to rounding (tested below)
                    step = 0.0
                    break
            if step <= 1e-10 * current:
                converged = True
                break
        # Converged means stationary, whatever the steps did: the step the normal equations predict
        # from here (lightly damped) would lower the cost by a negligible fraction of it. A small last
        # decrease alone is not that (a step damped short, or a direction frozen, decreases little
        # far from any minimum), and a cost not at a minimum overstates the model's.
        if converged and np.isfinite(current):
            if not strict.afford(len(view) + solve_units):
                return None
            H, g, Vp, gp, W = system(Rs, ts, f, X)
            dc, dX = solve(H, g, Vp, gp, W, STATIONARY_DAMPING)
            predicted = -(float(g @ dc) + float(np.sum(gp[used] * dX[used])))
            converged = bool(np.isfinite(predicted) and predicted <= STATIONARY * current)
    except np.linalg.LinAlgError:
        return None
    x, _ = images(Rs, ts, f, X)
    # Not converged: its cost would overstate what the model costs, and widen the tie by that much;
    # the certificate is then held to the returned cameras (stricter), not to it.
    return (x, f) if converged and np.all(np.isfinite(x)) and np.all(np.isfinite(f)) else None


def _unit_gauge(Rs: np.ndarray, ts: np.ndarray, X: np.ndarray, used: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """The same reconstruction (the same images, K and rotations) in a similarity gauge of unit
    size: the translations and points moved so that the finite points' and the cameras' centres'
    median lies at the origin and their median distance from it is 1, each point at infinity of
    unit direction, each finite point's w 1. The result chooses its gauge; the fit's numbers then
    do not depend on it. None when that cannot be read (not finite)."""
    w = X[:, 3]
    finite = w != 0
    Y = X.copy()
    with np.errstate(all="ignore"):
        Y[finite, :3] = X[finite, :3] / w[finite, None]
        Y[finite, 3] = 1.0
        directions = np.linalg.norm(X[~finite, :3], axis=1)
        Y[~finite, :3] = X[~finite, :3] / directions[:, None]
        centres = -np.einsum("kji,kj->ki", Rs, ts)
    where = np.concatenate([Y[finite & used, :3], centres])
    if not (np.all(np.isfinite(Y[used])) and np.all(np.isfinite(where))):
        return None
    middle = np.median(where, axis=0)
    size = float(np.median(np.linalg.norm(where - middle, axis=1)))
    if not (np.isfinite(size) and size > 0):
        return None
    Y[finite, :3] = (Y[finite, :3] - middle) / size
    return (ts + Rs @ middle) / size, Y


def _pairs(point: np.ndarray, n_points: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every (k, l) pair of observations of one point, in blocks of at most CHUNK pairs."""
    order = np.argsort(point, kind="stable")
    counts = np.bincount(point, minlength=n_points)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    ks, ls = [], []
    for c in np.unique(counts[counts > 0]):
        rows = order[starts[counts == c][:, None] + np.arange(c)]  # (points seen c times, c)
        ks.append(np.repeat(rows, c, axis=1).ravel())
        ls.append(np.tile(rows, (1, c)).ravel())
    k, l = np.concatenate(ks), np.concatenate(ls)
    return [(k[i:i + CHUNK], l[i:i + CHUNK]) for i in range(0, len(k), CHUNK)]
