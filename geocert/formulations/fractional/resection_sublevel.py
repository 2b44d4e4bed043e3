"""A proven interval of a resection's camera centre: every camera of the scope (every 3x4 camera
putting every point at positive depth) whose L2L2 cost is at most the optimum's plus ``increase``
has its centre within the intervals. Numpy only: the solver states it, the verifier recomputes it.

Cameras are taken on the slice where the reference point's depth is the returned camera P0's
(every camera of the scope is a positive multiple of one there; the cost and the centre do not
change with the scale), as P0 + D(theta), theta in R^11: the first two rows' entries, then the
third row's first three, its fourth fixed by the slice (-theta[8:11] . X_ref). Point j's depth is
w_j(theta) = w_j + theta[8:11] . (X_j - X_ref), its numerator n_j(theta) = n_j + B_j theta (the
residual r_j = n_j / w_j, both linear in theta), and whitened coordinates theta = T phi, with T'
H0 T = I for H0 the Gauss-Newton information at P0. Let c be P0's cost (the optimum is at most
c) and U = c + increase: the set L of cameras costing at most U is what is bounded.

(1) An enclosure, as the triangulation's (convexity.py (E)): every camera of L has every
    |r_j| <= rho = sqrt(U), so lies in the convex set of cameras with positive depths and every
    |n_j(theta)| <= rho w_j(theta), which holds phi = 0. On the sphere |phi| = R that set has
    |G_j u| <= tau_j = (rho + |r_j|)(w_j + R |g_j|) / R for the unit u = phi / R, G_j = A_j T the
    residual's exact first-order map (r_j(theta) - r_j = A_j theta / w_j(theta)) and g_j =
    T[8:11]' (X_j - X_ref) (so |w_j(theta) - w_j| <= R |g_j|); so sum_j |G_j u|^2 / tau_j^2 <=
    k, which lambda_min(sum_j G_j' G_j / tau_j^2) > k refutes: the convex set, and L, lie
    inside |phi| < R. The bound is loose by about the number of points (each residual may take
    the whole budget): it only starts (2). Its passing also proves T invertible (T' (...) T is
    then positive definite), so every theta is some T phi: any computed T serves.
(2) Rounds: knowing L inside |phi| <= r, every depth there is at most hi_j = w_j + r |g_j|, so
    every camera of L has sum_j |n_j + B_j T phi|^2 / hi_j^2 <= (its cost) <= U: a quadratic in
    phi, q0 + 2 rho' phi + phi' K phi, whose sublevel set lies in |phi| <= (|rho| + sqrt(|rho|^2
    + kappa (U - q0))) / kappa for kappa <= lambda_min(K). That is the next r (never more than
    the last). Near P0 the quadratic is the cost's Gauss-Newton model scaled by (w_j / hi_j)^2,
    so the rounds approach the estimate's ellipsoid at level U (its ball in whitened
    coordinates) once r |g_j| is small beside w_j.
(3) The centre C of P0 + D solves A C = -p4 (A the left 3x3, p4 the last column), and so does
    computed centre of P0, Z a computed inverse of A0 and e = P0 [C0; 1]: C - C0 =
    -Z D [C0; 1] - (A0^-1 - Z) D [C0; 1] - A0^-1 e + A0^-1 dA A^-1 (e + D [C0; 1]). The first
    term is linear in theta (l_k . theta for coordinate k, ranging over +- r |T' l_k|), the rest
    second order or rounding, bounded with s <= sigma_min(A0) and |dA| <= |D|_F <= |T|_F r
    sqrt(1 + |X_ref|^2).

Round-off (docs/certificate.md): each computed quantity is widened by a generous multiple of the
unit round-off times the size of the terms behind it; inexact data-derived matrices (B_j, G_j,
n_j) enter through |a + b|^2 >= (1 - eta) |a|^2 - (1 / eta - 1) |b|^2 with b their error bound;
a smallest eigenvalue is proven by a Cholesky factorisation of the matrix less the margin, its
entries' error and 32 u trace (Demmel's, Rump's bound for order 11 is (n + 1) u trace); weights
1 / tau^2 and 1 / hi^2 are rounded down. The numbers are kept to a moderate range (convexity.py:
0 or magnitude within 2^+-128), so that no product underflows beyond UNDERFLOW.

The cost is O(k) per test or round (k x 2 x 11 products, an 11 x 11 Cholesky factorisation): the
check of a stated proof is linear in the number of points, its stated rounds at most MAX_ROUNDS.
"""

