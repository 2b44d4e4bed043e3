"""What a problem kind is, and the registry of the kinds served.

A kind turns a job's ``data`` into independent items (tracks, maps, frames, ...), solves one
item, and assembles the result. Everything that depends on the kind comes from its entry here:
the API's request and result models (and so the OpenAPI schema), ``/v1/problems``, chunk sizes,
the verifier's reading of its data, the benchmark runner and the contract tests. Adding a kind is
one module (or package) defining a ProblemKind and one line in ``geocert/kinds/__init__.py``.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
import importlib
import typing
from typing import Any, Callable

from pydantic import BaseModel

from geocert.verify import adapters as verified_kinds
from geocert.verify.verification import hook
from geocert.core.geometry import InputError

ProgressCallback = Callable[[Any], "bool | None"]


class ProblemKind(abc.ABC):
    """What every kind is (see kinds/triangulation.py for one): a subclass states the required class
    attributes below (the registry refuses a kind missing one), defines the abstract methods, and
    overrides an optional member only where its default does not fit."""

    # Required: each kind states these (as class attributes, or in its __init__).
    name: str  # the job's "kind"
    description: str
    item_key: str  # where items sit in data and result ("tracks", "maps")
    chunk_size: int  # items per queued task by default (GEOCERT_CHUNK_SIZES overrides)
    options_type: type  # the solver's options dataclass (defaults, OPTION_RANGES, check())
    request_model: type[BaseModel]  # the job request: kind literal, data, options
    result_model: type[BaseModel]  # the result document
    solution_fields: tuple[str, ...]  # what of an item its certificate claims as the solution
    verification: Any  # numpy-only adapter the verifier reads items through (read, item, domain, proofs)
    example: dict  # a small job ({"kind", "data", "options"}) that solves quickly: docs and contract tests

    @abc.abstractmethod
    def parse(self, data: Any, items: range | None = None) -> Any:
        """The job's data decoded (only the given items' when ``items`` is given), or InputError."""

    @abc.abstractmethod
    def count(self, parsed: Any) -> int:
        """How many items the parsed data hold."""

    @abc.abstractmethod
    def observations(self, parsed: Any) -> int:
        """How many observations the parsed data hold (a job's size for budgets and stats)."""

    @abc.abstractmethod
    def solve_item(self, parsed: Any, index: int, options: Any, callback: ProgressCallback | None) -> dict:
        """Item ``index`` solved: its document in the result."""

    @abc.abstractmethod
    def cancelled_item(self, options: Any) -> dict:
        """An item never started (a cancel, or the job's time limit first), for the job's options."""

    @abc.abstractmethod
    def assemble(self, options: Any, items: list[dict], stats: dict) -> dict:
        """The result document from the items' documents, in order, and the job's stats."""

    # Optional: what a kind may leave out, with what it means then.
    certifies: bool = True
    """It issues certificates. A kind of estimates sets ``certifies = False``: no certificate
    option, nothing for the verifier."""

    chunk_key: str | None = None
    """The list of its data that holds its items one to one (e.g. "tracks"), which the job store
    keeps item by item so that a task reads only its chunk's; None: no such list."""

    streamed_result: bool = False
    """Its result is its items in order (under item_key) plus members that depend on the options
    and stats alone, so a large job's result is stored a task's run of items at a time and never
    assembled whole (batch.streams_result)."""

    solve_batch: Callable[..., list[dict]] | None = None
    """None: no batch path, each item is solved by solve_item. A kind that shares work between
    items (triangulation) defines ``solve_batch(parsed, indices, options, callback, deadline=None)
    -> documents``: many items solved at once (as solve_item would solve each, in order),
    batch_size of them at a time; ``callback`` as solve_item's, for what runs long inside;
    ``deadline`` (time.monotonic(), the job's: batch.job_deadline) one clock for the whole batch:
    each item's search stops by it, and an item not started by then reads time_limit
    (batch.not_started_item)."""

    batch_size: int = 1
    """How many items solve_batch is given at a time (unused without solve_batch)."""

    def check_options(self, parsed: Any, options: Any) -> None:
        """Raise InputError when the data and options do not fit together; by default nothing to
        check beyond each alone."""
        return None

    def claimed_items(self, items: list[dict]) -> list[dict]:
        """The items its certificate claims; by default every item."""
        return items

    def certificate_data(self, data: Any, items: list[dict]) -> Any:
        """The data its certificate's claims are about; by default the job's. A kind whose claims
        are about what an earlier stage found (reconstruction's points in the cameras it returns)
        states those instead."""
        return data

    def time_bound_s(self, parsed: Any, options: Any) -> float:
        """The longest one item runs, in seconds, when every time limit of the job is kept: by
        default its options' time_limit_s, per item (a kind says otherwise: per stage, per point).
        The service sizes a task's last-resort limits from it (batch.task_time_bound_s)."""
        return float(getattr(options, "time_limit_s", 0.0) or 0.0)

    def request_figures(self, data: Any) -> dict:
        """{figure: (value, field)}: what the job asks of the service beyond its items and
        observations, computed cheaply from the request's data as validated by its model, before
        anything is decoded or built (a photo's pixels from its header, shapes times points): the
        API refuses a job over a limit of settings.BUDGETS (413 naming the figure, its field and
        limit). By default nothing."""
        return {}


REQUIRED_ATTRIBUTES = ("name", "description", "item_key", "chunk_size", "options_type", "request_model",
                       "result_model", "solution_fields", "verification", "example")
"""The class attributes every kind states (the optional ones have defaults on ProblemKind)."""


class Registry:
    """The kinds served, by name, in the order registered. A kind may be registered by where it is
    defined (``"module:attribute"``) and is imported on first use: a process that solves one kind
    (the command line's ``geocert solve``) imports that kind's solvers only, not every kind's."""

    def __init__(self, *kinds: ProblemKind, **defined_in: str):
        self._kinds: dict[str, ProblemKind | str] = {}
        for kind in kinds:
            self.register(kind)
        for name, where in defined_in.items():
            self._kinds[name] = where

    def register(self, kind: ProblemKind) -> ProblemKind:
        if not isinstance(kind, ProblemKind):
            lacking = [name for name in (*REQUIRED_ATTRIBUTES, *ProblemKind.__abstractmethods__)
                       if not hasattr(kind, name)]
            raise TypeError(f"{kind!r} is not a ProblemKind: a kind subclasses geocert.kinds.base.ProblemKind"
                            + (f" (and lacks: {', '.join(sorted(lacking))})" if lacking else ""))
        missing = [name for name in REQUIRED_ATTRIBUTES if not hasattr(kind, name)]
        if missing:
            raise TypeError(f"{kind!r} is not a complete ProblemKind: missing {', '.join(missing)}")
        # the verifier's registry holds the served kinds' contracts; a kind added here joins it
        # (or, when served, must state the contract the verifier already checks it by)
        verified_kinds.register(verified_kinds.VerifiedKind(
            kind.name, kind.item_key, tuple(kind.solution_fields), kind.verification,
            kind.options_type if hook(kind.verification, "checked_options") is None else None,
            kind.certifies, result_members(kind.result_model) if kind.certifies else ()))
        self._kinds[kind.name] = kind
        return kind

    def get(self, name: Any) -> ProblemKind:
        if not isinstance(name, str) or name not in self._kinds:
            raise InputError("kind", f"unknown problem kind {name!r} (served: {', '.join(self._kinds)})")
        kind = self._kinds[name]
        if isinstance(kind, str):
            module, attribute = kind.split(":")
            kind = getattr(importlib.import_module(module), attribute)
            if getattr(kind, "name", None) != name:
                raise TypeError(f"{module}:{attribute} is not the kind {name!r}")
            self.register(kind)
        return kind

    def __contains__(self, name: object) -> bool:
        return name in self._kinds

    def __iter__(self):
        return iter([self.get(name) for name in list(self._kinds)])

    def names(self) -> list[str]:
        return list(self._kinds)


def result_members(model: type[BaseModel]) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """A result model's members, and those of each model (or list of models) it nests one level
    down, as the verifier's registry lists them (VerifiedKind.members); a model keeping members
    beyond its own (a certificate document: the verifier closes those itself) is left open. A
    result may carry its full certificate whether or not its model names one (batch.solve_job
    adds it), as the verifier's own lists say."""
    members = [("", tuple(sorted(set(model.model_fields) | {"certificate"})))]
    for name, field in sorted(model.model_fields.items()):
        nested = _model_in(field.annotation)
        if nested is not None and nested.model_config.get("extra") != "allow":
            members.append((name, tuple(sorted(nested.model_fields))))
    return tuple(members)


def _model_in(annotation: Any) -> type[BaseModel] | None:
    """The model an annotation holds (itself, a list's, an optional's), or None."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for argument in typing.get_args(annotation):
        found = _model_in(argument)
        if found is not None:
            return found
    return None


def options_from(options_type: type, given: dict | None, field: str = "options"):
    """Build an options dataclass from a dict, naming any unknown or ill-typed option; the
    dataclass's own check() validates ranges (the same OPTION_RANGES the API's models use)."""
    given = dict(given or {})
    defaults, types = _option_facts(options_type)
    for key in given:
        if key not in types:
            raise InputError(f"{field}/{key}", f"unknown option (known: {', '.join(sorted(types))})")
    for key, value in given.items():
        default = defaults[key]
        if isinstance(default, bool):  # before the numbers: a bool is an int to Python
            if not isinstance(value, bool):
                raise InputError(f"{field}/{key}", "must be true or false")
            continue
        if value is None and "None" in types[key]:  # an optional option set to null
            continue
        if isinstance(default, str) and not isinstance(value, str):
            raise InputError(f"{field}/{key}", "must be a string")
        numeric = isinstance(value, (int, float)) and not isinstance(value, bool)
        if (isinstance(default, (int, float)) or (default is None and value is not None)) and not numeric:
            raise InputError(f"{field}/{key}", "must be a number")
        if isinstance(default, int) and not isinstance(default, bool) and not isinstance(value, int):
            raise InputError(f"{field}/{key}", "must be an integer")
    options = options_type(**given)
    options.check()
    return options


@functools.cache
def _option_facts(options_type: type) -> tuple[dict, dict]:
    """An options dataclass's defaults and its fields' types as text, by name: read once a class
    (options_from read them on every job's parse, a defaults instance made each time)."""
    defaults = options_type()
    fields = dataclasses.fields(options_type)
    return {f.name: getattr(defaults, f.name) for f in fields}, {f.name: str(f.type) for f in fields}


def default_options(kind: ProblemKind) -> dict:
    """The options a job of this kind gets when it gives none, as its request model writes them:
    what GET /v1/problems advertises, which the API accepts back as they are (the solver's options
    dataclass may hold more, e.g. the reconstruction's ``detail``, which the API does not take)."""
    return kind.request_model.model_fields["options"].get_default(call_default_factory=True).model_dump(mode="json")
