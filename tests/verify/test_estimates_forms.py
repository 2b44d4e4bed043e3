"""The estimates' forms (core.determinacy.FORMS, hashed into the problem hash): a document is read
in the form its hash declares. Documents of form 1 (every interval states its tolerance; levels at
3 standard errors whatever the degrees of freedom), written by that form's code and stored under
tests/data/certificates/earlier/ (make_tolerance_form.py), still verify, their report saying which
form they are of; today's documents are written and checked in today's form (issue 37: levels at
the Student quantile of the fit's degrees of freedom), and a document of form 1 cannot claim
today's form by its hash."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from geocert.core.certificates import data_hash, problem_hash
from geocert.core.determinacy import CURRENT_FORM, ESTIMATES_FORM, FORMS, level_sigmas
from geocert.jobs.runner import solve_job
from geocert.kinds import get_kind
from geocert.verify.checks import verify_any
from tests.support import map_job, seed

EARLIER = Path(__file__).resolve().parents[1] / "data" / "certificates" / "earlier"
TOLERANCE_FORM = ("resection_six_points_tolerance_form", "autocalibration_stratified_tolerance_form",
                  "autocalibration_four_views_tolerance_form")


def stored(name: str) -> dict:
    return json.loads((EARLIER / f"{name}.json").read_text())


def hashed_as(result: dict, marks: dict) -> dict:
    """The result with its certificate's problem hash made again with the form ``marks``."""
    result = copy.deepcopy(result)
    document = result["certificate"]
    names = getattr(get_kind(document["kind"]).verification, "claim_options", None)
    document["data_sha256"] = data_hash(document["kind"], document["data"])
    document["problem_sha256"] = problem_hash(document["kind"], document["data"], document["options"], names, marks)
    return result


def test_today_is_the_last_form_and_form_1_is_the_one_before():
    assert CURRENT_FORM == len(FORMS) == 2 and ESTIMATES_FORM == FORMS[-1]
    assert FORMS[0] == {"determinacy": "every interval states its tolerance"}


@pytest.mark.parametrize("name", TOLERANCE_FORM)
def test_a_stored_document_of_form_1_verifies_in_its_form(name):
    result = stored(name)
    report = verify_any(result)
    assert report.valid, report.first_failure
    assert "an earlier form of the estimates" in report.scope["problem_sha256"]
    # its hash is of form 1's mark: the same document hashed as today's form is read by today's
    # rules, under which its estimates are not the writer's
    assert hashed_as(result, FORMS[0])["certificate"]["problem_sha256"] == result["certificate"]["problem_sha256"]


def test_a_form_1_resection_claiming_todays_form_is_refused():
    """Its 6-point maps' levels are 3^2 times the residual variance; today's form reads them at
    the Student quantile of one degree of freedom (235.8^2), so the estimate is not today's."""
    report = verify_any(hashed_as(stored("resection_six_points_tolerance_form"), ESTIMATES_FORM))
    assert not report.valid and report.first_failure["check"] == "returned", report.first_failure


def test_todays_six_point_resection_states_the_student_level_and_verifies():
    result = solve_job(map_job(np.random.default_rng(seed("form 2", "resection")), "resection", 6, "L2L2", maps=2,
                               noise=0.5))
    report = verify_any(result)
    assert report.valid, report.first_failure
    assert "problem_sha256" not in report.scope  # today's form: nothing said of an earlier one
    for item, claim in zip(result["maps"], result["certificate"]["items"]):
        determinacy = item["determinacy"]
        assert determinacy["redundancy"] == 1
        assert level_sigmas(1) == pytest.approx(235.80149796, rel=1e-9)
        # the level: the Student quantile's square times the fit's residual variance (its cost over
        # one degree of freedom), or the certified gap where that is larger
        assert determinacy["cost_increase"] >= level_sigmas(1) ** 2 * claim["cost"] * (1 - 1e-9)


def test_a_principal_point_stated_at_the_focal_lengths_tolerance_is_refused_in_todays_form():
    """Issue 37 F4: today's form holds a principal point's and skew's tolerance to a tenth of half
    the image's larger side; one stated at a tenth of the focal length (form 1's) is refused, and
    the stored form-1 document, which states that, verifies in its form (above)."""
    job = get_kind("autocalibration").example
    result = json.loads(json.dumps(solve_job({**job, "options": {**job.get("options", {}), "certificate": "full"}})))
    assert verify_any(result).valid
    metric = result["stages"][1]["determinacy"]
    side = 0.5 * max(result["certificate"]["data"]["image_size"])
    focal = 0.5 * (metric["intervals"][0]["value"] + metric["intervals"][1]["value"])
    assert [i["tolerance"] for i in metric["intervals"][2:]] == pytest.approx([0.1 * side] * 3, rel=1e-12)
    for found in metric["intervals"][2:]:
        found["tolerance"] = 0.1 * focal
    report = verify_any(result)
    assert not report.valid and "tolerance" in report.first_failure["detail"], report.first_failure
    earlier = stored("autocalibration_stratified_tolerance_form")["stages"][1]["determinacy"]["intervals"]
    assert earlier[3]["tolerance"] == pytest.approx(0.1 * 0.5 * (earlier[0]["value"] + earlier[1]["value"]))


def _without_no_redundancy(result: dict) -> dict:
    """The result with every stage's no_redundancy warning left out, ``determined`` restated as the
    remaining warnings and the intervals give it (so that only the warning's absence is wrong)."""
    from geocert.core.determinacy import fixes

    result = copy.deepcopy(result)
    for stage in result["stages"]:
        determinacy = stage["determinacy"]
        determinacy["warnings"] = [w for w in determinacy["warnings"] if w["code"] != "no_redundancy"]
        determinacy["determined"] = all(fixes(i) for i in determinacy["intervals"]) and not determinacy["warnings"]
    return result


def test_four_views_without_no_redundancy_are_refused_in_todays_form_and_not_in_form_1():
    """Four views: the affine stage's three modulus constraints fit the plane's three unknowns
    exactly. Today's form requires both stages to warn no_redundancy (issue 37); a stored document
    of form 1, which was not required to, still verifies with the warnings left out."""
    from geocert.solvers.autocalibration import scenes

    scene = scenes.make_scene(4, 0.1, seed=1)
    result = json.loads(json.dumps(solve_job({"kind": "autocalibration", "data": scene.job_data(),
                                              "options": {"time_limit_s": 60, "certificate": "full"}})))
    assert verify_any(result).valid
    assert all("no_redundancy" in [w["code"] for w in stage["determinacy"]["warnings"]] for stage in result["stages"])
    report = verify_any(_without_no_redundancy(result))
    assert not report.valid and "no_redundancy" in report.first_failure["detail"], report.first_failure
    earlier = stored("autocalibration_four_views_tolerance_form")
    assert verify_any(earlier).valid
    report = verify_any(_without_no_redundancy(earlier))
    assert report.valid, report.first_failure
