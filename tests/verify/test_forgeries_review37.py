"""Review 37 (issue 33): a hostile review of review 36's fixes: checks._check_residual_claim with
_least_cost (a track's or map's claimed cost at least the least cost residuals within rounding + 2
residual_uncertainty of the verifier's give), fractional.determinacy.exact_squared_residuals (the
map estimate's level), estimates.MAP_VALUE_ROUNDING and JACOBIAN_ROUNDING * _map_offset (a map
estimate's value and ends), MapItems.check_returned (returned residuals held besides to 2
residual_uncertainty), and autocalibration._stated_reference / check_claims.

Found: two forgeries (classes 1 and 2: strict xfail tests that the forged document is refused) and
four classes of GENUINE documents refused (classes 3 to 6: strict xfail tests that they verify).
Class 5 is a regression of review 36's fix (9bf0f71): proven resections 1e3 or more from the
origin are refused by their own writer's verifier. Classes 3, 4 and 6 solve and verify in
subprocesses under OPENBLAS_CORETYPE=Haswell and Prescott (review 35's _run; skipped without AVX2);
classes 1, 2 and 5 run in this process and state what holds on any machine.

Fixed at their cause: class 5 (fractional.determinacy.map_level: one level, 3^2 times the squared
residuals computed exactly over 2k - 11, at least the certified gap, read by the estimate, the
proven interval and fractional._check_map_level alike); class 3 (estimates._check_maps: a
homography's value keeps VALUE_SLACK of itself, MAP_VALUE_ROUNDING holds a resection's centre
only, so review 36's class 2 is open again for far homographies). Class 4
(fractional.MapItems.solution_cost: an uncertified map's cost figure is held to the objective
check's slack and twice its spread besides figure_allowance; since review 38, to the exact cost).
Class 1 (core.exact: a certified track's or map's cost, where the floats' rounding could move it
past a quarter of OBJECTIVE_TOLERANCE, and every map's returned residuals, are stated from the
residuals computed exactly and rounded once, one number on every machine;
checks._check_residual_claim holds the claim to them at OBJECTIVE_TOLERANCE and 4 ulps, no longer
the worst-case spread). Class 6 (resection_sublevel, resection_centre_l1 and resection_bound
recompute their proofs in a fixed order of operations, fixed_order: one float on every machine,
no allowance). Class 2 (estimates._check_tracks: the x, y and z values are the returned point's
coordinates exactly, and every end is read as its offset from its value, to NUMBER_SLACK of the
width and two ulps of the end). Class 3's value is computed exactly by the writer
(fractional.determinacy.exact_centroid_image), and since review 38's class 4 the estimate's ends
too are one float on every machine (fractional.homography_estimate): far off, the value is held
to an ulp and the ends read as offsets from it (item 3). Open: none.

1. A far map's cost understated within the least cost's window, its residuals stated 0. Review
   36's far resection (offset 1e6, 1e-6 px of noise, seed 5; certified by the trivial bound) costs
   1.2933e-11 (this machine's float r'r; the exact cost, exact_squared_residuals, 1.2995e-11). The
   least cost _check_residual_claim now asks for reads each residual within rounding + 2
   residual_uncertainty of the verifier's, and residual_uncertainty is a worst-case 1e-15 of the
   residual's terms (about 5e-7 px here, 25 times the residuals' measured rounding): the least is
   3.114e-12. Restated at 1.05 of it, 3.27e-12 (and at 1.5 of it, 4.67e-12), claim, result and
   gap, the estimate recomputed there, the document verifies: a certified cost a quarter of the
   matrix's exact cost. MapItems.check_returned's allowance is wider still (1e-9 of the target,
   3e-7 px at 300 px, + 2 rounding + 2 residual_uncertainty): each returned residual moved 0.9 of
   it toward 0 states 18 of the 24 coordinates as fitted exactly, where every exact residual
   (Fractions) exceeds 1e-8 px. The estimate's level still reads the stated cost through the
   certified gap (max(gap, 3^2 r'r / 13)), so the forged intervals are 0.83 of the genuine widths.
   Refused: the cost at 0.9 of the least ("the solution costs at least 3.114102186477981e-12").
   At fault: geocert/verify/checks.py:_check_residual_claim (least cost at rounding + 2
   uncertainty, the uncertainty a bound on any float evaluation, not the writer's) and
   geocert/verify/fractional.py:MapItems.check_returned (1e-9 * |target| + 2 rounding + 2
   uncertainty). Suggested fix at the cause: a map's cost and residuals are functions of the data
   and the matrix that can be computed exactly (exact_squared_residuals does so for the level):
   have the writer state the cost and residuals computed exactly and rounded once, the same floats
   on every machine, and hold them to an ulp or two (documents of earlier writers, by their form,
   under today's windows); read the certified gap of the level from the exact cost too.

2. Review 36's class 2 open for tracks. estimates._check_tracks calls _compare with its default
   value_slack, VALUE_SLACK (1e-9 of the value), and no value floor: review 36's fix reached maps
   only. A track 1e6 from the origin (three cameras K [I | -C], centres 1 apart near (1e6, -0.5e6,
   0.3e6), the point 5 in front, 1e-6 px of noise; certified) has point intervals 4.6e-8 to
   2.5e-7 wide (x: [1000000.6100058183, 1000000.6100058709]), compared at 1e-3 px (19,000
   widths): (a) the x, y and z intervals collapsed onto their values (lower = value = upper:
   "known exactly") verify; (b) moved with their values by 0.9e-9 of them (9e-4 px on x) they
   verify, the returned point outside its own intervals. At an offset of 1e3 (world coordinates in
   metres, any city-scale scene) both verify too (slack 1e-6 px, 19 widths of x's interval).
   Only the depth interval (its value near 5) is held: collapsed, refused ("intervals/3/lower").
   (_check_frames reads the same default, but a bilinear frame's coefficients are of unit size:
   the stored result's intervals collapsed are refused.)
   At fault: geocert/verify/estimates.py:_check_tracks with _compare's VALUE_SLACK default.
   Fixed at the cause: the writer (fractional.determinacy.track and tracks_many) states the
   returned point's coordinate, float(X[k]), as the x, y and z values, so _check_point_values
   requires them bit for bit; _compare(offsets=True) reads each end as its offset from its own
   value (end - value) against the estimate's, to NUMBER_SLACK and TRACK_WIDTH_SLACK (1e-5) of the
   width and END_OFFSET_ULPS (2) ulps of the end (each side's end is its value -+ the half-width
   rounded once), whatever the value's size. Measured before choosing: far tracks (offsets 0, 1e3,
   1e6; exact and 1e-6 px; seeds 5 and 6) written under Haswell and Prescott and recomputed under
   each: every value, end offset and level bit for bit the writer's (widths 4e-10 to 2.5e-7 at
   1e6), all 48 verify; hostile scenes (seeds 1 and 2, 400 tracks, L2L2; 2,840 ends a document):
   the writer's batched path and the verifier's differ by up to 5.8e-7 of the width, under either
   kernel alike.
   Collapsed or moved, the intervals are refused ("intervals/0/lower ... its offset from the
   value", "the returned point's x"); an interval narrowed or widened by a hundredth of its width
   is refused too. An interval a few ulps wide (exact data at 1e6: 4e-10, 3 ulps) cannot be told
   from its collapse: its width is its rounding.

3. Far homographies refused under another kernel: the value at MAP_VALUE_ROUNDING. The
   constant (8 ulps of the value and of the data's largest coordinate) was measured on resections
   only. A homography's value is the centroid's image through the normalisers, (Tt^-1 N Ts) c,
   which rounds at eps times the data's size times their offset over their spread. 15 points
   uniform in [-100, 100]^2 mapped by a homography near the identity, both sides moved by the
   offset, solved and verified across kernels (seeds 5 and 6, exact, 1e-6 px and 1e-3 px of
   noise: 12 documents an offset): at 1e4 all verify; at 1e5 one is refused (Prescott's seed 5 with
   1e-6 px: 100006.9608578685 against 100006.96085786901); at 1e6 all 12 ("maps/0/determinacy/
   intervals/0/value is 1000006.9608577258, the estimate at the solution returned gives
   1000006.9608577619": 3.6e-8 apart, about 310 ulps, against an allowance of about 3.6e-9); at
   1e7 all 8 exact and 1e-6 px ones (8.8e-6 apart). Each verifies under its writer's kernel.
   At fault: geocert/verify/estimates.py:_check_maps (MAP_VALUE_ROUNDING, for a homography's
   centroid image) with fractional/determinacy.map_'s transfer (computed through the normalisers).
   Suggested fix at the cause: compute the value from the returned matrix and the centroid exactly
   (integers, as exact_squared_residuals, rounded once: the same float everywhere) and compare it
   at an ulp; failing that, grow the value's slack with _map_offset as the width's does.
   Half done: the writer, fractional.determinacy.map_, states exact_centroid_image (the same float
   on every machine; the verifier recomputes it by the same function): homographies at offsets
   1e4 to 1e7 (exact, 1e-6 and 1e-3 px, seeds 5 and 6) written under one kernel and recomputed
   under the other are 0 ulps apart. The value is still compared at VALUE_SLACK, so the moved
   interval (review 36's class 2) is open for far homographies: documents of earlier writers state
   the value through the normalisers (the stored homography_far_from_origin.json 3.6e-8 from the
   exact image, and 1.8e-8 and 2.2e-8 from Prescott's recomputation by the earlier path, against
   MAP_VALUE_ROUNDING's 2.3e-9), and telling them apart needs a form mark (fractional.MapItems'
   hash_marks and checks._check_hashes). Nor can the ends be read as offsets from the value, as a
   track's are: the half-widths of far homographies differ between kernels by 1.2e-4 of the width
   at 1e6 with 1e-3 px of noise (beyond MAP_WIDTH_SLACK + JACOBIAN_ROUNDING * _map_offset, 1.03e-4;
   VALUE_SLACK of the value holds them today).
   Fixed (review 38 class 4's fix): the writer computes the whole estimate in a fixed order
   (fractional.homography_estimate: bit for bit across kernels, 48 of 48 estimates at offsets 0 to
   1e7). Where exact.needs_exact (the map's float cost unreliable: far off), estimates._check_maps
   holds a homography's value to HOMOGRAPHY_VALUE_ULPS (one ulp) of the
   exact centroid image and reads each end as its offset from the value (_compare(offsets=True)),
   to NUMBER_SLACK and the width slack of before (MAP_WIDTH_SLACK + spread + _map_offset *
   JACOBIAN_ROUNDING): a document of a writer before the exact value states a float cost, held to
   the exact one there; nearer the origin the rule is today's. The interval collapsed onto its
   value or moved with it by 0.9e-9 of it is refused.

4. An uncertified far map's cost figure refused under another kernel. A job of two homographies,
   one at 1e4 (exact: certified) and one at 1e7 with 1e-3 px of noise (left uncertified: its
   spread is beyond the tolerance). Each writer's document verifies under its kernel; under the
   other all four are refused: "cost 2.5069907383660356e-05, its solution costs
   2.507187402373684e-05" (Haswell's seed 5 under Prescott; Prescott's seed 6 under Haswell:
   1.769121360730222e-05 against 1.7703671790891135e-05). figure_allowance is 1e-9 absolute below
   a cost of 1, while the verifier's own spread of this cost (cost_rounding at
   residual_uncertainty) is more than twice that. L2L1 and L1L1 resections at 1e6 (1e-6 px) and
   1e7 (exact), uncertified, differ by 1e-8 to 4e-7 between kernels alike.
   At fault: geocert/verify/fractional.py:figure_allowance as MapItems.solution_cost returns it
   (checks.uncertified_claim). Suggested fix at the cause: add 2 spread (cost_rounding at
   residual_uncertainty, as _check_residual_claim does) to an uncertified item's allowance; or
   (class 1's fix) state the cost computed exactly.

5. Proven resections refused on their writer's own machine (a regression of review 36's fix).
   Since 9bf0f71 determinacy.map_ reads the level's r'r from exact_squared_residuals, while the
   solver proves the sublevel intervals at, and fractional._check_map_level recomputes, 3^2 times
   the claim's float cost over 2k - 11 (at least its gap), held to LEVEL_ROUNDING (1e-9). Where the
   two sums differ by more (the data a little off the origin), the writer's own document is
   refused: review 35's resection job (12 points, K [I | 0]) with 1e-3 px of noise moved by 1e5,
   seeds 5 and 6, in this process (Haswell): "maps/0/determinacy/cost_increase is
   8.940342276761281e-06, the map's own level is 8.9403472280 (3^2 times its cost over 2k - 11,
   at least its gap)" and "maps/0/determinacy/proven_intervals are proven at cost increase
   1.0595871829 below the 1.0595874399 its estimate is read at" (5.5e-7 apart); under Prescott
   alike. At an offset of 1e3 all four seeds 5 to 8 are refused (8.940348436676826e-06 against
   8.9403485185e-06: 9e-9 apart); at offset 0 all verify.
   At fault: geocert/formulations/fractional/determinacy.py:map_ (the exact r'r) against
   determinacy.prove_map and geocert/verify/fractional.py:_check_map_level and _check_proven (the
   claim's float cost). Suggested fix at the cause: one level for the three: map_cost_increase of
   exact_squared_residuals(data, matrix) (with the certified gap) in prove_map and in
   _check_map_level, so that the estimate, the proof and the check read one float on every
   machine.

6. A far resection's sublevel proof refused under another kernel. Class 5's documents (offset
   1e5, 1e-3 px, seeds 5 and 6), written under one kernel and verified under the other, fail
   their claim check before class 5's: "proof/sublevel/intervals are narrower than what the proof
   proves" (Haswell's seed 5), "... wider than what the proof proves: they are not its intervals"
   (Haswell's seed 6, Prescott's seed 5), "proof/sublevel: not proven at radius
   0.04968026993667487" (Prescott's seed 6). L1L1 and L2L1 far resections' centre proofs alike
   (resection_centre_l1: "narrower than what the proof proves", "not proven at radius").
   At fault: geocert/formulations/fractional/resection_sublevel.py:verify_resection_sublevel (the
   bounds recomputed with the verifier's rounding and compared with no allowance on the narrow
   side, CHECK_SLACK of the half-width and 4 ulps on the wide one) and its check_enclosure.
   Measured (seeds 5 and 6, 1e-3 px; the bounds one kernel recomputes against the other's, over
   the half-width): 6e-11 to 1.3e-10 at offset 0, 7e-9 to 2.5e-6 at 1e3, 2e-5 to 2.6e-3 at 1e5
   (the whitening T, LAPACK's Cholesky and inverse of an ill-conditioned 11 x 11 matrix, 1e-4
   apart; the centre, LAPACK's svd, 1.3e-6 apart, 1e-3 of a half-width), beyond CHECK_SLACK on
   the wide side too. An allowance would have had to be 3e-3 of the half-width at 1e5 (3e4
   times STATED_SLACK), growing with the offset: a forger's room. Fixed at the cause: every product, sum, Cholesky factorisation (the
   enclosure's and the eigenvalue tests), inverse and the centre the check reads are computed in
   a fixed order with elementwise operations (fractional.fixed_order; shrink's kappa by bisection
   on those factorisations, not LAPACK's eigvalsh; the L1 centre's dual bounds and
   resection_bound's tangent terms alike). The recomputation is now the same floats under both
   kernels (bounds, rounds' radius and T compared bit for bit at offsets 0, 1e3 and 1e5; at 1e6
   the trivial bound certifies them, with no sublevel), documents written by
   the fixed writer verify under both, and the narrow side keeps no allowance: an end one ulp
   inside the recomputed bound is refused (test below). Documents written before the fix verify
   at offset 0 (their intervals 5e-7 of a half-width wider than the new bounds, within
   CHECK_SLACK); at 1e5 they are refused (1e-3 of a half-width off), and at 1e3 so are Haswell's
   (resection_bound: "the proof establishes ... less than lower_bound", as under Prescott before).

Measured, no class: hostile triangulation scenes (testing.hostile_triangulation.scene, seeds 1
and 2, 400 tracks, triangulate_many under L2L2, L2L1 and L1L1: 181/182/181 and 160/156/152 certified)
are all accepted: the least cost refuses none. Across kernels (seeds 1 and 2, 400 tracks, L2L2,
written by solve_job under Haswell and Prescott, verified under both), one genuine document is
refused, before and after class 2's fix alike: Haswell's seed 2 under Prescott, "tracks/378/
determinacy/intervals/3/value is 1.9949068696118587e-09, the estimate at the solution returned
gives 1.9948572489375835e-09" (an uncertified point 2e-9 from camera 0's centre, |X| about 20:
the depth is a difference of numbers 1e10 times larger, held to VALUE_SLACK of itself; its
tolerance, a tenth of it, alike). Left without a test. Far tracks (1e3, 1e6; exact and 1e-6 px; all norms)
across kernels: no refusal beyond "no certified item" (L2L1 and L1L1 leave them uncertified).
exact_squared_residuals equals the sum computed in Fractions on data scaled by 1e-300, 5e-324,
1e-160, 1e160 and 1e300, in 2D and 3D, with depths of either sign; a point mapped to infinity
gives inf; a square beyond the largest float raises OverflowError (its docstring says a float;
safely turns it into no estimate, the writer's and the verifier's alike); inf and nan raise (the
kinds' input checks refuse them first). The level can still be moved by the document through the
certified gap (class 1). Seen once, left without a test (the writer's path decides it, and it
changed with the thread count): a certified L2L1 resection (offset 1e5, 1e-3 px, seed 5, written
in this process under Haswell) refused on its own machine: "maps/0/certificate/tolerance is
9.803071928124207e-06, the options give 9.803089803101722e-06" (checks.py holds the summary's
tolerance to 1e-6 of rel_gap * cost; the solver's incumbent cost is 1.8e-6 off the claim's).

Tried and refused (plain tests below): the far map's cost below the least; a far track's interval
moved by 1.5e-9 of its value; its depth interval collapsed; a stratified certificate's proofs
naming a null reference ("proof/reference is None"); the stored bilinear result's
intervals collapsed; review 34's edge result with its metric stage
made uncertified and its proof naming camera 1 while the certified affine stage names 3.
"""

