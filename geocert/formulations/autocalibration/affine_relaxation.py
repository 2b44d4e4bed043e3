"""The affine stage's convex relaxation on a box of v (thesis 6.5.4, (6.29)), numpy only: the
solver and the verifier build it with this one function.

In the centred quasi-affine frame the plane at infinity is (v, 1); ``M @ (v, 1) = (num, d)``
gives the reference-frame plane ``(p, 1) = (num / d, 1)`` with d > 0 on the chirality polytope.
For view j, alpha_j d = a_j(v), beta_j d = b_j(v), gamma_j d = c_j(v) are linear in v and

    cost(v) = sum_j (cbrt(gamma_j) alpha_j - beta_j)^2 = sum_j (cbrt(c_j) a_j - cbrt(d) b_j)^2 / d^(8/3).

Relaxation: minimise r subject to r e >= sum_j (f_j - g_j)^2 (a rotated cone),
f_j within the envelopes of t_j a_j with t_j within those of cbrt(c_j) (B.12/B.13, then
McCormick B.4: the two-step relaxation of x^(1/3) y, valid whatever the signs), g_j likewise
with s = cbrt(d), e below the secant of d^(8/3) (B.1), v in the box and on the chirality rows.

Variables: x = [v (3), r, e, s, t (m), f (m), g (m)].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.formulations.autocalibration import envelopes
from geocert.core.cones import ConeSpec

WIDEN = 1e-12  # relative outward rounding of every interval computed here


@dataclass
class AffineSetup:
    coef: np.ndarray  # (m, 3, 4): alpha, beta, gamma of each view, affine in p
    M: np.ndarray  # 4x4 plane map
    rows_a: np.ndarray  # (k, 3) chirality rows used in the relaxation: a . v + b >= 0
    rows_b: np.ndarray  # (k,)
    unit: float = 1.0  # the program's objective is unit * cost (about 1 at the incumbent: solver accuracy)

    def functionals(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(D, A, B, C): d = D . (v, 1); a_j = A[j] . (v, 1); likewise b_j, c_j."""
        num, D = self.M[:3], self.M[3]
        forms = self.coef[:, :, :3] @ num + self.coef[:, :, 3:4] * D[None, None, :]  # (m, 3, 4)
        return D, forms[:, 0], forms[:, 1], forms[:, 2]


