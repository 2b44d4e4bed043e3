"""Review 21 (issue 33): forged records of the reconstruction's focal length per view test
(stages.bundle_adjustment.focal_per_view). The verifier read the test's chi2 against the
document's own threshold, and never the screen's z, z_threshold, views named or parameters
added: a record stating a threshold of 0, a z_threshold below every z, or a view whose z lies
within the threshold named as set apart, verified. It now recomputes both quantiles at the
test's level and the views they name. The principal point's tests (the shared one's and the
per-view one's) read their chi2 against the document's threshold too: now against theirs."""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from geocert.verify.checks import verify_any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipelines" / "reconstruction"))
import test_focal_per_view as genuine  # noqa: E402


@pytest.fixture(scope="module")
def result():
    scene, tracks = genuine._scene(True, genuine.SMALLER_FACTOR)
    return genuine._job(tracks, scene.image_size)


def _test(document: dict) -> dict:
    return genuine._adjustment(document)["focal_per_view"]


FORGERIES = {
    # the chi-square below its quantile at 0.999 (10.83 for one parameter), the threshold lowered under it
    "threshold_lowered": lambda t: t.update(chi2=5.0, threshold=4.0),
    "threshold_zero": lambda t: t.update(chi2=1e-300, threshold=0.0),
    # the view named has a z within the screen's threshold
    "named_view_within_z_threshold": lambda t: t["z"].__setitem__(genuine.LONGER, 0.5),
    # the screen's threshold lowered below every z: any view may be named
    "z_threshold_lowered": lambda t: t.update(z_threshold=0.0),
    "parameters_added_more": lambda t: t.update(parameters_added=5),
    "parameters_added_none": lambda t: t.update(parameters_added=0),
    "z_for_fewer_views": lambda t: t.update(z=t["z"][:2]),
    "too_few_observations": lambda t: t.update(observations=3),
}
# The principal point tests before it (the same hole: their chi2 against the document's threshold).
# The shared one's threshold is 13.8 (2 parameters at 0.999); the per-view one's, here 36.12 for 14.
POINT_FORGERIES = {
    "shared_threshold_lowered": ("principal_point", lambda t: t.update(chi2=5.0, threshold=4.0)),
    "per_view_threshold_lowered": ("principal_point_per_view", lambda t: t.update(chi2=30.0, threshold=29.0)),
    "per_view_parameters_fewer": ("principal_point_per_view",
                                  lambda t: t.update(chi2=30.0, threshold=29.58829844507442, parameters_added=10)),
    "per_view_parameters_odd": ("principal_point_per_view", lambda t: t.update(parameters_added=13)),
    "per_view_too_few_observations": ("principal_point_per_view", lambda t: t.update(observations=3)),
}


def test_the_genuine_record_verifies(result):
    report = verify_any(json.loads(json.dumps(result)))
    assert report.valid, report.first_failure


@pytest.mark.parametrize("name", sorted(FORGERIES))
def test_a_focal_test_record_with_its_own_quantiles_is_refused(result, name):
    forged = copy.deepcopy(result)
    FORGERIES[name](_test(forged))
    report = verify_any(forged)
    assert not report.valid and report.first_failure["check"] == "returned", (name, report.first_failure)
    assert "focal_per_view" in report.first_failure["detail"], report.first_failure


@pytest.mark.parametrize("name", sorted(POINT_FORGERIES))
def test_a_principal_point_test_record_with_its_own_threshold_is_refused(result, name):
    forged = copy.deepcopy(result)
    record, change = POINT_FORGERIES[name]
    change(genuine._adjustment(forged)[record])
    report = verify_any(forged)
    assert not report.valid and report.first_failure["check"] == "returned", (name, report.first_failure)
    assert record in report.first_failure["detail"], report.first_failure


def test_the_verifiers_quantiles_are_scipys():
    """The verifier's numpy-free quantiles (bisection on the closed forms) equal scipy's, which the
    pipeline states, to the comparison's 1e-9, for every parameter count up to thousands."""
    from scipy.stats import chi2, norm

    from geocert.verify import reconstruction_members as members
    for k in (1, 2, 3, 4, 5, 7, 10, 11, 64, 999, 2000):
        assert members._close_quantile(float(chi2.ppf(1 - members.FOCAL_P, k)), members._chi2_quantile(0.999, k)), k
    for views in (3, 8, 11, 100, 5000):
        p = 1 - members.FOCAL_P / (2 * views)
        assert members._close_quantile(float(norm.ppf(p)), members._normal_quantile(p)), views