from __future__ import annotations

import copy
from fractions import Fraction

import numpy as np
import pytest

from tests.verify.test_forgeries_review34 import _refused, _valid, _verify
from tests.verify.test_forgeries_review34 import edge_data  # noqa: F401 (a fixture)
from tests.verify.test_forgeries_review35 import _far_resection, _has_avx2, _run
from tests.verify.test_forgeries_review36 import _at_cost, _edit_intervals, _widths
from tests.verify.test_forgeries_review36 import edge_service, far_resection  # noqa: F401 (fixtures)


# Class 1: a far map's cost understated, and its residuals zeroed, within the residuals' worst-case bound

def _map_item(result: dict, index: int = 0):
    from geocert.formulations.fractional.items import MapItem

    data = result["certificate"]["data"]["maps"][index]
    source, target = np.array(data["source"], dtype=float), np.array(data["target"], dtype=float)
    return MapItem((source, target), "L2L2", chart=False), np.array(result["maps"][index]["matrix"], dtype=float)


def _least(result: dict, index: int = 0) -> float:
    """The least cost review 36's check allowed: each residual within rounding + 2
    residual_uncertainty of the verifier's float one, its share clipped at 0."""
    item, matrix = _map_item(result, index)
    residuals, _, rounding = item.raw_residuals(matrix)
    allowance = rounding + 2.0 * item.residual_uncertainty(matrix)
    return float((np.maximum(np.abs(residuals) - allowance, 0.0) ** 2).sum())