from __future__ import annotations

import math

import numpy as np

from geocert.core.strict import Invalid, number, numbers, record
from geocert.formulations.fractional.convexity import LARGEST, SMALLEST, UNDERFLOW, in_range
from geocert.formulations.fractional.fixed_order import (cholesky, cholesky_completes, gram, inverse3, lower_inverse, mul, norm,
                                                   weighted)

U = 2.0 ** -52
ETA = 1e-6  # the split of inexact terms: (1 - ETA) of the computed quadratic is kept
MAX_ROUNDS = 32
ROUNDS_STOP = 0.99  # the solver stops its rounds once a round shrinks r by less than this factor
STATED_SLACK = 1e-7  # the solver states its intervals this much wider (relative to the half-width)
CHECK_SLACK = 1e-5  # a stated interval may be at most this much wider than the checker's
NAMES = ("centre_x", "centre_y", "centre_z")


class Scene:
    """What every test and round reads, with the round-off bounds of each."""

    def __init__(self, source: np.ndarray, target: np.ndarray, matrix: np.ndarray, reference: int,
                 norm: str = "L2L2"):
        X = np.asarray(source, dtype=float)
        self.norm = norm
        x = np.asarray(target, dtype=float)
        P = np.asarray(matrix, dtype=float)
        k = len(X)
        self.k, self.reference = k, reference
        self.usable = (X.ndim == 2 and X.shape[1] == 3 and x.shape == (k, 2) and P.shape == (3, 4)
                       and 0 <= reference < k and k >= 6 and bool(in_range(X).all() and in_range(x).all()
                                                                  and in_range(P).all()))
        if not self.usable:
            return
        Xh = np.hstack([X, np.ones((k, 1))])
        if mul(Xh[reference], P[2]) < 0:
            P = -P  # the scope's cameras put every point at positive depth: the sign that does
        self.P = P
        with np.errstate(all="ignore"):
            proj = mul(Xh, P.T)
            size = mul(np.abs(Xh), np.abs(P).T)  # (k, 3): the terms behind each projected coordinate
            w, size_w = proj[:, 2], size[:, 2]
            self.w = w
            self.w_hi = (w + 8 * U * size_w) * (1 + 4 * U)
            image = proj[:, :2] / w[:, None]
            r = image - x
            err_image = 32 * U * ((size[:, :2] + np.abs(image) * size_w[:, None]) / np.abs(w)[:, None]
                                  + np.abs(image))
            err_r = err_image + 32 * U * np.abs(x)
            self.r_up = np.sqrt(((np.abs(r) + err_r) ** 2).sum(axis=1)) * (1 + 8 * U)
            if norm == "L2L2":
                self.c_up = float((self.r_up ** 2).sum()) * (1 + (k + 8) * U)
            elif norm == "L2L1":  # the sum of the points' pixel distances
                self.c_up = float(self.r_up.sum()) * (1 + (k + 8) * U)
            else:  # L1L1: the sum of the coordinates' absolute residuals
                self.c_up = float((np.abs(r) + err_r).sum()) * (1 + 8 * U) * (1 + (2 * k + 8) * U)
            # n_j = P12 X_j - x_j w_j, and its error
            self.n = proj[:, :2] - x * w[:, None]
            self.eps_n = np.sqrt(((16 * U * (size[:, :2] + np.abs(x) * size_w[:, None])) ** 2).sum(axis=1))
            D = X - X[reference]  # (k, 3), each entry within U of the exact difference
            blocks = np.zeros((k, 2, 11))
            blocks[:, 0, 0:4] = Xh
            blocks[:, 1, 4:8] = Xh
            B = blocks.copy()
            B[:, :, 8:11] = -x[:, :, None] * D[:, None, :]
            A = blocks
            A[:, :, 8:11] = -image[:, :, None] * D[:, None, :]
            D_size = np.sqrt((D * D).sum(axis=1))
            self.err_B = 4 * U * np.sqrt((x * x).sum(axis=1)) * D_size  # |computed B_j - B_j|_F
            self.err_A = (np.sqrt((err_image ** 2).sum(axis=1)) + 4 * U * np.sqrt((image ** 2).sum(axis=1))) \
                * D_size * (1 + 4 * U)
            H0 = gram(A, 1 / (w * w))
            # T' H0 T = I to rounding (any T serves the proof), in a fixed order (fixed_order): on
            # far data H0 is ill-conditioned, and LAPACK's T differed between BLAS kernels by 1e-4
            L = cholesky(0.5 * (H0 + H0.T))
            if L is None:
                self.usable = False
                return
            T = lower_inverse(L).T
            # Entries far below the largest are rounding (they may be subnormal): any T serves
            # the proof, so they are set to 0, keeping every number in the moderate range.
            T = np.where(np.abs(T) < 1e-20 * np.abs(T).max(), 0.0, T)
            self.T = T
            self.T_F = float(np.sqrt((T * T).sum())) * (1 + 16 * U)
            self.G = mul(A, T)  # (k, 2, 11)
            self.C = mul(B, T)
            A_F = np.sqrt((A * A).sum(axis=(1, 2)))
            B_F = np.sqrt((B * B).sum(axis=(1, 2)))
            self.err_G = (self.err_A + 32 * U * A_F) * self.T_F * (1 + 8 * U)
            self.err_C = (self.err_B + 32 * U * B_F) * self.T_F * (1 + 8 * U)
            g = mul(D, T[8:11])
            g_size = np.sqrt((mul(np.abs(D), np.abs(T[8:11])) ** 2).sum(axis=1))
            self.g_up = (np.sqrt((g * g).sum(axis=1)) + 16 * U * g_size) * (1 + 8 * U)
            self.g, self.g_err = g, 16 * U * g_size * (1 + 8 * U)  # |computed g_j - g_j| (resection_bound)
            self.w_err = 8 * U * size_w * (1 + 4 * U)  # |computed w_j - w_j|
            self.usable = bool(np.all(w - 8 * U * size_w > 0) and np.isfinite(self.c_up) and np.all(np.isfinite(self.G))
                               and np.all(np.isfinite(self.C)) and np.all(np.isfinite(self.g_up))
                               and np.all(np.isfinite(self.eps_n)) and in_range(T).all())
        self.X_ref = X[reference]

    def level(self, increase: float) -> float:
        """U from above: the returned camera's cost (at least the optimum) plus the increase."""
        return (self.c_up + increase) * (1 + 4 * U)

    def rho(self, increase: float) -> float:
        """Every residual's length at most this on the cameras costing at most U: sqrt(U) under
        L2L2, U itself under the L1 norms (one point's pixel distance, or the sum of its absolute
        coordinates, is at most the sum over the points)."""
        level = self.level(increase)
        return math.sqrt(level) if self.norm == "L2L2" else level


