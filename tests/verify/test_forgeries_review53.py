"""Review 53: the holes review 52 left open (the run controls, the depth-reversal record's
mirror_capped), subnormal numbers where a number must be exactly 0 or positive, and a hostile
review of the newest checks (review 51's and 52's: records.check, _check_nothing_direct,
summary.calibration.model, the pooled floor's charges, the scope's words on chirality and
varying_focal) and of every kind but stratified autocalibration's frame: each number of each stored
result (tests/data/certificates; for a long list of numbers its first two and last two) set to
5e-324, -5e-324, -0.0 or 1e-300 where it was 0, and to 5e-324 or 1e-300 (its sign kept) where it
was not, the options among them with their hashes made again; the newest checks' members set to
null, "", a padded or capitalised word, 0, false, [] or {}, or deleted; the direct method's options
restated beside a stratified proof.

Part A (review 52's holes, decided):

- A run control (max_nodes, time_limit_s, job_time_limit_s, a reconstruction's stage limits)
  restated below what the proof implies (max_nodes 1 beside a proof of 30 leaves, a time limit of
  5e-324 s) verified, and the report said nothing of them. Decided: informational, and the report
  says so (scope.run_control: taken as stated, not checked against the proof). Hashing them would
  bind nothing (a forger makes the hash again, as these tests do); a check against the proof holds
  only for max_nodes and only loosely (a node closes up to 2d + 1 leaves: its box and the parts
  tightening cuts off; an autocalibration stage runs several searches on one budget), and a time
  limit has no machine-independent tie to a proof at all. No claim depends on them.
- summary.depth_reversal.mirror_capped (with the record's costs, noise and the twin's own counts
  and focal length) cannot be derived without running the twin's adjustment again. Decided: taken
  as stated, and the report now says so (scope.depth_reversal) where a record is stated; before,
  only docs/certificate.md did.
- Subnormals: refused already in dual vectors (no entry subnormal), units and scales (reviews
  before), below the diagonal of a reconstruction's cameras' K and of its stages' K (exact 0), and a
  rel_gap or abs_gap of 5e-324 is a gap of 0 in effect (the kinds allow 0; the scope then names the
  items abs_gap certifies). Found (classes 1 and 2 below): a returned K's lower triangle and a
  skew the camera model does not have.

Found (a test below for each, which failed while the class stood):

1. An autocalibration result's returned K, each of its Ks and each metric camera's K (either
   method's; a stratified result's K itself is its claim's, exact already) with an entry
   below the diagonal of 5e-324, -5e-324 or 1e-300 (or K[2][2] within rounding of 1) verified:
   they were read only within 1e-9 of the K recomputed from the quadric or the claims, so a
   matrix no calibration is (not upper triangular) was returned as one. Fixed:
   autocalibration._check_calibration_forms (exact 0 below the diagonal, K[2][2] exactly 1, as
   upper_triangular_root and the cameras' RQ write them; -0.0 is 0).
2. A reconstruction whose adjustment's model has no skew ("simple", "varying") returning a camera
   whose K states a skew of 5e-324, -5e-324 or 1e-300 verified: the model's calibration is read off
   each P within 1e-6 of the focal length (PER_VIEW_APART), and K only within rounding of P. Fixed:
   reconstruction_members._check_calibration, each camera's K[0][1] exactly 0 under such a model
   (the bundle adjustment and the start put in the model write it so).

Held (tried and refused, or accepted only where the edit claims nothing false):

- Every number of each stored result edited as above: refused but for informational figures
  (times, nodes, a leaf proof's bound lowered, focal rounds, the initial pair's thresholds and
  figures, RMS values, linear_K, rotation noise), proof parameters whose every change the verifier
  rechecks (a leaf's box widened, a root's claimed box around its proven range), determinacy
  intervals widened (a weaker statement: their check is that they hold the walked ones), a bilinear
  baseline's coefficient 0 moved within BASELINE_TOLERANCE (an estimate, read within its rounding),
  the autocalibration stage's K's skew within calibration_claim.SAME of the certified K's,
  counts and view indices 0 written -0.0 (the same number), and the run controls (Part A).
- summary.calibration.model null, "", "shared " or "SHARED", 0, false, [] or {}: refused; the
  member deleted: accepted (a document of the form before it claims no model; nothing else reads
  one). summary.warnings' entries {}, {"code": null}, an unknown code or a list: refused.
- A stratified stage's order, moment_rank or conic_status null: accepted (claims nothing); any
  other value, and Ks [], {}, false, 0 or [null]: refused. chirality restated true or false:
  refused; varying_focal false restated: verified with the scope saying it is not read;
  relaxation_order restated: only 2 is accepted (the one order served), so it states nothing a
  reader could misread.

Found, not fixed:

- None beyond Part A's decisions: the run controls and the depth-reversal record's costs and
  mirror_capped are taken as stated, and the report says so.
"""

