"""Problem data as fractional programs: the charts of triangulation and of P^n -> P^m maps.

Plain numpy, shared by the solvers and the certificate verifier (which rebuilds a program from
the problem data exactly as the solver built it). Choices made here (frames, reference
observations) are conditioning only: the program's cost is the caller's cost in any of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from geocert.core.geometry import lengths, outside_squares, square_safe_shift
from geocert.core.strict import charge
from geocert.formulations.fractional.relaxation import FractionalProgram


def camera_centres(cameras: np.ndarray) -> np.ndarray:
    """Null vectors of the (k, 3, 4) cameras, signed so that the last coordinate is not negative."""
    centres = np.linalg.svd(cameras)[2][:, -1, :]
    return centres * np.where(centres[:, 3:4] < 0, -1.0, 1.0)


def _spread_shift(offsets: np.ndarray) -> int:
    """core.geometry.square_safe_shift of the largest offset: 0 where the lengths are computed as
    they always were (the charts of documents written before are the same floats)."""
    return square_safe_shift(float(np.max(np.abs(offsets))) if offsets.size else 0.0)


def _near_one(cams: np.ndarray) -> np.ndarray:
    """Each camera whose largest entry is below 1e-150 or above 1e150 brought near 1 by an exact
    power of two (a camera is homogeneous: the same camera). In a world unit of 1e-300 m the
    framed cameras' entries are near 1e-300 and their rows' lengths underflowed to 0; cameras
    between are untouched (the same floats as before)."""
    largest = np.max(np.abs(cams), axis=(1, 2))
    outside = outside_squares(largest)
    if not outside.any():
        return cams
    shift = np.where(outside, -np.frexp(np.where(outside, largest, 1.0))[1], 0)
    return np.ldexp(cams, shift[:, None, None])


def _camera_frame(centres: np.ndarray) -> np.ndarray:
    """A 4x4 similarity H (X = H X') centring the camera centres with unit mean distance.

    Only conditioning: the problem is the same in any frame, and H keeps the last coordinate.
    """
    finite = np.abs(centres[:, 3]) > 1e-9 * lengths(centres, 1)
    H = np.eye(4)
    if finite.any():
        euclid = centres[finite, :3] / centres[finite, 3:4]
        middle = euclid.sum(axis=0) / len(euclid)  # the mean, without np.mean's overhead
        # A world unit so small (or large) that the lengths' squares underflow (overflow) is read
        # at an exact power of two: a spread read as 0 left the frame unscaled and the chart's
        # rows underflowing (a triangulation in a unit of 1e-162 m: the DLT's SVD did not converge).
        shift = _spread_shift(euclid - middle)
        spread = math.ldexp(float(lengths(np.ldexp(euclid - middle, shift), 1).sum() / len(euclid)), -shift)
        if not spread > 0:
            spread = 1.0
        H[:3, :3] *= spread
        H[:3, 3] = middle
    return H


# Choosing a track's reference projects every camera's centre into every other view: views^2
# pairs, each about 75 ns of CPU (1,000 views: 74 ms). A verification pays for them from its
# work budget (strict.charge) at PAIRS_PER_UNIT pairs a unit, so that a document of long tracks
# and little else cannot ask for more of this work than its size pays for: at most
# PAIRS_PER_UNIT * (WORK_PER_UNIT * size + WORK_BASE) pairs in all. A track's own data pay for
# its pairs up to about 190 views (3 numbers a view, 4 units a number: 12 k >= k^2 / 16);
# longer tracks draw on WORK_BASE (32 million pairs, 2.4 s: 32 tracks of 1,000 views).
PAIRS_PER_UNIT = 16


def reference_work(views: int, tracks: int = 1) -> int:
    """The work units choosing the reference of ``tracks`` tracks of ``views`` views costs."""
    return -(-tracks * views * views // PAIRS_PER_UNIT)


def _choose_reference(cameras: np.ndarray, points: np.ndarray, centres: np.ndarray) -> int:
    """The camera whose centre projects farthest from the other views' observations.

    A centre inside another view's residual cone makes the chart's region unbounded.
    """
    charge(reference_work(len(cameras)), "choosing a track's chart reference (each centre seen by every view)")
    nearest = np.empty(len(cameras))
    block = max(1, 4096 // len(cameras))  # k^2 work in blocks of rows: memory stays linear in k
    for start in range(0, len(cameras), block):
        rows = slice(start, start + block)
        proj = np.einsum("jab,rb->rja", cameras, centres[rows])  # centre r seen by camera j
        depth = proj[:, :, 2]
        safe = np.where(depth > 1e-12 * lengths(proj, 2), depth, np.nan)
        distance = lengths(proj[:, :, :2] / safe[:, :, None] - points[None], 2)
        # Behind camera j (or at infinity) is outside its cone: as good as infinitely far.
        distance = np.where(np.isnan(distance), np.inf, distance)
        own = np.arange(start, min(start + block, len(cameras)))
        distance[own - start, own] = np.inf
        nearest[rows] = distance.min(axis=1)
    return int(np.argmax(nearest))


def _parallel_rows(rows: np.ndarray, reference: int) -> np.ndarray:
    """Which rows are exactly parallel to row ``reference`` (every 2x2 minor zero in exact
    rational arithmetic; a quick float test first rules out the rest)."""
    d = rows[reference]
    minors = rows[:, :, None] * d[None, None, :] - rows[:, None, :] * d[None, :, None]
    size = lengths(rows, 1) * float(np.sqrt(d @ d))
    maybe = np.all(np.abs(minors) <= 1e-12 * size[:, None, None], axis=(1, 2))
    maybe[reference] = True
    exact = np.zeros(len(rows), dtype=bool)
    exact[reference] = True
    d_exact = [Fraction(x) for x in d.tolist()]
    for i in np.flatnonzero(maybe):
        if i == reference:
            continue
        p = [Fraction(x) for x in rows[i].tolist()]
        exact[i] = all(p[a] * d_exact[b] == p[b] * d_exact[a] for a in range(4) for b in range(a + 1, 4))
    return exact


@dataclass
class Chart:
    """A track as a fractional program in chart coordinates y, with X = T [y; 1].

    The reference camera's depth is 1 on the chart, so points at infinity are ordinary points and
    "in front of the reference camera" holds by construction; views whose depth is constant on the
    chart are exact. ``constant_depth_behind``: some view's depth is a non-positive constant.
    """

    program: FractionalProgram
    T: np.ndarray
    reference: int
    constant_depth_behind: bool

    @classmethod
    def build(cls, cameras: np.ndarray, points: np.ndarray, norm: str) -> "Chart":
        centres = camera_centres(cameras)
        reference = _choose_reference(cameras, points, centres)
        frame = _camera_frame(centres)
        cams = _near_one(cameras @ frame)
        cams = cams / lengths(cams[:, 2, :3], 1)[:, None, None]
        depth_row = cams[reference, 2]
        _, _, vt = np.linalg.svd(depth_row[None, :])
        T = np.empty((4, 4))
        T[:, :3] = vt[1:].T
        T[:, 3] = depth_row / (depth_row @ depth_row)
        shifted = cams.copy()  # image coordinates translated to the observation
        shifted[:, 0] -= points[:, 0:1] * cams[:, 2]
        shifted[:, 1] -= points[:, 1:2] * cams[:, 2]
        M = shifted @ T  # (k, 3, 4)
        grad = lengths(M[:, 2, :3], 1)
        row = lengths(M[:, 2], 1)
        # Exact (constant depth) only when it is constant: when the view's depth row is exactly
        # parallel to the reference's in the caller's data (the chart's round-off is then
        # discarded). A depth varying ever so slowly still varies, and far out on the chart it
        # would differ from any constant. Rows are scaled to a unit depth gradient, or, when the
        # depth barely varies, to a unit depth row.
        exact = _parallel_rows(cameras[:, 2], reference)
        scale = np.where(exact, M[:, 2, 3], np.where(grad > 1e-9 * row, grad, row))
        behind = bool((exact & (scale <= 0)).any())
        scale = np.where(scale == 0, 1.0, np.abs(scale))
        M = M / scale[:, None, None]
        den = M[:, 2, :].copy()
        den[exact] = np.array([0.0, 0.0, 0.0, 1.0])
        T = frame @ T  # from chart coordinates to the caller's frame
        # The domain also asks for a non-negative last homogeneous coordinate.
        program = FractionalProgram(M[:, :2, :].copy(), den, exact, T[3][None, :].copy(), norm)
        return cls(program, T, reference, behind)

    def dlt(self) -> np.ndarray | None:
        rows = self.program.num.reshape(-1, 4)
        Y = np.linalg.svd(rows / np.linalg.norm(rows, axis=1, keepdims=True))[2][-1]
        if abs(Y[3]) < 1e-14 * np.linalg.norm(Y):
            return None
        return Y[:3] / Y[3]


def normaliser(points: np.ndarray) -> np.ndarray:
    """Similarity (homogeneous) taking the points' centroid to 0 and mean distance to sqrt(dim)."""
    dim = points.shape[1]
    centre = points.mean(axis=0)
    offsets = points - centre
    # Squares of offsets below 1e-150 underflow and above 1e150 overflow: there the offsets are
    # read at a power of two bringing the largest near 1, exactly, and the mean scaled back (as
    # normalisation.normaliser). A spread read as 0 left a tiny world's points unscaled and the
    # solver's steps underflowing (a resection at 1e-162 returned an all-zero camera). Between,
    # the code path is unchanged: the charts of documents written before are the same floats.
    shift = _spread_shift(offsets)
    spread = math.ldexp(float(np.mean(np.linalg.norm(np.ldexp(offsets, shift), axis=1))), -shift) or 1.0
    S = np.eye(dim + 1)
    S[:dim, :dim] *= math.sqrt(dim) / spread
    S[:dim, dim] = -centre * math.sqrt(dim) / spread
    return S


@dataclass
class MapChart:
    program: FractionalProgram
    source_norm: np.ndarray  # S: normalised source = S [X; 1]
    target_shift: np.ndarray  # target translated by this (residuals unchanged)
    reference: int
    last_row_origin: np.ndarray  # l0
    last_row_basis: np.ndarray  # N, (n+1) x n

    @classmethod
    def build(cls, source: np.ndarray, target: np.ndarray, norm: str) -> "MapChart":
        count, n = source.shape
        m = target.shape[1]
        S = normaliser(source)
        X = (S @ np.hstack([source, np.ones((count, 1))]).T).T  # (count, n+1)
        shift = target.mean(axis=0)
        x = target - shift
        # Reference: the point nearest the centroid, whose depth is 1 by the choice of scale.
        reference = int(np.argmin(np.linalg.norm(X[:, :n], axis=1)))
        l0 = X[reference] / (X[reference] @ X[reference])
        N = np.linalg.svd(X[reference][None, :])[2][1:].T  # (n+1, n), orthonormal, N' X_ref = 0
        d = n + m * (n + 1)
        num = np.zeros((count, m, d + 1))
        den = np.zeros((count, d + 1))
        for j in range(count):
            # depth_j = (l0 + N w) . X_j
            den[j, :n] = N.T @ X[j]
            den[j, d] = l0 @ X[j]
            for k in range(m):
                # x_jk * depth_j - M_k . X_j; row k of M sits at v[n + k(n+1) : n + (k+1)(n+1)]
                num[j, k] = x[j, k] * den[j]
                num[j, k, n + k * (n + 1): n + (k + 1) * (n + 1)] -= X[j]
        exact = np.zeros(count, dtype=bool)
        exact[reference] = True
        den[reference] = 0.0
        den[reference, d] = 1.0
        program = FractionalProgram(num, den, exact, np.zeros((0, d + 1)), norm)
        return cls(program, S, shift, reference, l0, N)

    def matrix(self, v: np.ndarray) -> np.ndarray:
        """M in the caller's coordinates (before normalising its scale)."""
        n = self.last_row_basis.shape[1]
        m = (len(v) - n) // (n + 1)
        rows = v[n:].reshape(m, n + 1)
        last = self.last_row_origin + self.last_row_basis @ v[:n]
        M = np.vstack([rows, last])
        T = np.eye(m + 1)
        T[:m, m] = self.target_shift  # undo the target translation
        return T @ M @ self.source_norm

    def from_matrix(self, M: np.ndarray) -> np.ndarray | None:
        """v for a map given in the caller's coordinates (None when the reference depth <= 0)."""
        m = M.shape[0] - 1
        T_inv = np.eye(m + 1)
        T_inv[:m, m] = -self.target_shift
        Mn = T_inv @ M @ np.linalg.inv(self.source_norm)
        X_ref = self.last_row_origin / (self.last_row_origin @ self.last_row_origin)
        depth = Mn[m] @ X_ref
        if not depth > 0:
            return None
        Mn = Mn / depth
        w = self.last_row_basis.T @ Mn[m]
        return np.concatenate([w, Mn[:m].ravel()])
