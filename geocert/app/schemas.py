"""Request and response models of the HTTP API (version 1). Option defaults come from the
solvers' own option dataclasses, so the API, the CLI and the solvers cannot disagree."""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import AnyHttpUrl, BaseModel, ConfigDict, Field, TypeAdapter, create_model

from geocert.solvers.fractional.maps import MapOptions
from geocert.solvers.fractional.triangulation import TriangulationOptions

# Strict types (the Strict models below): a JSON string ("330") or a boolean is never a number, and
# a float (1.0) is never an integer; a JSON integer is still a number wherever a float is asked for.
Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
CameraRow = Annotated[list[Finite], Field(min_length=4, max_length=4)]
Camera = Annotated[list[CameraRow], Field(min_length=3, max_length=3, description="3x4 projective camera")]
Pixel = Annotated[list[Finite], Field(min_length=2, max_length=2, description="[u, v] in pixels")]



class Strict(BaseModel):
    """Unknown fields are refused, and values are taken only as their JSON type (strict mode)."""

    model_config = ConfigDict(extra="forbid", strict=True)


class TrackIn(Strict):
    views: list[Annotated[int, Field(ge=0)]] = Field(min_length=2, description="camera indices")
    points: list[Pixel] = Field(min_length=2, description="one observation per view, in the same order")


class TriangulationData(Strict):
    cameras: list[Camera] = Field(min_length=1)
    tracks: list[TrackIn] = Field(min_length=1)


def options_model(name: str, defaults, residual_units: str) -> type[BaseModel]:
    """The options of a kind, defaults taken from its solver's options dataclass."""
    return create_model(
        name,
        __base__=Strict,
        norm=(Literal["L2L2", "L2L1", "L1L1"], defaults.norm),
        rel_gap=(Finite, Field(defaults.rel_gap, ge=0, le=1, description="stop when gap <= rel_gap * cost ...")),
        abs_gap=(Finite, Field(defaults.abs_gap, ge=0, description="... or gap <= abs_gap (cost units)")),
        max_nodes=(int, Field(defaults.max_nodes, ge=1, le=1_000_000, description="per item")),
        time_limit_s=(Finite, Field(defaults.time_limit_s, gt=0, le=3600, description="per item")),
        max_residual=(Finite | None, Field(defaults.max_residual, gt=0,
                                           description=f"{residual_units}; narrows the certificate's scope")),
        certificate=(Literal["summary", "full"], Field(
            defaults.certificate, description="full: every bound's proof (dual vectors), checkable without "
                                              "a conic solver; see GET /v1/jobs/{id}/certificate")),
    )


TriangulationOptionsIn = options_model("TriangulationOptionsIn", TriangulationOptions(), "pixels")
MapOptionsIn = options_model("MapOptionsIn", MapOptions(), "target units")


class JobBase(Strict):
    callback_url: AnyHttpUrl | None = Field(
        None, description="receives the job document once it ends (POST, signed: X-Geocert-Signature)")


class TriangulationJob(JobBase):
    kind: Literal["triangulation"]
    data: TriangulationData
    options: TriangulationOptionsIn = Field(default_factory=TriangulationOptionsIn)


Coordinates = Annotated[list[Finite], Field(min_length=2, max_length=3)]


class MapIn(Strict):
    source: list[Coordinates] = Field(min_length=1, description="source points (3D for resection)")
    target: list[Coordinates] = Field(min_length=1, description="target points, same order (pixels for resection)")


class MapsData(Strict):
    maps: list[MapIn] = Field(min_length=1, description="independent maps, solved in parallel")


class ResectionJob(JobBase):
    kind: Literal["resection"]
    data: MapsData
    options: MapOptionsIn = Field(default_factory=MapOptionsIn)


class HomographyJob(JobBase):
    kind: Literal["homography"]
    data: MapsData
    options: MapOptionsIn = Field(default_factory=MapOptionsIn)