def least_eigenvalue_above(M: np.ndarray, margin: float, allowance: float) -> bool:
    """Whether every symmetric matrix within ``allowance`` (spectral norm) of the computed ``M``
    has its smallest eigenvalue above ``margin``: a Cholesky factorisation of M less the margin,
    the allowance and 32 u trace (the factorisation's own backward error), every pivot positive."""
    M = 0.5 * (M + M.T)
    trace = float(np.abs(np.diag(M)).sum())
    shift = (margin + allowance + 32 * U * (trace + abs(margin)) + UNDERFLOW) * (1 + 8 * U)
    if not (np.all(np.isfinite(M)) and math.isfinite(shift)):
        return False
    return cholesky(M - shift * np.eye(len(M))) is not None  # fixed_order: one answer on every machine



def _shift(margin: float, allowance: float, trace: float) -> float:
    """What least_eigenvalue_above takes off M's diagonal for ``margin`` (M's trace given)."""
    return (margin + allowance + 32 * U * (trace + abs(margin)) + UNDERFLOW) * (1 + 8 * U)


def _shifted(M: np.ndarray, margins: list, allowance: float) -> np.ndarray:
    """Whether least_eigenvalue_above(M, margin, allowance) passes, for each of the margins: its
    operations, each margin's matrix M less its shift, decided by one stacked factorisation
    (fixed_order.cholesky_completes: each answer the one cholesky gives alone)."""
    M = 0.5 * (M + M.T)
    trace = float(np.abs(np.diag(M)).sum())
    shifts = [_shift(margin, allowance, trace) for margin in margins]
    finite = np.array([math.isfinite(shift) for shift in shifts], dtype=bool) & bool(np.all(np.isfinite(M)))
    if not finite.any():
        return finite
    stack = M - np.array(shifts)[finite, None, None] * np.eye(len(M))  # each M - shift I, entry by entry
    passes = np.zeros(len(margins), dtype=bool)
    passes[finite] = cholesky_completes(stack)
    return passes


