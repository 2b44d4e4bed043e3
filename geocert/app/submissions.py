"""A large job body taken whole (a kind without an item list to stream: app.streamed) is submitted
in a process of its own, not in the API process.

Decoding it (json.loads), validating it by its model, dumping it back and storing it cost about
0.3 s of CPU a megabyte, and the decoder and parts of the model's work each hold the interpreter
lock for the whole body: in a thread of the API process they would still stop its event loop,
and every other client's request with it, for seconds. In a submission process they cost the API
process nothing but the body's bytes sent through a pipe; its answer is the job's document (or
the error), a few hundred bytes.

The route still runs its dependencies (the caller's key, its rate limit, its headers) with a
small stand-in body in place of the large one (StreamedItemsRoute); the submission process then
does what ``_submit`` does with the body itself, with the API process's settings (its GEOCERT_*
environment), so the job it makes, the request stored and the errors answered are those of a
body submitted in process. The processes start with the first large body, which waits for them
(seconds: they import what a submission needs): taken in a thread of the API process meanwhile,
it held the event loop, and every other client, for as long as it took (6.9 s, once). A
submission process that dies (killed for memory, say) fails the
submission it held with a 503 to retry; the next large body starts new ones.
"""

from __future__ import annotations

import json

from fastapi import Response

from geocert.app import processes

PROCESSES = 2  # submissions of large bodies at once; more wait their turn
# What the route's model reads in place of a large body (its validation is then cheap); the body
# itself is validated in the submission process.
STAND_IN = json.dumps({"kind": "triangulation", "data": {
    "cameras": [[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], [[1, 0, 0, -1], [0, 1, 0, 0], [0, 0, 1, 0]]],
    "tracks": [{"views": [0, 1], "points": [[0, 0], [-1, 0]]}]}}).encode()


def _ready() -> None:
    """A submission process's first task: what a submission imports, imported."""
    from geocert.app import job_submission  # noqa: F401


_POOL = processes.Pool(lambda: PROCESSES, _ready, "the process taking this large body")


async def submit(body: bytes, owner: str, idempotency_key: str | None, response: Response) -> dict:
    """Submit the job whose JSON body is ``body`` in a submission process: the job's document
    (``response`` given its headers and status), or the error raised here as it would be in process."""
    outcome = await _POOL.run(_submit_body, bytes(body), owner, idempotency_key, processes.environment())
    if outcome[0] != "document":
        processes.raise_carried(outcome, body)
    _, document, status, headers = outcome
    if status is not None:  # a replay's 200; else the route's own
        response.status_code = status
    response.headers.update(headers)
    return document


def _submit_body(body: bytes, owner: str, idempotency_key: str | None, environment: dict[str, str]) -> tuple:
    """In a submission process: what the route and ``_submit`` do with a body, as a tuple that
    crosses the pipe: ("document", document, status, headers), or an error carried (processes.
    validated, processes.carried): only plain values, so that nothing fails to cross back."""
    from geocert.app.api.deps import get_store
    from geocert.jobs.collection import collector_held
    from geocert.app.job_submission import _submit
    from geocert.app.schemas import JOB_REQUEST

    processes.use(environment)
    with collector_held():
        request, error = processes.validated(JOB_REQUEST, body)
    if error is not None:
        return error
    response = Response()  # as FastAPI gives a route: no status of its own until one is set
    response.status_code = None
    try:
        document = _submit(request, response, get_store(), owner, idempotency_key)
    except Exception as exc:  # the errors a submission answers with; anything else is a bug, raised
        error = processes.carried(exc)
        if error is None:
            raise
        return error
    headers = {name: value for name, value in response.headers.items() if name != "content-length"}
    return "document", document, response.status_code, headers
