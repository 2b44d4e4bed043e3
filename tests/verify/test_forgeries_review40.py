"""Review 40: a hostile review of the residuals' uncertainty below the normal range (proof.
image_uncertainty's LEAST_SUBNORMAL term), the fixed-order camera centres behind a track's depth
estimate (fixed_order.camera_centres, determinacy._length) and columns.certified_sublevel.

Found:

1. The scope check squares the residuals. checks._check_residual_claim (geocert/verify/checks.py:1040)
   reads a solution's longest residual as sqrt(sum r*r): a residual below about 1.5e-162 squares
   to 0 (below the least subnormal), so its length reads 0 and passes any max_residual (a finite
   number > 0, options.ResidualOptions: 1e-300 is one). Two cameras on one optical axis, K = I,
   observations (0, 0) and (1e-165, 0), max_residual 1e-300: no point has every residual within
   1e-300 (the first view asks |x| <= 1e-300, the second |x/2 - 1e-165| <= 1e-300), so the scope
   is empty and nothing in it is optimal; a claim "optimal at (0, 0, 1), cost 0 (L2L2) or 1e-165
   (L1L1), trivial bound" verifies, its residual 1e135 times max_residual. The solver itself
   certifies such a point on these data (its own scope test squares alike).
   Suggested fix at the cause: compare each residual coordinate against max_residual before
   squaring (|r_k| > max_residual is out), or measure the length scaled (np.hypot, or divided by
   the largest coordinate first), in the verifier's scope check and the solver's alike.

2. Genuine output refused on its own machine: cameras whose entries reach 2^1023 (a camera is
   defined up to scale; geometry.normalised_cameras brings it to its largest entry near 1 for the
   solvers and the certificate's checks). estimates._check_tracks (geocert/verify/estimates.py:306)
   recomputes a track's determinacy estimate from the raw data/cameras, not normalised: the
   projections overflow to inf, the verifier's estimate is undetermined, and the writer's
   (normalised cameras, determined) is refused at "returned". The certificate alone verifies.
   Suggested fix at the cause: read the cameras through normalised_cameras in _check_tracks (and
   wherever an estimate reads data/cameras), as the writer (triangulation.parse, check_cameras)
   does: a power of two changes no residual, depth or Jacobian.

3. Genuine output refused on its own machine, at a tie between the writer's batched estimate and
   the verifier's single-track one: determinacy.tracks_many (the writer of a job of several
   tracks) reads the rays' cosines by np.einsum, determinacy.track (which estimates._check_tracks
   recomputes) by ``unit @ unit.T`` (BLAS, fused products under some kernels): the two differ in
   the last bit in about half of the cases, and a track whose widest ray angle is within an ulp of
   PARALLAX_DEGREES (1 degree) gets its near_zero_parallax warning in one and not the other, so
   ``determined`` flips and the writer's document is refused at "returned" (measured here under
   OpenBLAS's Haswell kernel: three views on a line, the point found by bisection along its depth;
   the tie is reached on the solver's returned point in the first few jobs tried). The fixed
   order covers the centres and the lengths (fixed_order.camera_centres, _length), not the cosines.
   Suggested fix at the cause: the cosines in one fixed order in both (fixed_order's sums, or the
   same elementwise expression u0*v0 + u1*v1 + u2*v2 in the writer and the verifier), as
   _length now is.

4. Genuine output refused on its own machine, at a tie of ``determined``: a track's interval
   fixes its quantity when its half-width is within its tolerance (core.determinacy.fixes: a
   tenth of the depth), and estimates._compare holds the stated ``determined`` to the verifier's
   own exactly, while the widths it computes from one J'J (determinacy.track) and the writer's
   batched eigh (tracks_many) differ by some 1e-13 of themselves (TRACK_WIDTH_SLACK allows the
   widths 1e-5). A track whose depth_view0 half-width lies that close to a tenth of its depth
   (found by bisecting the observations' noise along one pattern: 2 of 8 patterns reach it
   under Haswell) is written determined and recomputed not (the writer's half-width 2e-13 under
   the tolerance, the verifier's 2.8e-13 over): refused at "returned".
   Suggested fix at the cause: read ``determined`` from the stated intervals (check_determined's
   rule, fixes() of each) once they are held to the verifier's within their slack, or accept
   either value where the verifier's half-width is within that slack of the tolerance.

5. (Borderline: docs/certificate.md lists ``note`` as informational.) A certified track's summary
   ``note`` states the convexity proof's fact in numbers, "no search: the cost is convex on the
   ball of radius R about the solution, which holds every point of the scope costing as little"
   (kinds/documents.py:50), and no check reads it: the note rewritten to a radius of 1e6 (the
   proof's is 6.2; a ball of radius 1e6 holds points behind the cameras, where the cost is not
   even defined) verifies. The summary's scope and root_region, which state facts alike, are tied
   to the proof (fractional._check_scope_words, _check_root_region).
   Suggested fix at the cause: a certified item's note is the writer's words for its proof (the
   convexity proof's radius as the proof states it; the other notes' fixed texts), or the note
   carries no numbers a reader would take as proven.

Seen, not a forgery: cameras in subnormal numbers (entries times 2^-1070) crash the solver's
parse (geometry.normalised_cameras: math.ldexp(1.0, 1069) raises OverflowError, not an
InputError) and the verifier refuses such a document at "format" with "OverflowError: math range
error" (a crash's text as its reason).

Refused (plain tests below): review 39's point at infinity just above the normal range (2^-1022
times 1 to 2^60, products below it where the camera's entries are under 1), its float image as
observations, claimed at cost 0 (refused at "objective": proof.image_uncertainty's LEAST_SUBNORMAL term
sends it down the exact path); proven intervals stated on an uncertified track, or a certified track's
proof's sublevel dropped with its determinacy still saying proven; a genuine result on cameras
scaled by 2^-1000 (products near the bottom of the normal range) verifies.

Fixed at their causes: (1) residual lengths by np.hypot (geometry.residual_lengths) in the
verifier's scope check, the program's in_scope and the solver's recomputed status; (2) the track
estimates and the pooled level read the cameras through normalised_cameras, as the writer does;
(3) the rays' cosines in one order for both paths (determinacy._cosines), read against
PARALLAX_COSINE (no arccos: its last bit is the vector unit's); (4) ``determined`` is no longer
compared exactly: check_determined derives it from the stated intervals, whose ends are held to
the verifier's within their slack; (5) a radius a summary's note states must be its proof's
(checks._check_note_radius; since review 42 the whole note is its proof's words: checks._check_note).
normalised_cameras scales by np.ldexp (subnormal cameras read).
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import rehash, uncertify


def _verify(document: dict):
    return verify_any(json.loads(json.dumps(document)))


# Class 1: a residual too small to square passes any max_residual

AXIS_CAMERAS = [np.hstack([np.eye(3), np.zeros((3, 1))]).tolist(),  # K = I, centre at the origin
                np.hstack([np.eye(3), np.array([[0.0], [0.0], [1.0]])]).tolist()]  # centre at (0, 0, -1)
TINY = 1e-165  # its square underflows to 0
MAX_RESIDUAL = 1e-300


def _empty_scope_certificate(norm: str) -> dict:
    """Observations (0, 0) and (TINY, 0) in two cameras on one optical axis, max_residual
    MAX_RESIDUAL (an empty scope), and a claim that (0, 0, 1) is optimal by the trivial bound."""
    cost = 0.0 if norm == "L2L2" else TINY  # (TINY^2 rounds to 0; TINY under L1L1)
    claim = {"index": 0, "status": "optimal", "certified": True, "cost": cost, "lower_bound": 0.0, "gap": cost,
             "point": [0.0, 0.0, 1.0], "at_infinity": False, "proof": {"type": "trivial"}}
    document = {"format": "geocert-certificate", "version": 2, "kind": "triangulation",
                "options": {"job_time_limit_s": 600.0, "rel_gap": 0.001, "abs_gap": 1e-07, "max_nodes": 2000,
                            "time_limit_s": 30.0, "certificate": "full", "norm": norm,
                            "max_residual": MAX_RESIDUAL, "detail": "full"},
                "data": {"cameras": AXIS_CAMERAS, "tracks": [{"views": [0, 1], "points": [[0.0, 0.0], [TINY, 0.0]]}]},
                "items": [claim]}
    return rehash(document)


def test_the_scope_is_empty_and_the_claimed_point_is_outside_it():
    """Machine-independent: the claimed point's residual in view 1 is TINY exactly (its image is
    (0, 0)), 1e135 times max_residual; and no point is in scope, since view 0 asks |x| <=
    MAX_RESIDUAL and view 1 |x / 2 - TINY| <= MAX_RESIDUAL (x / 2 <= MAX_RESIDUAL / 2)."""
    from geocert.core import exact
    from geocert.formulations.fractional.items import TrackItem

    document = _empty_scope_certificate("L1L1")
    item = TrackItem((np.array(AXIS_CAMERAS), np.array(document["data"]["tracks"][0]["points"])), "L1L1",
                     chart=False)
    residuals = item.exact_residuals(np.array([0.0, 0.0, 1.0, 1.0]))
    assert np.abs(residuals).max() == TINY > 1e100 * MAX_RESIDUAL
    assert MAX_RESIDUAL + MAX_RESIDUAL / 2 < TINY  # |x| and |x / 2 - TINY| cannot both be that small
    assert exact.cost(residuals, "L1L1") == TINY


@pytest.mark.parametrize("norm", ["L2L2", "L1L1"])
def test_a_point_outside_an_empty_scope_claimed_optimal_is_refused(norm):
    report = _verify(_empty_scope_certificate(norm))
    assert not report.valid and report.first_failure["check"] == "scope", report.first_failure


def test_the_solver_certifies_no_point_in_an_empty_scope():
    from geocert.jobs.runner import solve_job

    document = _empty_scope_certificate("L2L2")
    result = solve_job({"kind": "triangulation", "data": document["data"],
                        "options": {"norm": "L2L2", "certificate": "full", "max_residual": MAX_RESIDUAL}})
    assert not result["tracks"][0]["certified"]


# Class 2: cameras with entries near the top of the float range

def _scene(scale: float) -> dict:
    """Review 39's three cameras times ``scale`` (a power of two: the same cameras), one track of
    a point 10 in front, observed with offsets of a third of a pixel."""
    from tests.verify.test_forgeries_review39 import _cameras

    cameras = _cameras()
    X = np.array([0.3, 0.2, 10.0, 1.0])
    observations = [((P @ X)[:2] / (P @ X)[2] + np.array([0.3, -0.2])).tolist() for P in cameras]
    return {"cameras": (cameras * scale).tolist(), "tracks": [{"views": [0, 1, 2], "points": observations}]}


def _solve(scale: float) -> dict:
    from geocert.jobs.runner import solve_job

    return solve_job({"kind": "triangulation", "data": _scene(scale),
                      "options": {"norm": "L2L2", "certificate": "full"}})


def test_a_genuine_result_on_cameras_near_the_float_limit_verifies():
    result = _solve(2.0 ** 1023)
    assert result["tracks"][0]["certified"]
    assert _verify(result["certificate"]).valid  # the certificate alone: normalised cameras
    report = _verify(result)
    assert report.valid, report.first_failure


def test_a_genuine_result_on_cameras_near_the_bottom_of_the_normal_range_verifies():
    """2^-1000: every product still normal (entries to 2^-1010); the writer and the verifier agree."""
    result = _solve(2.0 ** -1000)
    assert result["tracks"][0]["certified"]
    report = _verify(result)
    assert report.valid, report.first_failure


# Refused: proven intervals tied to certified claims (columns.certified_sublevel)

@pytest.fixture(scope="module")
def proven_result() -> dict:
    result = _solve(1.0)
    assert result["tracks"][0]["determinacy"]["proven"] is True
    assert "sublevel" in result["certificate"]["items"][0]["proof"]
    return result


def test_proven_intervals_on_an_uncertified_track_are_refused(proven_result):
    result = copy.deepcopy(proven_result)
    uncertify(result["certificate"]["items"][0])
    del result["certificate"]["items"][0]["proof"]
    uncertify(result["tracks"][0])
    rehash(result["certificate"])
    report = _verify(result)
    assert not report.valid


def test_a_certified_tracks_proven_intervals_without_their_sublevel_are_refused(proven_result):
    result = copy.deepcopy(proven_result)
    del result["certificate"]["items"][0]["proof"]["sublevel"]
    report = _verify(result)
    assert not report.valid and report.first_failure["check"] == "returned", report.first_failure


# Class 3: the parallax warning at a tie between the batched writer and the single-track verifier

LINE_CAMERAS = np.array([np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
                         @ np.hstack([np.eye(3), -np.array([[x], [0.0], [0.0]])]) for x in (0.0, 0.37, 1.0)])


def _parallax_job(point: np.ndarray) -> dict:
    """Two exact tracks in LINE_CAMERAS (two, so that the writer takes the batched path): ``point``
    and one far from any tie."""
    tracks = []
    for X in (np.append(point, 1.0), np.array([0.2, -0.3, 4.0, 1.0])):
        tracks.append({"views": [0, 1, 2], "points": [((P @ X)[:2] / (P @ X)[2]).tolist() for P in LINE_CAMERAS]})
    return {"kind": "triangulation", "data": {"cameras": LINE_CAMERAS.tolist(), "tracks": tracks},
            "options": {"norm": "L2L2", "certificate": "full"}}


def test_genuine_tracks_at_the_parallax_threshold_verify():
    """Points on the 1 degree surface (bisection along the depth, by the rays' cosines), a few ulps
    either side, each solved (the batched writer) and verified (the single track): every one
    verifies. Before, the writer's einsum cosines and the verifier's matmul ones differed in the
    last bit about half the time, and at a tie the warning (and determined) differed."""
    from geocert.jobs.runner import solve_job
    from geocert.formulations.fractional import determinacy as estimate

    centres = estimate._centres(LINE_CAMERAS)

    def near(point):
        rays = point[None, :] - centres
        return float(estimate._cosines(rays / estimate._length(rays)[:, None]).min()) > estimate.PARALLAX_COSINE

    warned = set()
    for x in np.linspace(0.3, 0.7, 6):
        lo, hi = 40.0, 80.0
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if not near(np.array([x, 0.1, mid])) else (lo, mid)
        for k in range(-3, 4):
            result = solve_job(_parallax_job(np.array([x, 0.1, mid + 8 * k * np.spacing(mid)])))
            warned.add(any(w["code"] == "near_zero_parallax" for w in result["tracks"][0]["determinacy"]["warnings"]))
            report = _verify(result)
            assert report.valid, report.first_failure
    assert warned == {True, False}  # the premise: points on both sides of the threshold


# Class 4: determined at a tie of an interval's half-width and its tolerance

def _noisy_job(seed: int, amplitude: float) -> dict:
    """Two tracks in LINE_CAMERAS (the writer's batched path): a point drawn by ``seed``, observed
    with noise ``amplitude`` times a pattern drawn by it, and an exact one."""
    rng = np.random.default_rng(seed)
    pattern = rng.normal(size=(3, 2))
    X = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(3, 20), 1.0])
    observed = np.array([(P @ X)[:2] / (P @ X)[2] for P in LINE_CAMERAS]) + amplitude * pattern
    job = _parallax_job(np.array([0.2, -0.3, 4.0]))
    job["data"]["tracks"][0]["points"] = observed.tolist()
    return job


def test_genuine_tracks_at_their_intervals_tolerance_verify():
    """The noise amplitude bisected to where the writer's ``determined`` flips, every result on the
    way verified (under Haswell the flip met a refusal in 2 of 8 noise patterns: the verifier's
    half-width 2.8e-13 over the tolerance, the writer's 2e-13 under)."""
    from geocert.jobs.runner import solve_job

    seen = set()
    for seed in (2, 3, 1, 4):
        lo, hi = 0.0, 400.0
        for _ in range(70):
            mid = 0.5 * (lo + hi)
            if mid in (lo, hi):
                break
            result = solve_job(_noisy_job(seed, mid))
            report = _verify(result)
            assert report.valid, report.first_failure
            determined = result["tracks"][0]["determinacy"]["determined"]
            seen.add(determined)
            lo, hi = (mid, hi) if determined else (lo, mid)
    assert seen == {True, False}  # the premise: the bisection reached the flip


# Class 5: a certified track's note states its convexity radius, unread

def test_the_convexity_note_states_the_proofs_radius():
    """The writer's note names the radius its proof states (machine-independent: both are the
    same float written twice)."""
    result = _solve(1.0)
    proof = result["certificate"]["items"][0]["proof"]
    assert proof["type"] == "convexity"
    assert repr(proof["radius"]) in result["tracks"][0]["certificate"]["note"]


def test_a_note_stating_a_radius_the_proof_does_not_prove_is_refused():
    result = copy.deepcopy(_solve(1.0))
    radius = result["certificate"]["items"][0]["proof"]["radius"]
    assert radius < 10
    summary = result["tracks"][0]["certificate"]
    summary["note"] = summary["note"].replace(repr(radius), "1000000.0")
    assert "1000000.0" in summary["note"]
    report = _verify(result)
    assert not report.valid


# Refused: a direction just above the normal range, products below it

@pytest.mark.parametrize("power", [0, 5, 60])
def test_a_direction_just_above_the_normal_range_claimed_at_cost_0_is_refused(power):
    from geocert.formulations.fractional.items import TrackItem
    from tests.verify.test_forgeries_review39 import _subnormal_track_certificate

    document = _subnormal_track_certificate()
    cameras = np.array(document["data"]["cameras"])
    direction = np.array([3.0, 5.0, 40.0, 0.0]) * 2.0 ** (-1022 + power)
    observations = TrackItem((cameras, np.zeros((3, 2))), "L2L2", chart=False).raw_residuals(direction)[0]
    document["data"]["tracks"][0]["points"] = observations.tolist()
    document["items"][0]["point"] = direction.tolist()
    report = _verify(rehash(document))
    assert not report.valid and report.first_failure["check"] == "objective", report.first_failure


def test_cameras_of_subnormal_entries_are_read_not_crashed_on():
    """Seen by review 40: cameras scaled by 2^-1060 (subnormal entries) stopped normalised_cameras
    at OverflowError (it formed 2^1069 before scaling) in the solver's parse and the verifier. A
    camera is defined up to scale: these are read (their subnormal entries kept fewer digits, so
    the point is not the unscaled cameras'), solved and verified."""
    scaled = _solve(2.0 ** -1060)
    assert scaled["tracks"][0]["point"] is not None
    report = _verify(scaled)
    assert report.valid, report.first_failure
