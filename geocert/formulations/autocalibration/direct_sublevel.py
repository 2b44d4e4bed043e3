"""A proven interval of the direct method's focal length (fixed focal), or of each view's
(varying_focal: the section at the end), numpy only: the solver writes the proof
(direct_solve.prove_focal, prove_focal_lengths) and the verifier checks it with these functions.

The quantity, for Q (program frame, trace 1) and the program's cameras P_i (direct.DirectSetup):

    focal(Q) = f0 sqrt(r(Q)),   r(Q) = sum_i (w_i11 + w_i22) / (2 sum_i w_i33),   w_i = P_i Q P_i'

a weighted mean (weights w_i33 > 0) of the views' (w11 + w22) / (2 w33), preconditioned: for a
view of K (pixels) it is ((f_x^2 + f_y^2 + skew^2 + (u - u0)^2 + (v - v0)^2) / 2) / f0^2, the
combination the focal rows hold, so focal = f when the skew is 0, the aspect 1 and the principal
point the ranges' middle (u0, v0); f0 the preconditioner's focal length.

The set: every Q of the direct stage's scope (direct_relaxation's program, each orientation not
excluded) whose cost (7.12) is at most U = proofs.sublevel_level(cost, cost_increase). r >= c on it
when min tr((A - c B) Q) >= 0 over it (A = sum_i (p_i0 p_i0' + p_i1 p_i1') / 2, B = sum_i p_i2
p_i2'), bounded below by the order-2 relaxation of that program with the cost row U - f >= 0 and
its localizing matrix (over the monomials of degree <= 1: without it the bound was far looser,
measured); a dual vector z of it gives a safe bound s (direct_relaxation.safe_bound, not floored at
0) with tr((A - c B) Q) >= s. Since tr(B Q) <= BMAX = sum_i |p_i2|^2 on the set (Q PSD of trace
1), s > 0 proves r >= c + s / BMAX; the upper end likewise from -(A - c B): r <= c - s / BMAX.
Any c and any z give a true statement; a z with s <= 0 proves nothing and is refused. An end
stated null is the scope's (the focal rows'): nothing more is claimed for it.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from geocert.formulations.autocalibration import direct_relaxation
from geocert.core.cones import ConeSpec

NAME = "focal"
_SIDE = len(direct_relaxation.monomials(1))
EXTRA_ROWS = 1 + _SIDE * (_SIDE + 1) // 2  # the cost row, its localizing matrix (svec)


def _of(cameras: np.ndarray, view: int | None) -> np.ndarray:
    """The views the quantity is of: all (one focal length), or view ``view`` alone (its own)."""
    return cameras if view is None else cameras[view:view + 1]


def forms(cameras: np.ndarray, view: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(A, B): r(Q) = tr(A Q) / tr(B Q), over every view or over view ``view`` only."""
    cameras = _of(cameras, view)
    A = sum(np.outer(P[0], P[0]) + np.outer(P[1], P[1]) for P in cameras) / 2.0
    B = sum(np.outer(P[2], P[2]) for P in cameras)
    return A, B


def ratio(cameras: np.ndarray, Q: np.ndarray, view: int | None = None) -> float:
    A, B = forms(cameras, view)
    return float(np.sum(A * Q) / np.sum(B * Q))


def largest_weight(cameras: np.ndarray, view: int | None = None) -> float:
    """BMAX: tr(B Q) = sum_i p_i2' Q p_i2 <= sum_i |p_i2|^2 for Q PSD of trace 1, rounded up."""
    return float(np.sum(_of(cameras, view)[:, 2, :] ** 2)) * (1.0 + 1e-12)


def scope_range(unit_ranges: dict) -> tuple[float, float]:
    """r's range over the scope: every view's (w11 + w22) / w33 lies within the focal rows' [low,
    high] (direct.focal_rows), so their weighted mean's half does too."""
    r = unit_ranges
    low = (1.0 + r["aspect"][0] ** 2) * r["focal"][0] ** 2
    high = ((1.0 + r["aspect"][1] ** 2) * r["focal"][1] ** 2 + max(abs(v) for v in r["skew"]) ** 2
            + max(abs(v) for v in r["u"]) ** 2 + max(abs(v) for v in r["v"]) ** 2)
    return low / 2.0, high / 2.0


def program(cameras: np.ndarray, pairs, focal, S: np.ndarray, level: float) -> direct_relaxation.Program:
    """The order-2 relaxation of min tr(S Q) over the orientation's program (its pairs, the focal
    rows) with f <= level: the cost row (a nonnegative row) and its localizing matrix over the
    monomials of degree <= 1 (a PSD block before the moment matrix, which stays last)."""
    return polynomial_program(cameras, pairs, focal, direct_relaxation.trace_polynomial(S), level)


