"""A lower bound on a track's L2L2 triangulation cost from convexity around a local optimum (in
the manner of Hartley and Seo, "Verifying global minima for L2 minimization problems", 2008):
no search, a few 3x3 matrices a track, every track at once on flat arrays (fractional.flat).

Let x be a point in front of every camera (Euclidean coordinates of the caller's frame), c its
cost f(x) = sum_i |r_i(x)|^2 and rho = sqrt(c). Any point X of the scope (every point in front
of every camera, points at infinity included) with f(X) <= c has every residual |r_i| <= rho:
it lies in the convex region C = {every depth > 0, every |r_i| <= rho}. With a radius R:

(E) C lies inside the ball |X - x| < R. With M_i = P_i[:2, :3] - m_i d_i' (m_i the image of
    x in view i, d_i = P_i[2, :3] its depth gradient, w_i its depth), the exact identity
    r_i(X) - r_i(x) = M_i (X - x) / w_i(X) bounds, for X on the sphere |X - x| = R inside C,
    |M_i u| <= tau_i = e_i (w_i + R |d_i|) / R with u the unit direction and e_i = rho + |r_i(x)|;
    so sum_i |M_i u|^2 / tau_i^2 <= n, which lambda_min(sum_i M_i' M_i / tau_i^2) > n refutes.
    C is convex and holds x, so it meets no sphere around x: it lies inside the ball. A point at
    infinity in C would put the whole ray from x towards it in C (each residual along the ray is
    a convex combination of its two ends'), so none is in C.
(V) f is convex on the ball's part of C: there the depths lie in [lo_i, hi_i] = w_i -+ R |d_i|
    (lo_i > 0), and f's second derivative along any direction v is
        sum_i 2 |G_i v|^2 - 4 (d_i . v / w_i)(r_i . G_i v),   G_i = (M_i - (r_i(X) - r_i(x)) d_i') / w_i(X),
    which is at least v' S v with
        S = sum_i M_i' M_i / (2 hi_i^2) - (e_i^2 / hi_i^2 + 4 rho^2 / lo_i^2) d_i d_i'
    (|r_i(X)| <= rho, 2ab <= a^2 / t + t b^2, (a - b)_+^2 >= a^2 / 2 - b^2); S positive definite
    proves it.

Then every point of the scope costs at least f(x) - |grad f(x)| R: outside C more than
rho^2 = c, inside C (within the ball, where f is convex) at least its tangent plane at x. The
smallest R of a ladder that passes (E) is taken (the gradient's term is smallest, and (V) is
easiest, there).

The same test (E) at a higher level proves where the near-optimal points lie (a proven interval
of every solution within ``increase`` of the optimum): every point of the scope costing at most
f(x) + increase (the optimum costs at most f(x)) has every residual at most
rho' = sqrt(f(x) + increase), so lies in C' = {every depth > 0, every |r_i| <= rho'}, convex
and holding x; (E) with rho' in place of rho puts C' inside the ball |X - x| < R', so each
coordinate lies within R' of x's. No convexity of f is needed for this (only (E)), and the test
is monotone in R' (every weight R / (w_i + R |d_i|) grows with R), so the smallest R' passing is
found from a first guess near it, or by bisection (``sublevel_radii``). Under the L2L1 and L1L1 norms the same holds with
rho' = f(x) + increase (each residual's length is at most the sum), whatever proved the optimum.

Round-off (docs/certificate.md states the assumptions): every quantity is recomputed from the
data and x in floating point, and each bound is widened by a generous multiple of the unit
round-off u times the size of the terms behind it (the sums of their products' magnitudes).
A matrix is proven positive definite with a margin by a Cholesky factorisation of it less the
margin and its allowance (positive_definite). Those relative allowances hold while no product
underflows or overflows: the proof is therefore made only for numbers of a moderate range
(every camera entry, observation, point coordinate and the radius 0 or of magnitude within
2^+-128, the cost at least 2^-128), where the only products that can underflow are those of a
difference that cancelled, each losing at most half a subnormal: an absolute UNDERFLOW, far
above their sum, is taken off the bound and added to every positive-definiteness margin. An
overflow makes a number infinite, which no test passes.
"""

