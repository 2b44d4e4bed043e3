"""Strict readers of certificate documents: JSON numbers only (no strings, booleans, null or
non-finite values), of a stated shape, and an iterative nesting check. A failure is Invalid,
naming the verifier's check and what was wrong."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from geocert.solvers.core.bnb import Box


class Invalid(Exception):
    """A check failed: ``check`` names it, the message says why."""

    def __init__(self, check: str, detail: str):
        super().__init__(detail)
        self.check, self.detail = check, detail


def number(value: Any, name: str, check: str = "format") -> float:
    if type(value) is float:
        if math.isfinite(value):
            return value
    elif type(value) is int and abs(value) < 2**1023:
        return float(value)
    raise Invalid(check, f"{name} must be a finite JSON number, got {value!r:.40}")


def numbers(value: Any, name: str, shape: tuple[int | None, ...], check: str = "format") -> np.ndarray:
    """Nested lists of finite JSON numbers of the given shape (None: any length)."""
    def walk(v, level: int, where: str):
        if level == len(shape):
            return number(v, where, check)
        if not isinstance(v, list) or (shape[level] is not None and len(v) != shape[level]):
            size = "a list" if shape[level] is None else f"a list of {shape[level]}"
            raise Invalid(check, f"{where} must be {size}")
        return [walk(x, level + 1, f"{where}/{i}") for i, x in enumerate(v)]
    rows = walk(value, 0, name)
    try:
        array = np.array(rows, dtype=float)
    except ValueError as exc:
        raise Invalid(check, f"{name}: rows of different lengths") from exc
    if array.ndim != len(shape):
        raise Invalid(check, f"{name}: rows of different lengths")
    return array


def box(value: Any, name: str, k: int) -> Box:
    lo, hi = numbers(value, name, (2, k))
    return Box(lo, hi)


def nesting_depth(value: Any, limit: int) -> int:
    """How deeply lists and objects nest, up to ``limit`` + 1 (iterative: a hostile document
    cannot overflow a stack)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, (list, dict)):
            deepest = max(deepest, depth)
            if depth > limit:
                return depth
            stack.extend((x, depth + 1) for x in (v.values() if isinstance(v, dict) else v))
    return deepest
