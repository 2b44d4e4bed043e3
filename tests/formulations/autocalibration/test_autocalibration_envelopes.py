"""The envelopes of appendix B hold for the true functions on every point of every box.

Validity is decided EXACTLY: a float line (m, b) and a float point x are rationals, and since the
cube is increasing, ``m x + b >= x**(1/3)`` iff ``(m x + b)**3 >= x`` (likewise ``x**(8/3)``:
``L**3 >= x**8``, ``x**(1/3) y``: ``z**3`` against ``x y**3``), checked with ``fractions``. The
points checked are the box corners, 0, random points, and the points where ``L - f`` is stationary
(for a line of slope m > 0 against x**(1/3): x = +-(3m)**(-3/2)), which together contain the
minimiser of ``L - f`` over the box.

Each property check also runs against a mistyped formula (a local copy) and is shown to FAIL.
"""

from __future__ import annotations

import math
from fractions import Fraction as Q

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geocert.formulations.autocalibration import envelopes as env
from geocert.formulations.autocalibration.envelopes import (
    SLACK,
    caseI_over,
    caseI_under,
    cbrt,
    cbrt_over,
    cbrt_under,
    mccormick,
    power_secant,
)

EXAMPLES = settings(max_examples=100, deadline=None)

# ---- boxes ---------------------------------------------------------------------------------------

magnitude = st.floats(-6.0, 6.0).map(lambda e: 10.0**e)
signed = st.one_of(st.just(0.0), magnitude, magnitude.map(lambda v: -v))


@st.composite
def intervals(draw, kind=None):
    """[lo, hi] with magnitudes 1e-6..1e6, endpoints exactly 0, tiny widths, and boxes crossing
    0 with -lo/8 on both sides of hi (and exactly at it)."""
    kind = kind or draw(st.sampled_from(["free", "free", "tiny", "touch0", "cross8", "cross8"]))
    if kind == "free":
        a, b = draw(signed), draw(signed)
        return (min(a, b), max(a, b))
    if kind == "tiny":
        a = draw(signed)
        step = draw(st.sampled_from(["zero", "ulp", "abs"]))
        if step == "zero":
            return (a, a)
        if step == "ulp":
            return (a, float(np.nextafter(np.nextafter(a, np.inf), np.inf)))
        return (a, a + draw(st.sampled_from([1e-15, 3e-15, 1e-12])))
    if kind == "touch0":
        v = draw(magnitude)
        return draw(st.sampled_from([(0.0, v), (-v, 0.0)]))
    # cross8: lo < 0 < hi with hi = (-lo/8) * (1 + r)
    lo = -draw(magnitude)
    r = draw(st.one_of(st.sampled_from([0.0, 1e-12, -1e-12, 1e-6, -1e-6]), st.floats(-0.95, 1.0), st.floats(1.0, 20.0)))
    hi = (-lo / 8.0) * (1.0 + r)
    return (lo, hi) if draw(st.booleans()) else (-hi, -lo)


def sample_points(lo, hi, rng, n=16, extra=()):
    """Corners, 0, the points next to the corners, random points, and extra (clipped)."""
    pts = [lo, hi, float(np.nextafter(lo, hi)), float(np.nextafter(hi, lo))]
    if lo <= 0.0 <= hi:
        pts.append(0.0)
    pts += list(rng.uniform(lo, hi, n)) if hi > lo else []
    pts += [min(max(float(p), lo), hi) for p in extra if math.isfinite(p)]
    return pts


def cbrt_critical(lines):
    """Where L - x**(1/3) is stationary: x = +-(3m)**(-3/2), m > 0."""
    out = []
    for m, _ in lines:
        if m > 0:
            c = (3.0 * m) ** -1.5
            out += [c, -c]
    return out


def rng_for(*values):
    return np.random.default_rng(abs(hash(values)) % 2**32)


def scale(lo, hi):
    return 1.0 + max(abs(float(cbrt(lo))), abs(float(cbrt(hi))))


# ---- exact predicates ----------------------------------------------------------------------------


def line_ge_cbrt(m, b, x) -> bool:
    v = Q(m) * Q(x) + Q(b)
    return v**3 >= Q(x)


def line_le_cbrt(m, b, x) -> bool:
    v = Q(m) * Q(x) + Q(b)
    return v**3 <= Q(x)


