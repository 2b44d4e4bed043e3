"""Full certificates: fetch a job's, and check any (or a result or job carrying one) with the
independent verifier."""

from __future__ import annotations

import json

from fastapi import APIRouter, Depends, Request
from fastapi.responses import JSONResponse

from geocert.app import processes
from geocert.app.api.deps import JobStoreDep, error_responses, rate_limited
from geocert.app.api.routes.jobs import OwnedJob
from geocert.app.errors import PROBLEM_JSON, ApiProblem, is_json_media_type, json_syntax_problem
from geocert.app.schemas import RESULT_MODELS, VerifyReport
from geocert.kinds.schema import CertificateDocument
from geocert.verify import checks as verify
from geocert.core.strict import RepeatedName, Unreadable, load_document
from geocert.settings import get_settings
from geocert.jobs.store import TERMINAL

router = APIRouter(tags=["certificates"], dependencies=[Depends(rate_limited)])


@router.get("/v1/jobs/{job_id}/certificate", response_model=CertificateDocument, responses=error_responses(404, 409))
def job_certificate(job: OwnedJob, store: JobStoreDep):
    """The certificate document of a finished job submitted with ``options.certificate = "full"``."""
    if job["status"] not in TERMINAL:
        raise ApiProblem(409, f"job {job['id']} is {job['status']}: its certificate comes with its result")
    result = store.result(job["id"]) or {}
    if result.get("certificate") is None:  # absent, or null as the result model writes it
        raise ApiProblem(409, f"job {job['id']} has no full certificate: submit with options.certificate = \"full\"",
                         "options/certificate")
    return result["certificate"]


_VERIFIABLE = {
    "type": "object",
    "anyOf": [{"$ref": "#/components/schemas/CertificateDocument"},
              *({"$ref": f"#/components/schemas/{model.__name__}"} for model in RESULT_MODELS),  # from the registry
              {"$ref": "#/components/schemas/Job"},
              {"type": "object", "description": "any other object: answered with valid = false and the reason"}],
    "description": "a certificate document, a result carrying one (geocert solve's output, or a job's result) "
                   "or a job document (GET /v1/jobs/{id}) whose result carries one",
}


@router.post("/v1/certificates/verify", response_model=VerifyReport, responses=error_responses(400, 413, 415, 422),
             openapi_extra={"requestBody": {"required": True,
                                             "content": {"application/json": {"schema": _VERIFIABLE}}}})
async def verify_certificate(request: Request):
    """Check a certificate with the verifier (linear algebra only, no conic solver); takes what
    ``geocert verify`` takes: a certificate document, a result or a job document. For a result or
    a job, every item returned must also equal the item its certificate proves. ``valid`` is false,
    with ``first_failure`` naming the check, when any check fails (or the document carries no
    certificate); ``scope`` says what a valid document proves. A body naming a member twice in
    one object is refused (422): which of the two a reader takes is its parser's choice; so is valid
    JSON the reader cannot hold (an integer of more than 4,300 digits)."""
    content_type = request.headers.get("content-type")
    if not is_json_media_type(content_type):
        given = f"it was {content_type!r}" if content_type else "it was missing"
        raise ApiProblem(415, f"the body must be JSON sent with the header content-type: application/json ({given})",
                         "content-type")
    text = await request.body()
    # Parsed once, by the verifier's reader, in a verification process: the reader and the checks
    # hold the interpreter lock for seconds on a large document (two of 26 MB at once kept another
    # key's GET /v1/jobs waiting 2.6-5.2 s in a thread of the API process), and a body becomes
    # several times its size in memory.
    outcome = await _POOL.run(_verified_in_process, bytes(text), processes.environment())
    if outcome[0] == "report":
        return outcome[1]
    if outcome[0] == "syntax":  # not JSON, or not UTF-8 text
        _, position, error = outcome
        return JSONResponse(json_syntax_problem({"loc": ("body", position), "ctx": {"error": error}}, text,
                                                str(request.url.path)), status_code=400, media_type=PROBLEM_JSON)
    processes.raise_carried(outcome, text)


def _ready() -> None:
    """A verification process's first task: the verifier imported."""
    from geocert.verify import checks as _  # noqa: F401


# As many verification processes as verifications may run at once (its gate refuses more).
_POOL = processes.Pool(lambda: get_settings().max_concurrent_verifications or 2, _ready,
                       "the process verifying this document")


def _verified_in_process(text: bytes, environment: dict[str, str]) -> tuple:
    """In a verification process: ("report", the report), ("syntax", position, error) for a body
    that is not JSON or not UTF-8, or an error carried (processes.carried). The heap's free pages
    go back to the system after each."""
    processes.use(environment)
    try:
        return "report", _verified(text)
    except json.JSONDecodeError as exc:
        return "syntax", exc.pos, exc.msg
    except UnicodeDecodeError as exc:
        return "syntax", exc.start, f"not UTF-8 ({exc.reason})"
    except Exception as exc:  # the errors a verification answers with; anything else is a bug, raised
        return processes.carried_or_raised(exc)
    finally:
        processes.give_back_memory()


def _verified(text: bytes) -> dict:
    try:
        document = load_document(text)
    except RepeatedName as exc:
        raise ApiProblem(422, f"{exc}: a document must name each member once", exc.name) from None
    except Unreadable as exc:
        raise ApiProblem(422, str(exc), "body") from None
    except RecursionError:
        raise ApiProblem(422, "the body is nested too deeply to read", "body") from None
    if not isinstance(document, dict):
        raise ApiProblem(422, "the body must be a JSON object (a certificate document, a result or a job)", "body")
    return verify.verify_any(document).as_dict()
