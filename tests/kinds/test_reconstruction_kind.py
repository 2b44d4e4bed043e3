"""The reconstruction kind in-process: bad input is refused naming the item, the result fits its
model with every stage's figures, its full certificate verifies (points) beside a resection
certificate (cameras), a cancelled run keeps its stages, and the exports parse."""

from __future__ import annotations

import copy
import io
import json
import math
import struct
import zipfile

import numpy as np
import pytest

from geocert.jobs.runner import parse_job, solve_job
from geocert.kinds import get_kind
from geocert.core.geometry import InputError
from geocert.solvers.reconstruction import export
from geocert.verify.checks import verify_any, verify_document

KIND = get_kind("reconstruction")


def job(**changes) -> dict:
    body = copy.deepcopy(KIND.example)
    body["data"].update(changes.pop("data", {}))
    body["options"].update(changes)
    return body


@pytest.fixture(scope="module")
def solved():
    return solve_job(job(certificate="full"))


class TestBadInput:
    @pytest.mark.parametrize("data, field", [
        ({"tracks": [{"views": [0, 7], "points": [[1.0, 2.0], [3.0, 4.0]]}]}, "data/tracks/0/views/1"),
        ({"tracks": [{"views": [0, 1], "points": [[1.0, 2.0], [float("nan"), 4.0]]}]}, "data/tracks/0/points/1/0"),
        ({"tracks": [{"views": [0, 1], "points": [[1.0, 2.0]]}]}, "data/tracks/0"),
        ({"tracks": [{"views": [0, 0], "points": [[1.0, 2.0], [3.0, 4.0]]}]}, "data/tracks/0/views"),
        ({"views": [{"image_size": [640, -1]}] * 6}, "data/views/0/image_size"),
        ({"views": [{"image_size": [1e8, 480]}] * 6}, "data/views/0/image_size"),  # was queued: over 1e6 a side
        ({"cameras": []}, "data/cameras"),
    ])
    def test_names_the_item(self, data, field):
        with pytest.raises(InputError) as error:
            parse_job(job(data=data))
        assert error.value.field == field, error.value

    @pytest.mark.parametrize("track, field", [
        ({"views": [0, 7], "points": [[1.0, 2.0], [3.0, 4.0]]}, "data/tracks/1500/views/1"),
        ({"views": [0, 1], "points": [[1.0, 2.0], [2e9, 4.0]]}, "data/tracks/1500/points/1/0"),
        ({"views": [0, 1], "points": [[1.0, 2.0], [True, 4.0]]}, "data/tracks/1500/points/1/0"),
        ({"views": [0, 1], "points": [[1.0, 2.0]]}, "data/tracks/1500"),
        ({"views": [0, 1], "points": [[1.0, 2.0], [3.0, 4.0, 5.0]]}, "data/tracks/1500/points"),
        ({"views": [0, 0], "points": [[1.0, 2.0], [3.0, 4.0]]}, "data/tracks/1500/views"),
        ({"views": [0, 1.0], "points": [[1.0, 2.0], [3.0, 4.0]]}, "data/tracks/1500/views"),
        ({"views": [0, 1]}, "data/tracks/1500"),
    ])
    def test_a_defect_deep_in_many_tracks_is_named(self, track, field):
        """Many tracks are checked in bulk; a defect anywhere still gets its own field."""
        tracks = [{"views": [0, 1, 2], "points": [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]}] * 2000
        with pytest.raises(InputError) as error:
            parse_job(job(data={"tracks": tracks[:1500] + [track] + tracks[1501:]}))
        assert error.value.field == field, error.value

    def test_many_tracks_are_read_in_bulk(self, monkeypatch):
        """A large body's tracks are read by a few flat passes, not track by track (track by
        track, each observation cost some microseconds of the API's Python): the per-entry
        reader runs for the views only, and the tracks come back as they were."""
        from geocert.kinds import reconstruction

        calls = []
        original = reconstruction.number_array
        monkeypatch.setattr(reconstruction, "number_array", lambda *a, **k: calls.append(a[1]) or original(*a, **k))
        rng = np.random.default_rng(1)
        tracks = [{"views": [int(v) for v in rng.choice(6, size=3, replace=False)],
                   "points": rng.uniform(0, 600, (3, 2)).tolist()} for _ in range(2000)]
        parsed = parse_job(job(data={"tracks": tracks}))[1]
        assert all(field.startswith("data/views/") for field in calls), calls[:3]
        for (views, points), track in zip(parsed.tracks, tracks, strict=True):
            assert views.tolist() == track["views"] and points.tolist() == track["points"]

    def test_the_api_models_options_are_taken(self):
        """The API validates a job with its model and passes model_dump's options on: ranges not
        given are null there (a regression: they reached the upgrade as None)."""
        from geocert.jobs.runner import solve_job

        body = KIND.request_model.model_validate(job(resect_cameras=False)).model_dump(mode="json")
        assert body["options"]["intrinsics"]["focal"] is None
        assert solve_job(body)["summary"]["views_registered"] == 6

    def test_fewer_than_two_views_with_matches(self):
        tracks = [{"views": [0, 0 + 1], "points": [[1.0, 2.0], [3.0, 4.0]]}]
        parse_job(job(data={"tracks": tracks}))  # two views: accepted
        with pytest.raises(InputError) as error:
            parse_job(job(data={"tracks": [{"views": [2], "points": [[1.0, 2.0]]}]}))
        assert error.value.field.startswith("data/tracks/0")

    def test_images_of_different_sizes_as_one_camera(self):
        views = [{"image_size": [640, 480]}] * 5 + [{"image_size": [800, 600]}]
        with pytest.raises(InputError) as error:
            parse_job(job(data={"views": views}))
        assert error.value.field == "data/views/5/image_size"
        parse_job(job(data={"views": views}, camera_model="varying"))  # one focal length per view: allowed

    @pytest.mark.parametrize("options, field", [
        ({"intrinsics": {"K": [[800, 0, 320], [0, 800, 240]]}}, "options/intrinsics/K"),
        ({"intrinsics": {"focal": [10, 5]}}, "options/intrinsics/focal"),
        ({"intrinsics": {"focal": [1e200, 1e201]}}, "options/intrinsics/focal"),  # was a job failed: LinAlgError
        ({"autocalibration": "sometimes"}, "options/autocalibration"),
        ({"threshold_px": 0}, "options/threshold_px"),
        ({"features": {"guided_ratio": 1.0}}, "options/features/guided_ratio"),
        ({"features": {"max_features": 1.5}}, "options/features/max_features"),
        ({"features": {"edge": 3}}, "options/features/edge"),
    ])
    def test_bad_options(self, options, field):
        with pytest.raises(InputError) as error:
            parse_job(job(**options))
        assert error.value.field == field

    @pytest.mark.parametrize("intrinsics, field", [
        ({"focal": [800, 5e7]}, "options/intrinsics/focal"),
        ({"skew": [0, 2e7]}, "options/intrinsics/skew"),
        ({"principal_point": [[-3e8, 640], [0, 480]]}, "options/intrinsics/principal_point/0"),
        ({"principal_point": [[0, 640], [0, 1.5e7]]}, "options/intrinsics/principal_point/1"),
        ({"K": [[5e7, 0, 320], [0, 5e7, 240], [0, 0, 1]]}, "options/intrinsics/K/0/0"),
        ({"K": [[800, 2e7, 320], [0, 800, 240], [0, 0, 1]]}, "options/intrinsics/K/0/1"),
        ({"K": [[800, 0, -4e8], [0, 800, 240], [0, 0, 1]]}, "options/intrinsics/K/0/2"),
        ({"K": [[800, 0, 320], [0, 3e7, 240], [0, 0, 1]]}, "options/intrinsics/K/1/1"),
        ({"K": [[800, 0, 320], [0, 800, 1e12], [0, 0, 1]]}, "options/intrinsics/K/1/2"),  # no limit at all before
    ])
    def test_intrinsics_in_pixels_beyond_ten_image_sides(self, intrinsics, field):
        """A focal length, skew or principal point over 1e7 px (ten times the largest image side
        taken) was queued: now the 422 naming the range or the K entry, and the limit."""
        with pytest.raises(InputError) as error:
            parse_job(job(intrinsics=intrinsics))
        assert error.value.field == field and "exceeds the limit of 1e+07 px" in error.value.reason, error.value

    @pytest.mark.parametrize("intrinsics, field", [
        ({"aspect": [0.5, 1e9]}, "options/intrinsics/aspect"),
        ({"aspect": [1e-5, 1.0]}, "options/intrinsics/aspect"),
        ({"K": [[1, 0, 320], [0, 1e6, 240], [0, 0, 1]]}, "options/intrinsics/K/1/1"),
        ({"K": [[1e6, 0, 320], [0, 10, 240], [0, 0, 1]]}, "options/intrinsics/K/1/1"),
    ])
    def test_an_aspect_ratio_no_camera_has(self, intrinsics, field):
        """A pixel aspect ratio fy / fx beyond a thousand to one either way (a range's end, or a
        known K's fy over fx) was queued: now the 422 naming the range or fy, and the bounds."""
        with pytest.raises(InputError) as error:
            parse_job(job(intrinsics=intrinsics))
        assert error.value.field == field and "outside [0.001, 1000]" in error.value.reason, error.value

    @pytest.mark.parametrize("prior", [2e7, 1e9])
    def test_a_focal_prior_beyond_the_focal_ranges_limit(self, prior):
        """focal_prior_px is held to the focal ranges' limit (1e7 px): over it, the 422 naming it."""
        with pytest.raises(InputError) as error:
            parse_job(job(focal_prior_px=prior))
        assert error.value.field == "options/focal_prior_px" and "1e+07" in error.value.reason, error.value

    def test_a_focal_prior_as_long_as_a_focal_range_may_reach_is_taken(self):
        """A range may state focal lengths to 1e7 px, and a prior was refused above 1e6."""
        from geocert.formulations.reconstruction import run_control
        from geocert.kinds.autocalibration import MAX_INTRINSIC_PX

        assert run_control.FOCAL_PRIOR_LIMIT == MAX_INTRINSIC_PX
        parse_job(job(focal_prior_px=5e6))
        parse_job(job(focal_prior_px=1e7, intrinsics={"focal": [1e6, 1e7]}))

    def test_intrinsics_of_ten_million_pixels_are_taken(self):
        parse_job(job(intrinsics={"K": [[1e7, -1e7, 1e7], [0, 1e7, -1e7], [0, 0, 1]]}))
        parse_job(job(intrinsics={"K": [[1e4, 0, 320], [0, 1e7, 240], [0, 0, 1]]}))  # an aspect of 1e3
        parse_job(job(intrinsics={"focal": [1e6, 1e7], "aspect": [0.9, 1.1], "skew": [-1e7, 1e7],
                                  "principal_point": [[-1e7, 1e7], [-1e7, 1e7]]}))


