"""Review 43: a hostile review of autocalibration's determinacy estimates as the verifier now
walks them again (verify/autocalibration_estimates.py) and of extreme-scale inputs.

Found (each was an xfail(strict) test below, the forgery being accepted; all three are fixed at
their causes and their tests are plain):

1. A K stage's width from the plane's own family, and that family's critical-motion warning, are
   the document's word. The writer's K intervals are the metric walk's (the plane held fixed)
   widened in quadrature by the plane family's (determinacy.metric_stage), and its warning
   (_plane_warning) says when the plane at infinity is not fixed well enough to fix K. The
   verifier demands only that the stated intervals hold the fixed-plane metric walk
   (autocalibration_estimates.check_stratified, _check_holds) and a warning only where the DIAC's
   family is judged critical (_check_motion); "the plane family's own warning ... is not
   demanded". Five views of a general scene shot at 800 px with 3 px of noise
   (``_weak_plane_job``): the genuine result returns K with focal 590 px, every intrinsic's
   interval unbounded, a ``critical_motion`` warning on both stages (the modulus cost reaches
   "planes with no calibration at all"), determined false. Restated with the metric walk's
   intervals ([540, 635] px), the warnings dropped and ``determined`` true on both stages, it
   verifies (valid: true): "the data fix K to 10%, at 590 px", for a camera of 800 px.
   Where: verify/autocalibration_estimates.py, check_stratified (the metric stage checked
   against metric_walk alone, the plane family neither recomputed nor bounded below).
   Fixed: a K stage of today's form is held to its writer's intervals made again in full
   (determinacy.metric_intervals: the metric walk and the plane family in quadrature, the
   family's refits the writer's scipy least-squares), and each stage's plane family is judged
   again: where it moves K by more than 10% (clear of the margin) a critical-motion warning is
   demanded (autocalibration_estimates._check_K_stage, _check_plane_motion).

2. The "nearer of walk and curvature" rule, meant for documents written before the walk
   (their intervals state no tolerance), applies to current-form documents too. On the orbital
   motion of review 41 (``_orbital_job``) the metric walk leaves every intrinsic unbounded; the
   genuine result says so. Its metric intervals restated as the local curvature's, clipped to the
   scope (focal_x [278, 361] px, principal point bounded), the orbital warning kept, verify:
   bounded intervals for a K that a critical motion leaves free. The verifier knows the form
   (every interval states ``tolerance``; estimates.check_intrinsics reads ``earlier`` so).
   Where: verify/autocalibration_estimates.py, _nearer (used for every K stage, whatever form).
   Fixed: the nearer-end rule (_nearer) is read only in a document hashed without the
   estimates' form (the earlier form); today's are held to the writer's intervals.

3. A stage's whole estimate nulled (or restated as stopped at its clock: one ``time_limit``
   warning, no interval) hides a critical motion. On the orbital result, both stages'
   determinacy null, or both "stopped", verify (valid: true): the certified K of 320 px (scene
   shot at 800 px) then carries no ``orbital_motion`` warning at all. The writer writes null only
   where its analysis raised (core.determinacy.within -> safely) and stopped only past the job's
   deadline, and the verifier itself walks and judges the motion from the returned plane and K
   (it needs nothing of the stated estimate to find the motion critical). The motion judgement
   runs only for an analysed estimate.
   Where: verify/autocalibration_estimates.py, _analysed (None for null and for
   estimates.stopped), so _check_motion is skipped.
   Fixed: the writer judges the motion at the returned K first (determinacy.judged_motion) and
   states it even where the analysis stops at its clock or fails (with_motion: after the
   time_limit or not_analysed warning, which estimates.stopped reads as claiming no interval);
   the verifier judges the motion again whatever the estimate came to, and a null estimate or one
   without a critical-motion warning is refused where the motion is critical.

Seen, not filed as a class: any of CRITICAL_CODES is read as the critical-motion warning, so an
orbital motion's warning restated as ``pure_translation`` verifies (the code names the motion's
look; the decision is the same).

Seen, not yet classified (no time to tell a false claim from a scale-dependent cost): the stored
stratified job's cameras (largest entry 0.77) times 2^20, 2^24 and 2^28 lie inside
frames.unit_scaled's untouched band [2^-12, 2^28) and are posed as given; the metric stage's cost
rises from 2.2e-12 (2^0 to 2^16) to 1.2e-5 at 2^20 (K moves 0.3 px), the stage stops at its clock
at 2^24 (K 1009 px, skew 10), and at 2^28 it reports "optimal" with K at the intrinsics ranges'
corner (focal 5000 / 5250 px, skew 10, principal point (250, 750)) where the scene's K is 1000 px,
(500, 500); each document verifies. A camera is defined up to scale: the band is too wide for the
metric stage's cost (its rounding, or its relaxation's conditioning), so the certified K depends on
a scale that changes no ratio. Cameras times 2^-500 and 2^500 in one job, 2^-12 and 2^28 exactly:
K 1000 px, valid, as unit_scaled intends.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries_review41 import CRITICAL_CODES, _orbital_job

SCENE_K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])


def _accepted(document: dict) -> bool:
    return verify_any(json.loads(json.dumps(document))).valid


def _weak_plane_job() -> dict:
    """Five views from random directions on a sphere of radius 10 (all in front of the scene),
    looking near the origin with random roll, 30 points in [-2, 2]^3, 3 px of noise: a general
    motion (the DIAC's family is not critical) whose plane at infinity the modulus constraints
    leave loose."""
    from geocert.solvers.autocalibration import scenes

    rng = np.random.default_rng(7)
    cameras = []
    for _ in range(5):
        direction = rng.normal(size=3)
        direction[2] = -abs(direction[2]) - 1.0
        centre = 10 * direction / np.linalg.norm(direction)
        R = scenes.look_at(centre, rng.normal(size=3) * 0.3, rng, up=rng.normal(size=3))
        cameras.append(SCENE_K @ np.hstack([R, (-R @ centre)[:, None]]))
    scene = scenes.from_cameras(np.array(cameras), (np.full(3, -2.0), np.full(3, 2.0)), 3.0, seed=7, points=30)
    data = {"cameras": scene.cameras.tolist(), "points": scene.points.tolist(), "image_size": [640, 480]}
    return {"kind": "autocalibration", "data": data,
            "options": {"method": "stratified", "certificate": "full", "max_nodes": 1000}}


def _walked_again(document: dict) -> dict:
    """The verifier's own walks at the returned plane and K (the metric walk, and each end the
    nearer of walk and curvature as autocalibration_estimates._nearer reads it for earlier documents)."""
    from geocert.formulations.autocalibration import determinacy as writer, problem as autocalibration_problem
    from geocert.core.determinacy import certified_gap
    from geocert.verify import autocalibration as verifier
    from geocert.verify import autocalibration_estimates

    certificate = document["certificate"]
    cameras, points, image_size = verifier.read_data(certificate["data"])
    intrinsics = dict(certificate["options"].get("intrinsics") or {})
    problem = autocalibration_problem.prepare(cameras, points, image_size, intrinsics,
                                              verifier._stated_reference(certificate["items"], cameras, image_size,
                                                                         intrinsics))
    p = autocalibration_problem.plane_from_input(problem, np.asarray(document["plane_at_infinity"], dtype=float))
    w = autocalibration_problem.w_of_K(problem, np.asarray(document["K"], dtype=float))
    metric = document["stages"][1]
    walk = writer.metric_walk(problem, p, w, certified_gap(metric["cost"], metric["lower_bound"]))
    # the nearer-end rule, as read for a document of the earlier form (intervals without tolerances)
    return {"walk": walk["intervals"], "nearer": autocalibration_estimates._nearer(walk, problem)}


def _restated(document: dict, intervals: list[dict], drop_warnings: bool) -> dict:
    """The metric stage's intervals restated as ``intervals`` (ends only); with ``drop_warnings``
    both stages' warnings gone and ``determined`` what the intervals then give."""
    from geocert.core.determinacy import fixes

    forged = copy.deepcopy(document)
    for stated, own in zip(forged["stages"][1]["determinacy"]["intervals"], intervals):
        stated["lower"], stated["upper"] = own["lower"], own["upper"]
    if drop_warnings:
        for stage in forged["stages"]:
            stage["determinacy"]["warnings"] = []
            stage["determinacy"]["determined"] = all(fixes(i) for i in stage["determinacy"]["intervals"])
    return forged


