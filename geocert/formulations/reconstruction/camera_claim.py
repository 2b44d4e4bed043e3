"""What a certified camera of a reconstruction claims, stated once for the pipeline and the
verifier (numpy only).

The certified resection (thesis 5.5.2) proves a lower bound on the cost of every 3x4 camera that
puts the camera's points in front of it: 11 degrees of freedom. A returned camera P = K [R | t]
has fewer of its own: its pose (6), plus the intrinsics the cameras do not share (the "varying"
model's focal length: 7). Even the true camera therefore costs more than the 11-parameter optimum,
by the part of the noise the d = 11 - dof extra parameters fit: with Gaussian pixel noise and the
L2L2 cost, cost_returned - cost_free ~ sigma^2 chi^2(d) and cost_free ~ sigma^2 chi^2(2N - 11) for
N points, so the returned camera's excess over the free one is about d / (2N - 11) of the cost
(5 / 389 = 1.3% for 200 points, above a 1% gap: why no camera was certified against the bound
alone). The L1 costs (L2L1, L1L1) are maximum likelihood under Laplace noise, where twice the
excess over the noise's scale is chi^2(d) and the cost is about 2N - 11 scales: half the fraction.

A camera is certified when

    cost <= (1 + tolerance) * lower_bound + abs_gap,
    1 + tolerance = (1 + allowance) / (1 - camera_rel_gap),
    allowance = CHI2_999[d] / (k * (2N - 11)),   k = 1 for L2L2, 2 for L2L1 and L1L1,

lower_bound the certified resection's proven bound on every 3x4 camera putting the points in
front: the returned camera fits its points as well as the best 3x4 camera does, up to what its
d missing degrees of freedom explain at the 99.9% level (the chi-square test of the returned
camera against the free one) and the search's own gap. Where the allowance would exceed
MAX_ALLOWANCE (fewer than 26 points for a shared K under L2L2: so few points cannot tell a sound
camera from a wrong one by a ratio of costs) it is withheld (0): the camera is then certified
only as a 3x4 camera would be, against the bound and the search's gap alone (exact data are).
``dof`` is read from the cameras returned (``degrees_of_freedom``), so a verifier recomputes
every figure from the result.

Observations the returned camera misses by more than OUTLIER_SCALES noise scales (the scale read
from its median residual length, as a 2D Gaussian's: median = sigma sqrt(2 ln 2)) are outliers a
Gaussian would put there with probability exp(-OUTLIER_SCALES^2 / 2) = 1e-14: a camera whose
certificate fails on all its points is resected again without them (at most MAX_SET_ASIDE of its
points, and never a point behind it), and states how many it set aside (``set_aside``). The rule
is recomputed from the returned camera and points, so a verifier rebuilds the same map; a camera
stating 0 (or nothing, before the rule) is certified on all its points."""

from __future__ import annotations

import math

import numpy as np
from geocert.formulations.fractional.options import MAX_ABS_GAP as RESIDUAL_MAX_ABS_GAP

# Chi-square quantiles at 0.999 for 1 to 5 degrees of freedom (scipy.stats.chi2.ppf(0.999, d)).
CHI2_999 = {1: 10.828, 2: 13.816, 3: 16.266, 4: 18.467, 5: 20.515}
PROJECTIVE_DOF = 11  # a 3x4 camera up to scale
MIN_POINTS = 6  # fewer cannot fix a 3x4 camera: such a camera is not searched (status degenerate)
POSE_DOF = 6
MAX_ALLOWANCE = 0.5
# The loosest gaps a reconstruction's certified claims may be made with: a camera or a point
# "certified" at camera_rel_gap 0.999 or abs_gap 1e6 would be certified whatever it costs. With
# these, a certified camera costs at most 2 (1 + allowance) times its bound plus 1e-4 (px^2 under
# L2L2, px under the L1 norms): abs_gap is the residual kinds' (fractional.options.MAX_ABS_GAP),
# as the points and cameras are certified by triangulation and resection certificates.
MAX_REL_GAP = 0.5
MAX_ABS_GAP = RESIDUAL_MAX_ABS_GAP
# A reconstruction is doubtful as a whole (the pipeline's claims._doubts, the verifier's check of
# summary.doubtful) when more than these shares of its bounded cameras are not certified, of its
# observations were rejected, or of its registered cameras were dropped.
# A view's own principal point (principal_point "per_view") is kept only when the data fix each to
# this standard deviation, px (the pipeline's test; the verifier ties the test's record to it): the
# shifts it is meant to capture (Sceaux's stabilised lens) are 3-21 px, and a principal point known
# to worse than this cannot tell such a shift from a small rotation of its view (templeSparseRing's,
# fixed to 8-17 px, moved its rotations 1.4 degrees off the ground truth).
MAX_PRINCIPAL_POINT_SD_PX = 5.0
# A view's own focal length (principal_point "per_view", beside its principal point) is kept only
# when the data fix each to this fraction of it (standard deviation): Sceaux Castle's stands apart
# by 2% and is fixed to 0.2%.
MAX_FOCAL_SD_FRACTION = 0.01
# The levels of the camera model's tests (the pipeline runs them; the verifier recomputes their
# thresholds from these, never reading the document's): the shared principal point's chi-square
# quantile for its 2 parameters at 0.999; the per-view principal points' level; the focal length
# test's level (its screen's over the views, Bonferroni's, and its chi-square's).
PRINCIPAL_POINT_CHI2 = 13.8


