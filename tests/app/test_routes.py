"""The job and certificate routes in-process (tests/app/conftest.py: the app over a real Redis,
its queued tasks run here): submit, poll, result, cancel, certificates, idempotent replays,
listing, and problem+json naming the field (moved here from tests/service/test_service.py, which
started a real `geocert serve` for them). Results are checked against the ground truth the
data were made from."""

from __future__ import annotations

import json

import numpy as np
import pytest

from geocert.core.certificates import VERSION
from testing.jobs import look_at, service_job as triangulation_job
from tests.support import assert_problem

PROBLEM = "application/problem+json"


def exact_job(seed: int, tracks: int = 3, views: int = 3, **options) -> tuple[dict, np.ndarray]:
    """A triangulation job whose image points are the exact projections of known points: its
    optimum is those points at cost zero. Returns the body and the points."""
    rng = np.random.default_rng(seed)
    cameras = np.array([look_at(rng.normal(size=3) * 2 + [0.0, 0.0, -8.0], rng.normal(size=3) * 0.3)
                        for _ in range(views)])
    points = rng.normal(size=(tracks, 3))
    body_tracks = []
    for X in points:
        image = cameras @ np.append(X, 1.0)
        body_tracks.append({"views": list(range(views)), "points": (image[:, :2] / image[:, 2:]).tolist()})
    return ({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": body_tracks},
             "options": {"norm": "L2L2", **options}}, points)


def problem_fields(response, status: int) -> list[str]:
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith(PROBLEM)
    problem = response.json()
    assert problem["status"] == status and problem["title"]
    return [error["field"] for error in problem.get("errors", [])]


def test_a_job_is_queued_then_solved_to_the_points_it_was_made_from(api, run_queued):
    body, points = exact_job(1)
    response = api.post("/v1/jobs", json=body)
    assert response.status_code == 202
    job_id = response.json()["id"]
    assert response.headers["location"] == f"/v1/jobs/{job_id}"
    queued = api.get(f"/v1/jobs/{job_id}").json()
    assert queued["status"] == "queued" and queued["result"] is None
    assert run_queued() == ["geocert.solve_chunk"]
    job = api.get(f"/v1/jobs/{job_id}").json()
    assert job["status"] == "succeeded"
    tracks = job["result"]["tracks"]
    assert len(tracks) == 3 and all(track["certified"] for track in tracks)
    for track, X in zip(tracks, points):
        assert np.allclose(track["point"], X, atol=1e-6)
        assert track["cost"] == pytest.approx(0.0, abs=1e-9)
        assert track["lower_bound"] <= track["cost"] + 1e-12
    assert job["progress"]["items_done"] == job["progress"]["items_total"] == 3
    request = api.get(f"/v1/jobs/{job_id}/request").json()
    assert request["data"] == body["data"] and request["options"]["norm"] == "L2L2"


def test_the_full_certificate_is_served_and_verified_and_a_moved_point_is_caught(api, run_queued):
    body, _ = exact_job(2, certificate="full")
    job_id = api.post("/v1/jobs", json=body).json()["id"]
    run_queued()
    job = api.get(f"/v1/jobs/{job_id}").json()
    response = api.get(f"/v1/jobs/{job_id}/certificate")
    assert response.status_code == 200
    document = response.json()
    assert document == job["result"]["certificate"]
    assert document["format"] == "geocert-certificate" and document["version"] == VERSION
    for verifiable in (document, job["result"], job):
        report = api.post("/v1/certificates/verify", json=verifiable).json()
        assert report["valid"] is True and report["items_checked"] == 3 and report["first_failure"] is None, report
    tampered = json.loads(json.dumps(document))
    tampered["items"][1]["point"][0] += 1e-3
    report = api.post("/v1/certificates/verify", json=tampered).json()
    assert report["valid"] is False and (report["first_failure"]["check"], report["first_failure"]["item"]) == (
        "objective", 1)
    moved = json.loads(json.dumps(job))
    moved["result"]["tracks"][0]["point"][0] += 1.0  # the certificate itself untouched
    assert api.post("/v1/certificates/verify", json=moved).json()["first_failure"]["check"] == "returned"


