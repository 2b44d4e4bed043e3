"""A floor under the pooled cost increase the triangulation kind reads its determinacy at
(determinacy.pooled_increase), recomputed by the verifier from the residuals of the tracks a
document says were pooled, numpy only (docs/certificate.md, "The pooled level").

pooled_increase takes, over a pool's tracks of d_i = 2 n_i - 3 degrees of freedom and squared
residuals c_i: a first variance, the median of c_i / m(d_i) (m the chi-square's median); the
tracks with c_i at most q(d_i) times it (q its 99.9% point); their pooled variance V = sum c / sum
d over D = sum d degrees of freedom; and t(D)^2 V, t the Student quantile at 3 standard errors'
coverage. Its quantiles are scipy's. Here they are bounded instead, never exceeding the genuine
level: m and q from the chi-square's closed form within CHI2_ROUNDING either side for every track
length a job may have (chi_square_points; beyond, by the Wilson-Hilferty approximation within
CHI2_MARGIN, which tests/verify/test_pooled_floor.py checks against scipy's quantiles), so each
track is surely pooled, surely left out, or (within that rounding of the cut) either; V by the smallest
variance any such choice gives; and t(D) at the largest D: up to EXACT_STUDENT_DOF computed from
the distribution's closed form, a relative STUDENT_ROUNDING below it; beyond, by the first two
terms of its Cornish-Fisher expansion, z + (z^3 + z) / (4 D), below the quantile for every D and
within 2e-8 of it there (the same test checks both against scipy's)."""

from __future__ import annotations

import functools
import math

import numpy as np

from geocert.core.determinacy import SIGMAS
from geocert.core.strict import charge

# The normal quantiles of the chi-square's 99.9% point (determinacy.OUTLIER_TAIL) and of 3
# standard errors' two-sided coverage (determinacy.COVERAGE).
Z_OUTLIER = 3.090232306167813
OUTLIER_TAIL = 1e-3  # determinacy.OUTLIER_TAIL (the verifier imports no solver's module here)
Z_COVERAGE = SIGMAS
# How far the Wilson-Hilferty quantiles may be from the chi-square's for 1 degree of freedom and
# more (3.4% at most, for the median of 1).
CHI2_MARGIN = 0.05


def wilson_hilferty(dof: np.ndarray, z: float) -> np.ndarray:
    """The chi-square quantile of ``dof`` degrees of freedom at the normal quantile ``z``, by
    Wilson and Hilferty's cube-root approximation."""
    k = np.asarray(dof, dtype=float)
    return k * (1.0 - 2.0 / (9.0 * k) + z * np.sqrt(2.0 / (9.0 * k))) ** 3


# The degrees of freedom up to which chi_square_points computes the chi-square's median and 99.9%
# point from its closed form (every track a job may have: 2 n - 3 for n up to verify.fractional's
# MAX_VIEWS), each a relative CHI2_ROUNDING either side; beyond, Wilson-Hilferty's within
# CHI2_MARGIN. Wilson-Hilferty's 5% alone let a track just inside the writer's cut be read as
# possibly left out, and the floor drop it: one 2-view track of five at the cut put the floor at
# 0.18 of the writer's level (review 51).
EXACT_CHI2_DOF = 2000
CHI2_ROUNDING = 1e-9


def chi_square_survival(x: float, dof: int) -> float:
    """P(X > x) for a chi-square X of ``dof`` (an integer >= 1) degrees of freedom, from its closed
    form: for even dof, exp(-x/2) times the sum over j < dof/2 of (x/2)^j / j!; for odd dof,
    erfc(sqrt(x/2)) plus sqrt(2/pi) exp(-x/2) times the sum over 1 <= j <= (dof-1)/2 of
    x^(j-1/2) / (1.3...(2j-1)). Sums of positive terms, added in logarithms (no overflow)."""
    if not x > 0:
        return 1.0
    half = 0.5 * x
    if dof % 2 == 0:
        j = np.arange(dof // 2, dtype=float)
        logs = -half + j * math.log(half) - np.concatenate([[0.0], np.cumsum(np.log(j[1:]))])
        top = float(logs.max())
        return math.exp(top) * float(np.exp(logs - top).sum())
    tail = math.erfc(math.sqrt(half))
    if dof == 1:
        return tail
    j = np.arange(1, (dof - 1) // 2 + 1, dtype=float)
    logs = (0.5 * math.log(2.0 / math.pi) - half + (j - 0.5) * math.log(x)
            - np.cumsum(np.log(2.0 * j - 1.0)))
    top = float(logs.max())
    return tail + math.exp(top) * float(np.exp(logs - top).sum())


@functools.lru_cache(maxsize=4096)
def chi_square_quantile(dof: int, tail: float) -> float:
    """The x with P(X > x) = ``tail`` for a chi-square of ``dof`` degrees of freedom, by
    bisection on chi_square_survival (which decreases with x) to 1e-14 of it, from Wilson and
    Hilferty's approximation's CHI2_MARGIN either side (widened where that does not hold it)."""
    guess = float(wilson_hilferty(np.array([float(dof)]), math.sqrt(2.0) * _erfc_inverse(2.0 * tail))[0])
    low, high = guess * (1.0 - CHI2_MARGIN), guess * (1.0 + CHI2_MARGIN)
    while low > 0 and chi_square_survival(low, dof) <= tail:
        low *= 0.5
    while chi_square_survival(high, dof) > tail:
        high *= 2.0
    for _ in range(400):
        middle = 0.5 * (low + high)
        if high - low <= 1e-14 * high:
            break
        if chi_square_survival(middle, dof) > tail:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high)


def _erfc_inverse(y: float) -> float:
    """z with erfc(z) = y, by bisection (only to start chi_square_quantile's)."""
    low, high = -10.0, 10.0
    for _ in range(100):
        middle = 0.5 * (low + high)
        if math.erfc(middle) > y:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high)