def over_violations(lines, lo, hi, rng):
    return [(m, b, x) for x in sample_points(lo, hi, rng, extra=cbrt_critical(lines)) for m, b in lines if not line_ge_cbrt(m, b, x)]


def under_violations(lines, lo, hi, rng):
    return [(m, b, x) for x in sample_points(lo, hi, rng, extra=cbrt_critical(lines)) for m, b in lines if not line_le_cbrt(m, b, x)]


def env_min(lines, x):
    return min(m * x + b for m, b in lines)


def env_max(lines, x):
    return max(m * x + b for m, b in lines)


def monotonicity_violations(over, lo, hi, rng, n_sub=6):
    """Shrinking the box never loosens the envelope (thesis condition (L2)): on a sub-box the
    over-estimator is nowhere above the one of the box."""
    out = []
    parent = over(lo, hi)
    tol = 1e-9 * scale(lo, hi)
    for _ in range(n_sub):
        a, b = sorted(rng.uniform(lo, hi, 2))
        sub = over(a, b)
        for x in sample_points(a, b, rng, n=12):
            if env_min(sub, x) > env_min(parent, x) + tol:
                out.append((a, b, x))
    return out


def well_formed(lines):
    return len(lines) >= 1 and all(len(line) == 2 and all(math.isfinite(v) for v in line) for line in lines)


# ---- local copies of mistyped formulas -----------------------------------------------------------


def mutant_b12(lo, hi, two_thirds=1.0 / 3.0):
    """(B.12) with the 2/3 of (B.10) mistyped (default 1/3), widened like the module."""
    if not (lo < 0 < hi and -lo / 8 < hi):
        return cbrt_over(lo, hi)
    fl, fu = float(cbrt(lo)), float(cbrt(hi))
    raw = [(1 / (3 * fu * fu), 2 * fu / 3), ((fl - two_thirds * fu) / lo, two_thirds * fu)]
    s = lambda b: SLACK * (1 + abs(b) + max(abs(fl), abs(fu)))  # noqa: E731
    return [(m, b + s(b)) for m, b in raw]


def paper_2007_over(lo, hi):
    """The 2007 paper's over-estimator (B.4.1): min of (B.9) and the tangent from (xl, cbrt(xl))
    (B.18) t = (4x - xl) / (3 xl**(2/3)), in place of the segment (B.10)."""
    if not (lo < 0 < hi and -lo / 8 < hi):
        return cbrt_over(lo, hi)
    fl, fu = float(cbrt(lo)), float(cbrt(hi))
    raw = [(1 / (3 * fu * fu), 2 * fu / 3), (4 / (3 * fl * fl), -lo / (3 * fl * fl))]
    s = lambda b: SLACK * (1 + abs(b) + max(abs(fl), abs(fu)))  # noqa: E731
    return [(m, b + s(b)) for m, b in raw]