def test_a_summary_job_has_no_certificate_document(api, run_queued):
    job_id = api.post("/v1/jobs", json=exact_job(3)[0]).json()["id"]
    assert problem_fields(api.get(f"/v1/jobs/{job_id}/certificate"), 409) == []  # not ended yet
    run_queued()
    response = api.get(f"/v1/jobs/{job_id}/certificate")
    assert problem_fields(response, 409) == ["options/certificate"]
    assert 'options.certificate = "full"' in response.json()["detail"]


def test_an_autocalibration_option_its_method_ignores_is_a_422_naming_it(api):
    """varying_focal with the default (stratified) method: refused at submission, not queued to
    return one K for every view."""
    from geocert.kinds.autocalibration import EXAMPLE_DATA

    response = api.post("/v1/jobs", json={"kind": "autocalibration", "data": EXAMPLE_DATA,
                                          "options": {"varying_focal": True}})
    assert problem_fields(response, 422) == ["options/varying_focal"]


@pytest.mark.parametrize("kind, intrinsics, field", [
    ("autocalibration", {"focal": [800, 5e7]}, "options/intrinsics/focal"),
    ("autocalibration", {"principal_point": [[0, 640], [0, 2e8]]}, "options/intrinsics/principal_point/1"),
    ("reconstruction", {"K": [[5e8, 0, 320], [0, 5e8, 240], [0, 0, 1]]}, "options/intrinsics/K/0/0"),
])
def test_intrinsics_over_ten_image_sides_are_a_422_naming_the_field(api, kind, intrinsics, field):
    """A focal length or principal point over 1e7 px (ten times the largest image side taken)
    was queued: the problem names the range or K entry and the limit, and nothing is made."""
    from geocert.kinds import get_kind

    body = {**get_kind(kind).example, "options": {"intrinsics": intrinsics}}
    response = api.post("/v1/jobs", json=body)
    assert problem_fields(response, 422) == [field]
    assert "exceeds the limit of 1e+07 px" in response.json()["errors"][0]["reason"]
    assert api.get("/v1/jobs").json()["jobs"] == []


@pytest.mark.parametrize("kind", ["autocalibration", "reconstruction"])
def test_an_aspect_ratio_no_camera_has_is_a_422_naming_the_range(api, kind):
    """An aspect range to 1e9 (below the coordinate limit, far beyond any camera's pixel) was
    queued: the problem names options/intrinsics/aspect and the bounds, and nothing is made."""
    from geocert.kinds import get_kind

    body = {**get_kind(kind).example, "options": {"intrinsics": {"aspect": [0.5, 1e9]}}}
    response = api.post("/v1/jobs", json=body)
    assert problem_fields(response, 422) == ["options/intrinsics/aspect"]
    assert "outside [0.001, 1000]" in response.json()["errors"][0]["reason"]
    assert api.get("/v1/jobs").json()["jobs"] == []


def test_a_focal_prior_over_the_focal_ranges_limit_is_a_422_naming_it(api):
    """focal_prior_px to 1e7 px, as a focal range (it was capped at 1e6); over it, the problem
    names options/focal_prior_px."""
    from geocert.kinds import get_kind

    example = get_kind("reconstruction").example
    response = api.post("/v1/jobs", json={**example, "options": {"focal_prior_px": 2e7}})
    assert problem_fields(response, 422) == ["options/focal_prior_px"]
    assert api.get("/v1/jobs").json()["jobs"] == []


