"""options.detail = "brief" (the fractional kinds): items carry their solution, bounds and status
only, the same numbers as a full item, and a full certificate still verifies."""

from __future__ import annotations

import pydantic
import pytest

from geocert.jobs.runner import parse_job, solve_job
from geocert.kinds import get_kind
from geocert.core.geometry import InputError
from geocert.formulations.fractional import determinacy
from geocert.verify.checks import RETURNED_FIELDS, verify_any

KINDS = ("triangulation", "homography", "resection")

from tests.support import loose_gaps


def job(name: str, **options) -> dict:
    kind = get_kind(name)
    return {**kind.example, "options": {**kind.example.get("options", {}), **options}}


@pytest.mark.parametrize("name", KINDS)
class TestBriefDetail:
    def test_same_numbers_without_summary_or_determinacy(self, name):
        kind = get_kind(name)
        full = solve_job(job(name))
        brief = solve_job(job(name, detail="brief"))
        kind.result_model.model_validate(brief)
        assert len(brief[kind.item_key]) == len(full[kind.item_key])
        for short, long in zip(brief[kind.item_key], full[kind.item_key]):
            for field in RETURNED_FIELDS + tuple(kind.solution_fields):
                assert short[field] == long[field], field
            assert short["certificate"] is None and short.get("determinacy") is None
            assert long["certificate"] is not None and long["determinacy"] is not None

    def test_determinacy_is_not_computed(self, name, monkeypatch):
        calls = []
        for function in ("track", "tracks_many", "map_"):
            original = getattr(determinacy, function)
            monkeypatch.setattr(determinacy, function,
                                lambda *args, _original=original, **kwargs: calls.append(1) or _original(*args, **kwargs))
        solve_job(job(name))
        assert calls  # the patch is seen by the kind
        calls.clear()
        solve_job(job(name, detail="brief"))
        assert calls == []

    def test_full_certificate_verifies(self, name):
        kind = get_kind(name)
        brief = solve_job(job(name, detail="brief", certificate="full"))
        kind.result_model.model_validate(brief)
        assert all(item["certificate"] is None for item in brief[kind.item_key])
        report = verify_any(brief)
        assert report.valid, report.first_failure
        full = solve_job(job(name, certificate="full"))
        assert ([claim["proof"] for claim in brief["certificate"]["items"]]
                == [claim["proof"] for claim in full["certificate"]["items"]])
        forged = {**brief, kind.item_key: [dict(item) for item in brief[kind.item_key]]}
        forged[kind.item_key][0]["cost"] = 0.0
        assert verify_any(forged).first_failure["check"] == "returned"

    def test_an_item_at_the_trivial_bound_has_no_certificate_member(self, name):
        """An item whose cost is within abs_gap of 0 is certified by the trivial bound, whose proof
        exists in every mode: a brief item still carries none (its result fits the model)."""
        kind = get_kind(name)
        example = job(name, detail="brief", abs_gap=1e9)  # every item then meets the trivial bound
        with loose_gaps():  # (an abs_gap beyond the cap the kinds and the verifier keep, for this test only)
            for certificate in ("summary", "full"):
                result = solve_job({**example, "options": {**example["options"], "certificate": certificate}})
                kind.result_model.model_validate(result)
                assert all(item["certified"] and item["certificate"] is None for item in result[kind.item_key])
                if certificate == "full":
                    assert {claim["proof"]["type"] for claim in result["certificate"]["items"]} == {"trivial"}
                    assert verify_any(result).valid

    def test_unknown_detail_is_named(self, name):
        kind = get_kind(name)
        with pytest.raises(InputError) as error:
            parse_job(job(name, detail="short"))
        assert error.value.field == "options/detail"
        with pytest.raises(pydantic.ValidationError) as invalid:
            kind.request_model.model_validate(job(name, detail="short"))
        assert any(e["loc"][-1] == "detail" for e in invalid.value.errors())
