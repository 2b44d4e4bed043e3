"""Proven intervals of K that hold over the plane at infinity's own uncertainty (numpy only: the
solver's search and the verifier's check share ``hull``).

The metric stage's other proven intervals (metric_sublevel) are proven for the plane the affine
stage states; on a critical or near-critical motion that plane is one of a family the modulus
cost cannot tell apart, and the true K lies outside them. These are proven over the set

    S = {(pi, K) : pi a plane chirality allows, modulus cost of pi <= U_a,
                   K within the intrinsics ranges, metric cost of K for pi <= U_m}

with U_a the affine stage's cost plus ``affine_increase`` and U_m the metric stage's cost plus
``cost_increase`` (each proofs.sublevel_level: the costs recomputed from the planes and K stated):
every K of S has its focal lengths, skew and principal point within them. S holds the truth
whenever the truth costs within those increases, which the estimate's increases (3 standard
errors' worth of each stage's own residual variance) are chosen to make likely.

Read off two searches by interval arithmetic in each orientation's region: v the plane in the
affine stage's region frame (its box proved side by side in exact arithmetic as the affine
proof's is: proofs.check_regions), w omega's five free entries within the ranges' box. The first
tree is over v alone (chirality and the modulus cost); the box of its leaves not excluded, stated
as ``plane_box``, is the root of the second, over (v, w), which splits the planes' sides for its
first PLANE_SPLITS levels and omega's after. Bisection only (the widest side relative to the
root's, at its midpoint), one bit a box a level (split or leaf), so a reader replays both trees
exactly. A leaf is excluded when a chirality row is negative over it, when a lower bound on the
modulus cost over it exceeds U_a, or one on the metric cost exceeds U_m; the intervals are the
hull, over the second trees' leaves not excluded, of each intrinsic's range on the leaf
(metric_relaxation.intrinsics_ranges, which also drops a leaf with no K within the ranges).
Every interval operation is widened outward by ``WIDEN`` of its operands' size, so rounding
never excludes a box wrongly.

The bounds are interval arithmetic in mean-value form (Dual), not a relaxation: tight on small
boxes, loose on large ones, so the searches, stopped at their budgets, leave a critical family's
leaves open and often much more; a leaf never split excludes nothing its own bound does not, so
the intervals are then wide, never wrong. The modulus coefficients times the plane's last
coordinate d are affine in v, and so are the infinite homographies d H_j (the metric cost does
not see their scale): both are exact intervals over a box; the modulus residuals are also
bounded as cbrt(gamma alpha^3) - beta and in a homogeneous form needing no division by d."""

from __future__ import annotations

import math

import numpy as np

from geocert.formulations.autocalibration import frames, metric_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.formulations.autocalibration.proofs import (LARGEST_INCREASE, SMALLEST_INCREASE, check_regions, record,
                                                    sublevel_level)
from geocert.core.determinacy import proven_document as _proven_document
from geocert.core.strict import Invalid, charge, number, numbers

WIDEN = 1e-12
PLANE_BOXES = 6_000  # boxes bounded by the search over planes alone (3 dimensions)
MAX_BOXES = 6_000  # boxes bounded by the search over planes and omega (8 dimensions)
# What one box's bound against one camera costs, in units of the verifier's work budget
# (strict.charge; a unit is about 1.2 us of CPU: a chart's 16 centre-view pairs). Measured by
# replaying a genuine 8-view document's trees, bounded in blocks (excluded): about 2.3 us of CPU a
# camera-box over planes alone and 31 us over planes and omega (whose metric terms dominate).
PLANE_BOX_UNITS = 2
BOX_UNITS = 26
# The work the searches' trees may cost in all (units; strict.WORK_BASE is 2,000,000): each
# tree's boxes are as many as fit its share at the problem's number of views (tree_budget).
PLANE_TREE_WORK = 300_000
TREE_WORK = 1_200_000
FLOOR_BOXES = 200  # at least this many boxes a tree, however many views (a document past it pays by its size)
BLOCK_CAMERA_BOXES = 4_096  # bounded at once (about 4 kB a camera-box at the peak: some 16 MB)
# The chirality test is of every box against every row (the document's points, then its cameras):
# those pairs are tested CHIRALITY_PAIRS at a time (a few arrays of 0.5 MB, whatever the points),
# and a box is charged a unit for each ROWS_PER_UNIT rows beside its cameras' units, in the
# verifier's work (_kept) and in the solver's trees alike (tree_budget). Measured about 5 ns of CPU
# a pair tested so (40 to 70 ns a pair in one array of boxes x 10,000 rows), where a unit stands
# for 1.2 us: 64 pairs a unit leaves a fourfold margin.
CHIRALITY_PAIRS = 65_536
ROWS_PER_UNIT = 64
MAX_LEVELS = 400
PLANE_SPLITS = 3  # the levels of a search over planes and omega that split the planes' box (8 x 8 x 8)
NAMES = ("focal_x", "focal_y", "skew", "principal_u", "principal_v")
HULL_MARGIN = 1e-9  # the solver keeps leaves bounded within this much above a level (another machine's rounding)
STATED_SLACK = 1e-7


