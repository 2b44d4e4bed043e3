"""Strict readers of certificate documents: JSON numbers only (no strings, booleans, null or
non-finite values), of a stated shape, and an iterative nesting check. A failure is Invalid,
naming the verifier's check and what was wrong."""

from __future__ import annotations

import contextlib
import contextvars
import json
import math
from typing import Any

import numpy as np

from geocert.core.bnb import Box
from geocert.core.certificates import unpack
from geocert.core.geometry import InputError, is_number, number_array

SMALLEST_NORMAL = 2.0 ** -1022  # as cones.SMALLEST_NORMAL (this module imports no cone code)


class Invalid(Exception):
    """A check failed: ``check`` names it, the message says why."""

    def __init__(self, check: str, detail: str):
        super().__init__(detail)
        self.check, self.detail = check, detail


class RepeatedName(ValueError):
    """A JSON object names one member twice."""

    def __init__(self, name: str):
        super().__init__(f"the member name {name!r:.80} is repeated in one object")
        self.name = printable(name)


def _members(pairs: list[tuple[str, Any]]) -> dict:
    members: dict = {}
    for name, value in pairs:
        if name in members:
            raise RepeatedName(name)
        members[name] = value
    return members


class Unreadable(ValueError):
    """Valid JSON the reader cannot hold: an integer literal longer than Python converts
    (sys.get_int_max_str_digits, 4,300 digits by default), or any other ValueError of the parser
    that is not a syntax error."""

    def __init__(self, reason: str):
        super().__init__(f"the text cannot be read: {printable(reason)}")


def load_document(text: str | bytes) -> Any:
    """A document's JSON text read as the verifier reads it, refusing a member name repeated in
    one object (RepeatedName). RFC 8259 leaves a repeated name's meaning to each parser (the last
    value, the first, or an error), so one text could hold a second result that a reader keeping
    the first value reads and no check read; the verifier reads one document only. Valid JSON the
    parser cannot hold (an integer of more than 4,300 digits) is Unreadable; syntax errors stay
    JSONDecodeError, bytes not UTF-8 UnicodeDecodeError (both ValueErrors the callers name)."""
    try:
        return json.loads(text, object_pairs_hook=_members)
    except (json.JSONDecodeError, UnicodeDecodeError, RepeatedName):
        raise
    except ValueError as exc:
        raise Unreadable(str(exc)) from None


