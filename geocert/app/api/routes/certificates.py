"""Full certificates: fetch a job's, and check any (or a result or job carrying one) with the
independent verifier."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Depends

from geocert.app.api.deps import JobStoreDep, error_responses, rate_limited
from geocert.app.api.routes.jobs import OwnedJob
from geocert.app.errors import ApiProblem
from geocert.app.schemas import RESULT_MODELS, VerifyReport
from geocert.kinds.schema import CertificateDocument
from geocert.solvers import verify
from geocert.workers.store import TERMINAL

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
    "anyOf": [{"$ref": "#/components/schemas/CertificateDocument"},
              *({"$ref": f"#/components/schemas/{model.__name__}"} for model in RESULT_MODELS),  # from the registry
              {"$ref": "#/components/schemas/Job"},
              {"type": "object", "description": "any other object: answered with valid = false and the reason"}],
    "description": "a certificate document, a result carrying one (geocert solve's output, or a job's result) "
                   "or a job document (GET /v1/jobs/{id}) whose result carries one",
}


@router.post("/v1/certificates/verify", response_model=VerifyReport, responses=error_responses(400, 413, 415, 422),
             openapi_extra={"requestBody": {"content": {"application/json": {"schema": _VERIFIABLE}}}})
def verify_certificate(document: Annotated[dict[str, Any], Body()]):
    """Check a certificate with the verifier (linear algebra only, no conic solver); takes what
    ``geocert verify`` takes: a certificate document, a result or a job document. For a result or
    a job, every item returned must also equal the item its certificate proves. ``valid`` is false,
    with ``first_failure`` naming the check, when any check fails (or the document carries no
    certificate); ``scope`` says what a valid document proves."""
    return verify.verify_any(document).as_dict()
