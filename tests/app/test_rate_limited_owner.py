"""The job routes take their caller counted against the rate limit (deps.Owner), with no router
dependency beside it: every route is still rate limited, each request counted once, and FastAPI
walks the caller's dependencies (its key header) once a request, not twice."""

from __future__ import annotations

from geocert.app.api.deps import rate_limited
from geocert.app.api.routes import jobs as job_routes
from geocert.app.core.security import caller
from geocert.settings import get_settings
from tests.app.test_routes import exact_job


def _tree(dependant):
    yield dependant
    for sub in dependant.dependencies:
        yield from _tree(sub)


def test_every_job_route_is_rate_limited():
    for route in job_routes.router.routes:
        assert any(node.call is rate_limited for node in _tree(route.dependant)), route.path


def test_a_submission_and_a_poll_walk_the_caller_once():
    # FastAPI walks a cached dependency's tree again at each place it is named (fastapi's
    # solve_dependencies): the caller named twice was walked twice on every request.
    for path, method in (("/v1/jobs", "POST"), ("/v1/jobs/{job_id}", "GET"), ("/v1/jobs", "GET")):
        route = next(r for r in job_routes.router.routes if r.path == path and method in r.methods)
        assert sum(node.call is caller for node in _tree(route.dependant)) == 1, (method, path)


def test_each_request_is_counted_once(api, monkeypatch):
    monkeypatch.setenv("GEOCERT_RATE_LIMIT_PER_MINUTE", "3")
    get_settings.cache_clear()
    job_id = api.post("/v1/jobs", json=exact_job(7)[0]).json()["id"]
    assert api.get(f"/v1/jobs/{job_id}").status_code == 200
    assert api.get("/v1/jobs").status_code == 200  # the third of 3
    refused = api.get(f"/v1/jobs/{job_id}")
    assert refused.status_code == 429 and "GEOCERT_RATE_LIMIT_PER_MINUTE" in refused.json()["detail"]
    assert int(refused.headers["Retry-After"]) <= 61