class TestResult:
    def test_fits_the_model_and_recovers_the_scene(self, solved):
        KIND.result_model.model_validate(solved)
        summary = solved["summary"]
        assert summary["views_registered"] == 6 and summary["points"] == 24
        assert summary["points_certified_fraction"] == 1.0 and summary["autocalibration_certified"]
        assert summary["rms_reprojection_px"] < 1e-5  # pixels rounded to 1e-6
        assert [stage["name"] for stage in solved["stages"]] == ["projective", "autocalibration",
                                                                 "bundle_adjustment", "structure", "cameras"]
        assert all(stage["status"] == "done" for stage in solved["stages"])
        assert abs(solved["cameras"][0]["K"][0][0] / 800 - 1) < 1e-6
        for point in solved["points"]:
            assert point["observations"] and all(len(o) == 3 for o in point["observations"])

    def test_observations_name_their_view_by_an_integer(self, solved):
        """As the API writes the result (batch.result_json: the result model's JSON): [view, u, v]
        with view an integer (the model typed it float: [[0.0, 554.369, 163.897], ...])."""
        from geocert.jobs.runner import result_json

        written = json.loads(result_json(KIND, solved))
        for point in written["points"]:
            assert all(type(view) is int and type(u) is float for view, u, _ in point["observations"])
        schema = KIND.result_model.model_json_schema()
        items = schema["$defs"]["ReconstructionPoint"]["properties"]["observations"]["items"]
        assert [item["type"] for item in items["prefixItems"]] == ["integer", "number", "number"]

    def test_points_certificate_verifies_and_is_about_the_returned_cameras(self, solved):
        report = verify_any(solved)
        assert report.valid, report.first_failure
        data = solved["certificate"]["data"]
        registered = [c for c in solved["cameras"] if c["registered"]]
        assert data["cameras"] == [c["P"] for c in registered]
        moved = json.loads(json.dumps(solved))  # as a client reads it (the claims are separate copies)
        moved["points"][3]["point"][0] += 1e-3
        assert verify_any(moved).first_failure["check"] == "returned"
        other = copy.deepcopy(solved)
        other["certificate"]["data"]["cameras"][0][0][0] *= 1.001  # a camera the points were not solved in
        assert not verify_any(other).valid

    def test_camera_bounds_come_with_a_resection_certificate(self, solved):
        document = solved["camera_certificate"]
        assert document["kind"] == "resection" and len(document["items"]) == 6
        assert verify_document(document).valid
        for camera, claim in zip(solved["cameras"], document["items"]):
            assert camera["certified"] and camera["cost"] >= claim["lower_bound"] * (1 - 1e-9)
            assert camera["lower_bound"] <= camera["cost"]

    def test_the_returned_cameras_are_checked_against_the_camera_certificate(self, solved):
        camera = next(k for k, c in enumerate(solved["cameras"]) if c["certified"])
        for change, check in [
            (lambda r: r["cameras"][camera]["P"][0].__setitem__(3, r["cameras"][camera]["P"][0][3] + 1e-3), "returned"),
            (lambda r: r["cameras"][camera].__setitem__("lower_bound", r["cameras"][camera]["lower_bound"] * 1.5 + 1),
             "returned"),
            (lambda r: r["cameras"][camera].__setitem__("cost", r["cameras"][camera]["cost"] + 1.0), "returned"),
            (lambda r: r["camera_certificate"]["items"][camera].__setitem__("lower_bound", 1e9), "returned"),
            (lambda r: r.pop("camera_certificate"), "returned"),
        ]:
            forged = json.loads(json.dumps(solved))
            change(forged)
            report = verify_any(forged)
            assert not report.valid and report.first_failure["check"] == check, report.first_failure

    def test_progress_carries_no_placeholder_bounds(self):
        """A reconstruction's stages report counts, not bounds: its progress events carry null
        bounds (they carried 0, which the page drew), except a running search's own (the
        autocalibration's branch and bound)."""
        events = []
        solve_job(job(), sink=events.append)
        stages = {event.get("stage", "").split(" ")[0] for event in events}
        assert {"projective", "bundle_adjustment", "structure", "cameras"} <= stages
        for event in events:
            if event.get("stage", "").startswith("autocalibration"):
                assert event["lower_bound"] is None or event["lower_bound"] <= event["upper_bound"]
                continue
            assert (event["lower_bound"], event["upper_bound"], event["gap_abs"], event["gap_rel"]) == (
                None, None, None, None), event

    def test_a_cancelled_run_keeps_the_stages_before(self):
        from geocert.jobs.runner import solve_items

        parsed = KIND.parse(KIND.example["data"])
        options = parse_job(KIND.example)[2]
        labels = []

        def stop():  # part way through: once the first stage is done
            return any(not label.startswith("projective") for label in labels)

        items = solve_items(KIND, parsed, options, range(1), sink=lambda p: labels.append(p.get("stage", "")),
                            should_stop=stop)
        statuses = [stage["status"] for stage in items[0]["stages"]]
        assert "cancelled" in statuses and statuses[0] == "done", statuses