# Where no answer is known yet, the bisection's next BISECTION_LEVELS steps are decided by one
# stacked factorisation of every midpoint they may reach (2^levels - 1 of them): the
# factorisations of an 11 x 11 matrix are a few dozen small array operations each, so a stack
# costs little more than one matrix.
BISECTION_LEVELS = 4


def _bisect(halvings: list, hi: float, steps: int, passes) -> float | None:
    """The bisection least_eigenvalue_below makes: halving after halving to the first that passes,
    then midpoint after midpoint, each answer ``passes(margin, batch)``'s (``batch()``: the margins
    worth testing with it, the next halvings or the next levels' possible midpoints); None when no
    halving passes."""
    lo = None
    for at, halving in enumerate(halvings):
        if passes(halving, lambda: halvings[at:at + BISECTION_LEVELS]):
            lo = halving
            break
    if lo is None:
        return None
    hi = min(hi, 2 * lo)
    for taken in range(steps):
        middle = 0.5 * (lo + hi)
        if not lo < middle < hi:
            return lo
        if passes(middle, lambda: _tree_midpoints(lo, hi, min(BISECTION_LEVELS, steps - taken))):
            lo = middle
        else:
            hi = middle
    return lo


def _predicted_margins(M: np.ndarray, allowance: float, halvings: list, hi: float, steps: int) -> list:
    """The margins least_eigenvalue_below would test if each test's answer were what M's
    computed smallest eigenvalue predicts (the shift below it): the halvings up to the first
    predicted to pass, then the bisection's midpoints. Only a guess of where the tests go (near
    the eigenvalue the factorisation's rounding decides, not the prediction); empty where M has no
    computed eigenvalue."""
    M = 0.5 * (M + M.T)
    if not np.all(np.isfinite(M)):
        return []
    try:
        least = float(np.linalg.eigvalsh(M)[0])
    except np.linalg.LinAlgError:
        return []
    trace = float(np.abs(np.diag(M)).sum())
    margins: list = []

    def predicted(margin: float, batch) -> bool:
        margins.append(margin)
        return _shift(margin, allowance, trace) < least

    _bisect(halvings, hi, steps, predicted)
    return margins


def least_eigenvalue_below(M: np.ndarray, allowance: float, steps: int = 48) -> float | None:
    """A positive kappa that least_eigenvalue_above(M, kappa, allowance) passes, close to the
    largest such (by bisection from M's least diagonal entry, an upper bound of its smallest
    eigenvalue, to 2^-steps of it); None when none of 2^-60 of that passes. Only Cholesky
    factorisations in a fixed order decide: one kappa on every machine (LAPACK's eigvalsh, its
    first guess before, differed between BLAS kernels). The midpoints and each test's answer are
    those of testing one midpoint after another, halving after halving then midpoint after
    midpoint; the tests are made in stacks: first every margin the path eigvalsh predicts would
    reach (_predicted_margins: it only chooses what is tested, never an answer), then, from the
    first midpoint off that path, the next BISECTION_LEVELS steps' possible midpoints at once."""
    diagonal = np.diag(M)
    hi = float(diagonal.min()) if len(diagonal) else 0.0
    if not (hi > 0 and math.isfinite(hi)):
        return None
    halvings, lo = [], hi
    for _ in range(60):
        lo *= 0.5
        halvings.append(lo)
    answers: dict[float, bool] = {}  # each margin tested: whether it passes

    def test(margins: list) -> None:
        """The margins not tested yet, by one stacked factorisation."""
        unknown = [margin for margin in margins if margin not in answers]
        if unknown:
            answers.update(zip(unknown, _shifted(M, unknown, allowance).tolist()))

    def passes(margin: float, batch) -> bool:
        if margin not in answers:
            test(batch())
        return answers[margin]

    test(_predicted_margins(M, allowance, halvings, hi, steps))
    return _bisect(halvings, hi, steps, passes)


