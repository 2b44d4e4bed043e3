"""Review 23 (issue 33): a hostile review of the registration at the estimated principal point (the
projective stage's principal_point record, the one-K reference), the tie's other tracks, the
K-known radial term and the direct autocalibration's proven focal interval.

Found (verified on main, each test below failing there): the projective stage's principal_point
record was the document's word. On the (+30, -20) off-centre run, whose certificate's cameras are
built at the estimated principal point (349.2, 219.8), the document verified with the record saying
the registration held the principal point at the centre (estimated false), with no record, and
with its K_free (the cameras' K when estimated) moved to the images' centre or to 1.5 times the
focal length. The tie now reads the record beside the certificate's cameras
(calibration_tie._check_registration_record).

Not fixed (the xfail below): the tie's other tracks are the result's placed points, and a point
the structure stage drops (its safety net, pipeline._drop_outlier_points) leaves the document
altogether: its observations are in neither the result nor its certificates. A result keeping
only the 20 tracks nearest the scene's middle, the other 180 stated as dropped (summary and
structure counts, the warning), carries a certificate of those 20 re-posed at 1.5 times the focal
length at the record's principal point (1199 px, the tracks' 800) and verifies, determined, no
critical motion (its shared cost 44 px^2 against 54.5 allowed): the fit test's slack (review 22's
xfail) on tracks that barely fix the focal length. 40 tracks at 1.3 times verify too; 6 at twice
verify only stating the motion critical and K not determined (the motion judged from 6 points).

Not fixed (the second xfail): K known with a radial term kept, every k1 doubled alike (the
cameras', the summary's with its statement and warning, the adjustment's test's) verifies, and so
do the test's chi2, observations, residual_dof and k1_tested edited: the result returns the
undistorted observations only, the term is stated estimated and not certified, the certificates
conditional on it; the raw observations (the input) alone refute it.

Tried and not passing: the projective record's inside_middle_half false (its own test); the bundle
adjustment's principal_point estimated false (the simple model's principal point held); the test's
model "on" beside options "auto"; summary/distortion/focal_px moved by 1e-7. The direct proven
interval: a local search (SLSQP over rank-3 PSD quadrics, 12 starts a side) on Table 7.1's seed 0
found focal lengths within the level up to 0.99651969, the proven upper end 0.99652009: inside.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.verify.checks import verify_any
from tests.support import stage as _stage
from tests.verify.test_forgeries_review18 import SHIFTS, _scene_job


@pytest.fixture(scope="module")
def off_centre() -> dict:
    """The (+30, -20)-shifted scene, 200 tracks, cameras not resected (no camera certificate to
    re-solve when points are taken out): its registration estimates the principal point."""
    result = solve_job(_scene_job({"resect_cameras": False}, points=200,
                                  shift=np.tile(SHIFTS["(+30, -20)"], (8, 1))))
    assert _stage(result, "projective")["principal_point"]["estimated"] is True
    return result


def _verifies(result: dict):
    return verify_any(json.loads(json.dumps(result)))


def test_the_genuine_off_centre_run_verifies(off_centre):
    report = _verifies(off_centre)
    assert report.valid, report.first_failure


def _record(result: dict) -> dict:
    return _stage(result, "projective")["principal_point"]


EDITS = {
    "held at the centre": lambda r: _record(r).update(estimated=False),
    "held, its chi2 below the threshold": lambda r: _record(r).update(estimated=False, chi2=3.0),
    "no record": lambda r: _stage(r, "projective").pop("principal_point"),
    "K_free at the centre": lambda r: _record(r).update(
        K_free=[[_record(r)["K_free"][0][0], 0.0, 319.5], [0.0, _record(r)["K_free"][0][0], 239.5], [0.0, 0.0, 1.0]]),
    "K_free at 1.5 times the focal length": lambda r: _record(r).update(
        K_free=(np.asarray(_record(r)["K_free"]) @ np.diag([1.5, 1.5, 1.0])).tolist()),
}


@pytest.mark.parametrize("edit", sorted(EDITS))
def test_the_registration_record_must_say_what_the_certificate_is_built_at(off_centre, edit):
    """Found: each edit verified on main (the record read only for its own test's figures)."""
    forged = copy.deepcopy(off_centre)
    EDITS[edit](forged)
    report = _verifies(forged)
    assert not report.valid
    assert "stages/projective/principal_point" in report.first_failure["detail"], report.first_failure


def test_an_estimated_record_beside_a_centred_certificate_is_refused(off_centre):
    """The reverse: the record says the registration estimated the principal point, and the
    certificate's cameras are built at the centre (the returned K otherwise, the same poses)."""
    from geocert.formulations.reconstruction import calibration_tie
    from tests.verify.test_forgeries_review18 import _reposed

    K = np.array(next(c for c in off_centre["cameras"] if c.get("registered"))["K"], dtype=float)
    K[:2, 2], K[0, 1] = [319.5, 239.5], 0.0
    with pytest.raises(calibration_tie.Invalid, match="K_free"):
        calibration_tie.tie(off_centre, _stage(off_centre, "autocalibration"), _reposed(off_centre, K))


def _dropped(result: dict, count: int, scale: float) -> dict:
    """The result keeping the ``count`` tracks nearest the scene's middle, the others stated as
    dropped by the structure stage, carrying a certificate of those tracks re-posed at ``scale``
    times the focal length (review 22's forger, at the record's principal point)."""
    from tests.verify.test_calibration_tie import carrying
    from tests.verify.test_forgeries import rehash
    from tests.verify.test_forgeries_review22 import _central

    forged, data = _central(result, count, scale, every_track=False)
    forged = carrying(forged, data)
    held = set(_stage(forged, "autocalibration")["certificate_tracks"])
    dropped = len(forged["points"]) - len(held)
    forged["points"] = [p for p in forged["points"] if p["track"] in held]
    certificate = forged["certificate"]
    keep = [k for k, t in enumerate(certificate["data"]["input_labels"]["track_numbers"]) if t in held]
    certificate["data"]["tracks"] = [certificate["data"]["tracks"][k] for k in keep]
    certificate["data"]["input_labels"]["track_numbers"] = [
        certificate["data"]["input_labels"]["track_numbers"][k] for k in keep]
    certificate["items"] = [dict(certificate["items"][k], index=i) for i, k in enumerate(keep)]
    rehash(certificate)
    summary = forged["summary"]
    summary.update(points=len(held), points_certified=len(held), points_dropped=dropped,
                   observations=sum(len(p["observations"]) for p in forged["points"]))
    _stage(forged, "structure").update(points=len(held), points_dropped=dropped, certified=len(held))
    summary["warnings"].append({"code": "points_dropped", "detail": f"{dropped} certified points lay beyond the "
                                                                    "threshold"})
    errors = []
    cameras = {c["view"]: np.asarray(c["P"], dtype=float) for c in forged["cameras"] if c.get("registered")}
    for p in forged["points"]:
        for v, u, w in p["observations"]:
            x = cameras[v] @ np.r_[p["point"], 1.0]
            errors.append(np.hypot(x[0] / x[2] - u, x[1] / x[2] - w))
    summary["rms_reprojection_px"] = float(np.sqrt(np.mean(np.square(errors))))
    return forged


def test_middle_tracks_kept_and_the_rest_stated_dropped_is_refused(off_centre):
    """A dropped point leaves the document (its observations in neither the result nor a
    certificate), so the tie's other tracks cannot hold it: 20 middle tracks kept, 180 stated as
    dropped, beside a certificate at 1.5 times the focal length. Verified with the fit test's slack
    of one returned cost (44.0 px^2 against 54.5 allowed); refused by the shared observations' fit
    since that slack is the noise's."""
    forged = _dropped(off_centre, 20, 1.5)
    calibration = forged["summary"]["calibration"]
    assert abs(calibration["certified_K"][0][0] / 800.0 - 1.5) < 0.02  # a false focal length, certified
    assert calibration["determined"] is True and forged["summary"]["critical_motion"] is None
    report = _verifies(forged)
    assert not report.valid
    assert "fits the" in str(report.first_failure), report.first_failure


# --- the K-known radial term -------------------------------------------------------------------

from tests.verify.test_forgeries_radial_known_K import known_K_with_k1  # noqa: E402,F401 (a fixture)


@pytest.mark.xfail(strict=True, reason="the result returns the undistorted observations only (the raw ones are the "
                                       "input's, not the document's), so no k1 of the same sign is refutable from "
                                       "it: the term is stated estimated, not certified, the certificates "
                                       "conditional on it; refutable only beside the input")
def test_every_k1_doubled_alike_is_refused(known_K_with_k1):
    """Verifies: every k1 (the cameras', the summary's, its statement and warning, the adjustment's
    test's) doubled alike, a term twice the one estimated (the scene's -0.25)."""
    from tests.verify.test_forgeries_radial_known_K import _restated

    forged = copy.deepcopy(known_K_with_k1)
    _restated(forged, 2 * forged["summary"]["distortion"]["k1"])
    for camera in forged["cameras"]:
        if camera.get("k1") is not None:
            camera["k1"] *= 2
    _stage(forged, "bundle_adjustment")["radial_distortion"]["k1"] *= 2
    assert not _verifies(forged).valid
