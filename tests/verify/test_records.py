"""The closed records the verifier reads (geocert.core.records) and the warning codes it
accepts (core.warning_codes) are what the writers write: the kinds' result models, and every code
the source writes."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from geocert.core import records
from geocert.core.strict import Invalid
from geocert.core.warning_codes import WARNING_CODES

SOURCE = Path(__file__).resolve().parents[2] / "geocert"
# A code written as a literal ({"code": "x"}) or as a motion's name (return "x", looks).
LITERAL = re.compile(r"""["']code["']\s*:\s*(f?)["']([^"']+)["']""")
MOTION = re.compile(r"""return\s+\(?["']([a-z_]+)["']\s+if\s+.*else\s+["']([a-z_]+)["']\)?,\s*looks|return\s+["']([a-z_]+)["'],\s*looks""")


def written_codes() -> set[str]:
    codes = set()
    for path in SOURCE.rglob("*.py"):
        text = path.read_text()
        for formatted, code in LITERAL.findall(text):
            if formatted:  # the one formatted code: near_{shape}_points, shape "collinear" or "coplanar"
                assert code == "near_{shape}_points", f"{path}: a formatted warning code {code!r} to list"
                codes |= {"near_collinear_points", "near_coplanar_points"}
            else:
                codes.add(code)
        for match in MOTION.findall(text):
            codes |= {code for code in match if code}
    return codes


def test_every_warning_code_the_source_writes_is_registered():
    codes = written_codes()
    assert {"at_infinity", "poses_not_determined", "orbital_motion", "critical_motion"} <= codes  # the scan reads them
    assert codes <= WARNING_CODES, sorted(codes - WARNING_CODES)


def test_the_motion_codes_are_registered():
    from geocert.formulations.autocalibration.determinacy import CRITICAL_CODES

    assert set(CRITICAL_CODES) <= WARNING_CODES


def test_the_shared_records_are_the_result_models():
    from geocert.kinds import schema

    def fields(model) -> frozenset:
        return frozenset(model.model_fields)

    assert records.DETERMINACY.members == fields(schema.Determinacy)
    assert records.DETERMINACY.nested["intervals"].members == fields(schema.DeterminacyInterval)
    assert records.DETERMINACY.nested["warnings"].members == fields(schema.DeterminacyWarning)
    proven = records.DETERMINACY.nested["proven_intervals"]
    assert proven.members == fields(schema.ProvenIntervals)
    assert proven.nested["intervals"].members == fields(schema.ProvenInterval)
    for summary in (records.TRACK_SUMMARY, records.MAP_SUMMARY, records.FRAME_SUMMARY):
        assert summary.members == fields(schema.ItemCertificate)


def test_the_claim_members_are_what_certificate_document_writes():
    from geocert.jobs.runner import solve_job
    from geocert.kinds import KINDS

    for kind in KINDS:
        if not kind.certifies:
            continue
        job = {**kind.example, "options": {**kind.example.get("options", {}), "certificate": "full"}}
        certificate = solve_job(job)["certificate"]
        for item in certificate["items"]:
            assert set(item) <= set(records.CLAIM_MEMBERS) | set(kind.solution_fields), kind.name


def test_a_record_is_closed_at_every_depth():
    determinacy = {"method": "curvature", "proven": False, "determined": True, "level": "", "cost_increase": 1.0,
                   "redundancy": 1, "intervals": [{"name": "x", "value": 0.0, "lower": 0.0, "upper": 0.0}],
                   "warnings": [{"code": "at_infinity", "detail": ""}]}
    records.check(determinacy, records.DETERMINACY, "determinacy")
    for edit in (lambda d: d.update(certified=True), lambda d: d["intervals"][0].update(proven=True),
                 lambda d: d["warnings"][0].update(code="everything_certified")):
        forged = {**determinacy, "intervals": [dict(determinacy["intervals"][0])],
                  "warnings": [dict(determinacy["warnings"][0])]}
        edit(forged)
        with pytest.raises(Invalid):
            records.check(forged, records.DETERMINACY, "determinacy")


@pytest.fixture(scope="module")
def undeclared_stage_members():
    """Every member the reconstruction pipeline wrote in a stage record that
    stage_checks.STAGE_RECORDS does not declare (so that keep_declared left it out), over the
    kind's example solved with K unknown, with K known and with the projective registration."""
    import copy

    from geocert.jobs.runner import solve_job
    from geocert.kinds import KINDS
    from geocert.kinds import reconstruction as kind_module

    found: list[str] = []
    declared = kind_module.keep_declared

    def recording(value, shape):
        before = copy.deepcopy(value)
        kept = declared(value, shape)
        _missing(before, kept, f"stages/{before.get('name')}" if isinstance(before, dict) else "images", found)
        return kept

    example = KINDS.get("reconstruction").example
    original, kind_module.keep_declared = kind_module.keep_declared, recording
    try:
        result = solve_job(example)
        K = next(c["K"] for c in result["cameras"] if c.get("K"))
        for options in ({"intrinsics": {"K": K}}, {"registration": "projective"}):
            solve_job({**example, "options": {**example["options"], **options}})
    finally:
        kind_module.keep_declared = original
    return found


def _missing(before, after, where: str, found: list) -> None:
    if isinstance(before, dict):
        found += [f"{where}/{name}" for name in before if name not in after]
        for name, value in before.items():
            if name in after:
                _missing(value, after[name], f"{where}/{name}", found)
    elif isinstance(before, list):
        for index, (value, kept) in enumerate(zip(before, after)):
            _missing(value, kept, f"{where}/{index}", found)


def test_the_stage_records_declare_what_the_pipeline_writes(undeclared_stage_members):
    assert undeclared_stage_members == []


def test_a_stage_member_no_writer_writes_is_refused():
    from tests.verify.test_forgeries import stored
    from tests.verify.test_forgeries_review5 import _valid

    for name, member in (("projective", "certified"), ("structure", "verified"), ("cameras", "unique_optimum")):
        result = stored("reconstruction")
        next(s for s in result["stages"] if s["name"] == name)[member] = True
        assert not _valid(result), (name, member)
    result = stored("reconstruction")
    next(s for s in result["stages"] if s["name"] == "bundle_adjustment")["principal_point"]["certified"] = True
    assert not _valid(result)


def test_a_summary_time_of_no_stage_is_refused():
    from tests.verify.test_forgeries import stored
    from tests.verify.test_forgeries_review5 import _valid

    result = stored("reconstruction")
    assert _valid(result)
    result["summary"]["time_s"]["certification"] = 0.0
    assert not _valid(result)
