"""How well the data fix an answer: intervals from the cost's local curvature, and warnings.

A certificate proves that nothing in the scope costs less than the bound; it does not say that the
answer is the only one that fits. Near the optimum the squared residuals grow like
``|r(theta* + d)|^2 ~ cost* + d' J'J d`` (J the residuals' Jacobian, Gauss-Newton), so the
parameters costing at most ``cost* + delta`` form an ellipsoid, and a quantity g(theta) ranges
over ``g* +- sqrt(delta g' (J'J)^+ g)`` on it. Along a direction where J'J is (numerically) singular
the data do not fix the answer at all: a quantity with a component there is unbounded.

``delta`` is ``sigmas^2`` times the residual variance the fit itself estimates (cost / (n - p),
the usual least-squares standard error; 3 by default, so an interval is 3 standard errors), and
never less than the certified gap (cost - lower_bound). These intervals are estimates (the
curvature is the local one), not proofs; the result says so.

``determined`` is what a user may rely on: every interval bounded, each within
``RELATIVE_WIDTH`` (10%) of its quantity's scale on either side of the value (a quantity given
a scale: a length's is its value, a focal length's its value, a principal point's the focal
length; a quantity without one need only be bounded; the interval's ``tolerance`` states the
half-width allowed), and no warning.

Where the cost is far from quadratic over the ellipsoid (autocalibration's plane at infinity,
whose cost is a quartic), ``sublevel_rays`` walks the actual cost along the ellipsoid's axes
and the quantities' extreme directions until it rises by ``delta`` (or leaves the scope), and the
quantities are evaluated there, not extrapolated from their gradients.
"""

from __future__ import annotations

import functools
import math
import time
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field

import numpy as np

SIGMAS = 3.0
SINGULAR = 1e-10  # an eigenvalue of J'J below this fraction of the largest: a direction the data do not fix
RELATIVE_WIDTH = 0.1  # `determined`: every interval within this fraction of its quantity's scale of the value
# The estimates' forms, oldest first, each the mark a kind stating them declares through its
# problem hash (certificates.problem_hash's marks; Verification.hash_marks). Documents written
# before intervals stated a tolerance hash no mark (form 0), and their ``determined`` meant
# bounded; without a mark a document could choose that older reading by leaving every
# tolerance out. Form 1: every interval states its ``tolerance`` (null where its quantity has no
# scale) and ``determined`` is read against it. Form 2 (today's): a level from a fit's own
# residual variance uses the Student quantile of its degrees of freedom (level_sigmas), where
# forms 0 and 1 used SIGMAS standard errors whatever the degrees of freedom; an
# autocalibration's principal point and skew are held to the image's scale (image_scale), not the
# focal length's; and a stage with no redundancy must state no_redundancy (verify.estimates.
# check_no_redundancy), and one whose K interval (or aspect) the scope cuts must state
# at_range_edge. FORM_RULES (below) pairs each rule with the first form holding it.
FORMS = ({"determinacy": "every interval states its tolerance"},
         {"determinacy": "every interval states its tolerance",
          "level": "the Student quantile of the residual degrees of freedom",
          "scale": "a principal point's and skew's is half the image's larger side",
          "warnings": "no_redundancy where a stage has none, at_range_edge where the scope cuts K or its aspect, "
                      "few_degrees_of_freedom from one"})
ESTIMATES_FORM = FORMS[-1]
CURRENT_FORM = len(FORMS)  # the number of today's form (0: unmarked, k: FORMS[k - 1])
STUDENT_FORM = 2  # the first form whose levels use the Student quantile

OWN_SCALE_FORM = 2  # the first form giving a principal point and skew a scale of their own (image_scale)
NO_REDUNDANCY_FORM = 2  # the first form whose verifier requires no_redundancy where a stage has none
RANGE_EDGE_FORM = 2  # the first form whose verifier requires at_range_edge where the scope cuts an interval
ASPECT_EDGE_FORM = 2  # the first form whose at_range_edge covers K's aspect on its range's end (review 63)
TOLERANCE_FORM = 1  # the first form whose intervals state a tolerance, ``determined`` read against it