def _tree_midpoints(lo: float, hi: float, levels: int) -> list:
    """Every midpoint the next ``levels`` steps of bisecting [lo, hi] may test: node i (from 1)
    of the tree of intervals has children 2i (its midpoint fails: hi moves to it) and 2i + 1 (it
    passes: lo moves); a midpoint not strictly inside its interval ends the bisection there."""
    bounds, middles = {1: (lo, hi)}, []
    for node in range(1, 2 ** levels):
        if node not in bounds:
            continue
        a, b = bounds[node]
        middle = 0.5 * (a + b)
        if not a < middle < b:
            continue
        middles.append(middle)
        if 2 * node < 2 ** levels:
            bounds[2 * node], bounds[2 * node + 1] = (a, middle), (middle, b)
    return middles

def encloses(scene: Scene, increase: float, R: float, strictness: float = 1.0) -> bool:
    """(1) at radius R: every camera of the scope costing at most U lies within |phi| < R."""
    if not (scene.usable and SMALLEST <= R <= LARGEST):
        return False
    with np.errstate(all="ignore"):
        rho = scene.rho(increase) * (1 + 4 * U)
        e = (rho + scene.r_up) * (1 + 1e-12)
        tau = e * (scene.w_hi + R * scene.g_up) / R * (1 + 8 * U) + scene.err_G * (1 + 8 * U)
        weight = 1 / (tau * tau) * (1 - 8 * U)
        M = gram(scene.G, weight)
        allowance = 2 * (scene.k + 16) * U * float((weight * (scene.G ** 2).sum(axis=(1, 2))).sum())
        margin = scene.k * (1 + 1e-12 + 1e-6 * (strictness - 1))
        return least_eigenvalue_above(M, margin, strictness * allowance)


def shrink(scene: Scene, increase: float, r: float) -> float:
    """(2): one round from |phi| <= r to the radius it proves (at most r; r when it fails)."""
    with np.errstate(all="ignore"):
        hi = (scene.w_hi + r * scene.g_up) * (1 + 4 * U)
        weight = 1 / (hi * hi) * (1 - 8 * U)  # at most 1 / hi^2: the quadratic stays below the cost
        C, n = scene.C, scene.n
        if scene.norm != "L2L2":  # |y|^2 / b_j <= |y| for |y| <= b_j, y = n_j(theta) / hi_j: b_j is
            # at most rho (y is at most the residual's length) and |n_j| + r |C_j| over hi_j
            reach = (np.sqrt((n * n).sum(axis=1)) + scene.eps_n
                     + r * (np.sqrt((C * C).sum(axis=(1, 2))) + scene.err_C)) * (1 + 16 * U) / hi * (1 + 8 * U)
            b = np.maximum(np.minimum(reach, scene.rho(increase) * (1 + 4 * U)), SMALLEST)
            weight = weight / b * (1 - 4 * U)
        K = gram(C, weight)
        rho = weighted(C, n, weight)
        q0 = float((weight * (n * n).sum(axis=1)).sum())
        k = scene.k
        C_F = np.sqrt((C * C).sum(axis=(1, 2)))
        n_len = np.sqrt((n * n).sum(axis=1))
        K_allowance = 2 * (k + 16) * U * float((weight * C_F * C_F).sum())
        rho_up = (norm(rho) * (1 + 8 * U) + (k + 16) * U * float((weight * C_F * n_len).sum())) \
            * (1 + 4 * U)
        q0_lo = q0 * (1 - (k + 16) * U)
        kappa = least_eigenvalue_below(K, K_allowance)
        if kappa is None:
            return r
        errors_n = 2 / ETA * float((weight * scene.eps_n ** 2).sum()) * (1 + 8 * U)
        errors_C = 2 / ETA * float((weight * scene.err_C ** 2).sum()) * (1 + 8 * U)
        a2 = ((1 - ETA) * kappa - errors_C) * (1 - 8 * U)
        a1 = (1 - ETA) * rho_up * (1 + 4 * U)
        a0 = ((1 - ETA) * q0_lo - errors_n) * (1 - 8 * U) if (1 - ETA) * q0_lo > errors_n \
            else ((1 - ETA) * q0_lo - errors_n) * (1 + 8 * U)
        room = max((scene.level(increase) - a0) * (1 + 4 * U), 0.0)
        if not a2 > 0:
            return r
        bound = (a1 + math.sqrt((a1 * a1 + a2 * room) * (1 + 8 * U)) * (1 + 4 * U)) / a2 * (1 + 64 * U)
    return min(r, bound) if math.isfinite(bound) else r