from __future__ import annotations

import copy
import json

import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import TINY, refused_naming as _refused_naming, stored


# Part A1: run controls restated below what the proof implies, said to be taken as stated

@pytest.mark.parametrize("name, option, value", [
    ("resection_caps", "max_nodes", 1),  # beside a proof of 30 leaves
    ("triangulation_l2l2", "time_limit_s", TINY),
    ("homography_far_from_origin", "job_time_limit_s", TINY),
    ("bilinear_l2l2", "max_nodes", 1),
    ("autocalibration_direct", "time_limit_s", 1e-300),
    ("reconstruction", "max_nodes", 1),
])
def test_a_run_control_restated_below_its_proof_is_reported_taken_as_stated(name, option, value):
    """The document verifies (no claim depends on a run control; none is hashed, so the hashes
    stand), and its report says the stated value is taken as stated, unchecked against the proof,
    where before it said nothing of it."""
    forged = stored(name)
    forged["certificate"]["options"][option] = value
    report = verify_any(json.loads(json.dumps(forged)))
    assert report.valid, report.first_failure
    words = report.scope["run_control"]
    assert words.startswith("taken as stated") and f"{option} {value!r}" in words
    assert "not checked against the proof" in words and "no claim depends on them" in words


def test_every_stored_documents_report_names_its_run_controls():
    for name in ("triangulation_l2l1", "resection_l1l1", "homography2_l2l2", "bilinear_l1l1",
                 "autocalibration_stratified", "reconstruction_labelled"):
        report = verify_any(stored(name))
        assert report.valid and "max_nodes" in report.scope["run_control"], name


# Part A2: the depth-reversal record's mirror_capped (and costs) taken as stated, and said so

@pytest.fixture(scope="module")
def varying() -> dict:
    """A genuine reconstruction of today's form (six views, a focal length each) stating its
    depth-reversal record."""
    from geocert.jobs.runner import solve_job
    from tests.verify.test_forgeries_review46 import _varying_job

    return json.loads(json.dumps(solve_job(_varying_job())))


def test_a_depth_reversal_records_mirror_capped_is_reported_taken_as_stated(varying):
    record = varying["summary"]["depth_reversal"]
    assert record["checked"] is True and "mirror_capped" in record
    forged = copy.deepcopy(varying)
    forged["summary"]["depth_reversal"]["mirror_capped"] = not record["mirror_capped"]
    for document in (varying, forged):
        report = verify_any(json.loads(json.dumps(document)))
        assert report.valid, report.first_failure
        words = report.scope["depth_reversal"]
        assert words.startswith("taken as stated") and "mirror_capped" in words and "two costs" in words


# Class 1: a returned K of an autocalibration result not upper triangular (a subnormal below it)

@pytest.mark.parametrize("value", [TINY, -TINY, 1e-300])
@pytest.mark.parametrize("name, path", [
    ("autocalibration_direct", ("Ks", 0, 1, 0)),
    ("autocalibration_direct", ("Ks", 1, 2, 1)),
    ("autocalibration_direct", ("cameras", 0, "K", 2, 0)),
    ("autocalibration_direct_points", ("K", 1, 0)),
    ("autocalibration_direct_points", ("cameras", 2, "K", 2, 1)),
    ("autocalibration_stratified", ("cameras", 0, "K", 1, 0)),  # the metric cameras, read alike
])
def test_a_returned_K_with_a_subnormal_below_its_diagonal_is_refused(name, path, value):
    forged = stored(name)
    target = forged
    for key in path[:-1]:
        target = target[key]
    assert target[path[-1]] == 0
    target[path[-1]] = value
    _refused_naming(forged, "returned", "/".join(map(str, path[:-2])), "calibration matrix")


def test_a_returned_K_written_with_minus_zero_below_its_diagonal_verifies():
    """-0.0 is 0 (the writer's sign flips may write it): a K exactly upper triangular."""
    document = stored("autocalibration_direct_points")
    document["K"][2][0] = -0.0
    document["cameras"][0]["K"][1][0] = -0.0
    report = verify_any(json.loads(json.dumps(document)))
    assert report.valid, report.first_failure


# Class 2: a skew the reconstruction's camera model does not have

@pytest.mark.parametrize("value", [TINY, -TINY, 1e-300])
@pytest.mark.parametrize("name", ["reconstruction", "reconstruction_labelled", "varying"])
def test_a_cameras_skew_under_a_model_without_skew_is_refused(name, value, request):
    forged = copy.deepcopy(request.getfixturevalue("varying")) if name == "varying" else stored(name)
    camera = next(c for c in forged["cameras"] if c["registered"])
    assert camera["K"][0][1] == 0
    camera["K"][0][1] = value
    _refused_naming(forged, "returned", "skew", "the model has none")