def test_verify_refuses_what_is_not_a_json_object_sent_as_json(api):
    assert problem_fields(api.post("/v1/certificates/verify", json=[1, 2]), 422) == ["body"]
    assert problem_fields(api.post("/v1/certificates/verify", content=b"{}", headers={"content-type": "text/plain"}),
                          415) == ["content-type"]
    for document in ({"format": "something else"}, {"kind": "triangulation", "tracks": []}):
        response = api.post("/v1/certificates/verify", json=document)
        assert response.status_code == 200
        assert (response.json()["valid"], response.json()["first_failure"]["check"]) == (False, "format")


def test_a_queued_job_cancelled_never_starts_and_an_ended_one_is_a_409(api, run_queued):
    job_id = api.post("/v1/jobs", json=exact_job(4)[0]).json()["id"]
    response = api.post(f"/v1/jobs/{job_id}/cancel")
    assert response.status_code == 202 and response.json()["status"] == "cancelled"
    run_queued()  # a worker taking its task finds it ended
    job = api.get(f"/v1/jobs/{job_id}").json()
    assert job["status"] == "cancelled" and job["started_at"] is None and job["result"] is None
    response = api.post(f"/v1/jobs/{job_id}/cancel")
    assert problem_fields(response, 409) == []
    assert "cancelled" in response.json()["detail"] and "nothing to cancel" in response.json()["detail"]
    assert api.delete(f"/v1/jobs/{job_id}").status_code == 204
    assert problem_fields(api.get(f"/v1/jobs/{job_id}"), 404) == []


@pytest.mark.parametrize("change, field", [
    (lambda body: body["data"]["tracks"][0]["views"].__setitem__(1, 99), "data/tracks/0/views/1"),
    (lambda body: body["data"]["tracks"][0].update(views=[0], points=[[1.0, 2.0]]), "data/tracks/0/views"),
    (lambda body: body["options"].update(norm="L9"), "options/norm"),
    (lambda body: body["options"].update(no_such_option=1), "options/no_such_option"),
    (lambda body: body["options"].update(max_nodes=100.0), "options/max_nodes"),
    (lambda body: body["data"]["tracks"][0]["points"][0].__setitem__(0, "330"), "data/tracks/0/points/0/0"),
    (lambda body: body["data"]["tracks"][0]["views"].__setitem__(1, 10 ** 25), "data/tracks/0/views/1"),  # was a 500
    (lambda body: body.pop("kind"), "kind"),  # was named "body"
    (lambda body: body.update(kind="triangulate"), "kind"),  # was named "body"
    (lambda body: body.update(kind=5), "kind"),
])
def test_bad_input_is_a_422_naming_the_field(api, change, field):
    body, _ = exact_job(5)
    change(body)
    assert field in problem_fields(api.post("/v1/jobs", json=body), 422)
    assert api.get("/v1/jobs").json()["jobs"] == []  # nothing was made


@pytest.mark.parametrize("kind, given", [
    (5, "the number 5"),  # was "'5' is not a kind served": read as if the string "5" had been sent
    (None, "null"), (True, "true"), (["triangulation"], "an array"),
    ("triangulate", 'the string "triangulate"'),
])
def test_a_kind_not_served_says_it_must_be_one_of_the_kinds_served_and_what_was_given(api, kind, given):
    body, _ = exact_job(5)
    body["kind"] = kind
    response = api.post("/v1/jobs", json=body)
    assert problem_fields(response, 422) == ["kind"]
    reason = response.json()["errors"][0]["reason"]
    assert reason.startswith('must be one of the kinds served, a string: "triangulation", "resection"'), reason
    assert reason.endswith(f"(got {given})"), reason
    assert response.json()["detail"] == f"kind: {reason}"
    body.pop("kind")
    missing = api.post("/v1/jobs", json=body)
    assert problem_fields(missing, 422) == ["kind"]
    assert missing.json()["errors"][0]["reason"].startswith("Field required: must be one of the kinds served")


