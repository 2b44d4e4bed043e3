"""Request and response models of the HTTP API (version 1). Option defaults come from the
solvers' own option dataclasses, so the API, the CLI and the solvers cannot disagree."""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, Field, TypeAdapter, model_validator

from geocert.kinds import KINDS
from geocert.kinds.schema import Camera, Finite, Strict

# One request model and one result model per kind, from the registry (geocert.kinds): the API's
# unions, and so its OpenAPI schema, follow the kinds served.
REQUEST_MODELS = {kind.name: kind.request_model for kind in KINDS}
JobRequest = Annotated[Union[tuple(REQUEST_MODELS.values())], Field(discriminator="kind")]
JOB_REQUEST = TypeAdapter(JobRequest)
RESULT_MODELS = tuple(dict.fromkeys(kind.result_model for kind in KINDS))  # kinds may share one
JobResult = Union[RESULT_MODELS]

# One example per kind for the API documentation (Swagger UI's example menu): each kind's own
# small example job, which solves in seconds as given (the contract tests run every one).
JOB_EXAMPLES = {kind.name: {"summary": kind.name, "description": kind.description, "value": kind.example}
                for kind in KINDS}

JOB_STATUSES = Literal["queued", "running", "succeeded", "failed", "cancelled"]


class FieldError(BaseModel):
    field: str
    reason: str


class ProblemDetails(BaseModel):
    """RFC 9457 problem details."""

    type: str = "about:blank"
    title: str
    status: int
    detail: str | None = None
    instance: str | None = None
    errors: list[FieldError] | None = None
    line: int | None = Field(None, description="for a body that is not JSON: where the parser stopped (from 1)")
    column: int | None = Field(None, description="for a body that is not JSON: where the parser stopped (from 1)")


class JobProgress(BaseModel):
    """While a job runs: finished items plus the ones running. Once it ends: recomputed from its
    result, so the two agree (``items_done`` counts the items whose status is not ``cancelled``,
    ``nodes`` equals ``stats.nodes``, the bounds sum the items' lower bounds and costs).

    ``tracks_done`` and ``tracks_total`` are the old names of ``items_done`` and ``items_total``
    (they count maps too), kept with the same values for clients that read them."""

    nodes: int = 0
    open_boxes: int = 0
    lower_bound: float | None = None
    upper_bound: float | None = None
    gap_abs: float | None = None
    gap_rel: float | None = Field(None, description="worst relative gap over the items finished or running: each "
                                                    "item's gap beyond the absolute tolerance (abs_gap), relative "
                                                    "to its cost (0 for an item within abs_gap)")
    items_done: int = Field(0, description="items (tracks, maps) finished")
    items_total: int = Field(0, description="items (tracks, maps) in the job")
    items_certified: int | None = Field(None, description="items certified: set once the job has ended (with a result)")
    tracks_done: int = Field(0, deprecated=True, description="the same as items_done (an old name: it counts maps too)")
    tracks_total: int = Field(0, deprecated=True, description="the same as items_total (an old name: it counts maps too)")
    elapsed_s: float = 0.0
    stage: str | None = Field(None, description="a staged solve's running stage (autocalibration: affine, metric)")

    @model_validator(mode="before")
    @classmethod
    def _either_name(cls, data: Any) -> Any:
        """Progress stored under one pair of names only (e.g. by an older release) shows both."""
        if isinstance(data, dict):
            for new, old in (("items_done", "tracks_done"), ("items_total", "tracks_total")):
                if new in data and old not in data:
                    data = data | {old: data[new]}
                elif old in data and new not in data:
                    data = data | {new: data[old]}
        return data


class VerifyCheck(BaseModel):
    name: str
    passed: int = Field(description="items that passed this check (documents, for format and data_hash)")
    failed: int


class VerifyFailure(BaseModel):
    check: str
    item: int | None
    detail: str