def test_the_calibration_certificate_runs_no_analysis_it_does_not_carry(monkeypatch):
    """The calibration certificate's stratified item is built for its proofs; the stages'
    determinacy analyses, which the certificate does not carry, are not run (they ran outside any
    clock, for nothing), and the result still verifies."""
    from geocert.formulations.autocalibration import determinacy

    begun = []
    for name in ("affine_stage", "metric_stage"):
        monkeypatch.setattr(determinacy, name, lambda *args, name=name, **kwargs: begun.append(name))
    result = solve_job(job(certificate="full"))
    assert result["calibration_certificate"]["items"] and begun == []
    assert "determinacy" not in json.dumps(result["calibration_certificate"])
    assert verify_any(result).valid


def forgeries_refused(result: dict) -> None:
    """A result whose cameras are not all searched (some claim no bound): honest, it verifies;
    every way of claiming a bound without its map, or dropping a searched camera's map, is refused."""
    from geocert.verify.checks import verify_any

    honest = json.loads(json.dumps(result))
    report = verify_any(honest)
    assert report.valid, report.first_failure
    cameras = honest["cameras"]
    skipped = next(k for k, c in enumerate(cameras) if not c["searched"])
    searched = [k for k, c in enumerate(cameras) if c["searched"]]
    certified = next(k for k in searched if cameras[k]["certified"])
    assert len(honest["camera_certificate"]["items"]) == len(searched) < len(cameras)

    def claims_certified(r):
        r["cameras"][skipped].update(certified=True, lower_bound=r["cameras"][skipped]["cost"], gap=0.0,
                                     bound_reason=None)

    def claims_a_bound(r):
        r["cameras"][skipped]["lower_bound"] = r["cameras"][skipped]["cost"]

    def claims_searched(r):
        r["cameras"][skipped]["searched"] = True

    def swaps_searched(r):  # the certified camera's map said to be the skipped one's
        r["cameras"][skipped]["searched"], r["cameras"][certified]["searched"] = True, False

    def drops_a_map(r):
        k = searched.index(certified)
        r["camera_certificate"]["items"].pop(k)
        r["camera_certificate"]["data"]["maps"].pop(k)

    def forgets_searched(r):  # read as before: one map per registered camera
        for camera in r["cameras"]:
            camera.pop("searched")

    for change in (claims_certified, claims_a_bound, claims_searched, swaps_searched, drops_a_map, forgets_searched):
        forged = json.loads(json.dumps(honest))
        change(forged)
        report = verify_any(forged)
        assert not report.valid and report.first_failure["check"] == "returned", (change.__name__,
                                                                                 report.first_failure)