def test_an_unknown_job_is_a_404(api):
    assert problem_fields(api.get("/v1/jobs/" + "0" * 32), 404) == []
    assert problem_fields(api.post("/v1/jobs/not-an-id/cancel"), 404) == []


def test_an_idempotency_key_replays_its_job_and_refuses_another_body(api):
    body, _ = exact_job(6)
    first = api.post("/v1/jobs", json=body, headers={"Idempotency-Key": "k1"})
    assert first.status_code == 202
    again = api.post("/v1/jobs", json=body, headers={"Idempotency-Key": "k1"})
    assert again.status_code == 200 and again.json()["id"] == first.json()["id"]
    other, _ = exact_job(7)
    assert problem_fields(api.post("/v1/jobs", json=other, headers={"Idempotency-Key": "k1"}), 422) == [
        "Idempotency-Key"]
    fresh = api.post("/v1/jobs", json=body, headers={"Idempotency-Key": "k2"})
    assert fresh.status_code == 202 and fresh.json()["id"] != first.json()["id"]
    assert len(api.get("/v1/jobs").json()["jobs"]) == 2


def test_the_listing_pages_newest_first_and_filters_by_status(api, run_queued):
    ids = [api.post("/v1/jobs", json=exact_job(10 + n, tracks=1)[0]).json()["id"] for n in range(3)]
    first = api.get("/v1/jobs", params={"limit": 2})
    assert first.status_code == 200
    page = first.json()
    assert [job["id"] for job in page["jobs"]] == ids[::-1][:2]
    assert first.headers["link"] == f'<{page["links"]["next"]}>; rel="next"'
    rest = api.get(page["links"]["next"]).json()
    assert [job["id"] for job in rest["jobs"]] == ids[:1] and rest["next_cursor"] is None
    api.post(f"/v1/jobs/{ids[1]}/cancel")
    run_queued()
    statuses = {status: [job["id"] for job in api.get("/v1/jobs", params={"status": status}).json()["jobs"]]
                for status in ("succeeded", "cancelled", "queued")}
    assert statuses == {"succeeded": [ids[2], ids[0]], "cancelled": [ids[1]], "queued": []}
    assert "cursor" in problem_fields(api.get("/v1/jobs", params={"cursor": "nonsense"}), 422)


class TestCertificateBodies:
    def test_a_document_naming_a_member_twice_is_refused_and_one_not_sent_as_json_too(self, api, run_queued):
        """Which of two values of one name a reader takes is its parser's choice: a text holding
        two results (a first "tracks" with claims no proof backs, then a genuine result) is refused,
        naming the member, where the last was read and verified. A body not sent as JSON is a 415."""
        body = triangulation_job(np.random.default_rng(30), tracks=2, views=3, certificate="full")
        job_id = api.post("/v1/jobs", json=body).json()["id"]
        run_queued()
        result = api.get(f"/v1/jobs/{job_id}").json()["result"]
        forged = [{**track, "cost": 0.0, "lower_bound": 0.0, "gap": 0.0} for track in result["tracks"]]
        text = '{"tracks": ' + json.dumps(forged) + ", " + json.dumps(result)[1:]
        assert api.post("/v1/certificates/verify", json=result).json()["valid"] is True
        response = api.post("/v1/certificates/verify", content=text.encode(),
                            headers={"content-type": "application/json"})
        assert response.status_code == 422 and response.headers["content-type"].startswith("application/problem+json")
        assert [e["field"] for e in response.json()["errors"]] == ["tracks"], response.json()
        response = api.post("/v1/certificates/verify", content=json.dumps(result).encode(),
                            headers={"content-type": "text/plain"})
        assert response.status_code == 415 and "content-type: application/json" in response.json()["detail"]


