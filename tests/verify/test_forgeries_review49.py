"""Review 49: a hostile review of the pooled levels' degrees of freedom (fractional._check_pooled,
pooled_floor) and of a reconstruction's points' determinacy (the kind writes null).

Found (a test below for each):

1. A triangulation track's determinacy read at a level pooled over the job's tracks states, in
   its ``level`` sentence, the degrees of freedom its pool's variance is estimated from
   (determinacy.pooled_level: "(13 degrees of freedom, ...)"). The verifier checked the pool
   (pooled_tracks) and the cost_increase against the floor recomputed from the pool's
   residuals, but took the degrees of freedom as written: every track of a genuine result
   restated at 0 or 10^9 degrees of freedom (a pool of five tracks of 2 and more views holds 13
   at most; 10^9 reads as a variance known exactly, its Student quantile the normal's) verified.
   Where: verify/fractional.py, _check_pooled (pooled_dof read, only its presence checked).
   Fixed: pooled_floor.pooled_bounds gives the floor and the least and most degrees of freedom
   the writer's pooling may keep of the pool's tracks (those surely pooled; those surely or
   possibly pooled), and a stated figure outside them is refused, naming the level.

2. A reconstruction's points are written with ``"determinacy": null`` (kinds.reconstruction:
   the stages' analyses are not run for them), and nothing checked a point's determinacy
   beyond "not proven": a point stating one (a triangulation track's estimate, or any object
   saying proven: false) verified, an estimate of the point's uncertainty no writer made and no
   check recomputed. Where: verify/reconstruction.py, ReconstructionItems.check_returned.
   Fixed: a point's determinacy other than null is refused, naming it.

3. An autocalibration stage's determinacy states ``method`` "curvature" and core.determinacy's
   default ``level`` sentence on every path (autocalibration.determinacy sets neither), and no
   check read either: a stage's estimate said to be a search's ("branch_and_bound") or its level
   said to be a proof's ("every solution in the certificate's scope ... lies in these
   intervals") verified beside proven: false, in the direct and the stratified documents alike;
   a triangulation's, resection's or bilinear frame's words are checked exactly. Where:
   verify/autocalibration.py, check_returned (stratified and direct). Fixed: estimates.
   check_stage_words refuses other words, naming the member.

4. A certified reconstruction point's summary (``certificate``) with ``scope``, ``root_region``,
   ``tolerance``, ``tolerance_met`` or ``leaves`` deleted verified, where a triangulation track's
   (the same writer, track_document) is refused. Where: verify/checks.py, COMPLETE (no entry
   for a reconstruction's points). Fixed: a point's ``certified`` is listed there, so that the
   certified summary's members are required as a track's are.

Held (looked at, nothing found): single-field edits of the stored reconstruction's summary,
stats, images, stages, points and cameras (each number scaled, negated or zeroed, each boolean
flipped, each string extended; each member deleted (but a certified point's summary members:
class 4), a determinacy or an unknown member added)
are refused but for informational figures the docs name so (times, the registration's
thresholds and focal rounds, the adjustment's RMS, words) and members an earlier form lacks; the
same edits of a pooled triangulation's tracks and stats (with NaN, infinities, 1e308, the least
subnormal and -0.0 too) are refused but for times; of the stored resection, homography and
bilinear results, all refused; of the stored autocalibration results, refused but for times,
solver status words, the stage estimates' words (class 3) and their intervals widened, which a
document hashed without the estimates' form may state (docs/certificate.md: an end may hold the
metric walk's or the curvature's; wider holds the recomputed interval).
"""

from __future__ import annotations

import copy
import json

import pytest

from geocert.formulations.fractional.determinacy import pooled_dof, pooled_level
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored
from tests.verify.test_forgeries_review7 import far_two_view_track  # noqa: F401 (a fixture)


# Class 1: a pooled level's degrees of freedom as written

def test_the_genuine_pooled_result_verifies(far_two_view_track):  # noqa: F811
    result = json.loads(json.dumps(far_two_view_track[1]))
    assert all(pooled_dof(t["determinacy"]["level"]) is not None for t in result["tracks"])
    report = verify_any(result)
    assert report.valid, report.first_failure


def _restated(result: dict, dof: int) -> dict:
    forged = json.loads(json.dumps(result))
    for track in forged["tracks"]:
        determinacy = track["determinacy"]
        determinacy["level"] = pooled_level((determinacy["cost_increase"], dof))
    return forged


@pytest.mark.parametrize("dof", ["none", "one more than the pool holds", "a billion"])
def test_a_pooled_level_stating_degrees_of_freedom_its_pool_does_not_hold_is_refused(far_two_view_track, dof):  # noqa: F811
    result = far_two_view_track[1]
    data = result["certificate"]["data"]
    most = sum(2 * len(track["views"]) - 3 for track in data["tracks"])  # every track of the pool pooled
    stated = {"none": 0, "one more than the pool holds": most + 1, "a billion": 10 ** 9}[dof]
    report = verify_any(_restated(result, stated))
    assert not report.valid
    assert report.first_failure["check"] == "returned", report.first_failure
    assert "/determinacy/level" in report.first_failure["detail"], report.first_failure


