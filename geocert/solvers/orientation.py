"""Orienting a projective reconstruction: the signs of its cameras and points, and a plane at
infinity that leaves every point on one side.

A projective camera P and -P project every point to the same pixel, and so do X and -X; but
"in front of the camera" (positive depth, the third coordinate of P X, with the point's last
coordinate non-negative) depends on those signs. A certified triangulation searches exactly
the points in front of every camera, so a camera whose sign happens to be flipped turns an
ordinary track into "infeasible". This module fixes the signs from the reconstruction itself:

1. **Signs.** For every camera i seeing point j, the depth w_ij = P_i[2] . X_j. Choose signs
   s_i (cameras) and t_j (points) with s_i t_j w_ij > 0 for every observed pair. The pairs form a
   bipartite graph; signs are propagated along a spanning forest, then improved by majority
   votes (a reconstruction with noise or outliers may have no sign choice that makes every depth
   positive: the pairs left negative are reported). Each connected part keeps the overall sign
   that puts most of its points at a non-negative last coordinate.
2. **Plane at infinity.** Signs alone cannot make every point's last coordinate non-negative when
   the reconstruction's plane at infinity passes through the scene (a projective frame may put it
   anywhere). We then look for a plane v with v . X_j > 0 for every (signed) point and, when
   possible, every camera centre on one side of it as well (Hartley's quasi-affine
   reconstruction), as a linear program maximising the smallest normalised margin, and apply the
   projective change of frame H that sends v to the plane at infinity: points H X, cameras P H^-1.
   Depths are unchanged (P H^-1 H X = P X), and every point now has a positive last coordinate.
   A reconstruction already in such a frame (every point at a positive last coordinate, every
   camera centre on one side of the plane at infinity: any metric one) is left in its frame.

The returned cameras project every point to the same pixels as before; only signs (and, when
needed, the projective frame) change. Pure numerics: numpy and scipy's linear programming.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

_ZERO = 1e-12  # a depth this small, relative to |P[2]| |X|, has no sign: the point is on the principal plane


@dataclass
class Orientation:
    cameras: np.ndarray  # (m, 3, 4), each of Frobenius norm 1
    points: np.ndarray  # (n, 4) homogeneous, last coordinate >= 0 (> 0 when ``quasi_affine``)
    camera_signs: np.ndarray  # (m,) +1 / -1 applied to the input cameras
    point_signs: np.ndarray  # (n,) +1 / -1 applied to the input points
    transform: np.ndarray  # (4, 4): points = H (signed input points), cameras = (signed cameras) H^-1
    frame_changed: bool  # whether ``transform`` is more than a scale (the plane at infinity moved)
    quasi_affine: bool  # every point at a positive last coordinate
    centres_one_side: bool  # every camera centre on one side of the plane at infinity too
    negative_depths: list[tuple[int, int]] = field(default_factory=list)  # observed (camera, point) pairs left <= 0
    undetermined: list[tuple[int, int]] = field(default_factory=list)  # observed pairs with depth 0 (no sign)

    def depths(self) -> np.ndarray:
        """(m, n) third coordinates of P_i X_j in the returned frame."""
        return np.einsum("ik,jk->ij", self.cameras[:, 2, :], self.points)


def camera_centre(P: np.ndarray) -> np.ndarray:
    """The oriented centre of a 3x4 camera (the null vector with Hartley-Zisserman's signs:
    C = (det[p2 p3 p4], -det[p1 p3 p4], det[p1 p2 p4], -det[p1 p2 p3]))."""
    columns = [np.delete(P, k, axis=1) for k in range(4)]
    return np.array([(-1) ** k * np.linalg.det(c) for k, c in enumerate(columns)])


def _homogeneous(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] not in (3, 4):
        raise ValueError("points must be an (n, 3) or (n, 4) array")
    if points.shape[1] == 3:
        points = np.hstack([points, np.ones((len(points), 1))])
    # Each point divided by a power of two near its largest entry: the same projective point,
    # and no square of an entry near 1e308 overflows below.
    largest = np.max(np.abs(points), axis=1)
    exponents = np.frexp(np.where(largest > 0, largest, 1.0))[1]
    return np.ldexp(points, -exponents[:, None])


def _signs(W: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signs s (cameras), t (points) making s_i t_j W_ij > 0 on as many observed pairs as a
    spanning-forest propagation followed by majority votes finds; and each pair's component."""
    m, n = W.shape
    sign = np.where(seen, np.sign(W), 0.0)
    s, t = np.zeros(m), np.zeros(n)
    component = np.full(m + n, -1)
    label = 0
    for root in range(m + n):  # nodes 0..m-1 are cameras, m..m+n-1 points
        if component[root] >= 0:
            continue
        component[root] = label
        if root < m:
            s[root] = 1.0
        else:
            t[root - m] = 1.0
        queue = deque([root])
        while queue:
            node = queue.popleft()
            if node < m:
                for j in np.flatnonzero(sign[node]):
                    if component[m + j] < 0:
                        component[m + j], t[j] = label, s[node] * sign[node, j]
                        queue.append(m + j)
            else:
                j = node - m
                for i in np.flatnonzero(sign[:, j]):
                    if component[i] < 0:
                        component[i], s[i] = label, t[j] * sign[i, j]
                        queue.append(i)
        label += 1
    for _ in range(50):  # majority votes: each sign agrees with most of its pairs
        new_t = np.sign(sign.T @ s)
        new_t[new_t == 0] = t[new_t == 0]
        new_s = np.sign(sign @ new_t)
        new_s[new_s == 0] = s[new_s == 0]
        if np.array_equal(new_s, s) and np.array_equal(new_t, t):
            break
        s, t = new_s, new_t
    s[s == 0], t[t == 0] = 1.0, 1.0
    return s, t, component


