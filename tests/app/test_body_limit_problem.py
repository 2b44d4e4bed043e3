"""The 413 for a body over GEOCERT_MAX_BODY_BYTES is a problem document like every other refusal
of the API: it names the part of the request refused (``errors[0].field`` = ``body``, as the 400
for a body that is not JSON does) and the route (``instance``), whether content-length declared
the size or the bytes were counted as they arrived (quick tier: the middleware over a stub app)."""

from __future__ import annotations

from starlette.applications import Starlette
from starlette.responses import JSONResponse
from starlette.routing import Route
from starlette.testclient import TestClient

from geocert.app.main import BodySizeLimit

LIMIT = 1000


async def echo(request):
    return JSONResponse({"bytes": len(await request.body())})


def client():
    # the stub's reading of a refused body ends in ClientDisconnect (the middleware tells it the
    # client has gone, and drops its answer): not this test's subject, so not raised here
    app = Starlette(routes=[Route("/v1/jobs", echo, methods=["POST"])])
    return TestClient(BodySizeLimit(app, LIMIT), raise_server_exceptions=False)


def check(response):
    assert response.status_code == 413
    assert response.headers["content-type"].startswith("application/problem+json")
    problem = response.json()
    assert problem["status"] == 413 and problem["instance"] == "/v1/jobs"
    assert str(LIMIT) in problem["detail"] and "GEOCERT_MAX_BODY_BYTES" in problem["detail"]
    assert [e["field"] for e in problem["errors"]] == ["body"]
    assert "GEOCERT_MAX_BODY_BYTES" in problem["errors"][0]["reason"]


def test_a_body_under_the_limit_passes():
    assert client().post("/v1/jobs", content=b"x" * LIMIT).json() == {"bytes": LIMIT}


def test_a_declared_body_over_the_limit_is_a_problem_naming_the_body():
    check(client().post("/v1/jobs", content=b"x" * (LIMIT + 1)))


def test_a_chunked_body_over_the_limit_is_a_problem_naming_the_body():
    check(client().post("/v1/jobs", content=iter([b"x" * 600, b"x" * 600])))