def test_the_degrees_of_freedom_the_writer_states_are_within_the_bounds(far_two_view_track):  # noqa: F811
    """The genuine figure lies within what the verifier derives from the pool (the premise)."""
    import numpy as np

    from geocert.core.geometry import normalised_cameras
    from geocert.verify.pooled_floor import pooled_bounds, squared_residuals

    result = far_two_view_track[1]
    data = result["certificate"]["data"]
    cameras = normalised_cameras(data["cameras"])
    costs = [squared_residuals(cameras, t["views"], t["points"], r["point"]) for t, r in zip(data["tracks"],
                                                                                           result["tracks"])]
    dofs = [2 * len(t["views"]) - 3 for t in data["tracks"]]
    floor, least, most = pooled_bounds(np.array(costs), np.array(dofs))
    stated = pooled_dof(result["tracks"][0]["determinacy"]["level"])
    assert least <= stated <= most
    assert floor <= result["tracks"][0]["determinacy"]["cost_increase"]


# Class 2: a reconstruction point's determinacy, which its writer leaves null

def test_the_stored_reconstruction_states_no_point_determinacy():
    result = stored("reconstruction")
    assert all(point["determinacy"] is None for point in result["points"])
    report = verify_any(result)
    assert report.valid, report.first_failure


@pytest.mark.parametrize("stated", ["a triangulation track's", "proven false"])
def test_a_reconstruction_point_stating_a_determinacy_is_refused(stated):
    forged = stored("reconstruction")
    if stated == "proven false":
        determinacy = {"method": "curvature", "proven": False, "determined": True, "intervals": [], "warnings": []}
    else:
        determinacy = copy.deepcopy(stored("triangulation_l2l2")["tracks"][0]["determinacy"])
    forged["points"][0]["determinacy"] = determinacy
    report = verify_any(forged)
    assert not report.valid
    assert report.first_failure["check"] == "returned", report.first_failure
    assert "points/0/determinacy" in report.first_failure["detail"], report.first_failure


# Class 3: an autocalibration stage's determinacy words (method, level), which nothing read

AUTOCALIBRATION_DOCUMENTS = ["autocalibration_direct", "autocalibration_stratified", "autocalibration_five_views"]
WORDS = [("method", "branch_and_bound"),
         ("level", "every solution in the certificate's scope whose cost exceeds the optimum's by at most "
                   "cost_increase lies in these intervals; by the metric stage's proof")]


@pytest.mark.parametrize("name", AUTOCALIBRATION_DOCUMENTS)
def test_the_stored_autocalibrations_state_the_writers_words(name):
    from geocert.core.determinacy import Determinacy

    result = stored(name)
    written = Determinacy().document()
    for stage in result["stages"]:
        assert stage["determinacy"]["method"] == written["method"]
        assert stage["determinacy"]["level"] == written["level"]
    report = verify_any(result)
    assert report.valid, report.first_failure


@pytest.mark.parametrize("name", AUTOCALIBRATION_DOCUMENTS)
@pytest.mark.parametrize("member, words", WORDS)
def test_an_autocalibration_stages_determinacy_in_other_words_is_refused(name, member, words):
    """The writer states every stage's estimate in core.determinacy's one method and level
    sentence (the analyses of autocalibration.determinacy set neither): other words claim a
    method or a level no writer used and no check read (a level sentence saying the intervals
    are a proof's verified beside proven: false)."""
    forged = stored(name)
    forged["stages"][-1]["determinacy"][member] = words
    report = verify_any(forged)
    assert not report.valid
    assert report.first_failure["check"] == "returned", report.first_failure
    assert f"stages/{len(forged['stages']) - 1}/determinacy/{member}" in report.first_failure["detail"], \
        report.first_failure


# Class 4: a certified reconstruction point's summary with members left out

@pytest.mark.parametrize("member", ["scope", "root_region", "tolerance", "tolerance_met", "leaves"])
def test_a_reconstruction_points_summary_leaving_out_a_member_is_refused(member):
    """The writer states a certified point's summary as a triangulation track's (track_document:
    the same summary), and a track's leaving one out is refused; a point's verified."""
    forged = stored("reconstruction")
    assert forged["points"][0]["certified"] is True
    del forged["points"][0]["certificate"][member]
    report = verify_any(forged)
    assert not report.valid
    assert report.first_failure["check"] == "returned", report.first_failure
    assert "points/0/certificate" in report.first_failure["detail"], report.first_failure
    assert member in report.first_failure["detail"], report.first_failure
