"""The geometry of stereo line motion (thesis 9.3.2; ALGORITHMS.md section 6).

A calibrated rig: left camera ``K_l [I | 0]``, right camera ``K_r [R0 | t0]`` (in the left frame).
A motion (R, t) takes the rig of frame a to the rig of frame b: ``X_b = R X_a + t`` in the left
cameras' coordinates, so frame b's cameras are ``P3 = [R | t]`` and ``P4 = [R0 R | R0 t + t0]``.

A line seen in the four views gives four back-projected planes; stacked they form W (9.1), of
rank 2. Rank 2 means the planes of frame b contain the 3D line spanned by the null space of the
planes of frame a: with X_1, X_2 spanning that null space and (n, d) a plane of frame b in frame
b's own coordinates, ``n . (R X_j + t w_j) + d w_j = 0`` for j = 1, 2 and both planes of frame b:
four equations per line, affine in (R, t) (the thesis's f_i of 9.3, the same conditions as its
Gauss-Jordan elimination of W, written without the elimination's pivots, so without its (1,1)
degeneracy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class Rig:
    """A calibrated stereo rig: right = K_right [R | t] in the left camera's frame."""

    K_left: np.ndarray
    K_right: np.ndarray
    R: np.ndarray
    t: np.ndarray

    def __post_init__(self):
        self._cameras = (self.K_left @ np.hstack([np.eye(3), np.zeros((3, 1))]),
                         self.K_right @ np.hstack([self.R, np.asarray(self.t, dtype=float).reshape(3, 1)]))

    def cameras(self) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) 3x4 cameras (computed once: the hot loops ask often)."""
        return self._cameras


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """np.cross of (..., 3) arrays without its per-call overhead (the hot loops call it often),
    written into one array (stacking the components copied them again)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(a.shape if a.shape == b.shape else np.broadcast_shapes(a.shape, b.shape))
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rodrigues(w: np.ndarray) -> np.ndarray:
    """exp([w]x): cos I + sin [k]x + (1 - cos) k k^T for the unit axis k (in scalars: the hot loops
    call it for every step)."""
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    theta = math.sqrt(x * x + y * y + z * z)
    if theta < 1e-12:
        return np.array([[1.0, -z, y], [z, 1.0, -x], [-y, x, 1.0]])
    x, y, z = x / theta, y / theta, z / theta
    c, s = math.cos(theta), math.sin(theta)
    v = 1.0 - c
    return np.array([[c + x * x * v, x * y * v - z * s, x * z * v + y * s],
                     [y * x * v + z * s, c + y * y * v, y * z * v - x * s],
                     [z * x * v - y * s, z * y * v + x * s, c + z * z * v]])


def log_rotation(R: np.ndarray) -> np.ndarray:
    """The rotation vector w with exp([w]x) = R."""
    cos = np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)
    theta = float(np.arccos(cos))
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if theta < 1e-8:
        return v / 2
    if np.pi - theta < 1e-6:
        w, V = np.linalg.eigh((R + R.T) / 2)
        axis = V[:, np.argmax(w)]
        return theta * axis * (1 if axis @ v >= 0 else -1)
    return theta * v / (2 * np.sin(theta))


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def rotation_error_deg(R: np.ndarray, R_true: np.ndarray) -> float:
    return float(np.degrees(np.linalg.norm(log_rotation(R @ R_true.T))))


def segment_lines(segments: np.ndarray) -> np.ndarray:
    """Homogeneous image lines (N, 3) through segments (N, 4) [x0, y0, x1, y1], scaled so that
    (a, b) is a unit normal: a point's distance to the line is |l . [x, y, 1]|."""
    p = np.concatenate([segments[:, :2], np.ones((len(segments), 1))], axis=1)
    q = np.concatenate([segments[:, 2:], np.ones((len(segments), 1))], axis=1)
    lines = cross(p, q)
    return lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)


@dataclass
class LineSet:
    """Lines matched across the four views of a frame pair (a: frame a, b: frame b), with what
    every solver and the residuals need, computed once per frame pair.

    ``segments``: (N, 4, 4) pixels, views in the order left a, right a, left b, right b.
    ``planes_a`` / ``planes_b``: (N, 2, 4) the back-projected planes of each frame in its own
    left camera's coordinates, unit normals. ``points_a`` / ``points_b``: (N, 2, 4) an orthonormal
    basis of the null space of those planes: two homogeneous points spanning the 3D line.
    ``conditioning``: (N, 2) the sine of the angle between the two planes of each frame (0 when
    the line lies in an epipolar plane: the stereo pair does not fix it in 3D).
    """

    rig: Rig
    segments: np.ndarray
    planes_a: np.ndarray
    planes_b: np.ndarray
    points_a: np.ndarray
    points_b: np.ndarray
    conditioning: np.ndarray
    pixel_planes: np.ndarray  # (N, 4, 4): P_k^T l_k, each view in its own frame's coordinates, l_k unit normal in pixels
    depth: float = 1.0  # the scene's typical depth (_typical_depth), the scale of its coordinates

    def __len__(self) -> int:
        return len(self.segments)

    def subset(self, index) -> "LineSet":
        return LineSet(self.rig, self.segments[index], self.planes_a[index], self.planes_b[index],
                       self.points_a[index], self.points_b[index], self.conditioning[index],
                       self.pixel_planes[index], self.depth)