def polynomial_program(cameras: np.ndarray, pairs, focal, p: dict, level: float) -> direct_relaxation.Program:
    """program's relaxation with the objective a polynomial p in Q's centred entries (degree <= 4,
    the order-2 moments'; direct_relaxation's dict form)."""
    base = direct_relaxation.build(cameras, pairs, 2, (), focal)
    zero = tuple([0] * direct_relaxation.N)
    q = np.zeros(len(base.q))
    exps, coefs = direct_relaxation.poly({e: c for e, c in p.items() if e != zero})
    if len(coefs):
        np.add.at(q, base.moments.index(exps) - 1, coefs)  # y excludes y_0 (graded basis: y_0 first)
    cones = base.cones
    at = cones.zero + cones.nonneg
    exps, coefs = direct_relaxation.poly(direct_relaxation.objective(cameras))
    # (level - f) / level: the row and its block of order 1, not of the level's (measured: Table 7.1's seed 3, the
    # lower end's interior-point iterates, stalled either way, then led Dinkelbach's c to 0.945 steadily, not
    # between 0.87 and 0.91)
    scale = 1.0 / float(level) if level > 0 else 1.0
    slack = {tuple(int(v) for v in e): -float(c) * scale for e, c in zip(exps, coefs)}
    slack[zero] = slack.get(zero, 0.0) + float(level) * scale
    block, size = direct_relaxation.localizing(base.moments, [[slack]], 1)
    C = block.tocsc()
    m_size = cones.psd[-1]
    m_rows = m_size * (m_size + 1) // 2
    A = sp.vstack([base.A[:at], sp.csr_matrix(scale * base.q[None, :]), base.A[at:-m_rows], sp.csc_matrix(-C[:, 1:]),
                   base.A[-m_rows:]]).tocsc()
    b = np.concatenate([base.b[:at], [scale * (level - base.constant)], base.b[at:-m_rows],
                        np.asarray(C[:, 0].todense()).ravel(), base.b[-m_rows:]])
    spec = ConeSpec(cones.zero, cones.nonneg + 1, cones.soc, cones.psd[:-1] + (size, m_size))
    return direct_relaxation.Program(q, float(p.get(zero, 0.0)), A, b, spec, base.lower, base.upper, base.moments)


def side_program(cameras: np.ndarray, pairs, focal, c: float, sign: float, level: float,
                 view: int | None = None) -> direct_relaxation.Program:
    """sign +1: min tr((A - c B) Q) (r's lower end); -1: min tr((c B - A) Q) (its upper end). The
    program is over every view's cost and rows; A and B are view ``view``'s alone when given."""
    A, B = forms(cameras, view)
    return program(cameras, pairs, focal, sign * (A - c * B), level)


def end(cameras: np.ndarray, c: float, sign: float, safe: float, view: int | None = None) -> float | None:
    """What a safe bound ``safe`` at ``c`` proves of r (view ``view``'s when given): its lower end
    (sign +1) or upper (-1); None when it proves nothing (safe not above 0)."""
    if not (safe > 0 and math.isfinite(safe) and math.isfinite(c)):
        return None
    step = safe / largest_weight(cameras, view)
    value = c + sign * step
    return value - sign * 4.0 * 2.0 ** -52 * (abs(c) + step)  # the sum's rounding, outward


def pixels(f0: float, r_lo: float, r_hi: float, scope: tuple[float, float]) -> tuple[float, float]:
    """focal = f0 sqrt(r) over [r_lo, r_hi] clipped to the scope's range, rounded outward."""
    lo, hi = max(r_lo, scope[0]), min(r_hi, scope[1])
    lower = f0 * math.sqrt(max(lo, 0.0)) * (1.0 - 1e-12)
    upper = f0 * math.sqrt(max(hi, 0.0)) * (1.0 + 1e-12)
    return lower, upper


def focal_of(cameras: np.ndarray, Q: np.ndarray, f0: float, view: int | None = None) -> float:
    return f0 * math.sqrt(max(ratio(cameras, Q / np.trace(Q), view), 0.0))


LEVEL = ("every absolute dual quadric of the direct stage's scope whose cost (7.12) exceeds the certified one's by at "
         "most cost_increase has its focal length within this interval; the focal length of Q is f0 times the root "
         "of sum_i (w_i11 + w_i22) / (2 sum_i w_i33), w_i = P_i Q P_i' in the program's frame (preconditioned by K0, "
         "f0 its focal length): the root of the views' mean (weighted by w_i33) of (f_x^2 + f_y^2 + skew^2 + (u - "
         "u0)^2 + (v - v0)^2) / 2, the focal length when skew is 0, aspect 1 and the principal point the ranges' "
         "middle (pixels); clipped to what the focal rows allow")


