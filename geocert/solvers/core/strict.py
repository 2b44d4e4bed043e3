"""Strict readers of certificate documents: JSON numbers only (no strings, booleans, null or
non-finite values), of a stated shape, and an iterative nesting check. A failure is Invalid,
naming the verifier's check and what was wrong."""

from __future__ import annotations

from typing import Any

import numpy as np

from geocert.solvers.core.bnb import Box
from geocert.solvers.core.certificates import unpack
from geocert.solvers.core.geometry import InputError, is_number, number_array

SMALLEST_NORMAL = 2.0 ** -1022  # as cones.SMALLEST_NORMAL (this module imports no cone code)


class Invalid(Exception):
    """A check failed: ``check`` names it, the message says why."""

    def __init__(self, check: str, detail: str):
        super().__init__(detail)
        self.check, self.detail = check, detail


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

