"""A reconstruction's camera judged uncertifiable (not searched, not certified: a free 3x4 camera
found locally beats it by more than its tolerance, structure._bound_on) states that free camera,
and the verifier recomputes both costs from the camera's certified points (issue 33, review 14's
"a stop hidden as a judgement"). Documents of an earlier hash form (written before the free
camera was stated) still verify, their report's scope naming each such judgement unchecked."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.core.certificates import problem_hash
from geocert.verify import hashed_options
from geocert.verify.checks import checked_options, verify_any
from tests.verify.test_forgeries import stored


def _in_form(result: dict, names: tuple[str, ...]) -> dict:
    """The result with its certificate's problem_sha256 computed over ``names`` (an earlier form)."""
    result = copy.deepcopy(result)
    document = result["certificate"]
    options = checked_options("reconstruction", document["options"])
    document["problem_sha256"] = problem_hash("reconstruction", document["data"], options, names)
    return result


def _without_free_cameras(result: dict) -> dict:
    """The result as a kind from before the free camera was stated writes it (no such member)."""
    result = copy.deepcopy(result)
    for camera in result["cameras"]:
        camera.pop("free_camera", None)
    return result


def _costs(result: dict, camera: dict, matrix) -> float:
    """The L2L2 cost of ``matrix`` on the camera's certified points (squared errors summed), and
    whether every one of them is in front of it."""
    M = np.asarray(matrix, dtype=float)
    total, front = 0.0, True
    for point in result["points"]:
        for seen, u, v in point["observations"] if point["certified"] else []:
            if seen == camera["view"]:
                x = M @ np.append(point["point"], 1.0)
                front = front and x[2] > 0
                total += float(np.sum((x[:2] / x[2] - (u, v)) ** 2))
    return total, front


@pytest.fixture(scope="module")
def judged() -> dict:
    """The stored reconstruction's scene and options (six views of 16 points with 0.5 px of noise,
    camera_rel_gap 0.25), solved now: two cameras a free 3x4 camera beats beyond their tolerance."""
    from geocert.jobs.runner import solve_job
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=6, points=16, seed=3, noise_px=0.5)
    data = {"views": [{"name": f"view{v}", "image_size": list(scene.image_size)} for v in range(6)],
            "tracks": [{"views": [int(v) for v in views], "points": [[float(u), float(w)] for u, w in pixels]}
                       for views, pixels in scene.tracks]}
    result = solve_job({"kind": "reconstruction", "data": data,
                        "options": {"certificate": "full", "camera_rel_gap": 0.25}})
    assert [c["view"] for c in _beaten(result)], "no camera judged by a free camera"
    return result


def _beaten(result: dict) -> list[dict]:
    return [c for c in result["cameras"] if c["registered"] and not c["searched"] and c["status"] == "not_certified"]


def test_a_camera_judged_uncertifiable_states_the_free_camera_that_beats_it(judged):
    """Recomputed here from the points: the free camera puts every certified point in front and
    beats the returned camera by more than its tolerance; no other camera states one."""
    report = verify_any(judged)
    assert report.valid, report.first_failure
    assert "camera_judgements" not in report.scope
    abs_gap = judged["certificate"]["options"]["abs_gap"]
    for camera in _beaten(judged):
        own, _ = _costs(judged, camera, camera["P"])
        free, front = _costs(judged, camera, camera["free_camera"])
        assert front and own > (1 + camera["tolerance"]) * free + abs_gap, camera["view"]
    assert all(c["free_camera"] is None for c in judged["cameras"] if c not in _beaten(judged))


@pytest.mark.parametrize("change", ["its own camera", "every depth negated", "removed", "null"])
def test_a_judgement_without_a_free_camera_that_beats_it_is_refused(judged, change):
    forged = copy.deepcopy(judged)
    camera = _beaten(forged)[0]
    if change == "its own camera":  # costs what the camera does: within its tolerance
        camera["free_camera"] = camera["P"]
    elif change == "every depth negated":
        camera["free_camera"] = (-np.asarray(camera["free_camera"])).tolist()
    elif change == "removed":
        del camera["free_camera"]
    else:
        camera["free_camera"] = None
    report = verify_any(forged)
    assert not report.valid and f"cameras/{camera['view']}" in report.first_failure["detail"], report.first_failure


def test_a_searched_camera_stating_a_free_camera_is_refused(judged):
    forged = copy.deepcopy(judged)
    searched = next(c for c in forged["cameras"] if c["searched"])
    searched["free_camera"] = _beaten(forged)[0]["free_camera"]
    report = verify_any(forged)
    assert not report.valid and "free_camera" in report.first_failure["detail"], report.first_failure


@pytest.mark.parametrize("form", ["second", "earliest"])
def test_an_earlier_form_without_free_cameras_verifies_naming_the_judgements_unchecked(judged, form):
    """As a kind before the free camera wrote it, hashed in an earlier form (every option left out
    at what was asked): valid, the scope naming each judgement the verifier could not recompute."""
    names = hashed_options.SECOND_CLAIM_OPTIONS if form == "second" else hashed_options.EARLIER_CLAIM_OPTIONS
    report = verify_any(_in_form(_without_free_cameras(judged), names))
    assert report.valid, report.first_failure
    views = ", ".join(str(c["view"]) for c in _beaten(judged))
    assert report.scope["camera_judgements"].startswith(f"unchecked for cameras {views}:")


def test_the_stored_reconstruction_verifies_naming_its_judgements_unchecked():
    """A third party's stored document (the earliest form, no free camera) still verifies."""
    report = verify_any(stored("reconstruction"))
    assert report.valid, report.first_failure
    assert report.scope["camera_judgements"].startswith("unchecked for cameras 1, 2:")


def test_cameras_a_cancel_left_unstarted_restated_as_judged_in_the_second_form_are_named_unchecked():
    """Review 14's forgery (cameras a cancel left unstarted restated as judged uncertifiable, the
    job "optimal") rehashed in the second form, whose documents state no free camera: it cannot be
    told from such a document, so it verifies, and the report's scope names those cameras' judgement
    unchecked, saying that they may be ones a stop left unstarted. In the current form it is
    refused (test_forgeries_review14)."""
    from tests.verify.test_forgeries_review14 import _cost, _run, _stage

    result = _run(lambda labels: any(label.startswith("cameras 2/") for label in labels))
    unstarted = [c["view"] for c in result["cameras"] if c["status"] == "cancelled" and not c["searched"]]
    judged_one = next(c for c in result["cameras"] if c["searched"])
    assert unstarted
    forged = _without_free_cameras(result)
    for view in unstarted:
        forged["cameras"][view].update(
            status="not_certified", cost=_cost(forged, view), degrees_of_freedom=judged_one["degrees_of_freedom"],
            tolerance=judged_one["tolerance"], set_aside=0, bound_reason="no bound can certify it")
    stage = _stage(forged, "cameras")
    stage.pop("cameras_not_started")
    stage.update(status="done", reason=None)
    forged["stats"]["statuses"] = {"optimal": 1}
    assert not verify_any(forged).valid
    report = verify_any(_in_form(forged, hashed_options.SECOND_CLAIM_OPTIONS))
    assert report.valid, report.first_failure
    scope = report.scope["camera_judgements"]
    assert scope.startswith(f"unchecked for cameras {', '.join(map(str, unstarted))}:") and "stop" in scope
