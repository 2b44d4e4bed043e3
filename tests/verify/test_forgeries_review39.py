"""Review 39: a hostile review of core.exact's callers (checks._check_residual_claim: the float path
where exact.needs_exact says the floats' rounding cannot move the cost), fractional.MapItems.
check_returned, and the track and homography estimates' checks.

Found:

1. A solution in subnormal numbers takes the float path with no uncertainty. exact.needs_exact
   reads proof.residual_uncertainty, 1e-15 of the products' magnitudes over the depth: relative
   only, with no term for underflow. A point at infinity (4-vector, last coordinate 0) or a
   homography's matrix is read as the document writes it, at any positive scale, and nothing
   rescales it (cameras are: geometry.normalised_cameras). Written as integers times 2^-1074, every
   product behind the projection is subnormal and rounds to a multiple of 2^-1074, up to a third
   of itself, while the uncertainty underflows to 0: needs_exact says the floats serve, and
   _check_residual_claim holds the claim to this machine's float cost. A forger chooses the
   observations (or targets) to be the float image: cost 0, trivial bound, certified optimal.
   (a) triangulation, point at infinity (3, 5, 40, 0) * 1000 * 2^-1074, three cameras K [R | -R C]:
   the exact cost of the direction stated is above 1 px^2 (measured 87.4 here), and the solver's
   own certificate on the same data proves a lower bound above 1 (49.6): "optimal at 0" is false.
   (b) homography, its matrix rounded to integers times 2^-1074 (largest 1000): the exact cost is
   5.8e-6, the solver's own lower bound on the data 4.85e-6, 48 times abs_gap; claimed 0,
   trivial bound: the certificate verifies, and so does the full result with the exact residuals
   stated (check_returned holds them to the exact ones) and its determinacy left out (None).
   (c) resection alike (review 35's K [I | 0], 12 points): the camera's exact cost is 1.5e4
   px^2, the solver's own lower bound on the data 7.6e3 px^2; claimed 0, both verify.
   (d) a finite point: three cameras K R_i [I | 0] sharing their centre at the origin (a rotating
   camera), the point (3, 5, 40) * 1000 * 2^-1074 in front of them: exact cost 81.5 px^2 (the
   solver's own best point 81.2, uncertified), claimed 0: verifies. Rescaling the solution alone
   does not reach this one (its last coordinate is 1).
   At fault: geocert/formulations/fractional/proof.py:residual_uncertainty (no absolute term for
   underflow) as exact.needs_exact reads it in geocert/verify/checks.py:_check_residual_claim; the
   solutions read unscaled (items.TrackItem.solution for a point at infinity, MapItem.solution).
   Suggested fix at the cause: give residual_uncertainty an absolute term for underflow (each
   product's half of 2^-1074, a few 2^-1074 over the depth), or take the exact path wherever a
   projection's terms are below the normal range (2^-1022 times a margin), in the objective check,
   the stacked check (formulations/fractional/stacked.py _check_group), fractional._stated_figure and
   MapItems.check_returned alike; and read a homogeneous solution (a point at infinity, a map's
   matrix) scaled by a power of two to its largest entry near 1, as normalised_cameras does
   cameras (the exact residuals do not change).

Fixed at the cause: proof.image_uncertainty (which residual_uncertainty and the convexity path
read) adds 4 LEAST_SUBNORMAL (2^-1074) per product of numerator and depth over the depth and the
quotient's own LEAST_SUBNORMAL: on normal numbers nothing changes, and below the normal range the
uncertainty covers the products' real rounding (tested here against the exact residuals), so
needs_exact sends these claims down the exact path, where all four are refused at "objective".

Seen, no forgery (fixed: the spread is then the cap): fractional.estimates._map_cost_spread divides by the float cost, a Python float:
a map whose float residuals are all exactly 0 (cost 0.0) with a determinacy stated is refused with
"ZeroDivisionError: float division by zero" (a crash read as a failure, not a reason); the writer
never returned such a map here (integer exact data: 4.5e-28).
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import rehash

SUBNORMAL = 5e-324  # 2^-1074, the least subnormal


def _verify(document: dict):
    return verify_any(json.loads(json.dumps(document)))


def _rotation(vector: np.ndarray) -> np.ndarray:
    """Rodrigues' rotation by ``vector`` (axis times angle)."""
    angle = float(np.linalg.norm(vector))
    k = vector / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _cameras() -> np.ndarray:
    """Three cameras K [R | -R C] 1 apart, slightly rotated, each scaled to its largest entry 1
    (as normalised_cameras would leave them: no entry near a limit)."""
    rng = np.random.default_rng(1)
    K = np.array([[800.3, 0, 320.1], [0, 799.7, 240.2], [0, 0, 1]])
    cameras = []
    for i in range(3):
        R = _rotation(rng.normal(0, 0.05, 3))
        P = K @ np.hstack([R, -(R @ np.array([i - 1.0, 0.3 * i, 0.0]))[:, None]])
        cameras.append(P / np.abs(P).max())
    return np.array(cameras)


