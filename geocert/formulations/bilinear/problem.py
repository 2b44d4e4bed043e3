"""The bilinear fitting problem of one frame: the data read strictly, the exact cost of a camera and
coefficients from the raw data, and the power-of-two normalisation the relaxations use.

Model (thesis 8.1): the shape is ``S_j = sum_i alpha_i X^i_j`` (K basis shapes of N points) and an
affine camera ``[M | t]`` (2x4) images it as ``M S_j + t``. As ``sum alpha = 1``, the translation
enters linearly; the bilinear terms are ``M_rk alpha_i`` only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from geocert.core.geometry import COORDINATE_LIMIT, InputError, is_number, number_array

# The normalised basis may not have any direction (a combination of shapes) this much smaller than
# its largest: such a basis cannot tell its coefficients apart.
RANK_TOLERANCE = 1e-9


@dataclass
class Frame:
    """One frame in normalised units: ``X`` (K, n, 3) the basis at the n visible points, ``u``
    (n, 2) the observations, and the normalisation (raw = normalised * scale + centre; both
    scales powers of two, so converting cameras and costs is exact)."""

    X: np.ndarray
    u: np.ndarray
    visible: np.ndarray  # indices of the visible points
    shape_centre: np.ndarray
    shape_scale: float
    image_centre: np.ndarray
    image_scale: float

    @property
    def camera_scale(self) -> float:
        """Raw M = normalised M times this (a power of two)."""
        return self.image_scale / self.shape_scale


# The default camera box (camera_bound null): |M'_rk| <= ROOT_FACTOR max |M'| of the camera, rounded
# up to a power of two (at least 1: normalised images and shapes have unit spread).
ROOT_FACTOR = 4.0


def default_half_width(M: np.ndarray) -> float:
    """The default camera box's half-width (normalised) for a camera whose 2x3 part is M
    (normalised): the solver searches at least this box about the camera it returns, and the
    verifier asks a proof made without camera_bound to cover it."""
    largest = max(float(np.max(np.abs(M))), 0.25)
    return math.ldexp(1.0, math.ceil(math.log2(ROOT_FACTOR * largest)))


def _pow2(x: float) -> float:
    if not (x > 0 and math.isfinite(x)):
        return 1.0
    return math.ldexp(1.0, round(math.log2(x)))


def _independent(differences: np.ndarray) -> bool:
    """Whether the rows are independent: the smallest singular value above RANK_TOLERANCE of the
    largest (at least 1), times the root of the row length."""
    singular = np.linalg.svd(differences, compute_uv=False)
    return bool(singular[-1] > RANK_TOLERANCE * max(1.0, singular[0]) * math.sqrt(differences.shape[1]))


# Sizes served (the parser's and the verifier's, checked before anything is built): a frame's
# relaxation has about 6 K rows a point, and the basis check takes K^2 N work.
MAX_SHAPES = 64
MAX_BASIS_VALUES = 1_000_000  # K N


def read_basis(value: Any) -> np.ndarray:
    """The basis (K, N, 3), checked: equal sizes, finite numbers, not degenerate."""
    if not isinstance(value, list) or not value:
        raise InputError("data/basis", "must be a non-empty list of shapes (lists of [X, Y, Z] points)")
    if len(value) > MAX_SHAPES:
        raise InputError("data/basis", f"{len(value)} shapes exceed the limit of {MAX_SHAPES}")
    if isinstance(value[0], list) and len(value) * len(value[0]) > MAX_BASIS_VALUES:
        raise InputError("data/basis", f"{len(value)} shapes of {len(value[0])} points exceed the limit of "
                                       f"{MAX_BASIS_VALUES:,} shape points")
    shapes = []
    for i, shape in enumerate(value):
        where = f"data/basis/{i}"
        array = number_array(shape, where, "a non-empty list of [X, Y, Z] points", 2, COORDINATE_LIMIT)
        if array.shape[0] == 0 or array.shape[1] != 3:
            raise InputError(where, "must be a non-empty list of [X, Y, Z] points")
        if shapes and array.shape != shapes[0].shape:
            raise InputError(where, f"has {array.shape[0]} points, shape 0 has {shapes[0].shape[0]}: every "
                                    "shape has the same points")
        shapes.append(array)
    basis = np.array(shapes)
    centred = basis - basis.reshape(-1, 3).mean(axis=0)
    spread = float(np.sqrt(np.mean(centred * centred)))
    if not spread > 0:
        raise InputError("data/basis", "degenerate: every point of every shape coincides")
    # Each shape a vector of 3N numbers; the coefficients are identifiable (sum alpha = 1) only when
    # the differences to shape 0 are independent.
    flat = (basis / spread).reshape(len(basis), -1)

    def dependent(i: int) -> bool:  # shapes 0..i: is some difference to shape 0 dependent on the others?
        return not (i <= flat.shape[1] and _independent(flat[1:i + 1] - flat[0]))

    # One SVD when every difference passes at once: a prefix's smallest singular value is at least
    # the whole's and its largest at most the whole's (interlacing, rows <= columns), so each
    # prefix passes too, and every prefix past the first that fails fails: a bisection names the
    # first shape that fails (one decomposition per shape made this cost K^3 N).
    if len(basis) > 1 and dependent(len(basis) - 1):
        low, high = 1, len(basis) - 1  # the first dependent shape is in low..high
        while low < high:
            middle = (low + high) // 2
            low, high = (low, middle) if dependent(middle) else (middle + 1, high)
        raise InputError(f"data/basis/{low}", "degenerate basis: this shape is an affine combination of the "
                                              "shapes before it (equal shapes included)")
    for i, shape in enumerate(basis):
        if not np.any(shape != shape[0]):
            raise InputError(f"data/basis/{i}", "degenerate: all its points coincide")
    return basis


def read_frame(value: Any, index: int, n_points: int, n_shapes: int) -> np.ndarray:
    """One frame's points (N, 2), NaN where a point is missing (null)."""
    where = f"data/frames/{index}"
    if not isinstance(value, dict) or "points" not in value:
        raise InputError(where, "must be an object with 'points'")
    for key in value:
        if key != "points":
            raise InputError(f"{where}/{key}", "unknown field (known: points)")
    points = value["points"]
    if not isinstance(points, list):
        raise InputError(f"{where}/points", "must be a list of [u, v] pairs or null")
    if len(points) != n_points:
        raise InputError(f"{where}/points", f"has {len(points)} entries, the basis has {n_points} points "
                                            "(null for a point not seen)")
    out = np.full((n_points, 2), np.nan)
    for j, point in enumerate(points):
        if point is None:
            continue
        if not (isinstance(point, list) and len(point) == 2):
            raise InputError(f"{where}/points/{j}", "must be [u, v] or null")
        for c, x in enumerate(point):
            if not is_number(x):
                raise InputError(f"{where}/points/{j}/{c}", "must be a finite number")
            if abs(x) > COORDINATE_LIMIT:
                raise InputError(f"{where}/points/{j}/{c}", f"magnitude exceeds the limit {COORDINATE_LIMIT:g}")
        out[j] = point
    seen = int(np.sum(~np.isnan(out[:, 0])))
    unknowns = 7 + n_shapes  # 8 camera entries and K coefficients summing to 1
    if 2 * seen < unknowns:
        raise InputError(f"{where}/points", f"{seen} points seen give {2 * seen} equations, fewer than the "
                                            f"{unknowns} unknowns (8 camera entries, {n_shapes} coefficients "
                                            "summing to 1)")
    return out