# Each form's rules with their words (what a form before the rule's does not hold the document
# to): the report of a document of an earlier form lists every rule its form lacks (``lacked``),
# each paired here with the constant its code is gated on, so a rule added under a form is
# stated where it is missing (review 63: a form-1 report named only the level).
FORM_RULES = (
    (TOLERANCE_FORM, "every interval states its tolerance and determined means each within it (the form reads "
                     "determined as every interval bounded)"),
    (STUDENT_FORM, "levels use the Student quantile of the fit's residual degrees of freedom (the form's are "
                   f"{SIGMAS:g}^2 times the residual variance whatever its degrees of freedom, so an estimate "
                   "from few residuals may be narrower than today's writer would state)"),
    (STUDENT_FORM, "few_degrees_of_freedom is warned of a level from one degree of freedom (not required)"),
    (OWN_SCALE_FORM, "an autocalibration's principal point and skew are held to a tolerance of a tenth of half the "
                     "image's larger side (the form's is a tenth of the focal length, wider than the principal "
                     "point's whole range on a long focal length)"),
    (NO_REDUNDANCY_FORM, "no_redundancy is required of an autocalibration stage with no residual beyond its "
                         "parameters (not required: such a stage may claim determined)"),
    (RANGE_EDGE_FORM, "at_range_edge is required where the intrinsics ranges cut a K interval (not required: a K "
                      "pinned on a range's end may claim determined)"),
    (ASPECT_EDGE_FORM, "at_range_edge is required where K's aspect focal_y / focal_x lies on its range's end (not "
                       "required)"),
)


def lacked(number: int) -> list[str]:
    """The words of every rule (FORM_RULES) a document of form ``number`` is not held to."""
    return [words for first, words in FORM_RULES if number < first]

# The form estimates are computed in: today's for a writer; a verifier reading a document of an
# earlier form recomputes its estimates in that form (``reading``).
_FORM: ContextVar[int] = ContextVar("determinacy_form", default=CURRENT_FORM)


def form() -> int:
    """The number of the form estimates are computed in (CURRENT_FORM unless ``reading``)."""
    return _FORM.get()


@contextmanager
def reading(number: int):
    """Estimates computed in form ``number`` (a document of that form read again)."""
    token = _FORM.set(number)
    try:
        yield
    finally:
        _FORM.reset(token)


@dataclass
class Determinacy:
    intervals: list[dict] = field(default_factory=list)  # {name, value, lower, upper} (None: unbounded)
    warnings: list[dict] = field(default_factory=list)  # {code, detail}
    cost_increase: float | None = None  # delta
    redundancy: int = 0  # n - p: residuals beyond the parameters
    method: str = "curvature"
    proven: bool = False
    # What a certificate proves beside the estimate (proven_document): None when nothing is.
    proven_intervals: dict | None = None
    level: str | None = None  # how cost_increase was chosen, when not the default's way


    def document(self) -> dict:
        determined = all(fixes(i) for i in self.intervals)
        return {"method": self.method, "proven": self.proven or self.proven_intervals is not None,
                "proven_intervals": self.proven_intervals, "determined": determined and not self.warnings,
                "level": self.level or (f"parameters whose squared residuals exceed the optimum's by at most "
                                        f"cost_increase (max of {SIGMAS:g}^2 times the fit's residual variance and "
                                        "the certified gap), by the local curvature (Gauss-Newton)"),
                "cost_increase": _finite(self.cost_increase), "redundancy": self.redundancy,
                "intervals": self.intervals, "warnings": self.warnings}


def proven_document(cost_increase: float, names: tuple[str, ...], bounds: list[list[float]], how: str) -> dict:
    """Intervals a certificate proves: every solution of the scope whose cost is at most the
    certified optimum's plus ``cost_increase`` has each quantity within its [lower, upper]."""
    return {"cost_increase": float(cost_increase),
            "level": ("every solution in the certificate's scope whose cost exceeds the optimum's by at most "
                      f"cost_increase lies in these intervals; {how}"),
            "intervals": [{"name": name, "lower": float(lo), "upper": float(hi)}
                          for name, (lo, hi) in zip(names, bounds)]}