class TestCamerasNotSearched:
    """certificate "full" with cameras the search skipped (structure.resect_cameras: no bound could
    certify them): the camera certificate holds the searched cameras' maps, the verifier accepts
    the honest result and refuses a claim without its map (it asked for one map per registered
    camera, so the House's own result failed its verifier)."""

    def test_synthetic_scene_with_two_cameras_skipped(self):
        """Six views of 16 points with 0.5 px of noise at camera_rel_gap 0.25 (the stored
        reconstruction's scene): a free 3x4 camera beats some cameras by more than their tolerance,
        so they are not searched, and each states that camera (the verifier recomputes the
        judgement from it: a camera merely called skipped, as this test once made one, is refused)."""
        from geocert.solvers.reconstruction import synthetic

        scene = synthetic.scene(views=6, points=16, seed=3, noise_px=0.5)
        result = solve_job({"kind": "reconstruction", "options": {"certificate": "full", "camera_rel_gap": 0.25},
                            "data": {"views": [{"image_size": list(scene.image_size)}] * 6, "tracks": [
                                {"views": [int(v) for v in views], "points": [[float(u), float(w)] for u, w in pixels]}
                                for views, pixels in scene.tracks]}})
        skipped = [c for c in result["cameras"] if not c["searched"]]
        assert skipped and any(c["certified"] for c in result["cameras"])
        # Why a camera has no bound is said beside its bound; reason stays the registration's.
        for camera in skipped:
            assert "free 3x4 camera" in camera["bound_reason"] and camera["free_camera"] is not None
        assert all(c["reason"] is None and c["registered"] for c in result["cameras"])
        forgeries_refused(result)

    def test_model_house_from_tracks(self):
        from tests.solvers.reconstruction.test_reconstruction import house_tracks

        _, _, tracks = house_tracks()
        result = solve_job({"kind": "reconstruction", "options": {"certificate": "full"}, "data": {
            "views": [{"image_size": [768, 576]}] * 10,
            "tracks": [{"views": [int(v) for v in views], "points": pixels.tolist()} for views, pixels in tracks]}})
        # Every camera certified against its tolerance (camera_claim; 1 to 9 of 10 when held to
        # camera_rel_gap alone, as a 3x4 camera is).
        assert result["summary"]["views_registered"] == 10 and result["summary"]["cameras_certified"] == 10
        projective = result["stages"][0]  # every observation counted once (27 outliers but 52 not kept)
        assert projective["observations"] - projective["observations_kept"] == projective["outliers_removed"] + \
            projective["observations_of_dropped_tracks"] + projective["observations_of_unregistered_views"]
        for camera in result["cameras"]:  # every camera not certified says why (it was null: issue 14's trial)
            assert (camera["bound_reason"] is None) == camera["certified"], camera
        report = verify_any(json.loads(json.dumps(result)))
        assert report.valid, report.first_failure



def refused_as_returned(result: dict, change) -> dict:
    """The result edited by ``change``: the verifier refuses it, on the returned fields."""
    forged = json.loads(json.dumps(result))
    change(forged)
    report = verify_any(forged)
    assert not report.valid and report.first_failure["check"] == "returned", report.first_failure
    return report.first_failure


