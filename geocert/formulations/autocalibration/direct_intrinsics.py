"""Proven intervals of the direct method's other intrinsics (one K): the principal point, the
second focal length, the skew and the aspect ratio, proven as direct_sublevel proves the focal
length, numpy only (the solver writes the proof, direct_solve.prove_intrinsics; the verifier
checks it with check).

The quantities, for Q (program frame, trace 1) and the program's cameras P_i: W = mean_i P_i Q
P_i' (a positive multiple of the w33-weighted mean of the views' normalised DIACs, as in
direct_sublevel), its entries W_ab (0-based), and its 2x2 minors M22 = W11 W22 - W12^2 and M12 =
W01 W22 - W02 W12. For W = K K' up to scale, K = [[f, s, u], [0, a f, v], [0, 0, 1]]
(preconditioned):

    u  = W02 / W22                       v  = W12 / W22
    fy^2 = (a f)^2 = M22 / W22^2         t  = s / (a f) = M12 / M22
    a^2 = M22^2 / (W22 det W)            (f^2 (a f)^2 = det W / W22^3)

each a ratio N(Q) / D(Q) of polynomials of degree at most 4 in Q, D > 0 wherever the ratio is
defined. r >= c on the set (direct_sublevel's: every Q of the scope costing at most U) when N - c D
>= s > 0 there, bounded below by the order-2 relaxation of min (N - c D) with the cost row
(direct_sublevel.polynomial_program); then r >= c + s / DMAX, DMAX >= D on the set (below). The
upper end likewise from c D - N. A proven end also proves the ratio defined on the whole set (its
denominator positive: c D - N >= s > 0 with N >= 0 or, for the lower end, N > 0, which for each
ratio forces D > 0: t's M12 > 0 forces M22 > 0, as M12^2 <= M11 M22 for W PSD; u's and v's W22 >
0 holds on the set, where the focal rows leave no view with w33 = 0 and a nonzero Q).

DMAX: for Q PSD of trace 1, W_kk = mean_i p_ik' Q p_ik <= b_k = mean_i |p_ik|^2, M22 <= W11 W22,
det W <= W00 W11 W22 (Hadamard): W22 <= b2, W22^2 <= b2^2, M22 <= b1 b2, W22 det W <= b0 b1 b2^2.

In pixels (K_pixels = K0 K, K0 = [[f0, 0, u0], [0, f0, v0], [0, 0, 1]]): principal_u = u0 + f0 u,
principal_v = v0 + f0 v, focal_y = f0 sqrt(fy^2), aspect = sqrt(a^2), skew = f0 t fy: its interval
is the hull of the products of t's and fy's proven ends (fy > 0), unbounded on a side where one of
them is. An end no dual proves is stated null, with the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from geocert.formulations.autocalibration import direct_relaxation, direct_sublevel

RATIOS = ("u", "v", "fy2", "t", "a2")  # what the duals prove, each a ratio N / D
NAMES = ("principal_u", "principal_v", "focal_y", "skew", "aspect")  # what the intervals state, in order
SAFETY = 1.0 + 1e-12  # DMAX rounded up


@dataclass
class Ratio:
    numerator: dict  # polynomials in Q's centred entries (direct_relaxation's dict form)
    denominator: dict
    dmax: float

    def at(self, Q: np.ndarray) -> float:
        x = direct_relaxation.x_of(Q)
        d = direct_relaxation.evaluate(direct_relaxation.poly(self.denominator), x)
        return direct_relaxation.evaluate(direct_relaxation.poly(self.numerator), x) / d if d > 0 else math.nan

    def objective(self, c: float, sign: float) -> dict:
        """sign (N - c D): its minimum over the set above 0 proves r's lower end (sign +1) or upper."""
        return {e: sign * v for e, v in direct_relaxation._add(self.numerator, self.denominator, -float(c)).items()}

    def end(self, c: float, sign: float, safe: float) -> float | None:
        if not (safe > 0 and math.isfinite(safe) and math.isfinite(c)):
            return None
        step = safe / self.dmax
        value = c + sign * step
        return value - sign * 4.0 * 2.0 ** -52 * (abs(c) + step)  # the sum's rounding, outward