@pytest.mark.parametrize("per_view", [None, {"estimated": False}])
def test_a_focal_test_record_where_no_such_test_runs_is_refused(result, per_view):
    """The pipeline runs the focal length's test only once a principal point per view was kept: a
    record of it (here one saying it kept nothing, the cameras sharing one focal length and one
    principal point) beside no principal point test or one that kept none states a test that
    never ran. Checked on the stage (the cameras of a run without per-view principal points)."""
    from geocert.core.strict import Invalid
    from geocert.verify.reconstruction_members import _check_focals_per_view

    forged = copy.deepcopy(result)
    reference = next(c for c in forged["cameras"] if c["view"] != genuine.LONGER)
    for camera in forged["cameras"]:  # every camera with one K (the reference's): as a run with no test kept
        pose = np.column_stack([np.array(camera["R"]), np.array(camera["t"])])
        camera["P"] = (np.array(reference["K"]) @ pose).tolist()
    stage = genuine._adjustment(forged)
    stage["focal_per_view"] = {"estimated": False, "views": [], "reason": "no view's focal length stands apart from "
                                                                          "the others'"}
    stage["principal_point_per_view"] = per_view
    if per_view is None:
        del stage["principal_point_per_view"]
    with pytest.raises(Invalid, match="focal_per_view is stated"):
        _check_focals_per_view(forged, stage)
    stage["principal_point_per_view"] = {"estimated": True}  # where the test runs, the same record passes this check
    _check_focals_per_view(forged, stage)


# L1 resection centre (proof.sublevel.centre, fractional.resection_centre_l1): no forgery found.
# A guard, passing on main's code as on this branch: the classes tried (mu 0, subnormal, 1e-310,
# huge, 2^128, the stated one scaled; y on the dual norm's unit sphere, one ulp outside it, the
# stated one; NaN, bools, strings, shapes; narrowed intervals; radius halved or subnormal; rounds
# out of range) either are refused or prove bounds holding every camera a local search finds
# within the level.
@pytest.mark.parametrize("norm", ("L1L1", "L2L1"))
def test_stated_multipliers_never_bound_the_centre_short_of_a_camera_within_the_level(norm):
    from geocert.jobs.runner import solve_job
    from geocert.formulations.fractional import resection_centre_l1 as centre_l1
    from geocert.formulations.fractional.resection_sublevel import Scene, proven_centre
    from tests.solvers.fractional.test_resection_leaves import local_search, resection

    rng = np.random.default_rng(5)
    job, _ = resection(rng, 16, norm, noise=1.0)
    document = solve_job(job)
    item, proof = document["maps"][0], document["certificate"]["items"][0]["proof"]["sublevel"]
    source, target = (np.array(job["data"]["maps"][0][key]) for key in ("source", "target"))
    increase = item["determinacy"]["proven_intervals"]["cost_increase"]
    P = np.array(item["matrix"])
    cameras = local_search(rng, source, target, P, norm, item["cost"] + increase, proof["reference"])
    null = np.linalg.svd(cameras)[2][:, -1]
    centres = null[:, :3] / null[:, 3:]
    scene = Scene(source, target, P, proof["reference"], norm)
    _, r = proven_centre(scene, increase, proof["centre"]["radius"], proof["centre"]["rounds"])
    stated = centre_l1._duals(proof["centre"], len(source))
    for _ in range(100):
        duals = copy.deepcopy(stated)
        i, j = int(rng.integers(centre_l1.ROWS)), int(rng.integers(2))
        mu = float(rng.choice([0.0, 5e-324, 1e-310, 1e-10, 1.0, 1e10, 1e30, 2.0 ** 128]))
        if duals[i][j] is not None and rng.random() < 0.5:
            mu = duals[i][j][0] * float(rng.choice([1e-3, 0.5, 1 + 1e-12, 2.0, 1e3]))
        y = rng.normal(size=(len(source), 2))
        y = y / np.sqrt((y * y).sum(axis=1))[:, None] * (1 - 4.5e-16) if norm == "L2L1" else np.sign(y)
        if duals[i][j] is not None and rng.random() < 0.5:
            y = duals[i][j][1]
        duals[i][j] = (mu, y)
        bounds = centre_l1.bounds_with(scene, increase, r, duals)
        assert bounds is None or (np.all(bounds[:, 0] <= centres.min(axis=0))
                                  and np.all(centres.max(axis=0) <= bounds[:, 1])), (i, j, mu)