def cost_increase(cost: float, lower_bound: float, views: int) -> float:
    """The level the kind proves the interval at: SIGMAS^2 times (7.12)'s residual variance, cost
    over its 4 residuals a view less Q's 8 degrees of freedom, never below the certified gap
    (core.determinacy.cost_increase, the estimates' rule); the verifier asks no lower a level."""
    from geocert.core.determinacy import cost_increase as rule

    return rule(cost, max(4 * views - 8, 1), cost - lower_bound)


def proven_document(sublevel: dict) -> dict:
    """The proven intervals a direct stage's determinacy states from its proof's ``sublevel``."""
    from geocert.core.determinacy import proven_document as document

    return document(sublevel["cost_increase"], (NAME,), [sublevel["interval"]], LEVEL)


def _level(sublevel) -> float:
    """proof/sublevel's cost_increase, checked (the level is sublevel_level of the cost and it)."""
    from geocert.formulations.autocalibration.proofs import LARGEST_INCREASE, SMALLEST_INCREASE
    from geocert.core.strict import Invalid, is_number

    increase = sublevel.get("cost_increase")
    if not (is_number(increase) and (increase == 0 or SMALLEST_INCREASE <= increase <= LARGEST_INCREASE)):
        raise Invalid("proven_interval", "proof/sublevel/cost_increase must be 0 or within 2^-128 .. 2^128")
    return float(increase)


def _ends(setup, holder: dict, where: str, live: list, level: float, view: int | None, build=None,
          proves=None) -> dict:
    """r's ends (view ``view``'s, or the views' mean's; another ratio's with ``build(pairs, c,
    sign)`` its program and ``proves(c, sign, safe)`` what a safe bound proves, direct_intrinsics')
    that ``holder``'s "lower" and "upper" entries prove: one {delta, c, z} an orientation in
    ``live`` a side, each safe bound above 0; an end stated null is not proven (-inf or inf here;
    pixels clips the focal length's to the scope)."""
    from geocert.formulations.autocalibration import direct
    from geocert.core.strict import Invalid, charge, dual_vector, is_number, record

    if build is None:
        def build(pairs, c, sign):
            return side_program(setup.cameras, pairs, setup.focal, c, sign, level, view)

        def proves(c, sign, safe):
            return end(setup.cameras, c, sign, safe, view)

    ends = {"lower": -math.inf, "upper": math.inf}
    for side, sign in (("lower", 1.0), ("upper", -1.0)):
        entries = holder.get(side)
        if entries is None:  # this end is the scope's (pixels clips to it)
            continue
        if not (isinstance(entries, list) and len(entries) == len(live)):
            raise Invalid("format", f"{where}/{side} holds one entry for each orientation left to bound "
                                    f"({len(live)})")
        found = []
        for o in live:
            match = [e for e in entries if isinstance(e, dict) and direct._of_orientation(e.get("delta"), o.delta)]
            if len(match) != 1:
                raise Invalid("format", f"{where}/{side}: orientation {o.delta!r} needs exactly one entry")
            entry = record(match[0], f"{where}/{side}", ("delta", "c", "z"))
            c = entry.get("c")
            if not is_number(c):
                raise Invalid("format", f"{where}/{side}/c must be a finite number")
            rows = direct._rows_without_pairs(setup, 2, 0) + EXTRA_ROWS + (0 if o.pairs is None else len(o.pairs))
            charge(rows, f"the {side} interval program of orientation {o.delta!r}")
            dual_vector(entry.get("z"), rows, f"{where}/{side}/z", "proven_interval")
            built = build(o.pairs, float(c), sign)
            z = dual_vector(entry.get("z"), len(built.b), f"{where}/{side}/z", "proven_interval")
            safe, _ = direct_relaxation.safe_bound(built, z, -math.inf)
            value = proves(float(c), sign, safe)
            if value is None:
                raise Invalid("proven_interval", f"{where}/{side}: the dual's safe bound at c = {c!r} is "
                                                 f"{safe!r}, not above 0: it proves no {side} end")
            found.append(value)
        ends[side] = min(found) if sign > 0 else max(found)
    return ends


def _stated_holds(holder: dict, where: str, lo: float, hi: float) -> None:
    """The interval ``holder`` states holds [lo, hi] (a wider one is a weaker true statement)."""
    from geocert.core.strict import Invalid, numbers

    stated = numbers(holder.get("interval"), f"{where}/interval", (2,))
    if not (stated[0] <= lo and hi <= stated[1]):
        raise Invalid("proven_interval", f"{where}/interval {stated.tolist()} is narrower than what its "
                                         f"programs prove ([{lo!r}, {hi!r}])")