def printable(text: str) -> str:
    """``text`` (taken from a document: a member name, a value) as it may be echoed in a report or
    an error: a lone surrogate (valid as a JSON escape, \\ud800, but not encodable as UTF-8) written
    as its escape, every other character kept."""
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def printable_tree(value: Any) -> Any:
    """``value`` (a report: dicts, lists, strings, numbers) with every string and member name
    made printable (a report's details quote what a document holds)."""
    if isinstance(value, str):
        return printable(value)
    if isinstance(value, dict):
        return {printable_tree(key): printable_tree(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [printable_tree(item) for item in value]
    return value


def same(given: Any, expected: Any) -> bool:
    """Whether two JSON values are equal as JSON reads them: Python's == takes true for 1 and
    false for 0 (and 1.0), so a returned count compared by it could be stated as a boolean
    (``"certified": true`` for one item certified of six); here a boolean equals only a boolean,
    in lists and objects too."""
    if isinstance(given, bool) or isinstance(expected, bool):
        return type(given) is type(expected) and given == expected
    if isinstance(given, dict) and isinstance(expected, dict):
        return given.keys() == expected.keys() and all(same(given[k], expected[k]) for k in given)
    if isinstance(given, list) and isinstance(expected, list):
        return len(given) == len(expected) and all(same(a, b) for a, b in zip(given, expected))
    return given == expected


def same_counts(given: Any, expected: Any) -> bool:
    """``same``, with a count (an integer expected) stated as that integer only: JSON's 12, not
    12.0, which ``same`` takes for it (Python's 12.0 == 12). A count's writer writes an integer;
    review 60 found 12.0 accepted as a count where one was compared with ``same`` (a
    reconstruction's summary, its cameras' points, its stages', the job's stats) and refused where
    a count was typed (summary/tracks, the stages' figures)."""
    if type(expected) is int:
        return type(given) is int and given == expected
    if isinstance(given, dict) and isinstance(expected, dict):
        return given.keys() == expected.keys() and all(same_counts(given[k], expected[k]) for k in given)
    if isinstance(given, list) and isinstance(expected, list):
        return len(given) == len(expected) and all(same_counts(a, b) for a, b in zip(given, expected))
    return same(given, expected)


def number(value: Any, name: str, check: str = "format") -> float:
    if not is_number(value):
        raise Invalid(check, f"{name} must be a finite JSON number, got {value!r:.40}")
    return float(value)


def numbers(value: Any, name: str, shape: tuple[int | None, ...], check: str = "format") -> np.ndarray:
    """Nested lists of finite JSON numbers of the given shape (None: any length): the parser's
    strict reader (geometry.number_array), its refusal turned into the verifier's."""
    try:
        array = number_array(value, name, f"nested lists of numbers of shape {shape}", len(shape))
    except InputError as exc:
        raise Invalid(check, f"{exc.field}: {exc.reason}") from exc
    if any(expected is not None and size != expected for size, expected in zip(array.shape, shape)):
        raise Invalid(check, f"{name} has shape {list(array.shape)}, not {list(shape)}")
    return array


def box(value: Any, name: str, k: int) -> Box:
    lo, hi = numbers(value, name, (2, k))
    return Box(lo, hi)


_SCALARS = frozenset((int, float, str, bool, type(None)))


def nesting_depth(value: Any, limit: int) -> int:
    """How deeply lists and objects nest, up to ``limit`` + 1 (iterative, level by level: a
    hostile document cannot overflow a stack)."""
    depth, level = 0, [value] if isinstance(value, (list, dict)) else []
    while level:
        depth += 1
        if depth > limit:
            return depth
        below: list = []
        for v in level:
            members = v.values() if isinstance(v, dict) else v
            # Members of JSON's scalar types only (the common case: a list of numbers) are passed
            # over in C; otherwise the containers among them go on to the next level.
            if not _SCALARS.issuperset(map(type, members)):
                below.extend([x for x in members if isinstance(x, (list, dict))])
        level = below
    return depth


def dual_vector(text: Any, rows: int, where: str = "a dual vector", check: str = "format") -> np.ndarray:
    """A dual vector stored as base64 of little-endian float64: exactly ``rows`` finite entries,
    none subnormal (every product of one underflows: the solver writes 0 instead)."""
    if not isinstance(text, str):
        raise Invalid(check, f"{where} must be a base64 string")
    if len(text) != 4 * ((8 * rows + 2) // 3):  # before decoding: a hostile length costs nothing
        raise Invalid(check, f"{where} must have {rows} entries")
    try:
        z = unpack(text)
    except ValueError as exc:
        raise Invalid(check, f"{where} is not base64 of float64: {exc}") from exc
    if z is None or z.shape != (rows,) or not np.all(np.isfinite(z)):
        raise Invalid(check, f"{where} must have {rows} finite entries")
    if np.any((z != 0) & (np.abs(z) < SMALLEST_NORMAL)):
        raise Invalid(check, f"{where} has a subnormal entry (every product of one underflows)")
    return z



# --- the verifier's work, paid for by the document's size ---------------------------------------
#
# A verification may build, in total, at most WORK_PER_UNIT units of work per unit of the
# document's size (document_size: a JSON number, a string's 8 characters) plus WORK_BASE. A unit
# of work is one observation, point, view or chirality pair of a relaxation or program built
# (each a bounded number of rows and nonzeros), charged before it is built (charge). A proof
# with a dual vector pays for its own relaxation (its vector has a row per row); one without
# (a box behind a camera, a box without the domain) pays only its box, so a document cannot ask
# for work out of proportion to its size: time and memory stay linear in it.
WORK_PER_UNIT = 4
WORK_BASE = 2_000_000
_WORK: contextvars.ContextVar = contextvars.ContextVar("verification_work", default=None)


def document_size(value: Any) -> int:
    """The document's size in units: every number, boolean or null 1, every string its length
    over 8 (a dual vector's entry is about 1.3), every container 1 (iterative). Refuses a number
    that is not finite anywhere in it (JSON has none; a NaN compares false with everything, so
    a field no check reads could hold one unnoticed)."""
    size, level = 0, [value]
    while level:
        below: list = []
        for v in level:
            if isinstance(v, dict):
                size += 1
                below.extend(v.values())
                size += sum(len(k) // 8 for k in v)
            elif isinstance(v, list):
                size += 1
                if _NUMBERS.issuperset(map(type, v)):  # numbers only (the common case): in C
                    size += len(v)
                    if not math.isfinite(sum(x for x in v if type(x) is float)):
                        _finite_all(v)
                else:
                    below.extend(v)
            elif isinstance(v, str):
                size += 1 + len(v) // 8
            else:
                if type(v) is float and not math.isfinite(v):
                    _finite_all([v])
                size += 1
        level = below
    return size


_NUMBERS = frozenset((int, float, bool, type(None)))


def _finite_all(values: list) -> None:
    """Refuse a list holding a float that is not finite (a finite list's sum may overflow)."""
    for x in values:
        if type(x) is float and not math.isfinite(x):
            raise Invalid("format", f"the document holds the number {x!r}: every number must be finite (JSON has "
                                    "no NaN or Infinity)")


@contextlib.contextmanager
def work_budget(units: int):
    """Charges within this context (this thread or task) draw on ``units`` of work."""
    token = _WORK.set([units])
    try:
        yield
    finally:
        _WORK.reset(token)


def charge(units: int, what: str) -> None:
    """Pay for ``units`` of work before doing it (nothing outside a verification's budget: a
    solver checking its own claim)."""
    left = _WORK.get()
    if left is None:
        return
    left[0] -= units
    if left[0] < 0:
        raise Invalid("format", f"the document asks for more work than its size pays for ({what}): at most "
                                f"{WORK_PER_UNIT} units of work per unit of size, plus {WORK_BASE:,}")


def afford(units: int) -> bool:
    """Pay for ``units`` of work where the budget left pays for them (True, charged), else
    charge nothing and return False: for work a check may decline, with a stricter reading,
    rather than refuse the document (calibration_tie's re-adjustment, centred_fit). Outside a
    verification's budget, True."""
    left = _WORK.get()
    if left is None:
        return True
    if left[0] < units:
        return False
    left[0] -= units
    return True


def record(value: Any, where: str, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict:
    """An object with the ``required`` keys and perhaps the ``optional`` ones, no other: a field no
    check reads is not a place to hide what a reader might take for part of the proof."""
    if not isinstance(value, dict):
        raise Invalid("format", f"{where} must be an object")
    missing = [key for key in required if key not in value]
    unknown = [key for key in value if key not in required and key not in optional]
    if missing or unknown:
        raise Invalid("format", f"{where}: " + "; ".join(
            part for part in (f"missing {missing}" if missing else "", f"unknown {unknown}" if unknown else "") if part))
    return value


def informational(value: Any, where: str, kind: str = "number") -> None:
    """A field no proof check reads (a solver's note: a leaf's own bound beside the one recomputed,
    a moment matrix's rank): null or of its type, a number finite."""
    if value is None:
        return
    ok = {"number": is_number(value), "integer": type(value) is int, "text": isinstance(value, str)}[kind]
    if not ok:
        what = {"number": "a finite number", "integer": "an integer", "text": "a string"}[kind]
        raise Invalid("format", f"{where} must be null or {what} (informational: no check reads it), got {value!r:.40}")
