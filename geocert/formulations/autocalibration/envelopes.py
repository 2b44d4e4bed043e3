"""Linear envelopes of appendix B (Chandraker 2009), numpy only.

The stratified affine upgrade relaxes ``t = x**(1/3)``, ``z = x*y``, ``z = x**(1/3) * y`` and
``e = d**(8/3)`` by linear inequalities. Every function here returns lines (or rows) that hold for
the TRUE function at every point of the given box, also after floating-point rounding:

* each line is first computed from its formula, then widened OUTWARD by
  ``SLACK * (1 + |intercept| + max |f| on the box)`` (over-estimators move up, under-estimators
  down; for the lifted rows of case I the right-hand side grows by ``SLACK * (1 + scale)``). The
  rounding errors of the formulas are a few ulps of the same quantities (1e-16 relative), so the
  widening (1e-12 relative) covers them with a wide margin, also on degenerate boxes where a
  secant's slope is computed from cancelling differences (its error times the box width is still a
  few ulps of the values);
* degenerate boxes (``xl == xu``) get a horizontal line through the value, widened;
* lines whose coefficients overflow (a slope ``~1/|xl|`` with ``|xl|`` denormal) are dropped when
  another valid line remains, else replaced by the constant bound (``x**(1/3)`` is increasing, so
  ``cbrt(xl) <= x**(1/3) <= cbrt(xu)`` on the box); nothing returned is NaN or infinite.

A ``Line`` ``(slope, intercept)`` is the line ``t = slope * x + intercept``. For an over-estimator
the envelope is the minimum of the lines (concave), for an under-estimator their maximum (convex).

Findings about the thesis's formulas (checked by ``tests/test_autocalibration_envelopes.py``):

* (B.12)/(B.13), the corrected case-II envelopes of ``x**(1/3)`` for ``xl < 0 < xu``, are valid:
  the tangent at ``xu`` lies above the curve exactly on ``[-8 xu, inf)`` (it meets the curve again
  at ``-8 xu``), hence the switch at ``-xl/8 = xu``, and the segment (B.10) to ``(0, 2/3 cbrt(xu))``
  is above the tangent on ``[0, xu]``. They also shrink when the box shrinks (condition (L2)).
  The 2007 paper's tangent from ``(xl, cbrt(xl))`` (B.18, ``t = (4x - xl) / (3 cbrt(xl)**2)``) is
  still a valid over-estimator, but ``min((B.18), (B.9))`` grows at some points when ``xl``
  grows, which is the (L2) violation of B.4.1.
* (B.7)/(B.8), the case-I envelopes of ``x**(1/3) * y``: the thesis states that for ``xl > 0``
  ``f`` is concave in ``x`` and convex in ``y``; it is concave in ``x`` only where ``y >= 0``.
  (B.5)-(B.7) build the convex envelope from the two faces ``x = xl`` and ``x = xu`` only, which
  is valid for a function concave in ``x``. At ``y = yl < 0`` the constraints force
  ``y_p = (1 - lambda) yl`` and (B.7) gives ``z >= yl * chord(x) > yl * x**(1/3)``: INVALID.
  (B.8) is the same construction for ``-f`` (it is (B.7) applied to ``x**(1/3) * (-y)``), so it
  is valid only where ``y <= 0``: for ``xl > 0`` and ``yu > 0`` it cuts off ``f`` at
  ``y = yu``. So in case I, for ``x`` of one sign ``s``, (B.7) is valid iff ``s*y >= 0`` on the
  box and (B.8) iff ``s*y <= 0``; when y crosses 0 neither is. ``caseI_under``/``caseI_over``
  raise ``ValueError`` for the other boxes; use ``cbrt_over``/``cbrt_under`` for ``t`` and
  ``mccormick`` for ``t * y`` there (always valid).
"""

from __future__ import annotations

import math

import numpy as np

Line = tuple[float, float]  # (slope, intercept): the line t = slope * x + intercept
Row = tuple[float, float, float, float, float]  # (cx, cy, cp, cz, rhs): cx x + cy y + cp y_p + cz z <= rhs

SLACK = 1e-12  # relative outward widening of every returned line / row

__all__ = [
    "Line",
    "Row",
    "SLACK",
    "cbrt",
    "cbrt_over",
    "cbrt_under",
    "power_secant",
    "mccormick",
    "caseI_under",
    "caseI_over",
]


