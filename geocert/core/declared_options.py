"""Each option of a solver's options dataclass stated once, where the dataclass declares it: its
default, its range, its allowed words, its description, and whether the API takes it. The
dataclass's ``check()`` reads its ranges from here (``OPTION_RANGES``), and the kinds' pydantic
request models are built from here (``geocert.kinds.schema.options_model``), so the API, the
command line, the solver and the verifier cannot disagree on what an option may be."""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

MISSING = dataclasses.MISSING
KEY = "geocert.option"  # where a field's metadata holds its Declared


@dataclasses.dataclass(frozen=True)
class Declared:
    bounds: dict  # pydantic Field keywords (ge, gt, le, lt); empty: no range
    choices: tuple | None  # the words a string option may be (the wire model's Literal)
    description: str | None
    api: bool  # the API's request takes it (False: the solver's alone, e.g. an internal switch)
    wire_default: Any  # what the API's model writes when not given; MISSING: the dataclass's default
    wire: Any  # the wire type where it is not the field's own (a nested object, a union); None: derived


def option(default: Any = MISSING, *, default_factory: Any = MISSING, ge=None, gt=None, le=None, lt=None,
           choices=None, description: str | None = None, api: bool = True, wire_default: Any = MISSING,
           wire: Any = None) -> Any:
    """A dataclass field declaring an option (use it as ``name: type = option(default, ...)``)."""
    bounds = {key: value for key, value in (("ge", ge), ("gt", gt), ("le", le), ("lt", lt)) if value is not None}
    declared = Declared(bounds, tuple(choices) if choices is not None else None, description, api, wire_default,
                        wire)
    return dataclasses.field(default=default, default_factory=default_factory, metadata={KEY: declared})


def redeclared(owner: type, name: str, default: Any = MISSING, **changes) -> Any:
    """A subclass's field for ``owner``'s option ``name`` with a new default (or description, or
    another of Declared's members): the rest as ``owner`` declares it, stated there only."""
    found = {entry.name: entry for entry in dataclasses.fields(owner)}[name]
    declared = dataclasses.replace(found.metadata[KEY], **changes)
    if default is MISSING:
        default, factory = found.default, found.default_factory
    else:
        factory = MISSING
    return dataclasses.field(default=default, default_factory=factory, metadata={KEY: declared})


@functools.cache
def declarations(options_type: type) -> dict[str, Declared]:
    """The declared options of a dataclass, by name, in its fields' order (not to be changed: one
    dict a class). Kept once read: an options dataclass's check() reads its ranges through here,
    option by option, on every job's parse, and walking the fields each time was most of parsing
    a triangulation job's options (bench/results/service.md). Whoever rewrites a field's
    declaration after reading it clears this (``declarations.cache_clear()``)."""
    return {entry.name: entry.metadata[KEY] for entry in dataclasses.fields(options_type) if KEY in entry.metadata}


def option_ranges(options_type: type) -> dict[str, dict]:
    """{option: pydantic Field keywords} of every declared option with a range."""
    return {name: dict(declared.bounds) for name, declared in declarations(options_type).items() if declared.bounds}


class DeclaredRanges:
    """``OPTION_RANGES`` as a class attribute read from the declarations (a subclass's own
    included), never written by hand."""

    def __get__(self, instance, owner: type) -> dict[str, dict]:
        return option_ranges(owner)


class DeclaredRange:
    """One option's range as a class attribute (e.g. ``JOB_LIMIT_RANGE``), read from its declaration."""

    def __init__(self, name: str):
        self.name = name

    def __get__(self, instance, owner: type) -> dict:
        return option_ranges(owner)[self.name]