class TestCertifiedFieldsTied:
    """What a certified camera and summary.calibration claim is what the verifier checks: each
    camera's degrees of freedom from the returned K, its tolerance from its points
    (camera_claim), its cost within that tolerance of the proven bound; the calibration's K the
    cameras' own, the certified K's difference, edges, determined and warnings recomputed."""

    def test_the_honest_result_verifies(self, solved):
        report = verify_any(json.loads(json.dumps(solved)))
        assert report.valid, report.first_failure
        calibration = solved["summary"]["calibration"]
        assert calibration["certified"] and not calibration["returned_is_certified"]  # the adjustment moved K
        assert all(c["certified"] and c["degrees_of_freedom"] == 6 for c in solved["cameras"])

    @pytest.mark.parametrize("field, value", [("degrees_of_freedom", 5), ("degrees_of_freedom", 11),
                                              ("tolerance", 0.9)])
    def test_an_edited_camera_claim_is_refused(self, solved, field, value):
        refused_as_returned(solved, lambda r: r["cameras"][2].update({field: value}))

    def test_a_camera_beyond_its_tolerance_is_refused(self, monkeypatch):
        """A wrong camera (view 3 turned by 0.1 degree, about 1.4 px, before the structure stage: the points are
        certified in it) certified by a solver whose tolerance was forged (1e12: anything passes):
        refused for the stated tolerance, for none stated (then held to a 3x4 camera's), and for
        the true figures stated (its cost beyond them)."""
        from scipy.spatial.transform import Rotation

        from geocert.pipelines.reconstruction import pipeline
        from geocert.solvers.reconstruction import structure
        from geocert.formulations.reconstruction import camera_claim

        metric_cameras = pipeline._metric_cameras

        def turned(out, metric, n_views):
            R = metric.rotations[3]
            metric.rotations[3] = Rotation.from_rotvec([np.radians(0.1), 0.0, 0.0]).as_matrix() @ R
            metric.translations[3] = metric.rotations[3] @ (R.T @ metric.translations[3])  # the same centre
            return metric_cameras(out, metric, n_views)

        true_tolerance = camera_claim.tolerance
        monkeypatch.setattr(pipeline, "_metric_cameras", turned)
        monkeypatch.setattr(camera_claim, "tolerance", lambda *a: 1e12)
        result = solve_job(job(certificate="full", bound_every_camera=True))
        monkeypatch.undo()
        camera = result["cameras"][3]
        assert camera["certified"] and camera["cost"] > 2 * camera["lower_bound"] > 0, json.dumps({k: v for k, v in camera.items() if k not in ("K", "R", "t", "P", "center")})
        assert "tolerance" in refused_as_returned(result, lambda r: None)["detail"]

        def unstated(r):
            for c in r["cameras"]:
                c.pop("tolerance"), c.pop("degrees_of_freedom")

        def true_figures(r):
            for c in r["cameras"]:
                c["tolerance"] = true_tolerance(c["points"], 6, "L2L2", r["certificate"]["options"]["camera_rel_gap"])

        for change in (unstated, true_figures):
            assert "beyond (1 + tolerance" in refused_as_returned(result, change)["detail"]

    @pytest.mark.parametrize("change", [
        lambda c: c["K"][0].__setitem__(0, c["K"][0][0] * 1.01),  # not the cameras' K
        lambda c: c.update(certified_K=c["K"], returned_is_certified=True, source="autocalibration",
                           difference={"focal_percent": 0.0, "principal_point_px": 0.0, "aspect": 0.0,
                                       "skew_px": 0.0}),  # the returned K called the one the stage certified
        lambda c: c.update(returned_is_certified=True),
        lambda c: c.update(source="autocalibration"),
        lambda c: c["difference"].update(focal_percent=0.0),
        lambda c: c.update(certified=False, certified_K=None, difference=None),  # then determined is false
        lambda c: c.update(on_range_edge=["focal"]),
    ])
    def test_an_edited_calibration_is_refused(self, solved, change):
        refused_as_returned(solved, lambda r: change(r["summary"]["calibration"]))

    def test_the_ranges_are_the_calibration_certificates(self, solved):
        """The autocalibration stage's ranges edited to end at the certified focal length are
        refused: the range edges are judged on the ranges the calibration certificate searched."""
        def edge(r):
            stage = next(s for s in r["stages"] if s["name"] == "autocalibration")
            stage["intrinsics"]["focal"][1] = r["summary"]["calibration"]["certified_K"][0][0]
            r["summary"]["calibration"]["on_range_edge"] = ["focal"]
        assert "intrinsics" in refused_as_returned(solved, edge)["detail"]

    def test_determined_on_the_range_edge_is_refused(self, solved):
        """A focal range ending below the scene's focal length: the certified K lies on its edge,
        which the result says (a warning, not determined); determined true is refused."""
        focal = solved["summary"]["calibration"]["certified_K"][0][0]
        edged = solve_job(job(certificate="full", intrinsics={"focal": [0.5 * focal, 0.9 * focal]}))
        calibration = edged["summary"]["calibration"]
        assert calibration["certified"] and "focal" in calibration["on_range_edge"], calibration
        assert not calibration["determined"] and verify_any(edged).valid

        def determined(r):
            r["summary"]["calibration"]["determined"] = r["summary"]["autocalibration_determined"] = True
        assert "determined" in refused_as_returned(edged, determined)["detail"]

    @pytest.mark.parametrize("change", [
        lambda s: s.update(autocalibration_determined=None),
        lambda s: s.update(autocalibration_certified=False),
        lambda s: s.update(warnings=[]),  # the returned K not the certified one, unsaid
        lambda s: s.update(critical_motion="orbital_motion"),  # determined under a critical motion
    ])
    def test_an_edited_summary_claim_is_refused(self, solved, change):
        refused_as_returned(solved, lambda r: change(r["summary"]))

    def test_views_not_registered_are_said_first(self):
        """A view no track reaches is not registered: the first warning says so, and a result
        without that warning is refused."""
        body = job(certificate="full")
        body["data"]["views"].append({"name": "unseen", "image_size": [640, 480]})
        result = solve_job(body)
        assert result["summary"]["views_registered"] == 6 and result["summary"]["warnings"][0]["code"] == \
            "views_not_registered"
        assert verify_any(json.loads(json.dumps(result))).valid
        refused_as_returned(result, lambda r: r["summary"]["warnings"].pop(0))

    @pytest.mark.parametrize("named", [True, False])
    def test_views_not_registered_are_named_as_the_request_named_them(self, named):
        """Issue 35: the warning names each view not registered by its index and, when the request
        named the views (a photo's file name), its name too (it listed indices alone); the
        verifier still verifies it (it reads the warning's code)."""
        body = job(certificate="full")
        body["data"]["views"] += [{"name": "IMG_0007.jpg", "image_size": [640, 480]},
                                  {"name": "IMG_0008.jpg", "image_size": [640, 480]}]
        if not named:
            for view in body["data"]["views"]:
                view.pop("name", None)
        result = solve_job(body)
        warning = next(w for w in result["summary"]["warnings"] if w["code"] == "views_not_registered")
        said = "views 6 (IMG_0007.jpg), 7 (IMG_0008.jpg): " if named else "views 6, 7: "
        reason = result["cameras"][6]["reason"]
        assert reason and result["cameras"][7]["reason"] == reason
        assert warning["detail"] == ("2 of 8 views not registered (no camera returned for them): " + said
                                     + reason), warning
        assert verify_any(json.loads(json.dumps(result))).valid

    def test_many_views_not_registered_are_counted_past_the_first_ten(self):
        from geocert.pipelines.reconstruction.claims import unregistered_warning
        from geocert.pipelines.reconstruction.pipeline import Camera

        names = [f"IMG_{v:04d}.jpg" for v in range(50)]
        names[3] = None  # a view the request left unnamed: its index alone
        missing = [Camera(v, False, "no track observes this view") for v in range(2, 50)]
        detail = unregistered_warning(missing, 50, names)["detail"]
        assert detail == ("48 of 50 views not registered (no camera returned for them): views 2 (IMG_0002.jpg), 3, "
                          + ", ".join(f"{v} (IMG_{v:04d}.jpg)" for v in range(4, 12))
                          + ": no track observes this view; and 38 more (each camera's reason says why)"), detail

    def test_cameras_beyond_their_tolerance_are_named_as_the_request_named_them(self):
        """The camera_fit_beyond_tolerance warning's views, and each cause's, by index and name."""
        from types import SimpleNamespace

        from geocert.pipelines.reconstruction.claims import _misfit_said

        beyond = [SimpleNamespace(view=v, bound=SimpleNamespace(misfit={"cause": cause}))
                  for v, cause in ((1, "pose"), (4, "pose"), (5, "unexplained"))]
        said = _misfit_said(beyond, ["a.jpg", "b.jpg", None, None, "e.jpg", None])
        assert said.startswith("views 1 (b.jpg), 4 (e.jpg): refitting its pose alone"), said
        assert "; view 5: the pose is at its optimum" in said, said
        assert _misfit_said(beyond).startswith("views 1, 4: refitting"), _misfit_said(beyond)


