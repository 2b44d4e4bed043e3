"""The kind contract is an abstract base class: a kind subclasses ProblemKind, the registry refuses
anything else or a kind lacking a required member (naming it), and registering leaves the kind as
it was (its optional members' defaults live on the base class, not set onto the kind)."""

from __future__ import annotations

import pytest

from geocert.kinds.base import ProblemKind, Registry
from geocert.verify import adapters
from tests.kinds import toy_kind

REQUIRED = ("name", "description", "item_key", "chunk_size", "options_type", "request_model", "result_model",
            "solution_fields", "verification", "example")
ABSTRACT = ("parse", "count", "observations", "solve_item", "cancelled_item", "assemble")


@pytest.fixture(autouse=True)
def verifier_registry(monkeypatch):
    """Registering the toy kind adds its contract to the verifier's registry: kept to this test."""
    monkeypatch.setattr(adapters, "VERIFIED_KINDS", dict(adapters.VERIFIED_KINDS))


def toy_members(leaving_out: str = "") -> dict:
    """The toy kind's own members (the ProblemKind contract written out), less one."""
    return {key: value for key, value in vars(toy_kind.CentroidKind).items()
            if not key.startswith("__") and key != "_abc_impl" and key != leaving_out}


def test_registering_leaves_the_kind_as_it_was():
    kind = toy_kind.CentroidKind()
    before = dict(vars(kind))
    Registry().register(kind)
    assert vars(kind) == before
    # the defaults are the base class's
    assert kind.certifies is True and kind.solve_batch is None and kind.batch_size == 1
    assert kind.chunk_key is None and kind.streamed_result is False
    assert kind.request_figures({"sets": []}) == {} and kind.claimed_items([{"a": 1}]) == [{"a": 1}]
    assert kind.check_options(None, None) is None and kind.certificate_data({"d": 1}, []) == {"d": 1}


@pytest.mark.parametrize("name", REQUIRED)
def test_a_kind_lacking_a_required_attribute_is_refused_by_name(name):
    lacking = type("Lacking", (ProblemKind,), toy_members(leaving_out=name))()
    with pytest.raises(TypeError, match=rf"missing\W.*\b{name}\b"):
        Registry().register(lacking)


@pytest.mark.parametrize("name", ABSTRACT)
def test_a_kind_lacking_a_required_method_cannot_be_made(name):
    with pytest.raises(TypeError, match=rf"\b{name}\b"):
        type("Lacking", (ProblemKind,), toy_members(leaving_out=name))()


@pytest.mark.parametrize("name", ABSTRACT)
def test_a_duck_typed_kind_is_refused_naming_what_it_lacks(name):
    duck = type("Duck", (), toy_members(leaving_out=name))()
    with pytest.raises(TypeError, match=rf"ProblemKind.*lacks: .*\b{name}\b"):
        Registry().register(duck)


def test_a_complete_duck_typed_kind_is_still_refused():
    """Every member present but not a ProblemKind: the contract is the base class, not a shape."""
    duck = type("Duck", (), toy_members())()
    with pytest.raises(TypeError, match="subclasses geocert.kinds.base.ProblemKind"):
        Registry().register(duck)


def test_a_kind_overriding_a_default_keeps_its_own():
    members = toy_members()
    members.update(certifies=True, batch_size=7, request_figures=staticmethod(lambda data: {"points": (3, "x")}))
    kind = type("Own", (ProblemKind,), members)()
    Registry().register(kind)
    assert kind.batch_size == 7 and kind.request_figures({}) == {"points": (3, "x")}