def read_data(data: Any, items: range | None = None) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """basis, frames (only those in ``items`` read; the others None)."""
    if not isinstance(data, dict):
        raise InputError("data", "must be an object with 'basis' and 'frames'")
    for key in data:
        if key not in ("basis", "frames"):
            raise InputError(f"data/{key}", "unknown field (known: basis, frames)")
    for key in ("basis", "frames"):
        if key not in data:
            raise InputError(f"data/{key}", "is required")
    if not isinstance(data["frames"], list) or not data["frames"]:
        raise InputError("data/frames", "must be a non-empty list of {points}")
    basis = read_basis(data["basis"])
    frames: list = [None] * len(data["frames"])
    for i in items if items is not None else range(len(frames)):
        frames[i] = read_frame(data["frames"][i], i, basis.shape[1], basis.shape[0])
    return basis, frames


def normalise(basis: np.ndarray, points: np.ndarray) -> Frame:
    """The frame in normalised units (deterministic: the verifier computes the same)."""
    visible = np.flatnonzero(~np.isnan(points[:, 0]))
    shape_centre = basis.reshape(-1, 3).mean(axis=0)
    shape_scale = _pow2(float(np.sqrt(np.mean((basis - shape_centre) ** 2))))
    u = points[visible]
    image_centre = u.mean(axis=0)
    image_scale = _pow2(float(np.sqrt(np.mean((u - image_centre) ** 2))))
    X = (basis[:, visible, :] - shape_centre) / shape_scale
    return Frame(X, (u - image_centre) / image_scale, visible, shape_centre, shape_scale, image_centre, image_scale)