def centre_bounds(scene: Scene, r: float, linear_reach=None) -> np.ndarray | None:
    """(3): [lower, upper] of each centre coordinate over |phi| <= r, rounded outward; None when the
    left 3x3 block is not shown invertible over the whole ball. ``linear_reach`` (optional:
    resection_centre_l1's dual bounds) maps 12 rows (l's 3, then the 9 of vec(Z dA) = M theta)
    and their errors (2-norm bounds) to upper bounds of max row . theta and max -row . theta over
    the proven set, each used where it is below the ball's r |T' row|."""
    P = scene.P
    with np.errstate(all="ignore"):
        A0 = P[:, :3]
        # Z ~ A0^-1 and c0 ~ -Z p4 with one step of refinement, in a fixed order (fixed_order): the
        # expansion point and Z are any (their errors e and eps_Z are bounded below), but the
        # bounds are centred on c0, and LAPACK's svd put it 1e-3 of a half-width apart between
        # BLAS kernels on far data
        Z = inverse3(A0)
        if Z is None:
            return None
        c0 = -mul(Z, P[:, 3])
        c0 = c0 - mul(Z, mul(A0, c0) + P[:, 3])
        ch = np.append(c0, 1.0)
        # Z e, e = P0 [c0; 1]: its size from above (two products' rounding, the terms' sizes)
        Ze = mul(Z, mul(P, ch))
        Ze_up = (norm(Ze) * (1 + 8 * U)
                 + 16 * U * float(np.sqrt((mul(np.abs(Z), mul(np.abs(P), np.abs(ch))) ** 2).sum()))) * (1 + 4 * U)
        residual = np.eye(3) - mul(Z, A0)
        eps_Z = (float(np.sqrt((residual * residual).sum())) * (1 + 8 * U)
                 + 8 * U * float(np.sqrt((mul(np.abs(Z), np.abs(A0)) ** 2).sum()))) * (1 + 4 * U)
        T, T_F = scene.T, scene.T_F
        # l_k . theta = [Z D [c0; 1]]_k (rows 0, 1 of D times [c0; 1]; row 2's last entry is
        # -theta[8:11] . X_ref), and vec(Z dA) = M theta (M's entries are Z's, exactly)
        l = np.zeros((3, 11))
        l[:, 0:4] = Z[:, 0:1] * ch
        l[:, 4:8] = Z[:, 1:2] * ch
        l[:, 8:11] = Z[:, 2:3] * (c0 - scene.X_ref)
        l_err = 4 * U * np.abs(Z).max(axis=1) * (float(np.abs(ch).sum()) + float(np.abs(scene.X_ref).sum()))
        M = np.zeros((3, 3, 11))
        for a, start in enumerate((0, 4, 8)):
            M[:, :, start:start + 3] += Z[:, a, None, None] * np.eye(3)[None]
        M = M.reshape(9, 11)

        def reach(rows: np.ndarray, errors: np.ndarray) -> np.ndarray:
            """|rows_i . T phi| <= r * this, each row (its own error ``errors``, a 2-norm bound)."""
            product = mul(rows, T)
            return (np.sqrt((product * product).sum(axis=1)) * (1 + 8 * U)
                    + 16 * U * T_F * np.sqrt((rows * rows).sum(axis=1)) + T_F * errors) * (1 + 4 * U)

        linear = r * reach(l, l_err * math.sqrt(11))  # per coordinate
        entries = r * reach(M, np.zeros(9))  # row k of Z dA holds M's rows 3k .. 3k + 2
        below = above = linear  # of l_k . theta (the centre moves by minus it) and of -l_k . theta
        if linear_reach is not None:  # the same linear functionals bounded over the proven set
            plus, minus = linear_reach(np.vstack([l, M]), np.concatenate([l_err * math.sqrt(11), np.zeros(9)]))
            plus, minus = np.maximum(plus, 0.0), np.maximum(minus, 0.0)  # the set holds theta = 0
            below = np.where(np.isfinite(plus[:3]), np.minimum(below, plus[:3]), below)
            above = np.where(np.isfinite(minus[:3]), np.minimum(above, minus[:3]), above)
            entries = np.minimum(entries, np.maximum(plus[3:], minus[3:]))
        Eh = float(np.sqrt((np.maximum(below, above) ** 2).sum())) * (1 + 8 * U)  # |Z D [c0; 1]|
        rows = entries.reshape(3, 3)
        EA_rows = np.sqrt((rows * rows).sum(axis=1)) * (1 + 8 * U)  # |row k of Z dA|
        y = (eps_Z + float(np.sqrt((EA_rows * EA_rows).sum()))) * (1 + 8 * U)  # |I - Z A|_F over the ball
        if not y < 1:
            return None
        # C - c0 = -(Z A)^-1 (Z e + Z D [c0; 1]) with (Z A)^-1 = I + Y (I - Y)^-1, Y = I - Z A:
        # coordinate k's remainder is at most |row k of Y| |(I - Y)^-1| (|Z e| + |Z D [c0; 1]|)
        second = (Ze_up + (eps_Z + EA_rows) / (1 - y) * (Ze_up + Eh)) * (1 + 16 * U)
        low = (below + second) * (1 + 8 * U)
        high = (above + second) * (1 + 8 * U)
        bounds = np.stack([np.nextafter(c0 - low, -np.inf), np.nextafter(c0 + high, np.inf)], axis=-1)
    return bounds if np.all(np.isfinite(bounds)) else None


