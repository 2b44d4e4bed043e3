"""Proven intervals of an L1-norm resection's camera centre (L1L1, L2L1): every camera of the scope
(every point at positive depth) costing at most the returned camera P0's cost plus
``cost_increase`` has its centre within them. Stated beside the depth row read off the leaves
(fractional.resection_leaves: ``proof.sublevel.centre``), at the same level. Numpy only for the
check (the solver's conic programs, which only find the multipliers, go through core.conic).

The leaves bound the branched last row only; the centre needs all 11 of a camera's unknowns. It
is bounded as an L2L2 resection's (fractional.resection_sublevel: the slice, the whitened
coordinates phi, (1) the enclosure, (2) the rounds, (3) the centre over the ball) with the L1
cost's own inequalities, and a dual bound of the centre's linear term:

(1) Every camera costing at most U = c + delta (c: P0's L1 cost, at least the optimum) has every
    residual's length at most U (a point's pixel distance, or its coordinates' absolute sum, is
    at most the sum over the points): the enclosure at rho = U.
(2) With every such camera inside |phi| <= r, depths at most hi_j, and y_j = n_j(theta) / hi_j
    (|y_j| <= |r_j|, and |y_j| <= b_j = (|n_j| + r |C_j|) / hi_j over the ball):
    sum_j |y_j|^2 / min(b_j, U) <= sum_j |y_j| <= U, a quadratic as the L2L2 rounds'.
    This loses the L1 cost's kink (|y|^2 / b touches |y| only at |y| = b): r comes out several
    times the sublevel set's extent, so it serves only the second-order remainder of (3).
(3) The centre's first-order terms l_k . theta (resection_sublevel.centre_bounds), and the 9
    entries of Z dA its remainder reads, are bounded over the proven set by weak duality rather
    than by r |T' row|: the set is inside the convex one
    {sum_j s_j |n_j + C_j phi|_* <= U, |phi| <= r}, s_j = 1 / hi_j (rounded down) and |.|_* the
    point's norm (2-norm under L2L1, 1-norm under L1L1). For any mu >= 0 and y_j with dual norm
    at most 1 (2-norm, respectively largest entry), v = sum_j s_j C_j' y_j and e = T' l - mu v:
        l . theta = mu v . phi + e . phi <= mu (U - sum_j s_j y_j . n_j) + |e| r.
    The solver finds mu and y by a conic program (its multipliers: clarabel) per side of each
    functional (24 of them) and states them; the checker recomputes the bound from them, counting
    the data's errors (eps_n, err_C) and the products' round-off, and takes the smaller of it and
    the ball's. Any multipliers give a true bound: stating other ones can only widen it.

The checker recomputes (1) at the stated radius, the stated rounds, and (3) with the stated
multipliers; the stated intervals must hold its bounds (a narrower interval is not proven; a
wider one is a weaker truth and passes, as the depth row's beside them). O(k) a round, and 24
passes over the points for the multipliers (12 functionals of theta: the centre's 3 first-order
terms and the 9 entries of Z dA that its remainder reads, each side).
"""

from __future__ import annotations

import math

import numpy as np

from geocert.core.strict import Invalid, number, numbers, record
from geocert.formulations.fractional.convexity import LARGEST, SMALLEST, UNDERFLOW
from geocert.formulations.fractional.fixed_order import mul, norm, weighted
from geocert.formulations.fractional.resection_sublevel import (STATED_SLACK, U, Scene, centre_bounds, check_enclosure,
                                                           enclosed_radius, proven_centre)

NAMES = ("centre_x", "centre_y", "centre_z")
NORMS = ("L1L1", "L2L1")
ROWS = 12  # the linear functionals of theta centre_bounds bounds: l's 3, then vec(Z dA)'s 9
Y_SHRINK = 1e-9  # the solver states its multipliers this much inside the unit ball (their norm's rounding)


def _up(x: float) -> float:
    return x * (1 + 8 * U) if x > 0 else x * (1 - 8 * U)


def _weights(scene: Scene, r: float) -> np.ndarray:
    """s_j <= 1 / w_j(theta) over |phi| <= r: the reciprocal of the depth's bound, rounded down."""
    hi = (scene.w_hi + r * scene.g_up) * (1 + 4 * U)
    return 1 / hi * (1 - 8 * U)