def shape_of(basis: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    return np.einsum("i,ijk->jk", alpha, basis)


def residuals(basis: np.ndarray, points: np.ndarray, camera: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Observed minus imaged, (N, 2), NaN where a point is missing."""
    S = shape_of(basis, alpha)
    return points - (S @ camera[:, :3].T + camera[:, 3])


def cost(r: np.ndarray, norm: str) -> float:
    r = r[~np.isnan(r[:, 0])]
    return float(np.sum(np.abs(r))) if norm == "L1L1" else float(np.sum(r * r))


def to_raw(frame: Frame, M: np.ndarray, t: np.ndarray) -> np.ndarray:
    """A normalised camera (M' 2x3, t' 2) as the raw 2x4 camera."""
    M_raw = M * frame.camera_scale
    t_raw = frame.image_scale * t + frame.image_centre - M_raw @ frame.shape_centre
    return np.hstack([M_raw, t_raw[:, None]])


def cost_unit(frame: Frame, norm: str) -> float:
    """Raw cost = normalised cost times this (a power of two)."""
    return frame.image_scale if norm == "L1L1" else frame.image_scale ** 2


def feasible_coefficients(alpha: np.ndarray, coefficients: str, bound: float) -> bool:
    """Whether alpha is in the scope's coefficient set (sum 1 to within 1e-12 per coefficient)."""
    if not np.all(np.isfinite(alpha)) or abs(float(np.sum(alpha)) - 1.0) > 1e-12 * len(alpha):
        return False
    if coefficients == "convex":
        return bool(np.all(alpha >= 0))
    return bool(np.all(np.abs(alpha) <= bound))


def linear_baseline(X: np.ndarray, u: np.ndarray, norm: str, coefficients: str,
                    bound: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thesis 8.3.3, in a frame's normalised units (X (K, n, 3) the basis, u (n, 2)): least squares
    for beta_rki = M_rk alpha_i (and t), then the rank-1 SVD of the 6 x K matrix beta; coefficients
    projected onto the scope's set (sum 1), translation refitted (mean, or median under L1L1)."""
    K, n = X.shape[0], X.shape[1]
    design = np.hstack([np.transpose(X, (1, 2, 0)).reshape(n, 3 * K), np.ones((n, 1))])
    beta = np.linalg.lstsq(design, u, rcond=None)[0]  # (3K + 1, 2)
    B = beta[:3 * K].T.reshape(6, K)  # row r*3 + k, column i
    U, s, Vt = np.linalg.svd(B)
    w = Vt[0]
    total = float(w.sum())
    if abs(total) < 1e-12 * np.abs(w).sum():
        alpha = np.full(K, 1.0 / K)
        M = B.sum(axis=1).reshape(2, 3)
    else:
        alpha = w / total
        M = (U[:, 0] * s[0] * total).reshape(2, 3)
    alpha = project_coefficients(alpha, coefficients, bound)
    r = u - np.einsum("i,ijk->jk", alpha, X) @ M.T
    return M, alpha, np.median(r, axis=0) if norm == "L1L1" else r.mean(axis=0)


def project_coefficients(v: np.ndarray, coefficients: str, bound: float) -> np.ndarray:
    """The nearest coefficient vector of the scope (Euclidean): clip(v - tau, lo, hi) with tau
    such that the sum is 1, the last rounding put where there is room."""
    lo, hi = (0.0, 1.0) if coefficients == "convex" else (-bound, bound)
    v = np.where(np.isfinite(v), np.asarray(v, float), 0.0)
    # sum clip(v - tau, lo, hi) is piecewise linear and non-increasing in tau, with breakpoints at
    # v - hi and v - lo: evaluate it at all of them and interpolate on the piece holding 1.
    taus = np.unique(np.concatenate([v - hi, v - lo]))
    sums = np.clip(v[None, :] - taus[:, None], lo, hi).sum(axis=1)
    k = int(np.searchsorted(-sums, -1.0, side="left"))  # first breakpoint with sum <= 1
    if k == 0:
        tau = taus[0]
    elif k == len(taus):
        tau = taus[-1]
    else:
        t0, t1, s0, s1 = taus[k - 1], taus[k], sums[k - 1], sums[k]
        tau = t0 + (s0 - 1.0) * (t1 - t0) / (s0 - s1) if s0 != s1 else t1
    alpha = np.clip(v - tau, lo, hi)
    for _ in range(3):
        rest = 1.0 - float(alpha.sum())
        if rest == 0:
            break
        room = (hi - alpha) if rest > 0 else (alpha - lo)
        i = int(np.argmax(room))
        alpha[i] = min(hi, max(lo, alpha[i] + rest))
    return alpha
