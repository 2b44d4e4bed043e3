"""The metric stage's relaxation on a box of omega (thesis 6.6, (6.36)), numpy only.

omega (the DIAC in preconditioned coordinates) has free entries w = (w11, w12, w13, w22, w23)
and w33 = 1. With the plane at infinity fixed, view j's infinite homography H_j, and
q_j(omega) = h_j3' omega h_j3 (h_j3 the third row of H_j), the cost is

    cost(omega) = sum_j || omega - H_j omega H_j^T / q_j(omega) ||_F^2.

Relaxation: nu_j = lambda_j omega with lambda_j = 1 / q_j within bounds from q_j's range;
nu_j's entries within McCormick envelopes (B.4) of lambda_j w_k; nu_j33 = lambda_j;
h_j3' nu_j h_j3 = 1 (exact on the domain: a linear equation in the lifted variables);
omega positive semidefinite (a 3x3 PSD cone); omega in the box; q_j(omega) within its bounds;
r >= sum_j || omega - H_j nu_j H_j^T ||_F^2 (a rotated cone); the intrinsics ranges to second
order (domain_rows: beyond the thesis, which bounds omega by a box only). Minimise r.

Variables: x = [w (5), r, then per view: lambda_j, n_j (5), then u^2, v^2, u v, skew^2].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.formulations.autocalibration import envelopes
from geocert.core.cones import ConeSpec

WIDEN = 1e-12
# Not used, measured: the matrix form of McCormick's envelopes ((lambda - L) omega and
# (U - lambda) omega PSD) is valid and tighter, but its two 3x3 cones per view cost more than they
# save: side by side on a 20-view scene (0.1% noise) 5.4 s with them against 1.7 s without (both
# certified in 1 node after tightening), and on 10 views at 1% noise 1443 against 3329 nodes in
# the same 40 s, gaps alike.
ENTRIES = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2))  # the free entries of omega, in w's order
ALL = ENTRIES + ((2, 2),)
WEIGHTS = np.array([1.0, np.sqrt(2), np.sqrt(2), 1.0, np.sqrt(2), 1.0])  # Frobenius over 6 entries
_ROWS, _COLUMNS = np.array(ALL).T


def omega_of(w: np.ndarray) -> np.ndarray:
    return np.array([[w[0], w[1], w[2]], [w[1], w[3], w[4]], [w[2], w[4], 1.0]])


def sym_basis() -> np.ndarray:
    """(6, 3, 3): the symmetric matrix of each of the six entries (w's five, then the 33)."""
    basis = np.zeros((6, 3, 3))
    for i, (a, b) in enumerate(ALL):
        basis[i, a, b] = basis[i, b, a] = 1.0
    return basis


def congruence(H: np.ndarray) -> np.ndarray:
    """(6, 6) C with entries(H S H^T) = C @ coords(S) for symmetric S (both in ALL's order)."""
    basis = sym_basis()
    images = np.einsum("ka,iab,lb->ikl", H, basis, H)  # (6 coords, 3, 3)
    return np.array([[images[i, a, b] for i in range(6)] for a, b in ALL])


def q_form(H: np.ndarray) -> np.ndarray:
    """q(omega) = h3' omega h3 = Q[:5] . w + Q[5]."""
    h = H[2]
    return np.array([h[0] ** 2, 2 * h[0] * h[1], 2 * h[0] * h[2], h[1] ** 2, 2 * h[1] * h[2], h[2] ** 2])


@dataclass
class MetricSetup:
    H: np.ndarray  # (m, 3, 3) infinite homographies of the views but the reference
    q_lower: np.ndarray  # (m,) q_j's range on the domain (every K within the ranges)
    q_upper: np.ndarray
    ranges: dict | None = None  # the intrinsics' (preconditioned): the domain is every K within them
    unit: float = 1.0  # the program's objective is unit * cost (about 1 at the incumbent: solver accuracy)


def cost(setup: MetricSetup, w: np.ndarray) -> float:
    return float(residuals(setup, w) @ residuals(setup, w))


def residuals(setup: MetricSetup, w: np.ndarray) -> np.ndarray:
    omega = omega_of(w)
    images = np.einsum("jka,ab,jlb->jkl", setup.H, omega, setup.H)
    q = images[:, 2, 2]
    diff = omega[None] - images / q[:, None, None]
    return (WEIGHTS * diff[:, _ROWS, _COLUMNS]).ravel()


def intrinsics_of(w: np.ndarray) -> dict | None:
    """fx, fy, skew, u, v of the K with K K^T = omega (None unless omega is positive definite)."""
    omega = omega_of(w)
    J = np.eye(3)[::-1]
    try:
        L = np.linalg.cholesky(J @ omega @ J)
    except np.linalg.LinAlgError:
        return None
    K = J @ L @ J
    K = K * np.sign(np.diag(K))[None, :]
    K = K / K[2, 2]
    return {"fx": K[0, 0], "fy": K[1, 1], "skew": K[0, 1], "u": K[0, 2], "v": K[1, 2]}


def w_of_intrinsics(ranges_point: dict) -> np.ndarray:
    """omega's free entries for K from {focal, aspect, skew, u, v}."""
    f, aspect = ranges_point["focal"], ranges_point["aspect"]
    K = np.array([[f, ranges_point["skew"], ranges_point["u"]], [0.0, f * aspect, ranges_point["v"]], [0.0, 0.0, 1.0]])
    omega = K @ K.T
    return np.array([omega[a, b] for a, b in ENTRIES])


def in_ranges(ranges: dict, k: dict) -> bool:
    """Whether the intrinsics lie in the ranges, up to 1e-13 of a range's scale: a calibration on
    a range's edge must survive the round trip to pixels and back (the boxes and the pruning are
    widened by WIDEN = 1e-12, so the bounds still cover such points)."""
    def within(x, pair):
        slack = 1e-13 * max(abs(pair[0]), abs(pair[1]), 1.0)
        return pair[0] - slack <= x <= pair[1] + slack

    return (within(k["fx"], ranges["focal"]) and within(k["fy"] / k["fx"], ranges["aspect"])
            and within(k["skew"], ranges["skew"]) and within(k["u"], ranges["u"]) and within(k["v"], ranges["v"]))


def in_domain(setup: MetricSetup, w: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """omega in the box, positive definite, its K within the ranges, each view's scale in range."""
    if not (np.all(w >= lo) and np.all(w <= hi)):
        return False
    k = intrinsics_of(w)
    if k is None or (setup.ranges is not None and not in_ranges(setup.ranges, k)):
        return False
    q = np.array([q_form(H)[:5] @ w + q_form(H)[5] for H in setup.H])
    return bool(np.all(q >= setup.q_lower) and np.all(q <= setup.q_upper))


def _widen(a, *operands) -> np.ndarray:
    """An interval widened outward by WIDEN of its size, or of its ``operands``' when it is their
    sum or difference (which may cancel: its rounding is of theirs, not of the result's), so that
    rounding never narrows one wrongly."""
    size = max([abs(a[0]), abs(a[1]), 1e-300] + [float(np.max(np.abs(x))) for x in operands])
    pad = WIDEN * size
    return np.array([a[0] - pad, a[1] + pad])


def may_meet_ranges(ranges: dict, lo: np.ndarray, hi: np.ndarray) -> bool:
    """False only when no omega of the box has its K within the ranges (intrinsics_ranges)."""
    return intrinsics_ranges(ranges, lo, hi) is not None


def intrinsics_ranges(ranges: dict, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    """[lower, upper] (5 x 2) of (fx, fy, skew, u, v) (preconditioned) over every omega of the
    box whose K is within the ranges; None only when no omega of the box has one. Interval
    arithmetic on v = w23, u = w13, fy^2 = w22 - v^2, skew = (w12 - u v) / fy,
    fx^2 = w11 - skew^2 - u^2, aspect = fy / fx, each met with its range; every interval widened
    outward, so rounding never narrows or empties one wrongly."""
    def meet(a, b):
        low, high = max(a[0], b[0]), min(a[1], b[1])
        return None if low > high else np.array([low, high])

    fy_range = _mul(np.array(ranges["focal"], float), np.array(ranges["aspect"], float))
    u = meet(_widen(np.array([lo[2], hi[2]])), ranges["u"])
    v = meet(_widen(np.array([lo[4], hi[4]])), ranges["v"])
    if u is None or v is None:
        return None
    v2 = _sq(v)
    fy2 = meet(_widen(np.array([lo[3] - v2[1], hi[3] - v2[0]]), lo[3], hi[3], v2), fy_range ** 2)
    if fy2 is None:
        return None
    fy = _widen(np.sqrt(fy2))
    numerator = _widen(_add(np.array([lo[1], hi[1]]), -_mul(u, v)[::-1]), lo[1], hi[1], _mul(u, v))
    quotients = [numerator[0] / fy[0], numerator[0] / fy[1], numerator[1] / fy[0], numerator[1] / fy[1]]
    skew = meet(_widen(np.array([min(quotients), max(quotients)])), ranges["skew"])
    if skew is None:
        return None
    s2, u2 = _sq(skew), _sq(u)
    fx2 = meet(_widen(np.array([lo[0] - s2[1] - u2[1], hi[0] - s2[0] - u2[0]]), lo[0], hi[0], s2, u2),
               np.array(ranges["focal"], float) ** 2)
    if fx2 is None:
        return None
    fx = _widen(np.sqrt(fx2))
    aspect = _widen(np.array([fy[0] / fx[1], fy[1] / fx[0]]))
    if meet(aspect, ranges["aspect"]) is None:
        return None
    return np.array([fx, fy, skew, u, v])


def pixel_intervals(K0: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """(fx, fy, skew, u, v) intervals (5 x 2) in pixels from preconditioned ones, K = K0 K_unit
    with K0 = [[f0, 0, u0], [0, f0, v0], [0, 0, 1]] (f0 > 0), rounded outward."""
    f0, u0, v0 = float(K0[0, 0]), float(K0[0, 2]), float(K0[1, 2])
    out = unit * f0
    out[3] += u0
    out[4] += v0
    pad = WIDEN * (np.abs(out) + abs(u0) + abs(v0))
    return np.stack([out[:, 0] - pad[:, 0], out[:, 1] + pad[:, 1]], axis=1)


def lambda_range(setup: MetricSetup, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    Q = np.array([q_form(H) for H in setup.H])
    ql = Q[:, 5] + np.minimum(Q[:, :5] * lo, Q[:, :5] * hi).sum(axis=1)
    qu = Q[:, 5] + np.maximum(Q[:, :5] * lo, Q[:, :5] * hi).sum(axis=1)
    pad = WIDEN * (np.abs(Q[:, 5]) + (np.abs(Q[:, :5]) * np.maximum(np.abs(lo), np.abs(hi))).sum(axis=1))
    ql, qu = np.maximum(ql - pad, setup.q_lower), np.minimum(qu + pad, setup.q_upper)
    if np.any(ql > qu):
        return None  # no omega of the box meets every view's q range
    if not np.all(ql > 0):
        raise ValueError("a view's scale q = h3' omega h3 is not bounded away from 0 on the domain")
    low, high = 1.0 / qu, 1.0 / ql
    return low * (1 - 4e-16) - 1e-300, high * (1 + 4e-16)


@dataclass
class MetricProgram:
    q: np.ndarray
    A: np.ndarray
    b: np.ndarray
    cones: ConeSpec
    lower: np.ndarray
    upper: np.ndarray


def build(setup: MetricSetup, lo: np.ndarray, hi: np.ndarray, cap: float, cap_row: bool = False
          ) -> MetricProgram | None:
    """The relaxation over the box; None when no omega of the box meets the q ranges. With
    ``cap_row``, also r <= cap (in the program's units): the set bound tightening optimises over."""
    if setup.ranges is not None and not may_meet_ranges(setup.ranges, lo, hi):
        return None  # no K of the box within the ranges
    lam = lambda_range(setup, lo, hi)
    if lam is None:
        return None
    Ll, Lu = lam
    m = len(setup.H)
    n0 = 6 + 6 * m
    domain = setup.ranges is not None
    n = n0 + (4 if domain else 0)  # the domain's lifted terms: u^2, v^2, u v, skew^2
    R = 5
    views = np.arange(m)
    lam_var = 6 + 6 * views  # lambda_j; n_j's entries follow it
    Q = np.array([q_form(H) for H in setup.H])  # (m, 6)
    # h3' nu h3 = 1, nu = [n_j entries, lambda_j at 33]
    zero_rows = np.zeros((m, n))
    zero_rows[views[:, None], lam_var[:, None] + 1 + np.arange(5)] = Q[:, :5]
    zero_rows[views, lam_var] = Q[:, 5]
    head = np.zeros((11, n))  # the box, then the cap (kept with cap_row)
    head[2 * np.arange(5), np.arange(5)] = 1.0
    head[2 * np.arange(5) + 1, np.arange(5)] = -1.0
    head[10, R] = 1.0
    head_rhs = np.empty(11)
    head_rhs[0:10:2], head_rhs[1:10:2] = hi, -lo
    head_rhs[10] = cap * setup.unit
    # per view: q_j's range, lambda_j's, then McCormick's two under- and two over-estimators of
    # each n_jk = lambda_j w_k
    under, over = envelopes.mccormick_lines(np.repeat(Ll, 5), np.repeat(Lu, 5), np.tile(lo, m), np.tile(hi, m))
    view_rows = np.zeros((m, 4 + 20, n))
    view_rhs = np.empty((m, 4 + 20))
    view_rows[:, 0, :5], view_rhs[:, 0] = Q[:, :5], setup.q_upper - Q[:, 5]
    view_rows[:, 1, :5], view_rhs[:, 1] = -Q[:, :5], Q[:, 5] - setup.q_lower
    view_rows[views, 2, lam_var], view_rhs[:, 2] = 1.0, Lu
    view_rows[views, 3, lam_var], view_rhs[:, 3] = -1.0, -Ll
    entry_rows = view_rows[:, 4:].reshape(m, 5, 4, n)  # (view, k, the four rows)
    entry_rhs = view_rhs[:, 4:].reshape(m, 5, 4)
    pair_lam = np.repeat(lam_var, 5).reshape(m, 5)
    pair_n = pair_lam + 1 + np.arange(5)
    for half, lines, sign in ((slice(0, 2), under, -1.0), (slice(2, 4), over, 1.0)):
        cx, cy, c0 = (lines[:, :, i].reshape(m, 5, 2) for i in range(3))
        block = entry_rows[:, :, half]  # n_jk >= cx lambda_j + cy w_k + c0 (under), <= (over)
        block[views[:, None], np.arange(5), :, pair_n] = sign
        block[views[:, None], np.arange(5), :, pair_lam] = -sign * cx
        block[views[:, None], np.arange(5), :, np.arange(5)] = -sign * cy
        entry_rhs[:, :, half] = sign * c0
    corners = np.stack([np.outer(Ll, lo), np.outer(Ll, hi), np.outer(Lu, lo), np.outer(Lu, hi)])
    pad = WIDEN * np.abs(corners).max(axis=0)
    lam_lo_w, lam_hi_w = corners.min(axis=0) - pad, corners.max(axis=0) + pad  # (m, 5)
    rows, rhs = [], []

    def le(coeffs: dict, bound: float) -> None:
        row = np.zeros(n)
        for i, c in coeffs.items():
            row[i] += c
        rows.append(row)
        rhs.append(bound)

    domain_cones, domain_lower, domain_upper = [], [], []
    if domain:
        domain_cones, domain_lower, domain_upper = domain_rows(setup.ranges, lo, hi, n0, le)
    # r >= |res|^2: (r + 1, r - 1, 2 res) in the second-order cone, res_j = W (omega - C_j nu_j).
    C = np.array([congruence(H) for H in setup.H])  # (m, 6, 6)
    scale = 2 * WEIGHTS * np.sqrt(setup.unit)  # (6,)
    residual = np.zeros((m, 6, n))
    residual[:, np.arange(5), np.arange(5)] = 1.0  # omega's entry (omega33 = 1 is a constant)
    residual[views[:, None, None], np.arange(6)[:, None], lam_var[:, None, None] + 1 + np.arange(5)] = -C[:, :, :5]
    residual[views[:, None], np.arange(6), lam_var[:, None]] = -C[:, :, 5]
    cone_rows = np.concatenate([np.zeros((2, n)), (-scale[:, None] * residual).reshape(6 * m, n)])
    cone_rows[0, R] = cone_rows[1, R] = -1.0
    cone_rhs = np.concatenate([[1.0, -1.0], np.tile(scale * np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0]), m)])
    # omega PSD: its svec, order (0,0), (0,1), (1,1), (0,2), (1,2), (2,2), off-diagonals times
    # sqrt 2 (s = b - A x; omega33 = 1 is a constant).
    psd_rows, psd_rhs = [], []
    for entry, factor in ((0, 1.0), (1, np.sqrt(2)), (3, 1.0), (2, np.sqrt(2)), (4, np.sqrt(2)), (5, 1.0)):
        row = np.zeros(n)
        if entry < 5:
            row[entry] = -factor
        psd_rows.append(row)
        psd_rhs.append(0.0 if entry < 5 else factor)
    extra_rows = [_padded(row, n) for cone in domain_cones for row, _ in cone]
    extra_rhs = [value for cone in domain_cones for _, value in cone]
    kept = 10 + bool(cap_row)
    nonneg = np.concatenate([head[:kept], view_rows.reshape(m * 24, n), np.array(rows).reshape(len(rows), n)])
    A = np.vstack([zero_rows, nonneg, cone_rows, np.array(extra_rows).reshape(len(extra_rows), n), np.array(psd_rows)])
    b = np.concatenate([np.ones(m), head_rhs[:kept], view_rhs.ravel(), rhs, cone_rhs, extra_rhs, psd_rhs])
    q = np.zeros(n)
    q[R] = 1.0
    lower = np.concatenate([lo, [0.0], np.concatenate([Ll[:, None], lam_lo_w], axis=1).ravel(), domain_lower])
    upper = np.concatenate([hi, [cap * setup.unit], np.concatenate([Lu[:, None], lam_hi_w], axis=1).ravel(),
                            domain_upper])
    cones = ConeSpec(zero=m, nonneg=len(nonneg), soc=(len(cone_rows), *[len(c) for c in domain_cones]), psd=(3,))
    return MetricProgram(q, A, b, cones, lower, upper)


def _padded(row: np.ndarray, n: int) -> np.ndarray:
    return np.concatenate([row, np.zeros(n - len(row))])


def domain_rows(ranges: dict, lo: np.ndarray, hi: np.ndarray, first: int, le) -> tuple[list, list, list]:
    """The intrinsics ranges inside the relaxation, to second order in the box's width. With
    u = w13, v = w23, fy^2 = w22 - v^2, skew fy = w12 - u v and fx^2 = w11 - u^2 - skew^2, lift
    su = u^2, sv = v^2, puv = u v and ss = skew^2 (variables ``first`` to ``first + 3``); every
    omega of the domain, with its true lifted terms, meets

        su >= u^2 and sv >= v^2 (cones), each below its secant over the box; puv within
        McCormick's envelope; (w12 - puv)^2 <= ss (w22 - sv) (a rotated cone: equality on the
        domain); ss within skew^2's range; fx^2 = w11 - su - ss within focal^2's range;
        fy^2 = w22 - sv within (focal aspect)^2's; aspect_lo^2 fx^2 <= fy^2 <= aspect_hi^2 fx^2.

    Without these the ranges only prune whole boxes, and a search whose optimum lies on a range's
    edge (skew or aspect at its limit: common with 1% noise and 10 views) closes its gap only
    linearly in the boxes' width (measured: 5000 nodes for a 3e-4 gap). ``le`` adds a row
    (coefficients by variable, bound) to the program's inequalities; the cones are returned as
    lists of (row, rhs) with s = rhs - row . x, with the lifted terms' bounds."""
    SU, SV, PUV, SS = first, first + 1, first + 2, first + 3
    U, V, W11, W12, W22 = 2, 4, 0, 1, 3
    f, aspect, skew = (np.array(ranges[k], dtype=float) for k in ("focal", "aspect", "skew"))
    u, v = np.array([lo[U], hi[U]]), np.array([lo[V], hi[V]])
    su, sv, puv, ss = _widen(_sq(u)), _widen(_sq(v)), _widen(_mul(u, v)), _widen(_sq(skew))
    fx2, fy2 = _widen(_sq(f)), _widen(_sq(_mul(f, aspect)))
    a2 = _widen(_sq(aspect))
    for var, x, xr in ((SU, U, u), (SV, V, v)):  # secant: x^2 <= (l + h) x - l h on [l, h]
        slope, icpt = xr[0] + xr[1], -xr[0] * xr[1]
        le({var: 1.0, x: -slope}, icpt + WIDEN * (1.0 + abs(icpt) + abs(slope) * np.abs(xr).max()))
    under, over = envelopes.mccormick(u[0], u[1], v[0], v[1])
    for cx, cy, c0 in under:  # puv >= cx u + cy v + c0
        le({PUV: -1.0, U: cx, V: cy}, -c0)
    for cx, cy, c0 in over:
        le({PUV: 1.0, U: -cx, V: -cy}, c0)
    le({SS: 1.0}, ss[1])
    le({SS: -1.0}, -ss[0])
    le({W11: 1.0, SU: -1.0, SS: -1.0}, fx2[1])  # fx^2 <= focal_hi^2
    le({W11: -1.0, SU: 1.0, SS: 1.0}, -fx2[0])
    le({W22: 1.0, SV: -1.0}, fy2[1])
    le({W22: -1.0, SV: 1.0}, -fy2[0])
    # fy^2 >= a_lo^2 fx^2 and fy^2 <= a_hi^2 fx^2 (fx^2 > 0 on the domain)
    le({W22: -1.0, SV: 1.0, W11: a2[0], SU: -a2[0], SS: -a2[0]}, 0.0)
    le({W22: 1.0, SV: -1.0, W11: -a2[1], SU: a2[1], SS: a2[1]}, 0.0)

    def row(coeffs: dict) -> np.ndarray:
        out = np.zeros(first + 4)
        for i, c in coeffs.items():
            out[i] += c
        return out

    cones = []
    for var, x in ((SU, U), (SV, V)):  # (s + 1, s - 1, 2 x): 4 s >= 4 x^2
        cones.append([(row({var: -1.0}), 1.0), (row({var: -1.0}), -1.0), (row({x: -2.0}), 0.0)])
    # (ss + y, ss - y, 2 t), y = w22 - sv, t = w12 - puv: 4 ss y >= 4 t^2
    cones.append([(row({SS: -1.0, W22: -1.0, SV: 1.0}), 0.0), (row({SS: -1.0, W22: 1.0, SV: -1.0}), 0.0),
                  (row({W12: -2.0, PUV: 2.0}), 0.0)])
    return cones, [su[0], sv[0], puv[0], ss[0]], [su[1], sv[1], puv[1], ss[1]]


def omega_box(ranges: dict) -> tuple[np.ndarray, np.ndarray]:
    """The box of w from ranges of the (preconditioned) intrinsics by interval arithmetic:
    omega = [[fx^2 + s^2 + u^2, s fy + u v, u], [., fy^2 + v^2, v], [., ., 1]], fy = aspect fx."""
    f, aspect, s, u, v = (np.array(ranges[k], dtype=float) for k in ("focal", "aspect", "skew", "u", "v"))
    fy = _mul(f, aspect)
    w11 = _add(_add(_sq(f), _sq(s)), _sq(u))
    w12 = _add(_mul(s, fy), _mul(u, v))
    w22 = _add(_sq(fy), _sq(v))
    lo = np.array([w11[0], w12[0], u[0], w22[0], v[0]])
    hi = np.array([w11[1], w12[1], u[1], w22[1], v[1]])
    pad = WIDEN * np.maximum(np.abs(lo), np.abs(hi)) + 1e-300
    return lo - pad, hi + pad


def q_range(H: np.ndarray, ranges: dict) -> tuple[float, float]:
    """q = h3' K K^T h3 = |K^T h3|^2 over the ranges: K^T h = (fx h1, s h1 + fy h2, u h1 + v h2 + h3)."""
    f, aspect, s, u, v = (np.array(ranges[k], dtype=float) for k in ("focal", "aspect", "skew", "u", "v"))
    h = H[2]
    fy = _mul(f, aspect)
    c1 = _scale(f, h[0])
    c2 = _add(_scale(s, h[0]), _scale(fy, h[1]))
    c3 = _add(_add(_scale(u, h[0]), _scale(v, h[1])), np.array([h[2], h[2]]))
    total = _add(_add(_sq(c1), _sq(c2)), _sq(c3))
    return total[0] * (1 - 1e-12), total[1] * (1 + 1e-12)


def _mul(a, b):
    c = [a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1]]
    return np.array([min(c), max(c)])


def _add(a, b):
    return np.array([a[0] + b[0], a[1] + b[1]])


def _scale(a, x):
    return np.array(sorted([a[0] * x, a[1] * x]))


def _sq(a):
    if a[0] <= 0 <= a[1]:
        return np.array([0.0, max(a[0] ** 2, a[1] ** 2)])
    return np.array(sorted([a[0] ** 2, a[1] ** 2]))


def homographies(cameras: np.ndarray, reference: int, p: np.ndarray) -> np.ndarray:
    views = [i for i in range(len(cameras)) if i != reference]
    return np.array([cameras[i, :, :3] - np.outer(cameras[i, :, 3], p) for i in views])


def setup_for(cameras: np.ndarray, reference: int, p: np.ndarray, ranges: dict) -> MetricSetup:
    H = homographies(cameras, reference, p)
    bounds = np.array([q_range(h, ranges) for h in H])
    return MetricSetup(H, bounds[:, 0], bounds[:, 1], ranges)


def linear_baseline(setup: MetricSetup) -> tuple[np.ndarray, bool]:
    """The thesis's linear method (6.30, 6.31): each H normalised by det^(1/3), then
    omega - H omega H^T = 0 in least squares with omega33 = 1; the PSD flag says whether the
    answer is a DIAC at all (it is clipped to the nearest PSD matrix when not)."""
    rows, rhs = [], []
    basis = sym_basis()
    for H in setup.H:
        Hn = H / np.cbrt(np.linalg.det(H))
        images = np.einsum("ka,iab,lb->ikl", Hn, basis, Hn)
        for e, (a, b) in enumerate(ALL):
            coeffs = basis[:, a, b] - images[:, a, b]
            rows.append(WEIGHTS[e] * coeffs[:5])
            rhs.append(-WEIGHTS[e] * coeffs[5])
    w, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
    omega = omega_of(w)
    values, vectors = np.linalg.eigh(omega)
    psd = bool(values[0] >= 0)
    if not psd:
        omega = (vectors * np.maximum(values, 1e-12)) @ vectors.T
        omega = omega / omega[2, 2]
        w = np.array([omega[a, b] for a, b in ENTRIES])
    return w, psd