def fixes(interval: dict) -> bool:
    """Whether an interval fixes its quantity: bounded, and within its tolerance (when it has one)
    of the value on both sides."""
    lower, upper, value = interval["lower"], interval["upper"], interval.get("value")
    if lower is None or upper is None:
        return False
    tolerance = interval.get("tolerance")
    if tolerance is None:
        return True
    return value is not None and upper - value <= tolerance and value - lower <= tolerance


def image_scale(image_size, principal_point) -> float | None:
    """The scale of an autocalibration's principal point and skew (today's form; before
    OWN_SCALE_FORM, the focal length's, which on the dino, f 3310 px, allowed 331 px, wider than
    the principal point's whole range): half the image's larger side, from data.image_size; without
    one, the principal point range's larger width (the default range, the image's middle half, is
    half the side on each axis, so the two agree). A focal length a tenth off moves a point at the
    image's edge by a tenth of half the side: a principal point within that tolerance moves every
    point by no more. None where neither is a positive finite number."""
    if image_size is not None:
        side = 0.5 * max(float(image_size[0]), float(image_size[1]))
    else:
        try:
            side = max(float(hi) - float(lo) for lo, hi in principal_point)
        except (TypeError, ValueError):
            return None
    return side if math.isfinite(side) and side > 0 else None


def tolerance(scale: float | None) -> float | None:
    """The half-width ``determined`` allows a quantity of this scale (None: bounded suffices)."""
    return None if scale is None or not math.isfinite(scale) else RELATIVE_WIDTH * abs(float(scale))


def interval(name: str, value: float | None, lower: float | None, upper: float | None,
             scale: float | None = None) -> dict:
    """One interval as documents carry it (None ends: not fixed by the data)."""
    return {"name": name, "value": _finite(value), "lower": _finite(lower), "upper": _finite(upper),
            "tolerance": tolerance(scale)}


def clip(found: dict, lowest: float | None = None, highest: float | None = None) -> dict:
    """An interval clipped to what the scope (or physics) allows; the value is left alone, and the
    interval always holds it: an end is never moved past the value (a value beyond a bound the
    caller gives, e.g. a scope other than the one the answer was certified in, is not hidden by an
    interval with lower above upper: review 62), nor past the other end."""
    value = found.get("value")
    lower, upper = found["lower"], found["upper"]
    if lower is not None and lowest is not None:
        lower = max(lower, min(e for e in (lowest, value, upper) if e is not None))
    if upper is not None and highest is not None:
        upper = min(upper, max(e for e in (highest, value, lower) if e is not None))
    found["lower"], found["upper"] = lower, upper
    return found


# The analysis's clock: a deadline (time.monotonic) that ``tick`` reads between evaluations of a
# cost or a residual (each Jacobian column, each step of a ray), set for an analysis by ``within``.
# An analysis of many views was about 1 s of CPU past its job's time limit, unasked.
_DEADLINE: ContextVar[float | None] = ContextVar("determinacy_deadline", default=None)


class OutOfTime(Exception):
    """The analysis passed its deadline: stopped between two evaluations (``within`` answers)."""


def tick() -> None:
    """OutOfTime once the analysis's deadline has passed (nothing without one)."""
    deadline = _DEADLINE.get()
    if deadline is not None and time.monotonic() >= deadline:
        raise OutOfTime


@contextmanager
def _until(deadline: float | None):
    token = _DEADLINE.set(deadline)
    try:
        yield
    finally:
        _DEADLINE.reset(token)


def not_analysed(what: str, why: str, code: str = "time_limit") -> dict:
    """The determinacy document of an analysis not done: no interval, not determined, and a
    warning (``time_limit``: its clock ran out; ``not_analysed``: the data defeated its linear
    algebra) saying what was not analysed and why."""
    return Determinacy(warnings=[{"code": code, "detail": f"{what} was not analysed: {why}"}]).document()