# Class 1 (a): a point at infinity in subnormal numbers

DIRECTION = np.array([3.0, 5.0, 40.0, 0.0]) * 1000 * SUBNORMAL


def _subnormal_track_certificate() -> dict:
    """A triangulation certificate of one track whose observations are this machine's float image
    of DIRECTION (the verifier's own projection), claiming DIRECTION at cost 0 by the trivial bound."""
    from geocert.formulations.fractional.items import TrackItem

    cameras = _cameras()
    proj = TrackItem((cameras, np.zeros((3, 2))), "L2L2", chart=False).raw_residuals(DIRECTION)[0]
    observations = proj  # image - 0: the float image itself
    claim = {"index": 0, "status": "optimal", "certified": True, "cost": 0.0, "lower_bound": 0.0, "gap": 0.0,
             "point": DIRECTION.tolist(), "at_infinity": True, "proof": {"type": "trivial"}}
    document = {"format": "geocert-certificate", "version": 2, "kind": "triangulation",
                "options": {"job_time_limit_s": 600.0, "rel_gap": 0.001, "abs_gap": 1e-07, "max_nodes": 2000,
                            "time_limit_s": 30.0, "certificate": "full", "norm": "L2L2", "max_residual": None,
                            "detail": "full"},
                "data": {"cameras": cameras.tolist(),
                         "tracks": [{"views": [0, 1, 2], "points": observations.tolist()}]},
                "items": [claim]}
    return rehash(document)


def _refused_at_objective(document: dict) -> None:
    report = _verify(document)
    assert not report.valid and report.first_failure["check"] == "objective", report.first_failure


def _uncertainty_covers_the_rounding(item, solution: np.ndarray) -> None:
    """The fix at the cause (proof.image_uncertainty's LEAST_SUBNORMAL term): the uncertainty the float
    path trusts is at least how far this machine's float residuals lie from the exact ones, which
    here is a share of a pixel (1e-15 of the products' size alone underflowed to 0)."""
    floats = item.raw_residuals(solution)[0]
    off = np.abs(floats - item.exact_residuals(solution).reshape(floats.shape))
    assert off.max() > 0
    assert np.all(off <= item.residual_uncertainty(solution).reshape(floats.shape))


def test_a_subnormal_point_at_infinity_claimed_at_cost_0_is_refused():
    _refused_at_objective(_subnormal_track_certificate())