def run_cancelled_at(stage: str, monkeypatch=None, **options) -> tuple[dict, list[str]]:
    """The example job solved as the service solves it (batch.solve_items), cancelled once a
    progress label of ``stage`` has been published (the cancel is then seen at the next check,
    and stays requested, as the worker's ProgressPublisher.should_stop does)."""
    from geocert.jobs.runner import solve_items

    body = job(**options)
    kind, parsed, parsed_options = parse_job(body)
    labels: list[str] = []

    def stop() -> bool:
        return any(label.startswith(stage) for label in labels)

    items = solve_items(kind, parsed, parsed_options, range(1), sink=lambda p: labels.append(p.get("stage", "")),
                        should_stop=stop)
    return items[0], labels


class TestCancel:
    """A cancelled reconstruction ends "cancelled" (the item's status: workers.tasks._end ends a
    job cancelled when an item is) and keeps what was done before the cancel."""

    def test_during_the_projective_stage_keeps_the_views_registered(self):
        item, labels = run_cancelled_at("projective")
        assert item["status"] == "cancelled"
        from geocert.jobs.runner import item_sums

        assert item_sums([item])["statuses"] == {"cancelled": 1}
        statuses = {stage["name"]: stage["status"] for stage in item["stages"]}
        assert statuses == {"projective": "cancelled", "autocalibration": "cancelled",
                            "bundle_adjustment": "cancelled", "structure": "cancelled", "cameras": "cancelled"}
        registered = [c for c in item["cameras"] if c["registered"]]
        assert len(registered) == item["summary"]["views_registered"] >= 2
        assert all(c["P"] is not None for c in registered)
        KIND.result_model.model_validate({**KIND.assemble(parse_job(job())[2], [dict(item)], {
            "items": 1, "certified": 0, "nodes": 0, "solve_s": 0.0, "elapsed_s": 0.0, "statuses": {}})})

    def test_during_the_structure_stage_keeps_the_points_done(self, monkeypatch):
        from geocert.solvers.reconstruction import structure

        monkeypatch.setattr(structure, "TRACK_CHUNK", 10)  # 24 tracks: 3 chunks, the cancel after the first
        item, labels = run_cancelled_at("structure", certificate="full")
        assert item["status"] == "cancelled"
        statuses = {stage["name"]: stage["status"] for stage in item["stages"]}
        assert statuses["projective"] == statuses["bundle_adjustment"] == "done"
        assert statuses["structure"] == statuses["cameras"] == "cancelled"
        assert len(item["points"]) == item["summary"]["points"] == 10
        assert all(point["certified"] for point in item["points"])
        assert item["summary"]["views_registered"] == 6 and all(c["K"] is not None for c in item["cameras"])
        structure_stage = next(stage for stage in item["stages"] if stage["name"] == "structure")
        assert structure_stage["points"] == 10 and structure_stage["tracks_not_started"] == 14

    def test_during_the_cameras_stage_keeps_the_cameras_resected(self):
        item, labels = run_cancelled_at("cameras")
        assert item["status"] == "cancelled"
        assert len(item["points"]) == 24
        statuses = [c["status"] for c in item["cameras"]]
        assert 1 <= sum(s != "cancelled" for s in statuses) < 6, statuses
        assert next(stage for stage in item["stages"] if stage["name"] == "cameras")["status"] == "cancelled"


class TestTinyThreshold:
    """Review 14: options.threshold_px far below what any reconstruction of the data fits raised in
    the bundle adjustment's Schur solve (no observation left to adjust). A threshold is any
    positive number of pixels, so the run ends instead with a failed stage naming the option, the
    later stages skipped and no view returned registered; a start a threshold leaves nothing to
    is one adjust_best passes over."""

    @staticmethod
    def stages(result: dict) -> dict:
        KIND.result_model.model_validate(result)
        return {stage["name"]: stage for stage in result["stages"]}

    def test_no_observation_kept_fails_the_registration_naming_the_option(self):
        result = solve_job(job(threshold_px=0.01))
        stages = self.stages(result)
        assert stages["projective"]["status"] == "failed"
        assert "options.threshold_px (0.01 px)" in stages["projective"]["reason"]
        assert all(stages[name]["status"] == "skipped" for name in
                   ("autocalibration", "bundle_adjustment", "structure", "cameras"))
        assert result["summary"]["views_registered"] == 0 and result["summary"]["points"] == 0
        assert not any(camera["registered"] for camera in result["cameras"])

    def test_every_camera_dropped_fails_the_structure_stage(self):
        stages = self.stages(solve_job(job(threshold_px=1e-6)))
        assert stages["structure"]["status"] == "failed" and "no point can be triangulated" in stages["structure"]["reason"]
        assert stages["cameras"]["status"] == "skipped"

    def test_an_adjustment_left_with_nothing_is_judged_not_raised(self):
        """With the projective registration the returned rig fits every observation within 0.01 px
        (the example is noiseless: 3e-7 px); the depth-reversed twin's first adjustment keeps none
        of them (it raised there), and the twin is judged and rejected all the same."""
        result = solve_job(job(threshold_px=0.01, registration="projective"))
        stages = self.stages(result)
        assert all(stage["status"] == "done" for stage in stages.values()), stages
        assert result["summary"]["views_registered"] == 6 and result["summary"]["points"] == 24
        reversal = result["summary"]["depth_reversal"]
        assert reversal["checked"] and not reversal["adopted"] and not reversal["ambiguous"]


