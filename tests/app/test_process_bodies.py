"""Bodies read in the API's own processes (processes.validated: orient, large submissions) come
back as the errors FastAPI words for a body read in the API process (quick tier: no server)."""

from __future__ import annotations


def test_a_body_not_utf8_read_in_a_process_is_a_json_error_not_a_crash():
    """A body read in one of the API's processes (orient, large submissions: processes.validated)
    that is not UTF-8 text comes back as the JSON error FastAPI words (a 422 naming the body), not
    as an exception: schemathesis's b'\\xff\\x102di' to /v1/orient answered 500."""
    from pydantic import TypeAdapter

    from geocert.app import processes
    from geocert.app.schemas import OrientRequest

    request, error = processes.validated(TypeAdapter(OrientRequest), b"\xff\x102di")
    assert request is None and error[0] == "json" and "UTF-8" in error[2]
