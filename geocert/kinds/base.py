"""What a problem kind is, and the registry of the kinds served.

A kind turns a job's ``data`` into independent items (tracks, maps, frames, ...), solves one
item, and assembles the result. Everything that depends on the kind comes from its entry here:
the API's request and result models (and so the OpenAPI schema), ``/v1/problems``, chunk sizes,
the verifier's reading of its data, the benchmark runner and the contract tests. Adding a kind is
one module (or package) defining a ProblemKind and one line in ``geocert/kinds/__init__.py``.
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Any, Callable, Protocol, runtime_checkable

from pydantic import BaseModel

from geocert.verify import adapters as verified_kinds
from geocert.solvers.core.geometry import InputError

ProgressCallback = Callable[[Any], "bool | None"]


@runtime_checkable
class ProblemKind(Protocol):
    """The protocol every kind meets (duck-typed; see kinds/triangulation.py for one)."""

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

    def parse(self, data: Any, items: range | None = None) -> Any: ...

    def count(self, parsed: Any) -> int: ...

    def observations(self, parsed: Any) -> int: ...

    def solve_item(self, parsed: Any, index: int, options: Any, callback: ProgressCallback | None) -> dict: ...

    def cancelled_item(self, options: Any) -> dict:
        """An item never started (a cancel, or the job's time limit first), for the job's options."""

    def assemble(self, options: Any, items: list[dict], stats: dict) -> dict: ...


def _no_check(parsed: Any, options: Any) -> None:
    return None


def _every_item(items: list[dict]) -> list[dict]:
    return items


def _data_as_given(data: Any, items: list[dict]) -> Any:
    return data


def _no_figures(data: Any) -> dict:
    return {}


def _item_time_limit(parsed: Any, options: Any) -> float:
    return float(getattr(options, "time_limit_s", 0.0) or 0.0)


# Members a kind may leave out, with what they mean then: it issues certificates (a kind of
# estimates sets certifies = False: no certificate option, nothing for the verifier); nothing to
# check between its data and options beyond each alone; every item is a claim of its certificate;
# no list of its data holds its items one to one (chunk_key: the list that does, e.g. "tracks",
# which the job store keeps item by item so that a task reads only its chunk's); its certificate's
# data are the job's (a kind whose claims are about what an earlier stage found, e.g.
# reconstruction's points in the cameras it returns, states those instead).
# solve_batch(parsed, indices, options, callback, deadline=None) -> documents: many items solved
# at once (as solve_item would solve each, in order), batch_size of them at a time, when that
# shares work (triangulation); ``callback`` as solve_item's, for what runs long inside; ``deadline``
# (time.monotonic(), the job's: batch.job_deadline) one clock for the whole batch: each item's
# search stops by it, and an item not started by then reads time_limit (batch.not_started_item).
# streamed_result: its result is its items in order (under item_key) plus members that depend on
# the options and stats alone, so a large job's result is stored a task's run of items at a time
# and never assembled whole (batch.streams_result).
# time_bound_s(parsed, options) -> seconds: the longest one item runs when every time limit of
# the job is kept (its options' time_limit_s, per item, unless the kind says otherwise: per stage,
# per point); the service sizes a task's last-resort limits from it (batch.task_time_bound_s).
# request_figures(data) -> {figure: (value, field)}: what the job asks of the service beyond its
# items and observations, computed cheaply from the request's data as validated by its model,
# before anything is decoded or built (a photo's pixels from its header, shapes times points): the
# API refuses a job over a limit of settings.BUDGETS (413 naming the figure, its field and limit).
OPTIONAL_MEMBERS: dict[str, Any] = {"certifies": True, "check_options": _no_check, "claimed_items": _every_item,
                                    "chunk_key": None, "certificate_data": _data_as_given, "streamed_result": False,
                                    "solve_batch": None, "batch_size": 1, "time_bound_s": _item_time_limit,
                                    "request_figures": _no_figures}


class Registry:
    """The kinds served, by name, in the order registered."""

    def __init__(self, *kinds: ProblemKind):
        self._kinds: dict[str, ProblemKind] = {}
        for kind in kinds:
            self.register(kind)

    def register(self, kind: ProblemKind) -> ProblemKind:
        missing = [name for name in ProblemKind.__annotations__ if not hasattr(kind, name)]
        if missing or not isinstance(kind, ProblemKind):
            raise TypeError(f"{kind!r} is not a ProblemKind (missing: {', '.join(missing) or 'methods'})")
        for name, default in OPTIONAL_MEMBERS.items():  # what a kind may leave out, filled in once here
            if not hasattr(kind, name):
                setattr(kind, name, default)
        # the verifier's registry holds the served kinds' contracts; a kind added here joins it
        # (or, when served, must state the contract the verifier already checks it by)
        verified_kinds.register(verified_kinds.VerifiedKind(
            kind.name, kind.item_key, tuple(kind.solution_fields), kind.verification,
            getattr(kind, "options_type", None) if not hasattr(kind.verification, "checked_options") else None,
            kind.certifies, result_members(kind.result_model) if kind.certifies else ()))
        self._kinds[kind.name] = kind
        return kind

    def get(self, name: Any) -> ProblemKind:
        if not isinstance(name, str) or name not in self._kinds:
            raise InputError("kind", f"unknown problem kind {name!r} (served: {', '.join(self._kinds)})")
        return self._kinds[name]

    def __contains__(self, name: object) -> bool:
        return name in self._kinds

    def __iter__(self):
        return iter(self._kinds.values())

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
    names = {f.name for f in dataclasses.fields(options_type)}
    for key in given:
        if key not in names:
            raise InputError(f"{field}/{key}", f"unknown option (known: {', '.join(sorted(names))})")
    defaults = options_type()
    types = {f.name: str(f.type) for f in dataclasses.fields(options_type)}
    for key, value in given.items():
        default = getattr(defaults, key)
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


def default_options(kind: ProblemKind) -> dict:
    """The options a job of this kind gets when it gives none, as its request model writes them:
    what GET /v1/problems advertises, which the API accepts back as they are (the solver's options
    dataclass may hold more, e.g. the reconstruction's ``detail``, which the API does not take)."""
    return kind.request_model.model_fields["options"].get_default(call_default_factory=True).model_dump(mode="json")