from __future__ import annotations

import copy

import numpy as np

from geocert.core.strict import Invalid, number, numbers, record
from geocert.formulations.fractional.flat import PAIRS, FlatTracks, smallest_eigenvalue3

U = 2.0 ** -52
# R as fractions of the distance to the nearest principal plane (half of it at most, so that
# every depth stays above half its value on the ball).
RADII = (2.0 ** -10, 2.0 ** -5, 0.5)
DIAGONAL = [0, 3, 5]  # the diagonal's places in PAIRS order
SMALLEST, LARGEST = 2.0 ** -128, 2.0 ** 128  # the range a proof's numbers keep to (0 apart)
UNDERFLOW = 2.0 ** -900  # what products that underflow can lose, at most, in any test or bound


def in_range(values: np.ndarray) -> np.ndarray:
    """Entries that are 0 or of magnitude within [SMALLEST, LARGEST] (not nan)."""
    size = np.abs(values)
    return (size == 0) | ((size >= SMALLEST) & (size <= LARGEST))


def convexity_bounds(flat: FlatTracks, x: np.ndarray, radii=RADII, strictness: float = 1.0,
                     terms: "Terms | None" = None):
    """For every track t with point ``x[t]`` (T, 3): (lower, radius, cost), lower the proven
    bound on every point's cost in the scope (-inf where this test proves none), radius the R
    used (nan where none: the smallest of ``radii`` times the distance to the nearest principal
    plane that passes (E)), cost the point's sum of squared residuals as computed here.
    ``strictness`` > 1 asks each test to pass with its round-off allowances that many times over
    and a relative margin besides: a solver's claims then pass a checker's tests (strictness 1)
    whose sums differ from its own in their last bits. ``terms``: convexity_terms(flat, x), when
    the caller has them already."""
    terms = terms if terms is not None else convexity_terms(flat, x)
    with np.errstate(all="ignore"):
        R = np.asarray(radii, dtype=float)[:, None] * terms.reach[None]  # (K, T)
        enclosed = _encloses(flat, terms, R, strictness)
        first = np.argmax(enclosed, axis=0)
        R = R[first, np.arange(len(x))]
        return _bound(flat, terms, R, enclosed.any(axis=0), strictness)


def bounds_at(flat: FlatTracks, x: np.ndarray, radius: np.ndarray):
    """(lower, cost) of every track at its own radius (T,): lower -inf where (E) or (V) fails
    there (or the radius is not a positive number)."""
    terms = convexity_terms(flat, x)
    radius = np.asarray(radius, dtype=float)
    with np.errstate(all="ignore"):
        good = (radius > 0) & np.isfinite(radius)
        R = np.where(good, radius, 1.0)
        lower, _, cost = _bound(flat, terms, R, good & _encloses(flat, terms, R[None])[0])
    return lower, cost


class Terms:
    """What (E), (V) and the bound read at the tracks' points: per observation (m,) and per
    track (T,), each with the round-off allowance of its computation; and the projection
    behind them (``image`` (2, m), the residuals ``r`` (2, m), the depths ``w`` (m,), the sizes
    of the terms summed into each projected coordinate ``size`` (3, m)), which a caller reuses."""