def reference_point(source: np.ndarray) -> int:
    """The point nearest the points' centroid: the slice's depth is fixed there."""
    X = np.asarray(source, dtype=float)
    return int(np.argmin(((X - X.mean(axis=0)) ** 2).sum(axis=1)))


def proven_centre(scene: Scene, increase: float, radius: float, rounds: int) -> tuple[np.ndarray | None, float]:
    """The centre's bounds proven from radius (1) and that many rounds (2), and the final radius."""
    r = radius
    for _ in range(rounds):
        r = shrink(scene, increase, r)
    return centre_bounds(scene, r), r


def smallest_radius(scene: Scene, increase: float, steps: int = 40) -> float | None:
    """The smallest radius (1) passes at with twice its allowances (the solver's: the checker's
    sums, differing in their last bits, pass there too), by bisection; None when none does."""
    with np.errstate(all="ignore"):
        rho = scene.rho(increase)
        e = rho + scene.r_up
        M = np.einsum("kai,kaj,k->ij", scene.G, scene.G, 1 / (e * scene.w_hi) ** 2)
        least = float(np.linalg.eigvalsh(0.5 * (M + M.T))[0])
    if not least > 0:
        return None
    lo = max(math.sqrt(scene.k / least), SMALLEST)
    hi = lo
    for _ in range(300):
        if encloses(scene, increase, hi, strictness=2.0):
            break
        lo, hi = hi, 2 * hi
        if hi > LARGEST:
            return None
    for _ in range(steps):
        middle = math.sqrt(lo * hi)
        if middle >= hi or middle <= lo:
            break
        if encloses(scene, increase, middle, strictness=2.0):
            hi = middle
        else:
            lo = middle
    return hi


def enclosed_radius(scene: Scene, increase: float, steps: int = 40) -> tuple[float, float, int] | None:
    """The solver's enclosure (None where it finds none): the smallest radius (1) that passes
    with twice its allowances, then the rounds (2) until one shrinks r by less than 1%; the
    radius, the radius after the rounds and their count."""
    radius = smallest_radius(scene, increase, steps)
    if radius is None:
        return None
    r, rounds = radius, 0
    while rounds < MAX_ROUNDS:
        smaller = shrink(scene, increase, r)
        rounds += 1
        if not smaller < ROUNDS_STOP * r:
            r = smaller
            break
        r = smaller
    return radius, r, rounds