def dual_reach(scene: Scene, increase: float, r: float, row: np.ndarray, row_err: float, mu: float,
               y: np.ndarray) -> float:
    """An upper bound of row . theta over the cameras costing at most U within |phi| <= r, from the
    multipliers (mu, y) ((3) of the module's docstring); inf when they are not usable (a mu not
    finite and >= 0, a y of the wrong shape or dual norm above 1)."""
    k = scene.k
    if not (isinstance(mu, float) and math.isfinite(mu) and 0 <= mu <= LARGEST and y.shape == (k, 2)
            and np.all(np.isfinite(y))):
        return math.inf
    y_len = np.sqrt((y * y).sum(axis=1)) * (1 + 4 * U)  # 2-norms, from above
    if scene.norm == "L2L1":
        if not np.all(y_len <= 1):
            return math.inf
    elif not np.all(np.abs(y) <= 1):  # L1L1: |n|_1 >= y . n for |y| <= 1 entrywise
        return math.inf
    T, T_F, C, n = scene.T, scene.T_F, scene.C, scene.n
    with np.errstate(all="ignore"):
        s = _weights(scene, r)
        # in a fixed order (fixed_order): one bound on every machine, whatever its BLAS kernel
        lT = mul(row, T)
        lT_err = (16 * U * T_F * norm(row) + T_F * row_err) * (1 + 4 * U)
        v = weighted(C, y, s)
        C_F = np.sqrt((C * C).sum(axis=(1, 2)))
        # each entry of v sums 2k products of three factors; sum_(a, i) |C_jai y_ja| <= sqrt(11) |C_j|_F |y_j|
        v_err = (4 * (2 * k + 16) * U * float((s * C_F * y_len).sum()) + float((s * y_len * scene.err_C).sum())
                 + k * 64 * UNDERFLOW) * (1 + 8 * U)
        e = lT - mu * v
        e_size = norm(lT) + mu * norm(v)
        e_up = (norm(e) * (1 + 8 * U) + lT_err + mu * v_err * (1 + 4 * U) + 16 * U * e_size
                + 64 * UNDERFLOW) * (1 + 8 * U)
        yn = float(((y * n) * s[:, None]).sum())
        n_len = np.sqrt((n * n).sum(axis=1))
        yn_err = ((2 * k + 16) * U * float((s * y_len * n_len).sum()) + float((s * y_len * scene.eps_n).sum())
                  + k * 64 * UNDERFLOW) * (1 + 8 * U)
        room = _up(_up(scene.level(increase) - yn) + yn_err + 8 * U * (scene.level(increase) + abs(yn)))
        bound = _up(_up(mu * room) + e_up * r * (1 + 4 * U))
    return bound if math.isfinite(bound) else math.inf


def _duals(centre, k: int) -> list:
    """The stated multipliers: ROWS x 2 of (mu, y (k x 2)) or None (that side bounded by the ball)."""
    duals = centre.get("duals")
    if not (isinstance(duals, list) and len(duals) == ROWS
            and all(isinstance(d, list) and len(d) == 2 for d in duals)):
        raise Invalid("format", f"proof/sublevel/centre/duals must be {ROWS} pairs (each functional's two sides: the "
                                "centre's 3 first-order terms, then the 9 entries of Z dA)")
    out = []
    for i, pair in enumerate(duals):
        sides = []
        for j, side in enumerate(pair):
            where = f"proof/sublevel/centre/duals/{i}/{j}"
            if side is None:
                sides.append(None)
                continue
            record(side, where, ("mu", "y"))
            sides.append((number(side.get("mu"), f"{where}/mu"), numbers(side.get("y"), f"{where}/y", (k, 2))))
        out.append(sides)
    return out


def bounds_with(scene: Scene, increase: float, r: float, duals: list) -> np.ndarray | None:
    """(3) over |phi| <= r with the multipliers ``duals`` (ROWS x 2 of (mu, y) or None)."""

    def reach(l: np.ndarray, l_err: np.ndarray):
        plus, minus = np.full(ROWS, np.inf), np.full(ROWS, np.inf)
        for i in range(ROWS):
            if duals[i][0] is not None:  # max of l_i . theta (for a centre row: its lower side)
                plus[i] = dual_reach(scene, increase, r, l[i], float(l_err[i]), *duals[i][0])
            if duals[i][1] is not None:  # max of -l_i . theta
                minus[i] = dual_reach(scene, increase, r, -l[i], float(l_err[i]), *duals[i][1])
        return plus, minus

    return centre_bounds(scene, r, reach)


def _rows(scene: Scene) -> np.ndarray | None:
    """The ROWS functionals centre_bounds bounds (ROWS x 11), as it computes them."""
    found = []

    def capture(l, l_err):
        found.append(np.array(l))
        return np.full(ROWS, np.inf), np.full(ROWS, np.inf)

    centre_bounds(scene, 0.0, capture)
    return found[0] if found else None


