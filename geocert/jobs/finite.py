"""The guard every result passes before it is written: no number in it may be inf or NaN.

JSON has no such numbers: Python's encoder writes ``Infinity``/``NaN`` (not JSON), the result
models' writer writes ``null`` where the schema promises a number, and the verifier refuses either
("every number must be finite"). A quantity a solver cannot compute is stated as null beside its
reason by the solver itself (a kind's result builder), where its schema allows it; a non-finite
number reaching this guard is a solver's defect, and the job fails naming the field rather than
writing it (a kind cannot regress silently).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

TITLE = "Non-finite number in the result"


class NonFiniteResult(ArithmeticError):
    """A result holding inf or NaN at ``field`` (a JSON pointer-like path)."""

    def __init__(self, field: str, value: Any):
        self.field = field
        self.value = value
        super().__init__(f"{field or '(the result)'}: {value!r} is not a finite number. A result states only finite "
                         "numbers (one that cannot be computed is null, with its reason); this one was refused rather "
                         "than written: a defect of the solver, please report it with the job")

    def problem(self) -> dict:
        """The job's error as a problem document (RFC 9457), as the worker and the CLI state it."""
        return {"type": "about:blank", "title": TITLE, "status": 500, "detail": str(self),
                "errors": [{"field": self.field, "reason": str(self)}]}


def refuse_non_finite(document: Any, field: str = "") -> None:
    """Raise NonFiniteResult naming the first inf or NaN in ``document`` (dicts, lists, tuples,
    floats, numpy arrays and scalars; other values are the writer's to refuse). The usual case, a
    clean document, is one pass over it (about 0.3 us a number: a list of numbers is read by map
    at C speed); only a document that holds one is walked again to name the field."""
    if not _clean(document):
        _walk(document, field)
        raise NonFiniteResult(field, "a number")  # (_walk names it; this is never reached)


def _clean(value: Any) -> bool:
    kind = type(value)
    if kind is float:
        return math.isfinite(value)
    if kind is dict:
        return all(_clean(member) for member in value.values())
    if kind is list or kind is tuple:
        try:
            return all(map(math.isfinite, value))
        except (TypeError, OverflowError):  # not all of them numbers (or an int beyond the floats)
            return all(_clean(member) for member in value)
    if isinstance(value, np.ndarray):
        return not (value.dtype.kind in "fc" and not np.isfinite(value).all()) and (
            value.dtype != object or _clean(value.tolist()))
    if isinstance(value, (float, np.floating)):
        return math.isfinite(value)
    if isinstance(value, dict):  # subclasses: the exact types above are the fast path
        return all(_clean(member) for member in value.values())
    if isinstance(value, (list, tuple)):
        return all(_clean(member) for member in value)
    return True


def _walk(value: Any, field: str) -> None:
    if isinstance(value, dict):
        for key, member in value.items():
            _walk(member, f"{field}/{key}")
    elif isinstance(value, (list, tuple)):
        for index, member in enumerate(value):
            _walk(member, f"{field}/{index}")
    elif isinstance(value, np.ndarray):
        if value.dtype.kind in "fc" and not np.isfinite(value).all():
            where = np.argwhere(~np.isfinite(value))[0]
            raise NonFiniteResult(field + "".join(f"/{i}" for i in where), value[tuple(where)].item())
        if value.dtype == object:
            _walk(value.tolist(), field)
    elif isinstance(value, (float, np.floating)) and not math.isfinite(value):
        raise NonFiniteResult(field, float(value))
