"""Pydantic building blocks the kinds' request and result models are made of (strict JSON types,
options from a solver's options dataclass, the outcome every item reports, the certificate)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import AnyHttpUrl, BaseModel, ConfigDict, Field, create_model

# Strict types (the Strict models below): a JSON string ("330") or a boolean is never a number, and
# a float (1.0) is never an integer; a JSON integer is still a number wherever a float is asked for.
Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
CameraRow = Annotated[list[Finite], Field(min_length=4, max_length=4)]
Camera = Annotated[list[CameraRow], Field(min_length=3, max_length=3, description="3x4 projective camera")]
Pixel = Annotated[list[Finite], Field(min_length=2, max_length=2, description="[u, v] in pixels")]


class Strict(BaseModel):
    """Unknown fields are refused, and values are taken only as their JSON type (strict mode)."""

    model_config = ConfigDict(extra="forbid", strict=True)


def options_model(name: str, defaults, residual_units: str) -> type[BaseModel]:
    """The options of a kind, defaults and ranges taken from its solver's options dataclass
    (``OPTION_RANGES`` there), so the API, the CLI and the solver cannot disagree."""
    ranges = type(defaults).OPTION_RANGES
    return create_model(
        name,
        __base__=Strict,
        norm=(Literal["L2L2", "L2L1", "L1L1"], defaults.norm),
        rel_gap=(Finite, Field(defaults.rel_gap, **ranges["rel_gap"], description="stop when gap <= rel_gap * cost ...")),
        abs_gap=(Finite, Field(defaults.abs_gap, **ranges["abs_gap"], description="... or gap <= abs_gap (cost units)")),
        max_nodes=(int, Field(defaults.max_nodes, **ranges["max_nodes"], description="per item")),
        time_limit_s=(Finite, Field(defaults.time_limit_s, **ranges["time_limit_s"], description="per item")),
        max_residual=(Finite | None, Field(defaults.max_residual, **ranges["max_residual"],
                                           description=f"{residual_units}; narrows the certificate's scope")),
        certificate=(Literal["summary", "full"], Field(
            defaults.certificate, description="full: every bound's proof (dual vectors), checkable without "
                                              "a conic solver; see GET /v1/jobs/{id}/certificate")),
        detail=(Literal["full", "brief"], Field(
            defaults.detail, description="brief: each item carries its solution, bounds and status only "
                                         "(certificate and determinacy null, determinacy not computed): "
                                         "for large jobs; what is proven is the same")),
        **job_time_limit_field(defaults),
    )


def job_time_limit_field(defaults) -> dict:
    """The option ``job_time_limit_s`` of a many-item kind whose options have it (solvers'
    JobLimit), as a create_model field; none for a kind without."""
    if not hasattr(defaults, "job_time_limit_s"):
        return {}
    return {"job_time_limit_s": (Finite, Field(defaults.job_time_limit_s, **defaults.JOB_LIMIT_RANGE, description=(
        "the job in all, from when it starts: its items share this one clock; past it the item running stops "
        "with its best answer (status time_limit) and the items not started read time_limit, not started")))}


class JobBase(Strict):
    callback_url: AnyHttpUrl | None = Field(
        None, description="receives the job document once it ends (POST, signed: X-Geocert-Signature)")


ItemStatus = Literal["optimal", "node_limit", "time_limit", "cancelled", "not_certified", "infeasible"]


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


class ItemCertificate(BaseModel):
    scope: str
    root_region: dict[str, Any] | None = Field(
        description="the region searched and shown to hold the optimum; 'meaning' says how to read it")
    tolerance: float | None
    tolerance_met: bool
    leaves: int
    note: str | None = None


class DeterminacyInterval(BaseModel):
    name: str
    value: float | None
    lower: float | None = Field(description="null: not fixed by the data (unbounded)")
    upper: float | None
    tolerance: float | None = Field(None, description="the half-width `determined` allows: 10% of the quantity's "
                                                      "scale (a length's or focal length's value, a principal "
                                                      "point's focal length); null: bounded suffices")


class DeterminacyWarning(BaseModel):
    code: str = Field(description="near_zero_parallax, at_infinity, near_coplanar_points, "
                                  "near_critical_configuration, near_collinear_points, pure_translation, "
                                  "rotation_about_one_axis, orbital_motion, critical_motion, time_limit (the analysis "
                                  "stopped at the job's clock: not analysed), ...")
    detail: str


class ProvenInterval(BaseModel):
    name: str
    lower: float
    upper: float


class ProvenIntervals(BaseModel):
    """Intervals a certificate proves (its verifier checks them): every solution of the scope
    costing at most cost_increase more than the optimum lies in them."""

    cost_increase: float
    level: str
    intervals: list[ProvenInterval]


class ProvenOverPlanes(ProvenIntervals):
    """The stratified metric stage's intervals proven over the plane at infinity's own
    uncertainty: every K within the ranges costing at most cost_increase more than the stage's
    optimum for some plane chirality allows whose modulus cost is at most affine_increase above
    the affine stage's (docs/kinds/autocalibration.md)."""

    affine_increase: float


class Determinacy(BaseModel):
    """How well the data fix the answer (a certificate proves the optimum, not that it is unique):
    intervals of what a user reads off it over the answers costing at most cost_increase more,
    and the degeneracies recognised (docs/kinds.md, "Determinacy")."""

    method: Literal["curvature"]
    proven: bool = Field(description="true: proven_intervals holds intervals the certificate proves; the "
                                     "intervals beside them are estimated from the local curvature either way")
    proven_intervals: ProvenIntervals | None = Field(None, description="intervals proven within cost_increase of "
                                                                       "the optimum (null: none proven)")
    proven_over_planes: ProvenOverPlanes | None = Field(
        None, description="the stratified metric stage's intervals proven over every plane at infinity within "
                          "affine_increase of the affine stage's cost, not only the plane stated (absent: none proven)")
    determined: bool = Field(description="every interval bounded, within its tolerance of the value on both sides, "
                                         "and no warning")
    level: str
    cost_increase: float | None
    pooled_tracks: list[list[int]] | None = Field(None, description="with a level pooled over the job's tracks: "
                                                                    "the tracks pooled, as runs [first, stop) of "
                                                                    "their indices (the verifier recomputes the "
                                                                    "level from their residuals)")
    redundancy: int = Field(description="residuals beyond the parameters (0: no noise estimate)")
    intervals: list[DeterminacyInterval]
    warnings: list[DeterminacyWarning]


class ItemOutcome(BaseModel):
    """What every item (track, map) reports about its solve."""

    cost: float | None = Field(description="the upper bound, recomputed from the input: squared units (L2L2) or units")
    lower_bound: float | None = Field(description="the proven lower bound; null when the item is not certified (no "
                                                  "proof the verifier checks backs a stopped search's bound)")
    gap: float | None = Field(description="cost - lower_bound; null when the item is not certified")
    status: ItemStatus
    certified: bool
    nodes: int
    elapsed_s: float
    reason: str | None = Field(description="why the item is not certified, when it is not")
    certificate: ItemCertificate | None
    determinacy: Determinacy | None = Field(None, description="how well the data fix the answer (estimated)")


class JobStats(BaseModel):
    items: int
    certified: int
    nodes: int
    solve_s: float
    elapsed_s: float
    statuses: dict[str, int]