def cbrt(x):
    """Real cube root, vectorised (negative for negative x)."""
    return np.cbrt(x)


def _interval(lo, hi, name: str = "x") -> tuple[float, float]:
    lo, hi = float(lo), float(hi)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"{name} bounds must be finite, got [{lo}, {hi}]")
    if lo > hi:
        raise ValueError(f"empty {name} interval [{lo}, {hi}]")
    return lo, hi


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def _widened(slope: float, intercept: float, fmax: float, up: bool) -> Line | None:
    """The line moved outward by SLACK * (1 + |intercept| + max |f| on the box); None if not finite.

    The computed line differs from the exact one by a few ulps of |intercept| and of the values of
    the line near the curve (which are <= ~max |f|); where the line is far above the curve its
    rounding is dwarfed by its distance to the curve. 1e-12 is ~1e4 ulps of that scale."""
    s = SLACK * (1.0 + abs(intercept) + fmax)
    out = (float(slope), float(intercept + s if up else intercept - s))
    return out if _finite(*out) else None


def cbrt_over(xl: float, xu: float) -> list[Line]:
    """Lines L with L(x) >= x**(1/3) on [xl, xu]; their minimum is a concave over-estimator.

    * xl >= 0 (concave part): tangents ``t = (x + 2p) / (3 p**(2/3))`` at 5 points p of the box:
      xl, xu and three interior points evenly spaced when xl > 0; when xl == 0, xu / 4**k for
      k = 0..4 (never at 0, where the slope is infinite). Exact at p (so at both endpoints when
      xl > 0).
    * xu <= 0 (convex part): the secant through both endpoints.
    * xl < 0 < xu: (B.12). If -xl/8 < xu: the tangent at xu (B.9) and the segment from
      (xl, cbrt(xl)) to (0, 2/3 cbrt(xu)) (B.10); else the secant (B.11). Exact at both endpoints.
    """
    xl, xu = _interval(xl, xu)
    fl, fu = float(cbrt(xl)), float(cbrt(xu))
    fmax = max(abs(fl), abs(fu))
    fallback = _widened(0.0, fu, fmax, up=True)  # cbrt is increasing: cbrt(x) <= cbrt(xu)
    if xl == xu or not math.isfinite(xu - xl):
        return [fallback]
    raw: list[tuple[float, float]] = []
    if xl >= 0.0:
        if xl > 0.0:
            pts = [xl, xl + 0.25 * (xu - xl), xl + 0.5 * (xu - xl), xl + 0.75 * (xu - xl), xu]
        else:
            pts = [xu / 4.0**k for k in range(5)]
        for p in pts:
            if p > 0.0:
                c = float(cbrt(p))
                raw.append((1.0 / (3.0 * c * c), 2.0 * c / 3.0))
    elif xu <= 0.0:
        m = (fu - fl) / (xu - xl)
        raw.append((m, fl - m * xl))
    elif -xl / 8.0 < xu:
        raw.append((1.0 / (3.0 * fu * fu), 2.0 * fu / 3.0))  # (B.9) tangent at xu
        raw.append(((fl - 2.0 * fu / 3.0) / xl, 2.0 * fu / 3.0))  # (B.10) to (0, 2/3 cbrt(xu))
    else:
        m = (fu - fl) / (xu - xl)  # (B.11) secant
        raw.append((m, fl - m * xl))
    lines = [line for line in (_widened(m, b, fmax, up=True) for m, b in raw if _finite(m, b)) if line]
    return lines or [fallback]


def cbrt_under(xl: float, xu: float) -> list[Line]:
    """Lines L with L(x) <= x**(1/3) on [xl, xu]; their maximum is a convex under-estimator.

    The mirror image of ``cbrt_over`` (B.13): cbrt is odd, so if L(u) = m u + b >= cbrt(u) on
    [-xu, -xl] then m x - b <= cbrt(x) on [xl, xu]. x >= 0: the secant; x <= 0: tangents;
    xl < 0 < xu: the tangent at xl and the segment from (xu, cbrt(xu)) to (0, 2/3 cbrt(xl)) if
    xl < -xu/8, else the secant.
    """
    xl, xu = _interval(xl, xu)
    return [(m, -b) for m, b in cbrt_over(-xu, -xl)]


