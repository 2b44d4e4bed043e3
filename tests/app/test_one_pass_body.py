"""A job's body read in one pass (jobs.read_in_one_pass: the bytes validated by the model itself,
not json.loads then the objects it made), with a refused body's problem+json worded as FastAPI's
two passes word it (quick tier: the real app in-process, the submission itself stubbed: no Redis)."""

from __future__ import annotations

import asyncio
import json

import httpx
import pytest
from pydantic import ValidationError

from geocert.app.schemas import JOB_REQUEST
from geocert.kinds import KINDS
from geocert.settings import get_settings


@pytest.fixture
def post(monkeypatch):
    """POST /v1/jobs to the real app; the route's submission (after its body is read) is a stub
    that keeps the model it was given. Returns (status, answer, models received, json.loads calls)."""
    import starlette.requests

    from geocert.app.api.routes import jobs
    from geocert.app.main import create_app

    monkeypatch.setenv("GEOCERT_RATE_LIMIT_PER_MINUTE", "0")
    get_settings.cache_clear()
    received, loads = [], []

    class CountingJson:  # starlette.requests' json module, counting its json.loads calls
        def __getattr__(self, name):
            return getattr(json, name)

        @staticmethod
        def loads(*args, **kwargs):
            loads.append(1)
            return json.loads(*args, **kwargs)

    async def producer():
        return object()

    async def submitted(body, response, store, client, owner, idempotency_key, producer):
        received.append(body)
        return {"id": "0" * 32, "kind": body.kind, "status": "queued", "created_at": 1.0, "started_at": None,
                "finished_at": None, "progress": {}, "links": {}}

    monkeypatch.setattr(starlette.requests, "json", CountingJson())
    monkeypatch.setattr(jobs, "_loop_producer", producer)
    monkeypatch.setattr(jobs.job_submission, "submit_on_loop", submitted)
    monkeypatch.setattr(jobs, "get_async_redis", lambda *args, **kwargs: None)
    monkeypatch.setattr(jobs, "get_store", lambda: None)
    app = create_app()

    def send(content: bytes | str, content_type: str = "application/json"):
        received.clear(), loads.clear()

        async def one():
            async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://test") as client:
                return await client.post("/v1/jobs", content=content, headers={"content-type": content_type})

        response = asyncio.run(one())
        return response.status_code, response.json(), list(received), len(loads)

    yield send
    get_settings.cache_clear()


def test_a_valid_body_is_read_once_and_gives_the_model_the_two_passes_gave(post):
    """Every kind's example reaches the route as the model json.loads and validation made, and
    Starlette's json.loads never runs on it (FastAPI's first pass: 53 of the 128 ms it took for a
    0.9 MB body)."""
    for kind in KINDS:
        text = json.dumps(kind.example)
        status, answer, received, loads = post(text)
        assert status == 202, (kind.name, answer)
        assert loads == 0, kind.name
        assert len(received) == 1
        assert received[0].model_dump() == JOB_REQUEST.validate_python(json.loads(text)).model_dump(), kind.name


def _triangulation() -> dict:
    return json.loads(json.dumps(next(kind for kind in KINDS if kind.name == "triangulation").example))


def test_a_refused_body_is_worded_as_the_two_passes_word_it(post):
    """A body the one pass refuses goes FastAPI's way, so its problem+json names the field and the
    reason in the words it always had (the JSON parser's message and place; pydantic's message on
    Python objects, which differs from its message on JSON text: "a valid list", not "a valid
    array")."""
    job = _triangulation()
    job["data"]["cameras"][0] = 5
    status, answer, received, _ = post(json.dumps(job))
    assert (status, received) == (422, [])
    assert answer["errors"] == [{"field": "data/cameras/0", "reason": "Input should be a valid list"}]
    assert answer["detail"] == "data/cameras/0: Input should be a valid list"

    job = _triangulation()
    job["data"]["cameras"][0][0][0] = "800"
    status, answer, _, _ = post(json.dumps(job))
    assert status == 422
    assert answer["errors"] == [{"field": "data/cameras/0/0/0",
                                 "reason": 'Input should be a valid number (got a string "800")'}]

    text = json.dumps(_triangulation()).replace("800", "NaN", 1)
    status, answer, _, _ = post(text)
    assert status == 422 and answer["errors"][0]["field"] == "data/cameras/0/0/0"
    assert answer["errors"][0]["reason"] == "Input should be a finite number"

    status, answer, _, _ = post('{"kind": "triangulation",\n "data": }')
    assert status == 400
    assert answer["errors"] == [{"field": "body", "reason": "not valid JSON: Expecting value at line 2, column 10"}]
    assert (answer["line"], answer["column"]) == (2, 10)

    status, answer, _, loads = post(json.dumps(_triangulation()), content_type="text/plain")
    assert status == 415 and answer["errors"][0]["field"] == "content-type"


