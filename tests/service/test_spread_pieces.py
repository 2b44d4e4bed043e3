"""A reconstruction from photos through the service: its independent pieces (each image's
features, each image pair's matches) are spread over the solver processes (workers.pieces), and
the result is the same with one solver process, with two, and in-process (the CLI's path); a
cancel while they run stops them.

Photos: Middlebury's dinoSparseRing (Seitz, Curless, Diebel, Scharstein and Szeliski, CVPR 2006),
read from the shared data beside the checkout (the test skips without it)."""

from __future__ import annotations

import base64
import contextlib
import json
import os
import re
import subprocess
import sys
import time

import httpx
import pytest

from geocert.jobs.runner import result_json, solve_job
from geocert.kinds import get_kind
from tests.servers import free_port, wait_ready
from tests.service.test_cancel import cancel_at
from tests.support import SHARED_DATA

pytestmark = pytest.mark.slow  # real servers and SIFT on 14 photos


def ring_job() -> dict:
    folder = SHARED_DATA / "middlebury_dinoSparseRing"
    names = sorted(path.name for path in folder.glob("dinoSR*.png")) if folder.is_dir() else []
    if not names:
        pytest.skip(f"the dinoSparseRing photos are not in {folder} (see the README's Credits)")
    images = [{"name": name, "content": base64.b64encode((folder / name).read_bytes()).decode()} for name in names]
    return {"kind": "reconstruction", "data": {"images": images}, "options": {}}


def without_times(value):
    """The result without what the clock decides (times and the job's stats)."""
    if isinstance(value, dict):
        return {key: without_times(item) for key, item in value.items()
                if key not in ("elapsed_s", "cpu_s", "time_s", "stats")}
    if isinstance(value, list):
        return [without_times(item) for item in value]
    return value


def solved(client, job: dict, limit_s: float = 300) -> dict:
    response = client.post("/v1/jobs", json=job)
    assert response.status_code == 202, response.text
    job_id = response.json()["id"]
    deadline = time.monotonic() + limit_s
    while True:
        state = client.get(f"/v1/jobs/{job_id}").json()
        if state["status"] in ("succeeded", "failed", "cancelled"):
            return state
        assert time.monotonic() < deadline, f"job still {state['status']}"
        time.sleep(0.2)


def pieces_solved(client) -> dict[str, float]:
    text = client.get("/metrics").text
    return {by: float(value) for by, value in re.findall(r'geocert_pieces_total\{solved_by="(\w+)"\} ([0-9.e+]+)', text)}


@contextlib.contextmanager
def serve(data_dir, workers: int):
    """``geocert serve --workers N --concurrency 1``: N solver processes (and an embedded Redis)."""
    port = free_port()
    env = {key: value for key, value in os.environ.items() if key != "GEOCERT_REDIS_URL"}
    env.update(GEOCERT_DATA_DIR=str(data_dir), GEOCERT_PROGRESS_INTERVAL_S="0.05")
    process = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(port),
                                "--workers", str(workers), "--concurrency", "1"], env=env)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as client:
            wait_ready(client, process)
            deadline = time.monotonic() + 60
            while client.get("/readyz").json()["workers"] < workers:  # each one's first beat
                assert time.monotonic() < deadline, "the workers did not all beat within 60 s"
                time.sleep(0.2)
            yield client
    finally:
        process.terminate()
        process.wait(timeout=30)


def test_the_pieces_go_to_the_other_solver_and_the_result_is_the_same_as_with_one_and_in_process(tmp_path):
    job = ring_job()
    # as the API writes it (its result model: the members a result leaves out read null)
    in_process = without_times(json.loads(result_json(get_kind("reconstruction"), solve_job(job))))
    with serve(tmp_path / "one", workers=1) as client:
        one = solved(client, job)
        alone = pieces_solved(client)
    assert one["status"] == "succeeded", one.get("error")
    assert alone.get("helper", 0) == 0 and alone.get("task", 0) > 0  # one solver: the task did them all
    with serve(tmp_path / "two", workers=2) as client:
        two = solved(client, job)
        shared = pieces_solved(client)
        # a cancel while the pieces run ends the job, and its helpers take no piece after it
        cancelled = cancel_at(client, job, "matches")
        ended = pieces_solved(client)
        time.sleep(2.0)  # a piece the helper took before the cancel may still finish meanwhile
        settled = pieces_solved(client)
        time.sleep(1.0)
        after = pieces_solved(client)
    matches = cancelled["result"]["stages"][0]
    assert matches["name"] == "matches" and matches["status"] == "cancelled"
    # one helper (one solver process, concurrency 1): at most the one piece it held at the cancel
    # is counted after it, and none is taken later
    assert settled.get("helper", 0) - ended.get("helper", 0) <= 1
    assert settled.get("task", 0) == ended.get("task", 0)
    assert after == settled
    assert two["status"] == "succeeded", two.get("error")
    assert shared.get("helper", 0) > 0  # the other solver process took a share
    assert without_times(one["result"]) == in_process
    assert without_times(two["result"]) == in_process
    assert in_process["summary"]["views_registered"] >= 2
