"""A large body of a kind without an item list to stream (a reconstruction's tracks) is decoded,
validated and stored in a submission process (app.submissions), not on the API's event loop:
against real servers, with that process stopped (SIGSTOP) while it holds such a body, another
key's requests are answered, and the submission ends once it runs again, its request stored as
a body submitted in process stores it. Errors in such a body read as they do in process; a
submission process killed fails the body it held with a 503, and the next body is taken."""

from __future__ import annotations

import json
import os
import signal
import threading

import pytest

from geocert.app.schemas import JOB_REQUEST
from tests.servers import cluster, spawned

pytestmark = pytest.mark.slow  # real servers: the full run only

THRESHOLD = 20_000  # bodies over this are taken apart (items) or whole (here) by the route
KEYS = {"geocert_api_keys": "one,other", "geocert_stream_threshold_bytes": str(THRESHOLD)}
ONE, OTHER = {"X-API-Key": "one"}, {"X-API-Key": "other"}


def reconstruction(points: int, seed: int) -> dict:
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=6, points=points, seed=seed, noise_px=0.3)
    return {"kind": "reconstruction", "data": {
        "views": [{"image_size": list(scene.image_size)}] * 6,
        "tracks": [{"views": [int(v) for v in seen], "points": [[round(float(u), 3), round(float(w), 3)] for u, w in pixels]}
                   for seen, pixels in scene.tracks]}}


def test_another_keys_requests_are_answered_while_a_large_body_is_submitted(tmp_path):
    first, second = reconstruction(300, 3), reconstruction(300, 4)
    assert len(json.dumps(first)) > THRESHOLD
    with cluster(tmp_path, workers=0, **KEYS) as (running, client):
        answer = client.post("/v1/jobs", json=first, headers=ONE)
        assert answer.status_code == 202, answer.text
        stored = client.get(f"/v1/jobs/{answer.json()['id']}/request", headers=ONE).content
        assert stored == json.dumps(JOB_REQUEST.validate_python(first).model_dump(mode="json")).encode()
        # The first large body started the submission processes and waited for them (taken in a
        # thread of the API process meanwhile, it held the event loop). Once they have, a body
        # waits in them: stopped, it is not answered, and another key's list is.
        helpers = spawned(running.api.pid)
        assert helpers, "no submission process: the body was taken in the API process"
        for pid in helpers:
            os.kill(pid, signal.SIGSTOP)
        try:
            submitted = {}
            # Sent in chunks, without a content-length: taken the same way.
            chunks = iter([json.dumps(second).encode()])
            sender = threading.Thread(target=lambda: submitted.update(answer=client.post(
                "/v1/jobs", content=chunks, headers={**ONE, "content-type": "application/json"}, timeout=120)))
            sender.start()
            listed = client.get("/v1/jobs", headers=OTHER)
            assert listed.status_code == 200
            sender.join(timeout=5)  # an answer now could only come from the API process itself
            assert sender.is_alive(), "the body was taken in the API process"
        finally:
            for pid in helpers:
                os.kill(pid, signal.SIGCONT)
        sender.join(timeout=120)
        assert submitted["answer"].status_code == 202, submitted["answer"].text

        # The submission processes killed (for memory, say): the body sent then is refused, to be
        # sent again, and new processes take the next.
        for pid in spawned(running.api.pid):
            os.kill(pid, signal.SIGKILL)
        lost = client.post("/v1/jobs", json=second, headers=ONE, timeout=120)
        assert lost.status_code == 503 and lost.headers["Retry-After"], lost.text
        again = client.post("/v1/jobs", json=second, headers=ONE, timeout=120)
        assert again.status_code == 202, again.text

        bad = json.loads(json.dumps(second))
        bad["data"]["tracks"][7]["views"] = "many"
        refused = client.post("/v1/jobs", json=bad, headers=ONE)
        assert refused.status_code == 422 and refused.json()["errors"][0]["field"] == "data/tracks/7/views"
        broken = client.post("/v1/jobs", content=json.dumps(second)[:-2].encode() + b"x}",
                             headers={**ONE, "content-type": "application/json"})
        assert broken.status_code == 400, broken.text