def _separating_plane(rows: np.ndarray, cameras: np.ndarray | None) -> tuple[np.ndarray | None, float, bool]:
    """A plane v (|v|_inf <= 1) maximising min_j v . rows_j (rows normalised), and, when one
    exists with a positive margin, also delta v . centre_i for one delta in {+1, -1}. Returns the
    plane (None when no positive margin is possible), its margin, and whether the centres were kept."""
    from scipy.optimize import linprog

    def solve(constraints: np.ndarray) -> tuple[np.ndarray | None, float]:
        # maximise e subject to constraints @ v >= e, -1 <= v <= 1, e <= 1
        A = np.hstack([-constraints, np.ones((len(constraints), 1))])
        answer = linprog(c=np.r_[np.zeros(4), -1.0], A_ub=A, b_ub=np.zeros(len(constraints)),
                         bounds=[(-1, 1)] * 4 + [(None, 1)], method="highs")
        if answer.status != 0 or -answer.fun <= 1e-9:
            return None, 0.0
        return answer.x[:4], float(-answer.fun)

    unit = rows / np.linalg.norm(rows, axis=1, keepdims=True)
    if cameras is not None and len(cameras):
        centres = np.array([camera_centre(P) for P in cameras])
        centres /= np.linalg.norm(centres, axis=1, keepdims=True)
        best = max((solve(np.vstack([unit, delta * centres])) for delta in (1.0, -1.0)), key=lambda vm: vm[1])
        if best[0] is not None:
            return best[0], best[1], True
    plane, margin = solve(unit)
    return plane, margin, False


def _frame(v: np.ndarray) -> np.ndarray:
    """An invertible H whose last row is v (and close to the identity when v is close to e4)."""
    H = np.eye(4)
    H[3] = v
    if abs(v[3]) >= 1e-3 * np.abs(v).max():
        return H
    k = int(np.argmax(np.abs(v[:3])))  # v4 ~ 0: swap in the coordinate that v leans on
    H = np.eye(4)[[i for i in range(4) if i != k] + [k]]
    H[3] = v
    return H