class VerifyReport(BaseModel):
    valid: bool
    checks: list[VerifyCheck] = Field(description="the checks in the order they run")
    first_failure: VerifyFailure | None = Field(description="the first check that failed, and on which item")
    items_checked: int
    items_skipped: int = Field(description="items not claimed certified: nothing to check")
    scope: dict[str, Any] | None = Field(None, description="what a valid document proves, and for which problem "
                                                           "(kind, norm, max_residual, gaps, statement; "
                                                           "within_abs_gap: the positions of the items certified "
                                                           "only through abs_gap, in the cost's units)")


class WebhookState(BaseModel):
    url: str
    state: Literal["waiting", "retrying", "delivered", "failed", "refused"] = Field(
        description="refused: the destination is not a public address (nothing sent, not retried); failed: no "
                    "attempt was answered with a 2xx")
    attempts: int
    last_error: str | None = Field(None, description='"refused: ..." or "failed: ..." (never how the destination '
                                                     "failed: a closed port, a timeout, an HTTP status)")
    delivered_at: float | None = None


class JobSummary(BaseModel):
    """A job in a listing: its state and progress, without the result (GET its ``self`` link)."""

    id: str
    kind: str
    status: JOB_STATUSES
    created_at: float
    started_at: float | None
    finished_at: float | None
    progress: JobProgress
    links: dict[str, str]


class Job(JobSummary):
    result: JobResult | None = None
    error: ProblemDetails | None = None
    webhook: WebhookState | None = None


class JobList(BaseModel):
    jobs: list[JobSummary] = Field(description="newest first")
    next_cursor: str | None = Field(description="pass as ?cursor= for the next page; null on the last page")
    links: dict[str, str | None] = Field(description="next: the next page's URL (null on the last page)")


PointIn = Annotated[list[Finite], Field(min_length=3, max_length=4, description="[x, y, z] or homogeneous [x, y, z, w]")]


class OrientRequest(Strict):
    """A projective reconstruction: cameras, points, and which cameras see which point."""

    cameras: list[Camera] = Field(min_length=1)
    points: list[PointIn] = Field(min_length=1)
    views: list[list[Annotated[int, Field(ge=0)]]] | None = Field(
        None, description="views[j]: the cameras that see point j (default: every camera sees every point)")


class OrientResult(BaseModel):
    cameras: list[list[list[float]]] = Field(description="the cameras with their signs fixed (and in the new frame "
                                                         "when frame_changed), each of Frobenius norm 1")
    points: list[list[float]] = Field(description="homogeneous [x, y, z, w]: w = 1 for every point when quasi_affine")
    camera_signs: list[int] = Field(description="+1 or -1 applied to each input camera")
    point_signs: list[int] = Field(description="+1 or -1 applied to each input point")
    transform: list[list[float]] = Field(description="H (4x4): points = H (signed points), cameras = (signed cameras) "
                                                     "H^-1; the identity unless frame_changed")
    frame_changed: bool = Field(description="the plane at infinity was moved off the scene (a projective change "
                                            "of frame; pixels are unchanged)")
    quasi_affine: bool = Field(description="every point has a positive last coordinate")
    centres_one_side: bool = Field(description="every camera centre is on one side of the plane at infinity too")
    oriented: bool = Field(description="every observed point is in front of (at positive depth in) every camera "
                                       "that sees it, with quasi_affine: the scope certificates speak of")
    negative_depths: list[list[int]] = Field(description="[camera, point] pairs still at negative depth: no choice "
                                                         "of signs puts them in front (noise or outliers)")
    undetermined: list[list[int]] = Field(description="[camera, point] pairs at depth 0 (on the principal plane)")


class ProblemKindInfo(BaseModel):
    kind: str
    description: str
    item_name: str
    certifies: bool = Field(description="false: the kind returns estimates, with no certificate (stereo_lines)")
    request_schema: dict[str, Any]
    default_options: dict[str, Any]
    example: dict[str, Any] = Field(description="a small job of this kind that solves in seconds, as it could be "
                                                "submitted (POST /v1/jobs)")