class TestStructureTimeLimit:
    """The certified points and cameras keep one clock together, structure_time_limit_s (they had
    only time_limit_s per point and per camera: a job's length grew with its tracks, and so did
    its tasks' last-resort limits). Past it the job ends by its own limit, not cancelled: what
    was done is kept, the stages say time_limit and how much was left out."""

    def test_past_it_the_points_and_cameras_not_started_are_left_out(self):
        from geocert.jobs.runner import solve_items

        body = job(structure_time_limit_s=1e-9)
        kind, parsed, options = parse_job(body)
        item = solve_items(kind, parsed, options, range(1))[0]
        assert item["status"] == "not_certified" and item["points"] == []
        stages = {stage["name"]: stage for stage in item["stages"]}
        assert stages["bundle_adjustment"]["status"] == "done"
        assert stages["structure"]["status"] == stages["cameras"]["status"] == "time_limit"
        assert stages["structure"]["tracks_not_started"] == 24 and stages["cameras"]["cameras_not_started"] == 6
        assert stages["structure"]["reason"].startswith("time_limit: stopped at options.structure_time_limit_s")
        assert item["summary"]["views_registered"] == 6 and all(c["K"] is not None for c in item["cameras"])
        KIND.result_model.model_validate(KIND.assemble(options, [dict(item)], {
            "items": 1, "certified": 0, "nodes": 0, "solve_s": 0.0, "elapsed_s": 0.0, "statuses": {}}))

    def test_the_searches_of_a_chunk_of_tracks_ask_the_clock(self):
        """Tracks are triangulated 500 at a time, and the clock was asked only between chunks: 500
        searches of time_limit_s each ran past the stage's limit. Now every search asks it too:
        told to stop after the chunk has begun, the searches still to run stop, keeping their
        best point (cancelled, which the pipeline reads as time_limit)."""
        from geocert.formulations.fractional.options import TriangulationOptions
        from geocert.solvers.reconstruction import structure, synthetic

        scene = synthetic.scene(views=4, points=12, seed=3, noise_px=2.0)
        cameras = {v: scene.K @ np.hstack([scene.rotations[v], scene.translations[v][:, None]]) for v in range(4)}
        asked = []

        def after_the_first_ask() -> bool:
            asked.append(True)
            return len(asked) > 1

        results = structure.triangulate_tracks(cameras, scene.tracks, TriangulationOptions(norm="L1L1", rel_gap=1e-9),
                                               should_stop=after_the_first_ask)
        assert len(asked) > 1
        assert {r.status for r in results} >= {"cancelled"} and all(r.point is not None for r in results)

    def test_the_jobs_time_bound_does_not_grow_with_its_tracks(self):
        """What sizes its tasks' last-resort limits: its stages' own limits, not tracks times
        time_limit_s (photos: as many tracks as a job may hold, 200,000 times 10 s)."""
        import base64

        import cv2

        png = base64.b64encode(cv2.imencode(".png", np.zeros((48, 64), np.uint8))[1].tobytes()).decode()
        body = job(time_limit_s=10, autocalibration_time_limit_s=60, structure_time_limit_s=300)
        kind, parsed, options = parse_job(body)
        assert kind.time_bound_s(parsed, options) == 2 * 60 + 300 + 2 * 10
        photos = {"kind": "reconstruction", "options": {"time_limit_s": 10, "features": {"time_limit_s": 100}},
                  "data": {"images": [{"name": f"p{i}", "content": png} for i in range(2)]}}
        kind, parsed, options = parse_job(photos)
        assert kind.time_bound_s(parsed, options) == 100 + 2 * 60 + 600 + 2 * 10


class TestExports:
    def test_colmap_text_model(self, solved):
        files = zipfile.ZipFile(io.BytesIO(export.colmap_zip(solved)))
        cameras = [l for l in files.read("cameras.txt").decode().splitlines() if not l.startswith("#")]
        images = [l for l in files.read("images.txt").decode().splitlines() if not l.startswith("#")]
        points = [l for l in files.read("points3D.txt").decode().splitlines() if not l.startswith("#")]
        assert len(cameras) == 6 and all(l.split()[1] == "SIMPLE_PINHOLE" for l in cameras)
        assert abs(float(cameras[0].split()[4]) - solved["cameras"][0]["K"][0][0]) < 1e-9
        assert len(images) == 12 and len(points) == 24
        # The pose round-trips: the quaternion is the returned R, and each POINTS2D entry's
        # 3D point projects onto its pixel.
        from scipy.spatial.transform import Rotation

        xyz = {int(l.split()[0]): np.array([float(v) for v in l.split()[1:4]]) for l in points}
        for k in range(6):
            head = images[2 * k].split()
            qw, qx, qy, qz = map(float, head[1:5])
            R = Rotation.from_quat([qx, qy, qz, qw]).as_matrix()
            assert np.allclose(R, solved["cameras"][k]["R"], atol=1e-12)
            t = np.array([float(v) for v in head[5:8]])
            f, cx, cy = map(float, cameras[k].split()[4:7])
            entries = images[2 * k + 1].split()
            for u, v, pid in zip(entries[0::3], entries[1::3], entries[2::3]):
                cam = R @ xyz[int(pid)] + t
                assert math.hypot(f * cam[0] / cam[2] + cx - float(u), f * cam[1] / cam[2] + cy - float(v)) < 1e-4

    def test_ply_ascii_and_binary(self, solved):
        text = export.ply(solved).decode()
        header, body = text.split("end_header\n")
        assert "element vertex 24" in header and len(body.splitlines()) == 24
        assert np.allclose([float(v) for v in body.splitlines()[0].split()[:3]], solved["points"][0]["point"])
        raw = export.ply(solved, binary=True)
        head, payload = raw.split(b"end_header\n")
        assert b"binary_little_endian" in head and len(payload) == 24 * struct.calcsize("<ddddB")
        assert np.allclose(struct.unpack_from("<ddd", payload, 0), solved["points"][0]["point"])

    def test_a_camera_with_skew_is_written_without_it_and_says_so(self, solved):
        result = copy.deepcopy(solved)
        result["cameras"][0]["K"][0][1] = 3.0
        text = export.colmap_files(result)["cameras.txt"]
        assert "skew 3 px dropped" in text and text.splitlines()[4].split()[1] == "PINHOLE"