def power_secant(xl: float, xu: float, power: float = 8 / 3) -> Line:
    """Over-estimator of x**power on [xl, xu], 0 <= xl <= xu, power >= 1 (B.1): the secant.

    x**power is convex on [0, inf) for power >= 1, so the chord lies above it. Exact at both
    endpoints (up to the widening); xl == xu gives the horizontal line through the value."""
    xl, xu = _interval(xl, xu)
    power = float(power)
    if xl < 0.0:
        raise ValueError(f"power_secant needs xl >= 0, got {xl}")
    if not power >= 1.0:
        raise ValueError(f"power_secant needs power >= 1 (convex), got {power}")
    fl, fu = float(np.power(xl, power)), float(np.power(xu, power))
    if not _finite(fl, fu):
        raise ValueError(f"{xu}**{power} overflows")
    fallback = _widened(0.0, fu, fu, up=True)  # increasing on [0, inf)
    if xl == xu or not math.isfinite(xu - xl):
        return fallback
    m = (fu - fl) / (xu - xl)
    line = _widened(m, fl - m * xl, fu, up=True) if _finite(m, fl - m * xl) else None
    return line or fallback


def mccormick(xl, xu, yl, yu) -> tuple[list[tuple[float, float, float]], list[tuple[float, float, float]]]:
    """McCormick envelope of z = x*y on [xl, xu] x [yl, yu] (B.2)-(B.4).

    Returns (under, over): z >= cx*x + cy*y + c0 for each (cx, cy, c0) in under, z <= ... for
    each in over. The constants are widened by SLACK * (1 + max |x*y| at the corners); the
    envelope is exact (up to that) at the four corners."""
    xl, xu = _interval(xl, xu, "x")
    yl, yu = _interval(yl, yu, "y")
    corners = [xl * yl, xl * yu, xu * yl, xu * yu]
    if not _finite(*corners):
        raise ValueError("x*y overflows on the box")
    s = SLACK * (1.0 + max(abs(c) for c in corners))
    under = [(yl, xl, -xl * yl - s), (yu, xu, -xu * yu - s)]
    over = [(yl, xu, -xu * yl + s), (yu, xl, -xl * yu + s)]
    return under, over


# ---- case I: x**(1/3) * y with x of one sign, (B.7) / (B.8) --------------------------------------


def _b7_rows(xl, xu, yl, yu, sx: float, sy: float, sz: float) -> list[Row]:
    """(B.7) in the variables (x, y, y_p, z), unchecked.

    (B.7) for g(t, w) = t**(1/3) * w on [tl, tu] x [wl, wu], tl >= 0, with lambda = (t - tl)/W,
    W = tu - tl, is, multiplied through by W >= 0 (so that W == 0 stays finite):
        zeta >= cbrt(tl) p + cbrt(tu) (w - p)
        (tu - t) wl <= W p <= (tu - t) wu        ((1 - lambda) wl <= p <= (1 - lambda) wu)
        (t - tl) wl <= W (w - p) <= (t - tl) wu  (lambda wl <= w - p <= lambda wu)
    and is read with t = sx x, w = sy y, zeta = sz z, p = y_p. Each row is widened: rhs += SLACK *
    (1 + scale of its terms), which only enlarges the feasible set."""
    tl, tu = (xl, xu) if sx > 0 else (-xu, -xl)
    wl, wu = (yl, yu) if sy > 0 else (-yu, -yl)
    W = tu - tl
    A, B = float(cbrt(tl)), float(cbrt(tu))
    # rows in (t, w, p, zeta): (ct, cw, cp, czeta, rhs) meaning ct t + cw w + cp p + czeta zeta <= rhs
    rows_g = [
        (-wl, 0.0, -W, 0.0, -tu * wl),
        (wu, 0.0, W, 0.0, tu * wu),
        (wl, -W, W, 0.0, tl * wl),
        (-wu, W, -W, 0.0, -tl * wu),
        (0.0, B, A - B, -1.0, 0.0),
    ]
    # Widening: the y_p rows' terms are <= 3 X Y in size, the z row's <= 2 C Y. Their rounding
    # (a few ulps, incl. W = fl(tu - tl), or underflow, < 1e-322) is covered; the y_p rows' slack
    # moves the z bound by at most (B - A)/W * s_p <= (C/X) * s_p (the chord slope of the concave
    # root is at most C/X), i.e. ~3 C Y SLACK: no absolute term of size 1 in s_p, which divided by
    # a tiny W would loosen z without bound.
    X, Y, C = max(abs(xl), abs(xu)), max(abs(yl), abs(yu)), max(abs(A), abs(B))
    s_p, s_z = SLACK * 3.0 * X * Y + 1e-300, SLACK * (1.0 + 2.0 * C * Y)
    rows = [(sx * ct, sy * cw, cp, sz * cz, rhs + (s_z if cz else s_p)) for ct, cw, cp, cz, rhs in rows_g]
    if not all(_finite(*r) for r in rows):
        raise ValueError("case-I rows overflow on the box")
    return rows