JobRequest = Annotated[Union[TriangulationJob, ResectionJob, HomographyJob], Field(discriminator="kind")]
JOB_REQUEST = TypeAdapter(JobRequest)

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
    result, so the two agree (``tracks_done`` counts the items whose status is not ``cancelled``,
    ``nodes`` equals ``stats.nodes``, the bounds sum the items' lower bounds and costs)."""

    nodes: int = 0
    open_boxes: int = 0
    lower_bound: float | None = None
    upper_bound: float | None = None
    gap_abs: float | None = None
    gap_rel: float | None = Field(None, description="worst relative gap over the tracks finished or running")
    tracks_done: int = Field(0, description="items (tracks, maps) finished")
    tracks_total: int = Field(0, description="items (tracks, maps) in the job")
    elapsed_s: float = 0.0


ItemStatus = Literal["optimal", "node_limit", "time_limit", "cancelled", "not_certified", "infeasible", "degenerate"]


class CertificateDocument(BaseModel):
    """A full certificate (docs/certificate.md): anyone can check it with linear algebra alone.
    Members beyond those listed are kept as they are (the verifier decides what they mean)."""

    model_config = ConfigDict(extra="allow")

    format: Literal["geocert-certificate"]
    version: int = Field(description="the format's version (docs/certificate.md)")
    kind: str
    options: dict[str, Any] = Field(description="the options solved with, defaults filled in")
    data: dict[str, Any] = Field(description="the problem data as solved")
    data_sha256: str = Field(description='SHA-256 of canonical JSON {"kind", "data"} (sorted keys, no spaces)')
    problem_sha256: str | None = Field(None, description="SHA-256 of the kind, the data and the options a claim "
                                                         "depends on (docs/certificate.md)")
    items: list[dict[str, Any]] = Field(description="per item: index, status, certified, cost, lower_bound, gap, "
                                                    "the solution, and the proof (root region, tightening, leaves)")


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
                                                           "(kind, norm, max_residual, gaps, statement)")


class ItemCertificate(BaseModel):
    scope: str
    root_region: dict[str, Any] | None = Field(
        description="the region searched and shown to hold the optimum; 'meaning' says how to read it")
    tolerance: float | None
    tolerance_met: bool
    leaves: int
    note: str | None = None


class ItemOutcome(BaseModel):
    """What every item (track, map) reports about its solve."""

    cost: float | None = Field(description="the upper bound, recomputed from the input: squared units (L2L2) or units")
    lower_bound: float | None
    gap: float | None
    status: ItemStatus
    certified: bool
    nodes: int
    elapsed_s: float
    reason: str | None = Field(description="why the item is not certified, when it is not")
    certificate: ItemCertificate | None


class TrackOut(ItemOutcome):
    point: list[float] | None = Field(description="[x, y, z], or a homogeneous 4-vector when at_infinity")
    at_infinity: bool


class JobStats(BaseModel):
    items: int
    certified: int
    nodes: int
    solve_s: float
    elapsed_s: float
    statuses: dict[str, int]


class TriangulationResult(BaseModel):
    kind: Literal["triangulation"]
    norm: str
    tracks: list[TrackOut]
    stats: JobStats
    certificate: CertificateDocument | None = Field(None, description='with options.certificate = "full"')


class MapOut(ItemOutcome):
    matrix: list[list[float]] | None = Field(description="Frobenius norm 1, reference depth positive")
    residuals: list[list[float]] = Field(description="target minus the map's image, per point")


class MapsResult(BaseModel):
    kind: Literal["resection", "homography"]
    norm: str
    maps: list[MapOut]
    stats: JobStats
    certificate: CertificateDocument | None = Field(None, description='with options.certificate = "full"')


class WebhookState(BaseModel):
    url: str
    state: Literal["waiting", "retrying", "delivered", "failed"]
    attempts: int
    last_error: str | None = None
    delivered_at: float | None = None


class Job(BaseModel):
    id: str
    kind: str
    status: JOB_STATUSES
    created_at: float
    started_at: float | None
    finished_at: float | None
    progress: JobProgress
    result: TriangulationResult | MapsResult | None = None
    error: ProblemDetails | None = None
    webhook: WebhookState | None = None
    links: dict[str, str]


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
    request_schema: dict[str, Any]
    default_options: dict[str, Any]


REQUEST_MODELS = {"triangulation": TriangulationJob, "resection": ResectionJob, "homography": HomographyJob}
