"""The members of the records a result nests below its items, as their writers write them, and the
check that closes a result to them (numpy-free). A member no check reads claims nothing: a
record's member its writer never writes (a track's certificate summary stating "verified": true, a
determinacy "certified": true) is refused, as verify.check_members refuses one of the result's
own members or of an object one level down (docs/certificate.md, "Members").

Each record is listed once, here, beside the writer it is read from; the writers' own output is
checked against these lists by the tests (tests/verify/test_records.py), so that neither can
drift without a test failing. Older forms of a record are accepted with exactly the members their
writers wrote (the lists below hold every member a form of the record was written with)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from geocert.core.strict import Invalid
from geocert.core.warning_codes import WARNING_CODES


@dataclass(frozen=True)
class Record:
    """A record's members, and the records its members hold (a list's entries are each such a
    record). ``codes``: when set, the record's ``code`` is one of these (a warning)."""

    members: frozenset
    nested: dict = field(default_factory=dict)
    codes: frozenset | None = None

    def __hash__(self) -> int:  # the nested dict is never mutated
        return hash((self.members, tuple(sorted(self.nested)), self.codes))


@dataclass(frozen=True)
class ByName:
    """A list of records whose members depend on each one's ``name`` (a reconstruction's stages):
    ``records[name]``; a name not listed is refused."""

    records: dict

    def __hash__(self) -> int:
        return hash(tuple(sorted(self.records)))


def record(*members: str, codes: frozenset | None = None, **nested: "Record | ByName") -> Record:
    """A Record of ``members`` (a nested record's name is a member too)."""
    return Record(frozenset(members) | frozenset(nested), dict(nested), codes)


def keep_declared(value: Any, shape: "Record | ByName") -> Any:
    """The writer's side of check: ``value`` with every member its record does not declare left
    out, at every depth (a list's records each; a record of a name not declared as it is), so that
    what a writer returns is what the verifier reads. Returns the value (changed in place)."""
    if isinstance(value, list):
        for entry in value:
            keep_declared(entry, shape)
        return value
    if not isinstance(value, dict):
        return value
    if isinstance(shape, ByName):
        shape = shape.records.get(value.get("name"))
        if shape is None:
            return value
    for name in [name for name in value if name not in shape.members]:
        del value[name]
    for name, inner in shape.nested.items():
        if value.get(name) is not None:
            keep_declared(value[name], inner)
    return value


def check(value: Any, shape: "Record | ByName", where: str) -> None:
    """Refuses a member of ``value`` (a record, or a list of records) its writer never writes, at
    any depth of ``shape``. What is not a record (null, a number) in its place is left to the
    checks reading it; an entry of a list of records that is not one is refused: its writers write
    records only, and the checks reading a list pass over what is not one (a summary's warnings
    ending in null, a string "critical_motion" or a list verified: review 52)."""
    if isinstance(value, list):
        for index, entry in enumerate(value):
            if not isinstance(entry, dict):
                raise Invalid("returned", f"{where}/{index} is {entry!r:.40}: an entry of a list of records is a "
                                          "record (an object), as its writer writes it")
            check(entry, shape, f"{where}/{index}")
        return
    if not isinstance(value, dict):
        return
    if isinstance(shape, ByName):
        name = value.get("name")
        if not isinstance(name, str) or name not in shape.records:
            raise Invalid("returned", f"{where} is named {name!r:.40}, which no writer of it names (its names: "
                                      f"{', '.join(sorted(shape.records))})")
        shape = shape.records[name]
    extra = sorted(str(name) for name in set(value) - shape.members)
    if extra:
        raise Invalid("returned", f"{where} has a member {extra[0]!r:.40} its writer never writes (its members: "
                                  f"{', '.join(sorted(shape.members))}); a member no check reads claims nothing, so "
                                  "it is refused")
    if shape.codes is not None and value.get("code") not in shape.codes:
        raise Invalid("returned", f"{where}/code is {value.get('code')!r:.60}, a code nothing geocert runs writes "
                                  "(warning_codes.WARNING_CODES)")
    for name, inner in shape.nested.items():
        if value.get(name) is not None:
            check(value[name], inner, f"{where}/{name}")


# --- records every kind's items share (kinds.schema's models, kinds.documents' writers) ----------

# A warning (a determinacy's, a reconstruction summary's, a stage's motion warnings).
WARNING = record("code", "detail", codes=WARNING_CODES)

# Determinacy (kinds.schema.Determinacy, written by core.determinacy and each kind's own).
DETERMINACY = record("method", "proven", "determined", "level", "cost_increase", "redundancy", "pooled_tracks",
                     "proven_reason",
                     proven_intervals=record("cost_increase", "level", intervals=record("name", "lower", "upper", "reason")),
                     proven_over_planes=record("cost_increase", "affine_increase", "level",
                                               intervals=record("name", "lower", "upper")),
                     intervals=record("name", "value", "lower", "upper", "tolerance"),
                     warnings=WARNING)

# An item's certificate summary (kinds.schema.ItemCertificate; kinds.documents.certificate_summary,
# local_summary and bilinear.frame_document), its root region as each kind writes it.
SUMMARY_MEMBERS = ("scope", "tolerance", "tolerance_met", "leaves", "note")
FRACTIONAL_REGION = ("functionals", "denominator", "lower", "upper", "meaning")
TRACK_SUMMARY = record(*SUMMARY_MEMBERS, root_region=record("reference_view", *FRACTIONAL_REGION))
MAP_SUMMARY = record(*SUMMARY_MEMBERS, root_region=record("reference_point", *FRACTIONAL_REGION))
FRAME_SUMMARY = record(*SUMMARY_MEMBERS, root_region=record("camera_lower", "camera_upper", "translation",
                                                            "coefficients", "meaning"))
# An autocalibration stage's summary (kinds.autocalibration_stages.stage_document; the direct
# method adds its relaxation's figures: kinds.direct_autocalibration).
STAGE_SUMMARY = record("scope", "tolerance", "tolerance_met", "order", "moment_rank", "eigenvalue_ratio",
                       "conic_status")

# An item of a certificate document, beside its kind's solution fields (kinds.documents.
# certificate_document).
CLAIM_MEMBERS = ("index", "status", "certified", "cost", "lower_bound", "gap", "proof")

INTRINSIC_RANGES = record("focal", "aspect", "skew", "principal_point")

# An autocalibration stage as a reconstruction's autocalibration stage nests it
# (kinds.autocalibration_stages.stage_document, its certificate summary popped).
NESTED_STAGE = record("name", "cost", "lower_bound", "gap", "status", "certified", "nodes", "elapsed_s", "reason")

# A reconstruction's stages, summary and images are closed in reconstruction.stage_checks.


def check_nested(result: dict, nested: tuple) -> None:
    """Closes each record ``nested`` names: ((where, {member: shape}), ...), ``where`` a member of
    the result (a list's entries each) or "" for the result itself, ``member`` the record it holds."""
    for where, records in nested:
        value = result if where == "" else result.get(where)
        entries = value if isinstance(value, list) else [value]
        for index, entry in enumerate(entries):
            if not isinstance(entry, dict):
                continue
            place = where if not isinstance(value, list) else f"{where}/{index}"
            for name, shape in records.items():
                if entry.get(name) is not None:
                    check(entry[name], shape, f"{place}/{name}" if place else name)
