"""Review 64: a hostile review of the trust boundary after review 63's fixes (issue 33): the
proof reasons' table (core.proven_reasons, estimates.check_proven_reason), the estimates' form 2
and its rules, and the fields no check ties to the certificate.

Tried (forgeries built from the stored certificates and from jobs solved here with solve_job;
verify_any on the JSON text):

- Every returned field (outside the certificates) of the triangulation, resection, homography
  and bilinear examples solved today, five stratified views (form 2), a one-K direct stage with
  both proofs asked, and the stored labelled reconstruction: up to 1,200 edits a document (a
  number times 1.5, negated, plus 1, 0, 5e-324, null; a flag flipped or null; a text replaced or
  "(proven)" appended; a member dropped). Accepted beyond classes 4 and 6: timings, counts of
  nodes and leaves, a note, an estimate dropped (claims nothing), an interval widened or made
  unbounded, entries below a K's diagonal as 0 or -0.0, a pose entry moved by 1e-17, a pooled
  track's pool indices (documented), a direct summary's conic_status text, and a
  reconstruction's stage figures (its initial pair, forward motion, focal rounds, radial k1,
  thresholds: informational records, docs/certificate.md).
- proven_reason (class 1): the writer's words with its fields changed; held: texts not the
  writer's, reasons on stages not asked, the exact not_full and not_certified texts.
- The form-2 rules: no_redundancy, at_range_edge (focal and aspect) dropped on solved scenes held;
  few_degrees_of_freedom did not (class 2). A track's not_analysed held (review 63); the clock's
  code did not (class 3), nor an autocalibration stage's not_analysed with no motion (class 5).
- A reconstruction point's determinacy stated (held), a proven_reason on its calibration item
  (not reachable: the reconstruction's stages and summary are closed records; an autocalibration
  document built round its calibration certificate states the options an autocalibration job
  with a proof asked would, so "metric_none" there cannot be told from a search that found
  nothing without running it again: left).
- Cost: a proven_reason of 10^7 digits (0.03 s, refused now).

Found (each test failed on the code before its fix):

1. A proof's reason in its writer's words says what the options and the stage deny: the stored
   stratified document's metric stage (time limit 60 s) verified "the search for K's intervals
   proved none within its 1e+09 s" (the search runs at most the least of the time limit and 20 s)
   and "the stage states no cost or no cost increase" beside a cost 2.2e-12 and a cost increase
   1.0e-12; a direct stage solved with one K and both proofs asked verified a reason naming "each
   view's focal length" (varying_focal false), one leaving out that the other intrinsics' proofs
   were asked for, and "ran out 1e+09 s into the proof" under a 3600 s limit. The pattern
   (proven_reasons.is_reason) held each field only to its kind. Fixed: estimates.
   check_reason_fields holds what and after to the options, the seconds to the search's bound
   (the direct writer now states where the limit ran out, its deadline less the proof's start,
   not when a check noticed it), and metric_no_level to its writer's condition.
2. ``few_degrees_of_freedom`` dropped from an autocalibration stage verified: five views at 0.001
   (seed 2; the affine search stopped at 300 nodes, the metric stage certified) give an affine stage of redundancy 1 whose only warning is few_degrees_of_freedom
   (a noise level read off one residual); without it, and restated determined (its four plane
   intervals bounded), it verified. The verifier compared no stage's warnings with its level's
   degrees of freedom (only no_redundancy's 0, check_no_redundancy). Fixed: estimates.
   check_few_degrees, from the redundancy check_redundancy ties to the number of views, in form 2.
3. A track's, map's or frame's estimate replaced by a stopped one (core.determinacy.not_analysed:
   no interval, not determined) whose code is ``time_limit`` verified on the stored
   triangulation, resection, homography and bilinear documents (each item replaced determined),
   and a bilinear frame's ``not_analysed`` too: review 63 refused a map's not_analysed and judged
   a track's, and left the clock's code unjudged, though no clock stops these analyses (only the
   autocalibration stages' run under core.determinacy.within). The reason is false and the
   item's intervals and warnings hidden. Fixed: estimates._refuse_clock for tracks, maps and
   frames; a frame's not_analysed refused as a map's.
4. A certified item's ``reason`` is free text: the stored triangulation's first track (certified)
   verified with "not certified: the search stopped at its node limit; this point is not
   optimal", as did a certified map and frame (the fuzzing of every returned field of the
   triangulation, resection, homography and bilinear examples solved today found it: 1,200
   edits a document, the rest accepted were timings, a drop of an estimate and the pool's track
   indices, all documented as informational or unchecked). Their writers state a reason only
   for an item they do not certify. Fixed: checks.REASONLESS_WHEN_CERTIFIED (tracks, maps,
   frames); an uncertified item's reason stays informational (docs/certificate.md).
5. An autocalibration stage stated not analysed because "the data defeated its linear algebra"
   (code ``not_analysed``, no interval) with no critical motion after it verified: the five
   views' metric stage (determined, no warning), either stage of it, and the direct stage of
   class 1's scene. Its writer (autocalibration.determinacy.with_motion) states that code only
   beside the motion it judged; a failed analysis with none is written null. Fixed: estimates.
   check_defeated. (The same code beside a critical motion, and ``time_limit``, are left to the
   writer's word: telling its analysis failed would need the analysis made again, whose
   linear algebra may fail on one machine and not another; the motion stays required.)
6. An uncertified autocalibration stage's summary took any scope and tolerance: the five views'
   affine stage (stopped at its node limit) verified with the scope "every plane at infinity
   chirality allows (proven)" and a tolerance of -1, where an uncertified track's or map's
   states its search's words and a tolerance at least 0. Only a certified stage's scope was
   held to the kind's words (review 15). Fixed: autocalibration._check_uncertified_summary (the
   stage's words, or "" where the metric stage never ran; null or a tolerance at least 0).
"""

