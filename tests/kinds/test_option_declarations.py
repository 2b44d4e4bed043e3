"""Each kind's options are declared once, on its solver's options dataclass (default, range,
words, description: core.declared_options.option), and the API's wire model is derived
from that declaration (kinds.schema.options_model): the two agree option by option, and no kind
module states an option again."""

from __future__ import annotations

import ast
import dataclasses
import pathlib
import typing

import pytest
from pydantic import BaseModel

from geocert.kinds import KINDS
from geocert.core.declared_options import MISSING, declarations

KIND_MODULES = pathlib.Path(__file__).resolve().parents[2] / "geocert" / "kinds"
RANGE_KEYWORDS = ("ge", "gt", "le", "lt")


def wire_options(kind):
    return kind.request_model.model_fields["options"].annotation


def bounds_of(field) -> dict:
    """The range pydantic holds for a field (its constraints, however they were stated)."""
    found = {}
    for constraint in field.metadata:
        for key in RANGE_KEYWORDS:
            if getattr(constraint, key, None) is not None:
                found[key] = getattr(constraint, key)
    return found


def words_of(annotation) -> tuple | None:
    for argument in (annotation, *typing.get_args(annotation)):
        if typing.get_origin(argument) is typing.Literal:
            return typing.get_args(argument)
    return None


def pairs(options_type: type, model: type[BaseModel], prefix: str = ""):
    """(path, declaration, dataclass field, wire field) of every option the API takes, nested ones too."""
    entries = {entry.name: entry for entry in dataclasses.fields(options_type)}
    for name, declared in declarations(options_type).items():
        if not declared.api:
            continue
        assert name in model.model_fields, f"{prefix}{name}: declared for the API, missing from {model.__name__}"
        yield prefix + name, declared, entries[name], model.model_fields[name]


@pytest.mark.parametrize("kind", list(KINDS), ids=lambda kind: kind.name)
def test_every_option_the_api_takes_is_the_declared_one(kind):
    model = wire_options(kind)
    assert getattr(model, "__options_type__", None) is kind.options_type, "the wire model is not derived"
    stack, seen = [(kind.options_type, model, "")], 0
    while stack:
        options_type, wire, prefix = stack.pop()
        assert getattr(wire, "__options_type__", None) is options_type, f"{prefix or 'options'}: not derived"
        taken = {name for name, declared in declarations(options_type).items() if declared.api}
        assert set(wire.model_fields) == taken, f"{prefix or 'options'}: the wire model states other options"
        for path, declared, entry, field in pairs(options_type, wire, prefix):
            nested = field.annotation if isinstance(field.annotation, type) and issubclass(
                field.annotation, BaseModel) else None
            if nested is not None and getattr(nested, "__options_type__", None) is not None:
                stack.append((nested.__options_type__, nested, path + "/"))
                continue
            seen += 1
            if field.default_factory is None:
                default = declared.wire_default if declared.wire_default is not MISSING else (
                    entry.default if entry.default is not MISSING else entry.default_factory())
                assert field.default == default, f"{path}: default {field.default!r}, declared {default!r}"
            assert bounds_of(field) == declared.bounds, f"{path}: range {bounds_of(field)}, declared {declared.bounds}"
            if declared.choices is not None:
                assert words_of(field.annotation) == declared.choices, f"{path}: words differ from the declared"
            assert field.description == declared.description, f"{path}: description differs from the declared"
    assert seen == sum(1 for _ in _all_api_options(kind.options_type)), "an option the API takes was not compared"
    # the dataclass's check() reads the same ranges
    assert kind.options_type.OPTION_RANGES == {
        name: declared.bounds for name, declared in declarations(kind.options_type).items() if declared.bounds}


def _all_api_options(options_type: type):
    hints = typing.get_type_hints(options_type)
    for name, declared in declarations(options_type).items():
        if not declared.api:
            continue
        nested = declared.wire if declared.wire is not None else hints[name]
        if isinstance(nested, type) and dataclasses.is_dataclass(nested):
            yield from _all_api_options(nested)
        else:
            yield name


def _option_names() -> set[str]:
    """Every options dataclass a kind's wire model derives from, by class name."""
    names, stack = set(), [kind.options_type for kind in KINDS]
    while stack:
        options_type = stack.pop()
        names.add(options_type.__name__)
        hints = typing.get_type_hints(options_type)
        for name, declared in declarations(options_type).items():
            nested = declared.wire if declared.wire is not None else hints[name]
            if isinstance(nested, type) and dataclasses.is_dataclass(nested):
                stack.append(nested)
    return names


def test_no_kind_module_states_an_option_again():
    """Outside kinds/schema.py, no Field(...) reads an options dataclass (its defaults, or an
    instance of it) or a table of ranges: an option's default, range and description are stated
    on its declaration only."""
    classes = _option_names()
    found = []
    for path in sorted(KIND_MODULES.glob("*.py")):
        if path.name == "schema.py":
            continue
        tree = ast.parse(path.read_text())
        instances = {target.id for node in tree.body if isinstance(node, ast.Assign)
                     and isinstance(node.value, ast.Call) and _named(node.value.func) in classes
                     for target in node.targets if isinstance(target, ast.Name)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr in ("OPTION_RANGES", "FEATURE_RANGES",
                                                                 "JOB_LIMIT_RANGE"):
                found.append(f"{path.name}:{node.lineno} reads {node.attr}")
            if isinstance(node, ast.Call) and _named(node.func) == "Field":
                for part in ast.walk(node):
                    if isinstance(part, ast.Attribute) and isinstance(part.value, ast.Name) and (
                            part.value.id in classes or part.value.id in instances):
                        found.append(f"{path.name}:{node.lineno} states {part.value.id}.{part.attr} again")
    assert not found, "\n".join(found)


def _named(func) -> str | None:
    if isinstance(func, ast.Name):
        return func.id
    if isinstance(func, ast.Attribute):
        return func.attr
    return None