def test_the_subnormal_direction_costs_over_1_px2_and_the_data_admit_no_cost_below_1():
    """Machine-independent: the stated direction's exact cost (core.exact, one float everywhere)
    is above 1, and the solver's own certificate on the same data proves a lower bound above 1, so
    the claim "optimal at cost 0" is false whatever the direction."""
    from geocert.jobs.runner import solve_job
    from geocert.core import exact
    from geocert.formulations.fractional.items import TrackItem

    document = _subnormal_track_certificate()
    observations = np.array(document["data"]["tracks"][0]["points"])
    item = TrackItem((_cameras(), observations), "L2L2", chart=False)
    assert exact.cost(item.exact_residuals(DIRECTION), "L2L2") > 1.0
    _uncertainty_covers_the_rounding(item, DIRECTION)
    genuine = solve_job({"kind": "triangulation", "data": document["data"],
                         "options": {"norm": "L2L2", "certificate": "full"}})
    assert genuine["tracks"][0]["certified"] and genuine["tracks"][0]["lower_bound"] > 1.0
    assert _verify(genuine).valid


def test_the_same_direction_at_unit_scale_is_refused():
    """The power-of-two rescaling the suggested fix applies: the same direction, its exact
    residuals unchanged, read at unit scale takes the floats' real rounding and is refused."""
    document = _subnormal_track_certificate()
    document["items"][0]["point"] = (DIRECTION / (1000 * SUBNORMAL)).tolist()
    rehash(document)
    report = _verify(document)
    assert not report.valid and report.first_failure["check"] == "objective"


# Class 1 (d): a finite point a subnormal distance in front of cameras centred at the origin

def _rotating_camera_certificate() -> dict:
    """Three cameras K R_i [I | 0] sharing their centre at the origin (a rotating camera, a
    panorama), and a finite point (3, 5, 40) * 1000 * 2^-1074 in front of them: every product
    behind its projections is subnormal. The observations are this machine's float image of it,
    claimed at cost 0 by the trivial bound."""
    from geocert.formulations.fractional.items import TrackItem

    rng = np.random.default_rng(2)
    K = np.array([[800.3, 0, 320.1], [0, 799.7, 240.2], [0, 0, 1]])
    cameras = np.array([K @ np.hstack([_rotation(rng.normal(0, 0.05, 3)), np.zeros((3, 1))]) for _ in range(3)])
    cameras /= np.abs(cameras).max(axis=(1, 2))[:, None, None]
    point = np.append(DIRECTION[:3], 1.0)
    observations = TrackItem((cameras, np.zeros((3, 2))), "L2L2", chart=False).raw_residuals(point)[0]
    document = _subnormal_track_certificate()
    document["data"]["cameras"] = cameras.tolist()
    document["data"]["tracks"][0]["points"] = observations.tolist()
    document["items"][0].update(point=point[:3].tolist(), at_infinity=False)
    return rehash(document)


def test_a_finite_point_a_subnormal_distance_from_the_cameras_centre_claimed_at_cost_0_is_refused():
    _refused_at_objective(_rotating_camera_certificate())


def test_the_finite_subnormal_point_costs_over_1_px2():
    """Machine-independent: the stated point's exact cost is above 1 px^2 (measured 81.5; the
    solver's own best point on these data costs 81.2, uncertified): rescaling a point at infinity
    would not reach this one, whose last coordinate is 1."""
    from geocert.core import exact
    from geocert.formulations.fractional.items import TrackItem

    document = _rotating_camera_certificate()
    item = TrackItem((np.array(document["data"]["cameras"]), np.array(document["data"]["tracks"][0]["points"])),
                     "L2L2", chart=False)
    point = np.append(document["items"][0]["point"], 1.0)
    assert exact.cost(item.exact_residuals(point), "L2L2") > 1.0
    _uncertainty_covers_the_rounding(item, point)


# Class 1 (b) and (c): a homography's or a resection's matrix in subnormal numbers

def _genuine_map_job(kind: str) -> dict:
    """Review 37's near-identity homography, review 35's resection (K [I | 0], 12 points 5 in
    front): exact data, at the origin."""
    from tests.verify.test_forgeries_review35 import _far_resection
    from tests.verify.test_forgeries_review37 import _far_homography

    return _far_homography(0.0, 0.0, 5) if kind == "homography" else _far_resection(0.0, 0.0, 5)


