"""Review 50: a hostile review of the kinds other than reconstruction (triangulation under each
norm, batched and convexity-path tracks; resection and homography maps; bilinear; stratified and
direct autocalibration), one edit at a time of genuine full certificates of small scenes: every
member of the result and of the certificate beside its data set to 5e-324, -0.0, 0.0, 1e308,
-1e308, "NaN", null, half, one and a half times, a relative 1e-6 off; strings to other words of
the product (norms, statuses, proof types, methods); booleans flipped; lists duplicated at either
end, cut at either end, reversed, emptied; records given an extra member or missing one; each
option restated with its hashes made again.

Found (a test below for each, which failed while the class stood):

1. An autocalibration stage's determinacy may state any ``method`` and ``level`` (its words for
   what the intervals are): the stratified affine and metric stages' and the direct stage's alike.
   A curvature estimate relabelled ``"method": "proven"`` with the proven intervals' own level
   ("every solution in the certificate's scope whose cost exceeds the optimum's by at most
   cost_increase lies in these intervals; ...") verifies, so a reader takes the affine stage's
   unproven plane-at-infinity estimate (its ``proven`` false, no proven intervals) for intervals
   a proof covers. The track, map and frame estimates compare both words with their writer's
   (estimates.COMPARED); the autocalibration writer (core.determinacy.Determinacy.document) states
   only "curvature" and its default level, for every stage, analysed or not.
   Where: verify/autocalibration.py, check_returned and the direct arm: no check reads the words.
   Fixed at the cause: estimates.check_stage_words holds each stage's method and level to the
   writer's.

Held (plain tests below for the first two; the rest tried by the sweep above and refused, or
accepted only where the edit claims nothing false):

- A proof with no search (a triangulation's convexity bound, a resection's sublevel bound: nodes
  0) under a max_residual restated below its solution's residuals, hashes made again, is refused
  (check ``scope``); restated above them the resection's verifies, and is true (its proof covers
  every map), and the convexity proof is refused under any max_residual (check ``convexity``).
- A camera scaled by a subnormal factor, hashes made again, is refused where the scaling rounds
  the camera (the claimed cost is no longer the data's); scaled by -1 (every point behind it)
  refused at its depth.
- Accepted and claiming nothing false: a leaf box widened, a leaf's recorded bound or upper_bound
  lowered or raised within its slack, leaves reordered or a leaf proof repeated, a root claim box
  widened, a tightening round dropped or its cap raised, gaps (abs_gap, rel_gap) restated smaller
  where the other gap still holds, max_residual restated above every residual, an estimate's
  numbers moved within NUMBER_SLACK, an autocalibration estimate's interval widened (its check
  asks only that it hold the walked one: estimates of a stage are refitted with scipy), run-control
  options (max_nodes, time limits, certificate, detail) restated, informational words (reason,
  conic_status, note removed). A summary's ``leaves`` written as -0.0 verifies (equal to 0; JSON
  readers alike take it for 0).
- Not a class: a stratified autocalibration certificate stating ``varying_focal: true`` verifies
  with a scope identical to the genuine one. The solver took that option (a direct-method option)
  for a stratified job and ignored it, so a genuine earlier document may state it; a submission
  asking for it is refused since (kinds.autocalibration.METHOD_OPTIONS), the verifier still reads it.
"""

from __future__ import annotations

import copy
import json

import pytest

from geocert.core.determinacy import proven_document
from geocert.jobs.runner import solve_job
from geocert.kinds import get_kind
from geocert.verify.checks import verify_any


def _example(kind: str, **options) -> dict:
    example = get_kind(kind).example
    job = {**example, "options": {**example.get("options", {}), "certificate": "full", **options}}
    return json.loads(json.dumps(solve_job(job)))


@pytest.fixture(scope="module")
def stratified() -> dict:
    return _example("autocalibration", method="stratified")


@pytest.fixture(scope="module")
def direct() -> dict:
    return _example("autocalibration", method="direct")


# Class 1: an autocalibration stage's determinacy words are free

def test_the_genuine_autocalibrations_verify(stratified, direct):
    for result in (stratified, direct):
        report = verify_any(result)
        assert report.valid, report.first_failure


PROVEN_WORDS = proven_document(1.0, ("x",), [[0.0, 1.0]], "the curvature's ellipsoid")["level"]


@pytest.mark.parametrize("which, stage", [("stratified", 0), ("stratified", 1), ("direct", 0)])
@pytest.mark.parametrize("words", [{"method": "proven", "level": PROVEN_WORDS}, {"method": "sublevel"},
                                   {"level": PROVEN_WORDS}])
def test_an_estimate_worded_as_a_proof_is_refused(request, which, stage, words):
    forged = copy.deepcopy(request.getfixturevalue(which))
    determinacy = forged["stages"][stage]["determinacy"]
    assert determinacy["method"] == "curvature"
    determinacy.update(words)
    report = verify_any(forged)
    assert not report.valid
    assert report.first_failure["check"] == "returned" and f"stages/{stage}/determinacy" in report.first_failure["detail"]


# Held: max_residual restated on a proof with no search

@pytest.mark.parametrize("kind, proof, above", [("triangulation", "convexity", False),
                                                ("resection", "sublevel_bound", True)])
def test_a_max_residual_below_the_solutions_residuals_is_refused_on_a_proof_without_search(kind, proof, above):
    from tests.verify.test_forgeries import rehash

    result = _example(kind, norm="L2L2")
    assert result["certificate"]["items"][0]["proof"]["type"] == proof
    assert verify_any(result).valid
    for max_residual, valid in ((1e-3, False), (1e3, above)):
        forged = copy.deepcopy(result)
        forged["certificate"]["options"]["max_residual"] = max_residual
        rehash(forged["certificate"], marked=True)
        report = verify_any(json.loads(json.dumps(forged)))
        assert report.valid is valid, report.first_failure
        if max_residual < 1:
            assert report.first_failure["check"] == "scope"


# Held: a camera scaled to a subnormal (rounding it) or by -1, hashes made again

@pytest.mark.parametrize("scale, cameras", [(2.0 ** -1060, "all"), (-1.0, 0)])
def test_a_camera_rounded_by_a_subnormal_scale_or_turned_around_is_refused(scale, cameras):
    from tests.verify.test_forgeries import rehash

    forged = _example("triangulation", norm="L2L2")
    data = forged["certificate"]["data"]
    for index in (range(len(data["cameras"])) if cameras == "all" else [cameras]):
        data["cameras"][index] = [[value * scale for value in row] for row in data["cameras"][index]]
    rehash(forged["certificate"], marked=True)
    report = verify_any(json.loads(json.dumps(forged)))
    assert not report.valid
