"""Python's cyclic collector held off while a job's body is taken in (app.collection): it ran
again and again over the young objects a large body makes (the model validated from the bytes,
the request dumped back, the kind's parse), most of the intake's CPU, finding nothing."""

from __future__ import annotations

import gc
import json
import threading

import numpy as np
import pytest

from geocert.jobs.collection import collector_held


@pytest.fixture
def collections():
    """The collections the collector starts while the test runs (gc.callbacks)."""
    started = []

    def seen(phase, info):
        if phase == "start":
            started.append(info["generation"])

    gc.callbacks.append(seen)
    try:
        yield started
    finally:
        gc.callbacks.remove(seen)


def large_body(tracks: int = 3000) -> bytes:
    rng = np.random.default_rng(5)
    cameras = [[[800.0, 0, 320, float(i)], [0, 800.0, 240, 0], [0, 0, 1, 0]] for i in range(6)]
    entries = [{"views": [0, 2, 4], "points": (rng.normal(size=(3, 2)) * 300).tolist()} for _ in range(tracks)]
    return json.dumps({"kind": "triangulation", "data": {"cameras": cameras, "tracks": entries}}).encode()


def test_the_collector_is_held_while_any_intake_runs_and_runs_again_after():
    assert gc.isenabled()
    inside, release = threading.Event(), threading.Event()

    def other_intake():
        with collector_held():
            inside.set()
            release.wait(10)

    thread = threading.Thread(target=other_intake)
    with collector_held():
        assert not gc.isenabled()
        thread.start()
        inside.wait(10)
    assert not gc.isenabled()  # the other intake still holds it
    release.set()
    thread.join(10)
    assert gc.isenabled()


def test_a_collector_turned_off_elsewhere_stays_off():
    gc.disable()
    try:
        with collector_held():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()


def test_a_large_body_is_read_and_submitted_without_a_collection(collections, monkeypatch):
    from geocert.app import job_submission
    from geocert.app.api.routes.jobs import read_in_one_pass

    body = large_body()

    class Request:  # what read_in_one_pass reads of Starlette's request
        headers = {"content-type": "application/json"}
        _json = None

        async def body(self):
            return body

    def run(coroutine):  # to its end, no event loop (read_in_one_pass waits on nothing here)
        with pytest.raises(StopIteration):
            coroutine.send(None)

    request = Request()
    gc.collect()  # the counts at zero: what is allocated around the intake starts no collection
    collections.clear()
    run(read_in_one_pass(request))
    assert request._json is not None and len(request._json.data.tracks) == 3000
    assert len(collections) <= 1 and gc.isenabled()  # the one its allocations start once it runs again

    class Store:
        def document(self, meta):
            return meta

    made = []
    monkeypatch.setattr(job_submission, "_create",
                        lambda store, owner, kind, request, items, *args: made.append(items) or {"id": "0" * 32})
    response = job_submission.Response()
    gc.collect()
    collections.clear()
    assert job_submission._submit(request._json, response, Store(), "someone", None) == {"id": "0" * 32}
    assert made == [3000] and len(collections) <= 1 and gc.isenabled()
