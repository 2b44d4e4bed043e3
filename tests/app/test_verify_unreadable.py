"""The verify route on text its reader cannot hold or echo (issue 33): valid JSON with an integer
literal beyond Python's 4,300 digits, a member name that is a lone surrogate (a valid JSON escape,
not encodable as UTF-8) repeated in one object or named in a report's failure. Each is answered
as bad input (a 4xx problem+json) or as a report, never 500. The app alone (no Redis: the rate
limit is lifted), as the route runs in the service."""

from __future__ import annotations

import json

import pytest

from tests.verify.test_forgeries import rehash, stored


@pytest.fixture(scope="module")
def client():
    from fastapi.testclient import TestClient

    from geocert.app.api.deps import rate_limited
    from geocert.app.main import create_app

    app = create_app()
    app.dependency_overrides[rate_limited] = lambda: None
    return TestClient(app, raise_server_exceptions=False)


def post(client, text: str):
    return client.post("/v1/certificates/verify", content=text.encode(), headers={"content-type": "application/json"})


def test_an_integer_too_long_to_read_is_a_422_naming_the_body(client):
    text = json.dumps(stored("triangulation_l2l2"))[:-1] + ', "note": ' + "7" * 4301 + "}"
    response = post(client, text)
    assert response.status_code == 422 and response.headers["content-type"].startswith("application/problem+json")
    body = response.json()
    assert body["errors"][0]["field"] == "body" and "4300 digits" in body["detail"]


def test_a_long_integer_within_the_limit_is_read(client):
    """4,300 digits are read (the limit is Python's): the report then refuses the number as a cost."""
    result = stored("triangulation_l2l2")
    result["certificate"]["items"][0]["cost"] = "LONG"
    response = post(client, json.dumps(result).replace('"LONG"', "7" * 4300))
    assert response.status_code == 200 and response.json()["valid"] is False
    assert "cost must be a finite JSON number" in response.json()["first_failure"]["detail"]


@pytest.mark.parametrize("name", ["\\ud800", "\\udfff", "a\\ud83d"])
def test_a_repeated_lone_surrogate_name_is_a_422_naming_it_escaped(client, name):
    response = post(client, f'{{"{name}": 1, "{name}": 2}}')
    assert response.status_code == 422 and response.headers["content-type"].startswith("application/problem+json")
    assert response.json()["errors"][0]["field"] == json.loads(f'"{name}"').encode("utf-8", "backslashreplace").decode()


def test_a_report_quoting_a_lone_surrogate_is_answered_escaped(client):
    result = stored("autocalibration_stratified")
    result["certificate"]["data"]["\ud800"] = 1
    rehash(result["certificate"])
    response = post(client, json.dumps(result))
    assert response.status_code == 200, response.text[:300]
    report = response.json()
    assert report["valid"] is False and "\\ud800" in report["first_failure"]["detail"]


def test_a_non_ascii_name_is_quoted_as_it_is(client):
    """Only what UTF-8 cannot encode is escaped: a name in another script is echoed unchanged."""
    response = post(client, '{"é": 1, "é": 2}')
    assert response.status_code == 422 and response.json()["errors"][0]["field"] == "é"