def ratios(cameras: np.ndarray) -> dict[str, Ratio]:
    """The five ratios of the module docstring for the program's cameras."""
    m = len(cameras)
    mul, add = direct_relaxation._mul, direct_relaxation._add
    W = [[direct_relaxation.trace_polynomial(
        sum(np.outer(P[a], P[b]) + np.outer(P[b], P[a]) for P in cameras) / (2.0 * m)) for b in range(3)]
        for a in range(3)]
    b = [float(np.sum(cameras[:, k, :] ** 2)) / m * SAFETY for k in range(3)]
    m22 = add(mul(W[1][1], W[2][2]), mul(W[1][2], W[1][2]), -1.0)
    m12 = add(mul(W[0][1], W[2][2]), mul(W[0][2], W[1][2]), -1.0)
    det = {}
    for (i, j, k), sign in (((0, 1, 2), 1.0), ((1, 2, 0), 1.0), ((2, 0, 1), 1.0),
                            ((0, 2, 1), -1.0), ((1, 0, 2), -1.0), ((2, 1, 0), -1.0)):
        det = add(det, mul(mul(W[0][i], W[1][j]), W[2][k]), sign)
    return {"u": Ratio(W[0][2], W[2][2], b[2]), "v": Ratio(W[1][2], W[2][2], b[2]),
            "fy2": Ratio(m22, mul(W[2][2], W[2][2]), b[2] ** 2 * SAFETY),
            "t": Ratio(m12, m22, b[1] * b[2] * SAFETY),
            "a2": Ratio(mul(m22, m22), mul(W[2][2], det), b[0] * b[1] * b[2] ** 2 * SAFETY ** 3)}


def side_program(cameras: np.ndarray, pairs, focal, ratio: Ratio, c: float, sign: float, level: float
                 ) -> direct_relaxation.Program:
    return direct_sublevel.polynomial_program(cameras, pairs, focal, ratio.objective(c, sign), level)


def _root(x: float) -> float:
    return math.sqrt(max(x, 0.0))


def pixels(ends: dict, K0: np.ndarray) -> dict[str, list]:
    """Each stated name's [lower, upper] in pixels (None: not proven) from the ratios' proven
    ends ({ratio: (lower or -inf, upper or inf)}), rounded outward."""
    f0, u0, v0 = float(K0[0, 0]), float(K0[0, 2]), float(K0[1, 2])
    out = {}

    def finite(x):
        return x if math.isfinite(x) else None

    lo, hi = ends["u"]
    out["principal_u"] = [finite(u0 + f0 * lo), finite(u0 + f0 * hi)]
    lo, hi = ends["v"]
    out["principal_v"] = [finite(v0 + f0 * lo), finite(v0 + f0 * hi)]
    lo, hi = ends["fy2"]
    fy = (_root(lo), math.sqrt(hi) if math.isfinite(hi) and hi >= 0 else math.inf)
    out["focal_y"] = [f0 * fy[0] if fy[0] > 0 else None, finite(f0 * fy[1])]
    t_lo, t_hi = ends["t"]
    # s = t fy with fy in [fy_lo, fy_hi] (fy > 0 on the set): s's least is t_lo fy_hi when t_lo < 0,
    # else t_lo fy_lo; its greatest t_hi fy_hi when t_hi > 0, else t_hi fy_lo
    s_lo = t_lo * (fy[1] if t_lo < 0 else fy[0]) if math.isfinite(t_lo) else -math.inf
    s_hi = t_hi * (fy[1] if t_hi > 0 else fy[0]) if math.isfinite(t_hi) else math.inf
    out["skew"] = [finite(f0 * s_lo) if not math.isnan(s_lo) else None,
                   finite(f0 * s_hi) if not math.isnan(s_hi) else None]
    lo, hi = ends["a2"]
    out["aspect"] = [_root(lo) if lo > 0 else None, math.sqrt(hi) if math.isfinite(hi) and hi >= 0 else None]
    pad = 1e-12
    for name, (lo, hi) in out.items():
        out[name] = [None if lo is None else lo - pad * (abs(lo) + f0 * (name != "aspect")),
                     None if hi is None else hi + pad * (abs(hi) + f0 * (name != "aspect"))]
    return out


# --- the proof's part: sublevel["intrinsics"] -----------------------------------------------------
#
# {"u": {"lower": entries or null, "upper": ...}, "v": ..., "fy2": ..., "t": ..., "a2": ...,
#  "intervals": [[lower or null, upper or null], one a name of NAMES, in order]}: each ratio's ends
# as direct_sublevel's focal length's (one {delta, c, z} an orientation a side; null: not proven).

UNPROVEN = ("no dual of the order-2 relaxation proved this end within the job's time (the relaxation of "
            "its program is not tight enough there, or the search stopped): nothing is claimed for it")