def convexity_terms(flat: FlatTracks, x: np.ndarray, increase: np.ndarray | None = None,
                    norm: str = "L2L2") -> Terms:
    """The terms at the tracks' points; with ``increase`` (T,), rho (and e) at the level
    f(x) + increase instead of f(x) (only (E) reads them then), f the ``norm``'s cost: under
    L2L1 and L1L1 every residual's length is at most the whole cost, so rho is the level itself."""
    t = Terms()
    owner = flat.owner
    t.n = n = flat.sizes.astype(float)
    P, y = flat.rows, flat.points
    X = np.concatenate([x, np.ones((len(x), 1))], axis=1)[owner].T  # (4, m)
    proj = (P * X[None]).sum(axis=1)  # (3, m)
    # The sizes of the terms behind proj, summed in the order a sum over axis 1 takes (the same
    # numbers), written out: the broadcast product with the transposed X is several times slower.
    Pa, Xa = np.abs(P), np.abs(X)
    size = Pa[:, 0] * Xa[0] + Pa[:, 1] * Xa[1] + Pa[:, 2] * Xa[2] + Pa[:, 3] * Xa[3]
    w, size_w = proj[2], size[2]
    t.w, t.size = w, size
    with np.errstate(all="ignore"):
        t.image = image = proj[:2] / w
        t.r = r = image - y
        err_w = 16 * U * size_w
        # Each residual coordinate's error: the projection's terms, the division, the subtraction.
        err_r = 32 * U * ((size[:2] + np.abs(image) * size_w) / np.abs(w) + np.abs(image) + np.abs(y))
        r_len = np.sqrt((r * r).sum(axis=0))
        err_len = np.sqrt((err_r * err_r).sum(axis=0))
        t.d = d = P[2, :3]  # (3, m)
        t.d_up = d_up = np.sqrt((d * d).sum(axis=0)) * (1 + 8 * U)
        M = P[:2, :3] - image[:, None] * d[None]  # (2, 3, m)
        M_size = np.sqrt((M * M).sum(axis=(0, 1)))
        # |computed M - exact M|_F: the image's error times |d|, and the subtraction's rounding.
        err_M = err_len * d_up + 4 * U * (np.sqrt((P[:2, :3] ** 2).sum(axis=(0, 1)))
                                          + np.sqrt((image * image).sum(axis=0)) * d_up)
        t.MtM = MtM = np.stack([(M[:, a] * M[:, b]).sum(axis=0) for a, b in PAIRS])  # (6, m)
        # |computed M'M - exact M'M|_2 with the products' rounding, and the sums' rounding.
        MtM_size = np.sqrt((MtM * MtM).sum(axis=0) + (MtM[[1, 2, 4]] ** 2).sum(axis=0))
        t.slack = 2 * M_size * err_M + err_M ** 2 + 8 * U * M_size ** 2 + (n[owner] + 8) * U * MtM_size
        grad_terms = (M * (r / w)[:, None]).sum(axis=0) * 2  # (3, m): 2 M' r / w
        grad_err = 2 / np.abs(w) * (M_size * err_len + err_M * r_len) + 2 * M_size * r_len / np.abs(w) \
            * (err_w / np.abs(w) + 16 * U)
        sums = flat.per_track(np.concatenate([
            np.stack([r_len ** 2, (2 * r_len + err_len) * err_len, (~(w > err_w)).astype(float), grad_err,
                      2 * M_size * r_len / np.abs(w)]), grad_terms]))
        t.c, c_err, behind, g_err, g_size = sums[:5]
        c_err = c_err + 8 * U * n * t.c
        t.c_lo, c_hi = t.c - c_err, t.c + c_err
        if norm == "L2L2":
            level = c_hi if increase is None else (c_hi + increase) * (1 + 4 * U)
            t.rho = np.sqrt(level) * (1 + 4 * U)
        else:  # the sum of the residuals' lengths (L2L1) or of their coordinates' sizes (L1L1), from above
            each = r_len + err_len if norm == "L2L1" else np.abs(r).sum(axis=0) + err_r.sum(axis=0)
            cost_hi = flat.per_track(each * (1 + 4 * U)) * (1 + (n + 4) * U)
            t.rho = (cost_hi + increase) * (1 + 4 * U)
        t.g_up = (np.sqrt((sums[5:] ** 2).sum(axis=0)) + g_err + 8 * U * n * g_size) * (1 + 4 * U)
        t.c_hi, t.r_up = c_hi, (r_len + err_len) * (1 + 4 * U)  # at_level reads them
        t.e = (t.rho[owner] + t.r_up) * (1 + 1e-12)
        t.w_lo, t.w_hi = w - err_w, w + err_w
        t.reach = np.minimum.reduceat(np.where(t.w_lo > 0, t.w_lo / d_up, 0.0), flat.starts[:-1])
        # Numbers outside the moderate range (subnormal, huge, nan) are left unproven.
        outside = ~(in_range(P).all(axis=(0, 1)) & in_range(y).all(axis=0))
        t.usable = (behind == 0) & (t.c >= SMALLEST) & np.isfinite(t.c) & (t.reach > 0) & np.isfinite(t.reach) \
            & np.isfinite(t.g_up) & (flat.per_track(outside.astype(float)) == 0) & in_range(x).all(axis=1)
        if increase is not None:
            t.usable &= in_range(increase) & (increase >= 0)
    return t