def _understated(result: dict) -> dict:
    """The far map's cost restated at 1.05 of the least its check allows (claim, result, gap and the
    estimate recomputed there), and each returned residual moved 0.9 of its allowance toward 0
    (MapItems.check_returned's: 1e-9 of the target, 2 rounding and 2 residual_uncertainty)."""
    document = _at_cost(result, 1.05 * _least(result))
    item, matrix = _map_item(result)
    residuals, _, rounding = item.raw_residuals(matrix)
    allowance = 1e-9 * np.maximum(1.0, np.abs(item.target)) + 2 * rounding + 2 * item.residual_uncertainty(matrix)
    stated = np.array(result["maps"][0]["residuals"], dtype=float)
    document["maps"][0]["residuals"] = (np.sign(stated) * np.maximum(np.abs(stated) - 0.9 * allowance, 0.0)).tolist()
    return document


def _exact_residuals(result: dict) -> list[Fraction]:
    """The returned matrix's residuals on the data in exact arithmetic."""
    data = result["certificate"]["data"]["maps"][0]
    M = [[Fraction(v) for v in row] for row in result["maps"][0]["matrix"]]
    out = []
    for source, target in zip(data["source"], data["target"]):
        image = [sum(m * v for m, v in zip(row, [Fraction(s) for s in source] + [Fraction(1)])) for row in M]
        out += [Fraction(t) - image[k] / image[2] for k, t in enumerate(target)]
    return out