class TestBadInput:
    def test_malformed_payloads_get_422_naming_the_field(self, api):
        good = triangulation_job(np.random.default_rng(26), tracks=1)
        bad_index = json.loads(json.dumps(good))
        bad_index["data"]["tracks"][0]["views"][-1] = 99
        assert_problem(api.post("/v1/jobs", json=bad_index), 422, "data/tracks/0/views/1")
        nan = json.dumps(good).replace(str(good["data"]["tracks"][0]["points"][0][0]), "NaN", 1)
        assert_problem(api.post("/v1/jobs", content=nan, headers={"content-type": "application/json"}),
                            422, "data/tracks/0/points/0/0")
        short = json.loads(json.dumps(good))
        short["data"]["tracks"][0] = {"views": [0], "points": [[1.0, 2.0]]}
        assert_problem(api.post("/v1/jobs", json=short), 422, "data/tracks/0/views")
        flat = json.loads(json.dumps(good))
        flat["data"]["cameras"][0] = [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1, 0]]
        assert_problem(api.post("/v1/jobs", json=flat), 422, "data/cameras/0")
        assert_problem(api.post("/v1/jobs", json={**good, "options": {"norm": "L9"}}), 422, "options/norm")

    def test_unparseable_json_is_a_400_with_line_column_and_the_parsers_message(self, api):
        body = b'{"kind": "triangulation",\n "data": {"cameras": [1, 2,]}}'
        problem = assert_problem(
            api.post("/v1/jobs", content=body, headers={"content-type": "application/json"}), 400, "body")
        assert (problem["line"], problem["column"]) == (2, 28)
        assert "line 2, column 28" in problem["detail"] and "Expecting value" in problem["detail"]
        problem = assert_problem(
            api.post("/v1/certificates/verify", content=b"{not json", headers={"content-type": "application/json"}),
            400, "body")
        assert (problem["line"], problem["column"]) == (1, 2) and "double quotes" in problem["detail"]
        problem = assert_problem(  # bytes that are not UTF-8 text (found by schemathesis: a 500)
            api.post("/v1/certificates/verify", content=b'{"a": "\xff\xfe"}',
                         headers={"content-type": "application/json"}), 400, "body")
        assert "UTF-8" in problem["detail"]

    @pytest.mark.parametrize("headers", [{}, {"content-type": "text/plain"}, {"content-type": "application/x-www-form-urlencoded"}])
    def test_a_body_not_sent_as_json_gets_a_415_naming_the_header(self, api, headers):
        body = json.dumps(triangulation_job(np.random.default_rng(26), tracks=1)).encode()
        response = api.post("/v1/jobs", content=body, headers=headers)
        problem = assert_problem(response, 415, "content-type")
        assert "content-type: application/json" in problem["detail"]

    @pytest.mark.parametrize("place, value, field", [
        (("data", "tracks", 0, "points", 0, 0), "330", "data/tracks/0/points/0/0"),
        (("data", "tracks", 0, "points", 0, 1), True, "data/tracks/0/points/0/1"),
        (("data", "cameras", 0, 0, 0), "800", "data/cameras/0/0/0"),
        (("data", "tracks", 0, "views", 1), 1.0, "data/tracks/0/views/1"),
        (("options", "rel_gap"), "1e-3", "options/rel_gap"),
        (("options", "max_nodes"), 100.0, "options/max_nodes"),
        (("options", "time_limit_s"), False, "options/time_limit_s"),
    ])
    def test_values_are_taken_only_as_their_json_type(self, api, place, value, field):
        body = triangulation_job(np.random.default_rng(26), tracks=1, rel_gap=1e-3)
        target = body
        for key in place[:-1]:
            target = target[key]
        target[place[-1]] = value
        problem = assert_problem(api.post("/v1/jobs", json=body), 422, field)
        reason = next(e["reason"] for e in problem["errors"] if e["field"] == field)
        assert json.dumps(value) in reason  # says what it got: "330" is a string, 1.0 a decimal number

    def test_unknown_job_is_404(self, api):
        assert_problem(api.get("/v1/jobs/0123"), 404)
        assert_problem(api.get("/v1/jobs/0123/events"), 404)