def _encloses(flat: FlatTracks, t: Terms, R: np.ndarray, strictness: float = 1.0) -> np.ndarray:
    """(E) at radii R (K, T): lambda_min(sum_i M_i' M_i / tau_i^2) > n, (K, T)."""
    Rm = R[:, flat.owner]
    tau = t.e * (t.w_hi + Rm * t.d_up) / Rm  # (K, m)
    weight = 1 / (tau * tau) * (1 + 8 * U)
    A = flat.per_track(t.MtM[None] * weight[:, None])  # (K, 6, T)
    allowance = flat.per_track(weight * t.slack)  # (K, T)
    return t.usable & positive_definite(A, t.n * (1 + 1e-12 + 1e-6 * (strictness - 1)), strictness * allowance)


def _bound(flat: FlatTracks, t: Terms, R: np.ndarray, enclosed: np.ndarray, strictness: float = 1.0):
    """(V) at radii R (T,) and the bound where (E) and (V) hold: (lower, R, cost)."""
    owner = flat.owner
    Rm = R[owner]
    lo, hi = t.w_lo - Rm * t.d_up, t.w_hi + Rm * t.d_up
    negative = (t.e * t.e / (hi * hi) + 4 * t.rho[owner] ** 2 / (lo * lo)) * (1 + 16 * U)
    half = 1 / (2 * hi * hi) * (1 - 8 * U)
    d = t.d
    dd = np.stack([d[a] * d[b] for a, b in PAIRS])
    S = flat.per_track(np.concatenate([t.MtM * half - negative * dd, (~(lo > 0)).astype(float)[None]]))
    allowance = flat.per_track(half * t.slack + (t.n[owner] + 8) * U * negative * t.d_up ** 2)
    convex = (S[6] == 0) & positive_definite(S[:6], 0.0, strictness * allowance, 1e-9 * (strictness - 1))
    lower = t.c_lo - t.g_up * R
    lower = lower - 4 * U * np.abs(lower) - UNDERFLOW
    proven = enclosed & convex & np.isfinite(lower) & (R >= SMALLEST) & (R <= LARGEST)
    return np.where(proven, lower, -np.inf), np.where(proven, R, np.nan), t.c


def positive_definite(A: np.ndarray, margin, allowance, relative: float = 0.0) -> np.ndarray:
    """Whether the exact symmetric matrices whose entries (in PAIRS order, A (..., 6, T)) are
    within ``allowance`` (..., T) of A's (each entry) all have their smallest eigenvalue above
    ``margin`` (plus ``relative`` times the trace). The test: a Cholesky factorisation of
    A - shift I with shift = margin + 3 allowance + 8 u (trace + margin) + UNDERFLOW (3 allowance
    bounds the entries' error's spectral norm; a Cholesky factorisation computed in floating
    point is exact for a matrix within about 4 u trace of the one factored, Demmel's bound), each
    pivot positive."""
    a00, a01, a02, a11, a12, a22 = np.moveaxis(A, -2, 0)
    with np.errstate(all="ignore"):
        trace = np.abs(a00) + np.abs(a11) + np.abs(a22)
        shift = (margin + relative * trace + 3 * allowance + 8 * U * (trace + np.abs(margin)) + UNDERFLOW) \
            * (1 + 8 * U)
        p0 = a00 - shift
        l10, l20 = a01 / np.sqrt(p0), a02 / np.sqrt(p0)
        p1 = a11 - shift - l10 * l10
        l21 = (a12 - l20 * l10) / np.sqrt(p1)
        p2 = a22 - shift - l20 * l20 - l21 * l21
    return (p0 > 0) & (p1 > 0) & (p2 > 0) & np.isfinite(trace) & np.isfinite(shift)