def within(deadline: float | None, what: str, why: str, function, *args, **kwargs) -> dict | None:
    """``safely(function, ...)`` stopped at ``deadline`` (time.monotonic; None: no clock): past it
    before the start or during the analysis, ``not_analysed(what, why)``."""
    if deadline is not None and time.monotonic() >= deadline:
        return not_analysed(what, why)
    try:
        with _until(deadline):
            return safely(function, *args, **kwargs)
    except OutOfTime:
        return not_analysed(what, why)


def safely(function, *args, **kwargs) -> dict | None:
    """A determinacy document, or None when the data defeat the estimate's own linear algebra (it
    is an estimate beside the answer: it never fails a solve)."""
    try:
        with np.errstate(all="ignore"):
            return function(*args, **kwargs)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None


def certified_gap(cost: float | None, lower: float | None) -> float | None:
    """cost - lower_bound when both are finite numbers (None otherwise)."""
    if cost is None or lower is None or not (math.isfinite(cost) and math.isfinite(lower)):
        return None
    return max(cost - lower, 0.0)


def _finite(value: float | None) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def numeric_jacobian(function, theta: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """Central differences, the step relative to each parameter's size."""
    theta = np.asarray(theta, dtype=float)
    columns = []
    for k in range(len(theta)):
        tick()
        h = step * max(1.0, abs(theta[k]))
        e = np.zeros_like(theta)
        e[k] = h
        columns.append((np.asarray(function(theta + e)) - np.asarray(function(theta - e))) / (2 * h))
    return np.array(columns).T


def curvature_intervals(J: np.ndarray, residuals: np.ndarray, quantities: dict[str, tuple],
                        gap: float | None = None, sigmas: float = SIGMAS,
                        squared_sum: float | None = None, small_sample: bool = True) -> Determinacy:
    """Intervals for quantities (name -> (value, gradient in the parameters[, scale])) around an
    optimum with residual Jacobian J (n x p) and residuals r; ``squared_sum`` in place of the float
    r'r where the caller computes it exactly (core.exact.exact_squared_residuals)."""
    J = np.asarray(J, dtype=float)
    r = np.asarray(residuals, dtype=float)
    n, p = J.shape
    information = J.T @ J if np.all(np.isfinite(J)) else np.full((p, p), np.nan)
    total = float(r @ r) if squared_sum is None else float(squared_sum)
    return information_intervals(information, total, n - p, quantities, gap, sigmas, small_sample)


def cost_increase(cost: float, redundancy: int, gap: float | None = None, sigmas: float = SIGMAS,
                  small_sample: bool = True) -> float:
    """delta: the squared quantile (level_sigmas: the Student quantile of ``redundancy`` degrees of
    freedom as covering as ``sigmas`` standard errors) times the fit's residual variance, never
    less than the certified gap. ``small_sample`` False: ``sigmas`` itself, for a level floored by a
    pooled variance that carries its own Student quantile (a triangulation track's)."""
    factor = level_sigmas(redundancy, sigmas) if small_sample else sigmas
    delta = factor ** 2 * cost / redundancy if redundancy > 0 else 0.0
    if gap is not None and math.isfinite(gap):
        delta = max(delta, gap)
    return delta


def level_sigmas(redundancy: int, sigmas: float = SIGMAS) -> float:
    """The factor a fit's standard error is multiplied by for an interval covering as often as
    ``sigmas`` standard errors of a normal estimate (two-sided, erf(sigmas / sqrt 2): 99.73% for
    3). In today's form (STUDENT_FORM on) the variance is estimated from ``redundancy`` degrees of
    freedom, so the factor is the Student quantile of that many: 235.8 for one, 19.21 for two,
    3.96 for ten, 3.008 for a thousand (a resection from 6 points has one: with ``sigmas`` itself
    its intervals covered the truth about 85% of the time). Earlier forms: ``sigmas``. Pure Python
    (math only), so the writer and the verifier compute the same figure."""
    if form() < STUDENT_FORM or redundancy <= 0:
        return float(sigmas)
    return student_quantile(int(redundancy), math.erf(sigmas / math.sqrt(2.0)))


FEWEST_DEGREES = 2  # today's form: a level estimated from fewer degrees of freedom is never `determined`


def few_degrees(redundancy: int) -> list[dict]:
    """Today's form (STUDENT_FORM on): the ``few_degrees_of_freedom`` warning of a level estimated
    from its own residuals with fewer than FEWEST_DEGREES degrees of freedom (none otherwise, and
    none for 0: no_redundancy's). From one, the noise estimate is one residual's size, near 0 often
    enough that an interval judged narrow is narrow because the estimate is: at the Student level
    the `determined` centres of 6-point resections (one degree of freedom) still missed the truth
    5 times in 37 on the Model House at 0.1 px, where 7-point ones (three) missed 2 in 198."""
    if form() < STUDENT_FORM or not 0 < redundancy < FEWEST_DEGREES:
        return []
    return [{"code": "few_degrees_of_freedom",
             "detail": f"the noise level is estimated from {redundancy} degree of freedom (residuals beyond the "
                       "parameters): its estimate is often far below the truth, and an interval that looks narrow "
                       "may be narrow only because the estimate is, so nothing is determined. More data fix it"}]


@functools.lru_cache(maxsize=4096)
def student_quantile(dof: int, coverage: float) -> float:
    """t such that P(|T| <= t) = coverage for T Student-distributed with ``dof`` degrees of
    freedom: bisection on the two-sided tail I_{dof / (dof + t^2)}(dof / 2, 1 / 2)."""
    tail = 1.0 - coverage
    lo, hi = 0.0, 1.0
    while _student_tail(dof, hi) > tail:
        lo, hi = hi, 2.0 * hi
    for _ in range(2000):
        middle = 0.5 * (lo + hi)
        if middle in (lo, hi):
            break
        lo, hi = (middle, hi) if _student_tail(dof, middle) > tail else (lo, middle)
    return hi


def _student_tail(dof: int, t: float) -> float:
    """P(|T| > t), T Student with ``dof`` degrees of freedom."""
    return _incomplete_beta(0.5 * dof, 0.5, dof / (dof + t * t))


def _incomplete_beta(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b), by its continued fraction (Lentz), on
    the side where it converges quickly."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    front = math.exp(math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _beta_fraction(a, b, x) / a
    return 1.0 - front * _beta_fraction(b, a, 1.0 - x) / b


def _beta_fraction(a: float, b: float, x: float) -> float:
    tiny = 1e-300
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 100000):
        for numerator in (m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
                          -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))):
            d = 1.0 + numerator * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + numerator / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < 1e-16:
            break
    return h


