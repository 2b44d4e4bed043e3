"""Autocalibration through HTTP: a real `geocert serve` (embedded Redis, a real Celery worker)
takes a projective reconstruction, streams progress by stage, and returns a result whose full
certificate the service's own verify route accepts; bad input is a 422 naming the field."""

from __future__ import annotations

import json

import numpy as np
import pytest

from geocert.solvers.autocalibration import scenes
from tests.service.test_service import service, sse_events, wait_for  # noqa: F401 (the fixture)

pytestmark = pytest.mark.slow  # real servers: the full run only


class TestAutocalibrationThroughTheService:
    def test_a_reconstruction_is_upgraded_certified_and_verified(self, service):
        scene = scenes.make_scene(8, 0.1, seed=5)
        body = {"kind": "autocalibration", "data": scene.job_data(), "options": {"certificate": "full"}}
        response = service.post("/v1/jobs", json=body)
        assert response.status_code == 202, response.text
        job_id = response.json()["id"]
        stages = [data.get("stage") for _, event, data in sse_events(service, job_id, limit_s=120)
                  if event == "progress"]
        job = wait_for(service, job_id)
        assert job["status"] == "succeeded", job.get("error")
        result = job["result"]
        assert [stage["name"] for stage in result["stages"]] == ["affine", "metric"]
        assert all(stage["certified"] for stage in result["stages"])
        assert abs(result["K"][0][0] / 1000 - 1) < 0.05
        assert "metric" in stages or "affine" in stages
        report = service.post("/v1/certificates/verify", json=result).json()
        assert report["valid"] is True, report["first_failure"]
        forged = json.loads(json.dumps(result))
        forged["K"][0][0] *= 1.01
        assert service.post("/v1/certificates/verify", json=forged).json()["valid"] is False

    def test_two_cameras_are_a_422_naming_the_field(self, service):
        scene = scenes.make_scene(3, 0.0, seed=6)
        data = scene.job_data()
        data["cameras"] = data["cameras"][:2]
        response = service.post("/v1/jobs", json={"kind": "autocalibration", "data": data})
        assert response.status_code == 422
        assert any(error["field"].startswith("data/cameras") for error in response.json()["errors"])

    def test_no_image_size_and_no_ranges_is_a_422_before_queueing(self, service):
        data = scenes.make_scene(6, 0.0, seed=6).job_data()
        data.pop("image_size")
        before = [job["id"] for job in service.get("/v1/jobs").json()["jobs"]]
        response = service.post("/v1/jobs", json={"kind": "autocalibration", "data": data})
        assert response.status_code == 422, response.text
        assert response.headers["content-type"].startswith("application/problem+json")
        error = response.json()["errors"][0]
        assert error["field"].startswith("options/intrinsics/") and "image_size" in error["reason"]
        assert [job["id"] for job in service.get("/v1/jobs").json()["jobs"]] == before  # nothing queued
        ranges = {"focal": [300, 3000], "aspect": [0.9, 1.1], "skew": [-10, 10],
                  "principal_point": [[250, 750], [250, 750]]}
        given = service.post("/v1/jobs", json={"kind": "autocalibration", "data": data,
                                               "options": {"intrinsics": ranges, "time_limit_s": 5}})
        assert given.status_code == 202, given.text  # every range given: no image size needed

    def test_a_job_that_solved_nothing_says_so_at_the_top_of_its_result(self, service):
        """Three cameras without points do not bound the plane at infinity: both stages fail, and
        the result's own status says no metric upgrade was found (the job itself ran to its end)."""
        data = scenes.make_scene(3, 0.1, seed=5).job_data()
        data.pop("points")
        response = service.post("/v1/jobs", json={"kind": "autocalibration", "data": data})
        job = wait_for(service, response.json()["id"])
        result = job["result"]
        assert [stage["status"] for stage in result["stages"]] == ["failed", "failed"] and result["K"] is None
        assert result["status"] == "failed" and "no metric upgrade" in result["reason"]
        assert list(result)[:4] == ["kind", "method", "status", "reason"]

    def test_the_kind_is_listed_with_its_schema(self, service):
        kinds = {entry["kind"]: entry for entry in service.get("/v1/problems").json()}
        assert "autocalibration" in kinds and kinds["autocalibration"]["default_options"]["rel_gap"] == 1e-5