def chi_square_points(dofs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each track's chi-square median and 99.9% point (OUTLIER_TAIL) and the relative margin each
    is known to: from the closed form to CHI2_ROUNDING up to EXACT_CHI2_DOF degrees of freedom,
    else Wilson-Hilferty's to CHI2_MARGIN."""
    dofs = np.asarray(dofs, dtype=float)
    median, tail = wilson_hilferty(dofs, 0.0), wilson_hilferty(dofs, Z_OUTLIER)
    margin = np.full(len(dofs), CHI2_MARGIN)
    for k in np.unique(dofs):
        if 1 <= k <= EXACT_CHI2_DOF and float(k).is_integer():
            at = dofs == k
            median[at] = chi_square_quantile(int(k), 0.5)
            tail[at] = chi_square_quantile(int(k), OUTLIER_TAIL)
            margin[at] = CHI2_ROUNDING
    return median, tail, margin


def student_floor(dof: float) -> float:
    """A value at most the Student quantile at 3 standard errors' two-sided coverage for ``dof``
    degrees of freedom: up to EXACT_STUDENT_DOF, the quantile itself (student_quantile, from the
    distribution's closed form), less STUDENT_ROUNDING of it; beyond, Cornish-Fisher's first two
    terms, within 2e-8 of it there. The two terms alone gave at 4 degrees of freedom 4.9 for 6.6,
    so that a small pool's level stated at 0.55 of the writer's (each interval 0.74 of its width)
    verified (review 51)."""
    if 1 <= dof <= EXACT_STUDENT_DOF and float(dof).is_integer():
        return student_quantile(int(dof)) * (1.0 - STUDENT_ROUNDING)
    z = Z_COVERAGE
    return z + (z ** 3 + z) / (4.0 * dof)


# The degrees of freedom up to which student_floor computes the quantile from the closed form (a
# sum of dof / 2 terms, each bisection step); and how far below it the floor is put: the sum's
# rounding (some dof ulps of the coverage, 1e-12 at EXACT_STUDENT_DOF) moves the quantile by that
# over the density there (about 1e-10 of it), far below this and far below what a forger gains.
EXACT_STUDENT_DOF = 20000
STUDENT_ROUNDING = 1e-8


def student_coverage(t: float, dof: int) -> float:
    """P(|T| <= t) for Student's T of ``dof`` (an integer >= 1) degrees of freedom: the closed
    form (Abramowitz and Stegun 26.7.3 and 26.7.4), with theta = atan(t / sqrt(dof))."""
    theta = math.atan(t / math.sqrt(dof))
    c2 = math.cos(theta) ** 2
    if dof % 2 == 0:  # sin(theta) (1 + 1/2 c^2 + 1.3/(2.4) c^4 + ... up to c^(dof-2))
        k = np.arange(1, dof // 2, dtype=float)
        return math.sin(theta) * (1.0 + float(np.cumprod((2 * k - 1) / (2 * k) * c2).sum()))
    if dof == 1:
        return 2.0 * theta / math.pi
    k = np.arange(1, (dof - 1) // 2, dtype=float)  # 2/pi (theta + sin cos (1 + 2/3 c^2 + 2.4/(3.5) c^4 + ...))
    series = 1.0 + float(np.cumprod(2 * k / (2 * k + 1) * c2).sum())
    return 2.0 / math.pi * (theta + math.sin(theta) * math.cos(theta) * series)


@functools.lru_cache(maxsize=256)
def student_quantile(dof: int) -> float:
    """The Student quantile at 3 standard errors' two-sided coverage for ``dof`` degrees of
    freedom, by bisection on student_coverage (which increases with t) to a few ulps."""
    coverage = math.erf(Z_COVERAGE / math.sqrt(2.0))
    low, high = Z_COVERAGE, 2.0 * Z_COVERAGE  # the quantile is above the normal's
    while student_coverage(high, dof) < coverage:
        low, high = high, 2.0 * high
    for _ in range(200):
        middle = 0.5 * (low + high)
        if middle <= low or middle >= high:
            break
        if student_coverage(middle, dof) < coverage:
            low = middle
        else:
            high = middle
    return low


def pooled_floor(costs: np.ndarray, dofs: np.ndarray) -> float | None:
    """At most the cost increase pooled_increase gives tracks of squared residuals ``costs`` and
    degrees of freedom ``dofs`` (as above); None where it gives none."""
    bounds = pooled_bounds(costs, dofs)
    return None if bounds is None else bounds[0]


# What the quantiles cost, charged to the verification's budget (strict.charge, a unit about a
# microsecond of CPU here) before they are computed: each is a bisection of about QUANTILE_STEPS
# evaluations of a sum of dof / 2 terms (chi_square_survival, student_coverage: some 8 units an
# evaluation and a unit per TERMS_PER_UNIT terms). Unpaid, a document stating a track of every
# length up to 1,000 views, or pools of many degrees of freedom each (the Student quantile's cache
# keeps 256), asked for seconds of CPU its size did not pay for. The cache's values are charged as
# if computed, once a document (pooled_bounds' ``paid``), so a verdict does not depend on what
# the process verified before.
QUANTILE_STEPS = 60
EVALUATION_UNITS = 8
TERMS_PER_UNIT = 256


def quantile_work(dof: float) -> int:
    """The work units one quantile computed from the closed form at ``dof`` degrees of freedom
    costs (QUANTILE_STEPS evaluations of a sum of dof / 2 terms)."""
    return QUANTILE_STEPS * (EVALUATION_UNITS + int(dof) // TERMS_PER_UNIT)


def charge_quantiles(dofs: np.ndarray, most: float | None, paid: set) -> None:
    """Charge (strict.charge) the closed-form quantiles pooled_bounds reads: each track length's
    two chi-square points for tracks of ``dofs`` degrees of freedom (chi_square_points) and the
    Student quantile at ``most`` (student_floor; None, none), each not in ``paid`` (a document's,
    which they are added to)."""
    work = 0
    for k in np.unique(np.asarray(dofs, dtype=float)):
        if 1 <= k <= EXACT_CHI2_DOF and float(k).is_integer() and ("chi2", k) not in paid:
            paid.add(("chi2", k))
            work += 2 * quantile_work(k)
    if most is not None and 1 <= most <= EXACT_STUDENT_DOF and float(most).is_integer() and ("t", most) not in paid:
        paid.add(("t", most))
        work += quantile_work(most)
    if work:
        charge(work, "the pooled level's chi-square and Student quantiles")


def pooled_bounds(costs: np.ndarray, dofs: np.ndarray, paid: set | None = None) -> tuple[float, int, int] | None:
    """(floor, least, most): pooled_floor's floor, and the least and most degrees of freedom D
    pooled_increase may pool of these tracks (the sum over the tracks surely pooled; over those
    surely or possibly pooled), between which the D a pooled level states must lie: a level's
    degrees of freedom are its pool's, not the document's word (review 49). None where
    pooled_increase gives no level. ``paid``: the quantiles this document has paid for
    (charge_quantiles; None, a set of its own)."""
    dof = np.asarray(dofs, dtype=float)
    cost = np.asarray(costs, dtype=float)
    use = (dof > 0) & np.isfinite(cost)
    dof, cost = dof[use], cost[use]
    if not len(cost):
        return None
    paid = set() if paid is None else paid
    charge_quantiles(dof, None, paid)
    median, tail, margin = chi_square_points(dof)
    first_low = float(np.median(cost / (median * (1 + margin))))
    first_high = float(np.median(cost / (median * (1 - margin))))
    if not first_high > 0:
        return None
    sure = cost <= tail * (1 - margin) * first_low
    either = ~sure & (cost <= tail * (1 + margin) * first_high)
    total, degrees = float(cost[sure].sum()), float(dof[sure].sum())
    for k in np.flatnonzero(either)[np.argsort(cost[either] / dof[either], kind="stable")]:
        if degrees == 0 or cost[k] / dof[k] < total / degrees:  # pooling it lowers the variance
            total, degrees = total + float(cost[k]), degrees + float(dof[k])
    if degrees == 0:
        return None
    most = float(dof[sure | either].sum())
    charge_quantiles(np.zeros(0), most, paid)
    t = student_floor(most)
    return t * t * total / degrees, int(dof[sure].sum()), int(most)


def squared_residuals(cameras: np.ndarray, views: list, points: np.ndarray, point) -> float:
    """A track's squared residuals at its returned point (math.inf where it projects to none)."""
    with np.errstate(all="ignore"):
        proj = np.asarray(cameras, dtype=float)[views] @ np.append(np.asarray(point, dtype=float), 1.0)
        cost = float(np.sum((proj[:, :2] / proj[:, 2:3] - np.asarray(points, dtype=float)) ** 2))
    return cost if math.isfinite(cost) else math.inf
