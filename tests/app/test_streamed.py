"""Large bodies taken item by item (app.streamed), against a real Redis: the scan finds exactly
the items json.loads would, refuses what it does not handle, and the upload stores each item as
the ordinary path would, naming a bad item as it would."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi import Request
from fastapi.exceptions import RequestValidationError

from geocert.app.errors import field_path
from geocert.app.schemas import JOB_REQUEST, JobRequest
from geocert.app import streamed
from geocert.app.streamed import split_items, upload_items
from geocert.jobs.store import JobStore
from geocert.core.geometry import InputError
from tests.support import embedded_redis_client, triangulation_job


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    yield from embedded_redis_client(tmp_path_factory, decode_responses=True)


def body_of(tracks: int = 30, indent=None) -> tuple[dict, str]:
    job = triangulation_job(np.random.default_rng(7), tracks=tracks, views=4, norm="L2L2")
    job["data"]["tracks"][3]["points"][0] = [320, 240]  # ints, as a client may send them
    return job, json.dumps(job, indent=indent)


def head_request(split) -> dict:
    return JOB_REQUEST.validate_json(split.head).model_dump(mode="json")


def as_given(text: str, form: str):
    return text if form == "str" else text.encode() if form == "bytes" else bytearray(text.encode())


class TestSplitItems:
    @pytest.mark.parametrize("form", ["str", "bytes", "bytearray"])
    @pytest.mark.parametrize("window", [1 << 16, 7])  # 7: values cut at a window's edge all the time
    @pytest.mark.parametrize("indent", [None, 2])
    def test_the_items_and_the_head_are_what_the_parser_reads(self, indent, window, form, monkeypatch):
        monkeypatch.setattr(streamed._AsciiBytes, "WINDOW", window)
        job, text = body_of(indent=indent)
        split = split_items(as_given(text, form))
        assert split is not None and (split.kind, split.chunk_key, split.count) == ("triangulation", "tracks", 30)
        assert [json.loads(split.item_text(i)) for i in range(30)] == job["data"]["tracks"]
        head = json.loads(split.head)
        assert head["data"]["tracks"] == job["data"]["tracks"][:1]
        assert {k: v for k, v in head["data"].items() if k != "tracks"} == \
            {k: v for k, v in job["data"].items() if k != "tracks"}
        assert head["options"] == job["options"] and head["kind"] == job["kind"]

    @pytest.mark.parametrize("text", [
        "",
        "[1, 2]",
        '{"kind": "triangulation", "data": {"cameras": [], "tracks": [{}, {}]}',  # unclosed
        '{"kind": "triangulation", "kind": "triangulation", "data": {"tracks": [{}, {}]}}',  # repeated key
        '{"kind": "triangulation", "data": {"tracks": [{}, {}], "tracks": [{}, {}]}}',
        '{"kind": "triangulation", "data": {"tracks": [{}]}}',  # one item: nothing to gain
        '{"kind": "bogus", "data": {"tracks": [{}, {}]}}',
        '{"kind": "triangulation", "data": {"tracks": [{}, {},]}}',  # a trailing comma
        '{"kind": "triangulation", "data": {"tracks": [{}, {}]}} trailing',
        '{"data": {"tracks": [{}, {}]}}',
    ])
    def test_what_the_scan_does_not_handle_goes_the_ordinary_way(self, text):
        assert split_items(text) is None
        assert split_items(text.encode()) is None

    def test_a_body_beyond_ascii_is_scanned_as_text(self):
        job, _ = body_of()
        job["data"]["tracks"][4]["label"] = "caf\u00e9 \u2013 north"  # not a field of a track: the model refuses it later
        text = json.dumps(job, ensure_ascii=False)
        split = split_items(text.encode())
        assert split is not None and json.loads(split.item_text(4)) == job["data"]["tracks"][4]
        assert [json.loads(split.item_text(i)) for i in range(30)] == job["data"]["tracks"]
        assert split_items(b'{"kind": "triangulation", "data": {"tracks": [{}, {"x": "\xff"}]}}') is None  # not UTF-8

    def test_an_ascii_body_is_never_held_as_text_too(self):
        import tracemalloc

        _, text = body_of(tracks=10000)  # 2 MB
        body = bytearray(text.encode())
        tracemalloc.start()
        try:
            split = split_items(body)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert split is not None and split.count == 10000
        # The spans (8 bytes an item), the head and a window or two (64 KiB): not the body's text.
        assert peak < 8 * 10000 + 4 * streamed._AsciiBytes.WINDOW + 50_000 < 0.25 * len(body)


class TestUploadItems:
    def test_items_are_stored_as_the_ordinary_path_stores_them(self, client):
        job, text = body_of()
        split = split_items(text)
        upload = upload_items(JobStore(client), split, head_request(split))
        ordinary = JOB_REQUEST.validate_python(job).model_dump(mode="json")
        assert client.lrange(upload.key, 0, -1) == [json.dumps(item) for item in ordinary["data"]["tracks"]]
        assert (upload.count, upload.observations) == (30, 120)
        assert 0 < client.ttl(upload.key) <= 3600  # gone by itself if the API dies before the job is made
        client.delete(upload.key)

    def test_the_digest_is_made_only_when_asked_and_names_the_request(self, client):
        job, compact = body_of()
        _, indented = body_of(indent=2)

        def digest(text: str, asked: bool = True) -> str | None:
            split = split_items(text)
            upload = upload_items(JobStore(client), split, head_request(split), with_digest=asked)
            client.delete(upload.key)
            return upload.digest

        assert digest(compact, asked=False) is None
        assert digest(compact) == digest(indented)  # the request, not its spelling
        job["data"]["tracks"][29]["points"][0][0] += 1.0
        assert digest(json.dumps(job)) != digest(compact)

    def test_a_bad_item_is_named_and_nothing_is_left(self, client):
        job, _ = body_of()
        job["data"]["tracks"][17]["points"][2] = ["a", 1]
        split = split_items(json.dumps(job))
        before = set(client.scan_iter("geocert:upload:*"))
        with pytest.raises(RequestValidationError) as raised:
            upload_items(JobStore(client), split, head_request(split))
        assert field_path(raised.value.errors()[0]["loc"]).startswith("data/tracks/17/points/2")
        assert set(client.scan_iter("geocert:upload:*")) == before

    def test_the_kinds_own_checks_name_the_item(self, client):
        job, _ = body_of()
        job["data"]["tracks"][25]["views"] = [0, 1, 2, 9]  # no camera 9
        split = split_items(json.dumps(job))
        with pytest.raises(InputError) as raised:
            upload_items(JobStore(client), split, head_request(split))
        assert raised.value.field == "data/tracks/25/views/3"
        assert not list(client.scan_iter("geocert:upload:*"))


class TestStreamedItemsRoute:
    """The jobs router's route class hands a body over the threshold to the route as its head,
    with the items' places on request.state; a smaller body, or one the scan leaves alone, goes
    through untouched."""

    @pytest.fixture
    def client(self, monkeypatch):
        import asyncio

        import httpx
        from fastapi import APIRouter, FastAPI

        from geocert.app.api.routes.jobs import StreamedItemsRoute
        from geocert.settings import get_settings

        monkeypatch.setenv("GEOCERT_STREAM_THRESHOLD_BYTES", "4000")
        get_settings.cache_clear()
        router = APIRouter(route_class=StreamedItemsRoute)

        @router.post("/jobs")
        def submit(body: JobRequest, request: Request):
            split = getattr(request.state, "streamed", None)
            return {"tracks_in_model": len(body.data.tracks), "streamed": None if split is None else split.count}

        app = FastAPI()
        app.include_router(router)

        def post(text: str) -> dict:
            async def send():
                async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://test") as client:
                    return (await client.post("/jobs", content=text, headers={"content-type": "application/json"})).json()
            return asyncio.run(send())

        yield post
        get_settings.cache_clear()

    def test_a_large_body_reaches_the_route_as_its_head_and_its_items(self, client):
        job, text = body_of(30)
        assert len(text) > 4000
        answer = client(text)
        assert answer == {"tracks_in_model": 1, "streamed": 30}

    def test_a_small_body_goes_through_whole(self, client):
        job, text = body_of(30)
        job["data"]["tracks"] = job["data"]["tracks"][:3]
        text = json.dumps(job)
        assert len(text) < 4000
        answer = client(text)
        assert answer == {"tracks_in_model": 3, "streamed": None}


def test_a_body_of_a_kind_without_an_item_list_is_not_scanned(monkeypatch):
    """A reconstruction's or an autocalibration's body is taken whole: its kind, read first (msgspec,
    every other value skipped), spares the event loop the scan of every array (0.29 s for an
    11.9 MB reconstruction); a body whose kind cannot be read so is scanned as before."""
    def scanned(*args, **kwargs):
        raise AssertionError("scanned")

    body = json.dumps({"kind": "reconstruction", "data": {"views": [{"image_size": [640, 480]}] * 2, "tracks": [
        {"views": [0, 1], "points": [[1.0, 2.0], [3.0, 4.0]]}] * 5}})
    monkeypatch.setattr(streamed, "_object", scanned)
    assert split_items(body) is None
    with pytest.raises(AssertionError, match="scanned"):
        split_items(body_of(30)[1])
