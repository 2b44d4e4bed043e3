"""summary.calibration.K where each returned camera has its own K (the claim's model "varying") is
the one camera's K the writer picks among the cameras it returns, and the verifier holds it to
that pick (issue 33):

- a focal length per view with shared intrinsics (camera_model "varying"): the middle focal
  length's camera (sorted, index len // 2);
- a principal point per view (principal_point "per_view"): among the views sharing the focal
  length most of them have, the one whose principal point lies nearest the median of theirs.

The sanity layer (pipeline._check_cameras) may drop a camera after the adjustment picked its K;
the pick is then made again among the cameras returned, so a genuine result whose picked (or an
end) camera was dropped verifies. A camera is dropped here by the sanity layer's own rule with
its level raised (MIN_CAMERA_POINTS: the dropped view sees fewer points than that, the others
more; the verifier does not read the level)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import scenes
from geocert.solvers.reconstruction import synthetic
from geocert.formulations.reconstruction import calibration_claim
from geocert.verify.checks import verify_any

FOCALS = [700.0, 760.0, 820.0, 880.0, 940.0, 1000.0]  # view k's focal length (camera_model "varying")
MIDDLE = 3  # the view of the middle focal length (sorted, index len // 2)
SEEN = 30  # the points a view to be dropped sees (of 80; of 200 in the per-view scene)


def _registered(result: dict) -> list[dict]:
    return [c for c in result["cameras"] if c["registered"]]


def _run(job: dict, drop: int | None) -> dict:
    from geocert.pipelines.reconstruction import pipeline

    with pytest.MonkeyPatch.context() as patch:
        if drop is not None:
            patch.setattr(pipeline, "MIN_CAMERA_POINTS", SEEN + 20)
        result = json.loads(json.dumps(solve_job(job)))
    if drop is not None:
        assert [c["view"] for c in result["cameras"] if not c["registered"]] == [drop]
        assert next(c for c in result["cameras"] if c["view"] == drop)["reason"].startswith("dropped")
    return result


def _tracks(images: list, drop: int | None) -> list[dict]:
    """The tracks of every point in every view, view ``drop`` seeing only the first SEEN points."""
    tracks = []
    for k, pixels in enumerate(images):
        views = [v for v in range(len(pixels)) if v != drop or k < SEEN]
        tracks.append({"views": views, "points": [pixels[v] for v in views]})
    return tracks


def _varying(drop: int | None = None) -> dict:
    """Six views round a cloud, each with its own focal length (FOCALS), 0.3 px noise."""
    rng = np.random.default_rng(7)
    X = rng.uniform(-1, 1, size=(80, 3))
    cameras = []
    for i, f in enumerate(FOCALS):
        angle = 2 * np.pi * i / 6
        centre = np.array([5 * np.cos(angle), 1.5 * np.sin(3 * angle), 5 * np.sin(angle)])
        R = scenes.look_at(centre, np.zeros(3), rng, up=np.array([0.0, 1.0, 0.0]))
        K = np.array([[f, 0, 320.0], [0, f, 240.0], [0, 0, 1]])
        cameras.append(K @ np.hstack([R, (-R @ centre)[:, None]]))
    images = [[((P @ np.append(x, 1.0))[:2] / (P @ np.append(x, 1.0))[2] + rng.normal(0, 0.3, 2)).tolist()
               for P in cameras] for x in X]
    views = [{"name": f"view{i}", "image_size": [640, 480]} for i in range(6)]
    return _run({"kind": "reconstruction", "data": {"views": views, "tracks": _tracks(images, drop)},
                 "options": {"certificate": "full", "camera_model": "varying"}}, drop)


PER_VIEW = 8


LONGER = 3  # the view seen with a longer focal length (_per_view's ``longer``)


def _per_view(drop: int | None = None, longer: bool = False) -> dict:
    """Eight general views, 0.3 px noise, each view's principal point moved by its own offset (up
    to 15 px each way: the per-view principal points are kept), principal_point "per_view";
    ``longer``: view LONGER seen with a focal length 1.15 times the others' (its pixels scaled
    about its principal point: it is given a focal length of its own)."""
    scene = synthetic.scene(views=PER_VIEW, points=200, seed=6, noise_px=0.3, spread_degrees=50.0)
    shift = np.random.default_rng(1).uniform(-15, 15, (PER_VIEW, 2))
    factor = np.where(np.arange(PER_VIEW) == LONGER, 1.15 if longer else 1.0, 1.0)
    centre = scene.K[:2, 2]
    images = [[None] * PER_VIEW for _ in scene.tracks]
    for k, (views, pixels) in enumerate(scene.tracks):
        views = np.asarray(views)
        for v, p in zip(views, centre + (pixels - centre) * factor[views, None] + shift[views]):
            images[k][int(v)] = p.tolist()
    tracks = []
    for k, row in enumerate(images):
        views = [v for v, p in enumerate(row) if p is not None and (v != drop or k < SEEN)]
        if len(views) >= 2:
            tracks.append({"views": views, "points": [row[v] for v in views]})
    return _run({"kind": "reconstruction", "data": {"views": [{"image_size": list(scene.image_size)}] * PER_VIEW,
                                                    "tracks": tracks},
                 "options": {"certificate": "full", "principal_point": "per_view"}}, drop)


def _middle_focal_K(result: dict) -> list:
    cameras = sorted(_registered(result), key=lambda c: c["K"][0][0])
    return cameras[len(cameras) // 2]["K"]


def _middle_centre_K(result: dict) -> list:
    """The K of the camera whose principal point lies nearest the median of the returned ones'
    (one focal length shared: the scene has no view of a focal length of its own)."""
    cameras = _registered(result)
    assert len({c["K"][0][0] for c in cameras}) == 1
    centres = np.array([[c["K"][0][2], c["K"][1][2]] for c in cameras])
    return cameras[int(np.argmin(np.linalg.norm(centres - np.median(centres, axis=0), axis=1)))]["K"]


def _restated(result: dict, K: list) -> dict:
    """``result`` with ``K`` stated as summary.calibration.K, and the records read against it (the
    adjustment stage's K, the depth-reversal record's focal length, the difference from the
    certified K and the warning that states it) restated to match."""
    forged = copy.deepcopy(result)
    claim = forged["summary"]["calibration"]
    if claim.get("certified_K") is not None:
        was = calibration_claim.moved_figures(claim["difference"])
        claim["difference"] = calibration_claim.difference(np.array(K), np.array(claim["certified_K"]))
        for warning in forged["summary"].get("warnings") or []:
            warning["detail"] = warning["detail"].replace(was, calibration_claim.moved_figures(claim["difference"]))
    claim["K"] = K
    for stage in forged["stages"]:
        if stage["name"] == "bundle_adjustment" and "K" in stage:
            stage["K"] = K
    depth = forged["summary"].get("depth_reversal")
    if isinstance(depth, dict) and depth.get("checked"):
        depth["mirror_focal_px" if depth.get("adopted") else "focal_px"] = K[0][0]
    return forged


@pytest.fixture(scope="module")
def per_view() -> dict:
    return _per_view()


# A focal length per view: the picked camera, or an end camera (which moves the middle), dropped
# after the adjustment picked its K

@pytest.mark.parametrize("drop", [MIDDLE, len(FOCALS) - 1])
def test_a_genuine_varying_result_whose_camera_was_dropped_after_the_pick_verifies(drop):
    result = _varying(drop)
    claim = result["summary"]["calibration"]
    assert claim["model"] == "varying" and len(_registered(result)) == len(FOCALS) - 1
    assert claim["K"] == _middle_focal_K(result)
    report = verify_any(result)
    assert report.valid, report.first_failure


# A principal point per view: the writer's pick is held

def test_the_genuine_per_view_result_states_the_middle_principal_points_K_and_verifies(per_view):
    claim = per_view["summary"]["calibration"]
    adjustment = next(s for s in per_view["stages"] if s["name"] == "bundle_adjustment")
    assert adjustment["principal_point_per_view"]["estimated"] is True and claim["model"] == "varying"
    assert claim["K"] == _middle_centre_K(per_view)
    report = verify_any(per_view)
    assert report.valid, report.first_failure


def test_another_cameras_K_restated_as_the_per_view_calibration_K_is_refused(per_view):
    picked = _middle_centre_K(per_view)
    others = [c["K"] for c in _registered(per_view) if c["K"] != picked]
    assert len(others) == PER_VIEW - 1
    report = verify_any(_restated(per_view, picked))  # restating the pick itself changes nothing
    assert report.valid, report.first_failure
    for K in others:
        report = verify_any(_restated(per_view, K))
        assert not report.valid and report.first_failure["check"] == "returned", report.first_failure


def test_a_genuine_per_view_result_whose_picked_camera_was_dropped_verifies(per_view):
    picked = next(c["view"] for c in _registered(per_view) if c["K"] == _middle_centre_K(per_view))
    result = _per_view(picked)
    assert result["summary"]["calibration"]["K"] == _middle_centre_K(result)
    report = verify_any(result)
    assert report.valid, report.first_failure


# A focal length of its own for one view besides a principal point each: the pick is among the
# views sharing the others' focal length

@pytest.fixture(scope="module")
def focal_groups() -> dict:
    return _per_view(longer=True)


def _group_pick(result: dict) -> list:
    """The K of the camera whose principal point lies nearest the median of those of the cameras
    sharing the most common focal length."""
    cameras = _registered(result)
    focals = [c["K"][0][0] for c in cameras]
    shared = [c for c in cameras if c["K"][0][0] == max(focals, key=focals.count)]
    centres = np.array([[c["K"][0][2], c["K"][1][2]] for c in shared])
    return shared[int(np.argmin(np.linalg.norm(centres - np.median(centres, axis=0), axis=1)))]["K"]


def test_another_cameras_K_restated_beside_focal_groups_is_refused(focal_groups):
    adjustment = next(s for s in focal_groups["stages"] if s["name"] == "bundle_adjustment")
    assert adjustment["focal_per_view"]["estimated"] is True and adjustment["focal_per_view"]["views"] == [LONGER]
    picked = _group_pick(focal_groups)
    assert focal_groups["summary"]["calibration"]["K"] == picked
    report = verify_any(focal_groups)
    assert report.valid, report.first_failure
    longer = next(c["K"] for c in _registered(focal_groups) if c["view"] == LONGER)
    other = next(c["K"] for c in _registered(focal_groups) if c["view"] != LONGER and c["K"] != picked)
    for K in (longer, other):  # the view of its own focal length, and another of the shared one
        report = verify_any(_restated(focal_groups, K))
        assert not report.valid and report.first_failure["check"] == "returned", report.first_failure
