"""What a finished job reports about itself, through a real `geocert serve` (embedded Redis, a
real Celery worker): its progress's worst relative gap for a fully certified job."""

from __future__ import annotations

import numpy as np
import pytest

from tests.service.test_service import service, sse_events, wait_for  # noqa: F401 (the fixture)
from tests.support import triangulation_job

pytestmark = pytest.mark.slow  # real servers: the full run only


def test_a_fully_certified_job_reports_a_gap_within_its_tolerance(service):
    """Exact tracks cost about 1e-26 with the trivial bound 0 (certified by abs_gap): their relative
    gap (1.0) says nothing, and the job's worst gap counts only what lies beyond abs_gap."""
    exact = triangulation_job(np.random.default_rng(3), 6, 3, "L2L2", noise=0.0)
    noisy = triangulation_job(np.random.default_rng(4), 6, 3, "L2L2", noise=1.0)
    offset = len(exact["data"]["cameras"])
    tracks = exact["data"]["tracks"] + [{**track, "views": [v + offset for v in track["views"]]}
                                        for track in noisy["data"]["tracks"]]
    body = {"kind": "triangulation", "data": {"cameras": exact["data"]["cameras"] + noisy["data"]["cameras"],
                                              "tracks": tracks}, "options": {"norm": "L2L2"}}
    job_id = service.post("/v1/jobs", json=body).json()["id"]
    job = wait_for(service, job_id)
    assert job["status"] == "succeeded", job["error"]
    items = job["result"]["tracks"]
    assert all(item["certified"] for item in items)
    assert any(0 < item["cost"] < 1e-7 and item["lower_bound"] == 0 for item in items)  # the case in point
    rel_gap = 1e-3  # the default tolerance: every certified item is within it or within abs_gap
    assert job["progress"]["gap_rel"] <= rel_gap
    last = [data for _, event, data in sse_events(service, job_id) if event == "progress"][-1]
    assert last["gap_rel"] <= rel_gap