LEVEL = ("every absolute dual quadric of the direct stage's scope whose cost (7.12) exceeds the certified one's by at "
         "most cost_increase has its intrinsics within these intervals, read from W = mean_i P_i Q P_i' (program "
         "frame, preconditioned by K0 = [[f0, 0, u0], [0, f0, v0], [0, 0, 1]]; the w33-weighted mean of the views' "
         "DIACs) as K K' up to scale: focal the root of (W00 + W11) / (2 W22) times f0 (the focal length when skew "
         "is 0, aspect 1 and the principal point the ranges' middle; clipped to what the focal rows allow), "
         "principal_u u0 + f0 W02 / W22, principal_v v0 + f0 W12 / W22, focal_y f0 sqrt(W11 W22 - W12^2) / W22, "
         "skew f0 (W01 W22 - W02 W12) / (W22 sqrt(W11 W22 - W12^2)), aspect focal_y over the first focal length "
         "(pixels); an end null is not proven (its reason says why)")


def proven_ends(setup, sides: dict, where: str, live: list, level: float) -> dict[str, list]:
    """Each name's [lower, upper] in pixels (None: not proven) that ``sides`` ({ratio: {"lower",
    "upper"}}, each side's entries one {delta, c, z} an orientation of ``live``) prove at
    ``level``, every dual read by safe_bound in its rebuilt program (direct_sublevel._ends)."""
    from geocert.core.strict import record

    forms = ratios(setup.cameras)
    ends = {}
    for name in RATIOS:
        holder = record(sides[name], f"{where}/{name}", ("lower", "upper"))
        ratio = forms[name]

        def build(pairs, c, sign, ratio=ratio):
            return side_program(setup.cameras, pairs, setup.focal, ratio, c, sign, level)

        found = direct_sublevel._ends(setup, holder, f"{where}/{name}", live, level, None, build, ratio.end)
        ends[name] = (found["lower"], found["upper"])
    return pixels(ends, setup.problem.K0)


def check(setup, sublevel, gone: tuple, cost: float) -> dict[str, list]:
    """What a direct proof's sublevel["intrinsics"] proves: each name's [lower, upper] in pixels
    (None: not proven) over every Q of the scope (setup built with exclude=False; ``gone`` the
    orientations the proof excludes) costing at most sublevel_level(cost, cost_increase), the
    focal length's set (direct_sublevel.check, which checks the rest of ``sublevel``). Each
    ratio's entries as the focal length's (every safe bound above 0); the stated intervals must
    hold what they prove: a stated end beyond a proven one (narrower) or where none is proven is
    refused."""
    from geocert.formulations.autocalibration.proofs import sublevel_level
    from geocert.core.strict import Invalid, is_number, record

    where = "proof/sublevel/intrinsics"
    intrinsics = record(sublevel["intrinsics"], where, RATIOS + ("intervals",))
    level = sublevel_level(cost, direct_sublevel._level(sublevel))
    live = [o for o in setup.orientations if o.delta not in gone]
    proven = proven_ends(setup, intrinsics, where, live, level)
    stated = intrinsics["intervals"]
    if not (isinstance(stated, list) and len(stated) == len(NAMES)):
        raise Invalid("format", f"{where}/intervals holds one [lower, upper] a name ({', '.join(NAMES)}), in order")
    for k, name in enumerate(NAMES):
        pair = stated[k]
        if not (isinstance(pair, list) and len(pair) == 2 and all(v is None or is_number(v) for v in pair)):
            raise Invalid("format", f"{where}/intervals/{k} must be [lower, upper], each a number or null")
        for side, (said, got) in enumerate(zip(pair, proven[name])):
            if said is None:
                continue  # not claimed: a weaker true statement
            if got is None or (said > got if side == 0 else said < got):
                raise Invalid("proven_interval", f"{where}/intervals/{k} ({name}) states {pair!r}, narrower than "
                                                 f"what its programs prove ({proven[name]!r})")
    return proven


def proven_document(sublevel: dict) -> dict:
    """The proven intervals a one-K direct stage's determinacy states from its proof's sublevel:
    the focal length's (direct_sublevel.proven_document), then, when it carries "intrinsics",
    NAMES' in order, a null end with its reason."""
    from geocert.core.determinacy import proven_document as document

    if "intrinsics" not in sublevel:
        return direct_sublevel.proven_document(sublevel)
    out = document(sublevel["cost_increase"], (direct_sublevel.NAME,), [sublevel["interval"]], LEVEL)
    for name, (lo, hi) in zip(NAMES, sublevel["intrinsics"]["intervals"]):
        entry = {"name": name, "lower": None if lo is None else float(lo), "upper": None if hi is None else float(hi)}
        if lo is None or hi is None:
            entry["reason"] = UNPROVEN
        out["intervals"].append(entry)
    return out