# --- interval arithmetic on arrays of intervals (lo, hi), widened outward ------------------------

def _pad(lo, hi, size):
    pad = WIDEN * size + 1e-300
    return lo - pad, hi + pad


def _mul(a, b):
    c = np.stack([a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1]])
    lo, hi = c.min(axis=0), c.max(axis=0)
    return _pad(lo, hi, np.abs(c).max(axis=0))


def _div(a, b):
    """a / b for b > 0 throughout (the caller checks)."""
    c = np.stack([a[0] / b[0], a[0] / b[1], a[1] / b[0], a[1] / b[1]])
    lo, hi = c.min(axis=0), c.max(axis=0)
    return _pad(lo, hi, np.abs(c).max(axis=0))


def _sq_lower(a):
    """The least square over each interval (0 where either end is NaN: an interval built from an
    unbounded gradient says nothing)."""
    below = np.where(a[0] > 0, a[0], np.where(a[1] < 0, -a[1], 0.0))
    below = np.where(np.isnan(a[0]) | np.isnan(a[1]), 0.0, below)
    return below * below * (1 - 4 * WIDEN)


def _affine(C, centre, radius):
    """Exact intervals of C[..., :k] x + C[..., k] over the boxes (centre, radius: (N, k)) as
    (N, ...) arrays: the centre's value plus or minus |C| radius, widened."""
    k = centre.shape[1]
    flat = C.reshape(-1, k + 1)
    mid = centre @ flat[:, :k].T + flat[:, k]
    rad = radius @ np.abs(flat[:, :k]).T
    size = np.abs(centre) @ np.abs(flat[:, :k]).T + np.abs(flat[:, k]) + rad
    lo, hi = _pad(mid - rad, mid + rad, size)
    shape = (len(centre),) + C.shape[:-1]
    return lo.reshape(shape), hi.reshape(shape)


class Dual:
    """Intervals (lo, hi) of a quantity over each box and of its gradient in the box's
    coordinates (glo, ghi: one more axis, the coordinates): the mean-value form reads the
    gradient's, whose overestimate is of second order in the box's size (a plain interval
    extension of cbrt(gamma) alpha - beta, a difference of two nearly equal terms, is of first)."""

    def __init__(self, lo, hi, glo, ghi):
        self.lo, self.hi, self.glo, self.ghi = lo, hi, glo, ghi

    @staticmethod
    def affine(C, centre, radius, points: bool = False):
        """C[..., :k] x + C[..., k] over the boxes (exact, widened); at the centres when ``points``."""
        lo, hi = _affine(C, centre, 0 * radius if points else radius)
        g = np.broadcast_to(C[..., :-1], lo.shape + (C.shape[-1] - 1,))
        return Dual(lo, hi, g, g)

    def __add__(self, o):
        lo, hi = _pad(self.lo + o.lo, self.hi + o.hi, np.abs(self.lo) + np.abs(self.hi) + np.abs(o.lo) + np.abs(o.hi))
        glo, ghi = _pad(self.glo + o.glo, self.ghi + o.ghi,
                        np.abs(self.glo) + np.abs(self.ghi) + np.abs(o.glo) + np.abs(o.ghi))
        return Dual(lo, hi, glo, ghi)

    def __neg__(self):
        return Dual(-self.hi, -self.lo, -self.ghi, -self.glo)

    def __sub__(self, o):
        return self + (-o)

    def __mul__(self, o):
        lo, hi = _mul((self.lo, self.hi), (o.lo, o.hi))
        a = _mul((self.lo[..., None], self.hi[..., None]), (o.glo, o.ghi))
        b = _mul((o.lo[..., None], o.hi[..., None]), (self.glo, self.ghi))
        glo, ghi = _pad(a[0] + b[0], a[1] + b[1], np.abs(a[0]) + np.abs(a[1]) + np.abs(b[0]) + np.abs(b[1]))
        return Dual(lo, hi, glo, ghi)

    def positive(self):
        return self.lo > 0

    def over(self, o):
        """self / o, for o > 0 throughout (the caller masks the rest)."""
        lo, hi = _div((self.lo, self.hi), (o.lo, o.hi))
        a = _div((self.glo, self.ghi), (o.lo[..., None], o.hi[..., None]))
        square = _mul((o.lo, o.hi), (o.lo, o.hi))
        b = _div(_mul((self.lo[..., None], self.hi[..., None]), (o.glo, o.ghi)),
                 (square[0][..., None], square[1][..., None]))
        glo, ghi = _pad(a[0] - b[1], a[1] - b[0], np.abs(a[0]) + np.abs(a[1]) + np.abs(b[0]) + np.abs(b[1]))
        return Dual(lo, hi, glo, ghi)

    def cbrt(self):
        """The cube root, for intervals not holding 0 (the caller masks the rest)."""
        lo, hi = np.cbrt(self.lo), np.cbrt(self.hi)
        lo, hi = _pad(lo, hi, np.abs(lo) + np.abs(hi))
        square = _mul((lo, hi), (lo, hi))
        three = (3 * square[0][..., None], 3 * square[1][..., None])
        glo, ghi = _div((self.glo, self.ghi), three)
        return Dual(lo, hi, glo, ghi)


