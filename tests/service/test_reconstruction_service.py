"""Reconstruction through HTTP: a real `geocert serve` takes tracks, streams progress by stage,
returns cameras and certified points whose full certificate the verify route accepts, and
exports them as COLMAP text (a zip) and PLY that parse; wrong jobs and formats are problems."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from geocert.kinds import get_kind
from tests.service.test_service import service, sse_events, wait_for  # noqa: F401 (the fixture)

pytestmark = pytest.mark.slow  # real servers: the full run only


class TestReconstructionThroughTheService:
    def test_submit_result_certificate_and_exports(self, service):
        body = {**get_kind("reconstruction").example, "options": {"certificate": "full"}}
        response = service.post("/v1/jobs", json=body)
        assert response.status_code == 202, response.text
        job_id = response.json()["id"]
        assert service.get(f"/v1/jobs/{job_id}/export", params={"format": "ply"}).status_code in (200, 409)
        stages = {data.get("stage", "").split()[0] for _, event, data in sse_events(service, job_id, limit_s=120)
                  if event == "progress" and data.get("stage")}
        job = wait_for(service, job_id)
        assert job["status"] == "succeeded", job.get("error")
        result = job["result"]
        # Progress is throttled (GEOCERT_PROGRESS_INTERVAL_S, 0.25 s), so a stage shorter than that
        # may go unseen (this job's structure stage, 24 points, with the radial test before it):
        # the stream shows the first stage and others, each one of the pipeline's.
        from geocert.pipelines.reconstruction.pipeline import STAGES

        assert "projective" in stages and len(stages) >= 2 and stages <= set(STAGES), stages
        assert result["summary"]["views_registered"] == 6 and result["summary"]["points"] == 24
        assert all(point["certified"] for point in result["points"])
        assert abs(result["cameras"][0]["K"][0][0] / 800 - 1) < 1e-4
        report = service.post("/v1/certificates/verify", json=result).json()
        assert report["valid"] is True, report["first_failure"]
        assert service.post("/v1/certificates/verify", json=result["camera_certificate"]).json()["valid"] is True

        archive = service.get(f"/v1/jobs/{job_id}/export", params={"format": "colmap"})
        assert archive.status_code == 200 and archive.headers["content-type"] == "application/zip"
        files = zipfile.ZipFile(io.BytesIO(archive.content))
        assert sorted(files.namelist()) == ["cameras.txt", "images.txt", "points3D.txt"]
        points = [line for line in files.read("points3D.txt").decode().splitlines() if not line.startswith("#")]
        assert len(points) == 24
        xyz = np.array([[float(x) for x in line.split()[1:4]] for line in points])
        assert np.allclose(xyz, [p["point"] for p in result["points"]])
        cloud = service.get(f"/v1/jobs/{job_id}/export", params={"format": "ply"}).text
        assert "element vertex 24" in cloud and len(cloud.split("end_header\n")[1].splitlines()) == 24

        wrong = service.get(f"/v1/jobs/{job_id}/export", params={"format": "obj"})
        assert wrong.status_code == 422 and wrong.headers["content-type"].startswith("application/problem+json")
        assert service.get("/v1/jobs/nope/export", params={"format": "ply"}).status_code == 404

    def test_a_cancel_during_the_structure_stage_ends_cancelled_keeping_the_points_done(self, service):
        """Through the worker: a cancel seen between two chunks of tracks ends the job
        "cancelled" (not "succeeded"), with the stages before it done, the points solved before
        it kept (certified), and the tracks not started left out; a cancelled job is not exported."""
        from geocert.solvers.reconstruction import synthetic

        scene = synthetic.scene(views=6, points=3000, seed=3, noise_px=0.3)
        body = {"kind": "reconstruction", "options": {},
                "data": {"views": [{"image_size": list(scene.image_size)}] * 6,
                         "tracks": [{"views": [int(v) for v in views],
                                     "points": [[round(float(u), 3), round(float(w), 3)] for u, w in pixels]}
                                    for views, pixels in scene.tracks]}}
        response = service.post("/v1/jobs", json=body)
        assert response.status_code == 202, response.text
        job_id = response.json()["id"]
        for _, event, data in sse_events(service, job_id, limit_s=120):
            if event == "progress" and data.get("stage", "").startswith("structure"):
                break  # 3000 tracks in chunks of 500: the cancel is seen after the first chunk or so
        assert service.post(f"/v1/jobs/{job_id}/cancel").status_code == 202
        job = wait_for(service, job_id, limit_s=120)
        assert job["status"] == "cancelled", job.get("error")
        result = job["result"]
        stages = {stage["name"]: stage for stage in result["stages"]}
        assert [stages[name]["status"] for name in ("projective", "bundle_adjustment", "structure", "cameras")] == [
            "done", "done", "cancelled", "cancelled"]
        points = result["summary"]["points"]
        assert 0 < points < 3000 and points == len(result["points"]) == stages["structure"]["points"]
        assert stages["structure"]["tracks_not_started"] == 3000 - points
        assert all(point["certified"] for point in result["points"])
        assert result["summary"]["views_registered"] == 6
        assert all(camera["registered"] and camera["K"] is not None for camera in result["cameras"])
        assert service.get(f"/v1/jobs/{job_id}/export", params={"format": "ply"}).status_code == 409

    def test_a_track_naming_an_unknown_view_is_a_422(self, service):
        data = get_kind("reconstruction").example["data"]
        data = {**data, "tracks": [*data["tracks"][:3], {"views": [0, 9], "points": [[1.0, 2.0], [3.0, 4.0]]}]}
        response = service.post("/v1/jobs", json={"kind": "reconstruction", "data": data})
        assert response.status_code == 422
        assert any(error["field"] == "data/tracks/3/views/1" for error in response.json()["errors"])

    def test_another_kind_is_not_exported(self, service):
        body = get_kind("triangulation").example
        job_id = service.post("/v1/jobs", json=body).json()["id"]
        wait_for(service, job_id)
        response = service.get(f"/v1/jobs/{job_id}/export", params={"format": "colmap"})
        assert response.status_code == 422