def in_middle_half(u: float, v: float, width: float, height: float) -> bool:
    """Whether a principal point (u, v) lies in the middle half of a width x height image, the
    registration's and the adjustment's test keeps an estimate only there (|u - w/2| <= w/4 and
    |v - h/2| <= h/4); the pipeline and the verifier judge it with these same float operations."""
    return bool(abs(u - width / 2) <= width / 4 and abs(v - height / 2) <= height / 4)
# The radial term k1's chi-square quantile for its 1 parameter at 0.999 (the pipeline's
# _radial_test with K unknown and _fixed_radial_test with K known; the verifier reads a K-known
# term's test against it).
RADIAL_CHI2 = 10.8
PRINCIPAL_POINT_P = 0.001
FOCAL_P = 0.001
DOUBTFUL_FRACTION = 0.5
DOUBTFUL_REMOVED = 0.25
DOUBTFUL_DROPPED = 0.25
OUTLIER_SCALES = 8.0
MAX_SET_ASIDE = 0.05  # of a camera's points: more misses than this are the camera's, not outliers
RAYLEIGH_MEDIAN = math.sqrt(2.0 * math.log(2.0))  # a 2D Gaussian residual's median length over sigma
SAME = 1e-9  # relative: intrinsics equal up to JSON round trips are shared
# relative: a free 3x4 camera judges a camera uncertifiable only when it beats it by more than its
# tolerance with this to spare on its own cost, so that the verifier, recomputing both costs from
# the numbers returned (to 1e-9 of them), judges the same
JUDGED_MARGIN = 1e-6


def _intrinsics(K) -> np.ndarray:
    """(focal, aspect, skew, u, v) of a K (K[2][2] = 1)."""
    K = np.asarray(K, dtype=float)
    return np.array([K[0, 0], K[1, 1] / K[0, 0], K[0, 1], K[0, 2], K[1, 2]])


def degrees_of_freedom(Ks: list) -> int:
    """A returned camera's own degrees of freedom: its pose (6) plus one per intrinsic (focal,
    aspect, skew, principal point u and v) that is not the same in every registered camera's K
    (a shared K is fitted to every view, not to one camera)."""
    if not Ks:
        return POSE_DOF
    values = np.array([_intrinsics(K) for K in Ks])
    focal = max(float(np.abs(values[:, 0]).max()), 1.0)
    scales = np.array([focal, 1.0, focal, focal, focal])  # pixels against the focal length; the aspect is a ratio
    varying = np.any(np.abs(values - values[0]) > SAME * scales, axis=0)
    return POSE_DOF + int(varying.sum())


def model_allowance(points: int, dof: int, norm: str) -> float | None:
    """The excess over the 11-parameter optimum the returned camera's fewer degrees of freedom
    explain (module docstring), before MAX_ALLOWANCE; None when the points cannot carry the
    comparison (2N - 11 < 1)."""
    residual_dof = 2 * points - PROJECTIVE_DOF
    if residual_dof < 1:
        return None
    d = PROJECTIVE_DOF - dof
    if d <= 0:
        return 0.0
    return CHI2_999[min(d, 5)] / ((1.0 if norm == "L2L2" else 2.0) * residual_dof)


def allowance(points: int, dof: int, norm: str) -> float | None:
    """The allowance a camera is given: model_allowance, withheld (0) above MAX_ALLOWANCE."""
    extra = model_allowance(points, dof, norm)
    return None if extra is None else 0.0 if extra > MAX_ALLOWANCE else extra