def test_a_body_not_utf8_is_the_json_error_naming_the_body(post):
    """Bytes that are not UTF-8 are answered as a body read in one of the API's processes answers
    them (processes.validated): 400 naming the body, with the position; it was FastAPI's bare
    "There was an error parsing the body", without a field."""
    status, answer, received, _ = post(b"\xff" + json.dumps(_triangulation()).encode())
    assert status == 400 and not received, answer
    assert answer["errors"][0]["field"] == "body" and "not UTF-8" in answer["errors"][0]["reason"], answer
    assert (answer["line"], answer["column"]) == (1, 1)


def _variants() -> list[bytes]:
    """Valid and refused bodies where JSON text and Python objects could part: non-finite and
    huge numbers, integers where decimals go and back, booleans, duplicate members, escapes (a
    lone surrogate, control characters), a byte-order mark, bytes that are not UTF-8, deep nesting."""
    base = json.dumps(_triangulation())
    out = [json.dumps(kind.example).encode() for kind in KINDS]
    for old, new in (("800", "NaN"), ("800", "Infinity"), ("800", "-Infinity"), ("800", "1e400"), ("800", "800.0"),
                     ("800", "8e2"), ("800", "true"), ("800", "1" + "0" * 400), ("0.3", "0.30000000000000004"),
                     ('"L2L2"', '"L2L2", "norm": "L1L1"'), ('"L2L2"', '"L\\u0032L2"'), ('"L2L2"', '"L2L2\\ud800"'),
                     ('"views": [0, 1]', '"views": [0.0, 1]'), ('"views": [0, 1]', '"views": [false, 1]'),
                     ('"views": [0, 1]', '"views": [0, 1], "views": [1, 2]'),
                     ('"options": {', '"options": {"rel_gap": 1e-3, '), ('"options": {', '"options": {"x": 1, ')):
        out.append(base.replace(old, new, 1).encode())
    reconstruction = next(kind for kind in KINDS if kind.name == "reconstruction").example
    named = json.dumps(reconstruction)
    if '"name": "' in named:
        out.append(named.replace('"name": "', '"name": "a\\u0000', 1).encode())
        out.append(named.replace('"name": "', '"name": "\\udc80', 1).encode())
    out += [b"\xef\xbb\xbf" + base.encode(), base.encode() + b"\n ", b"\xff" + base.encode(),
            base.replace('"L2L2"', '"L2L2\xe9"', 1).encode("latin-1"),
            b'{"kind": "triangulation", "data": ' + b"[" * 3000 + b"]" * 3000 + b"}"]
    return out


@pytest.mark.parametrize("body", _variants(), ids=lambda body: str(hash(body) % 10**6))
def test_the_one_pass_accepts_only_what_the_two_passes_accept_and_gives_the_same_model(body):
    """The one pass's model stands for the two passes' (a body it refuses goes their way): so it
    must accept no body they refuse, and give the model they give for each body it accepts."""
    try:
        one = JOB_REQUEST.validate_json(body)
    except ValidationError:
        return  # refused here: the two passes answer it, as before
    two = JOB_REQUEST.validate_python(json.loads(body))  # raises if they refuse what the one pass took
    assert json.dumps(one.model_dump()) == json.dumps(two.model_dump())


def test_a_client_gone_mid_body_is_answered_as_before_not_raised(monkeypatch):
    """A client that leaves while its body arrives: the one pass's read meets the disconnect, and
    leaves it to FastAPI's read, which answers it (400, to no one) as it did; the disconnect is
    not raised out of the app (uvicorn would log it as the application's error)."""
    from geocert.app.main import create_app

    monkeypatch.setenv("GEOCERT_RATE_LIMIT_PER_MINUTE", "0")
    get_settings.cache_clear()
    app = create_app()
    text = json.dumps(_triangulation()).encode()
    messages = iter([{"type": "http.request", "body": text[:100], "more_body": True}])
    statuses = []

    async def receive():
        return next(messages, {"type": "http.disconnect"})

    async def send(message):
        if message["type"] == "http.response.start":
            statuses.append(message["status"])

    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST", "scheme": "http",
             "path": "/v1/jobs", "raw_path": b"/v1/jobs", "query_string": b"", "root_path": "",
             "headers": [(b"host", b"test"), (b"content-type", b"application/json"),
                         (b"content-length", str(len(text)).encode())],
             "client": ("127.0.0.1", 50000), "server": ("127.0.0.1", 8000), "state": {}}
    try:
        asyncio.run(app(scope, receive, send))
    finally:
        get_settings.cache_clear()
    assert statuses == [400]