@pytest.fixture(scope="module", params=["homography", "resection"])
def subnormal_map(request) -> dict:
    """A genuine result of the kind, its matrix rounded to integers times 2^-1074 (largest 1000),
    its targets this machine's float image under that matrix, claimed at cost 0 by the trivial
    bound, the exact residuals stated, no determinacy."""
    from geocert.jobs.runner import solve_job
    from geocert.formulations.fractional.items import MapItem

    result = copy.deepcopy(solve_job(_genuine_map_job(request.param)))
    certificate = result["certificate"]
    source = np.array(certificate["data"]["maps"][0]["source"], dtype=float)
    genuine = np.array(result["maps"][0]["matrix"], dtype=float)
    matrix = np.round(genuine / np.abs(genuine).max() * 1000) * SUBNORMAL
    nothing = np.zeros((len(source), len(matrix) - 1))
    target = -MapItem((source, nothing), "L2L2", chart=False).raw_residuals(matrix)[0]
    certificate["data"]["maps"][0]["target"] = target.tolist()
    exact_residuals = MapItem((source, target), "L2L2", chart=False).exact_residuals(matrix)
    for where in (certificate["items"][0], result["maps"][0]):
        where.update(matrix=matrix.tolist(), cost=0.0, lower_bound=0.0, gap=0.0)
    certificate["items"][0]["proof"] = {"type": "trivial"}
    result["maps"][0]["residuals"] = exact_residuals.tolist()
    result["maps"][0]["determinacy"] = None
    rehash(certificate)
    return result


def test_a_subnormal_map_claimed_at_cost_0_is_refused(subnormal_map):
    _refused_at_objective(subnormal_map["certificate"])


def test_a_subnormal_maps_result_claimed_at_cost_0_is_refused(subnormal_map):
    _refused_at_objective(subnormal_map)


def test_the_subnormal_map_costs_more_than_abs_gap_and_so_does_every_map(subnormal_map):
    """Machine-independent: the stated matrix's exact cost is above 1e-6 (ten times abs_gap), and
    the solver's own certificate on the same data proves a lower bound above 1e-6 (measured: a
    homography's 5.8e-6 against 4.85e-6; a resection's 1.5e4 against 7.6e3 px^2)."""
    from geocert.jobs.runner import solve_job
    from geocert.core import exact
    from geocert.formulations.fractional.items import MapItem

    certificate = subnormal_map["certificate"]
    data = certificate["data"]["maps"][0]
    item = MapItem((np.array(data["source"]), np.array(data["target"])), "L2L2", chart=False)
    matrix = np.array(certificate["items"][0]["matrix"])
    assert exact.cost(item.exact_residuals(matrix), "L2L2") > 1e-6
    genuine = solve_job({"kind": certificate["kind"], "data": certificate["data"],
                         "options": {"norm": "L2L2", "certificate": "full"}})
    assert genuine["maps"][0]["certified"] and genuine["maps"][0]["lower_bound"] > 1e-6


def test_a_map_whose_float_residuals_are_all_0_gets_the_spread_cap_not_a_division_by_0():
    """Seen by review 39: a map's cost spread divided by its float cost, so a map fitting its data
    to the last bit stopped the verifier at ZeroDivisionError (a crash read as a failure, with no
    reason). Its cost is then not determined at all: the spread is the cap."""
    from geocert.verify.estimates import MAX_COST_SPREAD, _map_cost_spread

    source = np.array([[x, y] for x in range(4) for y in range(3)], dtype=float)
    matrix = np.array([[2.0, 1.0, 3.0], [0.0, 1.0, -1.0], [0.0, 0.0, 1.0]])
    target = source @ matrix[:2, :2].T + matrix[:2, 2]  # exact in floats: every residual 0
    assert _map_cost_spread(source, target, matrix) == MAX_COST_SPREAD
