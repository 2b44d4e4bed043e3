"""A toy kind, to show what adding a kind takes: this one module and one registry line.

"centroid": each item is a set of 2D points; the solution is the point minimising the sum of
squared distances to them (their mean), and its proof, of a type of its own ("closed_form"), is
that a convex quadratic's stationary point is its minimum: the verifier checks the gradient.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, Field

from geocert.kinds.base import ProblemKind
from geocert.kinds.schema import JobBase, JobStats, Pixel, Strict, options_model
from geocert.core.declared_options import DeclaredRanges, option
from geocert.core.geometry import InputError, number_array
from geocert.core.strict import Invalid, numbers
from geocert.verify.verification import Verification


@dataclass
class CentroidOptions:
    """Each option declared once (its default, range, words, description): the API's model below
    and the ranges its check and the verifier apply derive from these."""

    norm: str = option("L2L2", choices=("L2L2",))
    rel_gap: float = option(1e-3, ge=0, le=1)
    abs_gap: float = option(1e-7, ge=0)
    max_residual: float | None = option(None, api=False)  # the solver's, never asked for by the API
    certificate: str = option("summary", choices=("summary", "full"))
    OPTION_RANGES = DeclaredRanges()

    def check(self) -> None:
        if self.norm != "L2L2":
            raise InputError("options/norm", "the centroid is the L2L2 optimum only")
        if self.max_residual is not None:
            raise InputError("options/max_residual", "not supported by this kind")


CentroidOptionsIn = options_model("CentroidOptionsIn", CentroidOptions)


class CentroidData(Strict):
    sets: list[list[Pixel]] = Field(min_length=1)


class CentroidJob(JobBase):
    kind: Literal["centroid"]
    data: CentroidData
    options: CentroidOptionsIn = Field(default_factory=CentroidOptionsIn)


class CentroidOut(BaseModel):
    point: list[float]
    cost: float
    lower_bound: float
    gap: float
    status: str
    certified: bool
    nodes: int
    elapsed_s: float


class CentroidResult(BaseModel):
    kind: Literal["centroid"]
    norm: str
    sets: list[CentroidOut]
    stats: JobStats


def _check_closed_form(item, options, proof, lower_claimed, solution, passed) -> float:
    gradient = 2 * (len(item.points) * solution[:2] - item.points.sum(axis=0))
    if not np.all(np.abs(gradient) <= 1e-9 * (1 + np.abs(item.points).sum())):
        raise Invalid("leaf_bounds", "the gradient at the solution is not zero")
    passed.append("leaf_bounds")
    residuals = solution[:2] - item.points
    return float((residuals * residuals).sum()) * (1 - 1e-12)


class CentroidItem:
    def __init__(self, points: np.ndarray):
        self.points = points

    def solution(self, claim: dict) -> np.ndarray:
        return np.append(numbers(claim.get("point"), "point", (2,)), 1.0)

    def raw_residuals(self, solution):
        residuals = solution[:2] - self.points
        return residuals, np.ones(len(self.points)), 1e-12 * (np.abs(solution[:2]) + np.abs(self.points))

    def depths_agree(self, depths) -> bool:
        return True


class CentroidVerification(Verification):
    proofs = {"closed_form": _check_closed_form}
    domain = "every point of the plane"

    def read(self, data: dict, index: int):
        sets = data.get("sets") if isinstance(data, dict) else None
        if not isinstance(sets, list) or not 0 <= index < len(sets):
            raise Invalid("data", f"data/sets/{index}: no such set")
        return (numbers(sets[index], f"data/sets/{index}", (None, 2), "data"),)

    def item(self, arrays, norm):
        return CentroidItem(arrays[0])


class CentroidKind(ProblemKind):
    name = "centroid"
    description = "Toy: the point nearest (least squares) to each set of 2D points."
    item_key = "sets"
    chunk_size = 10
    options_type = CentroidOptions
    request_model = CentroidJob
    result_model = CentroidResult
    solution_fields = ("point",)
    verification = CentroidVerification()
    example = {"kind": "centroid", "options": {}, "data": {"sets": [[[0, 0], [2, 0], [1, 3]], [[5, 5], [7, 9]]]}}

    def parse(self, data: Any, items: range | None = None):
        if not isinstance(data, dict) or not isinstance(data.get("sets"), list) or not data["sets"]:
            raise InputError("data/sets", "must be a non-empty list of point sets")
        return [number_array(points, f"data/sets/{i}", "a list of [x, y] points", 2) for i, points in enumerate(data["sets"])]

    def count(self, parsed) -> int:
        return len(parsed)

    def observations(self, parsed) -> int:
        return sum(len(points) for points in parsed)

    def solve_item(self, parsed, index, options, callback) -> dict:
        points = parsed[index]
        centre = points.mean(axis=0)
        cost = float(((centre - points) ** 2).sum())
        return {"point": centre.tolist(), "cost": cost, "lower_bound": cost, "gap": 0.0, "status": "optimal",
                "certified": True, "nodes": 0, "elapsed_s": 0.0,
                "certificate": {"proof": {"type": "closed_form"}}}

    def cancelled_item(self, options: Any) -> dict:
        return {"point": [math.nan, math.nan], "cost": None, "lower_bound": None, "gap": None, "status": "cancelled",
                "certified": False, "nodes": 0, "elapsed_s": 0.0}

    def assemble(self, options, items: list[dict], stats: dict) -> dict:
        for item in items:
            item.pop("certificate", None)
        return {"kind": self.name, "norm": options.norm, "sets": items, "stats": stats}


KIND = CentroidKind()