from __future__ import annotations

import copy
import json

import pytest

from geocert.core import proven_reasons
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored

pytestmark = pytest.mark.filterwarnings("ignore")


def _report(document: dict):
    return verify_any(json.loads(json.dumps(document)))


def _refused_for_reason(document: dict) -> bool:
    report = _report(document)
    return not report.valid and "proven_reason" in report.first_failure["detail"]


# 1. A proof's reason whose fields the options and the stage deny

def _stratified_with_reason(text: str) -> dict:
    document = stored("autocalibration_stratified")  # a full certificate, time_limit_s 60
    document["stages"][1]["determinacy"]["proven_reason"] = text
    return document


def test_a_stratified_reason_within_its_search_bound_verifies():
    assert _report(_stratified_with_reason(proven_reasons.reason("metric_none", seconds=20))).valid


@pytest.mark.parametrize("text", [
    proven_reasons.reason("metric_none", seconds=1e9),  # the search runs at most min(60, 20) s
    proven_reasons.reason("metric_none", seconds=21),
    proven_reasons.reason("metric_no_level"),  # the stage states a cost and a cost increase
])
def test_a_stratified_reason_the_stage_denies_is_refused(text):
    determinacy = stored("autocalibration_stratified")["stages"][1]["determinacy"]
    assert determinacy["cost_increase"] > 0
    assert _refused_for_reason(_stratified_with_reason(text))


@pytest.fixture(scope="module")
def direct_stopped() -> dict:
    """One K, both proofs asked, time_limit_s 3600: the focal proof stopped by the deadline at once
    (tests/kinds/test_direct_proven_reason's scene)."""
    from tests.kinds.test_direct_proven_reason import solved_with_proofs_stopped

    return solved_with_proofs_stopped(certificate="full")


def test_the_direct_writers_stopped_reason_states_its_deadline_and_verifies(direct_stopped):
    reason = direct_stopped["stages"][0]["determinacy"]["proven_reason"]
    seconds = float(proven_reasons.fields(reason, "direct_stopped")["seconds"])
    assert 3500 < seconds <= 3602 * 1.005, reason  # the limit and grace less the solve's seconds
    assert _report(direct_stopped).valid


@pytest.mark.parametrize("key,fields", [
    ("direct_none", {"what": proven_reasons.WHAT[1], "after": proven_reasons.AFTER[1]}),  # not varying_focal
    ("direct_failed", {"what": proven_reasons.WHAT[0], "after": "", "error": "LinAlgError"}),  # intrinsics asked
    ("direct_stopped", {"what": proven_reasons.WHAT[0], "after": proven_reasons.AFTER[1], "seconds": 1e9}),
])
def test_a_direct_reason_the_options_deny_is_refused(direct_stopped, key, fields):
    options = direct_stopped["certificate"]["options"]
    assert options["varying_focal"] is False and options["prove_intrinsics_intervals"] is True
    forged = copy.deepcopy(direct_stopped)
    forged["stages"][0]["determinacy"]["proven_reason"] = proven_reasons.reason(key, **fields)
    assert _refused_for_reason(forged)


# 2. few_degrees_of_freedom dropped from an autocalibration stage