@pytest.mark.slow
class TestPhotos:
    def test_rendered_photos_with_their_K_and_without(self):
        """Stage 1 from photos (a rendered textured box, 8 views over 120 degrees): with K given the
        calibrated path registers every view; without, the upgrade and the "simple" adjustment
        recover f = 700 px."""
        import base64

        import cv2

        from geocert.solvers.reconstruction import render
        from testing.reconstruction import aligned_rotation_errors

        scene = render.box_scene(n_views=8, arc_deg=120, seed=1)
        images = [{"name": f"v{k}", "content": base64.b64encode(cv2.imencode(".png", scene.render(c))[1]).decode()}
                  for k, c in enumerate(scene.cameras)]
        K = scene.cameras[0].K
        for options in ({"intrinsics": {"K": K.tolist()}}, {"autocalibration_time_limit_s": 5}):
            result = solve_job({"kind": "reconstruction", "data": {"images": images},
                                "options": {**options, "resect_cameras": False}})
            KIND.result_model.model_validate(result)
            assert result["stages"][0]["name"] == "matches" and result["images"]["images"] == 8
            matches = result["stages"][0]  # timed like the other stages, and in the summary's times
            assert matches["elapsed_s"] > 0 and matches["cpu_s"] > 0
            assert list(result["summary"]["time_s"]) == list(result["summary"]["cpu_s"]) == [
                stage["name"] for stage in result["stages"]]
            assert result["summary"]["time_s"]["matches"] == matches["elapsed_s"]
            assert result["summary"]["cpu_s"]["matches"] == matches["cpu_s"]
            assert result["summary"]["views_registered"] == 8 and result["summary"]["points"] > 500
            assert result["summary"]["points_certified_fraction"] == 1.0
            assert abs(result["cameras"][0]["K"][0][0] / 700 - 1) < 0.01
            errors = aligned_rotation_errors([np.array(c["R"]) for c in result["cameras"]], [c.R for c in scene.cameras])
            assert errors.max() < 0.5

    def test_fewer_than_two_images_with_matches_fail_the_matches_stage_and_keep_the_result(self):
        """A rendered photo and an all-black one of the same size: no verified pair. As when the
        projective stage fails: the job's result says why (the matches stage failed, with its
        figures and time), the later stages skipped with that reason, every camera not
        registered with its reason, and the summary filled (it was {}, with cameras [])."""
        import base64

        import cv2

        from geocert.solvers.reconstruction import render

        scene = render.box_scene(n_views=2, arc_deg=20, seed=1)
        photo = scene.render(scene.cameras[0])
        images = [{"name": name, "content": base64.b64encode(cv2.imencode(".png", image)[1]).decode()}
                  for name, image in (("photo", photo), ("black", np.zeros_like(photo)))]
        body = {"kind": "reconstruction", "data": {"images": images}, "options": {}}
        kind, parsed, options = parse_job(body)
        item = kind.solve_item(parsed, 0, options, None)
        assert item["status"] == "not_certified" and not item["certified"]
        stopped = kind.solve_item(parsed, 0, options, lambda progress: True)  # a cancel during the matching
        assert stopped["status"] == "cancelled" and stopped["summary"]["views"] == 2
        assert {stage["status"] for stage in stopped["stages"]} == {"cancelled"} and len(stopped["stages"]) == 6
        result = solve_job(body)
        KIND.result_model.model_validate(result)
        stages = {stage["name"]: stage for stage in result["stages"]}
        assert list(stages) == ["matches", "projective", "autocalibration", "bundle_adjustment", "structure",
                                "cameras"]
        assert stages["matches"]["status"] == "failed"
        assert stages["matches"]["reason"] == "fewer than 2 images have verified matches (0)"
        assert stages["matches"]["elapsed_s"] > 0 and stages["matches"]["images"] == 2
        for name in list(stages)[1:]:
            assert stages[name]["status"] == "skipped", stages[name]
            assert stages[name]["reason"] == "the matches stage failed: fewer than 2 images have verified matches (0)"
        summary = result["summary"]
        assert (summary["views"], summary["views_registered"], summary["points"], summary["tracks"]) == (2, 0, 0, 0)
        assert summary["time_s"]["matches"] == stages["matches"]["elapsed_s"]
        assert [(c["name"], c["registered"], c["reason"]) for c in result["cameras"]] == [
            ("photo", False, "no verified matches with another image"),
            ("black", False, "no verified matches with another image")]

    def test_the_matching_options_reach_stage_one_and_the_calibrated_path(self, monkeypatch):
        """options.features sets stage 1's FeatureOptions (null keeps a default), merge_components
        the calibrated path's (what the Middlebury ring needs: bench/reconstruction_images.py)."""
        import base64

        import cv2

        from geocert.pipelines.reconstruction import features
        from geocert.solvers.reconstruction import calibrated, render

        seen = {}
        original_tracks, original_calibrated = features.tracks_from_images, calibrated.calibrated_reconstruction

        def tracks(images, options=None, callback=None):
            seen["features"] = options
            return original_tracks(images, options, callback)

        def reconstruction(tracks, Ks, options=None, callback=None):
            seen["calibrated"] = options
            return original_calibrated(tracks, Ks, options, callback)

        monkeypatch.setattr(features, "tracks_from_images", tracks)
        monkeypatch.setattr(calibrated, "calibrated_reconstruction", reconstruction)
        scene = render.box_scene(n_views=4, arc_deg=60, seed=1)
        images = [{"name": f"v{k}", "content": base64.b64encode(cv2.imencode(".png", scene.render(c))[1]).decode()}
                  for k, c in enumerate(scene.cameras)]
        body = {"kind": "reconstruction", "data": {"images": images},
                "options": {"intrinsics": {"K": scene.cameras[0].K.tolist()}, "resect_cameras": False,
                            "merge_components": True, "features": {"guided_ratio": 0.8, "ratio": 0.85}}}
        body = KIND.request_model.model_validate(body).model_dump(mode="json")  # as the API passes it on
        result = solve_job(body)
        assert result["summary"]["views_registered"] == 4
        assert seen["features"].guided_ratio == 0.8 and seen["features"].ratio == 0.85
        assert seen["features"].contrast_threshold == features.FeatureOptions().contrast_threshold
        assert seen["calibrated"].merge_components is True

    def test_an_undecodable_image_names_the_item(self):
        with pytest.raises(InputError) as error:
            parse_job({"kind": "reconstruction", "data": {"images": [{"content": "aGVsbG8="}] * 2}})
        assert error.value.field == "data/images/0/content"