def test_a_far_map_cost_understated_within_the_least_cost_window_is_refused(far_resection):
    _refused(_understated(far_resection))


def test_the_understated_far_map_claims_a_quarter_of_its_exact_cost_and_zero_residuals(far_resection):
    """Machine-independent: the exact cost (determinacy.exact_squared_residuals, one float on every
    machine) is over 3 times the understated claim; every exact residual is above 1e-8 px while the
    forgery states at least half of them 0; its intervals are no wider than the genuine ones
    (narrower in the estimates' forms before 2, where the certified gap over a trivial bound set
    the genuine level; today's level, the exact residuals' at the Student quantile of 9 degrees of
    freedom, 1.54 times theirs, exceeds both gaps, and the understated cost does not move it)."""
    from geocert.formulations.fractional import determinacy

    forged = _understated(far_resection)
    item, matrix = _map_item(far_resection)
    exact = determinacy.exact_squared_residuals(item.source, item.target, matrix)
    claimed = forged["maps"][0]["cost"]
    assert forged["maps"][0]["certified"] and forged["certificate"]["items"][0]["cost"] == claimed
    assert exact > 3 * claimed and abs(exact - far_resection["maps"][0]["cost"]) < 0.05 * exact
    assert min(abs(r) for r in _exact_residuals(far_resection)) > 1e-8
    assert sum(r == 0 for r in np.ravel(forged["maps"][0]["residuals"])) >= 12
    for narrowed, genuine in zip(_widths(forged), _widths(far_resection)):
        assert narrowed <= genuine * (1 + 1e-9)


def test_a_far_map_cost_below_the_least_cost_is_refused(far_resection):
    _refused(_at_cost(far_resection, 0.9 * _least(far_resection)), "the solution costs")


# Class 2 (fixed): review 36's class 2 open for tracks: an interval's ends were held to 1e-9 of the
# value (1e-3 px at 1e6, for intervals 5e-8 wide); now the value is the returned point's coordinate
# and each end's offset from it is held to the width


def _far_track(offset: float, noise: float = 1e-6, seed: int = 5) -> dict:
    """Two points near (offset, -offset / 2, 0.3 offset) + (0, 0, 5), seen by three cameras K [I | -C]
    whose centres lie about 1 apart near the same offset, with Gaussian noise of ``noise`` px."""
    rng = np.random.default_rng(seed)
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    origin = np.array([offset, -0.5 * offset, 0.3 * offset])
    cameras = [K @ np.hstack([np.eye(3), -(origin + np.array([i - 1.0, 0.3 * i, 0.0]))[:, None]]) for i in range(3)]
    tracks = []
    for _ in range(2):
        X = np.append(origin + rng.uniform(-1, 1, 3) + np.array([0, 0, 5.0]), 1.0)
        points = [(P @ X)[:2] / (P @ X)[2] + rng.normal(0, noise, 2) for P in cameras]
        tracks.append({"views": [0, 1, 2], "points": np.array(points).tolist()})
    return {"kind": "triangulation", "data": {"cameras": [P.tolist() for P in cameras], "tracks": tracks},
            "options": {"norm": "L2L2", "certificate": "full"}}


@pytest.fixture(scope="module", params=[1e3, 1e6], ids=["offset_1e3", "offset_1e6"])
def far_track(request) -> dict:
    from geocert.jobs.runner import solve_job

    result = solve_job(_far_track(request.param))
    _valid(result)
    assert result["tracks"][0]["certified"] and result["tracks"][0]["determinacy"]["intervals"][0]["name"] == "x"
    return result