def _mean_value(box: Dual, point: Dual, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The quantity's interval over each box: its value at the centre (``point``) plus the
    gradient's interval times the box's radius, met with the plain interval (``box``)."""
    reach = (np.maximum(np.abs(box.glo), np.abs(box.ghi)) * radius).sum(axis=-1)
    lo, hi = _pad(point.lo - reach, point.hi + reach, np.abs(point.lo) + np.abs(point.hi) + reach)
    return np.maximum(lo, box.lo), np.minimum(hi, box.hi)


# --- what the set is built from ------------------------------------------------------------------

class Region:
    """One orientation's plane box (v in the affine frame) and what the bounds need of it."""

    def __init__(self, problem, delta: float, G: np.ndarray, lo: np.ndarray, hi: np.ndarray):
        self.delta, self.G, self.lo, self.hi = delta, G, lo, hi
        rows = frames.chirality_rows(problem.norm, delta)
        a, b = frames.frame_rows(G, rows)
        self.rows = np.concatenate([a, b[:, None]], axis=1)  # a v + b >= 0 on the scope
        M = frames.plane_map(G, delta)  # (n, d) = M (v, 1), p = n / d
        coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
        self.modulus = np.einsum("jkl,lm->jkm", coef, M)  # d alpha, d beta, d gamma: affine in v
        self.d = M[3]
        views = [i for i in range(len(problem.norm.cameras)) if i != problem.norm.reference]
        A = problem.norm.cameras[views, :, :3]
        a_ = problem.norm.cameras[views, :, 3]
        # d H_j = d A_j - a_j n^T: entry (k, l) is (A_kl M[3] - a_k M[l]) . (v, 1)
        self.homography = A[:, :, :, None] * M[3][None, None, None, :] - a_[:, :, None, None] * M[None, None, :3, :]


class Context:
    def __init__(self, problem, regions: list[Region], U_affine: float, U_metric: float):
        self.problem, self.regions = problem, regions
        self.U_affine, self.U_metric = U_affine, U_metric
        self.w_lo, self.w_hi = metric_relaxation.omega_box(problem.unit_ranges)


def _take(x: Dual, index) -> Dual:
    return Dual(x.lo[..., index], x.hi[..., index], x.glo[..., index, :], x.ghi[..., index, :])


def _modulus_terms(region: Region, centre: np.ndarray, radius: np.ndarray, points: bool):
    """The modulus residuals (Dual, (N, m')) over the boxes of v (or at their centres), and
    whether each box's d is positive (where it is not, nothing is bounded)."""
    d = Dual.affine(region.d[None, :], centre, radius, points)  # (N, 1)
    positive = d.lo[:, 0] > 0
    d = Dual(np.where(d.lo > 0, d.lo, 1.0), np.where(d.lo > 0, d.hi, 1.0), d.glo, d.ghi)
    abg = Dual.affine(region.modulus, centre, radius, points)  # (N, m', 3)
    alpha, beta, gamma = (_take(abg, k).over(d) for k in range(3))
    nonzero = (gamma.lo > 0) | (gamma.hi < 0)  # the cube root's gradient is bounded
    root = gamma.cbrt()
    root.glo = np.where(nonzero[..., None], root.glo, 0.0)
    root.ghi = np.where(nonzero[..., None], root.ghi, 0.0)
    residual = root * alpha - beta
    return residual, positive, np.all(nonzero, axis=1)


def _metric_terms(region: Region, centre: np.ndarray, radius: np.ndarray, points: bool):
    """The metric residuals (Dual, (N, m', 5)) over the boxes of (v, w) (or at their centres),
    and whether every view's scale q is positive over the box."""
    C = np.zeros(region.homography.shape[:-1] + (9,))
    C[..., :3], C[..., 8] = region.homography[..., :3], region.homography[..., 3]
    H = Dual.affine(C, centre, radius, points)  # (N, m', 3, 3)
    entries = {(0, 0): 0, (0, 1): 1, (1, 0): 1, (0, 2): 2, (2, 0): 2, (1, 1): 3, (1, 2): 4, (2, 1): 4}
    omega = {}
    for a in range(3):
        for b in range(3):
            row = np.zeros(9)
            if (a, b) in entries:
                row[3 + entries[(a, b)]] = 1.0
            else:
                row[8] = 1.0
            one = Dual.affine(row[None, :], centre, radius, points)  # (N, 1)
            omega[a, b] = one

    def h(k, a):
        return Dual(H.lo[:, :, k, a], H.hi[:, :, k, a], H.glo[:, :, k, a, :], H.ghi[:, :, k, a, :])

    T = {}
    for k in range(3):
        for b in range(3):
            total = None
            for a in range(3):
                term = h(k, a) * omega[a, b]
                total = term if total is None else total + term
            T[k, b] = total

    def image(k, l):
        total = None
        for b in range(3):
            term = T[k, b] * h(l, b)
            total = term if total is None else total + term
        return total

    q = image(2, 2)
    positive = q.lo > 0
    q = Dual(np.where(positive, q.lo, 1.0), np.where(positive, q.hi, 2.0), q.glo, q.ghi)
    residuals = [omega[k, l] - image(k, l).over(q) for k, l in metric_relaxation.ENTRIES]
    return residuals, np.all(positive, axis=1)


def excluded(context: Context, region: Region, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Which boxes (N, 8: v then w; or N, 3: v alone, every omega) hold no point of S (module
    docstring), by interval bounds in mean-value form. A bound that comes out NaN (an unbounded
    gradient) excludes nothing: every comparison with it is false. The boxes are bounded in
    blocks of BLOCK_CAMERA_BOXES camera-boxes, so memory does not grow with the tree."""
    step = max(1, BLOCK_CAMERA_BOXES // max(len(context.problem.norm.cameras), 1))
    with np.errstate(all="ignore"):
        if len(lo) <= step:
            return _excluded(context, region, lo, hi)
        return np.concatenate([_excluded(context, region, lo[k:k + step], hi[k:k + step])
                               for k in range(0, len(lo), step)])


def tree_budget(views: int, dimensions: int, regions: int = 1, rows: int = 0) -> int:
    """The boxes one tree (of ``regions``' one each) may bound: its share of PLANE_TREE_WORK (a
    tree over planes, 3 dimensions) or TREE_WORK (over planes and omega) at a box's units
    (box_charge: its cameras' and its chirality ``rows``'), within PLANE_BOXES or MAX_BOXES and at
    least FLOOR_BOXES. The solver searches within it at its rows; the verifier replays no more than
    it at no rows (the most any writer searched: one from before the rows were charged counted
    none), and pays for what it replays by the document's size (_kept)."""
    views = max(int(views), 1)
    work, units, most = ((PLANE_TREE_WORK, PLANE_BOX_UNITS, PLANE_BOXES) if dimensions == 3
                         else (TREE_WORK, BOX_UNITS, MAX_BOXES))
    per_box = units * views * ROWS_PER_UNIT + max(int(rows), 0)  # in 1 / ROWS_PER_UNIT units
    return max(FLOOR_BOXES, min(most, work * ROWS_PER_UNIT // per_box)) // max(int(regions), 1)


def box_charge(boxes: int, views: int, dimensions: int, rows: int) -> int:
    """The units ``boxes`` boxes' bounds are charged: box_units a camera-box, and a unit for each
    ROWS_PER_UNIT box-row pairs of the chirality test (rounded up)."""
    return boxes * max(int(views), 1) * box_units(dimensions) + -(-boxes * rows // ROWS_PER_UNIT)


def box_units(dimensions: int) -> int:
    """The work units one box's bound against one camera is charged (PLANE_BOX_UNITS, BOX_UNITS)."""
    return PLANE_BOX_UNITS if dimensions == 3 else BOX_UNITS


def _meet(a, b):
    return np.maximum(a[0], b[0]), np.minimum(a[1], b[1])


def _root_form(region: Region, vc: np.ndarray, vr: np.ndarray):
    """The modulus residuals' intervals as cbrt(Y) - beta, Y = (d gamma) (d alpha)^3 / d^4."""
    d = _affine(region.d[None, :], vc, vr)
    d = (np.where(d[0] > 0, d[0], np.nan), np.where(d[0] > 0, d[1], np.nan))
    abg = _affine(region.modulus, vc, vr)
    alpha, beta, gamma = ((abg[0][:, :, k], abg[1][:, :, k]) for k in range(3))
    cube = _pad(alpha[0] ** 3, alpha[1] ** 3, np.abs(alpha[0]) ** 3 + np.abs(alpha[1]) ** 3)
    d2 = _mul(d, d)
    d4 = _mul(d2, d2)
    Y = _div(_mul(gamma, cube), d4)
    b = _div(beta, d)
    root = _pad(np.cbrt(Y[0]), np.cbrt(Y[1]), np.abs(np.cbrt(Y[0])) + np.abs(np.cbrt(Y[1])))
    return _pad(root[0] - b[1], root[1] - b[0], np.abs(root[0]) + np.abs(root[1]) + np.abs(b[0]) + np.abs(b[1]))


def _homogeneous_form(region: Region, vc: np.ndarray, vr: np.ndarray) -> np.ndarray:
    """A lower bound on each squared modulus residual over the box's planes with d > 0 (every
    plane of the scope: d is the reference camera's chirality row), from the homogeneous form
    d^(4/3) r = cbrt(d gamma) (d alpha) - cbrt(d) (d beta): no division by d, so boxes reaching
    d = 0 (planes through the reference camera's centre, where p = n / d runs off) are bounded."""
    d = _affine(region.d[None, :], vc, vr)
    top = d[1][:, 0]
    low = np.maximum(d[0][:, 0], 0.0)[:, None]
    abg = _affine(region.modulus, vc, vr)
    alpha, beta, gamma = ((abg[0][:, :, k], abg[1][:, :, k]) for k in range(3))
    root = _pad(np.cbrt(gamma[0]), np.cbrt(gamma[1]), np.abs(np.cbrt(gamma[0])) + np.abs(np.cbrt(gamma[1])))
    first = _mul(root, alpha)
    rd = _pad(np.cbrt(low), np.cbrt(np.broadcast_to(top[:, None], low.shape)), np.cbrt(top)[:, None])
    second = _mul(rd, beta)
    F = _pad(first[0] - second[1], first[1] - second[0],
             np.abs(first[0]) + np.abs(first[1]) + np.abs(second[0]) + np.abs(second[1]))
    scale = np.cbrt(top) ** 8 * (1 + 16 * WIDEN)  # d^(8/3) at its largest
    bound = _sq_lower(F) / scale[:, None]
    return np.where((top > 0)[:, None] & np.isfinite(bound), bound, 0.0)


def _against_chirality(region: Region, vc: np.ndarray, vr: np.ndarray) -> np.ndarray:
    """Which boxes of v (centres, radii) a chirality row is negative over throughout: the rows
    (the document's points, then its cameras) taken CHIRALITY_PAIRS // boxes at a time, so the
    arrays are of at most CHIRALITY_PAIRS box-row pairs however many points the document holds."""
    out = np.zeros(len(vc), dtype=bool)
    step = max(1, CHIRALITY_PAIRS // max(len(vc), 1))
    for k in range(0, len(region.rows), step):
        rows = region.rows[k:k + step]
        A, b = rows[:, :3], rows[:, 3]
        reach = vr @ np.abs(A).T
        top = vc @ A.T + reach + b
        size = np.abs(vc) @ np.abs(A).T + reach + np.abs(b)
        out |= np.any(top + WIDEN * size < 0, axis=1)
    return out


def _excluded(context: Context, region: Region, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    centre, radius = (lo + hi) / 2, (hi - lo) / 2
    vc, vr = centre[:, :3], radius[:, :3]
    out = _against_chirality(region, vc, vr)
    box, positive, smooth = _modulus_terms(region, vc, vr, False)
    point, _, _ = _modulus_terms(region, vc, vr, True)
    mean = _mean_value(box, point, vr[:, None, :])
    residual = (np.where(smooth[:, None], mean[0], box.lo), np.where(smooth[:, None], mean[1], box.hi))
    # cbrt(gamma) alpha = cbrt(gamma alpha^3), monotone in gamma alpha^3: no steep cube root where a
    # box's planes pass near a camera's centre (gamma = det H near 0, on chirality's boundary)
    residual = _meet(residual, _root_form(region, vc, vr))
    low = np.where(positive[:, None], _sq_lower(residual), 0.0)
    modulus = np.maximum(low, _homogeneous_form(region, vc, vr)).sum(axis=1)
    out |= modulus > context.U_affine * (1 + 4 * WIDEN)
    if lo.shape[1] == 3:
        return out
    box, bounded = _metric_terms(region, centre, radius, False)
    point, bounded_point = _metric_terms(region, centre, radius, True)
    metric = 0.0
    for e, (b, p) in enumerate(zip(box, point)):
        residual = _mean_value(b, p, radius[:, None, :])
        metric = metric + metric_relaxation.WEIGHTS[e] ** 2 * _sq_lower(residual).sum(axis=1)
    out |= bounded & bounded_point & (metric > context.U_metric * (1 + 4 * WIDEN))
    return out


def _split(lo: np.ndarray, hi: np.ndarray, root_width: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray]:
    """Each box's two halves (the lower ones first), along its widest side relative to the root's;
    a box of planes and omega (the planes' box being the plane tree's hull) along the planes'
    sides for its first PLANE_SPLITS levels, then along omega's only: the metric cost's bound
    over a box of planes takes each view's worst plane apart, and holds to the cost at about
    an eighth of the hull's width."""
    if lo.shape[1] == 3:
        first, last = 0, 3
    else:
        first, last = (0, 3) if level < PLANE_SPLITS else (3, 8)
    axis = first + np.argmax((hi[:, first:last] - lo[:, first:last]) / root_width[first:last], axis=1)
    rows = np.arange(len(lo))
    mid = (lo[rows, axis] + hi[rows, axis]) / 2
    lo2, hi2 = np.repeat(lo, 2, axis=0), np.repeat(hi, 2, axis=0)
    hi2[2 * rows, axis] = mid
    lo2[2 * rows + 1, axis] = mid
    return lo2, hi2


def search(context: Context, region: Region, lo: np.ndarray, hi: np.ndarray, budget: int) -> list[str]:
    """The tree over the root box (lo, hi: (1, k)): its levels, each the hex of one bit a box (1:
    split), bounded breadth first until nothing is left to split or the budget is spent."""
    width = np.where(hi[0] > lo[0], hi[0] - lo[0], 1.0)
    levels, spent = [], 0
    while len(lo) and len(levels) < MAX_LEVELS:
        out = excluded(context, region, lo, hi)
        spent += len(lo)
        split = ~out if spent + 2 * int(np.sum(~out)) <= budget else np.zeros(len(lo), bool)
        levels.append(np.packbits(split.astype(np.uint8)).tobytes().hex())
        if not split.any():
            break
        lo, hi = _split(lo[split], hi[split], width, len(levels) - 1)
    return levels


def leaves(lo: np.ndarray, hi: np.ndarray, levels, where: str, most: int) -> tuple[np.ndarray, np.ndarray]:
    """The leaves the levels describe over the root box (lo, hi: (1, k)), replayed exactly and read
    strictly (at most ``most`` boxes in all)."""
    if not isinstance(levels, list) or not 1 <= len(levels) <= MAX_LEVELS:
        raise Invalid("format", f"{where} must be a list of 1 to {MAX_LEVELS} hex strings")
    width = np.where(hi[0] > lo[0], hi[0] - lo[0], 1.0)
    kept_lo, kept_hi, total = [], [], 0
    for n, text in enumerate(levels):
        count = len(lo)
        total += count
        if total > most or not isinstance(text, str) or len(text) != 2 * ((count + 7) // 8):
            raise Invalid("format", f"{where}/{n}: one bit a box of the level ({count}) as hex, at most {most} "
                                    "boxes in all")
        try:
            bits = np.unpackbits(np.frombuffer(bytes.fromhex(text), dtype=np.uint8))
        except ValueError as exc:
            raise Invalid("format", f"{where}/{n} is not hex") from exc
        if np.any(bits[count:]):
            raise Invalid("format", f"{where}/{n}: bits beyond the level's boxes")
        split = bits[:count].astype(bool)
        kept_lo.append(lo[~split])
        kept_hi.append(hi[~split])
        if n == len(levels) - 1:
            if split.any():
                raise Invalid("coverage", f"{where}: the last level splits boxes no level holds")
            break
        if not split.any():
            raise Invalid("format", f"{where}/{n + 1}: a level after one that splits nothing")
        lo, hi = _split(lo[split], hi[split], width, n)
    return np.concatenate(kept_lo), np.concatenate(kept_hi)


def _kept(context: Context, region: Region, lo: np.ndarray, hi: np.ndarray, margin: float) -> np.ndarray:
    widened = Context(context.problem, context.regions, context.U_affine * (1 + margin),
                      context.U_metric * (1 + margin))
    charge(box_charge(len(lo), len(context.problem.norm.cameras), lo.shape[1], len(region.rows)),
           "proof/plane_sublevel")
    return ~excluded(widened, region, lo, hi)


def plane_hull(context: Context, region: Region, plane_levels, where: str, margin: float = 0.0
               ) -> tuple[np.ndarray, np.ndarray] | None:
    """The hull (in the region's frame) of the plane tree's leaves not excluded; None: none is."""
    most = tree_budget(len(context.problem.norm.cameras), 3, len(context.regions))
    lo, hi = leaves(region.lo[None, :], region.hi[None, :], plane_levels, where, max(most, 1) + 2)
    keep = _kept(context, region, lo, hi, margin)
    if not keep.any():
        return None
    return lo[keep].min(axis=0), hi[keep].max(axis=0)


def hull(context: Context, trees: list, margin: float = 0.0) -> np.ndarray:
    """(fx, fy, skew, u, v) in pixels (5 x 2): the hull, over every region's leaves not excluded
    (at the levels times 1 + ``margin``), of each intrinsic's range on the leaf. ``trees``: each
    region's (plane box stated, or None when its plane tree excludes every leaf; levels)."""
    found = []
    for i, (region, (box, levels)) in enumerate(zip(context.regions, trees)):
        if box is None:  # its plane tree leaves no plane
            continue
        lo, hi = leaves(np.concatenate([box[0], context.w_lo])[None, :],
                        np.concatenate([box[1], context.w_hi])[None, :],
                        levels, f"proof/plane_sublevel/regions/{i}/levels",
                        max(tree_budget(len(context.problem.norm.cameras), 8, len(context.regions)), 1) + 2)
        keep = _kept(context, region, lo, hi, margin)
        for j in np.flatnonzero(keep):
            r = metric_relaxation.intrinsics_ranges(context.problem.unit_ranges, lo[j, 3:], hi[j, 3:])
            if r is not None:
                found.append(r)
    if not found:
        raise Invalid("proven_interval", "proof/plane_sublevel: every leaf is excluded (not even the stated plane "
                                         "and K cost that little)")
    stacked = np.array(found)
    return metric_relaxation.pixel_intervals(
        context.problem.K0, np.stack([stacked[:, :, 0].min(axis=0), stacked[:, :, 1].max(axis=0)], axis=1))


def prove(problem, regions: list[tuple[float, np.ndarray, np.ndarray, np.ndarray, list]], excluded_: list,
          affine_cost: float, affine_increase: float, metric_cost: float, metric_increase: float) -> dict | None:
    """The metric proof's ``plane_sublevel``: the affine stage's regions (delta, frame G, box lo,
    hi, basis) and exclusions as its proof states them; each region's plane tree (the modulus
    cost and chirality alone, over v), the box of planes it leaves (padded outward), and the tree
    over that box times omega's; and the intervals (hull's, at a small margin, padded outward).
    None when no level is finite or nothing is proven."""
    if not all(math.isfinite(x) and x >= 0 for x in (affine_cost, affine_increase, metric_cost, metric_increase)):
        return None
    # each box's bounds cost about a view's work: many views search fewer boxes (wider intervals)
    views = max(len(problem.norm.cameras), 1)
    built = [Region(problem, delta, G, lo, hi) for delta, G, lo, hi, _ in regions]
    context = Context(problem, built, sublevel_level(affine_cost, affine_increase),
                      sublevel_level(metric_cost, metric_increase))
    documents, trees = [], []
    for n, region in enumerate(built):
        plane_levels = search(context, region, region.lo[None, :].copy(), region.hi[None, :].copy(),
                              tree_budget(views, 3, len(built), len(region.rows)))
        found = plane_hull(context, region, plane_levels, "plane_levels", HULL_MARGIN)
        box = None
        if found is not None:
            pad = 1e-9 * (found[1] - found[0]) + 1e-12 * (np.abs(found[0]) + np.abs(found[1]))
            box = (found[0] - pad, found[1] + pad)
        levels = ["00"] if box is None else search(
            context, region, np.concatenate([box[0], context.w_lo])[None, :],
            np.concatenate([box[1], context.w_hi])[None, :],
            tree_budget(views, 8, len(built), len(region.rows)))
        trees.append((box, levels))
        delta, G, lo, hi, basis = regions[n]
        documents.append({"delta": float(delta), "frame": np.asarray(G).tolist(),
                          "box": [np.asarray(lo).tolist(), np.asarray(hi).tolist()],
                          "basis": [[int(k) for k in b] for b in basis], "plane_levels": plane_levels,
                          "plane_box": None if box is None else [box[0].tolist(), box[1].tolist()],
                          "levels": levels})
    try:
        intervals = hull(context, trees, HULL_MARGIN)
    except Invalid:
        return None
    half = 0.5 * (intervals[:, 1] - intervals[:, 0])
    pad = STATED_SLACK * half + 1e-12 * np.abs(intervals).max(axis=1)
    return {"affine_increase": float(affine_increase), "cost_increase": float(metric_increase),
            "regions": documents, "excluded": excluded_,
            "intervals": np.stack([intervals[:, 0] - pad, intervals[:, 1] + pad], axis=1).tolist()}


REGION_FIELDS = ("delta", "frame", "box", "basis", "plane_levels", "plane_box", "levels")


def check(problem, p: np.ndarray, sublevel, metric_cost: float) -> np.ndarray:
    """A metric proof's ``plane_sublevel`` (module docstring), read strictly: its regions proved as
    an affine proof's are (proofs.check_regions), the plane trees replayed and their leaves not
    excluded held by the plane boxes stated, the trees over those boxes times omega's replayed,
    and the intervals stated holding the hull of their leaves not excluded (a wider one is a
    weaker true statement, a narrower one is refused). U_a is the affine cost of the plane p
    stated, U_m ``metric_cost`` (the claimed K's, recomputed), each plus its increase. Returns
    the hull proven."""
    where = "proof/plane_sublevel"
    record(sublevel, where, ("affine_increase", "cost_increase", "regions", "excluded", "intervals"))
    increases = []
    for name in ("affine_increase", "cost_increase"):
        value = number(sublevel.get(name), f"{where}/{name}", "proven_interval")
        if not (value == 0 or SMALLEST_INCREASE <= value <= LARGEST_INCREASE):
            raise Invalid("proven_interval", f"{where}/{name} must be 0 or within 2^-128 .. 2^128")
        increases.append(value)
    stated = numbers(sublevel.get("intervals"), f"{where}/intervals", (5, 2), "proven_interval")
    checked = check_regions(problem, sublevel.get("regions"), sublevel.get("excluded"), REGION_FIELDS, f"{where}/")
    affine_cost = autocalibration_problem.affine_cost(problem, p)
    regions = [Region(problem, delta, G, lo, hi) for delta, G, _, _, lo, hi in checked]
    context = Context(problem, regions, sublevel_level(affine_cost, increases[0]),
                      sublevel_level(metric_cost, increases[1]))
    trees: list = []
    for i, (region, item) in enumerate(zip(regions, sublevel["regions"])):
        at = f"{where}/regions/{i}"
        found = plane_hull(context, region, item.get("plane_levels"), f"{at}/plane_levels")
        box = item.get("plane_box")
        if box is None:
            if found is not None:
                raise Invalid("proven_interval", f"{at}/plane_box is null, but its plane tree leaves planes")
            if item.get("levels") != ["00"]:
                raise Invalid("format", f"{at}/levels: a region with no plane left has the one level [\"00\"]")
            trees.append((None, None))
            continue
        lo, hi = (numbers(side, f"{at}/plane_box", (3,), "proven_interval") for side in
                  (box if isinstance(box, list) and len(box) == 2 else [None, None]))
        if not np.all(lo <= hi):
            raise Invalid("proven_interval", f"{at}/plane_box is not a box")
        if found is not None and not (np.all(lo <= found[0]) and np.all(found[1] <= hi)):
            raise Invalid("proven_interval", f"{at}/plane_box does not hold the planes its tree leaves "
                                             f"({found[0].tolist()}, {found[1].tolist()})")
        trees.append(((lo, hi), item.get("levels")))
    proven = hull(context, trees)
    if not np.all((stated[:, 0] <= proven[:, 0]) & (proven[:, 1] <= stated[:, 1])):
        raise Invalid("proven_interval", f"{where}/intervals are narrower than what its leaves prove "
                                         f"({proven.tolist()})")
    return proven


def proven_document(sublevel: dict) -> dict:
    """What a metric stage's determinacy states as ``proven_over_planes`` from its proof's
    ``plane_sublevel``."""
    out = _proven_document(sublevel["cost_increase"], NAMES, sublevel["intervals"],
                   "over every plane at infinity chirality allows whose modulus cost exceeds the affine stage's by "
                   "at most affine_increase (not only the plane the stages state): the hull, over the leaves of a "
                   "search by interval arithmetic over planes and omega that no bound excludes, of each intrinsic's "
                   "range, in pixels")
    return {**out, "affine_increase": float(sublevel["affine_increase"])}
