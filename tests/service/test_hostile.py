"""Hostile input: schemathesis over the checked-in OpenAPI document (the SSE route excluded),
and hypothesis payloads with NaN, huge numbers, deep nesting and wrong types. Nothing may
answer 500 or outside the schema; every rejection is 4xx problem+json."""

from __future__ import annotations

import json

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from schemathesis.checks import (
    content_type_conformance,
    not_a_server_error,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from tests.servers import cluster
from tests.support import ROOT

SPEC = ROOT / "openapi" / "openapi.json"
SCHEMA = schemathesis.openapi.from_path(SPEC).exclude(path="/v1/jobs/{job_id}/events")
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance,
          response_headers_conformance]


pytestmark = pytest.mark.slow  # real servers, real data or SCIP: the full run only


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    """One worker (so /readyz is ready), and no rate or active-job limits to trip over."""
    with cluster(tmp_path_factory.mktemp("hostile"), workers=1, geocert_rate_limit_per_minute="0",
                 geocert_max_active_jobs_per_key="0", geocert_max_body_bytes="200000") as (running, client):
        yield running.base, client


@SCHEMA.parametrize()
@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
def test_no_server_error_and_every_answer_fits_the_schema(case, hostile):
    base, _ = hostile
    response = case.call(base_url=base, timeout=30)
    case.validate_response(response, checks=CHECKS)


def nested(depth: int):
    value: object = 1.0
    for _ in range(depth):
        value = [value]
    return value


numbers = st.one_of(st.just(float("nan")), st.just(float("inf")), st.just(-1e308), st.just(1e308),
                    st.floats(allow_nan=True, allow_infinity=True), st.integers(-(10**30), 10**30))
junk = st.recursive(st.one_of(st.none(), st.booleans(), numbers, st.text(max_size=5)),
                    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=5), inner,
                                                                                          max_size=4)),
                    max_leaves=20)


def mutate(base: dict, path: list, value) -> dict:
    body = json.loads(json.dumps(base))
    target = body
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return body


GOOD = {"kind": "triangulation",
        "data": {"cameras": [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]],
                             [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]],
                 "tracks": [{"views": [0, 1], "points": [[330.0, 250.0], [250.0, 250.0]]}]}}
PLACES = [["kind"], ["data"], ["data", "cameras"], ["data", "cameras", 0], ["data", "cameras", 0, 0, 0],
          ["data", "tracks"], ["data", "tracks", 0, "views"], ["data", "tracks", 0, "views", 0],
          ["data", "tracks", 0, "points", 0, 1], ["options"]]


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(place=st.sampled_from(PLACES), value=st.one_of(junk, st.integers(1, 400).map(nested)))
def test_malformed_payloads_are_4xx_problems(hostile, place, value):
    _, client = hostile
    body = json.dumps(mutate(GOOD, place, value), allow_nan=True)  # NaN and Infinity as JSON extensions
    response = client.post("/v1/jobs", content=body, headers={"content-type": "application/json"})
    if response.status_code == 202:  # the mutation happened to be valid: it must then be a real job
        assert response.json()["status"] in ("queued", "running", "succeeded")
        return
    assert 400 <= response.status_code < 500, response.text
    assert response.headers["content-type"] == "application/problem+json"
    problem = response.json()
    assert problem["status"] == response.status_code and problem["title"]