def _track_intervals_edited(result: dict, how: str) -> dict:
    """Track 0's point intervals (x, y, z; the depth's, near 5, is left) collapsed onto their values,
    or each moved with its value by ``how`` of it."""
    document = copy.deepcopy(result)
    _edit_intervals(document["tracks"][0]["determinacy"]["intervals"][:3], how)
    return document


@pytest.mark.parametrize("how", ["collapsed", "0.9e-9"])
def test_a_far_track_interval_collapsed_or_moved_with_its_value_is_refused(far_track, how):
    _refused(_track_intervals_edited(far_track, how))


def test_the_moved_track_interval_misses_the_returned_point_by_many_widths(far_track):
    point = far_track["tracks"][0]["point"]
    moved = _track_intervals_edited(far_track, "0.9e-9")["tracks"][0]["determinacy"]["intervals"]
    off = []
    for k, interval in enumerate(moved[:3]):
        width = interval["upper"] - interval["lower"]
        assert 0 < width < 1e-6 and interval["lower"] <= interval["value"] <= interval["upper"]
        assert interval["lower"] > point[k]  # the returned point lies outside its own interval
        off.append((interval["lower"] - point[k]) / width)
    assert max(off) > 10


def test_a_far_track_interval_moved_beyond_value_slack_is_refused(far_track):
    _refused(_track_intervals_edited(far_track, "1.5e-9"), "determinacy/intervals/0")


def test_a_far_track_cost_understated_within_the_former_window_is_refused(far_track):
    """Class 1 on tracks: the writer states the cost of the residuals computed exactly; restated at
    1.05 of the least review 36's window allowed (each residual within rounding + 2
    residual_uncertainty of the verifier's float one: at 1e6 a quarter of the exact cost), refused."""
    from geocert.core import exact
    from geocert.formulations.fractional.items import TrackItem

    cameras = np.array(far_track["certificate"]["data"]["cameras"], dtype=float)
    track = far_track["certificate"]["data"]["tracks"][0]
    item = TrackItem((cameras[track["views"]], np.array(track["points"], dtype=float)), "L2L2")
    X = np.append(far_track["tracks"][0]["point"], 1.0)
    assert far_track["tracks"][0]["cost"] == exact.cost(item.exact_residuals(X), "L2L2")
    residuals, _, rounding = item.raw_residuals(X)
    former = float((np.maximum(np.abs(residuals) - rounding - 2 * item.residual_uncertainty(X), 0.0) ** 2).sum())
    document = copy.deepcopy(far_track)
    stated = min(1.05 * former, 0.999 * far_track["tracks"][0]["cost"])
    for where in (document["tracks"][0], document["certificate"]["items"][0]):
        where["cost"], where["gap"] = stated, stated - where["lower_bound"]
    _refused(document, "the solution costs")


def test_a_far_track_value_an_ulp_off_the_returned_point_is_refused(far_track):
    """The x interval's value is the returned point's coordinate bit for bit: an ulp off, its ends
    with it (the interval's offsets left the writer's), is refused."""
    document = copy.deepcopy(far_track)
    interval = document["tracks"][0]["determinacy"]["intervals"][0]
    for name in ("value", "lower", "upper"):
        interval[name] = float(np.nextafter(interval[name], np.inf))
    _refused(document, "the returned point's x")


@pytest.mark.parametrize("share", [0.01, -0.01])
def test_a_far_track_interval_narrowed_or_widened_by_a_hundredth_of_its_width_is_refused(far_track, share):
    """An end's offset from the value is held to the width (NUMBER_SLACK and TRACK_WIDTH_SLACK of it
    and two ulps of the end), not to the value's size: a hundredth of a 5e-8 interval at 1e6 (about 4
    ulps) is refused."""
    document = copy.deepcopy(far_track)
    interval = document["tracks"][0]["determinacy"]["intervals"][0]
    width = interval["upper"] - interval["lower"]
    interval["lower"] += share * width
    interval["upper"] -= share * width
    _refused(document, "determinacy/intervals/0/lower")


def test_a_far_track_depth_interval_collapsed_is_refused(far_track):
    document = copy.deepcopy(far_track)
    depth = document["tracks"][0]["determinacy"]["intervals"][3]
    assert depth["name"].startswith("depth")
    depth["lower"] = depth["upper"] = depth["value"]
    _refused(document, "intervals/3/lower")


# Classes 3 and 4: far maps a writer under one kernel returns, refused under the other

CLASS_3 = ("review 37 class 3: estimates._check_maps holds a map estimate's value to MAP_VALUE_ROUNDING (8 ulps of "
           "the value and of the data's largest coordinate), while a far homography's centroid image, computed "
           "through the normalisers, differs between kernels by about 310 ulps at an offset of 1e6 (3.6e-8 px)")
CLASS_4 = ("review 37 class 4: an uncertified map's cost figure is held to figure_allowance (1e-9 absolute below a "
           "cost of 1), while at an offset of 1e7 the kernels' costs differ by 2e-9 (the objective check's own spread "
           "of them is larger)")


def _far_homography(offset: float, noise: float, seed: int) -> dict:
    """15 points uniform in [-100, 100]^2 mapped by a homography near the identity (a 0.1 linear part
    and a 1e-4 perspective row), Gaussian noise of ``noise`` px, both sides moved by ``offset``."""
    rng = np.random.default_rng(seed)
    source = rng.uniform(-100, 100, (15, 2))
    H = np.eye(3)
    H[:2, :2] += rng.normal(0, 0.1, (2, 2))
    H[2, :2] = rng.normal(0, 1e-4, 2)
    image = np.hstack([source, np.ones((15, 1))]) @ H.T
    target = image[:, :2] / image[:, 2:] + rng.normal(0, noise, (15, 2))
    return {"kind": "homography", "data": {"maps": [{"source": (source + offset).tolist(),
                                                     "target": (target + offset).tolist()}]},
            "options": {"norm": "L2L2", "certificate": "full"}}


FAR_MAPS = {"homography_1e6_5": (1e6, 0.0, 5), "homography_1e6_6": (1e6, 0.0, 6)}  # class 3 (certified)