def outside_range(cameras: np.ndarray, points: np.ndarray, point: np.ndarray, radius: float) -> str | None:
    """What of one track's numbers lies outside the range a convexity proof is made for (None:
    nothing): its cameras' entries, observations, point and radius."""
    for name, values in (("a camera entry", cameras), ("an observation", points), ("the point", point),
                         ("the radius", radius)):
        if not np.all(in_range(np.asarray(values, dtype=float))):
            return (f"{name} is subnormal, huge or not a number: a convexity proof is checked only for numbers "
                    f"that are 0 or of magnitude within [2^-128, 2^128]")
    return None


def track_bound(cameras: np.ndarray, points: np.ndarray, point: np.ndarray, radius: float) -> float:
    """A checker's bound for one track: the bound bounds_at proves at ``point`` (x, y, z) with
    ``radius``, for ``cameras`` (k, 3, 4) and ``points`` (k, 2) as the problem's data give them;
    -inf where (E) or (V) fails there."""
    flat = FlatTracks.build(cameras, [(list(range(len(cameras))), points)])
    lower, _ = bounds_at(flat, np.asarray(point, dtype=float).reshape(1, 3), np.array([radius], dtype=float))
    return float(lower[0])


def at_level(flat: FlatTracks, t: Terms, increase: np.ndarray) -> Terms:
    """L2L2 terms ``t`` (convexity_terms with no increase) moved to the level f(x) + ``increase``
    (T,): the numbers convexity_terms(flat, x, increase) computes, without its passes over the
    observations again (only rho, e and usable differ)."""
    level = copy.copy(t)
    level.rho = np.sqrt((t.c_hi + increase) * (1 + 4 * U)) * (1 + 4 * U)
    level.e = (level.rho[flat.owner] + t.r_up) * (1 + 1e-12)
    level.usable = t.usable & in_range(increase) & (increase >= 0)
    return level


def sublevel_radii(flat: FlatTracks, x: np.ndarray, increase: np.ndarray, strictness: float = 1.0,
                   steps: int = 30, norm: str = "L2L2", terms: Terms | None = None) -> np.ndarray:
    """For every track t: a radius R' at which (E) at the level f(x[t]) + increase[t] holds,
    so that every point of the scope costing at most that lies within R' of x[t], nan where
    none up to 2^128 is found. R' is within a factor 1 / (1 - R0 q) (plus 1e-6) of the
    smallest (R0 below, q the largest |d_i| / w_i), or found by doubling and bisection (to a
    relative 2^-steps) where that first guess does not pass. ``terms``: L2L2's
    convexity_terms(flat, x), when the caller has them."""
    increase = np.asarray(increase, dtype=float)
    with np.errstate(all="ignore"):
        terms = at_level(flat, terms, increase) if terms is not None and norm == "L2L2" else \
            convexity_terms(flat, x, increase, norm)
    usable = terms.usable
    with np.errstate(all="ignore"):
        # Below R0 = sqrt(n / lambda_min(sum_i M_i' M_i / (e_i w_i)^2)) the test fails (each
        # weight is below R^2 / (e_i w_i)^2 there); at R the weights are at least
        # R^2 / (e_i w_i (1 + R q))^2, so R0 / (1 - R0 q) passes but for the test's margins.
        weight = 1 / (terms.e * terms.w_hi) ** 2
        A = flat.per_track(terms.MtM * weight)
        smallest = smallest_eigenvalue3(A)  # eigvalsh's to rounding (non-finite entries read as 0)
        lo = np.sqrt(terms.n / np.where(smallest > 0, smallest, np.nan))
        lo = np.where(np.isfinite(lo) & (lo >= SMALLEST), lo, SMALLEST)
        q = np.maximum.reduceat(np.where(terms.w_hi > 0, terms.d_up / terms.w_hi, np.inf), flat.starts[:-1])
        first = np.where(lo * q < 0.5, lo / (1 - lo * q) * (1 + 1e-6), 2 * lo)

        def passes(R):
            return _encloses(flat, terms, R[None], strictness)[0] & (R <= LARGEST)

        found = passes(first) & usable
        hi = np.where(found, first, lo)
        if not (found | ~usable).all():  # the rest: doubling from R0, then bisection
            done = found | ~usable
            found = found | (passes(hi) & ~done)
            for _ in range(260):  # up to 2^128
                if (found | ~usable).all() or (hi[~found & usable] > LARGEST).all():
                    break
                hi = np.where(found | ~usable, hi, 2 * hi)
                found = found | (passes(hi) & usable)
            lo = np.where(found & ~done & (hi > lo), hi / 2, lo)
            for _ in range(steps):
                middle = np.where(done, hi, np.sqrt(lo * hi))
                ok = passes(middle)
                hi, lo = np.where(ok, middle, hi), np.where(ok, lo, middle)
        return np.where(found & usable, hi, np.nan)


