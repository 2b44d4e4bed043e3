"""Review 45's stage records the verifier can tie to what it holds (issue 33), each held now:

- the autocalibration stage's points_used is the calibration certificate's count of points (both
  the points upgrade.autocalibrate chose): a count beside the certificate that states another is
  refused (calibration_tie.tie);
- principal_point_per_view's ``precise`` restates its sd_px (each at most max_sd_px), and beside
  ``estimated`` false it cannot join a chi-square above its threshold and every principal point
  in the middle half: that test would have kept them (reconstruction_members.
  _check_principal_points_per_view).

The adjustment's rms_px_after is not tied: it is the RMS over the observations the adjustment
kept, of the points it adjusted, before the sanity layer and the certified structure re-triangulate
the points the result returns, so nothing returned recomputes it (docs/certificate.md lists it
among the informational figures)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.reconstruction import synthetic
from geocert.verify.checks import verify_any

VIEWS = 8


def _job(principal_point: str) -> dict:
    """Eight general views sharing one principal point, 0.3 px noise (the per-view test runs and
    keeps the shared one)."""
    scene = synthetic.scene(views=VIEWS, points=200, seed=6, noise_px=0.3, spread_degrees=50.0)
    return json.loads(json.dumps(solve_job({
        "kind": "reconstruction", "options": {"certificate": "full", "principal_point": principal_point},
        "data": {"views": [{"image_size": list(scene.image_size)}] * VIEWS,
                 "tracks": [{"views": [int(v) for v in views], "points": pixels.tolist()}
                            for views, pixels in scene.tracks]}})))


@pytest.fixture(scope="module")
def shared() -> dict:
    return _job("per_view")


def _stage(result: dict, name: str) -> dict:
    return next(stage for stage in result["stages"] if stage["name"] == name)


def _refused(forged: dict) -> None:
    report = verify_any(forged)
    assert not report.valid and report.first_failure["check"] == "returned", report.first_failure


def test_the_genuine_result_verifies(shared):
    report = verify_any(shared)
    assert report.valid, report.first_failure


def test_points_used_beside_a_certificate_of_another_count_is_refused(shared):
    stage = _stage(shared, "autocalibration")
    assert shared.get("calibration_certificate") is not None
    assert stage["points_used"] == len(shared["calibration_certificate"]["data"]["points"])
    for count in (stage["points_used"] + 1, stage["points_used"] - 1):
        forged = copy.deepcopy(shared)
        _stage(forged, "autocalibration")["points_used"] = count
        _refused(forged)


def test_precise_beside_an_sd_above_its_limit_is_refused(shared):
    test = _stage(shared, "bundle_adjustment")["principal_point_per_view"]
    assert test["estimated"] is False and isinstance(test.get("sd_px"), list)
    forged = copy.deepcopy(shared)
    record = _stage(forged, "bundle_adjustment")["principal_point_per_view"]
    record.update(precise=True, sd_px=record["sd_px"][:2] + [2.0 * record["max_sd_px"]])
    _refused(forged)


def test_a_passed_test_beside_estimated_false_is_refused(shared):
    """chi2 above the threshold, inside the middle half and precise: the test would have kept a
    principal point per view, so ``estimated`` false beside them is refused."""
    test = _stage(shared, "bundle_adjustment")["principal_point_per_view"]
    assert test["estimated"] is False and test["chi2"] < test["threshold"]
    forged = copy.deepcopy(shared)
    record = _stage(forged, "bundle_adjustment")["principal_point_per_view"]
    record.update(chi2=2.0 * record["threshold"], inside_middle_half=True, precise=True,
                  sd_px=[min(s, record["max_sd_px"]) for s in record["sd_px"]])
    _refused(forged)
    failed = copy.deepcopy(forged)  # the same record with the middle half failed: a test that did not pass
    _stage(failed, "bundle_adjustment")["principal_point_per_view"]["inside_middle_half"] = False
    report = verify_any(failed)
    assert report.valid, report.first_failure