def _multipliers(scene: Scene, increase: float, r: float, direction: np.ndarray) -> tuple[float, np.ndarray] | None:
    """(mu, y) for max direction . theta over the convex set of (3): the multipliers of its conic
    program (solved once; an inexact answer serves, since the check recomputes the bound from
    whatever multipliers are stated); None when it does not solve."""
    from geocert.core.cones import ConeSpec
    from geocert.core.conic import SolveSettings, solve_once

    k, norm = scene.k, scene.norm
    s = _weights(scene, r)
    d = scene.T.T @ direction
    a = scene.n * s[:, None]  # (k, 2)
    M = scene.C * s[:, None, None]  # (k, 2, 11)
    parts = k if norm == "L2L1" else 2 * k  # one t per point (a 3-cone) or per coordinate (a 2-cone)
    size = 11 + parts
    rows, b, cones = [], [], []  # cones: the second-order cones' sizes, after one nonnegative row
    first = np.zeros(size)
    first[11:] = 1.0
    rows.append(first)
    b.append(scene.level(increase))
    for j in range(k):
        groups = ((0, 1),) if norm == "L2L1" else ((0,), (1,))
        for g, coordinates in enumerate(groups):
            t = np.zeros(size)
            t[11 + (j if norm == "L2L1" else 2 * j + g)] = -1.0
            rows.append(t)
            b.append(0.0)
            for m in coordinates:
                line = np.zeros(size)
                line[:11] = -M[j, m]
                rows.append(line)
                b.append(a[j, m])
            cones.append(1 + len(coordinates))
    ball = np.zeros((12, size))
    ball[1:, :11] = -np.eye(11)
    rows.extend(ball)
    b.extend([r] + [0.0] * 11)
    cones.append(12)
    q = np.zeros(size)
    q[:11] = -d
    solution = solve_once(q, np.array(rows), np.array(b), ConeSpec(nonneg=1, soc=tuple(cones)), SolveSettings(gap=1e-10))
    # an almost-solved answer's multipliers serve as well (any multipliers give a true bound)
    if not solution.dual_usable:
        return None
    z = solution.z
    mu = float(z[0])
    if not (math.isfinite(mu) and mu > 0):
        return None
    y = np.zeros((k, 2))
    at = 1
    for j in range(k):
        if norm == "L2L1":
            y[j] = -z[at + 1:at + 3] / mu
            at += 3
        else:
            y[j, 0], y[j, 1] = -z[at + 1] / mu, -z[at + 3] / mu
            at += 4
    if norm == "L2L1":
        length = np.sqrt((y * y).sum(axis=1))
        y = y / np.maximum(length, 1.0)[:, None]
    else:
        y = np.clip(y, -1.0, 1.0)
    return mu, y * (1 - Y_SHRINK)


def l1_centre(source, target, matrix, norm: str, increase: float, reference: int) -> dict | None:
    """The proof/sublevel/centre a solver states beside an L1 resection's leaves (None where none
    is proven): the enclosure's smallest radius (twice its allowances, by bisection), the rounds
    until they shrink r by less than 1%, the multipliers of each side of each coordinate, and the
    intervals a little wider (STATED_SLACK) than its own recomputation's."""
    if norm not in NORMS or not (math.isfinite(increase) and increase >= 0
                                 and (increase == 0 or SMALLEST <= increase <= LARGEST)):
        return None
    scene = Scene(source, target, matrix, reference, norm)
    if not scene.usable:
        return None
    enclosure = enclosed_radius(scene, increase)
    if enclosure is None:
        return None
    radius, r, rounds = enclosure
    l = _rows(scene)
    if l is None:
        return None
    duals = []
    for i in range(ROWS):
        pair = []
        for sign in (1.0, -1.0):
            found = _multipliers(scene, increase, r, sign * l[i])
            pair.append(None if found is None else {"mu": found[0], "y": found[1].tolist()})
        duals.append(pair)
    bounds = bounds_with(scene, increase, r, _duals({"duals": duals}, scene.k))
    if bounds is None:
        return None
    wider = 0.5 * (bounds[:, 1] - bounds[:, 0]) * STATED_SLACK
    stated = np.stack([np.nextafter(bounds[:, 0] - wider, -np.inf), np.nextafter(bounds[:, 1] + wider, np.inf)],
                      axis=-1)
    return {"radius": float(radius), "rounds": rounds, "duals": duals, "intervals": stated.tolist()}


def verify_l1_centre(source: np.ndarray, target: np.ndarray, centre, matrix: np.ndarray, norm: str,
                     increase: float, reference: int) -> None:
    """An L1 resection's proven centre intervals (proof/sublevel/centre): refused unless (1) holds
    at the stated radius, and the stated intervals hold the bounds the stated rounds (2) and
    multipliers (3) prove here (a narrower interval is not proven; a wider one, as the depth row's
    beside it, is a weaker truth and passes)."""
    record(centre, "proof/sublevel/centre", ("radius", "rounds", "duals", "intervals"))
    radius = number(centre.get("radius"), "proof/sublevel/centre/radius")
    intervals = numbers(centre.get("intervals"), "proof/sublevel/centre/intervals", (3, 2))
    rounds = centre.get("rounds")
    if norm not in NORMS:
        raise Invalid("proven_interval", "proof/sublevel/centre is for the L1 norms (L1L1, L2L1)")
    duals = _duals(centre, len(source))
    scene = Scene(source, target, matrix, reference, norm)
    check_enclosure(scene, increase, radius, rounds, "proof/sublevel/centre")
    _, r = proven_centre(scene, increase, radius, rounds)
    bounds = bounds_with(scene, increase, r, duals)
    if bounds is None:
        raise Invalid("proven_interval", "the camera's left 3x3 block is not shown invertible over the proven set: "
                                         "no interval of its centre is proven")
    if not (np.all(intervals[:, 0] <= bounds[:, 0]) and np.all(intervals[:, 1] >= bounds[:, 1])):
        raise Invalid("proven_interval", "proof/sublevel/centre/intervals are narrower than what the proof proves "
                                         f"({bounds.tolist()})")