def check_enclosure(scene: Scene, increase: float, radius: float, rounds, where: str) -> None:
    """The checker's part shared by every resection's proven centre: the stated rounds and radius
    in range, the scene's numbers in the range a proof is checked for, and the radius (1)
    enclosing every camera within ``increase`` of the optimum (Invalid naming ``where`` if not)."""
    if type(rounds) is not int or not 0 <= rounds <= MAX_ROUNDS:
        raise Invalid("proven_interval", f"{where}/rounds must be an integer from 0 to {MAX_ROUNDS}")
    if not (increase >= 0 and (increase == 0 or SMALLEST <= increase <= LARGEST) and SMALLEST <= radius <= LARGEST):
        raise Invalid("proven_interval", f"{where} needs cost_increase >= 0 and a radius of magnitude within "
                                         "[2^-128, 2^128]")
    if not scene.usable:
        raise Invalid("proven_interval", "the map's numbers are outside the range a proven interval is checked for "
                                         "(6 points at least, every number 0 or of magnitude within [2^-128, 2^128], "
                                         "every depth positive)")
    if not encloses(scene, increase, radius):
        raise Invalid("proven_interval", f"{where}: not proven at radius {radius!r}: the cameras costing up to "
                                         f"cost_increase {increase!r} more are not shown to lie within it")


def resection_sublevel(source, target, matrix, increase: float, steps: int = 40) -> dict | None:
    """The proof a solver states (None where it finds none): the smallest radius (1) passes with
    twice its allowances (bisection), the rounds (2) until they shrink r by less than 1%, and
    the centre's intervals a little wider (STATED_SLACK) than its own recomputation's."""
    if not (math.isfinite(increase) and increase >= 0 and (increase == 0 or SMALLEST <= increase <= LARGEST)):
        return None
    reference = reference_point(source)
    scene = Scene(source, target, matrix, reference)
    if not scene.usable:
        return None
    enclosure = enclosed_radius(scene, increase, steps)
    if enclosure is None:
        return None
    radius, r, rounds = enclosure
    bounds = centre_bounds(scene, r)
    if bounds is None:
        return None
    wider = 0.5 * (bounds[:, 1] - bounds[:, 0]) * STATED_SLACK
    stated = np.stack([np.nextafter(bounds[:, 0] - wider, -np.inf), np.nextafter(bounds[:, 1] + wider, np.inf)],
                      axis=-1)
    return {"cost_increase": float(increase), "reference": reference, "radius": float(radius), "rounds": rounds,
            "intervals": stated.tolist()}


def verify_resection_sublevel(source: np.ndarray, target: np.ndarray, sublevel, matrix: np.ndarray, norm: str) -> None:
    """A resection's proven interval: refused unless (1) holds at the stated radius, and the
    stated intervals hold the centre's bounds the stated rounds (2) and (3) prove here, and are
    no wider than those by more than CHECK_SLACK of their half-widths (a narrower interval is not
    proven, a much wider one is not the proof's). O(k) a round: at most MAX_ROUNDS + 1 passes
    over the points."""
    record(sublevel, "proof/sublevel", ("cost_increase", "reference", "radius", "rounds", "intervals"))
    increase = number(sublevel.get("cost_increase"), "proof/sublevel/cost_increase")
    radius = number(sublevel.get("radius"), "proof/sublevel/radius")
    intervals = numbers(sublevel.get("intervals"), "proof/sublevel/intervals", (3, 2))
    reference, rounds = sublevel.get("reference"), sublevel.get("rounds")
    if norm != "L2L2":
        raise Invalid("proven_interval", "a resection's proven interval is for L2L2 (its cost the sum of squares)")
    if type(reference) is not int or not 0 <= reference < len(source):
        raise Invalid("proven_interval", "proof/sublevel/reference must index a point of the map")
    scene = Scene(source, target, matrix, reference)
    check_enclosure(scene, increase, radius, rounds, "proof/sublevel")
    bounds, _ = proven_centre(scene, increase, radius, rounds)
    if bounds is None:
        raise Invalid("proven_interval", "the camera's left 3x3 block is not shown invertible over the proven set: "
                                         "no interval of its centre is proven")
    if not (np.all(intervals[:, 0] <= bounds[:, 0]) and np.all(intervals[:, 1] >= bounds[:, 1])):
        raise Invalid("proven_interval", "proof/sublevel/intervals are narrower than what the proof proves")
    slack = 0.5 * (bounds[:, 1] - bounds[:, 0]) * CHECK_SLACK + 4 * np.spacing(np.abs(bounds).max(axis=1))
    if not (np.all(intervals[:, 0] >= bounds[:, 0] - slack) and np.all(intervals[:, 1] <= bounds[:, 1] + slack)):
        raise Invalid("proven_interval", "proof/sublevel/intervals are wider than what the proof proves: they are not "
                                         "its intervals")