@pytest.fixture(scope="module")
def five_views() -> dict:
    """Five views at 0.001 (seed 2): the affine search ends at its node limit (300 nodes, about
    2 s; no clock decides it), the metric stage certified with no warning; the affine stage's
    estimate is stated whether or not it is certified."""
    from geocert.jobs.runner import solve_job
    from geocert.solvers.autocalibration import scenes

    scene = scenes.make_scene(5, 0.001, seed=2)
    return json.loads(json.dumps(solve_job({"kind": "autocalibration", "data": scene.job_data(),
                                            "options": {"time_limit_s": 600, "max_nodes": 300,
                                                        "certificate": "full", "method": "stratified"}})))


def test_an_affine_stage_of_one_degree_of_freedom_restated_determined_is_refused(five_views):
    from geocert.core.determinacy import fixes

    genuine = five_views
    affine = genuine["stages"][0]["determinacy"]
    assert affine["redundancy"] == 1 and [w["code"] for w in affine["warnings"]] == ["few_degrees_of_freedom"]
    assert _report(genuine).valid
    forged = copy.deepcopy(genuine)
    affine = forged["stages"][0]["determinacy"]
    affine["warnings"] = []
    affine["determined"] = all(fixes(i) for i in affine["intervals"])
    assert affine["determined"]
    report = _report(forged)
    assert not report.valid and "few_degrees_of_freedom" in report.first_failure["detail"], report.first_failure


# 3. A track's, map's or frame's estimate stated stopped by a clock no writer runs

@pytest.mark.parametrize("name,member", [("triangulation_l2l2", "tracks"), ("resection_l2l2", "maps"),
                                         ("homography2_l2l2", "maps"), ("bilinear_l2l2", "frames")])
@pytest.mark.parametrize("code", ["time_limit", "not_analysed"])
def test_an_estimate_stated_stopped_where_its_writer_analyses_is_refused(name, member, code):
    from geocert.core.determinacy import not_analysed

    forged = stored(name)
    assert forged[member][0]["determinacy"]["determined"] is True
    forged[member][0]["determinacy"] = not_analysed("the estimate", "its clock ran out", code)
    report = _report(forged)
    assert not report.valid and f"{member}/0/determinacy" in report.first_failure["detail"], report.first_failure


# 4. A certified item's reason saying it is not

@pytest.mark.parametrize("name,member", [("triangulation_l2l2", "tracks"), ("resection_l2l2", "maps"),
                                         ("homography2_l2l2", "maps"), ("bilinear_l2l2", "frames")])
def test_a_certified_items_reason_is_refused(name, member):
    forged = stored(name)
    assert forged[member][0]["certified"] is True and forged[member][0]["reason"] is None
    forged[member][0]["reason"] = "not certified: the search stopped at its node limit; this point is not optimal"
    report = _report(forged)
    assert not report.valid and f"{member}/0/reason" in report.first_failure["detail"], report.first_failure


# 5. An autocalibration stage stated defeated by the data with no motion to state

@pytest.mark.parametrize("stage", [0, 1])
def test_a_stratified_stage_stated_defeated_without_a_motion_is_refused(five_views, stage):
    from geocert.core.determinacy import not_analysed

    assert _report(five_views).valid
    forged = copy.deepcopy(five_views)
    determinacy = forged["stages"][stage]["determinacy"]
    assert not [w for w in determinacy["warnings"] if w["code"] != "few_degrees_of_freedom"]  # no motion
    forged["stages"][stage]["determinacy"] = not_analysed("the stage's determinacy",
                                                          "the data defeated its linear algebra", "not_analysed")
    report = _report(forged)
    assert not report.valid and "not analysed" in report.first_failure["detail"], report.first_failure


def test_the_direct_stage_stated_defeated_without_a_motion_is_refused(direct_stopped):
    from geocert.core.determinacy import not_analysed

    forged = copy.deepcopy(direct_stopped)
    determinacy = forged["stages"][0]["determinacy"]
    assert determinacy["intervals"] and determinacy["warnings"] == []
    forged["stages"][0]["determinacy"] = {
        **not_analysed("the direct stage's determinacy", "the data defeated its linear algebra", "not_analysed"),
        "proven_reason": determinacy["proven_reason"]}
    report = _report(forged)
    assert not report.valid and "not analysed" in report.first_failure["detail"], report.first_failure


# 6. An uncertified stage's summary: its scope and tolerance

@pytest.mark.parametrize("member,value", [("scope", "every plane at infinity chirality allows (proven)"),
                                          ("tolerance", -1.0)])
def test_an_uncertified_stages_summary_claiming_more_is_refused(five_views, member, value):
    forged = copy.deepcopy(five_views)
    stage = forged["stages"][0]
    assert stage["certified"] is False and stage["certificate"]["scope"] == "every plane at infinity chirality allows"
    stage["certificate"][member] = value
    report = _report(forged)
    assert not report.valid and f"stages/0/certificate/{member}" in report.first_failure["detail"], \
        report.first_failure
