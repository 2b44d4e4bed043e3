"""A cancel through a real `geocert serve` (embedded Redis, a real Celery worker) ends a running job
``cancelled``, whatever its kind and stage, keeping everything it finished: the autocalibration's
affine stage (it ended "failed" with a numpy error), its metric stage, the direct method (it
ignored the cancel), a reconstruction's adjustment (it ran to its end), and a sequence of stereo
frame pairs (tests/workers/test_job_end.py: a cancel no solver saw still ends the job "cancelled"). Waits are bounded generously: no wall-clock outcome is asserted."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.solvers.autocalibration import scenes
from geocert.kinds import get_kind
from tests.service.test_service import service, sse_events, wait_for  # noqa: F401 (the fixture)

pytestmark = pytest.mark.slow  # real servers: the full run only


def cancel_at(service, body: dict, stage: str) -> dict:
    """Submit, wait for a progress event of ``stage`` (a prefix), cancel, and return the job ended."""
    response = service.post("/v1/jobs", json=body)
    assert response.status_code == 202, response.text
    job_id = response.json()["id"]
    for _, event, data in sse_events(service, job_id, limit_s=300):
        if event == "progress" and (data.get("stage") or "").startswith(stage):
            break
        assert event != "end", f"the job ended before its {stage} stage: {data}"
    answer = service.post(f"/v1/jobs/{job_id}/cancel")
    assert answer.status_code == 202, answer.text
    job = wait_for(service, job_id, limit_s=120)
    assert job["status"] == "cancelled", job["error"]
    assert job["error"] is None
    return job


def test_autocalibration_cancelled_in_its_affine_stage(service):
    data = scenes.make_scene(4, 0.1, seed=5).job_data()
    data.pop("points")  # the affine stage runs to its limit (60 s): the cancel comes first
    result = cancel_at(service, {"kind": "autocalibration", "data": data}, "affine")["result"]
    assert [stage["status"] for stage in result["stages"]] == ["cancelled", "cancelled"]
    assert result["status"] == "cancelled"
    assert result["stages"][0]["nodes"] > 0  # what it searched is reported


def test_autocalibration_cancelled_in_its_metric_stage_keeps_the_affine_stage(service):
    data = scenes.make_scene(10, 1.0, seed=5).job_data()  # a metric stage of a dozen nodes, seconds long
    result = cancel_at(service, {"kind": "autocalibration", "data": data}, "metric")["result"]
    affine = result["stages"][0]
    assert affine["certified"] and affine["status"] == "optimal"
    assert result["plane_at_infinity"] == affine["plane_at_infinity"] is not None


def test_direct_autocalibration_is_cancelled(service):
    body = {**get_kind("autocalibration").example, "options": {"method": "direct"}}
    result = cancel_at(service, body, "direct")["result"]
    assert [stage["status"] for stage in result["stages"]] == ["cancelled"]
    assert result["stages"][0]["reason"] == "the job was cancelled"


def test_reconstruction_cancelled_in_its_bundle_adjustment_keeps_the_cameras(service):
    """The metric adjustment (seconds long here; 80 s for the Dinosaur under load) ends where it is at
    a cancel (it used to run to its end first): the stage says cancelled, and the views registered
    keep their metric cameras, adjusted as far as it went."""
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=8, points=1500, seed=3, noise_px=0.3)
    body = {"kind": "reconstruction", "data": {"views": [{"image_size": list(scene.image_size)}] * 8,
                                               "tracks": [{"views": [int(v) for v in views],
                                                           "points": [[round(float(u), 3), round(float(w), 3)]
                                                                      for u, w in pixels]}
                                                          for views, pixels in scene.tracks]}}
    result = cancel_at(service, body, "bundle_adjustment")["result"]
    stages = {stage["name"]: stage for stage in result["stages"]}
    assert stages["projective"]["status"] == "done" and stages["structure"]["status"] == "cancelled"
    assert stages["bundle_adjustment"]["status"] == "cancelled"
    assert "adjusted as far as the adjustment went" in stages["bundle_adjustment"]["reason"]
    registered = [camera for camera in result["cameras"] if camera["registered"]]
    assert len(registered) == 8 and all(camera["K"] is not None for camera in registered)


def test_stereo_lines_cancelled_keeps_the_pairs_done(service):
    from geocert.solvers.lines.scenes import pair_scene

    rig = pair_scene(np.random.default_rng(7), 2).rig
    pairs = [np.round(pair_scene(np.random.default_rng(seed), 200, noise_px=0.5, outlier_fraction=0.9).segments,
                      4).tolist() for seed in range(6)]
    body = {"kind": "stereo_lines", "data": {"rig": {"K_left": rig.K_left.tolist(), "K_right": rig.K_right.tolist(),
                                                     "R": rig.R.tolist(), "t": rig.t.tolist()}, "matches": pairs},
            "options": {"solver": "polynomial", "sample_size": 2, "time_limit_s": 2,
                        "ransac": {"max_iterations": 100_000, "confidence": 0.9999999}}}
    response = service.post("/v1/jobs", json=body)
    job_id = response.json()["id"]
    for _, event, data in sse_events(service, job_id, limit_s=300):
        if event == "progress" and data["items_done"] >= 1:
            break
    assert service.post(f"/v1/jobs/{job_id}/cancel").status_code == 202
    job = wait_for(service, job_id, limit_s=120)
    assert job["status"] == "cancelled"
    statuses = [pair["status"] for pair in job["result"]["pairs"]]
    assert statuses[0] != "cancelled" and statuses[-1] == "cancelled"
    assert job["result"]["pairs"][0]["reason"].startswith("time_limit")  # each pair ends at its own limit