def _with_uncertified(seed: int) -> dict:
    """Class 4's job: two maps, a near exact one (offset 1e4, certified) and one at 1e7 with 1e-3 px
    of noise (left uncertified: the data determine its cost only to within its spread)."""
    job = _far_homography(1e4, 0.0, seed)
    job["data"]["maps"].append(_far_homography(1e7, 1e-3, seed)["data"]["maps"][0])
    return job


@pytest.fixture(scope="module")
def far_maps_across_kernels(tmp_path_factory) -> dict:
    """Each far homography solved under Haswell's and Prescott's kernels, each document verified
    under the other's (review 35's subprocesses): {"written": {kernel: {job: result}},
    "checked": {writer: {job: [valid, first_failure]}}}."""
    if not _has_avx2():
        pytest.skip("needs OpenBLAS's Haswell and Prescott kernels (x86-64 with AVX2)")
    directory = tmp_path_factory.mktemp("far_maps")
    jobs = {**{name: _far_homography(*given) for name, given in FAR_MAPS.items()},
            **{f"homography_1e7_noisy_{seed}": _with_uncertified(seed) for seed in (5, 6)},
            **{f"proven_1e5_{seed}": _far_resection(1e5, 1e-3, seed) for seed in (5, 6)}}  # class 6
    written = {kernel: _run(kernel, "solve", jobs, directory) for kernel in ("Haswell", "Prescott")}
    own = {kernel: _run(kernel, "verify", written[kernel], directory) for kernel in written}
    for kernel, checked in own.items():  # each writer's documents verify under its own kernel (class 5's
        # proven resections but for class 5's refusal, a returned check after every claim's)
        assert all(valid or (job.startswith("proven") and failure["check"] == "returned")
                   for job, (valid, failure) in checked.items()), (kernel, checked)
    return {"written": written,
            "checked": {"Haswell": _run("Prescott", "verify", written["Haswell"], directory),
                        "Prescott": _run("Haswell", "verify", written["Prescott"], directory)}}


def _refusals(far_maps_across_kernels: dict, prefix: str) -> list:
    return [(job, writer, failure["detail"]) for writer, checked in far_maps_across_kernels["checked"].items()
            for job, (valid, failure) in checked.items() if job.startswith(prefix) and not valid]


def test_far_homographies_verify_under_another_kernel(far_maps_across_kernels):
    refusals = _refusals(far_maps_across_kernels, "homography_1e6")
    assert not refusals, refusals


def test_the_far_homographies_are_certified_with_their_estimates(far_maps_across_kernels):
    for kernel, results in far_maps_across_kernels["written"].items():
        for job in ("homography_1e6_5", "homography_1e6_6"):
            item = results[job]["maps"][0]
            assert item["certified"], (kernel, job)
            assert item["determinacy"]["intervals"][0]["name"] == "centroid_image_x", (kernel, job)


def test_an_uncertified_far_homography_verifies_under_another_kernel(far_maps_across_kernels):
    refusals = _refusals(far_maps_across_kernels, "homography_1e7_noisy")
    assert not refusals, refusals


def test_the_uncertified_far_homography_is_left_uncertified_by_both_kernels(far_maps_across_kernels):
    for kernel, results in far_maps_across_kernels["written"].items():
        for seed in (5, 6):
            near, far = results[f"homography_1e7_noisy_{seed}"]["maps"]
            assert near["certified"] and not far["certified"] and far["matrix"] is not None, (kernel, seed)


# determinacy.exact_squared_residuals: measured against Fractions, no class

def _fraction_squared_residuals(source, target, matrix) -> float:
    """Each residual computed in Fractions and rounded once to a float, the squares summed exactly."""
    total = Fraction(0)
    for X, x in zip(np.asarray(source, dtype=float).tolist(), np.asarray(target, dtype=float).tolist()):
        image = [sum(Fraction(m) * Fraction(v) for m, v in zip(row, X + [1.0])) for row in np.asarray(matrix).tolist()]
        if image[-1] == 0:
            return float("inf")
        total += sum(Fraction(float(Fraction(t) - image[k] / image[-1])) ** 2 for k, t in enumerate(x))
    return float(total)


@pytest.mark.parametrize("scale", [1.0, 1e-300, 5e-324, 1e-160, 1e160, 1e300])
@pytest.mark.parametrize("dims", [2, 3])
def test_exact_squared_residuals_are_the_fraction_sum_on_tiny_huge_and_subnormal_data(scale, dims):
    from geocert.formulations.fractional.determinacy import exact_squared_residuals

    rng = np.random.default_rng(37)
    source, target = rng.uniform(-1, 1, (6, dims)) * scale, rng.uniform(-1, 1, (6, dims))
    matrix = rng.normal(size=(dims + 1, dims + 1))
    matrix[-1] *= -1  # depths of either sign: the squares do not care
    assert exact_squared_residuals(source, target, matrix) == _fraction_squared_residuals(source, target, matrix)


def test_exact_squared_residuals_of_a_point_mapped_to_infinity_are_infinite():
    from geocert.formulations.fractional.determinacy import exact_squared_residuals

    rng = np.random.default_rng(37)
    matrix = rng.normal(size=(3, 3))
    matrix[2] = 0.0
    assert exact_squared_residuals(rng.uniform(-1, 1, (4, 2)), rng.uniform(-1, 1, (4, 2)), matrix) == float("inf")


def test_an_estimate_whose_exact_sum_overflows_is_left_out_on_both_sides():
    """A squared residual beyond the largest float: exact_squared_residuals gives inf (it raised
    OverflowError, against its docstring), and the estimate is none, the writer's and the
    verifier's alike (a null determinacy is accepted as it is)."""
    from geocert.core.determinacy import safely
    from geocert.formulations.fractional import determinacy

    rng = np.random.default_rng(37)
    source, target = rng.uniform(-1, 1, (8, 2)), rng.uniform(-1, 1, (8, 2)) * 1e200
    assert determinacy.exact_squared_residuals(source, target, np.eye(3)) == float("inf")
    assert safely(determinacy.map_, source, target, np.eye(3).tolist(), 1.0, 0.0) is None


# Class 3's value: a homography's centroid image computed exactly, the same float on every machine