def stereo_planes(rig: Rig, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """(N, 2, 4) back-projected planes P^T l of the left and right image lines, unit normals."""
    P_left, P_right = rig.cameras()
    planes = np.stack([left @ P_left, right @ P_right], axis=1)
    return planes / np.linalg.norm(planes[:, :, :3], axis=2, keepdims=True)


def _typical_depth(rig: Rig, left: np.ndarray, right_planes: np.ndarray) -> float:
    """The median depth of the left segments' endpoints (N, 4) triangulated on the right
    camera's planes (N, 4): the scene's own scale, in the rig's unit. (It was once the median
    of |z / w| over an orthonormal basis of each line's null space; that basis is arbitrary
    within the line and its mix of points changes with the unit, so a scene measured in
    millimetres read as 7.7 km deep.) Endpoints behind the rig or on a plane through the ray
    (a line in an epipolar plane) are left out; with none left, the baseline's length."""
    rays = np.concatenate([left.reshape(-1, 2, 2), np.ones((len(left), 2, 1))], axis=2) @ np.linalg.inv(rig.K_left).T
    n, d = right_planes[:, None, :3], right_planes[:, None, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        depths = (-d / (n * rays).sum(axis=2) * rays[:, :, 2]).reshape(-1)
    depths = depths[np.isfinite(depths) & (depths > 0)]
    return float(np.median(depths)) if len(depths) else float(np.linalg.norm(rig.t))


def line_set(rig: Rig, segments: np.ndarray) -> LineSet:
    """The LineSet of (N, 4, 4) segments (left a, right a, left b, right b)."""
    segments = np.asarray(segments, dtype=float).reshape(-1, 4, 4)
    lines = segment_lines(segments.reshape(-1, 4)).reshape(-1, 4, 3)
    planes_a = stereo_planes(rig, lines[:, 0], lines[:, 1])
    planes_b = stereo_planes(rig, lines[:, 2], lines[:, 3])
    points_a = np.linalg.svd(planes_a)[2][:, 2:, :] if len(segments) else np.zeros((0, 2, 4))
    points_b = np.linalg.svd(planes_b)[2][:, 2:, :] if len(segments) else np.zeros((0, 2, 4))
    conditioning = np.stack([
        np.linalg.norm(cross(planes_a[:, 0, :3], planes_a[:, 1, :3]), axis=1),
        np.linalg.norm(cross(planes_b[:, 0, :3], planes_b[:, 1, :3]), axis=1)], axis=1)
    P_left, P_right = rig.cameras()
    pixel_planes = np.stack([lines[:, 0] @ P_left, lines[:, 1] @ P_right, lines[:, 2] @ P_left,
                             lines[:, 3] @ P_right], axis=1)
    depth = _typical_depth(rig, segments[:, 0], planes_a[:, 1])
    return LineSet(rig, segments, planes_a, planes_b, points_a, points_b, conditioning, pixel_planes, depth)


def in_depth_units(lines: LineSet) -> tuple[LineSet, float]:
    """The same lines with the scene's typical depth (_typical_depth) as the unit of length, and
    that unit in the rig's units: a motion found from them has its t in depths. The algebraic
    solvers' equations (9.3) weigh rotation terms (proportional to the points' coordinates)
    against translation terms (to their homogeneous weight) by the unit, as do their orthonormal
    null-space points; in the rig's own unit the same images of a scaled world gave other
    motions (errors of 15% to several times t at 1e-3 or 1e3 times the unit), in depths they give
    one. Depths rather than baselines: with the points about 1 away the two kinds of terms are
    balanced (in baselines, 30 to 80 away here, RANSAC's samples were worse: bench/stereo_lines.py)."""
    unit = lines.depth
    rig = lines.rig
    return line_set(Rig(rig.K_left, rig.K_right, rig.R, np.asarray(rig.t, dtype=float) / unit), lines.segments), unit


def equations(lines: LineSet) -> tuple[np.ndarray, np.ndarray]:
    """The 4N equations ``A [vec(R) (row-major); t] = b`` (9.3): frame a's line points on frame
    b's planes. Rows scaled so that each has unit norm in (A, b)."""
    X = lines.points_a  # (N, 2, 4)
    n = lines.planes_b[:, :, :3]  # (N, 2, 3)
    d = lines.planes_b[:, :, 3]  # (N, 2)
    N = len(lines)
    # rows for (plane k, point j): kron(n_k, X_j[:3]), w_j n_k ; b = -d_k w_j
    kron = np.einsum("nki,nja->nkjia", n, X[:, :, :3]).reshape(N, 2, 2, 9)
    tcoef = n[:, :, None, :] * X[:, None, :, 3:4]
    A = np.concatenate([kron, tcoef], axis=3).reshape(4 * N, 12)
    b = (-d[:, :, None] * X[:, None, :, 3]).reshape(4 * N)
    scale = np.sqrt((A * A).sum(axis=1) + b * b)
    scale[scale == 0] = 1.0
    return A / scale[:, None], b / scale


def translation_given_rotation(lines: LineSet, R: np.ndarray) -> np.ndarray:
    """The least-squares t of the equations (9.3) for a given R."""
    A, b = equations(lines)
    rhs = b - A[:, :9] @ R.reshape(9)
    return np.linalg.lstsq(A[:, 9:], rhs, rcond=None)[0]


def transform_points(R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Homogeneous points (..., 4) of frame a in frame b's coordinates."""
    out = np.empty_like(X)
    out[..., :3] = X[..., :3] @ R.T + X[..., 3:4] * t
    out[..., 3] = X[..., 3]
    return out


def _view_distances(rig: Rig, X: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """(N, 8) the signed distances of the segments' endpoints (2 frames, 2 cameras, N, 4) to the
    projections of the 3D lines X (2 frames, N, 2, 4: two homogeneous points, each frame's left
    camera coordinates) into each frame's left and right cameras; views in the order (frame,
    camera), two endpoints each. Every view at once: these are the hot loops' residuals."""
    cameras = np.stack(rig.cameras()).transpose(0, 2, 1)  # (2 cameras, 4, 3)
    x = X[:, None] @ cameras[None, :, None]  # (2 frames, 2 cameras, N, 2 points, 3)
    line = cross(x[..., 0, :], x[..., 1, :])
    a, b, c = line[..., 0], line[..., 1], line[..., 2]
    norm = np.hypot(a, b)
    norm[norm == 0] = 1e-300
    s0, s1, s2, s3 = segments[..., 0], segments[..., 1], segments[..., 2], segments[..., 3]
    # oriented like the segment's own line (p0 x p1): a projected line's sign is arbitrary
    scale = np.where(a * (s1 - s3) + b * (s2 - s0) < 0, -1.0, 1.0) / norm
    out = np.stack([(a * s0 + b * s1 + c) * scale, (a * s2 + b * s3 + c) * scale], axis=-1)
    return out.transpose(2, 0, 1, 3).reshape(-1, 8)


def transfer_residuals(lines: LineSet, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 8) pixel residuals of a motion: frame a's 3D lines moved into frame b and projected
    (distances of frame b's segment endpoints, left and right), and frame b's 3D lines moved back
    into frame a (frame a's endpoints)."""
    X = np.stack([transform_points(R, t, lines.points_a), transform_points(R.T, -R.T @ t, lines.points_b)])
    s = lines.segments
    return _view_distances(lines.rig, X, np.stack([s[:, 2:], s[:, :2]]).transpose(0, 2, 1, 3))


def line_errors(lines: LineSet, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N,) the root mean square of each line's 8 endpoint distances (pixels) under a motion:
    what RANSAC thresholds (threshold_px)."""
    r = transfer_residuals(lines, R, t)
    return np.sqrt((r * r).mean(axis=1))


def directions_and_points(planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) unit directions and (N, 3) closest points to the origin of the 3D lines where the
    plane pairs (N, 2, 4) meet."""
    n1, n2 = planes[:, 0, :3], planes[:, 1, :3]
    d1, d2 = planes[:, 0, 3], planes[:, 1, 3]
    direction = cross(n1, n2)
    norm2 = (direction * direction).sum(axis=1)
    norm2[norm2 == 0] = 1e-300
    point = cross(direction, n1) * (-d2)[:, None] + cross(n2, direction) * (-d1)[:, None]
    point = point / norm2[:, None]
    return direction / np.sqrt(norm2)[:, None], point


def _pixel_planes(lines: LineSet, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 4, 4) the four back-projected planes P_k^T l_k in frame a's coordinates, each image
    line scaled to a unit normal in pixels (so that l . P X is a pixel distance times a depth)."""
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, t
    W = lines.pixel_planes.copy()
    W[:, 2:] = W[:, 2:] @ M
    return W


def triangulated_lines(lines: LineSet, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 2, 4) the 3D lines (two homogeneous points, frame a) nearest to all four views'
    planes under the motion: W's best rank-2 approximation (9.1), rows weighted as pixel
    distances times depth (near the least-squares line of the four views for a small motion)."""
    W = _pixel_planes(lines, R, t)
    # Coordinates scaled by the scene's depth, so that the eigenvectors' metric treats points of
    # the scene alike (unit-norm homogeneous points in metres favour points far away).
    H = np.array([lines.depth, lines.depth, lines.depth, 1.0])
    X = np.linalg.eigh((W * H).transpose(0, 2, 1) @ (W * H))[1][:, :, :2].transpose(0, 2, 1)
    return X * H


def reprojection_residuals(lines: LineSet, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 8) pixel distances of the segments' endpoints in the four views to the projections of
    the line triangulated from all four views under the motion."""
    X = triangulated_lines(lines, R, t)
    return _view_distances(lines.rig, np.stack([X, transform_points(R, t, X)]),
                           lines.segments.reshape(-1, 2, 2, 4).transpose(1, 2, 0, 3))