def check(setup, sublevel, gone: tuple, cost: float) -> tuple[float, float]:
    """What a direct proof's ``sublevel`` proves (the module docstring): (lower, upper) in pixels
    of the focal length of every Q in the scope (setup built with exclude=False; ``gone`` the
    orientations the proof excludes) costing at most sublevel_level(cost, cost_increase). Each
    orientation left has one entry a side, {delta, c, z}, whose safe bound must be above 0; the
    stated interval must hold what they prove (a wider one is a weaker true statement, a
    narrower one is refused). Returns the interval proven."""
    from geocert.formulations.autocalibration.proofs import sublevel_level
    from geocert.core.strict import record

    record(sublevel, "proof/sublevel", ("cost_increase", "lower", "upper", "interval"), ("intrinsics",))
    level = sublevel_level(cost, _level(sublevel))
    live = [o for o in setup.orientations if o.delta not in gone]
    ends = _ends(setup, sublevel, "proof/sublevel", live, level, None)
    lo, hi = pixels(float(setup.problem.K0[0, 0]), ends["lower"], ends["upper"],
                    scope_range(setup.problem.unit_ranges))
    _stated_holds(sublevel, "proof/sublevel", lo, hi)
    return lo, hi  # its "intrinsics", when carried: direct_intrinsics.check


# --- one focal length a view (varying_focal) ---------------------------------------------------
#
# The same proof, view by view: focal_i(Q) = f0 sqrt(r_i(Q)), r_i = (w_i11 + w_i22) / (2 w_i33), is
# the ratio tr(A_i Q) / tr(B_i Q) of view i's forms alone (forms(cameras, i)), over the same set (the
# program's cost row and rows are every view's), with BMAX_i = |p_i2|^2; its range over the scope is
# the focal rows' (scope_range), as each view's (w11 + w22) / w33 lies within them. The proof's
# ``sublevel`` is {cost_increase, views: [{lower, upper, interval}, one a view, in order]}, each
# view's ends as the one focal length's (null: the scope's).

VIEW_NAME = "focal[{}]"  # estimates.check_focal_lengths' names, the same quantities' estimates

VIEWS_LEVEL = ("every absolute dual quadric of the direct stage's scope whose cost (7.12) exceeds the certified one's "
               "by at most cost_increase has view k's focal length within focal[k]; view k's focal length of Q is f0 "
               "times the root of (w_11 + w_22) / (2 w_33), w = P_k Q P_k' in the program's frame (preconditioned by "
               "K0, f0 its focal length): the root of (f_x^2 + f_y^2 + skew^2 + (u - u0)^2 + (v - v0)^2) / 2, the "
               "focal length when skew is 0, aspect 1 and the principal point the ranges' middle (pixels); clipped "
               "to what the focal rows allow")


def proven_views_document(sublevel: dict) -> dict:
    """The proven intervals a varying-focal direct stage's determinacy states from its proof's
    ``sublevel``: focal[0] .. focal[m-1]."""
    from geocert.core.determinacy import proven_document as document

    views = sublevel["views"]
    return document(sublevel["cost_increase"], tuple(VIEW_NAME.format(k) for k in range(len(views))),
                    [view["interval"] for view in views], VIEWS_LEVEL)


def check_views(setup, sublevel, gone: tuple, cost: float) -> list[tuple[float, float]]:
    """What a varying-focal direct proof's ``sublevel`` proves: each view's (lower, upper) focal
    length in pixels over every Q of the scope (as check's) costing at most sublevel_level(cost,
    cost_increase). One entry a view, in order, each {lower, upper, interval} as check's one
    focal length's; every view's stated interval must hold what its programs prove."""
    from geocert.formulations.autocalibration.proofs import sublevel_level
    from geocert.core.strict import Invalid, record

    record(sublevel, "proof/sublevel", ("cost_increase", "views"))
    level = sublevel_level(cost, _level(sublevel))
    views = sublevel.get("views")
    if not (isinstance(views, list) and len(views) == len(setup.cameras)):
        raise Invalid("format", f"proof/sublevel/views holds one entry a view ({len(setup.cameras)}), in order")
    live = [o for o in setup.orientations if o.delta not in gone]
    f0, scope = float(setup.problem.K0[0, 0]), scope_range(setup.problem.unit_ranges)
    out = []
    for k, holder in enumerate(views):
        where = f"proof/sublevel/views/{k}"
        holder = record(holder, where, ("lower", "upper", "interval"))
        ends = _ends(setup, holder, where, live, level, k)
        lo, hi = pixels(f0, ends["lower"], ends["upper"], scope)
        _stated_holds(holder, where, lo, hi)
        out.append((lo, hi))
    return out