def _case_i_sign(xl: float, xu: float) -> float:
    if xl >= 0.0:
        return 1.0
    if xu <= 0.0:
        return -1.0
    raise ValueError(f"case I needs x of one sign, got [{xl}, {xu}]; use cbrt_over/cbrt_under and mccormick")


def caseI_under(xl, xu, yl, yu) -> list[Row]:
    """(B.7): convex relaxation of z = x**(1/3) * y for x of one sign, as linear rows.

    Variables (x, y, y_p, z), y_p auxiliary; each row (cx, cy, cp, cz, rhs) means
    ``cx*x + cy*y + cp*y_p + cz*z <= rhs``. For xl >= 0 this is (B.7) with lambda =
    (x - xl)/(xu - xl), multiplied through by xu - xl:
        z >= cbrt(xl) y_p + cbrt(xu) (y - y_p),
        (1 - lambda) yl <= y_p <= (1 - lambda) yu,   lambda yl <= y - y_p <= lambda yu.
    For xu <= 0 it is (B.7) for t**(1/3) w with t = -x, w = -y (x**(1/3) y = t**(1/3) w), y_p then
    standing for the auxiliary of w.

    Valid only where f is concave in x: y >= 0 when x >= 0, y <= 0 when x <= 0. Otherwise
    ValueError: at y = yl < 0 (x > 0) the rows force y_p = (1 - lambda) yl and give
    z >= yl * chord(x) > yl * x**(1/3) = f, cutting off the graph.
    """
    xl, xu = _interval(xl, xu, "x")
    yl, yu = _interval(yl, yu, "y")
    sx = _case_i_sign(xl, xu)
    if (sx > 0 and yl < 0.0) or (sx < 0 and yu > 0.0):
        raise ValueError(
            "(B.7) is valid only where x**(1/3) * y is concave in x (y >= 0 for x > 0, y <= 0 for "
            f"x < 0); got x in [{xl}, {xu}], y in [{yl}, {yu}]"
        )
    return _b7_rows(xl, xu, yl, yu, sx, sx, 1.0)


def caseI_over(xl, xu, yl, yu) -> list[Row]:
    """(B.8): concave relaxation of z = x**(1/3) * y for x of one sign, as linear rows.

    Same variables and row convention as ``caseI_under``. For xl >= 0 this is (B.8), i.e. (B.7)
    for x**(1/3) * (-y) with z -> -z, y_p' = y_p:
        z <= (cbrt(xu) - cbrt(xl)) y_p + cbrt(xu) y,
        -(1 - lambda) yu <= y_p <= -(1 - lambda) yl,   lambda yl <= y + y_p <= lambda yu.
    For xu <= 0: (B.7) for t**(1/3) y with t = -x, z -> -z.

    Valid only where f is convex in x: y <= 0 when x >= 0, y >= 0 when x <= 0 (the thesis states
    no such restriction). Otherwise ValueError: at y = yu > 0 (x > 0) the rows give
    z <= yu * chord(x) < yu * x**(1/3) = f.
    """
    xl, xu = _interval(xl, xu, "x")
    yl, yu = _interval(yl, yu, "y")
    sx = _case_i_sign(xl, xu)
    if (sx > 0 and yu > 0.0) or (sx < 0 and yl < 0.0):
        raise ValueError(
            "(B.8) is valid only where x**(1/3) * y is convex in x (y <= 0 for x > 0, y >= 0 for "
            f"x < 0); got x in [{xl}, {xu}], y in [{yl}, {yu}]"
        )
    return _b7_rows(xl, xu, yl, yu, sx, -sx, -1.0)


# ---- the same envelopes for many boxes at once ---------------------------------------------------
# A relaxation with one envelope a view builds its rows from these: the same lines, in the same
# order and to the last bit (the same operations on the same float64 values), as the scalar
# functions above give box by box, without a Python loop over the views.