def tolerance(points: int, dof: int, norm: str, rel_gap: float) -> float | None:
    """The relative tolerance of a camera seeing ``points`` points, with ``dof`` of its own,
    against the resection's bound proven to ``rel_gap``; None when it cannot be certified
    (fewer than 6 points, or a gap beyond MAX_REL_GAP)."""
    extra = allowance(points, dof, norm)
    if extra is None or not 0 <= rel_gap <= MAX_REL_GAP:
        return None
    return (1.0 + extra) / (1.0 - rel_gap) - 1.0


def within(cost: float, lower_bound: float, tolerance_: float, abs_gap: float) -> bool:
    """The certified camera's inequality: cost <= (1 + tolerance) * lower_bound + abs_gap."""
    return bool(math.isfinite(cost) and cost <= (1.0 + tolerance_) * lower_bound + abs_gap)


def outliers(source, target, matrix) -> np.ndarray | None:
    """The observations the rule sets aside for camera ``matrix`` (module docstring) as a mask over
    its map (source points, target pixels); None when it sets none aside: none beyond
    OUTLIER_SCALES scales, more than MAX_SET_ASIDE of them, a point behind the camera among them,
    or fewer than MIN_POINTS left."""
    X = np.asarray(source, dtype=float).reshape(-1, 3)
    x = np.asarray(target, dtype=float).reshape(-1, 2)
    if len(X) < MIN_POINTS:
        return None
    with np.errstate(all="ignore"):
        projected = np.hstack([X, np.ones((len(X), 1))]) @ np.asarray(matrix, dtype=float).T
        lengths = np.linalg.norm(x - projected[:, :2] / projected[:, 2:3], axis=1)
        scale = float(np.median(lengths)) / RAYLEIGH_MEDIAN
        beyond = ~(lengths <= OUTLIER_SCALES * scale)  # a NaN length (a point at depth 0) too
    count = int(beyond.sum())
    if (count == 0 or count > MAX_SET_ASIDE * len(X) or len(X) - count < MIN_POINTS
            or not np.all(projected[beyond, 2] > 0)):
        return None
    return beyond


def kept(source: list, target: list, matrix, set_aside: int | None) -> tuple[list, list] | None:
    """The map a camera stating ``set_aside`` is certified on: all of it for 0 or None, the rule's
    kept observations when it is the rule's count; None for any other number (refused)."""
    if not set_aside:
        return source, target
    beyond = outliers(source, target, matrix)
    if beyond is None or int(beyond.sum()) != set_aside:
        return None
    return ([s for s, out in zip(source, beyond) if not out], [t for t, out in zip(target, beyond) if not out])


def statement(norm: str, rel_gap: float, set_aside: bool = False) -> str:
    """What "certified" says of a camera, in words (the result's cameras stage and summary);
    ``set_aside`` False (the default): the words before the outlier rule, for results whose
    cameras state no set_aside; the pipeline states it."""
    k = "" if norm == "L2L2" else "2 * "
    aside = (f"; a camera not certified on all its points is resected again without the observations it misses by "
             f"more than {OUTLIER_SCALES:g} noise scales (read from its median residual), at most "
             f"{MAX_SET_ASIDE:.0%} of them, and its claim is then about the points kept (it states how many it set "
             "aside)") if set_aside else ""
    return (f"a certified camera's cost on its points is at most (1 + tolerance) times the lower bound the certified "
            f"resection proves for every 3x4 camera putting those points in front (plus abs_gap); 1 + tolerance = "
            f"(1 + allowance) / (1 - camera_rel_gap {rel_gap:g}), allowance = chi2_0.999(11 - degrees_of_freedom) / "
            f"({k}(2 * points - 11)): what the returned camera's fewer degrees of freedom (its pose, plus the "
            f"intrinsics the cameras do not share) cost at the 99.9% level, not an error in it; withheld (0) where "
            f"it would exceed {MAX_ALLOWANCE:g}" + aside)


def sources(points, views: list[int]) -> list[tuple[list, list]]:
    """Each view's resection data: (source points, target pixels) from every observation in that
    view of a certified finite point, in the points' order. ``points``: (point, at_infinity,
    certified, observations) per returned point, observations [view, u, v]. Only certified
    points: an uncertified point's position is backed by no proof, and a camera fitted to points
    placed on its own rays would fit them exactly, whatever its pose."""
    found = {view: ([], []) for view in views}
    for point, at_infinity, certified, observations in points:
        if point is None or at_infinity or certified is not True:
            continue
        source = [float(c) for c in point]
        for view, u, v in observations or []:
            if int(view) in found:
                found[int(view)][0].append(list(source))
                found[int(view)][1].append([u, v])
    return [found[view] for view in views]
