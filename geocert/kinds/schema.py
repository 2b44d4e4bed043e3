"""Pydantic building blocks the kinds' request and result models are made of (strict JSON types,
options from a solver's options dataclass, the outcome every item reports, the certificate)."""

from __future__ import annotations

import dataclasses
import typing
from typing import Annotated, Any, Literal

from pydantic import AnyHttpUrl, BaseModel, ConfigDict, Field, create_model, model_serializer

from geocert.core.declared_options import KEY, MISSING

# Strict types (the Strict models below): a JSON string ("330") or a boolean is never a number, and
# a float (1.0) is never an integer; a JSON integer is still a number wherever a float is asked for.
Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
CameraRow = Annotated[list[Finite], Field(min_length=4, max_length=4)]
Camera = Annotated[list[CameraRow], Field(min_length=3, max_length=3, description="3x4 projective camera")]
Pixel = Annotated[list[Finite], Field(min_length=2, max_length=2, description="[u, v] in pixels")]


class Strict(BaseModel):
    """Unknown fields are refused, and values are taken only as their JSON type (strict mode)."""

    model_config = ConfigDict(extra="forbid", strict=True)


def options_model(name: str, options_type: type, wire: dict | None = None, doc: str | None = None) -> type[BaseModel]:
    """The wire model of a kind's options, derived from its solver's options dataclass: every
    option declared there (core.declared_options.option) that the API takes, with its
    default, range, allowed words and description as declared, so the API, the CLI, the solver
    and the verifier cannot disagree. A nested options dataclass becomes a nested model (named
    after the option, ``...In``; a dict-valued option may name its dataclass as its declared
    ``wire``, and its docstring, when it has one, describes the nested model; ``doc``: the
    model's own). ``wire``: {option: type, or (type, default factory)} for an
    option whose JSON shape is a model of the kind's (an object the dataclass holds as a dict)."""
    wire = wire or {}
    hints = typing.get_type_hints(options_type)
    fields = {}
    for entry in dataclasses.fields(options_type):
        declared = entry.metadata.get(KEY)
        if declared is None or not declared.api:
            continue
        keywords = dict(declared.bounds)
        if declared.description is not None:
            keywords["description"] = declared.description
        given = wire.get(entry.name, declared.wire)
        if isinstance(given, tuple):
            annotation, factory = given
            fields[entry.name] = (annotation, Field(default_factory=factory, **keywords))
            continue
        nested = given if given is not None else hints[entry.name]
        if isinstance(nested, type) and dataclasses.is_dataclass(nested):  # a nested object of options
            documented = nested.__doc__ and not nested.__doc__.startswith(nested.__name__ + "(")  # not dataclass's
            given = options_model("".join(part.capitalize() for part in entry.name.split("_")) + "In", nested,
                                  doc=nested.__doc__ if documented else None)
        annotation = given if given is not None else _wire_type(hints[entry.name], declared)
        if declared.wire_default is None and type(None) not in typing.get_args(annotation):
            annotation = annotation | None  # null on the wire: the solver's default
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            fields[entry.name] = (annotation, Field(default_factory=annotation, **keywords))
            continue
        if declared.wire_default is not MISSING:
            default = declared.wire_default
        elif entry.default is not MISSING:
            default = entry.default
        else:
            default = entry.default_factory()
        fields[entry.name] = (annotation, Field(default, **keywords))
    model = create_model(name, __base__=Strict, __doc__=doc, **fields)
    model.__options_type__ = options_type  # what it is derived from (tests/kinds/test_option_declarations.py)
    return model


def _wire_type(hint: Any, declared) -> Any:
    """The JSON type of an option of Python type ``hint``: a float is a finite number (an integer
    allowed), an int an integer, a str one of its declared words, X | None either or null."""
    arguments = typing.get_args(hint)
    if type(None) in arguments:
        (inner,) = [argument for argument in arguments if argument is not type(None)]
        return _wire_type(inner, declared) | None
    if hint is str and declared.choices is not None:
        return Literal[declared.choices]
    return {float: Finite, int: int, bool: bool, str: str}[hint]


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
                                                      "point's and skew's half the image's larger side); null: "
                                                      "bounded suffices")


class DeterminacyWarning(BaseModel):
    code: str = Field(description="near_zero_parallax, at_infinity, near_coplanar_points, "
                                  "near_critical_configuration, near_collinear_points, pure_translation, "
                                  "rotation_about_one_axis, orbital_motion, critical_motion, at_range_edge (an "
                                  "interval cut by the intrinsics ranges), no_redundancy (as many residuals as "
                                  "parameters: the noise not estimated), few_degrees_of_freedom (the noise "
                                  "estimated from one degree of freedom: nothing determined), time_limit (the analysis "
                                  "stopped at the job's clock: not analysed), ...")
    detail: str


class ProvenInterval(BaseModel):
    name: str
    lower: float | None = Field(description="null: no end is proven on this side (reason says why)")
    upper: float | None = Field(description="null: no end is proven on this side (reason says why)")
    reason: str | None = Field(None, description="why an end is null (absent when both are proven)")

    @model_serializer(mode="wrap")
    def _reason_only_where_stated(self, handler):
        # the writers state a reason only beside a null end; a null one written everywhere would
        # make every proven interval differ from its proof's, which the verifier compares
        out = handler(self)
        if isinstance(out, dict) and out.get("reason") is None:
            out.pop("reason", None)
        return out


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
    proven_reason: str | None = Field(None, description="where proven intervals were asked for and "
                                                         "proven_intervals is null: why (the time limit ran out "
                                                         "before the proof finished, the stage not certified, ...)")
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