@pytest.fixture(scope="module")
def weak_plane_result() -> dict:
    from geocert.jobs.runner import solve_job

    return solve_job(_weak_plane_job())


@pytest.fixture(scope="module")
def orbital_result() -> dict:
    from geocert.jobs.runner import solve_job

    return solve_job(_orbital_job())


# Class 1: the plane family's share of K's width, and its warning, unchecked

@pytest.mark.slow
def test_the_weak_planes_genuine_result_verifies_and_leaves_K_undetermined(weak_plane_result):
    """The premise of class 1: the writer says K is not fixed (a critical-motion warning on the
    metric stage, K's focal interval unbounded or wider than its tolerance), and that verifies."""
    metric = weak_plane_result["stages"][1]["determinacy"]
    assert weak_plane_result["stages"][1]["certified"] is True
    assert metric["determined"] is False
    assert metric["warnings"]
    assert _accepted(weak_plane_result)


@pytest.mark.slow
def test_a_weak_planes_K_restated_determined_is_refused(weak_plane_result):
    """K's intervals restated as the metric walk's alone (without the plane family's share), the
    warnings dropped and ``determined`` restated: refused. Today's form reads the walk at the
    Student quantile of the metric stage's 15 degrees of freedom (3.63 standard errors, not 3), and
    there the walk's focal interval is just beyond a tenth of the focal length: the forger takes
    0.8 of the walk's, which reads every interval as fixed."""
    walk = [dict(i, lower=i["value"] - 0.8 * (i["value"] - i["lower"]),
                 upper=i["value"] + 0.8 * (i["upper"] - i["value"])) for i in _walked_again(weak_plane_result)["walk"]]
    forged = _restated(weak_plane_result, walk, drop_warnings=True)
    assert [stage["determinacy"]["determined"] for stage in forged["stages"]] == [True, True]
    assert not _accepted(forged)