def orient(cameras, points, views: list[list[int]] | None = None) -> Orientation:
    """Orient a projective reconstruction (module docstring). ``cameras``: (m, 3, 4); ``points``:
    (n, 3) or (n, 4); ``views[j]``: the cameras that see point j (default: every camera)."""
    P = np.asarray(cameras, dtype=float)
    if P.ndim != 3 or P.shape[1:] != (3, 4) or len(P) == 0:
        raise ValueError("cameras must be an (m, 3, 4) array with m >= 1")
    largest = np.max(np.abs(P), axis=(1, 2))
    P = np.ldexp(P, -np.frexp(np.where(largest > 0, largest, 1.0))[1][:, None, None])  # exact rescaling
    X = _homogeneous(points)
    m, n = len(P), len(X)
    if n == 0:
        raise ValueError("at least one point is needed to orient the cameras")
    seen = np.ones((m, n), dtype=bool)
    if views is not None:
        if len(views) != n:
            raise ValueError("views must list the cameras of every point")
        seen[:] = False
        for j, cams in enumerate(views):
            seen[list(cams), j] = True
    W = np.einsum("ik,jk->ij", P[:, 2, :], X)
    scale = np.linalg.norm(P[:, 2, :], axis=1)[:, None] * np.linalg.norm(X, axis=1)[None, :]
    zero = seen & (np.abs(W) <= _ZERO * scale)
    s, t, component = _signs(W, seen & ~zero)
    # Each connected part may flip as a whole (s, t -> -s, -t): keep the overall sign that puts
    # most of its points' last coordinates at >= 0.
    for label in np.unique(component):
        cams, pts = component[:m] == label, component[m:] == label
        last = t[pts] * X[pts, 3]
        if np.sum(last > 0) < np.sum(last < 0):
            s[cams], t[pts] = -s[cams], -t[pts]
    Ps = P * s[:, None, None]
    Xs = X * t[:, None]
    H = np.eye(4)
    frame_changed = False
    centres_one_side = _centres_one_side(Ps, np.array([0.0, 0, 0, 1]))
    if np.any(Xs[:, 3] <= 0) or not centres_one_side:
        plane, _, with_centres = _separating_plane(Xs, Ps)
        if plane is not None and (with_centres or np.any(Xs[:, 3] <= 0)):
            H, frame_changed, centres_one_side = _frame(plane), True, with_centres
    Xo = Xs @ H.T
    Po = Ps @ np.linalg.inv(H)
    Po /= np.linalg.norm(Po, axis=(1, 2), keepdims=True)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        affine = Xo / np.where(Xo[:, 3:] > 0, Xo[:, 3:], 1.0)
    # w = 1 where that is representable; a point too near the plane at infinity for it keeps
    # unit norm (still w > 0).
    finite = (Xo[:, 3] > 0) & np.all(np.isfinite(affine), axis=1)
    Xo = np.where(finite[:, None], affine, Xo / np.linalg.norm(Xo, axis=1, keepdims=True))
    depths = np.einsum("ik,jk->ij", Po[:, 2, :], Xo)
    negative = [(int(i), int(j)) for i, j in zip(*np.nonzero(seen & ~zero & (depths <= 0)))]
    undetermined = [(int(i), int(j)) for i, j in zip(*np.nonzero(zero))]
    return Orientation(cameras=Po, points=Xo, camera_signs=s.astype(int), point_signs=t.astype(int), transform=H,
                       frame_changed=frame_changed, quasi_affine=bool(np.all(Xo[:, 3] > 0)),
                       centres_one_side=centres_one_side, negative_depths=negative, undetermined=undetermined)


def _centres_one_side(cameras: np.ndarray, plane: np.ndarray) -> bool:
    sides = np.array([plane @ camera_centre(P) for P in cameras])
    return bool(np.all(sides > 0) or np.all(sides < 0))


__all__ = ["Orientation", "camera_centre", "orient"]
