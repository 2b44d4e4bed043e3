"""A floor under the pooled cost increase the triangulation kind reads its determinacy at
(determinacy.pooled_increase), recomputed by the verifier from the residuals of the tracks a
document says were pooled, numpy only (docs/certificate.md, "The pooled level").

pooled_increase takes, over a pool's tracks of d_i = 2 n_i - 3 degrees of freedom and squared
residuals c_i: a first variance, the median of c_i / m(d_i) (m the chi-square's median); the
tracks with c_i at most q(d_i) times it (q its 99.9% point); their pooled variance V = sum c / sum
d over D = sum d degrees of freedom; and t(D)^2 V, t the Student quantile at 3 standard errors'
coverage. Its quantiles are scipy's. Here they are bounded instead, never exceeding the genuine
level: m and q by the Wilson-Hilferty approximation within CHI2_MARGIN either side (tests/solvers/
test_pooled_floor.py checks those bounds hold against scipy's quantiles for every track length a
job may have), so each track is surely pooled, surely left out, or either; V by the smallest
variance any such choice gives; and t(D) at the largest D: up to EXACT_STUDENT_DOF computed from
the distribution's closed form, a relative STUDENT_ROUNDING below it; beyond, by the first two
terms of its Cornish-Fisher expansion, z + (z^3 + z) / (4 D), below the quantile for every D and
within 2e-8 of it there (the same test checks both against scipy's)."""

from __future__ import annotations

import functools
import math

import numpy as np

from geocert.core.determinacy import SIGMAS

# The normal quantiles of the chi-square's 99.9% point (determinacy.OUTLIER_TAIL) and of 3
# standard errors' two-sided coverage (determinacy.COVERAGE).
Z_OUTLIER = 3.090232306167813
Z_COVERAGE = SIGMAS
# How far the Wilson-Hilferty quantiles may be from the chi-square's for 1 degree of freedom and
# more (3.4% at most, for the median of 1).
CHI2_MARGIN = 0.05


def wilson_hilferty(dof: np.ndarray, z: float) -> np.ndarray:
    """The chi-square quantile of ``dof`` degrees of freedom at the normal quantile ``z``, by
    Wilson and Hilferty's cube-root approximation."""
    k = np.asarray(dof, dtype=float)
    return k * (1.0 - 2.0 / (9.0 * k) + z * np.sqrt(2.0 / (9.0 * k))) ** 3


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


def pooled_bounds(costs: np.ndarray, dofs: np.ndarray) -> tuple[float, int, int] | None:
    """(floor, least, most): pooled_floor's floor, and the least and most degrees of freedom D
    pooled_increase may pool of these tracks (the sum over the tracks surely pooled; over those
    surely or possibly pooled), between which the D a pooled level states must lie: a level's
    degrees of freedom are its pool's, not the document's word (review 49). None where
    pooled_increase gives no level."""
    dof = np.asarray(dofs, dtype=float)
    cost = np.asarray(costs, dtype=float)
    use = (dof > 0) & np.isfinite(cost)
    dof, cost = dof[use], cost[use]
    if not len(cost):
        return None
    median = wilson_hilferty(dof, 0.0)
    first_low = float(np.median(cost / (median * (1 + CHI2_MARGIN))))
    first_high = float(np.median(cost / (median * (1 - CHI2_MARGIN))))
    if not first_high > 0:
        return None
    tail = wilson_hilferty(dof, Z_OUTLIER)
    sure = cost <= tail * (1 - CHI2_MARGIN) * first_low
    either = ~sure & (cost <= tail * (1 + CHI2_MARGIN) * first_high)
    total, degrees = float(cost[sure].sum()), float(dof[sure].sum())
    for k in np.flatnonzero(either)[np.argsort(cost[either] / dof[either], kind="stable")]:
        if degrees == 0 or cost[k] / dof[k] < total / degrees:  # pooling it lowers the variance
            total, degrees = total + float(cost[k]), degrees + float(dof[k])
    if degrees == 0:
        return None
    most = float(dof[sure | either].sum())
    t = student_floor(most)
    return t * t * total / degrees, int(dof[sure].sum()), int(most)


def squared_residuals(cameras: np.ndarray, views: list, points: np.ndarray, point) -> float:
    """A track's squared residuals at its returned point (math.inf where it projects to none)."""
    with np.errstate(all="ignore"):
        proj = np.asarray(cameras, dtype=float)[views] @ np.append(np.asarray(point, dtype=float), 1.0)
        cost = float(np.sum((proj[:, :2] / proj[:, 2:3] - np.asarray(points, dtype=float)) ** 2))
    return cost if math.isfinite(cost) else math.inf