def interval(F: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range of F . (v, 1) over the box (rows of F at once), widened outward."""
    F = np.atleast_2d(F)
    low = F[:, 3] + np.minimum(F[:, :3] * lo, F[:, :3] * hi).sum(axis=1)
    high = F[:, 3] + np.maximum(F[:, :3] * lo, F[:, :3] * hi).sum(axis=1)
    pad = WIDEN * (np.abs(F[:, 3]) + (np.abs(F[:, :3]) * np.maximum(np.abs(lo), np.abs(hi))).sum(axis=1))
    return low - pad, high + pad


def product_interval(al, au, bl, bu):
    corners = np.stack([al * bl, al * bu, au * bl, au * bu])
    low, high = corners.min(axis=0), corners.max(axis=0)
    pad = WIDEN * np.abs(corners).max(axis=0)
    return low - pad, high + pad


def cbrt_interval(lo, hi):
    low, high = np.cbrt(lo), np.cbrt(hi)
    pad = WIDEN * np.maximum(np.abs(low), np.abs(high))
    return low - pad, high + pad


@dataclass
class AffineProgram:
    q: np.ndarray
    A: np.ndarray
    b: np.ndarray
    cones: ConeSpec
    lower: np.ndarray  # bounds every point of the domain in the box (costing at most the cap) meets
    upper: np.ndarray


def d_range(setup: AffineSetup, lo: np.ndarray, hi: np.ndarray) -> tuple[float, float]:
    """d's range over the box, clipped at 0 (d > 0 on the domain)."""
    D = setup.functionals()[0]
    dl, du = interval(D, lo, hi)
    return max(float(dl[0]), 0.0), float(du[0])


def build(setup: AffineSetup, lo: np.ndarray, hi: np.ndarray, cap: float, cap_row: bool = False
          ) -> AffineProgram | None:
    """The relaxation over the box, its objective in units of ``1 / setup.unit`` of the cost;
    ``cap`` bounds the cost of the points that matter (with ``cap_row``, also as a constraint:
    the set a box's tightening optimises over). None when d <= 0 on the whole box (no domain
    point there)."""
    D, Af, Bf, Cf = setup.functionals()
    m = len(Af)
    dl, du = d_range(setup, lo, hi)
    if not du > 0:
        return None
    al, au = interval(Af, lo, hi)
    bl, bu = interval(Bf, lo, hi)
    cl, cu = interval(Cf, lo, hi)
    sl, su = cbrt_interval(np.array([dl]), np.array([du]))
    sl = np.maximum(sl, 0.0)
    tl, tu = cbrt_interval(cl, cu)
    fl, fu = product_interval(tl, tu, al, au)
    gl, gu = product_interval(sl, su, bl, bu)
    e_hi = du ** (8.0 / 3.0) * (1 + 1e-9)

    n = 6 + 3 * m
    V, R, E, S = slice(0, 3), 3, 4, 5
    T, Fv, Gv = 6 + np.arange(m), 6 + m + np.arange(m), 6 + 2 * m + np.arange(m)
    k = len(setup.rows_a)
    # the rows before the views': the box, chirality, s's cube-root envelope
    head = np.zeros((6 + k + 2 * envelopes.TANGENTS, n))
    head_rhs = np.zeros(len(head))
    for i in range(3):  # v_i <= hi_i, -v_i <= -lo_i
        head[2 * i, i], head_rhs[2 * i] = 1.0, hi[i]
        head[2 * i + 1, i], head_rhs[2 * i + 1] = -1.0, -lo[i]
    head[6:6 + k, V] = -setup.rows_a
    head_rhs[6:6 + k] = setup.rows_b
    s_rows, s_rhs, s_kept = cube_root_rows(np.array([S]), D[None], np.array([dl]), np.array([du]), n)
    count = 6 + k + int(s_kept.sum())
    head[6 + k:count], head_rhs[6 + k:count] = s_rows[s_kept], s_rhs[s_kept]
    # each view's rows in turn: t's cube-root envelope (over, under), then f's and g's McCormick
    # (under, over); a view's unused envelope slots are dropped, keeping the order
    t_rows, t_rhs, t_kept = cube_root_rows(T, Cf, cl, cu, n)
    f_rows, f_rhs = product_rows(Fv, T, Af, tl, tu, al, au, n)
    g_rows, g_rhs = product_rows(Gv, np.full(m, S), Bf, np.full(m, sl[0]), np.full(m, su[0]), bl, bu, n)
    view_rows = np.concatenate([t_rows, f_rows, g_rows], axis=1)
    view_rhs = np.concatenate([t_rhs, f_rhs, g_rhs], axis=1)
    view_kept = np.concatenate([t_kept, np.ones((m, 8), dtype=bool)], axis=1)
    tail = np.zeros((2, n))
    tail_rhs = np.zeros(2)
    slope, icpt = envelopes.power_secant(dl, du, 8.0 / 3.0)  # e <= slope d + icpt
    tail[0, E], tail[0, V], tail_rhs[0] = 1.0, -slope * D[:3], slope * D[3] + icpt
    if cap_row:
        tail[1, R], tail_rhs[1] = 1.0, cap * setup.unit
    A_rows = np.concatenate([head[:count], view_rows[view_kept], tail[:1 + cap_row]])
    rhs = np.concatenate([head_rhs[:count], view_rhs[view_kept], tail_rhs[:1 + cap_row]])
    count = len(A_rows)

    nonneg = count
    # Rotated cone r e >= |w|^2, w = f - g: (r + e, r - e, 2 w) in the second-order cone; as
    # s = b - A x, the rows of A are the negated expressions.
    cone = np.zeros((m + 2, n))
    cone[0, R], cone[0, E] = -1.0, -1.0
    cone[1, R], cone[1, E] = -1.0, 1.0
    root_unit = np.sqrt(setup.unit)
    cone[2 + np.arange(m), Fv] = -2.0 * root_unit
    cone[2 + np.arange(m), Gv] = 2.0 * root_unit
    A = np.vstack([A_rows, cone])
    b = np.concatenate([rhs, np.zeros(m + 2)])
    q = np.zeros(n)
    q[R] = 1.0
    lower = np.concatenate([lo, [0.0, 0.0], sl, tl, fl, gl])
    upper = np.concatenate([hi, [cap * setup.unit, e_hi], su, tu, fu, gu])
    return AffineProgram(q, A, b, ConeSpec(nonneg=nonneg, soc=(m + 2,)), lower, upper)


def cube_root_rows(var: np.ndarray, F: np.ndarray, xl: np.ndarray, xu: np.ndarray, n: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """y_i = cbrt(F[i] . (v, 1)), y_i the variable var[i], x_i = F[i] . (v, 1) in [xl[i], xu[i]]:
    per i, the rows of envelopes.cbrt_over (y <= slope x + icpt) then cbrt_under (y >= ...), as
    (rows (len(var), 2 TANGENTS, n), right-hand sides, which are kept)."""
    count = len(var)
    rows = np.zeros((count, 2 * envelopes.TANGENTS, n))
    rhs = np.zeros((count, 2 * envelopes.TANGENTS))
    kept = np.zeros((count, 2 * envelopes.TANGENTS), dtype=bool)
    for half, lines, sign in ((slice(0, envelopes.TANGENTS), envelopes.cbrt_over_lines, 1.0),
                              (slice(envelopes.TANGENTS, None), envelopes.cbrt_under_lines, -1.0)):
        slope, icpt, used = lines(xl, xu)
        slope, icpt = np.where(used, slope, 0.0), np.where(used, icpt, 0.0)
        block = rows[:, half]
        block[np.arange(count), :, var] = sign
        block[:, :, :3] = (-sign * slope)[:, :, None] * F[:, None, :3]
        rhs[:, half] = sign * (slope * F[:, 3:4]) + sign * icpt
        kept[:, half] = used
    return rows, rhs, kept


def product_rows(z: np.ndarray, y: np.ndarray, F: np.ndarray, yl, yu, xl, xu, n: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """z_i = y_i * x_i, x_i = F[i] . (v, 1), y_i in [yl[i], yu[i]], x_i in [xl[i], xu[i]]:
    McCormick's two under-estimators (z >= cy y + cx x + c0) then its two over-estimators, as
    (rows (len(z), 4, n), right-hand sides)."""
    count = len(z)
    under, over = envelopes.mccormick_lines(yl, yu, xl, xu)
    rows = np.zeros((count, 4, n))
    rhs = np.zeros((count, 4))
    for half, lines, sign in ((slice(0, 2), under, -1.0), (slice(2, 4), over, 1.0)):
        cy, cx, c0 = lines[:, :, 0], lines[:, :, 1], lines[:, :, 2]
        block = rows[:, half]
        block[np.arange(count), :, z] = sign
        block[np.arange(count), :, y] = -sign * cy
        block[:, :, :3] = (-sign * cx)[:, :, None] * F[:, None, :3]
        rhs[:, half] = sign * c0 + sign * (cx * F[:, 3:4])
    return rows, rhs


def cost(setup: AffineSetup, v: np.ndarray) -> float:
    """The modulus cost at v (inf where d <= 0: not a plane of the domain)."""
    from geocert.formulations.autocalibration.frames import modulus_residuals

    h = setup.M @ np.append(v, 1.0)
    if not h[3] > 0:
        return float("inf")
    residuals = modulus_residuals(setup.coef, h[:3] / h[3])
    return float(residuals @ residuals)