def information_intervals(information: np.ndarray, cost: float, redundancy: int,
                          quantities: dict[str, tuple], gap: float | None = None,
                          sigmas: float = SIGMAS, small_sample: bool = True) -> Determinacy:
    """The same from J'J itself (or a Schur complement of it, for parameters of interest with the
    others eliminated), the squared residuals' sum and n - p (``small_sample``: cost_increase's)."""
    delta = cost_increase(cost, redundancy, gap, sigmas, small_sample)
    out = Determinacy(cost_increase=delta, redundancy=redundancy)
    if small_sample:
        out.warnings += few_degrees(redundancy)
    if not (np.all(np.isfinite(information)) and math.isfinite(delta)):
        for name, (value, _, *scale) in quantities.items():
            out.intervals.append(interval(name, value, None, None, *scale))
        return out
    values, vectors = np.linalg.eigh(0.5 * (information + information.T))
    largest = max(float(values[-1]), 1e-300)
    fixed = values > SINGULAR * largest
    for name, (value, gradient, *scale) in quantities.items():
        g = vectors.T @ np.asarray(gradient, dtype=float)
        free = np.abs(g[~fixed]).max(initial=0.0)
        if free > 1e-6 * max(np.abs(g).max(), 1e-300) or not math.isfinite(value):
            out.intervals.append(interval(name, value, None, None, *scale))
            continue
        # g scaled by its largest entry before it is squared: a quantity in tiny units (a centre in
        # a world unit of 1e-300) has a gradient whose square underflows to 0, which gave a width
        # of 0 beside determined true (review 61 class 2); a huge one's overflowed
        size = float(np.abs(g[fixed]).max(initial=0.0))
        half = size * math.sqrt(delta * float(np.sum((g[fixed] / size) ** 2 / values[fixed]))) if size > 0 else 0.0
        out.intervals.append(interval(name, value, value - half, value + half, *scale))
    return out