def _fraction_centroid_image(source, matrix) -> list[float]:
    """The centroid of ``source`` and its image through ``matrix`` in Fractions, each coordinate
    rounded once to a float."""
    rows = np.asarray(source, dtype=float).tolist()
    centroid = [sum(Fraction(v) for v in column) / len(rows) for column in zip(*rows)] + [Fraction(1)]
    image = [sum(Fraction(m) * v for m, v in zip(row, centroid)) for row in np.asarray(matrix).tolist()]
    return [float(v / image[-1]) for v in image[:-1]]


@pytest.mark.parametrize("scale", [1.0, 1e-300, 5e-324, 1e6, 1e160, 1e300])
@pytest.mark.parametrize("dims", [2, 3])
def test_the_exact_centroid_image_is_the_fraction_one_on_tiny_huge_and_subnormal_data(scale, dims):
    from geocert.formulations.fractional.determinacy import exact_centroid_image

    rng = np.random.default_rng(37)
    source = rng.uniform(-1, 1, (7, dims)) * scale
    matrix = rng.normal(size=(dims + 1, dims + 1))
    assert exact_centroid_image(source, matrix) == _fraction_centroid_image(source, matrix)


def test_a_centroid_mapped_to_infinity_has_no_value():
    from geocert.formulations.fractional.determinacy import exact_centroid_image, map_

    source = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0], [2.0, 2.0]])  # centroid (1, 1)
    matrix = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, -2.0]])  # its third coordinate 0
    assert exact_centroid_image(source, matrix) == [float("inf")] * 2
    document = map_(source, source + 1.0, matrix, None, None)
    assert document is None or all(i["value"] is None and i["lower"] is None for i in document["intervals"])


def test_a_far_homographys_value_is_its_centroid_image_computed_exactly():
    """The writer states the exact centroid image (each coordinate rounded once), not the one
    through the normalisers, which another kernel rounded 310 ulps away at 1e6 (class 3)."""
    from geocert.jobs.runner import solve_job

    job = _far_homography(1e6, 1e-6, 5)
    result = solve_job(job)
    _valid(result)
    stated = [i["value"] for i in result["maps"][0]["determinacy"]["intervals"]]
    assert stated == _fraction_centroid_image(job["data"]["maps"][0]["source"], result["maps"][0]["matrix"])


# Fixed (review 38 class 4's fix): far off, a homography's value is held to an ulp of the exact
# centroid image and its ends read as offsets from it, so the interval collapsed onto its value or
# moved with it (1e-3 px at 1e6, hundreds of widths) is refused


@pytest.mark.parametrize("how", ["collapsed", "0.9e-9"])
def test_a_far_homography_interval_collapsed_or_moved_with_its_value_is_refused(how):
    from geocert.jobs.runner import solve_job

    result = solve_job(_far_homography(1e6, 1e-6, 5))
    _valid(result)
    document = copy.deepcopy(result)
    _edit_intervals(document["maps"][0]["determinacy"]["intervals"], how)
    _refused(document)


# The reference rules: guards

def test_stored_stratified_with_proofs_naming_a_null_reference_is_refused():
    """A proof stating "reference": null is not read as an earlier writer's unnamed proof."""
    from tests.verify.test_forgeries import stored

    certificate = copy.deepcopy(stored("autocalibration_stratified"))["certificate"]
    _valid(certificate)
    for item in certificate["items"]:
        item["proof"]["reference"] = None
    _refused(certificate, "proof/reference is None")


@pytest.mark.slow
def test_an_uncertified_metric_stage_naming_another_frame_is_refused(edge_service):
    """Review 36 class 4's fix the other way round: the affine stage certified in camera 3's frame,
    the metric stage made uncertified with its proof naming camera 1 (the fields left as returned)."""
    from geocert.verify.autocalibration import outcome

    document = copy.deepcopy(edge_service)
    for where in (document["stages"][1], document["certificate"]["items"][1]):
        where.update(status="not_certified", certified=False, lower_bound=None, gap=None)
    document["stages"][1].update(certificate=None, reason="the gap at the solution as returned exceeds the tolerance")
    document["certificate"]["items"][1]["proof"]["reference"] = 1
    document.update(outcome(document))
    document["stats"].update(certified=1, statuses={})
    _refused(document)


# Class 5: a resection's proven intervals and level: the estimate reads the exact r'r, the check the stated cost

CLASS_5 = ("review 37 class 5: since the map estimate's level reads exact_squared_residuals, a certified resection's "
           "level differs from the one fractional._check_map_level recomputes from the claimed cost (LEVEL_ROUNDING, "
           "1e-9) and from the level its sublevel proof is proven at, by 5e-7 at an offset of 1e5: the writer's own "
           "document is refused")


@pytest.fixture(scope="module")
def proven_far_resections() -> dict:
    """Resections at an offset of 1e5 with 1e-3 px of noise (seeds 5 and 6), certified by a search
    whose proof carries a sublevel bound, their estimates proven."""
    from geocert.jobs.runner import solve_job

    out = {}
    for seed in (5, 6):
        result = solve_job(_far_resection(1e5, 1e-3, seed))
        item = result["maps"][0]
        assert item["certified"] and "sublevel" in result["certificate"]["items"][0]["proof"]
        assert item["determinacy"]["proven"] is True and item["determinacy"]["proven_intervals"] is not None
        out[seed] = result
    return out


def test_proven_far_resections_verify_on_their_writers_machine(proven_far_resections):
    failures = {seed: _verify(result).first_failure for seed, result in proven_far_resections.items()}
    assert not any(failures.values()), failures


def test_the_exact_squared_residuals_differ_from_the_float_cost_beyond_level_rounding(proven_far_resections):
    """Machine-independent (the exact sum is one float everywhere; any machine's float sum of these
    residuals, 1e-3 px differences of terms of 1e5 * 800 px, rounds far beyond 1e-9 of the cost):
    the level the estimate reads and the level _check_map_level reads differ by more than it allows."""
    from geocert.formulations.fractional import determinacy
    from geocert.verify.fractional import LEVEL_ROUNDING

    for seed, result in proven_far_resections.items():
        item, matrix = _map_item(result)
        exact = determinacy.exact_squared_residuals(item.source, item.target, matrix)
        residuals, _, _ = item.raw_residuals(matrix)
        float_cost = float((residuals * residuals).sum())
        assert abs(exact - float_cost) > 10 * LEVEL_ROUNDING * float_cost, seed
        assert abs(exact - float_cost) < 1e-3 * float_cost, seed
        # the cost stated is the exact residuals' (class 1's fix): the level's sum to its rounding
        assert abs(exact - result["maps"][0]["cost"]) <= 1e-12 * exact, seed


