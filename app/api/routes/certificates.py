"""Full certificates: fetch a job's, and check any with the independent verifier."""

from __future__ import annotations

from fastapi import APIRouter, Depends

from app.api.deps import JobStoreDep, error_responses, rate_limited
from app.api.routes.jobs import OwnedJob
from app.problems import ApiProblem
from app.schemas import CertificateDocument, VerifyReport
from solvers.verify import verify_document
from workers.store import TERMINAL

router = APIRouter(tags=["certificates"], dependencies=[Depends(rate_limited)])


@router.get("/v1/jobs/{job_id}/certificate", response_model=CertificateDocument, responses=error_responses(404, 409))
def job_certificate(job: OwnedJob, store: JobStoreDep):
    """The certificate document of a finished job submitted with ``options.certificate = "full"``."""
    if job["status"] not in TERMINAL:
        raise ApiProblem(409, f"job {job['id']} is {job['status']}: its certificate comes with its result")
    result = store.result(job["id"]) or {}
    if "certificate" not in result:
        raise ApiProblem(409, f"job {job['id']} has no full certificate: submit with options.certificate = \"full\"",
                         "options/certificate")
    return result["certificate"]


@router.post("/v1/certificates/verify", response_model=VerifyReport, responses=error_responses(400, 413, 422))
def verify_certificate(document: CertificateDocument):
    """Check a certificate document with the verifier (linear algebra only, no conic solver).
    ``valid`` is false, with ``first_failure`` naming the check, when any check fails."""
    return verify_document(document.model_dump(mode="json")).as_dict()