def sublevel_rays(cost, theta: np.ndarray, information: np.ndarray, limit: float, gradients: list[np.ndarray],
                  allowed=None, doublings: int = 40) -> list[np.ndarray | None]:
    """Points on the boundary of the set {cost <= limit} (the parameters within delta of the
    optimum theta), walked along rays from theta: both ways along each axis of J'J's ellipsoid and
    each gradient's extreme direction (S g, S the pseudo-inverse; a singular axis gives None both
    ways, as ``information_intervals`` leaves such a direction unbounded). Each ray starts where the
    quadratic model puts the boundary, doubles while the cost stays below the limit, then bisects;
    ``allowed(theta)`` False (outside the scope) ends a ray as the limit does. None for a ray
    still below the limit after ``doublings`` doublings (the set is unbounded that way)."""
    theta = np.asarray(theta, dtype=float)
    values, vectors = np.linalg.eigh(0.5 * (information + information.T))
    largest = max(float(values[-1]), 1e-300)
    base = float(cost(theta))
    room = max(limit - base, 0.0)
    directions: list[np.ndarray | None] = []
    for k in range(len(values)):  # a singular direction (as information_intervals judges): unbounded
        fixed = values[k] > SINGULAR * largest
        directions.append(None if not fixed else vectors[:, k] * math.sqrt(room / values[k]) if room > 0
                          else vectors[:, k] * 1e-12)
    inverse = np.linalg.pinv(information, rcond=SINGULAR, hermitian=True)
    for g in gradients:
        d = inverse @ np.asarray(g, dtype=float)
        norm = float(np.sqrt(max(d @ information @ d, 0.0)))
        if norm > 0 and np.all(np.isfinite(d)):
            directions.append(d * math.sqrt(room) / norm if room > 0 else d / norm * 1e-12)

    def inside(s, d):
        tick()
        point = theta + s * d
        if allowed is not None and not allowed(point):
            return False
        value = cost(point)
        return bool(np.isfinite(value) and value <= limit)

    points: list[np.ndarray | None] = []
    for d in directions:
        if d is None:
            points += [None, None]
            continue
        for sign in (1.0, -1.0):
            step = sign * d
            lo, hi = 0.0, 1.0
            while inside(hi, step):
                lo, hi = hi, 2.0 * hi
                if hi > 2.0 ** doublings:
                    break
            if hi > 2.0 ** doublings:
                points.append(None)
                continue
            for _ in range(30):
                middle = 0.5 * (lo + hi)
                lo, hi = (middle, hi) if inside(middle, step) else (lo, middle)
            points.append(theta + lo * step)
    return points


def ranges_at(values: np.ndarray, samples: list[np.ndarray | None]) -> tuple[np.ndarray, np.ndarray]:
    """The hull of each quantity's value and its samples (rows; a None or non-finite sample
    makes every quantity it leaves undefined unbounded): (lower, upper), NaN when unbounded."""
    values = np.asarray(values, dtype=float)
    lower, upper = values.copy(), values.copy()
    for sample in samples:
        if sample is None:
            return np.full_like(values, np.nan), np.full_like(values, np.nan)
        sample = np.asarray(sample, dtype=float)
        bad = ~np.isfinite(sample)
        lower = np.where(bad, np.nan, np.minimum(lower, sample))
        upper = np.where(bad, np.nan, np.maximum(upper, sample))
    return lower, upper


def spread(points: np.ndarray) -> np.ndarray:
    """Singular values of the centred points over the largest (1, then smaller: how flat they are)."""
    points = np.asarray(points, dtype=float)
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return s / max(float(s[0]), 1e-300)