TANGENTS = 5  # the most lines cbrt_over gives


def _intervals(lo: np.ndarray, hi: np.ndarray, name: str = "x") -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ValueError(f"{name} bounds must be finite")
    if np.any(lo > hi):
        raise ValueError(f"empty {name} interval")
    return lo, hi


def cbrt_over_lines(xl: np.ndarray, xu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``cbrt_over`` for each box [xl[i], xu[i]]: (slopes, intercepts, kept), each (len(xl),
    TANGENTS); box i's lines are the kept entries of row i, in cbrt_over's order."""
    xl, xu = _intervals(xl, xu)
    m = len(xl)
    with np.errstate(all="ignore"):
        fl, fu = np.cbrt(xl), np.cbrt(xu)
        fmax = np.maximum(np.abs(fl), np.abs(fu))
        slopes, icpts = np.full((m, TANGENTS), np.nan), np.full((m, TANGENTS), np.nan)
        width = xu - xl
        degenerate = (xl == xu) | ~np.isfinite(width)
        concave = ~degenerate & (xl >= 0.0)
        inside = concave & (xl > 0.0)
        at_zero = concave & (xl == 0.0)
        points = np.empty((m, TANGENTS))
        points[:] = xl[:, None]
        for i, fraction in ((1, 0.25), (2, 0.5), (3, 0.75)):
            points[:, i] = xl + fraction * width
        points[:, 4] = xu
        points[at_zero] = xu[at_zero, None] / 4.0 ** np.arange(TANGENTS)
        c = np.cbrt(points)
        tangent = concave[:, None] & (points > 0.0)
        slopes[tangent] = (1.0 / (3.0 * c * c))[tangent]
        icpts[tangent] = (2.0 * c / 3.0)[tangent]
        convex = ~degenerate & (xl < 0.0) & (xu <= 0.0)
        crossing = ~degenerate & (xl < 0.0) & (xu > 0.0)
        b9 = crossing & (-xl / 8.0 < xu)
        secant = convex | (crossing & ~b9)
        m_secant = (fu - fl) / width
        slopes[secant, 0] = m_secant[secant]
        icpts[secant, 0] = (fl - m_secant * xl)[secant]
        slopes[b9, 0] = (1.0 / (3.0 * fu * fu))[b9]
        icpts[b9, 0] = (2.0 * fu / 3.0)[b9]
        slopes[b9, 1] = ((fl - 2.0 * fu / 3.0) / xl)[b9]
        icpts[b9, 1] = (2.0 * fu / 3.0)[b9]
        raw = np.isfinite(slopes) & np.isfinite(icpts)
        icpts = icpts + SLACK * (1.0 + np.abs(icpts) + fmax[:, None])  # _widened, upward
        kept = raw & np.isfinite(icpts) & ~degenerate[:, None]
        fallback = ~kept.any(axis=1)  # cbrt is increasing: cbrt(x) <= cbrt(xu)
        slopes[fallback, 0] = 0.0
        icpts[fallback, 0] = (fu + SLACK * (1.0 + np.abs(fu) + fmax))[fallback]
        kept[fallback, 0] = True
    return slopes, icpts, kept


def cbrt_under_lines(xl: np.ndarray, xu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``cbrt_under`` for each box, as cbrt_over_lines gives cbrt_over."""
    xl, xu = _intervals(xl, xu)
    slopes, icpts, kept = cbrt_over_lines(-xu, -xl)
    return slopes, -icpts, kept


def mccormick_lines(xl, xu, yl, yu) -> tuple[np.ndarray, np.ndarray]:
    """``mccormick`` for each box: (under, over), each (len(xl), 2, 3) of (cx, cy, c0)."""
    xl, xu = _intervals(xl, xu, "x")
    yl, yu = _intervals(yl, yu, "y")
    corners = np.stack([xl * yl, xl * yu, xu * yl, xu * yu])
    if not np.all(np.isfinite(corners)):
        raise ValueError("x*y overflows on the box")
    s = SLACK * (1.0 + np.abs(corners).max(axis=0))
    under = np.stack([np.stack([yl, xl, -xl * yl - s], axis=1), np.stack([yu, xu, -xu * yu - s], axis=1)], axis=1)
    over = np.stack([np.stack([yl, xu, -xu * yl + s], axis=1), np.stack([yu, xl, -xl * yu + s], axis=1)], axis=1)
    return under, over