def test_an_uncertified_far_homographys_figure_is_its_exact_cost_to_ulps():
    """Machine-independent: on class 4's far map the spread the verifier gives a float cost
    (cost_rounding at residual_uncertainty) is beyond the figure's 1e-9. Class 4's first fix held
    the figure to twice that spread, which let a far map's cost be stated 0 (review 38 class 2); now
    the figure is the cost of the exact residuals, as its writer states it, held to 1e-9 of itself
    and 4 ulps of each residual, far below that spread."""
    from geocert.jobs.runner import solve_job
    from geocert.core import exact
    from geocert.core.geometry import cost_rounding
    from geocert.verify.fractional import MapItems

    result = solve_job(_with_uncertified(5))
    assert not result["maps"][1]["certified"]
    _valid(result)
    certificate = result["certificate"]
    value, allowance = MapItems("homography", {(2, 2)}).solution_cost(certificate["data"], certificate["items"][1],
                                                                       certificate["options"])
    item, matrix = _map_item(result, 1)
    residuals, _, _ = item.raw_residuals(matrix)
    spread = cost_rounding(residuals, item.residual_uncertainty(matrix), "L2L2")
    assert value == exact.cost(item.exact_residuals(matrix), "L2L2") == result["maps"][1]["cost"]
    assert 1e-9 < spread and allowance < 1e-3 * spread


# Class 6: a far resection's sublevel proof, recomputed under another kernel (fixed: one recomputation,
# in a fixed order, on every machine)


def test_proven_far_resections_pass_their_proof_check_under_another_kernel(far_maps_across_kernels):
    refusals = [(job, writer, failure["detail"]) for writer, checked in far_maps_across_kernels["checked"].items()
                for job, (valid, failure) in checked.items()
                if job.startswith("proven") and not valid and failure["check"] != "returned"]
    assert not refusals, refusals



def test_a_far_resections_centre_narrowed_one_ulp_past_its_proven_bound_is_refused(proven_far_resections):
    """Class 6's fix allows the narrow side nothing: the recomputation is one float on every machine
    (fixed_order), so the stated intervals are the writer's bounds widened by STATED_SLACK of the
    half-width, and an end moved one ulp inside the bound recomputed here is refused."""
    from geocert.formulations.fractional.resection_sublevel import STATED_SLACK, Scene, proven_centre

    for seed, result in proven_far_resections.items():
        item, matrix = _map_item(result)
        sublevel = result["certificate"]["items"][0]["proof"]["sublevel"]
        scene = Scene(item.source, item.target, matrix, sublevel["reference"])
        bounds, _ = proven_centre(scene, sublevel["cost_increase"], sublevel["radius"], sublevel["rounds"])
        stated = np.array(sublevel["intervals"])
        half = 0.5 * (bounds[:, 1] - bounds[:, 0])
        assert np.all(stated[:, 0] <= bounds[:, 0]) and np.all(stated[:, 1] >= bounds[:, 1]), seed
        gap = np.maximum(bounds[:, 0] - stated[:, 0], stated[:, 1] - bounds[:, 1])
        assert np.all(gap <= 1.01 * STATED_SLACK * half + 2 * np.spacing(np.abs(bounds).max(axis=1))), seed
        for end, inward in ((0, np.inf), (1, -np.inf)):
            document = copy.deepcopy(result)
            edited = document["certificate"]["items"][0]["proof"]["sublevel"]["intervals"]
            edited[0][end] = float(np.nextafter(bounds[0, end], inward))
            _refused(document, "narrower than what the proof proves")

def test_stored_bilinear_frames_intervals_collapsed_are_refused():
    """Class 2's edit on a bilinear result: its coefficients are of unit size, so 1e-9 of the value
    is far below any width, and the collapsed intervals are refused."""
    from tests.verify.test_forgeries import stored

    document = copy.deepcopy(stored("bilinear_l2l2"))
    for frame in document["frames"]:
        for interval in frame["determinacy"]["intervals"]:
            if interval["lower"] is not None:
                interval["lower"] = interval["upper"] = interval["value"]
    _refused(document, "frames/0/determinacy/intervals/0/lower")


@pytest.mark.parametrize("norm", ["L2L1", "L1L1"])
def test_a_far_resections_search_summary_states_the_tolerance_of_its_stated_cost(norm):
    """Seen by review 37 and again by class 6's fix: a certified L2L1 or L1L1 resection 1e5 from the
    origin (1e-3 px, seed 5) was refused on its own machine, its summary's tolerance (the search's
    working one, from its incumbent's cost in the program) 1.1e-6 off the one its stated cost gives.
    The writer states the tolerance of the cost it states (items.stated_tolerance)."""
    from geocert.jobs.runner import solve_job

    job = _far_resection(1e5, 1e-3, 5)
    job["options"]["norm"] = norm
    result = solve_job(job)
    item = result["maps"][0]
    assert item["certified"] and item["certificate"]["leaves"] > 0
    options = result["certificate"]["options"]
    assert item["certificate"]["tolerance"] == max(options["abs_gap"], options["rel_gap"] * item["cost"])
    _valid(result)


@pytest.mark.parametrize("offset", [1e5, 1e6])
def test_a_far_homographys_cost_understated_within_its_targets_rounding_is_refused(offset):
    """Class 1's fix, its slack: a cost read from exact residuals is held to their ulps (and 1e-9 of
    abs_gap), not to the rounding allowance of a float evaluation (1e-14 of the target's size: on
    targets 1e6 from the origin, 2e-6 of this cost). A far homography (1e-3 px, certified) restated
    1e-7 (relative) below its cost is refused."""
    from geocert.jobs.runner import solve_job

    result = solve_job(_far_homography(offset, 1e-3, 5))
    assert result["maps"][0]["certified"]
    _valid(result)
    document = copy.deepcopy(result)
    stated = result["maps"][0]["cost"] * (1 - 1e-7)
    for where in (document["maps"][0], document["certificate"]["items"][0]):
        where["cost"], where["gap"] = stated, stated - where["lower_bound"]
    _refused(document, "the solution costs")