def ball_bounds(point, radius) -> np.ndarray:
    """[lower, upper] of each coordinate over the open ball of ``radius`` about ``point``, rounded
    outward (what a proven interval states, recomputed alike by the checker): (3, 2) for one
    point (3,), or (T, 3, 2) for points (T, 3) and radii (T,)."""
    centre = np.asarray(point, dtype=float)
    radius = np.asarray(radius, dtype=float)[..., None] if centre.ndim == 2 else float(radius)
    return np.stack([np.nextafter(centre - radius, -np.inf), np.nextafter(centre + radius, np.inf)], axis=-1)


def ball_intervals(point, radius) -> list:
    """ball_bounds as nested lists (what a document states)."""
    return ball_bounds(point, radius).tolist()


def sublevel_holds(cameras: np.ndarray, points: np.ndarray, point: np.ndarray, increase: float,
                   radius: float, norm: str = "L2L2") -> bool:
    """A checker's test for one track: (E) at the level f(point) + ``increase`` holds at
    ``radius`` (every point of the scope costing at most that lies within ``radius`` of
    ``point``)."""
    flat = FlatTracks.build(cameras, [(list(range(len(cameras))), points)])
    x = np.asarray(point, dtype=float).reshape(1, 3)
    terms = convexity_terms(flat, x, np.array([increase], dtype=float), norm)
    with np.errstate(all="ignore"):
        return bool(_encloses(flat, terms, np.array([[radius]], dtype=float))[0, 0])


def verify_sublevel(cameras: np.ndarray, points: np.ndarray, sublevel, solution, norm: str) -> None:
    """A proven interval (fractional.convexity, ``sublevel_radii``): every point of the scope
    costing at most the optimum plus cost_increase lies in the intervals. Refused unless (E) at
    that level holds at the radius and the intervals are exactly the ball's about the solution
    (outward rounded): a narrower interval is not proven, a wider one is not the proof's."""
    record(sublevel, "proof/sublevel", ("cost_increase", "radius", "intervals"))
    increase = number(sublevel.get("cost_increase"), "proof/sublevel/cost_increase")
    radius = number(sublevel.get("radius"), "proof/sublevel/radius")
    intervals = numbers(sublevel.get("intervals"), "proof/sublevel/intervals", (3, 2))
    if not (solution[3] == 1.0 and np.all(np.isfinite(solution))):
        raise Invalid("proven_interval", "a proven interval is for a finite solution [x, y, z]")
    if not (increase >= 0 and radius > 0):
        raise Invalid("proven_interval", "proof/sublevel needs cost_increase >= 0 and radius > 0")
    outside = outside_range(cameras, points, solution[:3], radius)
    if outside is not None or not (increase == 0 or 2.0 ** -128 <= increase <= 2.0 ** 128):
        raise Invalid("proven_interval", outside or "proof/sublevel/cost_increase is subnormal or huge")
    if not np.array_equal(intervals, np.array(ball_intervals(solution[:3], radius))):
        raise Invalid("proven_interval", "proof/sublevel/intervals are not the ball's of that radius about the point "
                                         "(each coordinate's [x - radius, x + radius], rounded outward)")
    if not sublevel_holds(cameras, points, solution[:3], increase, radius, norm):
        raise Invalid("proven_interval", f"not proven at radius {radius!r}: the points costing up to cost_increase "
                                         f"{increase!r} more are not shown to lie within it")