def crossing_boxes(n=200, seed=7):
    """Seeded boxes xl < 0 < xu with -xl/8 < xu (where (B.10) is used)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        lo = -(10.0 ** rng.uniform(-6, 6))
        hi = (-lo / 8) * 10.0 ** rng.uniform(0.0, 3.0)
        out.append((lo, hi))
    return out


# ---- tests ---------------------------------------------------------------------------------------


class TestCbrt:
    def test_real_cube_root_vectorised(self):
        x = np.array([-27.0, -1e-6, 0.0, 8.0, 1e6])
        np.testing.assert_allclose(cbrt(x), [-3.0, -1e-2, 0.0, 2.0, 1e2], rtol=1e-15)
        assert float(cbrt(-8.0)) == -2.0

    @given(x=signed)
    def test_odd(self, x):
        assert float(cbrt(-x)) == -float(cbrt(x))


class TestCbrtOver:
    @EXAMPLES
    @given(box=intervals())
    def test_every_line_over_estimates(self, box):
        lo, hi = box
        lines = cbrt_over(lo, hi)
        assert well_formed(lines)
        assert over_violations(lines, lo, hi, rng_for(lo, hi)) == []

    @EXAMPLES
    @given(box=intervals())
    def test_tight_at_the_endpoints(self, box):
        """Exact (within 1e-9 of the box's scale) at xu always and at xl unless xl == 0 (where
        only tangents at points > 0 are used)."""
        lo, hi = box
        lines = cbrt_over(lo, hi)
        tol = 1e-9 * scale(lo, hi)
        assert env_min(lines, hi) - float(cbrt(hi)) <= tol
        if lo != 0.0 or hi == 0.0:
            assert env_min(lines, lo) - float(cbrt(lo)) <= tol

    @EXAMPLES
    @given(box=intervals())
    def test_no_looser_than_the_constant_bound(self, box):
        lo, hi = box
        lines = cbrt_over(lo, hi)
        tol = 1e-9 * scale(lo, hi)
        for x in sample_points(lo, hi, rng_for(lo, hi, 1)):
            assert env_min(lines, x) <= float(cbrt(hi)) + tol

    @EXAMPLES
    @given(box=st.one_of(intervals("cross8"), intervals("free")))
    def test_shrinking_the_box_never_loosens_it(self, box):
        """(L2) for (B.12) and the secant (boxes with xl < 0); tangents sampled on xl >= 0 boxes
        move with the box and are not monotone, so those parents are skipped."""
        lo, hi = box
        if lo >= 0.0 or lo == hi:
            return
        assert monotonicity_violations(cbrt_over, lo, hi, rng_for(lo, hi, 2)) == []

    def test_b12_switches_at_minus_xl_over_8(self):
        assert len(cbrt_over(-8.0, 1.0 + 1e-9)) == 2  # (B.9) and (B.10)
        assert len(cbrt_over(-8.0, 1.0)) == 1  # (B.11) secant
        # at the switch the secant is the tangent at xu: (x + 2) / 3
        (m, b), = cbrt_over(-8.0, 1.0)
        assert m == pytest.approx(1 / 3, rel=1e-14) and b == pytest.approx(2 / 3, rel=1e-9)

    @pytest.mark.parametrize("box", [(0.0, 0.0), (-1.0, -1.0), (5.0, 5.0), (-5e-324, 1.0), (0.0, 5e-324), (-1e-300, 1e-300), (-1e300, 1e300)])
    def test_degenerate_boxes_stay_finite_and_valid(self, box):
        lines = cbrt_over(*box)
        assert well_formed(lines)
        assert over_violations(lines, *box, np.random.default_rng(0)) == []

    def test_bad_input(self):
        with pytest.raises(ValueError):
            cbrt_over(1.0, 0.0)
        with pytest.raises(ValueError):
            cbrt_over(float("nan"), 1.0)

    # The property checks are able to fail: mistyped formulas, local copies.

    def test_mistyped_b10_is_caught(self):
        """2/3 -> 1/3 in (B.10): the segment then dips under the curve on (0, xu)."""
        caught = [box for box in crossing_boxes() if over_violations(mutant_b12(*box), *box, np.random.default_rng(1))]
        assert len(caught) > 50
        # the unmutated formula passes the same check on the same boxes
        assert not [box for box in crossing_boxes() if over_violations(mutant_b12(*box, two_thirds=2 / 3), *box, np.random.default_rng(1))]

    def test_paper_2007_tangent_is_valid_but_not_monotone(self):
        """B.4.1: (B.18) over-estimates, but min((B.18), (B.9)) rises on (-xl/8, xa) when xl rises:
        the validity check passes it, the (L2) check catches it."""
        boxes = crossing_boxes()
        assert not [box for box in boxes if over_violations(paper_2007_over(*box), *box, np.random.default_rng(1))]
        caught = [box for box in boxes if monotonicity_violations(paper_2007_over, *box, np.random.default_rng(1))]
        assert len(caught) > 20
        # the thesis's own example: on [-1, 1] vs [-0.9, 1] at x = 0.25 in (1/8, xa = 1/3)
        assert env_min(paper_2007_over(-0.9, 1.0), 0.25) > env_min(paper_2007_over(-1.0, 1.0), 0.25) + 1e-3


class TestCbrtUnder:
    @EXAMPLES
    @given(box=intervals())
    def test_every_line_under_estimates(self, box):
        lo, hi = box
        lines = cbrt_under(lo, hi)
        assert well_formed(lines)
        assert under_violations(lines, lo, hi, rng_for(lo, hi)) == []

    @EXAMPLES
    @given(box=intervals())
    def test_tight_at_the_endpoints(self, box):
        lo, hi = box
        lines = cbrt_under(lo, hi)
        tol = 1e-9 * scale(lo, hi)
        assert float(cbrt(lo)) - env_max(lines, lo) <= tol
        if hi != 0.0 or lo == 0.0:
            assert float(cbrt(hi)) - env_max(lines, hi) <= tol

    @EXAMPLES
    @given(box=st.one_of(intervals("cross8"), intervals("free")))
    def test_shrinking_the_box_never_loosens_it(self, box):
        lo, hi = box
        if hi <= 0.0 or lo == hi:
            return
        neg_over = lambda a, b: [(m, -c) for m, c in cbrt_under(-b, -a)]  # noqa: E731  (mirror)
        assert monotonicity_violations(neg_over, -hi, -lo, rng_for(lo, hi, 2)) == []

    def test_b13_is_the_thesis_formula(self):
        """xu/8 < -xl: max of the tangent at xl and the segment from (xu, cbrt xu) to
        (0, 2/3 cbrt xl), as printed in (B.13)."""
        xl, xu = -1.0, 2.0
        lines = sorted(cbrt_under(xl, xu))
        expected = sorted([(1 / 3, 2 / 3 * xl), (xu ** (-2 / 3) - 2 / 3 / xu * float(cbrt(xl)), 2 / 3 * float(cbrt(xl)))])
        np.testing.assert_allclose(lines, expected, rtol=1e-9)

    def test_mistyped_b13_is_caught(self):
        mutant = lambda a, b: [(m, -c) for m, c in mutant_b12(-b, -a)]  # noqa: E731
        caught = [(-hi, -lo) for lo, hi in crossing_boxes() if under_violations(mutant(-hi, -lo), -hi, -lo, np.random.default_rng(1))]
        assert len(caught) > 50


class TestPowerSecant:
    @staticmethod
    def violations(line, lo, hi, rng):
        m, b = line
        crit = (3 * m / 8) ** 0.6 if m > 0 else lo  # where L - x**(8/3) is stationary
        bad = []
        for x in sample_points(lo, hi, rng, extra=[crit]):
            v = Q(m) * Q(x) + Q(b)
            if v < 0 or v**3 < Q(x) ** 8:
                bad.append(x)
        return bad

    @EXAMPLES
    @given(box=intervals())
    def test_over_estimates_x_to_8_3(self, box):
        lo, hi = abs(box[0]), abs(box[1])
        lo, hi = min(lo, hi), max(lo, hi)
        line = power_secant(lo, hi)
        assert well_formed([line])
        assert self.violations(line, lo, hi, rng_for(lo, hi)) == []
        tol = 1e-9 * (1 + hi ** (8 / 3))
        for x in (lo, hi):
            assert line[0] * x + line[1] - x ** (8 / 3) <= tol

    def test_other_power(self):
        m, b = power_secant(1.0, 3.0, power=2.0)
        assert all(Q(m) * Q(x) + Q(b) >= Q(x) ** 2 for x in np.linspace(1, 3, 101))

    def test_refuses(self):
        with pytest.raises(ValueError):
            power_secant(-1.0, 1.0)
        with pytest.raises(ValueError):
            power_secant(0.0, 1.0, power=0.5)  # concave: the secant would under-estimate

    def test_mistyped_power_is_caught(self):
        """Secant of x**(5/3) checked against x**(8/3): fails."""
        m, b = power_secant(0.5, 2.0, power=5 / 3)
        assert self.violations((m, b), 0.5, 2.0, np.random.default_rng(0))


class TestMcCormick:
    @staticmethod
    def violations(under, over, xl, xu, yl, yu, rng):
        xs = sample_points(xl, xu, rng, n=4)
        ys = sample_points(yl, yu, rng, n=4)
        bad = []
        for x in xs:
            for y in ys:
                z = Q(x) * Q(y)
                bad += [("under", x, y) for cx, cy, c0 in under if Q(cx) * Q(x) + Q(cy) * Q(y) + Q(c0) > z]
                bad += [("over", x, y) for cx, cy, c0 in over if Q(cx) * Q(x) + Q(cy) * Q(y) + Q(c0) < z]
        return bad

    @EXAMPLES
    @given(bx=intervals(), by=intervals())
    def test_valid_on_the_box(self, bx, by):
        under, over = mccormick(*bx, *by)
        assert all(math.isfinite(v) for row in under + over for v in row)
        assert self.violations(under, over, *bx, *by, rng_for(bx, by)) == []

    @EXAMPLES
    @given(bx=intervals(), by=intervals())
    def test_exact_at_the_corners(self, bx, by):
        under, over = mccormick(*bx, *by)
        tol = 1e-9 * (1 + max(abs(a * b) for a in bx for b in by))
        for x in bx:
            for y in by:
                assert abs(max(cx * x + cy * y + c0 for cx, cy, c0 in under) - x * y) <= tol
                assert abs(min(cx * x + cy * y + c0 for cx, cy, c0 in over) - x * y) <= tol

    def test_mistyped_corner_is_caught(self):
        """(B.3) with xl and xu swapped in its first plane."""
        rng = np.random.default_rng(0)
        caught = 0
        for _ in range(50):
            xl, xu = sorted(rng.uniform(-3, 3, 2))
            yl, yu = sorted(rng.uniform(-3, 3, 2))
            under, over = mccormick(xl, xu, yl, yu)
            bad_over = [(yl, xl, -xl * yl), over[1]]
            caught += bool(self.violations(under, bad_over, xl, xu, yl, yu, rng))
        assert caught > 25


# ---- case I: x**(1/3) * y ------------------------------------------------------------------------


def implied_z_bound(rows, x, y, sense):
    """The bound on z the rows imply at (x, y), projecting y_p out exactly: the lowest lower bound
    ("under") or highest upper bound ("over") over the feasible y_p. None if infinite (no bound);
    "empty" if no y_p is feasible (the graph is cut off entirely)."""
    x, y = Q(x), Q(y)
    lo_p, hi_p = None, None
    zrows = []
    for cx, cy, cp, cz, rhs in rows:
        r = Q(rhs) - Q(cx) * x - Q(cy) * y  # cp*p + cz*z <= r
        if cz != 0:
            zrows.append((Q(cp), Q(cz), r))
        elif cp > 0:
            hi_p = r / Q(cp) if hi_p is None else min(hi_p, r / Q(cp))
        elif cp < 0:
            lo_p = r / Q(cp) if lo_p is None else max(lo_p, r / Q(cp))
        elif r < 0:
            return "empty"
    if lo_p is not None and hi_p is not None and lo_p > hi_p:
        return "empty"
    (cp, cz, r), = zrows
    # cz*z <= r - cp*p: z >= g(p) = (cp*p - r)/(-cz) if cz < 0, z <= g(p) = (r - cp*p)/cz if cz > 0
    g = (lambda p: (cp * p - r) / (-cz)) if cz < 0 else (lambda p: (r - cp * p) / cz)
    if cp == 0:
        return g(Q(0))
    slope = cp / -cz if cz < 0 else -cp / cz
    # under: the lowest lower bound; over: the highest upper bound
    end = (lo_p if slope > 0 else hi_p) if sense == "under" else (hi_p if slope > 0 else lo_p)
    return None if end is None else g(end)


def case_i_violations(rows, sense, xl, xu, yl, yu, rng, n=3):
    """Points (x, y) of the box whose (x, y, x**(1/3) y) the rows cut off (exact)."""
    bad = []
    xs = sample_points(xl, xu, rng, n=n, extra=[0.5 * (xl + xu)])
    ys = sample_points(yl, yu, rng, n=n)
    for x in xs:
        for y in ys:
            zb = implied_z_bound(rows, x, y, sense)
            if zb is None:
                continue
            if zb == "empty":
                bad.append((x, y, "empty"))
                continue
            target = Q(x) * Q(y) ** 3  # f**3, f = cbrt(x) y
            if (sense == "under" and zb**3 > target) or (sense == "over" and zb**3 < target):
                bad.append((x, y, float(zb)))
    return bad


@st.composite
def case_i_boxes(draw, sense, valid=True):
    """x of one sign; y of the sign for which (B.7) ("under") or (B.8) ("over") applies, or
    (valid=False) of the other sign / crossing 0."""
    xl, xu = draw(intervals())
    if xl < 0 < xu:
        xl, xu = (0.0, xu) if draw(st.booleans()) else (xl, 0.0)
    s = 1.0 if xl >= 0 else -1.0
    a, b = draw(st.one_of(st.just(0.0), magnitude)), draw(magnitude)
    a, b = min(a, b), max(a, b)
    want = s if sense == "under" else -s  # sign y must have
    if valid:
        yl, yu = (a, b) if want > 0 else (-b, -a)
    else:
        kind = draw(st.sampled_from(["cross", "wrong"]))
        if kind == "cross":
            yl, yu = -draw(magnitude), draw(magnitude)
        else:
            yl, yu = (-b, -a) if want > 0 else (a, b)
            if yl == yu == 0.0:
                yl, yu = (-1.0, -1.0) if want > 0 else (1.0, 1.0)
    return xl, xu, yl, yu


class TestCaseIUnder:
    @EXAMPLES
    @given(box=case_i_boxes("under"))
    def test_valid_where_offered(self, box):
        rows = caseI_under(*box)
        assert all(math.isfinite(v) for r in rows for v in r)
        assert case_i_violations(rows, "under", *box, rng_for(box)) == []

    @EXAMPLES
    @given(box=case_i_boxes("under"))
    def test_exact_at_the_corners(self, box):
        xl, xu, yl, yu = box
        rows = caseI_under(*box)
        tol = 1e-9 * (1 + max(abs(yl), abs(yu)) * (1 + max(abs(float(cbrt(xl))), abs(float(cbrt(xu))))))
        for x in (xl, xu):
            for y in (yl, yu):
                zb = implied_z_bound(rows, x, y, "under")
                assert zb is not None and zb != "empty"
                assert abs(float(zb) - float(cbrt(x)) * y) <= tol

    @EXAMPLES
    @given(box=case_i_boxes("under", valid=False))
    def test_refused_where_invalid(self, box):
        with pytest.raises(ValueError):
            caseI_under(*box)

    def test_refused_when_x_crosses_zero(self):
        with pytest.raises(ValueError):
            caseI_under(-1.0, 1.0, 0.0, 1.0)

    def test_b7_is_invalid_when_y_crosses_zero(self):
        """The finding behind the refusal: (B.7) as printed (the unchecked rows), for x > 0 and
        yl < 0, cuts off f at y = yl, x mid-box, on every box with a non-negligible x range; and
        for x < 0 (mirrored) when yu > 0."""
        rng = np.random.default_rng(3)
        for _ in range(100):
            xl = 10.0 ** rng.uniform(-6, 6) * rng.choice([0.0, 1.0])
            xu = (xl if xl > 0 else 10.0 ** rng.uniform(-6, 6)) * 10.0 ** rng.uniform(0.1, 3)
            yl = -(10.0 ** rng.uniform(-6, 6))
            yu = rng.choice([-1.0, 1.0]) * abs(yl) * 10.0 ** rng.uniform(-2, 2)
            yl, yu = min(yl, yu), max(yl, yu)
            rows = env._b7_rows(xl, xu, yl, yu, 1.0, 1.0, 1.0)
            x = 0.5 * (xl + xu)
            zb = implied_z_bound(rows, x, yl, "under")
            assert zb**3 > Q(x) * Q(yl) ** 3, (xl, xu, yl, yu)  # above f: invalid
            # mirrored: x < 0, yu > 0
            rows = env._b7_rows(-xu, -xl, -yu, -yl, -1.0, -1.0, 1.0)
            zb = implied_z_bound(rows, -x, -yl, "under")
            assert zb**3 > Q(-x) * Q(-yl) ** 3

    @EXAMPLES
    @given(box=case_i_boxes("under", valid=False))
    def test_unchecked_rows_fail_the_property_check_on_refused_boxes(self, box):
        """Same property check as test_valid_where_offered, run on the refused boxes with the raw
        (B.7) rows: it finds points cut off whenever the x range and y are not negligible."""
        xl, xu, yl, yu = box
        s = 1.0 if xl >= 0 else -1.0
        rows = env._b7_rows(xl, xu, yl, yu, s, s, 1.0)
        bad = case_i_violations(rows, "under", *box, rng_for(box))
        wide_x = min(abs(xl), abs(xu)) * 1.1 < max(abs(xl), abs(xu))
        # the part of y of the wrong sign is not lost in the widening (1e-12 of max |y|)
        # and the cut (>= ~1e-4 C |y_wrong| for a wide x range) is above the absolute widening
        y_wrong = max(-s * yl, -s * yu, 0.0)
        wrong_y = y_wrong >= 1e-2 * max(abs(yl), abs(yu))
        visible = y_wrong * max(abs(float(cbrt(xl))), abs(float(cbrt(xu)))) > 1e-6
        if wide_x and wrong_y and visible:
            assert bad


class TestCaseIOver:
    @EXAMPLES
    @given(box=case_i_boxes("over"))
    def test_valid_where_offered(self, box):
        rows = caseI_over(*box)
        assert all(math.isfinite(v) for r in rows for v in r)
        assert case_i_violations(rows, "over", *box, rng_for(box)) == []

    @EXAMPLES
    @given(box=case_i_boxes("over"))
    def test_exact_at_the_corners(self, box):
        xl, xu, yl, yu = box
        rows = caseI_over(*box)
        tol = 1e-9 * (1 + max(abs(yl), abs(yu)) * (1 + max(abs(float(cbrt(xl))), abs(float(cbrt(xu))))))
        for x in (xl, xu):
            for y in (yl, yu):
                zb = implied_z_bound(rows, x, y, "over")
                assert zb is not None and zb != "empty"
                assert abs(float(zb) - float(cbrt(x)) * y) <= tol

    @EXAMPLES
    @given(box=case_i_boxes("over", valid=False))
    def test_refused_where_invalid(self, box):
        with pytest.raises(ValueError):
            caseI_over(*box)

    def test_b8_is_invalid_for_positive_y(self):
        """(B.8) as printed, x in [1, 8], y in [0, 1] (the usual case): at y = 1, x = 4.5 it
        bounds z by the chord 1 + (4.5 - 1)/7 = 1.5 < 4.5**(1/3) = 1.651: f is cut off."""
        rows = env._b7_rows(1.0, 8.0, 0.0, 1.0, 1.0, -1.0, -1.0)
        zb = implied_z_bound(rows, 4.5, 1.0, "over")
        assert float(zb) == pytest.approx(1.5, rel=1e-9)
        assert zb**3 < Q(4.5)
        with pytest.raises(ValueError):
            caseI_over(1.0, 8.0, 0.0, 1.0)


class TestManyBoxesAtOnce:
    """The relaxations build their rows from cbrt_over_lines, cbrt_under_lines and
    mccormick_lines, one call for every view: each box's lines must be the scalar functions',
    in their order and to the last bit, so that a program (and a stored certificate's dual
    against it) is the same whichever builds it."""

    @staticmethod
    def kept_lines(slopes, icpts, kept, i):
        return [(float(m), float(b)) for m, b, k in zip(slopes[i], icpts[i], kept[i]) if k]

    @EXAMPLES
    @given(boxes=st.lists(intervals(), min_size=1, max_size=6))
    def test_cube_root_lines_are_the_scalar_ones(self, boxes):
        lo, hi = np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes])
        for many, one in ((env.cbrt_over_lines, cbrt_over), (env.cbrt_under_lines, cbrt_under)):
            slopes, icpts, kept = many(lo, hi)
            for i, (xl, xu) in enumerate(boxes):
                assert self.kept_lines(slopes, icpts, kept, i) == [(float(m), float(b)) for m, b in one(xl, xu)]

    @EXAMPLES
    @given(boxes=st.lists(st.tuples(intervals("free"), intervals("free")), min_size=1, max_size=6))
    def test_mccormick_lines_are_the_scalar_ones(self, boxes):
        xl, xu = np.array([b[0][0] for b in boxes]), np.array([b[0][1] for b in boxes])
        yl, yu = np.array([b[1][0] for b in boxes]), np.array([b[1][1] for b in boxes])
        under, over = env.mccormick_lines(xl, xu, yl, yu)
        for i, ((a, b), (c, d)) in enumerate(boxes):
            scalar_under, scalar_over = mccormick(a, b, c, d)
            assert [tuple(map(float, line)) for line in under[i]] == [tuple(map(float, x)) for x in scalar_under]
            assert [tuple(map(float, line)) for line in over[i]] == [tuple(map(float, x)) for x in scalar_over]

    def test_refused_as_the_scalar_ones_are(self):
        with pytest.raises(ValueError):
            env.cbrt_over_lines(np.array([0.0, 2.0]), np.array([1.0, 1.0]))  # an empty interval
        with pytest.raises(ValueError):
            env.mccormick_lines(np.array([0.0]), np.array([np.inf]), np.array([0.0]), np.array([1.0]))