# Class 2: the nearer-of-walk-and-curvature rule read on current-form documents

@pytest.mark.slow
def test_an_orbital_Ks_unbounded_intervals_restated_bounded_are_refused(orbital_result):
    again = _walked_again(orbital_result)
    assert all(own["lower"] is None and own["upper"] is None for own in again["walk"])
    assert all("tolerance" in i for i in orbital_result["stages"][1]["determinacy"]["intervals"])
    forged = _restated(orbital_result, again["nearer"], drop_warnings=False)
    assert all(i["lower"] is not None and i["upper"] is not None
               for i in forged["stages"][1]["determinacy"]["intervals"])
    assert not _accepted(forged)


# Class 3: a critical motion hidden by an estimate nulled or stated stopped

STOPPED = {"intervals": [], "determined": False, "proven": False, "proven_intervals": None,
           "warnings": [{"code": "time_limit", "detail": "the stage's determinacy was not analysed: the job's deadline"}]}


@pytest.mark.slow
def test_an_orbital_motions_estimates_nulled_or_stopped_are_refused(orbital_result):
    """Both restatements refused: null (the writer's when its analysis raised) and stopped (its
    clock's), each hiding the orbital warning the verifier finds again at the returned K."""
    for restated in (None, STOPPED):
        forged = copy.deepcopy(orbital_result)
        for stage in forged["stages"]:
            stage["determinacy"] = None if restated is None else dict(stage["determinacy"], **copy.deepcopy(restated))
        assert not _accepted(forged)


@pytest.mark.slow
@pytest.mark.parametrize("stops_with", ["clock", "linear_algebra"])
def test_a_stage_stopped_or_failed_states_the_critical_motion_and_verifies(monkeypatch, stops_with):
    """The writer's side of class 3: the metric stage's analysis stopped at its clock (OutOfTime,
    as core.determinacy.within stops it) or defeated by the data (a LinAlgError: safely) still
    states the orbital motion judged at the returned K, and the document verifies; the same
    document with that warning dropped is refused."""
    from geocert.core.determinacy import OutOfTime
    from geocert.jobs.runner import solve_job
    from geocert.formulations.autocalibration import determinacy

    def stopped(*args, **kwargs):
        raise OutOfTime if stops_with == "clock" else np.linalg.LinAlgError("singular")

    monkeypatch.setattr(determinacy, "metric_stage", stopped)
    result = solve_job(_orbital_job())
    metric = result["stages"][1]["determinacy"]
    assert metric["intervals"] == [] and metric["determined"] is False
    codes = [w["code"] for w in metric["warnings"]]
    assert codes[0] == ("time_limit" if stops_with == "clock" else "not_analysed")
    assert any(code in CRITICAL_CODES for code in codes[1:])
    assert _accepted(result)
    forged = copy.deepcopy(result)
    forged["stages"][1]["determinacy"]["warnings"] = metric["warnings"][:1]
    assert not _accepted(forged)
